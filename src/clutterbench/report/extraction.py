"""Table 6.3: extraction success per step and per episode, our simulated trials beside the
thesis' real-robot rows.

Rows are labelled '<method>/<objects>' (the `row:` values of table_6_3 in
reports/thesis_figures.yaml, or rows the thesis lacks such as the oracle and random ones);
each maps to one trials condition. Every rate comes from trials.stats.aggregate. The same
rows split by scene family make table_6_3_families (ours only).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import (
    Column,
    comparison_frame,
    grouped,
    rate_text,
    thesis_rate_text,
    values_text,
    write_raw_csv,
    write_table,
)
from clutterbench.trials.stats import aggregate

if TYPE_CHECKING:
    from clutterbench.trials.config import Ch6TrialParams

TABLE = "table_6_3"
FAMILIES_TABLE = f"{TABLE}_families"

METHODS = {
    "single_step": "single-step extraction (target pulled at once)",
    "multi_step": "multi-step extraction (CPG order, one arm)",
    "bimanual": "multi-step + bimanual hold",
    "oracle": "oracle (ceiling)",
    "random": "random (floor)",
}
"""Planner (the `planner` of a trial record) -> how its row reads."""

COLUMNS = [
    Column("objects", "objects", "{}"),
    Column("step_success", "success per step", "{}"),
    Column("success", "success per episode", "{}"),
    Column("strict_success", "strict success per episode", "{}"),
    Column("mean_steps", "mean steps", "{:.3g}"),
    Column("mean_n_disturbed", "mean disturbed boxes", "{:.2f}"),
    Column("mean_disturbance_mm", "mean disturbance (mm)", "{:.1f}"),
    Column("episodes", "episodes", "{:d}"),
]

FAMILY_COLUMNS = [
    Column("family", "family", "{}"),
    Column("step_success", "success per step", "{}"),
    Column("success", "success per episode", "{}"),
    Column("mean_steps", "mean steps", "{:.3g}"),
    Column("episodes", "episodes", "{:d}"),
]
"""Table 6.3 by scene family: ours only (the thesis has no per-family split)."""

SUCCESS_NOTE = (
    "success per step: the pulled box left the shelf and no other box moved beyond the "
    "threshold, judged from physics after the action settled (never from a planner's "
    "prediction). success per episode: the target left the shelf and every step kept the "
    "others still. k/n = rate [Wilson 95% interval]."
)


def _parse_row(row: str) -> tuple[str, str]:
    method, sep, objects = row.partition("/")
    if not sep or method not in METHODS or not objects:
        raise ClutterbenchError(
            f"report.{TABLE}: row '{row}' must read '<method>/<objects>' with method one of "
            f"{', '.join(METHODS)}"
        )
    return method, objects


def _thesis_rows(figures: Mapping[str, Any], method: str, objects: str) -> list[dict[str, Any]]:
    """The thesis' rows of this method and object count: its per-step rate (Table 6.3) and
    its per-episode rate and mean steps (the single-arm text)."""
    if TABLE not in figures:
        raise ClutterbenchError(f"thesis figures: no table '{TABLE}'")
    found = []
    for r in figures[TABLE].get("rows", []):
        if r.get("method") == method and str(r.get("n_objects")) == objects:
            if r.get("rate_unit") not in ("per_step", "per_target"):
                raise ClutterbenchError(
                    f"thesis figures: {TABLE} row {r.get('row')}: rate_unit must be per_step "
                    f"or per_target, not {r.get('rate_unit')!r}"
                )
            found.append(r)
    return found


def thesis_figures_for(figures: Mapping[str, Any], method: str, objects: str) -> dict[str, Any]:
    """The thesis column's values for one row, keyed as COLUMNS ({} where it has none)."""
    out: dict[str, Any] = {}
    for r in _thesis_rows(figures, method, objects):
        out["objects"] = str(r["n_objects"])
        if r["rate_unit"] == "per_step":
            out["step_success"] = thesis_rate_text(r)
        else:
            out["success"] = thesis_rate_text(r)
            if "mean_steps" in r:
                out["mean_steps"] = r["mean_steps"]
    return out


def _thesis_counts(figures: Mapping[str, Any], method: str, objects: str) -> dict[str, Any]:
    """The thesis' raw counts for the CSV: thesis_step_success_k/n/rate, thesis_success_k/n/
    rate (per episode) and thesis_mean_steps, where it has them."""
    out: dict[str, Any] = {}
    for r in _thesis_rows(figures, method, objects):
        prefix = "thesis_step_success" if r["rate_unit"] == "per_step" else "thesis_success"
        out |= {
            f"{prefix}_k": r.get("success"),
            f"{prefix}_n": r.get("trials"),
            f"{prefix}_rate": r.get("success_rate"),
        }
        if "mean_steps" in r:
            out["thesis_mean_steps"] = r["mean_steps"]
    return out


