"""`make bench`, grouped part: what encoding a scene once for all its targets buys.

Each measure runs the per-pair path (every (scene, target) pair through the whole network,
its depth image loaded and encoded again, as before the grouped path existed) and the
grouped one (models.collapse_map: the depth encoder once per scene; for inference also
BatchNorm folded and, in the ch. 6 planner, a decision's heatmaps reused for its collapse
scores) on the same inputs, in one process on this machine, and reports their ratio:
- training pairs per second (loading + train step) of the default-scale networks on their
  generated training data;
- inference pairs per second of the trials' collapse predictor on validation scenes;
- collapse-prediction seconds per multi-step trial (ch. 6) and per 10-box ch. 4 plan, with
  the trial's calls split into one-target calls (a pull's abort checks, each on a new depth
  image: nothing to share) and several-target calls (a decision's support maps).
Beside each training and inference ratio, its ceiling from the network's arithmetic alone
(forward FLOPs per pair, per-pair / grouped, at the measured pairs per scene; training
costs a fixed multiple of the forward in both paths).
Needs data/generate, data/split and the trained models (dvc repro); skipped without them.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch

from clutterbench.bench import bench_ch6_jobs, header, write_result
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.predict import CollapsePredictor, predict_collapse
from clutterbench.collapse.train import loss_fn, model_seed, train_step
from clutterbench.config import load_params, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.data.dataset import PairDataset, open_pairs
from clutterbench.models import build_model
from clutterbench.platform_info import cpu_description

TRAIN_MODELS = ("cp_focal", "cmn_bs32", "ch4_various")
"""One network per chapter's data: ch. 6, ch. 5, ch. 4 (pairs of masks)."""
TRAIN_BATCHES = 20
"""Timed training batches per path (after one warm-up batch)."""


def _default_params() -> dict[str, Any]:
    params = load_params("params.yaml")
    return {**params, "base": {**params["base"], "scale": "default"}}


def _per_pair_batch(ds: PairDataset, indices: list[int]) -> dict[str, torch.Tensor]:
    """The batch as the per-pair path loaded it: each item on its own (its own copy of the
    depth image, noised apart), stacked."""
    items = [ds[i] for i in indices]
    return {k: torch.stack([item[k] for item in items]) for k in items[0]}


def flop_split(model: Any) -> dict[str, float]:
    """Forward GFLOPs of a collapse_map network: the depth encoder per scene, the decoder's
    per-scene part (its convs' VGG-map halves), its per-target part, and the per-pair
    (concatenated) network."""
    from torch.utils.flop_counter import FlopCounterMode

    model = model.eval()
    size, n_masks, n = int(model.cfg.input_size), int(model.cfg.n_masks), 8

    def gflops(fn: Any) -> float:
        with torch.no_grad(), FlopCounterMode(display=False) as counter:
            fn()
        return counter.get_total_flops() / 1e9

    depth = torch.rand(1, 1, size, size)
    masks = torch.rand(n, n_masks, size, size)
    feats = model.encode(depth)
    encoder = gflops(lambda: model.encode(depth))
    pair = gflops(lambda: model(depth, masks[:1]))  # the concatenated (per-pair) network
    one = gflops(lambda: model.decode(feats, masks[:1], torch.zeros(1, dtype=torch.int64)))
    many = gflops(lambda: model.decode(feats, masks, torch.zeros(n, dtype=torch.int64)))
    per_target = (many - one) / (n - 1)
    return {
        "encoder_gflop": encoder,
        "decoder_scene_gflop": one - per_target,
        "decoder_target_gflop": per_target,
        "pair_gflop": pair,
    }


def ceiling(split: dict[str, float], targets_per_scene: float) -> float:
    """Per-pair / grouped FLOPs per pair at `targets_per_scene`: the most encoding a scene
    once can buy, before any overhead."""
    per_scene = split["encoder_gflop"] + split["decoder_scene_gflop"]
    return split["pair_gflop"] / (per_scene / targets_per_scene + split["decoder_target_gflop"])


