"""`make bench`, physics-from-depth part: the planner's decision time per step on one core ->
reports/bench/physics_depth.{json,md}.

Episodes of the physics-from-depth planners (one arm, holding) on bench scenes of the 3-10
stream (seed 99, never a table's), every decision timed: box fitting, the estimated scene
(built, settled) and the search on it, separately. Needs no trained network.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from clutterbench.bench import bench_ch6_jobs, header, measure_table, write_result
from clutterbench.config import load_params, load_section
from clutterbench.platform_info import cpu_description

EPISODES = 8


def bench_physics_depth(out_dir: Path = Path("reports/bench"), episodes: int = EPISODES) -> dict:
    import torch

    from clutterbench.planning.ch6 import physics_depth
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch6 import physics_model
    from clutterbench.trials.config import TrialsConfig

    torch.set_num_threads(1)
    params = load_params("params.yaml")
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    times: dict[str, list[float]] = {"decision": [], "decision_cpu": [], "scene": []}

    decide = physics_depth.PhysicsFromDepthPlanner.decide
    scene = physics_model.EstimatedWorldModel.scene

    def timed_decide(self, *a, **k):
        t0, c0 = time.perf_counter(), time.process_time()
        out = decide(self, *a, **k)
        times["decision"].append(time.perf_counter() - t0)
        times["decision_cpu"].append(time.process_time() - c0)
        return out

    def timed_scene(self, est):
        t0 = time.perf_counter()
        out = scene(self, est)
        times["scene"].append(time.perf_counter() - t0)
        return out

    result: dict = cpu_description() | {"episodes": episodes}
    physics_depth.PhysicsFromDepthPlanner.decide = timed_decide
    physics_model.EstimatedWorldModel.scene = timed_scene
    try:
        for planner in ("physics_from_depth", "physics_from_depth_hold"):
            for k in times:
                times[k].clear()
            walls = _episode_walls(planner, episodes, trials, sim)
            result |= _planner_times(planner, times, walls)
    finally:
        physics_depth.PhysicsFromDepthPlanner.decide = decide
        physics_model.EstimatedWorldModel.scene = scene
    result |= _box_fit_times(episodes, trials, sim)
    result["load_average_1min"] = float(__import__("os").getloadavg()[0])
    result["node_budget"] = trials.ch6.physics_depth_node_budget
    lines = header("Physics from depth: decision time per step (one core)", result)
    lines += measure_table(
        result, skip=("cpu_model", "machine", "cpu_flags", "torch_cpu_capability")
    )
    write_result(out_dir, "physics_depth", result, lines)
    for k, v in result.items():
        if k.endswith(("_median", "_p90")):
            print(f"{k}: {v:.3f}")
    return result


def _episode_walls(planner: str, episodes: int, trials, sim) -> list[float]:
    """Wall seconds of each bench episode of `planner` (stream ch6_3_10, seed 99)."""
    from clutterbench.trials.ch6.episodes import run_ch6_episode

    jobs = bench_ch6_jobs(planner, episodes, trials, sim, None, 1.0, Path("unused"))
    walls = []
    for job in jobs:
        t0 = time.perf_counter()
        run_ch6_episode(dataclasses.replace(job, stream="bench", record_images=False))
        walls.append(time.perf_counter() - t0)
    return walls


def _planner_times(planner: str, times: dict[str, list[float]], walls: list[float]) -> dict:
    """The result's rows of one planner: its decision, estimated-scene and episode times."""
    result: dict = {}
    result[f"{planner}_decision_s_median"] = float(np.median(times["decision"]))
    result[f"{planner}_decision_s_p90"] = float(np.percentile(times["decision"], 90))
    # CPU seconds of this process: what a core of its own would take, whatever else
    # runs on the machine (wall times above include waiting for a shared core)
    result[f"{planner}_decision_cpu_s_median"] = float(np.median(times["decision_cpu"]))
    result[f"{planner}_decision_cpu_s_p90"] = float(np.percentile(times["decision_cpu"], 90))
    result[f"{planner}_decisions"] = len(times["decision"])
    result[f"{planner}_estimated_scene_s_median"] = float(np.median(times["scene"]))
    result[f"{planner}_episode_s_median"] = float(np.median(walls))
    return result


def _box_fit_times(episodes: int, trials, sim) -> dict:
    """The box fit alone, on the bench scenes' first observations: wall and CPU medians."""
    from clutterbench.data.trial_scenes import draw_trial_spec
    from clutterbench.perception.fitted_scenes import make_estimator
    from clutterbench.sim.pull import SceneState, world_at
    from clutterbench.sim.render import observe

    fit = make_estimator(trials.streams["ch6_3_10"].catalogue, trials.ch6.min_pixels)
    fits, fits_cpu = [], []
    for i in range(episodes):
        spec = draw_trial_spec(
            "bench", trials.streams["ch6_3_10"], 99, i, sim.physics, sim.camera, 30
        )
        obs = observe(world_at(spec, SceneState.start(spec), sim.physics, True), sim.camera)
        t0, c0 = time.perf_counter(), time.process_time()
        fit(obs)
        fits.append(time.perf_counter() - t0)
        fits_cpu.append(time.process_time() - c0)
    return {
        "box_fit_s_median": float(np.median(fits)),
        "box_fit_cpu_s_median": float(np.median(fits_cpu)),
    }
