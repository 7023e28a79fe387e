"""Table 4.1: ch. 4 simulated trials (one pull of an (extract, support) pair), ours beside the
thesis' real-robot rows; and the predetermined-target trials of thesis 4.3.3.

Rows of Table 4.1 are labelled '<method>/<objects>' (the `row:` values of table_4_1 in
reports/thesis_figures.yaml, or rows the thesis lacks such as the depth-only, random and
oracle ones), or '<method>/<objects>/<sensing>' for a condition run again under a depth
sensor (trials.ch4_sensed, docs/sensing.md; never a thesis row); each maps to one trials_ch4
condition. Every method (and sensor) also gets a '<method>/total[/<sensing>]' row pooling the
episodes of its cells, as the thesis totals its models.
Rows of the predetermined-target table are methods alone. Every rate comes from
trials.stats.aggregate.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import (
    IDEAL,
    SENSORS,
    Column,
    comparison_frame,
    grouped,
    rate_text,
    sensed_by_preset,
    sensed_text,
    thesis_rate_text,
    thesis_row,
    values_text,
    write_raw_csv,
    write_table,
)
from clutterbench.trials.core.stats import aggregate, rate

TABLE = "table_4_1"
TARGET_TABLE = "table_4_1_target"
TARGET_FIGURES = "ch4_predetermined_target"
"""The thesis' predetermined-target result (a text figure, no table)."""
TARGET_THESIS_ROW = "predetermined_target"
TARGET_THESIS_METHOD = "various_model"
"""The thesis ran its predetermined-target trials with the various-size model only."""
TOTAL = "total"


@dataclasses.dataclass(frozen=True)
class Method:
    label: str
    """How its row reads."""
    requires: Mapping[str, Any]
    """Trial-record field -> the value every record of its condition must hold."""


def _risk(model: str, perception: str) -> dict[str, Any]:
    return {"planner": "risk", "model": model, "perception": perception}


METHODS = {
    "same_model": Method("trained with same-size boxes", _risk("ch4_same", "instance")),
    "various_model": Method("trained with various-size boxes", _risk("ch4_various", "instance")),
    "same_model_depth": Method(
        "trained with same-size boxes + depth-only segmentation", _risk("ch4_same", "depth")
    ),
    "various_model_depth": Method(
        "trained with various-size boxes + depth-only segmentation", _risk("ch4_various", "depth")
    ),
    "random": Method("random pair (floor)", {"planner": "random"}),
    "oracle": Method("oracle: every pair simulated (ceiling)", {"planner": "oracle"}),
}
"""Table 4.1 method (the part of a row before '/') -> its label and its trials."""

TARGET_METHODS = {
    "various_model": METHODS["various_model"],
    "same_model": METHODS["same_model"],
    "random": Method("random support (floor)", {"planner": "random"}),
    "oracle": Method("oracle: every support simulated (ceiling)", {"planner": "oracle"}),
}
"""Predetermined-target method -> its label and its trials (the target is fixed; only the
support is chosen)."""

OBJECTS = {
    "same_size_5": {"catalogue": "same"},
    "various_size_5": {"catalogue": "various"},
    "new_various_size_5": {"catalogue": "new"},
    "same_size_10": {"catalogue": "same"},
}
"""Table 4.1 objects (the part of a row after '/') -> what its trial records must hold. The
box count is shown from the records rather than checked (scales may shrink the scenes)."""

CATALOGUE_TEXT = {"same": "same-size", "various": "various-size", "new": "new various-size"}

COLUMNS = [
    Column("objects", "objects", "{}"),
    Column("success", "collapse-free success", "{}"),
    Column("strict_success", "strict success (no other box moved > 5 mm)", "{}"),
    Column("success_held", "no other box off the shelf, judged while the support is held", "{}"),
    Column("mean_n_disturbed", "mean disturbed boxes", "{:.2f}"),
    Column("mean_disturbance_mm", "mean disturbance (mm)", "{:.1f}"),
    Column("invalid", "invalid actions", "{:d}"),
    Column("episodes", "episodes", "{:d}"),
]


@dataclasses.dataclass(frozen=True)
class _Row:
    row: str
    method: str
    objects: str
    label: str
    conditions: tuple[str, ...]
    records: list[dict[str, Any]]
    thesis: Mapping[str, Any]
    """The thesis' row ({} where it has none)."""


def _parse_row(row: str) -> tuple[str, str, str]:
    """'<method>/<objects>[/<sensing>]' -> (method, objects, sensing; ideal where none)."""
    method, objects, sensing = [*row.split("/", 2), IDEAL][:3]
    if method not in METHODS or objects not in OBJECTS or sensing not in (IDEAL, *SENSORS):
        raise ClutterbenchError(
            f"report.{TABLE}.{row}: a row must read '<method>/<objects>[/<sensing>]' with method "
            f"one of {', '.join(METHODS)}, objects one of {', '.join(OBJECTS)} and sensing one of "
            f"{', '.join(SENSORS)} (totals are added)"
        )
    return method, objects, sensing