def flop_ceiling(model: Any, targets_per_scene: float) -> dict[str, float]:
    """flop_split of `model` and its ceiling at `targets_per_scene`."""
    split = flop_split(model)
    return split | {"ceiling": ceiling(split, targets_per_scene)}


def bench_training(params: dict[str, Any], name: str, batches: int) -> dict[str, float]:
    """Training pairs per second of train.models[name], per-pair vs grouped: the same
    batches, the same initial weights."""
    cfg = load_section(TrainConfig, "train", params)
    gen = load_section(GenerateConfig, "generate", params)
    mcfg = cfg.models[name]
    threshold = gen.datasets[mcfg.dataset].moved_threshold_m
    split = Path(f"data/split/{mcfg.dataset}.json")
    noise = cfg.noise if mcfg.noise else None
    seed = model_seed(0, name)
    out: dict[str, float] = {}
    for path in ("per_pair", "grouped"):
        ds = open_pairs(
            mcfg.net.n_masks,
            Path("data/generate"),
            split,
            "train",
            threshold,
            noise,
            mcfg.flip,
            labels=mcfg.labels,  # one label channel per head, as train.py trains it
            collapse_free=label_thresholds(params),
        )
        torch.manual_seed(seed)
        model = build_model(mcfg.arch, mcfg.net).train()
        if cfg.channels_last:
            model = model.to(memory_format=torch.channels_last)
        opt = torch.optim.Adam(model.parameters(), lr=mcfg.lr)
        loss = loss_fn(cfg, mcfg)
        sampler = iter(ds.group_sampler(mcfg.batch_size, mcfg.scene_group, seed))
        pairs, seconds, scenes = 0, 0.0, 0
        for b in range(batches + 1):
            indices = next(sampler)
            t0 = time.perf_counter()
            if path == "grouped":
                batch = ds.batch(indices)
                scenes += len(batch["depth_m"]) * (b > 0)
            else:
                batch = _per_pair_batch(ds, indices)
            train_step(model, batch, opt, loss, cfg)
            if b:  # the first batch warms up
                seconds += time.perf_counter() - t0
                pairs += len(indices)
        out[f"train_{name}_{path}_pairs_per_s"] = pairs / seconds
        if path == "grouped":
            out[f"train_{name}_pairs_per_scene"] = pairs / max(scenes, 1)
    per_scene = len(ds.pairs) / len(np.unique(ds.pairs[:, 0]))
    split = flop_ceiling(build_model(mcfg.arch, mcfg.net), out[f"train_{name}_pairs_per_scene"])
    out |= {f"train_{name}_{k}": v for k, v in split.items()}
    out[f"train_{name}_targets_per_scene"] = per_scene
    out[f"train_{name}_ceiling_whole_scenes"] = ceiling(split, per_scene)
    out[f"train_{name}_ratio"] = (
        out[f"train_{name}_grouped_pairs_per_s"] / out[f"train_{name}_per_pair_pairs_per_s"]
    )
    return out


def bench_inference(params: dict[str, Any], scenes: int) -> dict[str, float]:
    """Inference pairs per second of the trials' predictor: all visible boxes of a
    validation scene in one call, per-pair vs grouped."""
    from clutterbench.trials.config import TrialsConfig

    trials = load_section(TrialsConfig, "trials", params)
    gen = load_section(GenerateConfig, "generate", params)
    ckpt = Path(f"models/{trials.ch6.model}/best.pt")
    ds = open_pairs(
        1,
        Path("data/generate"),
        Path("data/split/ch6.json"),
        "val",
        gen.datasets["ch6"].moved_threshold_m,
    )
    picks = np.unique(ds.pairs[:, 0])[:scenes]
    inputs = []
    for s in picks:
        rows = np.flatnonzero(ds.pairs[:, 0] == s)
        batch = ds.batch(rows.tolist())
        inputs.append((batch["depth_m"][0, 0].numpy(), batch["target"][:, 0].numpy()))
    out: dict[str, float] = {}
    for path, once in (("per_pair", False), ("grouped", True)):
        predictor = CollapsePredictor.from_checkpoint(ckpt, encode_once=once, fold_bn=once)
        predict_collapse(predictor, *inputs[0])  # warm-up
        predictor.seconds = 0.0
        for depth, masks in inputs:
            predict_collapse(predictor, depth, masks)
        out[f"infer_{path}_pairs_per_s"] = sum(len(m) for _, m in inputs) / predictor.seconds
    out["infer_pairs_per_scene"] = float(np.mean([len(m) for _, m in inputs]))
    model = CollapsePredictor.from_checkpoint(ckpt, fold_bn=False).model
    out["infer_ceiling"] = flop_ceiling(model, out["infer_pairs_per_scene"])["ceiling"]
    out["infer_ratio"] = out["infer_grouped_pairs_per_s"] / out["infer_per_pair_pairs_per_s"]
    return out


