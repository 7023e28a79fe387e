"""How far the ch. 6 one-image planners could get together, from the committed trial records:
on Table 6.3's 3-10 stream (collapse-free), the episodes won by at least one planner of a set,
as if a planner knew in hindsight, episode by episode, which of them would succeed. That is
the ceiling of any choice of one of them per episode; a planner that mixed their decisions
within an episode would reach states none of them reached, and is not bounded by it.

    python experiments/reports/ch6_hindsight/hindsight.py   # from the repository root -> its README table
"""

import json
from pathlib import Path

SETS = (
    ("one arm", ("multi_step_box_physics",)),
    ("one arm", ("physics_from_depth",)),
    ("one arm", ("multi_step_box_physics", "physics_from_depth")),
    (
        "one arm",
        (
            "multi_step_box_physics",
            "physics_from_depth",
            "multi_step_box",
            "multi_step_pull",
            "multi_step",
        ),
    ),
    ("one arm", ("multi_step_pull_truth",)),
    ("one arm", ("oracle",)),
    ("holding", ("bimanual_box_physics",)),
    ("holding", ("physics_from_depth_hold",)),
    ("holding", ("bimanual_box_physics", "physics_from_depth_hold")),
    (
        "holding",
        (
            "bimanual_box_physics",
            "physics_from_depth_hold",
            "bimanual_box",
            "bimanual_pull",
            "bimanual",
        ),
    ),
    ("holding", ("bimanual_pull_truth",)),
    ("holding", ("oracle_hold",)),
)


def wins(cond: str, root: Path) -> dict[tuple[str, int], bool]:
    """(scene, target) -> collapse-free, for every episode of `cond`."""
    records = [json.loads(x) for x in (root / cond / "records.jsonl").open()]
    return {(r["scene"], r["target"]): bool(r["success"]) for r in records}


def table(root: Path = Path("reports/trials")) -> str:
    lines = [
        "| actions | planners | episodes won by at least one | of | collapse-free % |",
        "|---|---|---|---|---|",
    ]
    for arm, conds in SETS:
        runs = [wins(c, root) for c in conds]
        episodes = set(runs[0])
        if any(set(r) != episodes for r in runs):
            raise SystemExit(f"{', '.join(conds)}: not the same episodes")
        won = sum(any(r[e] for r in runs) for e in episodes)
        lines.append(
            f"| {arm} | {' or '.join(conds)} | {won} | {len(episodes)} "
            f"| {100 * won / len(episodes):.1f} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(table())