def _objects_text(records: Sequence[Mapping[str, Any]], row: str) -> str:
    """'3-10': the range of object counts in the trial scenes."""
    if any("n_objects" not in r for r in records):
        raise ClutterbenchError(f"report.{TABLE}.{row}: trial records lack 'n_objects'")
    counts = sorted({int(r["n_objects"]) for r in records})
    return f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"


def _condition_records(
    records_by_condition: Mapping[str, list[dict[str, Any]]], row: str, condition: str
) -> list[dict[str, Any]]:
    if condition not in records_by_condition:
        raise ClutterbenchError(
            f"report.{TABLE}.{row}: no trial records for condition '{condition}'; "
            f"run trials@{condition}"
        )
    records = records_by_condition[condition]
    if not records:
        raise ClutterbenchError(f"report.{TABLE}.{row}: condition '{condition}' has no records")
    return records


def _check_planner(records: Sequence[Mapping[str, Any]], row: str, method: str) -> None:
    planners = sorted({str(r.get("planner")) for r in records})
    if planners != [method]:
        raise ClutterbenchError(
            f"report.{TABLE}.{row}: its trials ran planner {', '.join(planners)}, not {method}"
        )


def extraction_table(
    records_by_condition: Mapping[str, list[dict[str, Any]]],
    rows: Mapping[str, str],
    figures: dict[str, Any],
    out_dir: Path,
    scale: str,
    notes_extra: Sequence[str] = (),
) -> pd.DataFrame:
    """Table 6.3 as reports/tables/table_6_3.md (ours beside the thesis) and .csv (the raw
    aggregate, with the thesis counts beside it). Returns the raw frame.

    rows: '<method>/<objects>' -> trials condition."""
    shown, raw, used = [], [], {}
    for row, condition in rows.items():
        method, objects = _parse_row(row)
        records = _condition_records(records_by_condition, row, condition)
        _check_planner(records, row, method)
        agg = aggregate(records, "condition").to_dict("records")
        if len(agg) != 1 or agg[0]["condition"] != condition:
            found = ", ".join(str(a["condition"]) for a in agg)
            raise ClutterbenchError(
                f"report.{TABLE}.{row}: records of condition '{condition}' say condition {found}"
            )
        a = agg[0]
        ours = {
            "objects": _objects_text(records, row),
            "step_success": rate_text(a, "step_success"),
            "success": rate_text(a, "success"),
            "strict_success": rate_text(a, "strict_success"),
            "mean_steps": a.get("mean_steps"),
            "mean_n_disturbed": a.get("mean_n_disturbed"),
            "mean_disturbance_mm": 1000.0 * a["mean_disturbance_m"]
            if "mean_disturbance_m" in a
            else None,
            "episodes": a["episodes"],
        }
        thesis = thesis_figures_for(figures, method, objects)
        shown.append((f"{METHODS[method]} [{condition}]", ours, thesis))
        raw.append({"row": row, "method": method, **a, **_thesis_counts(figures, method, objects)})
        used[condition] = records
    # A column no row fills (strict success, steps of single-action trials) is left out.
    columns = [
        c for c in COLUMNS if any(o.get(c.key) is not None or c.key in t for _, o, t in shown)
    ]
    frame = comparison_frame(shown, columns, "method [our condition]")
    caption = figures[TABLE].get("caption", TABLE)
    notes = [*_notes(figures, used, scale), *notes_extra]
    write_table(frame, columns, out_dir, TABLE, f"Table 6.3: {caption}", notes)
    return write_raw_csv(raw, out_dir / f"{TABLE}.csv")