def _check_sensing(records: Sequence[Mapping[str, Any]], where: str, sensing: str) -> None:
    """Every record saw through `sensing` (a record without the field: the exact depth)."""
    found = sorted({str(r.get("sensing", IDEAL)) for r in records})
    if found != [sensing]:
        raise ClutterbenchError(
            f"{where}: its trials ran sensing {', '.join(found)}, not {sensing}"
        )


def _condition_records(
    records_by_condition: Mapping[str, list[dict[str, Any]]],
    where: str,
    condition: str,
) -> list[dict[str, Any]]:
    if condition not in records_by_condition:
        raise ClutterbenchError(
            f"{where}: no trial records for condition '{condition}'; run the trials_ch4 stage"
        )
    records = records_by_condition[condition]
    if not records:
        raise ClutterbenchError(f"{where}: condition '{condition}' has no records")
    found = sorted({str(r.get("condition")) for r in records})
    if found != [condition]:
        raise ClutterbenchError(
            f"{where}: records of condition '{condition}' say condition {', '.join(found)}"
        )
    return records


def _check(records: Sequence[Mapping[str, Any]], where: str, requires: Mapping[str, Any]) -> None:
    """Every record holds each required value (a condition run with another planner, model,
    perception, mode or box catalogue is not this row's)."""
    for key, want in requires.items():
        found = sorted({str(r.get(key)) for r in records})
        if found != [str(want)]:
            raise ClutterbenchError(f"{where}: its trials ran {key} {', '.join(found)}, not {want}")


def _objects_text(records: Sequence[Mapping[str, Any]], where: str) -> str:
    """'5 same-size', or pooled '5-10 same-size, 5 various-size': box counts per catalogue."""
    counts: dict[str, set[int]] = {}
    for r in records:
        if "n_objects" not in r or r.get("catalogue") not in CATALOGUE_TEXT:
            raise ClutterbenchError(
                f"{where}: trial records need 'n_objects' and a 'catalogue' of "
                f"{', '.join(CATALOGUE_TEXT)}"
            )
        counts.setdefault(r["catalogue"], set()).add(int(r["n_objects"]))
    parts = []
    for catalogue, ns in counts.items():
        lo, hi = min(ns), max(ns)
        parts.append(f"{lo if lo == hi else f'{lo}-{hi}'} {CATALOGUE_TEXT[catalogue]}")
    return ", ".join(parts)


def _thesis_counts(thesis: Mapping[str, Any]) -> dict[str, Any]:
    if not thesis:
        return {}
    return {
        "thesis_success_k": thesis.get("success"),
        "thesis_success_n": thesis.get("trials"),
        "thesis_success_rate": thesis.get("success_rate"),
    }


def _ours(table: str, row: _Row) -> tuple[dict[str, Any], dict[str, Any]]:
    """(our figures keyed as COLUMNS, the raw CSV row) of one table row."""
    where = f"report.{table}.{row.row}"
    objects = _objects_text(row.records, where)
    frame = aggregate([{**r, "row": row.row} for r in row.records], "row")
    a = {k: v for k, v in frame.to_dict("records")[0].items() if k != "row"}
    valid = rate(row.records, "valid")
    ours = {
        "objects": objects,
        "success": rate_text(a, "success"),
        "strict_success": rate_text(a, "strict_success"),
        "success_held": rate_text(a, "success_held"),
        "mean_n_disturbed": a.get("mean_n_disturbed"),
        "mean_disturbance_mm": 1000.0 * a["mean_disturbance_m"]
        if "mean_disturbance_m" in a
        else None,
        "invalid": valid.n - valid.k,
        "episodes": a["episodes"],
    }
    raw = {
        "row": row.row,
        "method": row.method,
        "objects": row.objects,
        "boxes": objects,
        "condition": "+".join(row.conditions),
        **a,
        "invalid": valid.n - valid.k,
        **_thesis_counts(row.thesis),
    }
    return ours, raw


