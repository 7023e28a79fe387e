"""Table 6.3: extraction success per step and per episode, our simulated trials beside the
thesis' real-robot rows.

Rows are labelled '<method>/<objects>' (the `row:` values of table_6_3 in
reports/thesis_figures.yaml, or rows the thesis lacks such as the oracle and random ones);
each maps to one trials condition. Every rate comes from trials.stats.aggregate. The same
rows split by scene family make table_6_3_families (ours only).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.report.table_6_3_noise import noise_text
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
from clutterbench.trials.ch6 import planners
from clutterbench.trials.condition_sets import NOT_RUN
from clutterbench.trials.core.stats import aggregate

if TYPE_CHECKING:
    from clutterbench.trials.ch6_groups import PullExecution

TABLE = "table_6_3"
FAMILIES_TABLE = f"{TABLE}_families"


def row_label(planner: str) -> str:
    """How a planner's row reads: its declared label (trials/ch6/planners), else its name."""
    return planners.declared(planner).row_label


def ceiling(planner: str) -> str:
    """The search oracle a planner is measured against: the holding search for planners that
    hold a box, the one-arm search for every other (its declaration; a planner no module
    declares: the one-arm search)."""
    return planners.declared(planner).ceiling


def is_oracle(planner: str) -> bool:
    return planners.declared(planner).role == "oracle"


COLUMNS = [
    Column("objects", "objects", "{}"),
    Column("seen", "depth image, object masks", "{}"),
    Column("step_success", "collapse-free success per step", "{}"),
    Column("success", "collapse-free success per episode", "{}"),
    Column("task_noise", "collapse-free in perturbed worlds: mean ± sd (successes kept)", "{}"),
    Column("step_strict_success", "strict success per step", "{}"),
    Column("strict_success", "strict success per episode", "{}"),
    Column("below_oracle", "points below its oracle (collapse-free)", "{}"),
    Column("below_oracle_strict", "points below its oracle (strict)", "{}"),
    Column("success_held", "per episode, strict, judged while held", "{}"),
    Column("aborts", "aborts without a collapse (of them: before any motion / moved a box)", "{}"),
    Column("mean_steps", "mean steps", "{:.3g}"),
    Column("mean_n_disturbed", "mean disturbed boxes", "{:.2f}"),
    Column("mean_disturbance_mm", "mean disturbance (mm)", "{:.1f}"),
    Column("episodes", "episodes", "{:d}"),
]

FAMILY_COLUMNS = [
    Column("family", "family", "{}"),
    Column("step_success", "collapse-free success per step", "{}"),
    Column("success", "collapse-free success per episode", "{}"),
    Column("strict_success", "strict success per episode", "{}"),
    Column("mean_steps", "mean steps", "{:.3g}"),
    Column("episodes", "episodes", "{:d}"),
]
"""Table 6.3 by scene family: ours only (the thesis has no per-family split)."""

SUCCESS_NOTE = (
    "protocol: every step starts from a fresh world at the state the last one left; the pulled "
    "box leaves the shelf (or, aborted, is let go), every held box is released and the scene "
    "settles, then the step is judged from physics (never from a planner's prediction). Two "
    "criteria from one run: a step is collapse-free when its box left the shelf and no other "
    "box left the shelf, dropped more than trials.collapse_free.drop_m or tipped more than "
    "trials.collapse_free.tilt_deg (a horizontal slide is disturbance, not a collapse); strict "
    "when, in addition, no box other than the manipulated ones (pulled, held) moved beyond the "
    "label threshold (the released box may settle lower but must stay on the shelf). An "
    "episode ends at its first collapse-free failure, when the target is out (success), when "
    "the target fell, or when the planner gives up; the planner does not know the criterion, "
    "so the strict episode is its prefix up to the first strict failure, and strict per-step "
    "counts stop there. The thesis column stands beside the collapse-free one: the thesis "
    "judged its real-robot trials by whether objects collapsed or fell, not by millimetres. "
    "Every executed step is judged, aborted or not. success per step: over the counted steps "
    "(executed pulls that took their box out or disturbed the pile under that criterion; the "
    "records' counted / strict_counted); aborts without a collapse are counted apart: "
    "before any motion, or after it (an abort that moved another box beyond the label "
    "threshold is a strict failure, counted in the strict columns). "
    "Intervals: per episode, Wilson 95%; per step, a 95% cluster bootstrap over episodes "
    "(2,000 resamples, seed 0), since the steps of one episode are not independent. judged "
    "while held: the strict judgement before the release, where that differs. Every record "
    "can be re-judged under other thresholds: python -m clutterbench.trials.rejudge."
)


