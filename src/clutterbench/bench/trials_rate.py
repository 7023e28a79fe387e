"""`make bench`, trials_rate part: what each condition of the `trials` stage (Table 6.3) costs
per episode with the project's own trained networks, thresholds and fusion weights, measured
without a profiler.

Run it in a project where `dvc repro support` has run (models/, reports/support/,
reports/box_head/ of this params.yaml; `python -m clutterbench.bench trials_rate`). For every
condition the stage runs (trials.run_conditions, as `stage_conditions` picks them), its first
EPISODES episodes are built by the stage's own job constructor and run one after another in
this process by the stage's own episode function, on one torch thread at the stage's
inference precision, as one worker of the stage's pool runs them (worker start-up excluded:
the networks are loaded by the first episode of each planner, which is run once unmeasured).
Per condition: wall and CPU seconds per episode, and the single-core minutes of all its
episodes at this scale (an extrapolation from the first episodes; the stream's scenes vary);
their sum over the stage's workers is the stage's extrapolated wall time. Where the committed
records of the same episodes exist (reports/trials/), their steps are listed beside the
sample's, so that a sample of shorter or longer episodes shows.

Writes reports/bench/trials_rate.{json,md}; `CLUTTERBENCH_TRIALS_RATE_EPISODES` sets the
episodes per condition (default EPISODES).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError

EPISODES = 3
THRESHOLDS = Path("reports/support/thresholds.json")
OUT = Path("reports/bench")


def _episodes() -> int:
    raw = os.environ.get("CLUTTERBENCH_TRIALS_RATE_EPISODES", str(EPISODES))
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise ClutterbenchError(f"CLUTTERBENCH_TRIALS_RATE_EPISODES={raw!r}: need an integer >= 1")
    return n


def measure(episodes: int) -> dict[str, Any]:
    """Every condition the stage runs: its first `episodes` episodes, timed one by one."""
    import dataclasses

    from clutterbench.bench.run_times import cpu_identity
    from clutterbench.config import load_base, load_params, load_section
    from clutterbench.parallel import worker_init
    from clutterbench.platform_info import cpu_description
    from clutterbench.precision import inference_from_params
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch6.episodes import condition_jobs, load_planners, run_ch6_episode
    from clutterbench.trials.config import TrialsConfig

    params = load_params("params.yaml")
    base = load_base(params)
    cfg = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    if not THRESHOLDS.is_file():
        raise ClutterbenchError(f"{THRESHOLDS} missing: run dvc repro support first")
    precision = inference_from_params(params)
    worker_init(1)
    conditions = cfg.stage_conditions([])
    load_planners(cfg.planner_modules, [c.planner for c in conditions.values()])
    warmed: set[str] = set()
    rows = []
    for name, cond in conditions.items():
        k = min(episodes, cond.episodes)
        jobs = condition_jobs(
            name,
            dataclasses.replace(cond, episodes=k),
            trials=cfg,
            sim=sim,
            seed=base.seed,
            thresholds=THRESHOLDS,
        )[0]
        if cond.planner not in warmed:  # the worker's once-per-process loading, unmeasured
            run_ch6_episode(jobs[0])
            warmed.add(cond.planner)
        wall, cpu, steps = [], [], []
        for job in jobs:
            w0, c0 = time.perf_counter(), time.process_time()
            result = run_ch6_episode(job)
            wall.append(time.perf_counter() - w0)
            cpu.append(time.process_time() - c0)
            steps.append(len(result.record["steps"]))
        per = sum(wall) / len(wall)
        rows.append(
            {
                "condition": name,
                "planner": cond.planner,
                "sensing": cond.sensing,
                "episodes_sampled": k,
                "episodes_stage": cond.episodes,
                "wall_s_per_episode": round(per, 4),
                "cpu_s_per_episode": round(sum(cpu) / len(cpu), 4),
                "steps": steps,
                "stage_min_one_core": round(per * cond.episodes / 60.0, 2),
            }
        )
        print(f"{name}: {per:.2f} s per episode, {rows[-1]['stage_min_one_core']:.1f} min")
    workers = cfg.workers
    one_core = sum(r["stage_min_one_core"] for r in rows)
    return {
        "machine": cpu_description() | cpu_identity(),
        "scale": base.scale,
        "precision": precision,
        "episodes_per_condition": episodes,
        "workers": workers,
        "conditions": rows,
        "stage_min_one_core": round(one_core, 1),
        "stage_min_wall": round(one_core / max(1, workers), 1),
    }


def committed_steps(rows: list[dict[str, Any]], reports: Path = Path("reports")) -> None:
    """Each row's committed steps of the same episodes (sim_profile.committed_steps of stage
    trials; None where they are not all committed)."""
    from clutterbench.bench.sim_profile import committed_steps as steps_of

    known = steps_of("trials", reports)
    for row in rows:
        steps = [known.get((row["condition"], i)) for i in range(row["episodes_sampled"])]
        row["committed_steps"] = None if None in steps else steps


def markdown(res: dict[str, Any]) -> str:
    m = res["machine"]
    lines = [
        "# Trials stage: cost of each condition per episode (one core, trained networks)",
        "",
        f"Machine: {m.get('cpu_model')} (CPU family {m.get('cpu_family')}, model "
        f"{m.get('cpu_model_number')}), {m.get('logical_cpus')} logical CPUs, 1 torch thread; "
        f"{res['scale']} scale, inference {res['precision']}.",
        "",
        f"The first {res['episodes_per_condition']} episodes of each condition the stage runs, "
        "with the project's own trained networks (bench/trials_rate.py). Extrapolated stage: "
        "per condition its seconds per episode times its episodes; **"
        f"{res['stage_min_one_core']} min on one core, {res['stage_min_wall']} min over "
        f"{res['workers']} workers** (an extrapolation, not a measurement of the stage).",
        "",
        "| condition | planner | sensing | s / episode (wall) | CPU s / episode | steps: sample "
        "/ committed | stage min (one core) | share |",
        "|---|---|---|---|---|---|---|---|",
    ]
    total = res["stage_min_one_core"] or 1.0
    for r in sorted(res["conditions"], key=lambda r: -r["stage_min_one_core"]):
        committed = r.get("committed_steps")
        steps = f"{sum(r['steps'])} / {sum(committed) if committed is not None else '—'}"
        lines.append(
            f"| {r['condition']} | {r['planner']} | {r['sensing']} | "
            f"{r['wall_s_per_episode']:.2f} | {r['cpu_s_per_episode']:.2f} | {steps} | "
            f"{r['stage_min_one_core']:.1f} | {100 * r['stage_min_one_core'] / total:.1f} % |"
        )
    by_planner: dict[str, float] = {}
    for r in res["conditions"]:
        by_planner[r["planner"]] = by_planner.get(r["planner"], 0.0) + r["stage_min_one_core"]
    lines += [
        "",
        "| planner (all its conditions) | stage min (one core) | share |",
        "|---|---|---|",
    ]
    for p, v in sorted(by_planner.items(), key=lambda kv: -kv[1]):
        lines.append(f"| {p} | {v:.1f} | {100 * v / total:.1f} % |")
    return "\n".join(lines) + "\n"


def bench_trials_rate() -> dict[str, Any]:
    from clutterbench.io import write_json, write_text

    res = measure(_episodes())
    committed_steps(res["conditions"])
    write_json(OUT / "trials_rate.json", res)
    write_text(OUT / "trials_rate.md", markdown(res))
    print(f"{OUT / 'trials_rate.md'}: {res['stage_min_wall']} min over {res['workers']} workers")
    return res
