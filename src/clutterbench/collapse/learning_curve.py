"""Learning curve of one network: the same training run on nested subsets of its training
scenes, validation unchanged. Answers "would more scenes help?" before paying for them.

    python -m clutterbench.collapse.learning_curve cp_focal --fractions 0.25 0.5
    make learning-curve                     # cp_focal at 1/4 and 1/2 of its training scenes

Each point trains `train.models.<model>` exactly as stage train@<model> does (same seed,
epochs, schedule, augmentation) on a seeded subset of the split's train scenes (the subsets
are nested: the 1/4 is inside the 1/2). The full-data point is the pipeline's own run
(reports/train/<model>/summary.json), so it costs nothing here. Writes
reports/learning_curve/<model>.{csv,md,png}; not a dvc stage (it costs several trainings).
"""

from __future__ import annotations

import argparse
import tempfile
import time
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import TrainPaths, train_model
from clutterbench.config import load_base, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.io import atomic_path, read_json, write_json, write_text
from clutterbench.stage import run_stage

COLUMNS = (
    "fraction",
    "train_scenes",
    "train_pairs",
    "epochs_run",
    "best_epoch",
    "val_loss",
    "val_iou",
    "val_iou_best",
    "val_precision",
    "val_recall",
    "seconds",
)


def subset_split(record: dict[str, Any], fraction: float, seed: int) -> dict[str, Any]:
    """The split `record` with its train scenes cut to round(fraction x n) (at least one),
    drawn by a seeded permutation, so smaller fractions are subsets of larger ones; val and
    test untouched."""
    if not 0.0 < fraction <= 1.0:
        raise ClutterbenchError(f"learning curve: fraction {fraction} is not in (0, 1]")
    train = list(record["train"])
    rng = np.random.default_rng([seed, zlib.crc32(str(record["dataset"]).encode()), 7])
    keep = rng.permutation(len(train))[: max(1, int(round(fraction * len(train))))]
    return {**record, "train": sorted(train[k] for k in keep)}


def _row(fraction: float, scenes: int, summary: dict[str, Any], seconds: float | None) -> dict:
    best = summary["best"]
    return {
        "fraction": fraction,
        "train_scenes": scenes,
        "train_pairs": summary["train_pairs"],
        "epochs_run": summary["epochs_run"],
        "best_epoch": best["epoch"],
        "val_loss": best["val_loss"],
        "val_iou": best["val_iou"],
        "val_iou_best": best.get("val_iou_best", float("nan")),
        "val_precision": best["val_precision"],
        "val_recall": best["val_recall"],
        "seconds": seconds,
    }


def learning_curve(
    model: str,
    fractions: Sequence[float],
    params: dict[str, Any],
    data_dir: Path = Path("data"),
    train_dir: Path = Path("reports/train"),
    timing_dir: Path = Path("reports/timing"),
    out_dir: Path = Path("reports/learning_curve"),
) -> list[dict[str, Any]]:
    """Train `model` on each fraction of its training scenes; the rows, full data last."""
    base = load_base(params)
    cfg = load_section(TrainConfig, "train", params)
    if model not in cfg.models:
        raise ClutterbenchError(
            f"train.models.{model}: no such model (known: {', '.join(cfg.models)})"
        )
    dataset = cfg.models[model].dataset
    threshold = load_section(GenerateConfig, "generate", params).datasets[dataset].moved_threshold_m
    split_file = data_dir / "split" / f"{dataset}.json"
    full_summary = train_dir / model / "summary.json"
    for path, stage in ((split_file, f"split@{dataset}"), (full_summary, f"train@{model}")):
        if not path.exists():
            raise ClutterbenchError(f"{path} not found; run stage {stage} first")
    record = read_json(split_file)
    rows = []
    for fraction in sorted(set(fractions) - {1.0}):
        sub = subset_split(record, fraction, base.seed)
        with tempfile.TemporaryDirectory(prefix=f"curve-{model}-") as tmp:
            tmp = Path(tmp)
            write_json(tmp / "split.json", sub)
            paths = TrainPaths(
                gen_dir=data_dir / "generate",
                split_file=tmp / "split.json",
                model_dir=tmp / "model",
                report_dir=tmp / "report",
                timing_file=tmp / "timing.json",
            )
            t0 = time.perf_counter()
            summary = train_model(model, cfg, threshold, base.seed, paths)
            rows.append(_row(fraction, len(sub["train"]), summary, time.perf_counter() - t0))
    timing = timing_dir / f"train_{model}.json"
    seconds = read_json(timing)["seconds"] if timing.exists() else None
    rows.append(_row(1.0, len(record["train"]), read_json(full_summary), seconds))
    write_curve(model, rows, base.scale, out_dir)
    return rows


def write_curve(model: str, rows: list[dict[str, Any]], scale: str, out_dir: Path) -> None:
    import pandas as pd

    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    out_dir.mkdir(parents=True, exist_ok=True)
    write_text(out_dir / f"{model}.csv", frame.to_csv(index=False, float_format="%.6g"))
    lines = [
        f"# Learning curve: {model} ({scale} scale)",
        "",
        "| training scenes | training pairs | best epoch / run | val loss | val IoU "
        "| val IoU, best threshold | val precision | val recall | train s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        secs = "" if r["seconds"] is None else f"{r['seconds']:.0f}"
        lines.append(
            f"| {r['train_scenes']} ({r['fraction']:.0%}) | {r['train_pairs']} | "
            f"{r['best_epoch']} / {r['epochs_run']} | {r['val_loss']:.5f} | {r['val_iou']:.3f} | "
            f"{r['val_iou_best']:.3f} | {r['val_precision']:.3f} | {r['val_recall']:.3f} | {secs} |"
        )
    lines += [
        "",
        "Same training run (params' train.models entry, seed, epochs) on nested seeded subsets "
        "of the split's train scenes; validation scenes unchanged. Validation scores at the "
        "best epoch (lowest val loss), pixel threshold train.val_threshold.",
    ]
    write_text(out_dir / f"{model}.md", "\n".join(lines) + "\n")
    _plot(model, frame, out_dir / f"{model}.png")


def _plot(model: str, frame: Any, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(frame["train_scenes"], frame["val_iou"], "o-", label="val IoU at 0.5")
    ax.plot(frame["train_scenes"], frame["val_iou_best"], "^-", label="val IoU, best threshold")
    ax.plot(frame["train_scenes"], frame["val_recall"], "s--", label="val recall")
    ax.set_xscale("log")
    ax.set_xlabel("training scenes")
    ax.set_ylabel("score at the best epoch")
    ax.set_title(f"{model}: learning curve")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120, metadata={"Software": None})
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a key of train.models")
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.25, 0.5])
    args = parser.parse_args(argv)

    def run(params: dict[str, Any], base: Any) -> None:
        for r in learning_curve(args.model, args.fractions, params):
            print(
                f"{r['train_scenes']:6d} scenes: val IoU {r['val_iou']:.3f}, "
                f"val loss {r['val_loss']:.5f}"
            )

    run_stage(run)  # params.yaml, seeding and torch threads as every stage; errors: one line


if __name__ == "__main__":
    main()
