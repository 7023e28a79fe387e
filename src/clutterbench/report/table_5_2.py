"""Table 5.2: shelf replenishment success per scene type, our simulated trials beside the
thesis' real-robot rows, and the failures broken down by the planner's branch.

Rows are labelled '<method>/<scene type>' (report.table_5_2 in params.yaml), or
'<method>/<scene type>/<sensing>' for a condition run again under a depth sensor
(trials.ch5_sensed, docs/sensing.md: a method row of its own, never a thesis row); each maps
to one trials_ch5 condition, and every method gets a total over its scene types. Rates are
k/n with Wilson 95% intervals (trials.stats). The oracle simulates every candidate action, so
a method succeeding where the oracle failed on the same scene is counted (it should not
happen).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import (
    IDEAL,
    SENSORS,
    sensed_by_preset,
    sensed_text,
    thesis_row,
    write_raw_csv,
    write_table,
)
from clutterbench.trials.core.stats import Rate, rate

TABLE = "table_5_2"
BRANCH_TABLE = f"{TABLE}_branches"
SCENES = ("stacked", "shelved", "random")
METHODS = {
    "replenish": "with collapse prediction",
    "no_collapse": "without collapse prediction",
    "replenish_gt": "with collapse prediction, ground-truth clusters",
    "contact": "with collapse prediction, pushing where it has no plan (beyond the thesis)",
    "random": "random action (floor)",
    "oracle": "oracle: every candidate action simulated (ceiling)",
    "oracle_no_contact": "oracle over the actions that move no box into another (the thesis "
    "planners' ceiling)",
}
NOTE = (
    "protocol: every step starts from a fresh world at the present state; a blocker is carried "
    "aside and held (bimanual) or let go (rearrangement), the new box is let go at the "
    "candidate, every held box is released and the scene settles, then the step is judged from "
    "physics. Success: the new box rests inside the shelf within place_tol_m of its planned "
    "place, no box left the shelf (a moved box must stay on it) and no box other than the "
    "moved ones collapsed (collapse-free) or, strict, also moved beyond the threshold; an "
    "episode ends at its first collapse-free failure, when the box is placed, or when the "
    "planner has no plan (gave up, a failure). Intervals: Wilson 95%."
)


def _parse(row: str) -> tuple[str, str, str]:
    """'<method>/<scene type>[/<sensing>]' -> (method, scene type, sensing; ideal where none)."""
    method, _, rest = row.partition("/")
    scene, _, sensing = rest.partition("/")
    if (
        not scene
        or method not in METHODS
        or scene not in SCENES
        or (sensing and sensing not in SENSORS)
    ):
        raise ClutterbenchError(
            f"report.table_5_2: row '{row}' must be '<method>/<scene type>[/<sensing>]' with "
            f"method in {', '.join(METHODS)}, scene type in {', '.join(SCENES)} and sensing in "
            f"{', '.join(SENSORS)}"
        )
    return method, scene, sensing or IDEAL


def _method_key(method: str, sensing: str) -> str:
    """A method's key in the table's cells and raw CSVs: the method, '<method>/<sensing>' for
    its rows under a sensor."""
    return method if sensing == IDEAL else f"{method}/{sensing}"


def _label(key: str) -> str:
    """A method row's label: the method's, with the sensor named for a sensed one."""
    method, _, sensing = key.partition("/")
    return METHODS[method] + sensed_text(sensing or IDEAL)


def _thesis_text(figures: Mapping[str, Any], row: str) -> str | None:
    t = thesis_row(figures, TABLE, row)
    if "success" not in t:
        return None
    return f"{t['success']}/{t['trials']} ({100 * t['success_rate']:.1f}%)"


def table_5_2(
    by_condition: Mapping[str, Sequence[Mapping[str, Any]]],
    rows: Mapping[str, str],
    figures: Mapping[str, Any],
    out_dir: Path,
    scale: str,
) -> pd.DataFrame:
    """reports/tables/table_5_2.{md,csv} and table_5_2_branches.{md,csv}."""
    cells = _cells(by_condition, rows)
    oracle = cells.get("oracle", {})
    oracle_ok = {
        scene: {r["episode"]: bool(r["success"]) for r in recs} for scene, recs in oracle.items()
    }
    table_rows, raw = [], []
    for method, scenes in cells.items():
        table_rows.append(_method_line(method, scenes, oracle, oracle_ok, figures, raw))
    frame = pd.DataFrame.from_records(table_rows)
    thesis_cols = [c for c in frame.columns if c.endswith("(thesis)") and frame[c].notna().any()]
    frame = frame.drop(
        columns=[c for c in frame.columns if c.endswith("(thesis)") and c not in thesis_cols]
    )
    write_table(
        frame,
        [],
        out_dir,
        TABLE,
        f"Table 5.2: shelf replenishment success ({scale} scale, simulated)",
        [*_notes(cells), *_sensing_notes(by_condition, rows)],
    )
    write_raw_csv(raw, out_dir / f"{TABLE}.csv", counts=())
    _write_branches(cells, out_dir, scale)
    return frame


def _cells(
    by_condition: Mapping[str, Sequence[Mapping[str, Any]]], rows: Mapping[str, str]
) -> dict[str, dict[str, list[Mapping[str, Any]]]]:
    """method key (`_method_key`) -> scene type -> the records of the row's trials_ch5
    condition, each checked to have seen through the row's sensing."""
    cells: dict[str, dict[str, list[Mapping[str, Any]]]] = {}
    for row, cond in rows.items():
        method, scene, sensing = _parse(row)
        if cond not in by_condition:
            raise ClutterbenchError(
                f"report.table_5_2.{row}: no trial records of condition '{cond}' "
                "(run stage trials_ch5)"
            )
        records = list(by_condition[cond])
        found = sorted({str(r.get("sensing", IDEAL)) for r in records})
        if records and found != [sensing]:
            raise ClutterbenchError(
                f"report.table_5_2.{row}: condition '{cond}' ran sensing {', '.join(found)}, "
                f"not {sensing}"
            )
        cells.setdefault(_method_key(method, sensing), {})[scene] = records
    return cells


