"""Tables 5.1 and 6.1: collapse prediction pixel metrics, ours beside the thesis'."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json
from clutterbench.report.tables import Column, comparison_frame, thesis_row, write_table

COLUMNS = [
    Column("pixel_accuracy", "pixel acc."),
    Column("iou", "IoU"),
    Column("precision", "precision"),
    Column("recall", "recall"),
    Column("pairs", "test pairs", "{:d}"),
    Column("sweep_best_iou", "best IoU in sweep"),
    Column("sweep_best_threshold", "at threshold", "{:.2f}"),
]

LABELS = {
    "fcn8s_baseline": "FCN-8s-based",
    "ours_bs32": "Ours (batch size 32)",
    "ours_bs16": "Ours (batch size 16)",
    "ours_finetuned_bs16": "Ours (fine-tuned, batch size 16)",
    "ours_finetuned_bs32": "Ours (fine-tuned, batch size 32)",
    "previous_work": "Previous work (ch. 5 collapse map network)",
    "ours_focal_loss": "Ours (CP, focal loss)",
}


def load_run_metrics(eval_dir: Path, run: str) -> dict[str, Any]:
    path = eval_dir / run / "metrics.json"
    if not path.exists():
        raise ClutterbenchError(f"{path} not found; run stage evaluate@{run}")
    metrics = read_json(path)
    assert isinstance(metrics, dict)
    return metrics


def collapse_table(
    table: str,
    rows: Mapping[str, str | None],
    figures: Mapping[str, Any],
    eval_dir: Path,
    out_dir: Path,
    notes: list[str],
) -> dict[str, dict[str, Any]]:
    """One comparison table: thesis row -> our evaluate run (None: not run, said so)."""
    records, ours_all, not_run = [], {}, []
    for row, run in rows.items():
        ours = load_run_metrics(eval_dir, run) if run else {}
        if run is None:
            not_run.append(LABELS.get(row, row))
        else:
            ours_all[row] = ours
        label = LABELS.get(row, row) + (f" [{run}]" if run else " [not run]")
        records.append((label, ours, thesis_row(figures, table, row)))
    frame = comparison_frame(records, COLUMNS, "method [our evaluate run]")
    caption = figures[table].get("caption", table)
    number = table.removeprefix("table_").replace("_", ".")
    if not_run:
        notes = [
            f"not run: {', '.join(not_run)}. They need ImageNet VGG-16 weights, which cannot be "
            "downloaded here; give a local torchvision vgg16 .pth as "
            "train.models.<m>.net.encoder.pretrained (with width 1.0) and map the row to its "
            "run in report.{table}.".format(table=table),
            *notes,
        ]
    write_table(frame, COLUMNS, out_dir, table, f"Table {number}: {caption}", notes)
    return ours_all
