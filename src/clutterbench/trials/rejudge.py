"""Re-judge trial records under other thresholds, from the per-box fields alone.

    python -m clutterbench.trials.rejudge reports/trials/multi_step/records.jsonl \\
        --drop-m 0.01 --tilt-deg 15 --moved-m 0.005

Every step record carries `box_motion` (criteria.py), so both criteria can be
recomputed for any thresholds: per episode, collapse-free `success` and `strict_success`,
and per condition their counts (the tables' k/n). With the thresholds the harness ran under,
the output equals the records (and so the tables; tested). An episode ends at its first
collapse-free failure, so under *more lenient* thresholds than the run's, an episode that
ended in a collapse may have gone on: its outcome is unknown (`null`) and is counted apart.

Record kinds: chapter 3 games (`steps` with `piece`; one criterion, the game's: a game
succeeds when its first slide takes the piece off the board and no other piece moves beyond
the threshold or off it; the drop / tilt thresholds do not apply), chapter 4 trials (one
pull per record, no `steps`), chapter 5 replenishment (`steps` with `placed`) and chapter 6
extraction (`steps` with `box`).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from clutterbench import criteria
from clutterbench.criteria import CollapseFreeConfig

CRITERIA = ("success", "strict_success")


def step_failed(step: Mapping[str, Any], key: str, moved_m: float, cf: CollapseFreeConfig) -> bool:
    """Whether an executed step fails under criterion `key` at these thresholds: a box
    collapsed (or, strict, moved), or a replenishment step's new box is not at its place."""
    if not step["executed"]:
        return False
    motion = step["box_motion"]
    clean = (
        criteria.collapse_free(motion, cf)
        if key == "success"
        else criteria.still(motion, moved_m, cf)
    )
    if step.get("placed") and not step.get("at_place"):
        return True
    return not clean


def slide_failed(step: Mapping[str, Any], moved_m: float) -> bool:
    """Whether a chapter 3 slide fails under the game's rule, its one criterion (both keys):
    its piece did not leave the board, or another piece moved beyond `moved_m` or off it."""
    motion = step["box_motion"]
    clean = not any(e["left_shelf"] or e["displacement_m"] > moved_m for e in motion)
    return not (step["target_out"] and clean)


def episode_outcome(
    record: Mapping[str, Any], key: str, moved_m: float, cf: CollapseFreeConfig
) -> bool | None:
    """An episode's success under `key` at these thresholds (None: undecidable, the recorded
    episode stopped at a failure that these thresholds forgive)."""
    if "game" in record:  # chapter 3: a Yamakuzushi game
        steps = record["steps"]
        return bool(steps) and not slide_failed(steps[0], moved_m)
    if "steps" not in record:  # chapter 4: one pull
        ok = (
            record["executed"]
            and record["extracted"]
            and record["valid"]
            and (record.get("target") is None or record["extract"] == record["target"])
        )
        return bool(ok and not step_failed(record, key, moved_m, cf))
    steps = record["steps"]
    for s in steps:
        if step_failed(s, key, moved_m, cf):
            return False
    good_end = "placed" if "branch" in record else "target_out"
    if record["end"] == good_end:
        return True
    if record["end"] in ("collapse", "misplaced") and steps and steps[-1].get("executed"):
        return None  # the run stopped at a failure these thresholds forgive: unknown
    return False


def rejudge(
    records: Sequence[Mapping[str, Any]], moved_m: float, cf: CollapseFreeConfig
) -> list[dict[str, Any]]:
    """Per episode: condition, episode and its outcome under each criterion."""
    return [
        {"condition": r["condition"], "episode": r.get("episode", r.get("game"))}
        | {key: episode_outcome(r, key, moved_m, cf) for key in CRITERIA}
        for r in records
    ]


def summarize(rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per condition and criterion: k successes of n episodes, and the undecidable ones."""
    out: dict[str, dict[str, Any]] = {}
    for row in rows:
        c = out.setdefault(row["condition"], {"episodes": 0})
        c["episodes"] += 1
        for key in CRITERIA:
            c.setdefault(f"{key}_k", 0)
            c.setdefault(f"{key}_unknown", 0)
            c[f"{key}_k"] += row[key] is True
            c[f"{key}_unknown"] += row[key] is None
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("records", type=Path, nargs="+", help="records.jsonl file(s)")
    ap.add_argument("--drop-m", type=float, default=CollapseFreeConfig().drop_m)
    ap.add_argument("--tilt-deg", type=float, default=CollapseFreeConfig().tilt_deg)
    ap.add_argument(
        "--moved-m", type=float, default=None, help="label threshold (default: the records')"
    )
    ap.add_argument("--episodes", action="store_true", help="print every episode too")
    args = ap.parse_args(argv)
    from clutterbench.trials.core.records import read_records

    cf = CollapseFreeConfig(drop_m=args.drop_m, tilt_deg=args.tilt_deg)
    report: dict[str, Any] = {"drop_m": cf.drop_m, "tilt_deg": cf.tilt_deg, "files": {}}
    for path in args.records:
        records = read_records(path)
        rows: list[dict[str, Any]] = []
        for r in records:
            if any("box_motion" not in s for s in r.get("steps", [r])):
                print(f"{path}: episode {r.get('episode')} has no per-box fields", file=sys.stderr)
                return 2
            moved_m = args.moved_m if args.moved_m is not None else r["moved_threshold_m"]
            rows += rejudge([r], moved_m, cf)
        entry: dict[str, Any] = {"conditions": summarize(rows)}
        if args.episodes:
            entry["episodes"] = rows
        report["files"][str(path)] = entry
    print(json.dumps(report, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
