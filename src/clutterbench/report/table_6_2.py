"""Table 6.2: precision and recall of the inferred support relations (thesis eqs. 6.3, 6.4),
per method over the simulated test scenes, the thesis' mean beside the thesis' own rule.

Input: reports/support/scenes.csv, one row per (scene, method): the counts of true,
inferred and correct edges and the scene's precision / recall (NaN where undefined).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import Column, comparison_frame, thesis_row, write_table

TABLE = "table_6_2"
PULL_PREFIX = "pull_"
"""Methods on the CP's pull head, scored against the pull truth (support/evaluate.py)."""
THESIS_METHOD = "iou"
"""The rule the thesis evaluated (6.2.2: IoU of object and collapse area); its Table 6.2
mean sits beside this row only."""

SCENE_COLUMNS = (
    "scene",
    "family",
    "n_objects",
    "method",
    "n_true",
    "n_pred",
    "tp",
    "precision",
    "recall",
)

COLUMNS = [
    Column("precision", "mean precision"),
    Column("recall", "mean recall"),
    Column("pooled_precision", "pooled precision"),
    Column("pooled_recall", "pooled recall"),
    Column("true_per_scene", "true edges / scene", "{:.2f}"),
    Column("pred_per_scene", "inferred edges / scene", "{:.2f}"),
    Column("scenes", "scenes", "{:d}"),
    Column("scenes_precision", "scenes with precision", "{:d}"),
    Column("scenes_recall", "scenes with recall", "{:d}"),
    Column("thresholds", "thresholds", "{}"),
]

FAMILY_COLUMNS = [
    Column("family", "family", "{}"),
    Column("precision", "mean precision"),
    Column("recall", "mean recall"),
    Column("pooled_precision", "pooled precision"),
    Column("pooled_recall", "pooled recall"),
    Column("scenes", "scenes", "{:d}"),
]

# SupportParams field -> how it reads in the thresholds column.
THRESHOLD_TEXT = {
    "prob_threshold": lambda v: f"p>{v:.2f}",
    "score_threshold": lambda v: f"score>{v:.2f}",
    "bbox_margin_px": lambda v: f"margin {v} px",
    "adjacency_iou": lambda v: f"adj IoU>{v:.2f}",
    "max_gap_m": lambda v: "no gap test" if v is None else f"surface gap<{1000 * v:.0f} mm",
}


def thresholds_text(thresholds: Mapping[str, Any] | None) -> str:
    """'p>0.35, score>0.20, margin 3 px, adj IoU>0.00'; '—' for a method without any."""
    if not thresholds:
        return "—"
    parts = [
        THRESHOLD_TEXT[k](v) if k in THRESHOLD_TEXT else f"{k}={v}"
        for k, v in thresholds.items()
        if k != "rule"  # the row's method already names the rule
    ]
    return ", ".join(parts)


def _ratio(num: float, den: float) -> float:
    return float(num) / float(den) if den else float("nan")


def method_stats(scenes: pd.DataFrame) -> dict[str, Any]:
    """Means over scenes (each scene's precision / recall where defined, as the thesis' mean
    of Table 6.2) and pooled over scenes (summed edge counts)."""
    return {
        "precision": float(scenes["precision"].mean()),  # skips NaN: nothing inferred
        "recall": float(scenes["recall"].mean()),  # skips NaN: no true edge
        "pooled_precision": _ratio(scenes["tp"].sum(), scenes["n_pred"].sum()),
        "pooled_recall": _ratio(scenes["tp"].sum(), scenes["n_true"].sum()),
        "true_per_scene": float(scenes["n_true"].mean()),
        "pred_per_scene": float(scenes["n_pred"].mean()),
        "scenes": int(scenes["scene"].nunique()),
        "scenes_precision": int(scenes["precision"].notna().sum()),
        "scenes_recall": int(scenes["recall"].notna().sum()),
    }