def step_rate_text(agg: Mapping[str, Any], key: str = "success") -> str | None:
    """'k/n = x% [lo, hi]' of the per-step columns of `key`, the interval from the cluster
    bootstrap."""
    p = f"step_{key}"
    if f"{p}_k" not in agg or pd.isna(agg[f"{p}_k"]):
        return None
    k, n = int(agg[f"{p}_k"]), int(agg[f"{p}_n"])
    if n == 0:
        return "—"
    lo, hi = 100 * agg[f"{p}_lo"], 100 * agg[f"{p}_hi"]
    return f"{k}/{n} = {100 * k / n:.1f}% [{lo:.1f}, {hi:.1f}]"


def oracle_gaps(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]], key: str = "success"
) -> dict[str, dict[str, Any]]:
    """For every condition: its matching oracle's condition on the same stream (if one ran),
    the points its per-episode success under `key` lies below it, and the episodes it
    succeeded in where the oracle failed (impossible unless the oracle's search budget ran
    out or the planner left the oracle's action set)."""
    oracles: dict[tuple[str, str], str] = {}
    for cond, recs in records_by_condition.items():
        planner, stream = str(recs[0].get("planner")), str(recs[0].get("stream"))
        if is_oracle(planner):
            oracles[(planner, stream)] = cond
    out: dict[str, dict[str, Any]] = {}
    for cond, recs in records_by_condition.items():
        planner, stream = str(recs[0].get("planner")), str(recs[0].get("stream"))
        oracle = oracles.get((ceiling(planner), stream))
        if oracle is None:
            continue
        if any(key not in r for r in [*recs, *records_by_condition[oracle]]):
            continue
        theirs = {int(r["episode"]): bool(r[key]) for r in records_by_condition[oracle]}
        ours = {int(r["episode"]): bool(r[key]) for r in recs}
        shared = sorted(set(ours) & set(theirs))
        if not shared:
            continue
        gap = 100.0 * (sum(theirs[e] for e in shared) - sum(ours[e] for e in shared)) / len(shared)
        beat = [e for e in shared if ours[e] and not theirs[e]]
        by_episode = {int(r["episode"]): r for r in recs}
        partial = [e for e in beat if moved_by_a_partial_pull(by_episode[e])]
        held = [e for e in beat if held_during_another_pull(by_episode[e])]
        out[cond] = {
            "oracle": oracle,
            "points": gap,
            "beat": beat,
            "beat_partial": partial,
            "beat_held_aside": held,
            "episodes": len(shared),
        }
    return out


def moved_by_a_partial_pull(record: Mapping[str, Any]) -> bool:
    """Whether an episode has a pull that stopped after motion and moved another box: an
    action outside the search oracles' set (they simulate whole pulls)."""
    return any(
        s.get("aborted_after_motion") and int(s.get("n_disturbed", 0)) > 0
        for s in record.get("steps", [])
    )


def held_during_another_pull(record: Mapping[str, Any]) -> bool:
    """Whether an episode held a box while pulling one other than the target (a bimanual
    pull planner's idle arm): an action outside the search oracles' set (oracle_hold holds a
    box only while pulling the target)."""
    target = record.get("target")
    return any(
        s.get("hold") is not None and s.get("box") != target for s in record.get("steps", [])
    )


