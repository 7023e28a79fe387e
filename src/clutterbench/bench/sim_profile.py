"""`make bench`, sim_profile part: where each simulation stage's wall time goes, on one core.

For every simulation stage of the default scale (SIM_STAGES) a fresh Python process runs a
small sample of the stage's own work in-process (the job constructors and job functions its
script in stages/ calls, params.yaml at default scale; the samples: bench/sim_profile_stages.py)
under cProfile, one torch thread, as one worker of the stage's pool would. Its wall time is
split into two phases:

- start-up: the process's imports, configs, the stage's jobs built, the networks loaded and
  the renderer's first picture: once per worker process, counted
  whole as start-up;
- the sample's groups (a dataset, a planner, a variant), each a handful of units (scenes,
  episodes, games) run one after another, each job and result pickled and unpickled on the
  way (`transfer`: what a worker pool does to them, the inter-process transfer estimate).

Within a group every function's self time (cProfile's tottime) goes to one CATEGORIES entry
(bench/sim_profile_attribution.py): that of its outermost categorised caller (`classify` on
a function's file and name; callers from cProfile's caller edges, a function's time split
over its callers by the time each edge took, `attribute`), else its own, else Python around
the step. So the search of a planner, its PhysX steps included, is planner time, while the
steps of the episode's own pull are PhysX; the PhysX and render time inside each category
is listed beside it. Beside each group of episodes: their steps, and the steps of the same
episodes in the committed run's records (reports/<stage>/), where the stand-in networks
decide otherwise than the trained ones.

The extrapolated whole-stage single-core time (an extrapolation, not a measurement) is the
start-up phase once, plus per group its once-per-process start-up seconds once and its other
seconds per unit (less cProfile's overhead: the calls made times the overhead per call
measured in the same process) times the stage's units of that group at default scale.

Each stage's sample waits for idle cores and is rerun when other processes used the CPUs
meanwhile (cpu_rates.least_disturbed); the least disturbed run is kept, with their share.
Writes reports/bench/sim_profile.{json,md} (markdown: bench/sim_profile_md.py).
"""

from __future__ import annotations

import cProfile
import json
import pstats
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from clutterbench.bench.sim_profile_attribution import (
    TRANSFERS,
    attribute,
    extrapolate,
    stage_categories,
    top_functions,
)

SIM_STAGES = (
    "generate",
    "trials",
    "noise",
    "testset",
    "support",
    "slides",
    "trials_ch3",
    "trials_ch4",
    "trials_ch5",
    "trials_arm",
)
"""The simulation stages of dvc.yaml profiled, in pipeline order (rendering is part of
generate and of every trials stage: there is no render stage)."""
CHILD_TIMEOUT_S = 600
STAGE_LIMIT_S = 240.0
"""After this long a stage's sample is not rerun (least_disturbed's limit)."""
IDLE_WAIT_S = 20.0

# --- the child process: one stage's sample ---------------------------------------------------

BOOT = (
    "import cProfile, sys, time; t0 = time.perf_counter(); p = cProfile.Profile(); p.enable()\n"
    "from clutterbench.bench.sim_profile import child\n"
    "child(p, t0, *sys.argv[1:])"
)
"""The child process's program: profiling starts before the first clutterbench import."""


def child(prof: cProfile.Profile, t0: float, stage: str, out: str) -> None:
    """Run stage `stage`'s sample (start-up under `prof`, then each group under its own
    profile) and write what it measured to `out` (JSON)."""
    from clutterbench.bench.sim_profile_setup import Context, first_picture
    from clutterbench.bench.sim_profile_stages import STAGES

    ctx = Context(prof)
    first_picture(ctx)
    sample = STAGES[stage](ctx)
    prof.disable()
    startup_s = time.perf_counter() - t0 - ctx.upstream_s
    merged = pstats.Stats(prof)
    groups = []
    for group in sample.groups:
        got, profile = _run_group(group)
        groups.append(got)
        merged.add(profile)
    overhead = _overhead_per_call()
    result = {
        "stage": stage,
        "startup_s": startup_s,
        "upstream_s": ctx.upstream_s,
        "groups": groups,
        "notes": sample.notes,
        "overhead_per_call_s": overhead,
        "top": top_functions(merged.stats),  # type: ignore[attr-defined]
    }
    Path(out).write_text(json.dumps(result))


def _run_group(group: Any) -> tuple[dict[str, Any], cProfile.Profile]:
    """One group of the sample under its own profile: its wall, categories and transfers."""
    TRANSFERS.clear()
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    results = group.run()
    prof.disable()
    wall = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    seconds, inside = attribute(stats)
    got = {
        "name": group.name,
        "unit": group.unit,
        "units": group.units,
        "full_units": group.full,
        "about": group.about,
        "phase": group.phase,
        "wall_s": wall,
        "calls": int(sum(row[1] for row in stats.values())),
        "categories": seconds,
        "inside": {k: v for k, v in inside.items() if v},
        "transfer_bytes": sum(b for b, _ in TRANSFERS),
        "transfers": len(TRANSFERS),
        "episodes": episode_steps(results),
    }
    return got, prof