def _raw_row(method: str, scene: str, r: Rate, strict: Rate) -> dict[str, Any]:
    return {
        "method": method,
        "scene": scene,
        "success_k": r.k,
        "success_n": r.n,
        "strict_success_k": strict.k,
        "strict_success_n": strict.n,
    }


def _method_line(
    method: str,
    scenes: Mapping[str, Sequence[Mapping[str, Any]]],
    oracle: Mapping[str, Sequence[Mapping[str, Any]]],
    oracle_ok: Mapping[str, Mapping[Any, bool]],
    figures: Mapping[str, Any],
    raw: list[dict[str, Any]],
) -> dict[str, Any]:
    """One method's row of the table (`method`: its key, `_method_key`); its per-scene and
    total counts are appended to `raw`. A sensed row has no thesis figures (the thesis' rows
    are its own robot's, with its own sensor)."""
    line: dict[str, Any] = {"method": _label(method)}
    sensed = "/" in method
    all_recs: list[Mapping[str, Any]] = []
    beats = 0
    for scene in SCENES:
        recs = scenes.get(scene, [])
        all_recs += recs
        r = rate(recs, "success") if recs else Rate(0, 0)
        strict = rate(recs, "strict_success") if recs else Rate(0, 0)
        # the thesis column beside the collapse-free one (the thesis' trial notion)
        line[scene] = r.text()
        line[f"{scene} (thesis)"] = None if sensed else _thesis_text(figures, f"{method}/{scene}")
        line[f"{scene} strict"] = strict.text()
        raw.append(_raw_row(method, scene, r, strict))
        known = oracle_ok.get(scene, {})
        beats += sum(bool(x["success"]) and known.get(x["episode"]) is False for x in recs)
    total = rate(all_recs, "success") if all_recs else Rate(0, 0)
    total_strict = rate(all_recs, "strict_success") if all_recs else Rate(0, 0)
    line["total"] = total.text()
    line["total (thesis)"] = None if sensed else _thesis_text(figures, f"{method}/total")
    line["total strict"] = total_strict.text()
    raw.append(_raw_row(method, "total", total, total_strict))
    if oracle and method != "oracle":
        o = [x for s in oracle.values() for x in s]
        for key, ours, col in (
            ("success", total, "points below the oracle"),
            ("strict_success", total_strict, "points below the oracle (strict)"),
        ):
            gap = 100 * (rate(o, key).rate - ours.rate) if o and all_recs else None
            line[col] = f"{gap:.1f}" if gap is not None else "—"
        line["episodes the oracle failed"] = beats
    else:
        line["points below the oracle"] = "—"
        line["points below the oracle (strict)"] = "—"
        line["episodes the oracle failed"] = "—"
    line["mean disturbed boxes"] = (
        f"{sum(x['n_disturbed'] for x in all_recs) / len(all_recs):.2f}" if all_recs else "—"
    )
    return line


