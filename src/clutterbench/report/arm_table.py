"""Kinematic vs arm: each arm-level condition (stage trials_arm) beside the kinematic condition
it repeats, on the same episodes (same scenes, same targets), one by one."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import write_table
from clutterbench.trials.core.stats import Rate

TABLE = "arm_vs_kinematic"
FAILURES = ("unreachable", "planning_failed", "no_contact")
"""The arm failure kinds counted (maniskill/executor.ARM_OUTCOMES but `ok`)."""


def _steps(record: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """A record's executed steps: a ch. 6 episode's `steps`, a ch. 4 trial is one step."""
    steps = record.get("steps")
    return list(steps) if steps is not None else [record]


def arm_table(
    arm: Mapping[str, Sequence[Mapping[str, Any]]],
    kinematic: Mapping[str, Sequence[Mapping[str, Any]]],
    of: Mapping[str, str],
    out_dir: Path,
    scale: str,
) -> pd.DataFrame:
    """reports/tables/arm_vs_kinematic.{md,csv}: per arm-level condition, the success of the
    kinematic and the arm-level run on the same episodes, how many episodes agree, and the
    arms' failures per step. `arm`: condition -> its records; `kinematic`: the repeated
    condition -> its records; `of`: arm condition -> the condition it repeats."""
    rows = []
    for name, records in arm.items():
        kin_by_episode = {r["episode"]: r for r in kinematic.get(of[name], [])}
        missing = [r["episode"] for r in records if r["episode"] not in kin_by_episode]
        if missing:
            raise ClutterbenchError(
                f"{TABLE}: condition '{of[name]}' has no record of episode {missing[0]} that "
                f"'{name}' repeats (rerun its kinematic stage)"
            )
        pairs = [(kin_by_episode[r["episode"]], r) for r in records]
        n = len(pairs)
        row: dict[str, Any] = {"condition": name, "repeats": of[name], "episodes": n}
        for key, label in (("success", "collapse-free"), ("strict_success", "strict")):
            kin_ok = sum(bool(k[key]) for k, _ in pairs)
            arm_ok = sum(bool(a[key]) for _, a in pairs)
            agree = sum(bool(k[key]) == bool(a[key]) for k, a in pairs)
            row |= {
                f"kinematic {label}": Rate(kin_ok, n).text(),
                f"arm {label}": Rate(arm_ok, n).text(),
                f"points (arm - kinematic), {label}": f"{100 * (arm_ok - kin_ok) / n:+.1f}"
                if n
                else "—",
                f"agreement, {label}": Rate(agree, n).text(),
            }
        steps = [s for r in records for s in _steps(r) if "arm_outcome" in s]
        kinds = Counter(s["arm_outcome"] for s in steps)
        row["arm steps"] = len(steps)
        for kind in FAILURES:
            row[kind] = kinds.get(kind, 0)
        failed = kinds.get("unreachable", 0) + kinds.get("planning_failed", 0)
        row["reach / planning failures"] = Rate(failed, len(steps)).text()
        row["steps touching another box"] = sum(bool(s.get("arm_contacts")) for s in steps)
        row["retract failures"] = sum(len(s.get("arm_retract_failed") or []) for s in steps)
        rows.append(row)
    frame = pd.DataFrame.from_records(rows)
    write_table(
        frame,
        [],
        out_dir,
        TABLE,
        f"Kinematic vs arm-level execution ({scale} scale, simulated)",
        [
            "the same planner on the same scenes and targets (the first episodes of the "
            "repeated condition); kinematic: the box is moved kinematically; arm: Pandas of "
            "the ManiSkill tasks approach, take hold (suction-like), pull and hold; one judge.",
            "collapse-free: no other box left the shelf, dropped or tipped beyond "
            "trials.collapse_free; strict: also none moved beyond the label threshold (the "
            "strict episode: the prefix up to its first strict failure). agreement: episodes "
            "whose success is the same both ways.",
            "unreachable: no joint state puts the tool at the face; planning_failed: no "
            "straight tool path inside the joint limits clear of the shelf; no_contact: the "
            "tool stopped short of the face (other boxes in the way, or pushed); reach / "
            "planning failures: the first two over the arm steps. No such step is a success.",
            "steps touching another box: an arm touched a box it neither pulled nor held.",
        ],
    )
    return frame
