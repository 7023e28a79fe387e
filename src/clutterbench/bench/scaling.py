"""`make bench`, ray part: the same jobs on both parallel backends (params.yaml `parallel`),
1 and 2 workers -> reports/bench/ray.{json,md}; `--cost`: the paper scale costed from those
measurements -> reports/bench/paper_cost.{json,md} (docs/scaling.md).

Seven workloads (bench/workloads.py: each a stage's own jobs on the bench's own seed), each
run whole on every backend x workers, each case in a fresh process (as a stage runs it): a
generation shard set (`generate`: shards of the ch6 dataset's scenes,
data.generate.shard_arrays), the trials stage's mix (`trials`: ch. 6 episodes of every
default condition whose planner needs no trained network, round-robin, so the search oracles,
the truth-map planners and physics from depth weigh as in the stage; mix_conditions), the
slides stage's piles (`slides`: `--shards` piles, data.slides.label_pile), the network-free
conditions of trials_ch4 (`trials_ch4`: random and oracle trials), of trials_ch5
(`trials_ch5`: the oracles on the generator's clusters) and of trials_ch3 (`trials_ch3`:
Yamakuzushi games without the ConvNet), each round-robin, and `--arm-episodes` arm-level
episodes of the trials_arm stage's conditions whose networks are trained (`trials_arm`;
skipped, with a printed line, when none is: every arm condition repeats a network planner).
Every job times itself in its worker; a case's wall time includes starting its workers (a
pool, or a local Ray instance and its workers) and shutting them down. Measures per case: jobs
per second, overhead per job (wall time not spent in jobs, the jobs' time spread over the
workers; starting the workers and their renderers included, a local Ray instance's own start
and stop not: that is given apart), busy cores (the CPU seconds of the case's process and of
every process it started and waited for, over its wall time; of the processes backend: Ray's
own processes are not all its children), parallel efficiency (1-worker wall / (2 x 2-worker
wall)) and whether every case gave the same bytes.

    python -m clutterbench.bench.scaling [--scale default] [--shards 8] [--shard-size 5]
                                         [--episodes 16] [--arm-episodes 4]
    python -m clutterbench.bench.scaling --cost      # after the bench: paper_cost.md
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.bench import header, write_result
from clutterbench.bench.workloads import (
    WORKLOADS,
    job_conditions,
    scale_params,
    unavailable,
    workload_jobs,
)
from clutterbench.config import load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json, write_text
from clutterbench.parallel import BACKENDS, ParallelConfig, connect_ray, map_in_workers
from clutterbench.platform_info import cpu_description, cpu_seconds

OUT = Path("reports/bench")
CASES = [(b, w) for b in ("processes", "ray") for w in (1, 2)]
CLUSTER_NODES = (1, 4, 16)
CLUSTER_CORES = 16
"""The paper-scale table's Ray clusters: N nodes of 16 cores."""


def _timed(job: dict[str, Any]) -> tuple[float, Any]:
    """The wrapped job's result and the seconds it took in its worker."""
    start = time.perf_counter()
    result = job["fn"](job["job"])
    return time.perf_counter() - start, result


def _digest(result: Any) -> str:
    """A shard's arrays or an episode's record, as bytes to compare across backends."""
    h = hashlib.sha256()
    if isinstance(result, dict):
        for key in sorted(result):
            a = np.asarray(result[key])
            h.update(f"{key}{a.dtype}{a.shape}".encode() + a.tobytes())
    else:
        h.update(json.dumps(result.record, sort_keys=True).encode())
    return h.hexdigest()


