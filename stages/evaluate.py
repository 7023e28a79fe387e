"""Stage evaluate@<run>: pixel metrics, threshold sweeps and figure of one model on one set."""

import sys
from pathlib import Path

from clutterbench.collapse.config import EvaluateConfig
from clutterbench.collapse.evaluate import SplitRef, evaluate_checkpoint, write_sweep_csv
from clutterbench.collapse.figure import collapse_figure
from clutterbench.config import BaseConfig, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.precision import inference_from_params
from clutterbench.stage import run_stage


def evaluate(params: dict, base: BaseConfig) -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else ""
    cfg = load_section(EvaluateConfig, "evaluate", params)
    if name not in cfg.runs:
        raise ClutterbenchError(f"evaluate.runs.{name}: no such run (known: {', '.join(cfg.runs)})")
    run, cfg = cfg.runs[name], cfg.for_run(name)
    precision = inference_from_params(params)
    gen = load_section(GenerateConfig, "generate", params)
    for key, dataset in (("dataset", run.dataset), ("val_dataset", run.val_dataset)):
        if dataset not in gen.datasets:
            raise ClutterbenchError(f"evaluate.runs.{name}.{key}: unknown dataset '{dataset}'")

    def split(dataset: str, which: str) -> SplitRef:
        path = Path(f"data/split/{dataset}.json")
        threshold_m = gen.datasets[dataset].moved_threshold_m
        return SplitRef(dataset, path, which, threshold_m, label_thresholds(params))

    result = evaluate_checkpoint(
        Path(f"models/{run.model}/best.pt"),
        Path("data/generate"),
        split(run.dataset, run.split),
        split(run.val_dataset, "val"),
        cfg,
        f"evaluate.runs.{name}.val_dataset",
        run.head,
    )
    metrics = result.metrics
    out = Path(f"reports/evaluate/{name}")
    about = {"model": run.model, "dataset": run.dataset, "split": run.split}
    if run.head != "deletion":  # deletion runs' metrics stay as they were before heads
        about["head"] = run.head
    about |= {"network_precision": precision}
    write_json(out / "metrics.json", about | {"val_dataset": run.val_dataset, **metrics})
    write_sweep_csv(out / "sweep.csv", result.sweep)
    write_sweep_csv(out / "val_sweep.csv", result.val_sweep)
    head = "" if run.head == "deletion" else f", {run.head} head"
    title = f"{run.model}{head} on {run.dataset} ({run.split}): IoU {metrics['iou']:.3f}"
    collapse_figure(result.samples, title, out / "figure.png")
    scores = ", ".join(f"{k} {metrics[k]:.3f}" for k in ("pixel_accuracy", "iou", "precision"))
    chosen = metrics["val_chosen_threshold"]
    print(
        f"{name}: {scores}; per-pair IoU {metrics['pair_mean_iou']:.3f}; "
        f"at val-chosen {chosen:.2f}: IoU {metrics['iou_at_val_chosen']:.3f}"
    )


if __name__ == "__main__":
    run_stage(evaluate)
