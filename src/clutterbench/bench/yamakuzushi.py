"""`make bench`, chapter 3 part: the costs of a Yamakuzushi game -> reports/bench/ch3.{json,md}.

Measured in one process (one core, the worker setting): a pile's generation (drops, settling,
the rest check), one slide from a fresh world (build + slide + settle + judge), a top-view
picture, the ConvNet scoring every raster candidate of a pile (crops + forward), and one
POMDP decision (32 state fits, every viewpoint's V1 and V2) with a uniform belief and after
one observation. Needs models/slide_convnet/best.pt for the ConvNet line (skipped without).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from clutterbench.bench import header, measure_table, write_result
from clutterbench.config import load_params, load_section
from clutterbench.platform_info import cpu_description

N_PILES = 10
MODEL = Path("models/slide_convnet/best.pt")


def _per_call(fn, n: int) -> float:
    t0 = time.perf_counter()
    for i in range(n):
        fn(i)
    return (time.perf_counter() - t0) / n


def bench_ch3(out_dir: Path = Path("reports/bench")) -> dict:
    import torch

    from clutterbench.data.slide_crops import height_image, piece_under, raster_candidates
    from clutterbench.data.slides import pile_seed
    from clutterbench.parallel import worker_init
    from clutterbench.planning.ch3 import pomdp
    from clutterbench.sim.pile import PileWorld, generate_pile, slide, top_observation
    from clutterbench.trials.ch3.config import Ch3Config

    params = load_params("params.yaml")
    params = {**params, "base": {**params["base"], "scale": "default"}}
    cfg = load_section(Ch3Config, "yamakuzushi", params)
    worker_init(1)
    torch.set_num_threads(1)
    seeds = [pile_seed(0, "bench", i) for i in range(N_PILES)]
    specs = []
    generate_s = _per_call(lambda i: specs.append(generate_pile(cfg.pile, seeds[i])), N_PILES)
    worlds = [PileWorld.from_spec(s, cfg.pile, render=True) for s in specs]
    top_observation(worlds[0], cfg.camera)  # the process's first picture: the renderer's set-up
    tops = []
    render_s = _per_call(lambda i: tops.append(top_observation(worlds[i], cfg.camera)), N_PILES)
    slide_s = _per_call(
        lambda i: slide(PileWorld.from_spec(specs[i], cfg.pile), 0, np.pi / 4 * i, cfg.slide),
        N_PILES,
    )
    result = {
        **cpu_description(),
        "piles": N_PILES,
        "generate_pile_s": generate_s,
        "slide_s": slide_s,
        "top_picture_s": render_s,
    }
    if MODEL.exists():
        from clutterbench.models.slide_convnet import load_slide_convnet
        from clutterbench.planning.ch3.yamakuzushi import convnet_targets

        model, _ = load_slide_convnet(MODEL)
        result["convnet_scan_s"] = _per_call(
            lambda i: convnet_targets(model, tops[i], cfg.scan, cfg.select), N_PILES
        )
    cands = raster_candidates(cfg.scan)
    result["raster_candidates"] = len(cands)

    def decide(i: int, belief: np.ndarray) -> None:
        obs = tops[i]
        piece = int(piece_under(obs, cands.start_xy).max())
        pts = obs.camera.depth_to_points(obs.depth_m)
        mine = pts[obs.instance == piece + 1].reshape(-1, 3)
        others = pts[(obs.instance > 0) & (obs.instance != piece + 1)].reshape(-1, 3)
        centre = mine[:, :2].mean(axis=0)
        eye = obs.camera.T_world_from_cam[:3, 3]
        grid = pomdp.occupancy_grid(np.concatenate([mine, others]), eye, centre)
        eyes = pomdp.viewpoint_candidates([*centre, 0.0], cfg.pomdp.viewpoint_distances_m, 30)
        pomdp.decide(belief, eyes, centre, grid, others, reward=cfg.pomdp.reward)

    result["viewpoints"] = len(pomdp.viewpoint_candidates([0, 0, 0], (0.3,), 30))
    result["pomdp_decide_uniform_s"] = _per_call(
        lambda i: decide(i, pomdp.uniform_belief()), N_PILES
    )
    narrow = np.zeros(pomdp.N_STATES)
    narrow[list(pomdp.SLIDABLE_STATES)] = 0.1
    result["pomdp_decide_narrow_s"] = _per_call(lambda i: decide(i, narrow), N_PILES)
    heights = height_image(tops[0])
    result["top_image_px"] = int(heights.shape[0])
    md = header("Chapter 3 (Yamakuzushi) costs, one core", result)
    write_result(out_dir, "ch3", result, md + measure_table(result, tuple(cpu_description())))
    for k, v in result.items():
        print(f"{k}: {v}")
    return result