def run_case(
    workload: str, backend: str, workers: int, scale: str, shards: int, shard_size: int, n: int
) -> dict[str, Any]:
    """One workload on one backend and worker count, timed (run in a fresh process)."""
    fn, jobs, units = workload_jobs(workload, scale, shards, shard_size, n)
    wrapped = [{"index": k, "fn": fn, "job": job} for k, job in enumerate(jobs)]
    parallel = ParallelConfig(backend=backend)
    cpu0 = cpu_seconds()
    start = time.perf_counter()
    start_s = shutdown_s = 0.0
    if backend == "ray":
        import ray

        connect_ray(parallel, workers)  # a local instance of `workers` CPUs
        start_s = time.perf_counter() - start
    results = map_in_workers(
        f"bench {workload} {backend} x{workers}", _timed, wrapped, workers, parallel
    )
    if backend == "ray":
        t = time.perf_counter()
        ray.shutdown()
        shutdown_s = time.perf_counter() - t
    wall = time.perf_counter() - start
    cpu_s = cpu_seconds() - cpu0
    job_s = [s for s, _ in results]
    digest = hashlib.sha256("".join(_digest(r) for _, r in results).encode()).hexdigest()
    return {
        "workload": workload,
        "backend": backend,
        "workers": workers,
        "jobs": len(jobs),
        "units": units,
        "wall_s": wall,
        "start_s": start_s,
        "shutdown_s": shutdown_s,
        "job_s_sum": float(sum(job_s)),
        "jobs_per_s": len(jobs) / wall,
        "overhead_per_job_s": (wall - start_s - shutdown_s - sum(job_s) / workers) / len(jobs),
        "cpu_s": cpu_s,
        "busy_cores": cpu_s / wall,
        "digest": digest,
        "conditions": job_conditions(jobs),
    }


def bench_ray(
    scale: str = "default",
    shards: int = 8,
    shard_size: int = 5,
    episodes: int = 16,
    out_dir: Path = OUT,
    arm_episodes: int = 4,
) -> dict[str, Any]:
    """Every workload x backend x workers, each case in a fresh process -> ray.{json,md}.
    `episodes`: the jobs of every trials workload but trials_arm, which runs `arm_episodes`
    (an arm-level episode takes seconds to a minute). A workload that cannot run here (no
    condition it may run: bench.workloads.unavailable) is skipped with a printed line."""
    try:
        import ray  # noqa: F401
    except ImportError:
        print("bench ray: skipped (ray is not installed; make setup installs it)")
        return {}
    cases, skipped = [], {}
    for workload in WORKLOADS:
        why = unavailable(workload, scale)
        if why is not None:
            print(f"bench ray: {workload} skipped ({why})")
            skipped[workload] = why
            continue
        n = arm_episodes if workload == "trials_arm" else episodes
        for backend, workers in CASES:
            args = [workload, backend, str(workers), scale, str(shards), str(shard_size), str(n)]
            cmd = [sys.executable, "-m", "clutterbench.bench.scaling", "--case", *args]
            env = os.environ | {"PYTHONHASHSEED": "0"}  # as a stage runs (clutterbench.stage)
            out = subprocess.run(cmd, capture_output=True, text=True, env=env)
            if out.returncode != 0:
                tail = (out.stderr.strip().splitlines() or ["(no output)"])[-1]
                raise ClutterbenchError(f"bench ray: {workload} {backend} x{workers}: {tail}")
            cases.append(json.loads(out.stdout.strip().splitlines()[-1]))
    result = {"scale": scale, "cases": cases, "derived": derived(cases), "skipped": skipped}
    result |= cpu_description()
    write_result(out_dir, "ray", result, ray_markdown(result))
    return result


def derived(cases: list[dict[str, Any]]) -> dict[str, Any]:
    """Per workload: per-job cost (processes, 1 worker), parallel efficiency per backend, and
    Ray's overhead per task against processes at 2 workers; whether every case gave the
    same bytes."""
    out: dict[str, Any] = {}
    for workload in WORKLOADS:
        by = {(c["backend"], c["workers"]): c for c in cases if c["workload"] == workload}
        if len(by) < len(CASES):
            continue
        one = by[("processes", 1)]
        out[workload] = {
            "unit_s": one["job_s_sum"] / one["units"],
            "units": one["units"],
            "efficiency": {b: by[(b, 1)]["wall_s"] / (2 * by[(b, 2)]["wall_s"]) for b in BACKENDS},
            "ray_fixed_s": by[("ray", 2)]["start_s"] + by[("ray", 2)]["shutdown_s"],
            "ray_overhead_per_task_s": by[("ray", 2)]["overhead_per_job_s"]
            - by[("processes", 2)]["overhead_per_job_s"],
            "same_bytes": len({c["digest"] for c in by.values()}) == 1,
            "conditions": one.get("conditions", []),
        }
    return out