def bench_trial_cp(params: dict[str, Any], episodes: int) -> dict[str, float]:
    """Collapse-prediction seconds per multi-step trial (ch6_3_10, the same episodes) and
    per ch. 4 plan of a 10-box pile (all ordered pairs), per-pair vs grouped."""
    from clutterbench.io import read_json
    from clutterbench.planning.ch6.support import SupportParams
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.renderer import ensure_renderer
    from clutterbench.trials.ch6.episodes import run_ch6_episode
    from clutterbench.trials.config import TrialsConfig

    sim = load_section(SimConfig, "sim", params)
    trials = load_section(TrialsConfig, "trials", params)
    support = SupportParams(
        **read_json(Path("reports/support/thresholds.json"))["chosen"]["coverage"]
    )
    model = Path(f"models/{trials.ch6.model}/best.pt")
    ensure_renderer()
    out: dict[str, float] = {}
    for path, once in (("per_pair", False), ("grouped", True)):
        predictor = _use_predictor(model, sim.camera.image_size, once)
        cp_max = support.score_threshold
        jobs = bench_ch6_jobs("multi_step", episodes, trials, sim, support, cp_max, model)
        run_ch6_episode(jobs[0])  # warm-up
        predictor.seconds, wall = 0.0, time.perf_counter()
        with _calls_recorded() as calls:
            for job in jobs:
                run_ch6_episode(job)
        out[f"trial_multi_step_cp_{path}_s"] = predictor.seconds / len(jobs)
        for kind, mine in (
            ("one", [c for c in calls if c[0] == 1]),
            ("several", [c for c in calls if c[0] > 1]),
        ):
            out[f"trial_multi_step_{kind}_target_calls_{path}"] = len(mine) / len(jobs)
            out[f"trial_multi_step_{kind}_target_cp_{path}_s"] = sum(t for _, t in mine) / len(jobs)
        out[f"trial_multi_step_{path}_s"] = (time.perf_counter() - wall) / len(jobs)
    out["trial_multi_step_cp_ratio"] = (
        out["trial_multi_step_cp_per_pair_s"] / out["trial_multi_step_cp_grouped_s"]
    )
    out |= _ch4_plan(params, sim, trials, episodes)
    return out


@contextlib.contextmanager
def _calls_recorded() -> Iterator[list[tuple[int, float]]]:
    """(candidates, seconds) of every collapse-prediction call made inside the block."""
    from clutterbench.collapse import predict

    calls: list[tuple[int, float]] = []
    inner = predict.scene_logits

    def recorded(predictor: CollapsePredictor, depth_m: Any, masks: Any) -> torch.Tensor:
        t0 = time.perf_counter()
        logits = inner(predictor, depth_m, masks)
        calls.append((len(masks), time.perf_counter() - t0))
        return logits

    predict.scene_logits = recorded
    try:
        yield calls
    finally:
        predict.scene_logits = inner


