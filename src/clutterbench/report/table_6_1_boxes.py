"""Table 6.1 per box: the box head's per-box pull predictions on the ch6_test pairs (every
ordered pair of visible boxes, x pulled and y judged), beside the collapse predictor's pixel
heads read per box (each head's mean probability over the box's visible pixels), in Table
6.1's terms: precision and recall at the threshold chosen on validation pairs, AUROC, and
calibration (expected calibration error, Brier score). The thesis reports no per-box figure,
so the table has no thesis column.

Input: reports/box_head/scores.csv (stage box_head), one row per (method, output, group).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import Column, comparison_frame, write_table

TABLE = "table_6_1_boxes"
METHOD_TEXT = {"box_head": "box head (per box)"}
"""Row labels; a pixel head's method is 'pixel_<head>'."""
OUTPUT_TEXT = {
    "pull_collapse": "pull collapses the box",
    "pull": "pull moves the box (or it leaves the shelf)",
    "contact": "the two boxes touch",
}
COLUMNS = [
    Column("output", "predicts", "{}"),
    Column("group", "subset of pairs", "{}"),
    Column("precision", "precision"),
    Column("recall", "recall"),
    Column("f1", "F1"),
    Column("auroc", "AUROC"),
    Column("ece", "calibration error (ECE)"),
    Column("brier", "Brier"),
    Column("threshold", "val-chosen threshold", "{:.2f}"),
    Column("positives", "positive pairs", "{:d}"),
    Column("n", "pairs", "{:d}"),
]
NEEDED = {c.key for c in COLUMNS} | {"method"}


def method_text(method: str) -> str:
    if method.startswith("pixel_"):
        return f"CP {method.removeprefix('pixel_')} head (its mean over the box)"
    return METHOD_TEXT.get(method, method)


def box_table(scores: pd.DataFrame, out_dir: Path, scale: str) -> None:
    """reports/tables/table_6_1_boxes.{md,csv}: every method and output over all test pairs,
    then per family and visible-box count."""
    missing = sorted(NEEDED - set(scores.columns))
    if missing:
        raise ClutterbenchError(f"box-head scores lack column(s) {', '.join(missing)}")
    order = {g: i for i, g in enumerate(dict.fromkeys(scores["group"]))}
    ordered = scores.assign(_all=scores["group"] != "all", _g=scores["group"].map(order))
    ordered = ordered.sort_values(["_all", "output", "_g"], kind="stable")
    rows = []
    for _, r in ordered.iterrows():
        ours = r.to_dict() | {"output": OUTPUT_TEXT.get(r["output"], r["output"])}
        rows.append((method_text(str(r["method"])), ours, {}))
    frame = comparison_frame(rows, COLUMNS, "method")
    notes = [
        f"{scale} scale. pairs: every ordered pair (x pulled, y judged) of visible boxes of the "
        "ch6_test scenes; truth: the trials' pull of x out of the settled scene (pull: y moved "
        "beyond the label threshold or left the shelf; pull collapses: y left the shelf, "
        "dropped or tipped beyond trials.collapse_free) and contact in the settled scene.",
        "thresholds and the box head's epoch: chosen on the validation split's pairs, never on "
        "the test scenes. AUROC and calibration need no threshold. ECE: 10 equal-width bins.",
        "the pixel heads read per box are the collapse predictor's own maps, unchanged; the "
        "thesis reports no per-box figure.",
    ]
    write_table(
        frame,
        COLUMNS,
        out_dir,
        TABLE,
        "Table 6.1 per box: what pulling a box does to each other box",
        notes,
    )
