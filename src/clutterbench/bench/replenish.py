"""`make bench`, chapter 5 part: the costs of a replenishment trial -> reports/bench/ch5.{json,md}.

Measured in one process (one core, the worker setting) on the first N_SCENES scenes of each
trial stream drawn from the bench's own seed (never the table's scenes): a scene's draw
(drops, settling, redraws), a world built and observed, the detector's clusters, one collapse
map (the ch. 5 network on one cluster), one plan (candidates, the blockers' ways and
collapse maps), and whole episodes of each of PLANNERS. Needs the detector, the ch. 5
collapse network and its validation threshold (the part is skipped, with a message, without
them).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

from clutterbench.bench import header, measure_table, write_result
from clutterbench.config import load_params, load_section
from clutterbench.platform_info import cpu_description

N_SCENES = 8
SEED = 99
TYPES = ("stacked", "shelved", "random")
PLANNERS = ("replenish", "oracle", "contact", "oracle_no_contact")
"""Whole episodes of: the planner with collapse prediction, the oracle, the planner that may
push, the oracle over the actions that move no box into another (trials_ch5's rows)."""


def _timed(fn, *args, **kwargs) -> tuple[object, float]:
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def bench_ch5(out_dir: Path = Path("reports/bench")) -> dict:
    import torch

    from clutterbench.errors import ClutterbenchError
    from clutterbench.parallel import worker_init
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.renderer import ensure_renderer
    from clutterbench.trials.ch5 import episodes as ch5
    from clutterbench.trials.config import TrialsConfig

    params = load_params("params.yaml")
    params = {**params, "base": {**params["base"], "scale": "default"}}
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    try:
        ch5.check_models(dict(trials.ch5_conditions), trials.ch5)
        prob = ch5.collapse_threshold(trials.ch5)
    except ClutterbenchError as e:
        print(f"ch5 bench skipped: {e}")
        return {}
    worker_init(1)
    torch.set_num_threads(1)
    ensure_renderer()
    parts: dict[str, list[float]] = {
        k: [] for k in ("draw", "observe", "detect", "collapse_map", "plan")
    }
    episodes: dict[str, list[float]] = {}
    for scene_type in TYPES:
        for planner in PLANNERS:
            name = f"{planner}_{scene_type}"
            cond = trials.ch5_conditions[name]
            jobs = _bench_jobs(name, cond, scene_type, trials, sim, prob)
            ch5.run_ch5_episode(jobs[0])  # warm-up: models loaded, shaders compiled
            episodes[name] = [_timed(ch5.run_ch5_episode, job)[1] for job in jobs]
            if planner != "replenish":
                continue
            _time_parts(jobs, cond, trials, sim, parts)
    result: dict = {**cpu_description(), "scenes_per_type": N_SCENES}
    for k, v in parts.items():
        result[f"{k}_median_s"] = statistics.median(v)
    for k, v in episodes.items():
        result[f"episode_{k}_median_s"] = statistics.median(v)
    md = header("Chapter 5 (shelf replenishment) costs, one core", result)
    write_result(out_dir, "ch5", result, md + measure_table(result, tuple(cpu_description())))
    for k, v in result.items():
        print(f"{k}: {v}")
    return result


def _bench_jobs(name: str, cond, scene_type: str, trials, sim, prob: float) -> list:
    """The first N_SCENES episodes of condition `name` on the bench's seed."""
    from clutterbench.trials.ch5 import episodes as ch5

    return ch5.ch5_jobs(
        name,
        cond,
        trials=trials,
        sim=sim,
        seed=SEED,
        prob_threshold=prob,
        scene_type=scene_type,
        oracle_detector=True,
        record_images=False,
    )[:N_SCENES]


def _time_parts(jobs: list, cond, trials, sim, parts: dict[str, list[float]]) -> None:
    """Each job's draw, observation, detection, one collapse map and one plan, timed and
    appended to `parts`."""
    from clutterbench.data.trial_scenes import draw_trial_spec
    from clutterbench.planning.ch5.replenish import ReplenishPlanner, place_clusters
    from clutterbench.sim.pull import SceneState, world_at
    from clutterbench.sim.render import observe
    from clutterbench.trials.ch5 import episodes as ch5
    from clutterbench.trials.ch5 import perception as ch5_perception

    for job in jobs:
        spec, t = _timed(
            draw_trial_spec,
            cond.stream,
            job.stream_cfg,
            job.seed,
            job.index,
            sim.physics,
            sim.camera,
            job.max_attempts,
            keep_groups=True,
        )
        parts["draw"].append(t)
        state = SceneState.start(spec)
        obs, t = _timed(observe, world_at(spec, state, sim.physics, render=True), sim.camera)
        parts["observe"].append(t)
        dets, t = _timed(ch5_perception.perceive, job, spec, state, obs)
        parts["detect"].append(t)
        space = ch5.space_of(spec)
        cmap = ch5_perception.collapse_map_fn(job)
        clusters = place_clusters(obs, dets, space)
        if clusters:
            parts["collapse_map"].append(_timed(cmap, obs, clusters[0].mask)[1])
        size = ch5.new_box_size(job.seed, cond.stream, job.index, trials.ch5.new_boxes)
        plan = ReplenishPlanner(ch5.planner_params(job), space, cmap).plan
        parts["plan"].append(_timed(plan, obs, dets, size)[1])