def _use_predictor(model: Path, image_size: int, new: bool) -> CollapsePredictor:
    """Make the trials' workers (trials.harness.load_predictor) use the predictor of this path:
    new = the scene encoded once, BatchNorm folded, a decision's heatmaps reused for its
    collapse scores; old = none of these (the code before them)."""
    from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
    from clutterbench.trials.core import harness

    predictor = CollapsePredictor.from_checkpoint(
        model, image_size=image_size, encode_once=new, fold_bn=new
    )
    harness._PREDICTORS[str(model)] = predictor
    CollapseGraphPlanner.reuse_maps = new
    return predictor


def _ch4_plan(params: dict[str, Any], sim: Any, trials: Any, piles: int) -> dict[str, float]:
    from clutterbench.data.trial_scenes import draw_trial_spec
    from clutterbench.perception.masks import masks_from_instance
    from clutterbench.planning.ch4.risk_planner import plan_risk
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.render import observe

    model = Path(f"models/{trials.ch6.ch4_model}/best.pt")
    scenes = []
    for i in range(piles):
        spec = draw_trial_spec(
            "bench", trials.streams["ch4_same_10"], 99, i, sim.physics, sim.camera, 30
        )
        obs = observe(BoxWorld.from_spec(spec, sim.physics, render=True), sim.camera)
        scenes.append((obs, masks_from_instance(obs, trials.ch4.min_pixels)))
    out: dict[str, float] = {}
    for path, once in (("per_pair", False), ("grouped", True)):
        predictor = _use_predictor(model, sim.camera.image_size, once)
        plan_risk(predictor, *scenes[0], None, trials.ch4.pixel_threshold)  # warm-up
        predictor.seconds = 0.0
        for obs, seg in scenes:
            plan_risk(predictor, obs, seg, None, trials.ch4.pixel_threshold)
        out[f"ch4_plan_10_objects_cp_{path}_s"] = predictor.seconds / len(scenes)
    out["ch4_plan_10_objects_cp_ratio"] = (
        out["ch4_plan_10_objects_cp_per_pair_s"] / out["ch4_plan_10_objects_cp_grouped_s"]
    )
    return out


def _paper_flops(targets_per_scene: float) -> dict[str, float]:
    """cp_focal's FLOP split at paper scale (full VGG-16, 256 px): arithmetic only."""
    params = load_params("params.yaml")
    params = {**params, "base": {**params["base"], "scale": "paper"}}
    mcfg = load_section(TrainConfig, "train", params).models["cp_focal"]
    net = build_model(mcfg.arch, mcfg.net)
    out = {f"paper_cp_focal_{k}": v for k, v in flop_ceiling(net, targets_per_scene).items()}
    out["paper_cp_focal_targets_per_scene"] = targets_per_scene
    return out


def bench_grouped(
    out_dir: Path = Path("reports/bench"),
    batches: int = TRAIN_BATCHES,
    scenes: int = 20,
    episodes: int = 8,
) -> dict[str, Any] | None:
    params = _default_params()
    needed = [Path("data/split/ch6.json"), Path("reports/support/thresholds.json")]
    needed += [Path(f"models/{m}/best.pt") for m in ("cp_focal", "ch4_various")]
    missing = [str(p) for p in needed if not p.exists()]
    if missing:
        print(f"bench grouped: skipped ({', '.join(missing)} missing; run dvc repro first)")
        return None
    torch.set_num_threads(2)
    result: dict[str, Any] = {}
    for name in TRAIN_MODELS:
        result |= bench_training(params, name, batches)
    result |= _paper_flops(result["train_cp_focal_targets_per_scene"])
    result |= bench_inference(params, scenes)
    torch.set_num_threads(1)  # as a trials worker
    result |= bench_trial_cp(params, episodes)
    result |= cpu_description()
    write_result(out_dir, "grouped", result, _markdown(result))
    for k, v in result.items():
        print(f"{k}: {v}")
    return result