UNITS = {"generate": "scene", "slides": "pile", "trials_ch3": "game"}
"""What a workload's unit is (the others: an episode)."""


def ray_markdown(result: dict[str, Any]) -> list[str]:
    lines = header(f"Parallel backends: processes and Ray ({result['scale']} scale)", result)
    lines += [
        "The same jobs on each backend with 1 and 2 workers, each case in a fresh process; "
        "wall time includes starting and stopping the workers (a local Ray instance: start "
        "and shut down given apart). Overhead per job: wall time not spent in jobs (their "
        "summed time over the workers; a Ray instance's start and stop left out), per job. "
        "Busy cores: CPU seconds of the case's processes over its wall time, and that over the "
        "workers (processes backend only: Ray's own processes are not all children of the "
        "case). `python -m clutterbench.bench.scaling`.",
        "",
        "| workload | backend | workers | jobs | wall s | Ray start + stop s | jobs/s | "
        "overhead per job s | busy cores (of workers) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in result["cases"]:
        ray_s = f"{c['start_s'] + c['shutdown_s']:.2f}" if c["backend"] == "ray" else ""
        lines.append(
            f"| {c['workload']} | {c['backend']} | {c['workers']} | {c['jobs']} | "
            f"{c['wall_s']:.2f} | {ray_s} | {c['jobs_per_s']:.3f} | "
            f"{c['overhead_per_job_s']:.3f} | {busy_cell(c)} |"
        )
    lines += [
        "",
        "| workload | per unit s (1 worker) | efficiency, processes | efficiency, Ray | Ray "
        "overhead per task vs processes s | Ray start + stop s | same bytes, every case |",
        "|---|---|---|---|---|---|---|",
    ]
    for workload, d in result["derived"].items():
        unit = UNITS.get(workload, "episode")
        lines.append(
            f"| {workload} | {d['unit_s']:.3f} per {unit} | {d['efficiency']['processes']:.2f} "
            f"| {d['efficiency']['ray']:.2f} | {d['ray_overhead_per_task_s']:.3f} | "
            f"{d['ray_fixed_s']:.2f} | {'yes' if d['same_bytes'] else 'NO'} |"
        )
    for workload, why in result.get("skipped", {}).items():
        lines += ["", f"Skipped: `{workload}` ({why})."]
    target = trials_target(result)
    if target is not None:
        lines += [
            "",
            f"The Ray backend's target (overhead <= 5% of a trials stage's wall time at default "
            f"scale on 2 workers), estimated from these numbers for the default `trials` stage "
            f"({target['episodes']} episodes): {100 * target['fraction']:.2f}%.",
        ]
    return lines


def busy_cell(case: dict[str, Any]) -> str:
    """'1.62 (81%)': a case's busy cores and their share of its workers (processes backend;
    measured only by benches since added)."""
    if case["backend"] != "processes" or "busy_cores" not in case:
        return ""
    return f"{case['busy_cores']:.2f} ({100 * case['busy_cores'] / case['workers']:.0f}%)"


def trials_target(result: dict[str, Any]) -> dict[str, Any] | None:
    """Ray's overhead (start + stop, and per task against processes) as a fraction of the
    default trials stage's wall time on 2 workers, from the bench's own per-episode cost."""
    d = result["derived"].get("trials")
    if d is None:
        return None
    episodes = stage_jobs("default")["trials"]
    stage_s = episodes * d["unit_s"] / (2 * d["efficiency"]["processes"])
    extra = d["ray_fixed_s"] + max(0.0, d["ray_overhead_per_task_s"]) * episodes / 2
    return {"episodes": episodes, "fraction": extra / stage_s}


def stage_jobs(scale: str) -> dict[str, int]:
    """The jobs each simulation stage fans out at `scale` (params.yaml)."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.slides import SlideDataConfig
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.trials.ch3.config import Ch3Config
    from clutterbench.trials.config import TrialsConfig

    params = scale_params(scale)
    gen = load_section(GenerateConfig, "generate", params)
    trials = load_section(TrialsConfig, "trials", params)
    ch3 = load_section(Ch3Config, "yamakuzushi", params)
    return {
        "generate": sum(ds.n_scenes for ds in gen.datasets.values()),
        "support": load_section(SupportEvalConfig, "support", params).test_scenes,
        "trials": sum(c.episodes for c in trials.run_conditions.values()),
        "trials_ch4": sum(c.episodes for c in trials.ch4_conditions.values()),
        "trials_ch5": sum(c.episodes for c in trials.ch5_conditions.values()),
        "trials_arm": sum(c.episodes for c in trials.arm_conditions.values()),
        "slides": load_section(SlideDataConfig, "yamakuzushi.data", params).n_piles,
        "trials_ch3": ch3.games.n_games * len(ch3.games.variants),
    }


COSTED = {
    "generate": ("generate", "scenes (every dataset)", "a ch6 dataset scene"),
    "support": ("generate", "test scenes", "a ch6 dataset scene"),
    "trials": ("trials", "episodes (every ch. 6 condition)", "an episode of the stage's mix"),
    "slides": ("slides", "piles", "a pile at the bench's slides per pile"),
    "trials_ch4": ("trials_ch4", "trials", "a random or oracle trial"),
    "trials_ch5": (
        "trials_ch5",
        "episodes (every ch. 5 condition)",
        "a network-free ch. 5 episode (oracle, oracle_no_contact on the generator's clusters, "
        "not also simulating the detector's view)",
    ),
    "trials_arm": (
        "trials_arm",
        "episodes (every arm condition)",
        "an arm-level episode (Pandas) of {conditions}, with their trained networks",
    ),
    "trials_ch3": ("trials_ch3", "games (every variant)", "a no_convnet, random or oracle game"),
}
"""Stages costed from a bench workload: (workload, what a job is, what its cost is; a
`{conditions}` in it: the conditions the bench ran, which for trials_arm depend on the
networks trained where it ran)."""


def paper_cost(bench: dict[str, Any], scale: str = "paper") -> dict[str, Any]:
    """The paper scale's simulation stages costed from the bench's per-job costs: CPU-hours
    and wall hours on one machine of 2 cores (processes) and on Ray clusters of N x 16
    cores, assuming the 2-worker parallel efficiency measured here holds."""
    jobs = stage_jobs(scale)
    rows = []
    for stage, n in jobs.items():
        row: dict[str, Any] = {"stage": stage, "jobs": n}
        workload = COSTED[stage][0] if stage in COSTED else None
        if workload in bench.get("skipped", {}):
            row["skipped"] = bench["skipped"][workload]
        if workload in bench["derived"]:
            _, what, cost_of = COSTED[stage]
            d = bench["derived"][workload]
            ran = [c.removeprefix("bench_") for c in d.get("conditions", [])]
            cpu_s = n * d["unit_s"]
            row |= {
                "what": what,
                "unit_s": d["unit_s"],
                "cost_of": cost_of.format(conditions=", ".join(ran) or "its conditions"),
                "cpu_hours": cpu_s / 3600,
                "wall_h_2_cores": cpu_s / (2 * d["efficiency"]["processes"]) / 3600,
            }
            for nodes in CLUSTER_NODES:
                cores = nodes * CLUSTER_CORES
                wall = d["ray_fixed_s"] + cpu_s / (cores * d["efficiency"]["ray"])
                row[f"wall_h_ray_{nodes}x{CLUSTER_CORES}"] = wall / 3600
        rows.append(row)
    return {"scale": scale, "measured_at": bench["scale"], "cpu_model": bench["cpu_model"]} | {
        "rows": rows
    }


def cost_markdown(cost: dict[str, Any]) -> list[str]:
    ray_cols = [f"Ray {n} x {CLUSTER_CORES} cores" for n in CLUSTER_NODES]
    lines = [
        f"# The {cost['scale']} scale, costed",
        "",
        f"Per-job costs measured by `python -m clutterbench.bench.scaling` at "
        f"{cost['measured_at']} scale on {cost['cpu_model']} (reports/bench/ray.json), times "
        f"the {cost['scale']} scale's job counts (params.yaml); wall hours assume the 2-worker "
        "parallel efficiency measured there holds on every node. Written by "
        "`python -m clutterbench.bench.scaling --cost`.",
        "",
        "| stage | jobs | per job s (cost of) | CPU-hours | wall h, 1 machine of 2 cores | "
        + " | ".join(f"wall h, {c}" for c in ray_cols)
        + " |",
        "|---|---|---|---|---|" + "---|" * len(ray_cols),
    ]
    for r in cost["rows"]:
        if "cpu_hours" not in r:
            why = f" (skipped: {r['skipped']})" if "skipped" in r else ""
            cells = [f"not measured by this bench{why}"] + [""] * (2 + len(ray_cols))
            lines.append(f"| {r['stage']} | {r['jobs']:,} | " + " | ".join(cells) + " |")
            continue
        walls = [f"{r[f'wall_h_ray_{n}x{CLUSTER_CORES}']:.2f}" for n in CLUSTER_NODES]
        lines.append(
            f"| {r['stage']} | {r['jobs']:,} {r['what']} | {r['unit_s']:.3f} ({r['cost_of']}) | "
            f"{r['cpu_hours']:.1f} | {r['wall_h_2_cores']:.1f} | " + " | ".join(walls) + " |"
        )
    lines += [
        "",
        "What stays on one machine: network training (`train`, `train_slide`, `detector`), on "
        "a GPU where one is available (docs/platform.md); `split`, `evaluate` and `report` "
        "are minutes.",
    ]
    return lines


def write_paper_cost(out_dir: Path = OUT, scale: str = "paper") -> dict[str, Any]:
    path = out_dir / "ray.json"
    if not path.exists():
        raise ClutterbenchError(f"{path} missing: run python -m clutterbench.bench.scaling first")
    cost = paper_cost(read_json(path), scale)
    write_json(out_dir / "paper_cost.json", cost)
    write_text(out_dir / "paper_cost.md", "\n".join(cost_markdown(cost)) + "\n")
    return cost


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m clutterbench.bench.scaling")
    parser.add_argument("--scale", default="default", choices=("tiny", "default", "paper"))
    parser.add_argument("--shards", type=int, default=8)
    parser.add_argument("--shard-size", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument(
        "--arm-episodes", type=int, default=4, help="trials_arm's jobs (slow: Pandas)"
    )
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--cost", action="store_true", help="write paper_cost.md from ray.json")
    parser.add_argument("--case", nargs=7, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    try:
        if args.case:
            workload, backend, workers, scale, shards, shard_size, n = args.case
            res = run_case(
                workload, backend, int(workers), scale, int(shards), int(shard_size), int(n)
            )
            print(json.dumps(res))
        elif args.cost:
            write_paper_cost(args.out)
            print(f"wrote {args.out / 'paper_cost.md'}")
        else:
            bench_ray(
                args.scale, args.shards, args.shard_size, args.episodes, args.out, args.arm_episodes
            )
            print(f"wrote {args.out / 'ray.md'}")
    except ClutterbenchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