def _gap_text(gap: Mapping[str, Any] | None, condition: str) -> str | None:
    if gap is None or gap["oracle"] == condition:
        return None
    partial = len(gap.get("beat_partial", []))
    held = len(gap.get("beat_held_aside", []))
    through = f", {partial} through a partial pull" if partial else ""
    through += f", {held} holding a box during another box's pull" if held else ""
    return f"{gap['points']:.1f} ({gap['oracle']}; beat it in {len(gap['beat'])}{through})"


def _parse_row(row: str) -> tuple[str, str]:
    """'<method>/<objects>' or '<method>/<objects>/<tag>' (a second row of one method and
    object count, e.g. under a sensor) -> (method, objects)."""
    method, sep, rest = row.partition("/")
    objects = rest.partition("/")[0]
    if not sep or not method or not objects:
        raise ClutterbenchError(
            f"report.{TABLE}: row '{row}' must read '<method>/<objects>[/<tag>]' with method a "
            f"planner name (built in: {', '.join(planners.BUILT_IN)})"
        )
    return method, objects


IDEAL_SEEN = ("ideal", "instance")
"""What a record without `sensing` saw: the renderer's exact depth, the simulator's masks."""


def seen_of(records: Sequence[Mapping[str, Any]]) -> tuple[str, str]:
    """(sensing, perception) of a condition's records (trials/ch6/seeing.py)."""
    seen = {(str(r.get("sensing", "ideal")), str(r.get("perception", "instance"))) for r in records}
    if len(seen) != 1:
        raise ClutterbenchError(f"report.{TABLE}: one condition's records saw {sorted(seen)}")
    return seen.pop()


def seen_text(seen: tuple[str, str]) -> str:
    sensing, perception = seen
    masks = "simulator's masks" if perception == "instance" else "masks from depth"
    return f"{'exact depth' if sensing == 'ideal' else sensing}, {masks}"


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
            f"run the trials stage"
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
    noise: Mapping[str, Any] | None = None,
    not_run: Collection[str] = (),
) -> pd.DataFrame:
    """Table 6.3 as reports/tables/table_6_3.md (ours beside the thesis) and .csv (the raw
    aggregate, with the thesis counts beside it). Returns the raw frame.

    rows: '<method>/<objects>' -> trials condition. noise: the noise stage's summary per
    condition (its task-noise column; None: no such column). not_run: the opt-in conditions
    the run left out (trials.opt_in): their rows say NOT_RUN, and the CSV has none."""
    shown, raw, used = [], [], {}
    by_row = {
        c: _condition_records(records_by_condition, r, c)
        for r, c in rows.items()
        if c not in not_run
    }
    # the depth and masks column, once any row saw other than exact depth and the sim's masks
    any_seen = any(seen_of(recs) != IDEAL_SEEN for recs in by_row.values())
    gaps = oracle_gaps(by_row)
    strict_gaps = oracle_gaps(by_row, "strict_success")
    for row, condition in rows.items():
        method, objects = _parse_row(row)
        thesis = thesis_figures_for(figures, method, objects)
        label = f"{row_label(method)} [{condition}]"
        if condition in not_run:
            shown.append(
                (label, {"objects": objects, "success": NOT_RUN, "strict_success": NOT_RUN}, thesis)
            )
            continue
        records = by_row[condition]
        _check_planner(records, row, method)
        a = _aggregate_row(records, row, condition)
        ours = _cells(records, a, row, any_seen) | {
            "task_noise": noise_text(noise[condition]["success"])
            if noise and condition in noise
            else None,
            "below_oracle": _gap_text(gaps.get(condition), condition),
            "below_oracle_strict": _gap_text(strict_gaps.get(condition), condition),
        }
        shown.append((label, ours, thesis))
        extra = _raw_extra(gaps.get(condition), strict_gaps.get(condition), noise, condition)
        if any_seen:
            extra |= dict(zip(("sensing", "perception"), seen_of(records)))
        raw.append(
            {"row": row, "method": method, **a, **extra, **_thesis_counts(figures, method, objects)}
        )
        used[condition] = records
    # A column no row fills (strict success, steps of single-action trials) is left out.
    columns = [
        c for c in COLUMNS if any(o.get(c.key) is not None or c.key in t for _, o, t in shown)
    ]
    frame = comparison_frame(shown, columns, "method [our condition]")
    caption = figures[TABLE].get("caption", TABLE)
    notes = [*_notes(figures, used, scale), *not_run_note(rows, not_run), *notes_extra]
    title = (
        "Table 6.3 (simulated): extraction performance of different approaches and "
        f"conditions (the thesis' table: {caption})"
    )
    write_table(frame, columns, out_dir, TABLE, title, notes)
    return write_raw_csv(raw, out_dir / f"{TABLE}.csv")