def _check(scenes: pd.DataFrame, methods: Mapping[str, str]) -> None:
    missing = [c for c in SCENE_COLUMNS if c not in scenes.columns]
    if missing:
        raise ClutterbenchError(f"support scenes table lacks column(s) {', '.join(missing)}")
    for method in methods:
        if not (scenes["method"] == method).any():
            raise ClutterbenchError(f"support scenes table has no rows for method '{method}'")
    dup = scenes.duplicated(["scene", "method"])
    if dup.any():
        r = scenes[dup].iloc[0]
        raise ClutterbenchError(
            f"support scenes table: scene {r['scene']} method '{r['method']}' appears twice"
        )


def with_sensed(methods: Mapping[str, str], scenes: pd.DataFrame) -> dict[str, str]:
    """`methods`, then each one's rows under a sensor (support.sensing: method@<sensor> in
    scenes.csv) labelled so, sensor by sensor."""
    found = set(scenes["method"])
    sensors = sorted({m.partition("@")[2] for m in found if "@" in m})
    out = dict(methods)
    for sensor in sensors:
        for method, label in methods.items():
            if f"{method}@{sensor}" in found:
                out[f"{method}@{sensor}"] = f"{label}, on {sensor} depth"
    return out


def support_table(
    scenes: pd.DataFrame,
    methods: Mapping[str, str],
    thresholds: Mapping[str, Mapping[str, Any]],
    figures: Mapping[str, Any],
    out_dir: Path,
    scale: str,
    truth: Mapping[str, Sequence[Sequence[int]]] | None = None,
) -> pd.DataFrame:
    """reports/tables/table_6_2.{md,csv} (one row per method, in the order of `methods`)
    and table_6_2_families.{md,csv} (per method and scene family). Returns the per-method
    statistics.

    methods: method in scenes.csv -> its row label; thresholds: method -> the support
    thresholds it ran with (SupportParams fields), chosen on validation scenes; truth: test
    scene -> its true (supporter, supported) edges (data/support/truth.json), for the note on
    mutual support."""
    _check(scenes, methods)
    methods = with_sensed(methods, scenes)
    thesis = thesis_row(figures, TABLE, "mean")
    rows, stats = [], []
    family_rows = []
    for method, label in methods.items():
        mine = scenes[scenes["method"] == method]
        s = method_stats(mine) | {"thresholds": thresholds_text(thresholds.get(method))}
        stats.append({"method": method, "label": label, **s})
        rows.append((label, s, thesis if method == THESIS_METHOD else {}))
        for family, part in mine.groupby("family", sort=True):
            family_rows.append((label, {"family": family, **method_stats(part)}, {}))
    caption = figures[TABLE].get("caption", TABLE)
    notes = _notes(scenes, figures, scale)
    if truth is not None:
        notes.append(mutual_support_note(truth))
    frame = comparison_frame(rows, COLUMNS, "method")
    write_table(frame, COLUMNS, out_dir, TABLE, f"Table 6.2: {caption}", notes)
    families = comparison_frame(family_rows, FAMILY_COLUMNS, "method")
    write_table(
        families,
        FAMILY_COLUMNS,
        out_dir,
        f"{TABLE}_families",
        f"Table 6.2 by scene family: {caption}",
        notes,
    )
    return pd.DataFrame.from_records(stats)


def _notes(scenes: pd.DataFrame, figures: Mapping[str, Any], scale: str) -> list[str]:
    per_scene = scenes.drop_duplicates("scene")
    counts = per_scene["family"].value_counts().sort_index()
    mix = ", ".join(f"{family} {n}" for family, n in counts.items())
    lo, hi = int(per_scene["n_objects"].min()), int(per_scene["n_objects"].max())
    thesis_scenes = sum(1 for r in figures[TABLE].get("rows", []) if r.get("row") != "mean")
    return (
        [
            f"{scale} scale. ours: {len(per_scene)} simulated test scenes ({mix}), {lo}-{hi} "
            f"objects each; thesis: {thesis_scenes} real scenes, hand-annotated "
            f"({figures[TABLE].get('source', 'thesis')}).",
            "ground truth from physics: X supports Y when removing X moves Y beyond the threshold "
            "AND X and Y touch in the settled scene (the thesis drops relations between objects "
            "not in contact, 6.2.2).",
            "mean precision / recall: per-scene eqs. 6.3 and 6.4 averaged over the scenes where "
            "they are defined (precision: at least one inferred edge; recall: at least one true "
            "edge), as the thesis' mean; pooled: edge counts summed over scenes first.",
            f"thesis mean beside the thesis' own rule (method '{THESIS_METHOD}'). thresholds: "
            "chosen on validation scenes, never on test scenes.",
        ]
        + _pull_notes(scenes)
        + _estimate_notes(scenes)
        + _sensed_notes(scenes)
    )


