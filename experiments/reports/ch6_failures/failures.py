"""Where the holding ch. 6 planners fail, from the committed trial records: for each failed
episode (collapse-free) on the 3-10 stream, its failing step (the last one) by what the second
arm did (held nothing; held a box by the plan, by a feared score or idle) and by when the step
failed: already while the box was held (judged before the release) or only once it was let go,
and whether the held box itself, or an aborted pull's box, left the shelf.

    python experiments/reports/ch6_failures/failures.py   # from the repository root -> its README table
"""

import collections
import json
from pathlib import Path

CONDITIONS = (
    "bimanual_box_physics",
    "bimanual_box",
    "bimanual_pull",
    "bimanual_pull_truth",
    "physics_from_depth_hold",
    "oracle_hold",
)


def hold_kind(step: dict) -> str:
    if step.get("hold") is None:
        return "nothing held"
    if step.get("idle_hold"):
        return "idle arm's hold"
    if step.get("feared_hold") is not None:
        return "hold of a feared box"
    return "the plan's hold"


def classify(step: dict) -> tuple[str, str, bool, bool]:
    hold = step.get("hold")
    motion = step.get("box_motion", [])
    held_fell = any(m["held"] and m["left_shelf"] and m["box"] == hold for m in motion)
    pulled_fell = any(
        m["held"] and m["left_shelf"] and m["box"] == step["box"] for m in motion
    )
    when = "while held" if not step.get("success_held", step["success"]) else "after release"
    return hold_kind(step), when, held_fell, pulled_fell


def table(root: Path = Path("reports/trials")) -> str:
    lines = [
        "| condition | failed episodes | failing step: second arm | failed while held "
        "| failed only after the release | the held box left the shelf "
        "| an aborted pull's box left the shelf |",
        "|---|---|---|---|---|---|---|",
    ]
    for cond in CONDITIONS:
        records = [json.loads(x) for x in (root / cond / "records.jsonl").open()]
        failed = [r for r in records if not r["success"] and r["steps"]]
        cells = collections.Counter()
        kinds = collections.Counter()
        for r in failed:
            kind, when, held_fell, pulled_fell = classify(r["steps"][-1])
            kinds[kind] += 1
            cells[when] += 1
            cells["held_fell"] += held_fell
            cells["pulled_fell"] += pulled_fell
        arm = ", ".join(f"{k} {v}" for k, v in kinds.most_common())
        lines.append(
            f"| {cond} | {len(failed)}/{len(records)} | {arm} | {cells['while held']} "
            f"| {cells['after release']} | {cells['held_fell']} | {cells['pulled_fell']} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(table())
