"""One trials stage's records from two runs, episode by episode (same condition, same episode
or game index) -> markdown: per condition, both runs' success counts, and the episodes whose
start, outcome, actions or whole record differ. For the stages whose records are one file
(trials_ch4, trials_ch5, trials_ch3; the ch. 6 conditions: experiments/compare_runs.py), for
example a run on another CPU from the same benchmark scenes (experiments/reports/cross_cpu/).

    python -m experiments.compare_stage_records STAGE OURS_DIR THEIRS_DIR [--out FILE]

OURS_DIR and THEIRS_DIR hold the stage's records.jsonl (ch. 3: and slides.jsonl); THEIRS may
run a subset of the conditions: only the conditions it holds are compared.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text

STAGES = ("trials_ch4", "trials_ch5", "trials_ch3")

START = {
    "trials_ch4": ("target", "catalogue", "family"),
    "trials_ch5": ("family", "scene_type", "new_box_m", "free_at_start", "rejected_starts"),
    "trials_ch3": ("n_pieces",),
}
"""Per stage, the record fields that name an episode's start, beside the scene hash, its
source, the seed, the box count and the stream."""

OUTCOME = {
    "trials_ch4": ("success_held", "strict_success_held", "n_disturbed", "n_collapsed"),
    "trials_ch5": ("end", "strict_steps", "n_disturbed"),
    "trials_ch3": ("pieces_removed", "end", "slides"),
}
"""Per stage, the outcome fields beside success and strict success."""

CRITERIA = {
    "trials_ch4": ("success", "strict_success", "success_held", "strict_success_held"),
    "trials_ch5": ("success", "strict_success"),
    "trials_ch3": ("success", "strict_success"),
}


def read_records(path: Path) -> list[dict[str, Any]]:
    if not path.is_file():
        raise ClutterbenchError(f"{path}: no records (run the stage there first)")
    try:
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    except json.JSONDecodeError as exc:
        raise ClutterbenchError(f"{path}: not JSON lines ({exc})") from None


def _fields(r: Mapping[str, Any], keys: Sequence[str]) -> tuple[str, ...]:
    return tuple(json.dumps(r.get(k), sort_keys=True) for k in keys)


def start(stage: str, r: Mapping[str, Any]) -> tuple[str, ...]:
    return _fields(r, ("scene", "scene_source", "seed", "n_objects", "stream", *START[stage]))


def outcome(stage: str, r: Mapping[str, Any]) -> tuple[str, ...]:
    return _fields(r, ("success", "strict_success", *OUTCOME[stage]))


def actions(stage: str, r: Mapping[str, Any]) -> Any:
    """What the episode did: ch. 4 the extraction (box, mode); ch. 5 per step the branch, the
    boxes moved and the place; ch. 3 per slide the piece and direction."""
    if stage == "trials_ch4":
        return (r.get("extract"), r.get("mode"))
    steps = r.get("steps") or []
    if stage == "trials_ch5":
        return [(s.get("branch"), s.get("moved_boxes"), s.get("placed")) for s in steps]
    return [(s.get("piece"), s.get("direction")) for s in steps]


def k_of_n(records: Sequence[Mapping[str, Any]], key: str) -> str:
    return f"{sum(bool(r.get(key)) for r in records)}/{len(records)}"


DIFFERS = ("start", "success or strict", "outcome", "actions")


def compare(stage: str, ours: Path, theirs: Path) -> list[str]:
    if stage not in STAGES:
        raise ClutterbenchError(f"stage '{stage}': one of {', '.join(STAGES)}")
    index = "game" if stage == "trials_ch3" else "episode"
    a, b = read_records(ours / "records.jsonl"), read_records(theirs / "records.jsonl")
    by_ours = {(r["condition"], r[index]): r for r in a}
    crit = CRITERIA[stage]
    head = ["condition", "paired"]
    head += [f"{who} {c}" for c in crit for who in ("ours:", "theirs:")]
    head += [f"{d} differs" for d in DIFFERS] + ["records identical"]
    lines = [
        f"# {stage}: two runs compared episode by episode",
        "",
        f"ours: `{ours}`; theirs: `{theirs}` (`python -m experiments.compare_stage_records`).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    total: collections.Counter[str] = collections.Counter()
    fields: collections.Counter[str] = collections.Counter()
    conditions = list(dict.fromkeys(r["condition"] for r in b))
    for c in conditions:
        pairs = [(by_ours.get((c, y[index])), y) for y in b if y["condition"] == c]
        pairs = [(x, y) for x, y in pairs if x is not None]
        n: collections.Counter[str] = collections.Counter()
        for x, y in pairs:
            n["start"] += start(stage, x) != start(stage, y)
            n["success or strict"] += (bool(x["success"]), bool(x["strict_success"])) != (
                bool(y["success"]),
                bool(y["strict_success"]),
            )
            n["outcome"] += outcome(stage, x) != outcome(stage, y)
            n["actions"] += actions(stage, x) != actions(stage, y)
            n["identical"] += x == y
            fields.update(k for k in set(x) | set(y) if x.get(k) != y.get(k))
        total.update(n)
        total["paired"] += len(pairs)
        row = [c, str(len(pairs))]
        row += [k_of_n([p[i] for p in pairs], k) for k in crit for i in (0, 1)]
        row += [str(n[d]) for d in DIFFERS] + [f"{n['identical']}/{len(pairs)}"]
        lines.append("| " + " | ".join(row) + " |")
    paired = [
        (by_ours[r["condition"], r[index]], r) for r in b if (r["condition"], r[index]) in by_ours
    ]
    row = [f"**all {len(conditions)}**", str(total["paired"])]
    row += [k_of_n([p[i] for p in paired], k) for k in crit for i in (0, 1)]
    row += [str(total[d]) for d in DIFFERS] + [f"{total['identical']}/{total['paired']}"]
    lines += ["| " + " | ".join(row) + " |", ""]
    lines.append(
        f"Records: ours {len(a)}, theirs {len(b)} ({len(conditions)} conditions compared). "
        "'outcome' also counts "
        + ", ".join(f"`{k}`" for k in OUTCOME[stage])
        + "; 'actions': what the episode did (trials_ch4: the box extracted and how; "
        "trials_ch5: per step the branch, the boxes moved and the place; trials_ch3: per "
        "slide the piece and direction)."
    )
    if fields:
        lines.append(
            "Fields that differ, in how many paired records: "
            + ", ".join(f"`{k}` {v}" for k, v in fields.most_common())
            + "."
        )
    if stage == "trials_ch3" and (theirs / "slides.jsonl").is_file():
        lines.append(slides_line(ours, theirs, set(conditions)))
    return lines + [""]


def slides_line(ours: Path, theirs: Path, conditions: set[str]) -> str:
    """Chapter 3's per-slide records of the compared variants, paired by (variant, game, step)."""
    key = lambda s: (s["condition"], s["game"], s["step"])  # noqa: E731
    mine = [s for s in read_records(ours / "slides.jsonl") if s["condition"] in conditions]
    other = read_records(theirs / "slides.jsonl")
    by = {key(s): s for s in mine}
    pairs = [(by[key(s)], s) for s in other if key(s) in by]
    return (
        f"Slides (slides.jsonl): ours {len(mine)}, theirs {len(other)}, paired by (variant, "
        f"game, step) {len(pairs)}, identical {sum(x == y for x, y in pairs)}; per-slide "
        f"success ours {k_of_n(mine, 'success')}, theirs {k_of_n(other, 'success')}."
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.compare_stage_records")
    parser.add_argument("stage", choices=STAGES)
    parser.add_argument("ours", type=Path)
    parser.add_argument("theirs", type=Path)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    try:
        lines = compare(args.stage, args.ours, args.theirs)
    except (ClutterbenchError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    text = "\n".join(lines)
    if args.out:
        write_text(args.out, text)
        print(f"wrote {args.out}")
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