def extraction_families_table(
    records_by_condition: Mapping[str, list[dict[str, Any]]],
    rows: Mapping[str, str],
    out_dir: Path,
    scale: str,
    notes_extra: Sequence[str] = (),
) -> pd.DataFrame:
    """Table 6.3 by scene family as reports/tables/table_6_3_families.md (one row per table
    row and family, families sorted; ours only: the thesis has no per-family split) and
    .csv (the raw aggregate per family). Returns the raw frame.

    rows: '<method>/<objects>' -> trials condition, as for extraction_table."""
    shown, raw, used = [], [], {}
    for row, condition in rows.items():
        method, _ = _parse_row(row)
        records = _condition_records(records_by_condition, row, condition)
        _check_planner(records, row, method)
        label = f"{METHODS[method]} [{condition}]"
        by_family = aggregate(records, "family").to_dict("records")
        for a in sorted(by_family, key=lambda a: str(a["family"])):
            ours = {
                "family": a["family"],
                "step_success": rate_text(a, "step_success"),
                "success": rate_text(a, "success"),
                "mean_steps": a.get("mean_steps"),
                "episodes": a["episodes"],
            }
            shown.append((label, ours, {}))
            raw.append({"row": row, "method": method, "condition": condition, **a})
        used[condition] = records
    # A column no row fills (steps of records without them) is left out.
    columns = [c for c in FAMILY_COLUMNS if any(o.get(c.key) is not None for _, o, _ in shown)]
    frame = comparison_frame(shown, columns, "method [our condition]")
    notes = [
        f"{scale} scale. ours: simulated trials in SAPIEN, one episode per scene, split by the "
        "family of the scene; the thesis reports no per-family split.",
        SUCCESS_NOTE,
        f"trial scenes: {grouped(used, lambda rs: 'stream ' + values_text(rs, 'stream'))}.",
        *notes_extra,
    ]
    title = "Table 6.3 by scene family: extraction success per step and per episode"
    write_table(frame, columns, out_dir, FAMILIES_TABLE, title, notes)
    return write_raw_csv(raw, out_dir / f"{FAMILIES_TABLE}.csv")


def _mm(metres: float) -> str:
    return f"{1000.0 * metres:.1f} mm"


def trial_params_note(ch6: Ch6TrialParams) -> str:
    """The ch. 6 trial params that judge and execute an extraction, in words (a table
    note): the moved threshold, the grasp lift, the pull increment and the attempt cap."""
    lift = (
        f"the gripper raises the grasped box by {_mm(ch6.grasp_lift_m)} before pulling it out"
        if ch6.grasp_lift_m > 0
        else "the gripper pulls the grasped box out without raising it"
    )
    attempts = f"{ch6.max_steps} attempt{'s' if ch6.max_steps != 1 else ''}"
    return (
        f"a box moved: its centre moved more than {_mm(ch6.moved_threshold_m)}; {lift} in "
        f"{_mm(ch6.pull_increment_m)} increments; an episode gives up after {attempts}."
    )


def _no_safe_pull(records: Sequence[Mapping[str, Any]]) -> tuple[int, int, int, int]:
    """(episodes whose start had no safe pull, episodes, steps with none, steps) over the
    steps that say how many visible boxes could be pulled without moving another."""
    counted = [[s["safe_pulls"] for s in r["steps"] if "safe_pulls" in s] for r in records]
    counted = [c for c in counted if c]
    return (
        sum(c[0] == 0 for c in counted),
        len(counted),
        sum(n == 0 for c in counted for n in c),
        sum(len(c) for c in counted),
    )


def safe_pull_notes(used: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """For each condition whose steps count the safe pulls (the oracle simulates every
    visible box's pull): how often none was safe, and the bound that puts on every single-arm
    planner run on the same scenes."""
    notes = []
    for condition, records in used.items():
        starts, episodes, none, steps = _no_safe_pull(records)
        if not episodes:
            continue
        stream = values_text(records, "stream")
        families = sorted({str(r["family"]) for r in records})
        by_family = ", ".join(
            "{} {}/{}".format(f, *_no_safe_pull([r for r in records if r["family"] == f])[:2])
            for f in families
        )
        notes.append(
            f"no safe pull [{condition}]: at {starts}/{episodes} episode starts every visible box "
            f"moved another box when pulled (each pull simulated; {by_family}), so on stream "
            f"{stream} no single-arm planner can succeed in more than "
            f"{100.0 * (episodes - starts) / episodes:.1f}% of the episodes; at {none} of the "
            f"{steps} {condition} steps no visible box was safe to pull."
        )
    return notes


def _notes(
    figures: Mapping[str, Any], used: Mapping[str, Sequence[Mapping[str, Any]]], scale: str
) -> list[str]:
    source = figures[TABLE].get("source", "the thesis")
    return [
        f"{scale} scale. ours: simulated trials in SAPIEN, one episode per scene; thesis: "
        f"real-robot numbers ({source}), a different robot, objects and scenes.",
        SUCCESS_NOTE,
        "thesis per-step rates: Table 6.3; thesis per-episode rate and mean steps: the "
        "single-arm experiments in the text, beside our row of the same method and objects.",
        "mean disturbed boxes: boxes not extracted that moved beyond the threshold between the "
        "start and the end of the episode; mean disturbance: the summed displacement of the "
        "boxes not extracted (SafePicking's translation metric), per episode.",
        f"trial scenes: {grouped(used, lambda rs: 'stream ' + values_text(rs, 'stream'))}; "
        f"families: {grouped(used, lambda rs: values_text(rs, 'family'))}.",
        f"perception (masks): {grouped(used, lambda rs: values_text(rs, 'perception'))}.",
        *safe_pull_notes(used),
    ]
