"""Stage evaluate@<run>: pixel metrics, threshold sweep and figure of one model on one set."""

import sys
from pathlib import Path

from clutterbench.collapse.config import EvaluateConfig
from clutterbench.collapse.evaluate import evaluate_checkpoint
from clutterbench.collapse.figure import collapse_figure
from clutterbench.collapse.metrics import best_iou_row
from clutterbench.config import BaseConfig, load_section
from clutterbench.data.generate import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json, write_text
from clutterbench.stage import run_stage


def evaluate(params: dict, base: BaseConfig) -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else ""
    cfg = load_section(EvaluateConfig, "evaluate", params)
    if name not in cfg.runs:
        raise ClutterbenchError(f"evaluate.runs.{name}: no such run (known: {', '.join(cfg.runs)})")
    run = cfg.runs[name]
    gen = load_section(GenerateConfig, "generate", params)
    if run.dataset not in gen.datasets:
        raise ClutterbenchError(f"evaluate.runs.{name}.dataset: unknown dataset '{run.dataset}'")
    metrics, sweep, samples = evaluate_checkpoint(
        Path(f"models/{run.model}/best.pt"),
        Path("data/generate"),
        Path(f"data/split/{run.dataset}.json"),
        run.split,
        gen.datasets[run.dataset].moved_threshold_m,
        cfg,
    )
    best = best_iou_row(sweep)
    metrics |= {"sweep_best_iou": best["iou"], "sweep_best_threshold": best["threshold"]}
    out = Path(f"reports/evaluate/{name}")
    write_json(out / "metrics.json", {"model": run.model, "dataset": run.dataset, **metrics})
    header = list(sweep[0])
    lines = [",".join(header)] + [",".join(f"{r[h]:.6g}" for h in header) for r in sweep]
    write_text(out / "sweep.csv", "\n".join(lines) + "\n")
    title = f"{run.model} on {run.dataset} ({run.split}): IoU {metrics['iou']:.3f}"
    collapse_figure(samples, title, out / "figure.png")
    print(
        f"{name}: "
        + ", ".join(
            f"{k} {metrics[k]:.3f}" for k in ("pixel_accuracy", "iou", "precision", "recall")
        )
    )


if __name__ == "__main__":
    run_stage(evaluate)