def _notes(cells: Mapping[str, Mapping[str, Sequence[Mapping[str, Any]]]]) -> list[str]:
    """The notes under Table 5.2."""
    return [
        NOTE,
        "(thesis) columns: the thesis' real-robot counts (Table 5.2); ours are simulated. "
        "Each scene's first column is collapse-free success (no box off the shelf, none "
        "but the moved ones dropped beyond trials.collapse_free.drop_m or tipped beyond "
        "tilt_deg, the new box at its place: the thesis' trial notion, so the thesis "
        "column stands beside it); 'strict': also no other box moved beyond the label "
        "threshold, the prefix of the same episode up to its first strict failure.",
        "without collapse prediction: the same planner with the collapse prediction "
        "removed and nothing else: no R_s overlap test (eq. 5.5) before a blocker is "
        "moved and no collapse check of a rearrangement, so every blocker whose way is "
        "clear is movable; the geometric way check (the thesis' assumption that a moved "
        "object touches no other) stays in both variants. Random: an action drawn "
        "uniformly from the oracle's action set (a placement at any candidate, a blocker "
        "held aside, or an obstacle rearranged first) at every step.",
        "pushing where it has no plan (beyond the thesis): the planner with collapse "
        "prediction, but where it would give up it carries the first blocker that is "
        "movable (eq. 5.5) and whose goal is in the shelf although boxes stand in its way: "
        "they are pushed (the oracle's action set holds these carries, so it stays the "
        "ceiling). It differs from the row with collapse prediction only in episodes that "
        "row gave up. The oracle over the actions that move no box into another simulates "
        "only those the thesis' planners may take (no placement at an occupied candidate, "
        "no carry whose way is blocked): a planner that keeps the thesis' no-contact rule "
        "beats it only through the re-plan after a rearrangement, as it may the oracle "
        "(below); the contact and random rows can.",
        free_start_note(cells),
        "arrangement clusters from: "
        + ", ".join(
            sorted(
                {str(r.get("perception")) for s in cells.values() for v in s.values() for r in v}
            )
        )
        + " (clusters: the generator's ground truth; detector: the trained detector).",
        "episodes the oracle failed: scenes where the method succeeded but the oracle's "
        "first successful action sequence was not found (its budget or the rearrangement "
        "re-plan, which the oracle simulates as one fixed sequence).",
    ]


def _sensing_notes(
    by_condition: Mapping[str, Sequence[Mapping[str, Any]]], rows: Mapping[str, str]
) -> list[str]:
    """Which rows saw through a sensor model, by preset (none: no note, as before any was
    run)."""
    used = {cond: by_condition[cond] for row, cond in rows.items() if _parse(row)[2] != IDEAL}
    by = sensed_by_preset(used)
    if by is None:
        return []
    return [
        f"sensed rows (trials.ch5_sensed, docs/sensing.md), by sensor preset: {by}. Their "
        "planner reads every picture through the sensor model: the detector (trained on that "
        "sensor's images: stage detector_sensed), the collapse map network (trained on exact "
        "depth) and the planner's depth points see the sensed depth; the starts' free places, "
        "execution and judging read the exact picture and physics, as in every other row, "
        "which reads the renderer's exact depth. The thesis' figures stand beside the "
        "thesis' own rows only."
    ]


def _write_branches(
    cells: Mapping[str, Mapping[str, Sequence[Mapping[str, Any]]]], out_dir: Path, scale: str
) -> None:
    """table_5_2_branches.{md,csv}: where each method's episodes ended, by planner branch."""
    branches = branch_breakdown(cells)
    write_table(
        branches,
        [],
        out_dir,
        BRANCH_TABLE,
        f"Table 5.2 by planner branch: where the episodes ended ({scale} scale)",
        [
            "branch: the plan that placed the box (or the last one executed); "
            "ends: placed (success), collapse (another box collapsed), misplaced (the new box did "
            "not rest at its place), gave_up (no plan).",
            "why no plan: for the episodes that gave up, what ruled out each occupied "
            "candidate (an episode counts once per reason): filled by no detected cluster "
            "(nothing to grasp), filled by its own cluster, the blocker's goal outside the "
            "shelf, its way blocked (and the box in the way could not be rearranged), its "
            "collapse region overlapping another cluster (and no safe rearrangement).",
        ],
    )


def free_start_note(cells: Mapping[str, Mapping[str, Sequence[Mapping[str, Any]]]]) -> str:
    """How many starts offer a free placement candidate, per scene type (every condition of
    a scene type meets the same starts: the first method's records count)."""
    parts = []
    for scene in SCENES:
        recs = next((s[scene] for s in cells.values() if s.get(scene)), [])
        known = [r for r in recs if "free_at_start" in r]
        if known:
            k = sum(bool(r["free_at_start"]) for r in known)
            parts.append(f"{scene} {k}/{len(known)}")
    if not parts:
        return "starts with a free placement candidate: not recorded (trials_ch5 predates it)."
    return (
        "starts with a free placement candidate for the episode's box (the generator's "
        "ground-truth clusters; shelved starts are redrawn until none is free, thesis Fig. "
        "5.9): " + ", ".join(parts) + "."
    )


def branch_breakdown(
    cells: Mapping[str, Mapping[str, Sequence[Mapping[str, Any]]]],
) -> pd.DataFrame:
    rows = []
    for method, scenes in cells.items():
        for scene in SCENES:
            recs = scenes.get(scene, [])
            groups: dict[str, list[Mapping[str, Any]]] = {}
            for r in recs:
                groups.setdefault(str(r["branch"]), []).append(r)
            for branch in sorted(groups):
                g = groups[branch]
                row: dict[str, Any] = {
                    "method": method,
                    "scene": scene,
                    "branch": branch,
                    "episodes": len(g),
                }
                for end in ("placed", "collapse", "misplaced", "gave_up", "max_steps"):
                    row[end] = sum(r["end"] == end for r in g)
                why = Counter(w for r in g for w in r.get("gave_up_why", []))
                row["why no plan (episodes)"] = (
                    "; ".join(f"{w} {k}" for w, k in sorted(why.items())) if why else ""
                )
                rows.append(row)
    return pd.DataFrame.from_records(rows)