def _aggregate_row(records: list[dict[str, Any]], row: str, condition: str) -> dict[str, Any]:
    """The aggregate of one row's records, which must all be of its condition."""
    agg = aggregate(records, "condition").to_dict("records")
    if len(agg) != 1 or agg[0]["condition"] != condition:
        found = ", ".join(str(a["condition"]) for a in agg)
        raise ClutterbenchError(
            f"report.{TABLE}.{row}: records of condition '{condition}' say condition {found}"
        )
    return agg[0]


def _cells(
    records: Sequence[Mapping[str, Any]], a: Mapping[str, Any], row: str, any_seen: bool
) -> dict[str, Any]:
    """A row's cells of COLUMNS from its own records and aggregate `a` (not the task noise
    and the oracle gaps, which need other rows)."""
    return {
        "objects": _objects_text(records, row),
        "seen": seen_text(seen_of(records)) if any_seen else None,
        "step_success": step_rate_text(a),
        "success": rate_text(a, "success"),
        "step_strict_success": step_rate_text(a, "strict_success"),
        "strict_success": rate_text(a, "strict_success"),
        "success_held": rate_text(a, "success_held"),
        "aborts": aborts_text(a),
        "mean_steps": a.get("mean_steps"),
        "mean_n_disturbed": a.get("mean_n_disturbed"),
        "mean_disturbance_mm": 1000.0 * a["mean_disturbance_m"]
        if "mean_disturbance_m" in a
        else None,
        "episodes": a["episodes"],
    }


def not_run_note(rows: Mapping[str, str], not_run: Collection[str]) -> list[str]:
    """The note naming the rows of `rows` (row -> condition) whose condition the run left out
    (opt-in, trials.opt_in), if any."""
    left_out = [f"{row} [{c}]" for row, c in rows.items() if c in not_run]
    if not left_out:
        return []
    return [
        f"{NOT_RUN}: {', '.join(left_out)}. Opt-in conditions (trials.opt_in) that a run leaves "
        "out unless switched on: make repro-full (dvc exp run -S trials.opt_in.run=true) runs "
        "them; docs/run-times.md states their cost."
    ]


def _raw_extra(
    gap: Mapping[str, Any] | None,
    strict_gap: Mapping[str, Any] | None,
    noise: Mapping[str, Any] | None,
    condition: str,
) -> dict[str, Any]:
    """A row's raw CSV columns beyond its aggregate: its oracle gaps and its task noise."""
    extra: dict[str, Any] = {}
    if gap is not None:
        extra = {
            "oracle": gap["oracle"],
            "points_below_oracle": gap["points"],
            "beat_oracle": len(gap["beat"]),
        }
    if strict_gap is not None:
        extra |= {
            "points_below_oracle_strict": strict_gap["points"],
            "beat_oracle_strict": len(strict_gap["beat"]),
        }
    if noise and condition in noise:
        n = noise[condition]["success"]
        extra |= {f"noise_{k}": n[k] for k in ("draws", "mean_rate", "sd_rate", "survive")}
    return extra