def episode_steps(results: Any) -> list[list[Any]]:
    """[condition, episode (or game), steps] of each episode result with a list of steps."""
    out = []
    for r in results if isinstance(results, list) else []:
        rec = getattr(r, "record", None)
        if isinstance(rec, dict) and isinstance(rec.get("steps"), list):
            out.append(
                [rec.get("condition"), rec.get("episode", rec.get("game")), len(rec["steps"])]
            )
    return out


def _overhead_per_call(n: int = 200_000) -> float:
    """cProfile's added seconds per Python call in this process (an empty function called
    `n` times, with and without the profiler)."""

    def f() -> None:
        return None

    def loop() -> float:
        t0 = time.perf_counter()
        for _ in range(n):
            f()
        return time.perf_counter() - t0

    plain = min(loop() for _ in range(3))
    prof = cProfile.Profile()
    prof.enable()
    profiled = min(loop() for _ in range(3))
    prof.disable()
    return max(0.0, (profiled - plain) / n)


# --- the parent: every stage, and the report --------------------------------------------------


def committed_steps(stage: str, reports: Path) -> dict[tuple[str, int], int]:
    """(condition, episode) -> steps of the committed records of `stage` (reports/<stage>/)."""
    out = {}
    for path in sorted((reports / stage).rglob("records.jsonl")):
        for line in path.read_text().splitlines():
            r = json.loads(line)
            if isinstance(r.get("steps"), list):
                out[(r.get("condition"), r.get("episode", r.get("game")))] = len(r["steps"])
    return out


def compare_steps(stage: Mapping[str, Any], reports: Path) -> None:
    """Per group with episodes: their steps in the sample and in the committed run's records
    of the same episodes (`steps`: [sample, committed], None where none are committed)."""
    committed = committed_steps(stage["stage"], reports)
    for g in stage["groups"]:
        eps = [e for e in g.pop("episodes", []) if (e[0], e[1]) in committed]
        if eps:
            g["steps"] = [sum(e[2] for e in eps), sum(committed[(e[0], e[1])] for e in eps)]


def run_child(stage: str, project: Path) -> dict[str, Any]:
    """Stage `stage`'s sample in a fresh process (cwd `project`): its result, or the reason
    it could not run (`error`)."""
    with tempfile.NamedTemporaryFile(suffix=".json", dir=project, delete=False) as f:
        out = Path(f.name)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-c", BOOT, stage, str(out)],
            cwd=project,
            capture_output=True,
            text=True,
            timeout=CHILD_TIMEOUT_S,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return {"stage": stage, "error": f"sample over {CHILD_TIMEOUT_S} s", "process_s": 0.0}
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        return {"stage": stage, "error": " / ".join(tail), "process_s": wall}
    got = json.loads(out.read_text())
    out.unlink()
    return got | {"process_s": wall}


def code_state() -> dict[str, Any]:
    """The commit measured and the source files that differed from it (read-only git)."""

    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], capture_output=True, text=True).stdout.strip()
        except OSError:
            return ""

    changed = [line[3:] for line in git("status", "--porcelain", "--", "src").splitlines()]
    return {"commit": git("rev-parse", "--short", "HEAD"), "changed_src_files": len(changed)}


def bench_sim_profile(
    out_dir: Path = Path("reports/bench"), stages: tuple[str, ...] = SIM_STAGES
) -> dict[str, Any]:
    from clutterbench.bench import write_result
    from clutterbench.bench.cpu_rates import least_disturbed
    from clutterbench.bench.sim_profile_md import markdown
    from clutterbench.bench.sim_profile_setup import make_project
    from clutterbench.platform_info import cpu_description

    rows = []
    with tempfile.TemporaryDirectory(prefix="sim_profile_") as tmp:
        project = make_project(Path(tmp), Path.cwd())
        for stage in stages:
            print(f"sim_profile: {stage}", flush=True)
            got = least_disturbed(
                lambda stage=stage: run_child(stage, project),
                idle_wait_s=IDLE_WAIT_S,
                limit_s=STAGE_LIMIT_S,
                children=True,
            )
            if "error" not in got:
                compare_steps(got, Path("reports"))
                got |= extrapolate(got)
                got["categories"] = stage_categories(got)
            rows.append(got)
    result = {"stages": rows, "code": code_state(), **cpu_description(), "torch_threads": 1}
    write_result(out_dir, "sim_profile", result, markdown(result))
    return result
