"""Compare two default-scale runs of the pipeline (two checkouts' `reports/`), for example the
committed run and a fresh clone's `make repro` on another CPU -> one markdown report:

- every trials condition's per-episode success (collapse-free and strict) in both runs, and
  the episodes whose target differs (a different settled start: a CPU's physics);
- the trials' targets against the benchmark scenes (data/benchmark/ of this checkout, run
  from it): how many of a run's episodes have the target the artifact holds;
- the physics-from-depth conditions' box repair: boxes dropped and boxes with no
  place in the shelf, per stream, and decisions without a model.

    python -m experiments.compare_runs OURS_DIR THEIRS_DIR [--out FILE]

Both directories are repository roots whose `reports/` a default-scale run wrote.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text

TRIALS = "reports/trials"


def read_conditions(root: Path) -> dict[str, list[dict[str, Any]]]:
    """Every ch. 6 trials condition's records under `root`."""
    base = root / TRIALS
    if not base.is_dir():
        raise ClutterbenchError(f"{base}: no trials reports (run the pipeline there first)")
    out = {}
    for path in sorted(base.glob("*/records.jsonl")):
        out[path.parent.name] = [json.loads(line) for line in path.read_text().splitlines()]
    return out


def rate(records: Sequence[Mapping[str, Any]], key: str) -> str:
    k = sum(bool(r.get(key)) for r in records)
    return f"{k}/{len(records)} ({100.0 * k / max(len(records), 1):.1f}%)"


def repair_counts(records: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """The box repair in a physics-from-depth condition's records."""
    dropped = outside = decisions = 0
    for r in records:
        for d in r.get("estimate_dropped") or []:
            dropped += int(d or 0)
            decisions += 1
        outside += sum(int(o or 0) for o in r.get("estimate_outside") or [])
    failed = sum(int(r.get("perception_failed") or 0) for r in records)
    return {"decisions": decisions, "dropped": dropped, "outside": outside, "failed": failed}


def artifact_targets(scale: str = "default") -> dict[tuple[str, int], int]:
    """(stream, episode) -> the benchmark scenes' target of every ch. 6 episode the trials of
    `scale` run (this project's params.yaml and data/benchmark/, pin checked)."""
    from clutterbench.cli.benchmark_scenes import scale_jobs, start_of, target_key
    from clutterbench.config import load_params, project_params_path
    from clutterbench.sim import benchmark

    out = {}
    entries = benchmark.store().entries
    for job in scale_jobs(load_params(project_params_path()), scale):
        if job["kind"] == "ch6":
            found = entries.get(target_key(job, start_of(job, target=False)))
            if found is not None:
                out[job["stream"], int(job["index"])] = int(found["target"])
    return out


def episode_pairs(
    ra: Sequence[Mapping[str, Any]], rb: Sequence[Mapping[str, Any]]
) -> list[tuple[Mapping[str, Any], Mapping[str, Any]]]:
    """The episodes both runs hold, paired by index."""
    by_b = {r["episode"]: r for r in rb}
    return [(r, by_b[r["episode"]]) for r in ra if r["episode"] in by_b]


def _pulled(r: Mapping[str, Any]) -> list[Any]:
    return [s.get("box") for s in r.get("steps") or []]


PAIRED = {
    "target": lambda x, y: x["target"] != y["target"],
    "scene": lambda x, y: x.get("scene") != y.get("scene"),
    "outcome": lambda x, y: (
        (bool(x["success"]), bool(x["strict_success"]))
        != (bool(y["success"]), bool(y["strict_success"]))
    ),
    "pulled": lambda x, y: _pulled(x) != _pulled(y),
    "identical": lambda x, y: x == y,
}
"""Per paired episode: what differs between the runs (identical: nothing)."""


def compare(ours: Path, theirs: Path) -> list[str]:
    a, b = read_conditions(ours), read_conditions(theirs)
    shared = [c for c in a if c in b]
    targets = artifact_targets()
    same_run = ours.resolve() == theirs.resolve()
    lines = [
        "# Two runs compared" if not same_run else "# One run against the benchmark scenes",
        "",
        f"ours: `{ours}`; theirs: `{theirs}`; benchmark scenes: this checkout's data/benchmark/."
        + (" (One run given twice: read its own columns and the last one.)" if same_run else ""),
        "",
        "| condition | stream | ours: collapse-free | theirs | ours: strict | theirs | "
        "targets differ | ours: start = benchmark | scene hashes differ | outcome differs | "
        "boxes pulled differ | records identical |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    total = dict.fromkeys(PAIRED, 0)
    for c in shared:
        ra, rb = a[c], b[c]
        pairs = episode_pairs(ra, rb)
        stream = str(ra[0].get("stream"))
        same = sum(targets.get((stream, int(r["episode"]))) == r["target"] for r in ra)
        diff = {k: sum(f(x, y) for x, y in pairs) for k, f in PAIRED.items()}
        total = {k: total[k] + v for k, v in diff.items()}
        lines.append(
            f"| {c} | {stream} | {rate(ra, 'success')} | {rate(rb, 'success')} | "
            f"{rate(ra, 'strict_success')} | {rate(rb, 'strict_success')} | "
            f"{diff['target']}/{len(pairs)} | {same}/{len(ra)} targets | "
            f"{diff['scene']}/{len(pairs)} | {diff['outcome']} | {diff['pulled']} | "
            f"{diff['identical']} |"
        )
    n = sum(len(episode_pairs(a[c], b[c])) for c in shared)
    lines.append(
        f"| **all {len(shared)}** | | | | | | {total['target']}/{n} | | {total['scene']}/{n} | "
        f"{total['outcome']} | {total['pulled']} | {total['identical']} |"
    )
    lines += [
        "",
        "'targets differ': episodes whose target differs between the runs (their settled "
        "starts differ: the CPUs' physics); 'start = benchmark': episodes of ours whose target "
        "is the benchmark scenes' target of that episode; 'scene hashes differ': episodes whose "
        "records name different start scenes; 'outcome differs': collapse-free or strict "
        "success differs; 'boxes pulled differ': the sequence of pulled boxes differs; "
        "'records identical': the episode's record is the same in both runs, field for field.",
        "",
        "## Physics from depth: the box repair",
        "",
        "| condition | run | decisions | boxes dropped | of them: no place in the shelf | "
        "decisions without a model |",
        "|---|---|---|---|---|---|",
    ]
    for c in shared:
        if not str(a[c][0].get("planner", "")).startswith("physics_from_depth"):
            continue
        for name, recs in (("ours", a[c]), ("theirs", b[c])):
            if not any("estimate_dropped" in r for r in recs):
                lines.append(f"| {c} | {name} | (records before the repair's counts) | | | |")
                continue
            n = repair_counts(recs)
            lines.append(
                f"| {c} | {name} | {n['decisions']} | {n['dropped']} | {n['outside']} | "
                f"{n['failed']} |"
            )
    return lines + [""]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m experiments.compare_runs")
    parser.add_argument("ours", type=Path)
    parser.add_argument("theirs", type=Path)
    parser.add_argument("--out", type=Path, default=Path("experiments/reports/compare_runs.md"))
    args = parser.parse_args(argv)
    try:
        lines = compare(args.ours, args.theirs)
    except ClutterbenchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    write_text(args.out, "\n".join(lines))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