def _markdown(r: dict[str, Any]) -> list[str]:
    lines = header("Scene encoded once vs per pair (default scale)", r)
    lines += [
        "Same inputs, same process; per-pair = every (scene, target) pair loaded and encoded",
        "on its own (the path before grouping). Training and inference at 2 threads, trials",
        "at 1 (as a trials worker). FLOP ceiling: per-pair / grouped forward FLOPs per pair at",
        "the same pairs per scene, the most encoding once can buy before any overhead.",
        "",
        "| measure | per pair | grouped | ratio | FLOP ceiling |",
        "|---|---|---|---|---|",
    ]
    for name in TRAIN_MODELS:
        lines.append(
            f"| train {name}, pairs/s ({r[f'train_{name}_pairs_per_scene']:.1f} pairs per "
            f"scene in a batch) | {r[f'train_{name}_per_pair_pairs_per_s']:.1f} | "
            f"{r[f'train_{name}_grouped_pairs_per_s']:.1f} | {r[f'train_{name}_ratio']:.2f}x "
            f"| {r[f'train_{name}_ceiling']:.2f}x |"
        )
    lines.append(
        f"| inference, pairs/s ({r['infer_pairs_per_scene']:.1f} targets per scene) | "
        f"{r['infer_per_pair_pairs_per_s']:.1f} | {r['infer_grouped_pairs_per_s']:.1f} | "
        f"{r['infer_ratio']:.2f}x | {r['infer_ceiling']:.2f}x |"
    )
    lines.append(
        f"| collapse prediction per multi-step trial, s | "
        f"{r['trial_multi_step_cp_per_pair_s']:.3f} | {r['trial_multi_step_cp_grouped_s']:.3f} "
        f"| {r['trial_multi_step_cp_ratio']:.2f}x less | |"
    )
    for kind, what in (
        ("one", "one-target calls (abort checks)"),
        ("several", "several-target calls (support maps)"),
    ):
        lines.append(
            f"| - of which {what}: calls per trial / s | "
            f"{r[f'trial_multi_step_{kind}_target_calls_per_pair']:.1f} / "
            f"{r[f'trial_multi_step_{kind}_target_cp_per_pair_s']:.3f} | "
            f"{r[f'trial_multi_step_{kind}_target_calls_grouped']:.1f} / "
            f"{r[f'trial_multi_step_{kind}_target_cp_grouped_s']:.3f} | | |"
        )
    lines.append(
        f"| multi-step trial, wall s | {r['trial_multi_step_per_pair_s']:.3f} | "
        f"{r['trial_multi_step_grouped_s']:.3f} | | |"
    )
    lines.append(
        f"| collapse prediction per ch. 4 plan (10 boxes, all ordered pairs), s | "
        f"{r['ch4_plan_10_objects_cp_per_pair_s']:.3f} | "
        f"{r['ch4_plan_10_objects_cp_grouped_s']:.3f} | "
        f"{r['ch4_plan_10_objects_cp_ratio']:.2f}x less | |"
    )
    lines += [
        "",
        "Forward GFLOPs per pair (FlopCounterMode): depth encoder per scene, decoder part per",
        "scene (its convs' VGG-map halves), decoder part per target (mask encoder included);",
        "the ceiling if every batch held all of a scene's targets (the dataset's mean):",
        "",
        "| network | encoder / scene | decoder / scene | decoder / target | per-pair network "
        "| targets per scene | ceiling, whole scenes |",
        "|---|---|---|---|---|---|---|",
    ]
    rows = [(name, f"train_{name}") for name in TRAIN_MODELS]
    for name, key in [*rows, ("cp_focal, paper scale", "paper_cp_focal")]:
        whole = "ceiling" if key.startswith("paper") else "ceiling_whole_scenes"
        lines.append(
            f"| {name} | {r[f'{key}_encoder_gflop']:.3f} | "
            f"{r[f'{key}_decoder_scene_gflop']:.3f} | "
            f"{r[f'{key}_decoder_target_gflop']:.3f} | {r[f'{key}_pair_gflop']:.3f} "
            f"| {r[f'{key}_targets_per_scene']:.1f} | {r[f'{key}_{whole}']:.2f}x |"
        )
    return lines


if __name__ == "__main__":
    bench_grouped()