def extraction_families_table(
    records_by_condition: Mapping[str, list[dict[str, Any]]],
    rows: Mapping[str, str],
    out_dir: Path,
    scale: str,
    notes_extra: Sequence[str] = (),
    not_run: Collection[str] = (),
) -> pd.DataFrame:
    """Table 6.3 by scene family as reports/tables/table_6_3_families.md (one row per table
    row and family, families sorted; ours only: the thesis has no per-family split) and
    .csv (the raw aggregate per family). Returns the raw frame.

    rows: '<method>/<objects>' -> trials condition, as for extraction_table; not_run: the
    opt-in conditions the run left out, whose rows a note names instead."""
    shown, raw, used = [], [], {}
    for row, condition in rows.items():
        if condition in not_run:
            continue
        method, _ = _parse_row(row)
        records = _condition_records(records_by_condition, row, condition)
        _check_planner(records, row, method)
        label = f"{row_label(method)} [{condition}]"
        by_family = aggregate(records, "family").to_dict("records")
        for a in sorted(by_family, key=lambda a: str(a["family"])):
            ours = {
                "family": a["family"],
                "step_success": step_rate_text(a),
                "success": rate_text(a, "success"),
                "strict_success": rate_text(a, "strict_success"),
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
        *not_run_note(rows, not_run),
        *notes_extra,
    ]
    title = "Table 6.3 by scene family: extraction success per step and per episode"
    write_table(frame, columns, out_dir, FAMILIES_TABLE, title, notes)
    return write_raw_csv(raw, out_dir / f"{FAMILIES_TABLE}.csv")


def _mm(metres: float) -> str:
    return f"{1000.0 * metres:.1f} mm"


def trial_params_note(pull: PullExecution, max_steps: int) -> str:
    """The ch. 6 trial params that judge and execute an extraction, in words (a table
    note): the moved threshold, the grasp lift, the pull increment (trials.ch6's `pull`)
    and the attempt cap (trials.ch6.max_steps)."""
    lift = (
        f"the gripper raises the grasped box by {_mm(pull.grasp_lift_m)} before pulling it out"
        if pull.grasp_lift_m > 0
        else "the gripper pulls the grasped box out without raising it"
    )
    attempts = f"{max_steps} attempt{'s' if max_steps != 1 else ''}"
    return (
        f"a box moved: its centre moved more than {_mm(pull.moved_threshold_m)}; {lift} in "
        f"{_mm(pull.increment_m)} increments; an episode gives up after {attempts}."
    )


def rule_note(
    used: Mapping[str, Sequence[Mapping[str, Any]]],
    chosen: Mapping[str, Mapping[str, Any]],
    labels: Mapping[str, str],
) -> list[str]:
    """The support rule the CP planners ran with (their records' `rule`), its Table 6.2 row
    and the thresholds the support stage chose for it on validation scenes."""
    from clutterbench.report.table_6_2 import thresholds_text

    methods = sorted(
        {
            r.get("support_method") or _support_method(str(r.get("planner")), str(r["rule"]))
            for recs in used.values()
            for r in recs
            if r.get("rule")
        }
    )
    if not methods:
        return []
    parts = [
        f"{m} (Table 6.2 row '{labels.get(m, m)}'; {thresholds_text(chosen.get(m))})"
        for m in methods
    ]
    return [
        "support rule of the CP planners (multi-step, bimanual), thresholds chosen on "
        f"validation scenes: {'; '.join(parts)}"
        + (
            "; pull_<rule> / pull_collapse_<rule>: the same rule on the CP's pull head (maps of "
            "every box the pull moves) / pull_collapse head (of what it collapses), its "
            "thresholds chosen against that head's pull truth (the *_pull planners)."
            if any(m.startswith("pull_") for m in methods)
            else "."
        )
    ]