def _write(
    table: str,
    title: str,
    rows: Sequence[_Row],
    out_dir: Path,
    notes: Sequence[str],
) -> pd.DataFrame:
    """<table>.md (ours beside the thesis' success) and <table>.csv (the raw aggregate, with
    the thesis counts beside it). Returns the raw frame."""
    shown, raw = [], []
    for row in rows:
        ours, raw_row = _ours(table, row)
        thesis_text = thesis_rate_text(row.thesis)
        shown.append((row.label, ours, {"success": thesis_text} if thesis_text else {}))
        raw.append(raw_row)
    # A column no row fills (strict success of records without it; invalid actions where
    # every action was valid) is left out.
    columns = [
        c
        for c in COLUMNS
        if any(o.get(c.key) is not None and (c.key != "invalid" or o[c.key]) for _, o, _ in shown)
    ]
    frame = comparison_frame(shown, columns, "method [our condition]")
    invalid_note = (
        ["invalid actions: episodes whose chosen segments did not map to two different boxes."]
        if any(c.key == "invalid" for c in columns)
        else []
    )
    write_table(frame, columns, out_dir, table, title, [*notes, *invalid_note])
    return write_raw_csv(raw, out_dir / f"{table}.csv", ("episodes", "invalid"))


def table_4_1(
    records_by_condition: Mapping[str, list[dict[str, Any]]],
    rows: Mapping[str, str],
    figures: dict[str, Any],
    out_dir: Path,
    scale: str,
    sensed_models: Mapping[str, str] | None = None,
) -> pd.DataFrame:
    """Table 4.1 as reports/tables/table_4_1.md (ours beside the thesis) and .csv (the raw
    aggregate, with the thesis counts beside it). Returns the raw frame; with no rows,
    writes nothing and returns an empty frame.

    rows: '<method>/<objects>' -> trials_ch4 condition. Each method's cells are followed by
    a '<method>/total' row pooling their episodes. sensed_models: a network -> the one a
    sensed row of its method reads instead (trials.ch4_sensed.models)."""
    if not rows:
        return pd.DataFrame()
    if TABLE not in figures:
        raise ClutterbenchError(f"thesis figures: no table '{TABLE}'")
    cells: dict[tuple[str, str], list[_Row]] = {}
    used: dict[str, list[dict[str, Any]]] = {}
    for row, condition in rows.items():
        method, objects, sensing = _parse_row(row)
        where = f"report.{TABLE}.{row}"
        records = _condition_records(records_by_condition, where, condition)
        requires = dict(METHODS[method].requires)
        swapped = sensing != IDEAL and requires.get("model") in (sensed_models or {})
        if swapped:  # the network trained on the sensor's images (trials.ch4_sensed.models)
            requires["model"] = (sensed_models or {})[requires["model"]]
        _check(records, where, {**requires, "mode": "pair"})
        _check(records, where, OBJECTS[objects])
        _check_sensing(records, where, sensing)
        trained = f", network trained on its images ({requires['model']})" if swapped else ""
        label = f"{METHODS[method].label}{sensed_text(sensing)}{trained} [{condition}]"
        thesis = thesis_row(figures, TABLE, row) if sensing == IDEAL else {}
        cells.setdefault((method, sensing), []).append(
            _Row(row, method, objects, label, (condition,), records, thesis)
        )
        used[condition] = records
    table_rows: list[_Row] = []
    for (method, sensing), method_cells in cells.items():
        table_rows += method_cells
        total = f"{method}/{TOTAL}" + (f"/{sensing}" if sensing != IDEAL else "")
        pooled = [r for cell in method_cells for r in cell.records]
        conditions = tuple(c for cell in method_cells for c in cell.conditions)
        n = len(method_cells)
        label = (
            f"{METHODS[method].label}{sensed_text(sensing)}: total of {n} "
            f"cell{'s' if n > 1 else ''}"
        )
        thesis = thesis_row(figures, TABLE, total) if sensing == IDEAL else {}
        table_rows.append(_Row(total, method, TOTAL, label, conditions, pooled, thesis))
    caption = figures[TABLE].get("caption") or TABLE
    return _write(
        TABLE,
        f"Table 4.1 (simulated): {caption}",
        table_rows,
        out_dir,
        _notes(figures, TABLE, used, scale),
    )