def _sensed_notes(scenes: pd.DataFrame) -> list[str]:
    """What the rows under a sensor (support.sensing) read."""
    if not scenes["method"].astype(str).str.contains("@").any():
        return []
    return [
        "rows 'on <sensor> depth': the same test scenes with their depth images through that "
        "sensor model (the masks stay the simulator's), every threshold, the box head's edges "
        "and its fusion chosen on the same validation scenes through the same sensor."
    ]


def _pull_notes(scenes: pd.DataFrame) -> list[str]:
    """What the pull rows (methods pull_*: the CP's pull head) are measured against."""
    if not scenes["method"].astype(str).str.startswith(PULL_PREFIX).any():
        return []
    return [
        "pull_* rows: the collapse predictor's pull head (maps of pulling each box out with "
        "the trials' executor, train.models.<m>.labels), its thresholds chosen on the same "
        "validation scenes against the pull truth, scored against the pull truth of the same "
        "test scenes: X supports Y when the trials' pull of X out of the settled scene moves Y "
        "beyond the threshold or off the shelf AND X and Y touch (data/support/truth.json "
        "pull_edges). pull_collapse_* rows: the same for the pull_collapse head, against the "
        "truth of what the pull collapses (Y leaves the shelf, drops or tips beyond "
        "trials.collapse_free; pull_collapse_edges). The other rows: the deletion truth above."
    ]


def _estimate_notes(scenes: pd.DataFrame) -> list[str]:
    """What the physics-from-depth row's estimates lost: boxes the repair dropped (overlapping
    beyond repair, or with no place inside the shelf) and scenes whose perception failed."""
    if "est_dropped" not in scenes.columns:
        return []
    mine = scenes[scenes["est_dropped"].notna()]
    dropped = int(mine["est_dropped"].sum())
    outside = int(mine["est_outside"].sum())
    failed = int(mine["perception_failed"].sum())
    hit = int((mine["est_dropped"] > 0).sum())
    return [
        f"physics from depth: the repair of the fitted boxes (sim/estimated.py) dropped "
        f"{dropped} boxes in {hit} of {len(mine)} scenes ({outside} with no place inside the "
        f"shelf, the others overlapping beyond repair); perception failed in {failed} scenes "
        "(nothing inferred there)."
    ]


def mutual_support_note(truth: Mapping[str, Sequence[Sequence[int]]]) -> str:
    """How many true edges come in mutual pairs (removing either box moves the other, and they
    touch): the rule keeps one direction of a pair (thesis 6.2.3), which caps its recall
    whatever the collapse map (the oracle rows)."""
    edges = {(scene, int(x), int(y)) for scene, pairs in truth.items() for x, y in pairs}
    pairs = sum((scene, y, x) in edges for scene, x, y in edges) // 2
    n = len(edges)
    share = f" ({100.0 * 2 * pairs / n:.1f}%)" if n else ""
    cap = f"{1.0 - pairs / n:.3f}" if n else "undefined"
    return (
        f"mutual support: {2 * pairs} of the {n} true edges{share} come in mutual pairs "
        "(removing either box moves the other); the rule keeps one direction of a pair "
        f"(thesis 6.2.3), so its pooled recall is at most {cap}, whatever the collapse map."
    )
