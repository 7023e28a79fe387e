"""`make bench`, trials part: support-graph latency and wall time per trial, on one core.

Needs the trained collapse predictor (models/<trials.ch6.model>/best.pt) and the support
thresholds (reports/support/thresholds.json); skipped with a message when they are missing.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from clutterbench.bench import bench_ch6_jobs, header, measure_table, write_result
from clutterbench.config import load_params, load_section
from clutterbench.data.trial_scenes import draw_trial_spec
from clutterbench.io import read_json
from clutterbench.planning.ch6.cpg import build_cpg
from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
from clutterbench.planning.ch6.support import SupportParams
from clutterbench.platform_info import cpu_description
from clutterbench.sim.config import SimConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.renderer import ensure_renderer
from clutterbench.trials.ch6.episodes import run_ch6_episode
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.harness import load_predictor

THRESHOLDS = Path("reports/support/thresholds.json")


def bench_ch4(trials: TrialsConfig, sim: SimConfig, scenes: int) -> dict:
    """Ch. 4 planning latency: every ordered pair of a 10-box pile through the network
    (thesis eqs. 4.1, 4.2), and the median wall time of one trial per ch. 4 planner."""
    from clutterbench.perception.masks import masks_from_instance
    from clutterbench.planning.ch4.risk_planner import plan_risk
    from clutterbench.trials.ch4.episodes import ch4_jobs, run_ch4_episode
    from clutterbench.trials.config import Ch4ConditionConfig

    out: dict = {}
    models = {c.model for c in trials.ch4_conditions.values() if c.model is not None}
    model = next((m for m in sorted(models) if Path(f"models/{m}/best.pt").exists()), None)
    if model is None:
        print("bench trials: ch. 4 skipped (no trained ch. 4 model; run dvc repro first)")
        return out
    predictor = load_predictor(Path(f"models/{model}/best.pt"), sim.camera.image_size)
    plan_s, pairs = [], []
    for i in range(scenes + 1):
        spec = draw_trial_spec(
            "bench", trials.streams["ch4_same_10"], 99, i, sim.physics, sim.camera, 30
        )
        obs = observe(BoxWorld.from_spec(spec, sim.physics, render=True), sim.camera)
        seg = masks_from_instance(obs, trials.ch4.min_pixels)
        t0 = time.perf_counter()
        _, cands, _, _ = plan_risk(predictor, obs, seg, None, trials.ch4.pixel_threshold)
        if i:
            plan_s.append(time.perf_counter() - t0)
            pairs.append(len(cands))
    out["ch4_plan_10_objects_s_median"] = float(np.median(plan_s))
    out["ch4_plan_10_objects_pairs_mean"] = float(np.mean(pairs))
    for planner in ("risk", "random", "oracle"):
        cond = Ch4ConditionConfig(
            planner=planner,
            stream="ch4_various_5",
            episodes=scenes,
            model=model if planner == "risk" else None,
        )
        jobs = ch4_jobs(
            "bench",
            cond,
            trials=trials,
            sim=sim,
            seed=99,
        )
        wall = []
        for job in jobs:
            t0 = time.perf_counter()
            run_ch4_episode(job)
            wall.append(time.perf_counter() - t0)
        out[f"ch4_trial_{planner}_5_objects_s_median"] = float(np.median(wall))
    return out


def bench_trials(
    graphs: int = 20, episodes: int = 10, out_dir: Path = Path("reports/bench")
) -> dict | None:
    params = load_params("params.yaml")
    params = {**params, "base": {**params["base"], "scale": "default"}}
    sim = load_section(SimConfig, "sim", params)
    trials = load_section(TrialsConfig, "trials", params)
    model = Path(f"models/{trials.ch6.model}/best.pt")
    if not model.exists() or not THRESHOLDS.exists():
        print(f"bench trials: skipped ({model} or {THRESHOLDS} missing; run dvc repro first)")
        return None
    torch.set_num_threads(1)
    ensure_renderer()
    support = SupportParams(**read_json(THRESHOLDS)["chosen"]["coverage"])
    predict = load_predictor(model, sim.camera.image_size)
    planner = CollapseGraphPlanner(predict, support, support.score_threshold, trials.ch6.min_pixels)
    stream = trials.streams["ch6_10"]
    graph_s = []
    for i in range(graphs + 1):
        spec = draw_trial_spec("bench", stream, 99, i, sim.physics, sim.camera, 30)
        obs = observe(BoxWorld.from_spec(spec, sim.physics, render=True), sim.camera)
        t0 = time.perf_counter()
        build_cpg(planner.support_edges(obs), obs.visible_boxes(trials.ch6.min_pixels)[0])
        if i:  # the first call pays for lazy initialisation
            graph_s.append(time.perf_counter() - t0)
    result: dict = {
        "support_graph_10_objects_ms_median": 1000 * float(np.median(graph_s)),
        "threads": 1,
    }
    for planner_name in ("single_step", "multi_step", "bimanual", "oracle", "random"):
        cp_max = support.score_threshold
        jobs = bench_ch6_jobs(planner_name, episodes, trials, sim, support, cp_max, model)
        wall = []
        for job in jobs:
            t0 = time.perf_counter()
            run_ch6_episode(job)
            wall.append(time.perf_counter() - t0)
        result[f"trial_{planner_name}_s_median"] = float(np.median(wall))
    result |= bench_ch4(trials, sim, graphs)
    result |= cpu_description()  # cpu_model, logical_cpus, torch_threads (1), machine
    lines = header("Trials benchmark (one core)", result) + measure_table(result, skip=("threads",))
    write_result(out_dir, "trials", result, lines)
    for k, v in result.items():
        print(f"{k}: {v}")
    return result