def search_notes(used: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """For each search oracle condition: how often its search ran out of node budget (then
    a planner may beat it) or had to search again because the world left the simulated path."""
    notes = []
    for condition, records in used.items():
        if not records or "search_nodes" not in records[0]:
            continue
        if "estimate_settle_mm" in records[0]:  # physics from depth: a search per decision
            decisions = sum(len(r["estimate_settle_mm"]) for r in records)
            notes.append(
                f"physics from depth [{condition}]: node budget exhausted in "
                f"{sum(int(r['search_exhausted']) > 0 for r in records)}/{len(records)} "
                f"episodes; {sum(int(r['search_nodes']) for r in records)} states of estimated "
                f"scenes expanded over {decisions} decisions; the estimated scene was not at "
                f"rest after settling in {sum(int(r['estimate_not_at_rest']) for r in records)}."
            )
            continue
        exhausted = sum(int(r["search_exhausted"]) > 0 for r in records)
        replanned = sum(int(r["search_replanned"]) > 0 for r in records)
        nodes = [int(r["search_nodes"]) for r in records]
        notes.append(
            f"search [{condition}]: node budget exhausted in {exhausted}/{len(records)} "
            f"episodes, path left in {replanned}; {sum(nodes)} states expanded "
            f"(max {max(nodes)} in one episode)."
        )
    return notes


def _notes(
    figures: Mapping[str, Any], used: Mapping[str, Sequence[Mapping[str, Any]]], scale: str
) -> list[str]:
    source = figures[TABLE].get("source", "the thesis")
    return [
        f"{scale} scale. ours: simulated trials in SAPIEN, one episode per scene; thesis: "
        f"real-robot numbers ({source}), a different robot, objects and scenes. The thesis' "
        "single-step rows are its previous method (ch. 4, extract while supporting; their counts "
        "equal Table 4.1's various-size cells): our single-step rows run that planner with the "
        "ch. 4 network; the naive pull is its own row.",
        SUCCESS_NOTE,
        "thesis per-step rates: Table 6.3; thesis per-episode rate and mean steps: the "
        "single-arm experiments in the text, beside our row of the same method and objects.",
        "mean disturbed boxes: boxes not extracted that moved beyond the threshold between the "
        "start and the end of the episode; mean disturbance: the summed displacement of the "
        "boxes not extracted (SafePicking's translation metric), per episode.",
        f"trial scenes: {grouped(used, lambda rs: 'stream ' + values_text(rs, 'stream'))}; "
        f"families: {grouped(used, lambda rs: values_text(rs, 'family'))}.",
        f"perception (masks): {grouped(used, lambda rs: values_text(rs, 'perception'))}.",
        "points below its oracle: the matching search oracle's per-episode success on the same "
        "scenes and targets (oracle_hold for planners that hold a box, oracle otherwise) minus "
        "the row's, in points; 'beat it in': episodes the row succeeded in and its oracle did "
        "not; 'through a partial pull': of those, episodes with a pull stopped after motion "
        "that moved another box, an action outside the oracle's set (it simulates whole pulls); "
        "'holding a box during another box's pull': of those, episodes where the second arm "
        "held a box while a box other than the target was pulled (the bimanual pull planners' "
        "idle hold; oracle_hold may hold during any pull, oracle never holds). The search is "
        "complete up to its node budget: it tells states apart by the boxes out and where the "
        "rest stand (to float noise) and tries every clean action, every hold included; where "
        "its budget ran out (counted below) it is no ceiling, and there the points below it "
        "are a lower bound.",
        *search_notes(used),
    ]


def aborts_text(a: Mapping[str, Any]) -> str | None:
    """'142 (0 / 106)': aborts without a collapse (before any motion / moved another box
    beyond the label threshold), or just the count for records without the split."""
    if pd.isna(a.get("aborts", pd.NA)):
        return None
    text = str(int(a["aborts"]))
    if pd.isna(a.get("aborts_moved", pd.NA)) or pd.isna(a.get("aborts_before_motion", pd.NA)):
        return text
    return f"{text} ({int(a['aborts_before_motion'])} / {int(a['aborts_moved'])})"


def _support_method(planner: str, rule: str) -> str:
    """The support method of a record written before records named theirs."""
    return planners.declared(planner).support_method(rule)
