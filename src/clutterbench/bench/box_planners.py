"""`make bench`, box-planner part: the decision time per step of the box-head planners on one
core, the network alone (`*_box`) against learned plus physics (`*_box_physics`: the network fused
per box with each pull simulated on the fitted boxes), with the pulls simulated per decision ->
reports/bench/box_planners.{json,md}.

Episodes on bench scenes of the 3-10 stream (seed 99, never a table's). Needs the collapse
predictor, the box head and the support stage's thresholds and fusion; skipped with a message
when missing.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from clutterbench.bench import bench_ch6_jobs, header, measure_table, write_result
from clutterbench.config import load_params, load_section
from clutterbench.platform_info import cpu_description

EPISODES = 6
PLANNERS = ("multi_step_box", "multi_step_box_physics", "bimanual_box", "bimanual_box_physics")
THRESHOLDS = Path("reports/support/thresholds.json")
FUSION = THRESHOLDS.with_name("box_fusion.json")


def bench_box_planners(out_dir: Path = Path("reports/bench"), episodes: int = EPISODES) -> dict:
    import torch

    from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch6.episodes import BOX_HEAD, box_fields, planner_support
    from clutterbench.trials.config import TrialsConfig

    params = load_params("params.yaml")
    trials = load_section(TrialsConfig, "trials", params)
    model = Path(f"models/{trials.ch6.model}/best.pt")
    if not all(p.exists() for p in (model, BOX_HEAD, THRESHOLDS, FUSION)):
        print(
            "bench box_planners: skipped (needs the collapse predictor, the box head, "
            f"{THRESHOLDS} and {FUSION}; run dvc repro support)"
        )
        return {}
    torch.set_num_threads(1)
    sim = load_section(SimConfig, "sim", params)
    result: dict = cpu_description() | {"episodes": episodes}
    decide = CollapseGraphPlanner.decide
    times: list[tuple[float, int]] = []

    def timed(self, *a, **k):
        before = getattr(self.predict, "simulated", 0)
        t0 = time.perf_counter()
        try:
            return decide(self, *a, **k)
        finally:
            times.append((time.perf_counter() - t0, getattr(self.predict, "simulated", 0) - before))

    CollapseGraphPlanner.decide = timed
    try:
        for planner in PLANNERS:
            support, cp_max = planner_support(THRESHOLDS, planner, "coverage_gap", trials.ch6)
            box, cp_max = box_fields(THRESHOLDS, planner, trials.ch6)
            jobs = bench_ch6_jobs(planner, episodes, trials, sim, support, cp_max, model)
            times.clear()
            walls = _walls([dataclasses.replace(j, **box) for j in jobs])
            seconds = [t for t, _ in times]
            result[f"{planner}_decision_s_median"] = float(np.median(seconds))
            result[f"{planner}_decision_s_p90"] = float(np.percentile(seconds, 90))
            result[f"{planner}_decisions"] = len(seconds)
            result[f"{planner}_simulated_per_decision_mean"] = float(np.mean([n for _, n in times]))
            result[f"{planner}_episode_s_median"] = float(np.median(walls))
    finally:
        CollapseGraphPlanner.decide = decide
    lines = header("Box-head planners: decision time per step (one core)", result)
    lines += measure_table(
        result, skip=("cpu_model", "machine", "cpu_flags", "torch_cpu_capability")
    )
    write_result(out_dir, "box_planners", result, lines)
    for k, v in result.items():
        if k.endswith(("_median", "_mean")):
            print(f"{k}: {v:.3f}")
    return result


def _walls(jobs: list) -> list[float]:
    from clutterbench.trials.ch6.episodes import run_ch6_episode

    walls = []
    for job in jobs:
        t0 = time.perf_counter()
        run_ch6_episode(dataclasses.replace(job, stream="bench", record_images=False))
        walls.append(time.perf_counter() - t0)
    return walls