def table_4_1_target(
    records_by_condition: Mapping[str, list[dict[str, Any]]],
    rows: Mapping[str, str],
    figures: dict[str, Any],
    out_dir: Path,
    scale: str,
) -> pd.DataFrame:
    """The predetermined-target trials (thesis 4.3.3: the target is fixed, only its support
    is chosen) as reports/tables/table_4_1_target.md and .csv, the thesis' result beside
    the various-size model's row. Returns the raw frame; with no rows, writes nothing and
    returns an empty frame.

    rows: method -> trials_ch4 condition (records of mode 'target')."""
    if not rows:
        return pd.DataFrame()
    table_rows, used = [], {}
    for method, condition in rows.items():
        where = f"report.{TARGET_TABLE}.{method}"
        if method not in TARGET_METHODS:
            raise ClutterbenchError(
                f"{where}: a row must be a method, one of {', '.join(TARGET_METHODS)}"
            )
        records = _condition_records(records_by_condition, where, condition)
        _check(records, where, {**TARGET_METHODS[method].requires, "mode": "target"})
        label = f"{TARGET_METHODS[method].label} [{condition}]"
        thesis = (
            thesis_row(figures, TARGET_FIGURES, TARGET_THESIS_ROW)
            if method == TARGET_THESIS_METHOD
            else {}
        )
        table_rows.append(_Row(method, method, "", label, (condition,), records, thesis))
        used[condition] = records
    notes = [
        *_notes(figures, TARGET_FIGURES, used, scale),
        "predetermined target: the box to extract is fixed per episode and the planner "
        "chooses only its support; the thesis ran it with the various-size model only, the "
        "same target object in every trial.",
    ]
    title = "Predetermined target (simulated; thesis 4.3.3)"
    return _write(TARGET_TABLE, title, table_rows, out_dir, notes)


def _thesis_trials_text(figures: Mapping[str, Any], table: str) -> str:
    """'20 trials per cell' ('20 trials' for a one-row table) as the thesis' rows say
    (totals aside)."""
    cells = [
        int(r["trials"])
        for r in figures[table].get("rows", [])
        if "trials" in r and not str(r.get("row", "")).endswith(f"/{TOTAL}")
    ]
    if not cells:
        return "trials"
    text = f"{'/'.join(str(t) for t in sorted(set(cells)))} trials"
    return f"{text} per cell" if len(cells) > 1 else text


def _notes(
    figures: Mapping[str, Any],
    table: str,
    used: Mapping[str, Sequence[Mapping[str, Any]]],
    scale: str,
) -> list[str]:
    if table not in figures:
        raise ClutterbenchError(f"thesis figures: no table '{table}'")
    source = figures[table].get("source", "the thesis")
    return [
        f"{scale} scale. ours: simulated trials in SAPIEN, one pull per episode, judged from "
        f"physics after the action settled (never from a planner's prediction); thesis: "
        f"{_thesis_trials_text(figures, table)} on a real dual-arm robot ({source}), a "
        "different robot, objects and scenes.",
        "collapse-free success (the thesis' trial notion, so the thesis column stands beside "
        "it): the pulled box came out, no other box left the shelf, and none but the support "
        "dropped more than trials.collapse_free.drop_m or tipped more than "
        "trials.collapse_free.tilt_deg (a slide is disturbance, not a collapse). strict "
        "success: also no box but the pulled and the supporting one moved beyond the label "
        "threshold (5 mm). Both from one run, judged after the support was released and the "
        "scene settled; 'judged while the support is held': before the release. An invalid "
        "action (a segment of no box, or support = pulled box) is never a success. k/n = rate "
        "[Wilson 95% interval]; the thesis' rates as printed; records re-judge under other "
        "thresholds with python -m clutterbench.trials.rejudge.",
        "mean disturbed boxes: other boxes that moved beyond the threshold; mean "
        "disturbance: the summed displacement of the other boxes, per episode.",
        f"trial scenes: {grouped(used, lambda rs: 'stream ' + values_text(rs, 'stream'))}; "
        f"families: {grouped(used, lambda rs: values_text(rs, 'family'))}.",
        f"perception (masks): {grouped(used, lambda rs: values_text(rs, 'perception'))}.",
        *_sensing_notes(used),
        *tie_break_notes(used),
    ]


def _sensing_notes(used: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """Which rows saw through a sensor model (none: no note, as before any was run)."""
    by = sensed_by_preset(used)
    if by is None:
        return []
    return [
        f"sensing (docs/sensing.md): {by}; every other row reads the renderer's exact depth. "
        "A sensed row's planner reads the sensed depth and its masks from depth by region "
        "growing (each segment the box its grasp takes); execution and judging read the world."
    ]


def tie_break_notes(used: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """How often the risk planner's choice was decided by its tie-break (several candidates
    shared the least r_c, eq. 4.1: the least mean P(C) chose among them), and how often that
    least r_c was 0 (no pixel of any candidate's C reached the threshold)."""
    risk = [r for recs in used.values() for r in recs if r.get("planner") == "risk"]
    counted = [r for r in risk if r.get("risk_ties") is not None]
    if not counted:
        return []
    ties = sum(int(r["risk_ties"]) > 1 for r in counted)
    zero = sum(r.get("risk") == 0 for r in counted)
    return [
        f"tie-break: in {ties} of the {len(counted)} risk-planner choices several candidates "
        f"shared the least risk r_c and the least mean P(C) decided; the chosen r_c was 0 in "
        f"{zero}."
    ]
