"""Recheck: object masks from depth alone, under sensor noise. How many visible boxes does each
depth segmentation find, on exact depth and on noisy depth?

    python -m experiments.depth_masks     # settings: the constants below (not in params.yaml)

Scenes: the first SCENES start scenes of the dev stream STREAM (settled as the ch. 6 trials
settle them, base.seed; never a table's stream), rendered at the sim's image size (and
OTHER_SCENES of them at each of OTHER_SIZES). Each depth image is segmented as it is and under
each noise model of NOISE_MODELS (seeded per scene): the training's augmentation
(sim/noise.py's defaults), a stereo-like model, and sim/sensor.py's presets. Two methods:
`depth` (perception/depth_segmentation.py, the trials' `depth` masks) and `region_growing`
(perception/region_growing.py). A visible box (>= MIN_PIXELS pixels in the instance image) is
found when a segment covers it with IoU > 0.5 (one to one, as IoU > 0.5 is); a box is
over-segmented when two segments each hold >= 20% of it, a segment under-segments when it holds
>= 20% of each of two boxes. Writes experiments/reports/depth_masks.{json,md}; not a dvc stage.

RegionGrowingParams' defaults were chosen on scenes 60-119 of the same stream, never on the
scenes measured here.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from clutterbench.config import as_dict, load_section
from clutterbench.errors import ClutterbenchError
from experiments.command import OUT, run_command, save
from experiments.config import check_dev_streams, load_dev

NAME = "depth_masks"
STREAM = "dev_ch6_3_10"
"""The dev stream (dev.streams of experiments/params.yaml): ch. 6's 3-10 box families."""
SCENES = 60
"""Start scenes measured, at the sim's image size (scenes 0 .. SCENES - 1)."""
OTHER_SIZES = (64, 256)
"""Further image sizes (px), to show that one setting serves every size ..."""
OTHER_SCENES = 20
"""... on this many of the same scenes."""
MIN_PIXELS = 20
"""A visible box, and the smallest segment (masks.DEFAULT_MIN_PIXELS)."""
NOISE_SEED = 7
"""Seeds the noise of every image (with the scene's index and the model's)."""
SHARE = 0.2
"""A part of a box (or of a segment) counts for over- and under-segmentation from this share."""
METHODS = ("depth", "region_growing")
COUNTS = ("visible", "found", "segments", "over", "under", "stray", "returned", "found_returned")


def exact(depth_m: np.ndarray, camera: Any, rng: np.random.Generator) -> np.ndarray:
    """The renderer's depth, as it is."""
    return depth_m


def training_noise(depth_m: np.ndarray, camera: Any, rng: np.random.Generator) -> np.ndarray:
    """The training's augmentation (sim/noise.py, its defaults: 1 mm + 0.002 d^2 Gaussian, 0.5%
    dropout)."""
    from clutterbench.sim.noise import DepthNoiseConfig, add_depth_noise

    return add_depth_noise(depth_m, DepthNoiseConfig(), rng)


def stereo_like(depth_m: np.ndarray, camera: Any, rng: np.random.Generator) -> np.ndarray:
    """2 mm + 0.004 d^2 Gaussian, 2% dropout, and half the pixels beside a depth step of more
    than 1 cm (to a 4-neighbour, on the exact image) dropped."""
    d = depth_m.astype(np.float64)
    noisy = d + rng.standard_normal(d.shape) * (0.002 + 0.004 * d**2)
    step = np.zeros(d.shape, dtype=bool)
    for axis in (0, 1):
        jump = np.abs(np.diff(d, axis=axis)) > 0.01
        lo, hi = [slice(None)] * 2, [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        step[tuple(lo)] |= jump
        step[tuple(hi)] |= jump
    drop = (rng.random(d.shape) < 0.02) | (step & (rng.random(d.shape) < 0.5))
    noisy[drop | (depth_m <= 0)] = 0.0
    return noisy.astype(np.float32)


def sensor_preset(name: str) -> Callable[[np.ndarray, Any, np.random.Generator], np.ndarray]:
    """sim/sensor.py's preset `name`, seeded by observation_rng (NOISE_SEED, the image)."""

    def model(depth_m: np.ndarray, camera: Any, rng: np.random.Generator) -> np.ndarray:
        from clutterbench.sim import sensor

        noise_rng = sensor.observation_rng(NOISE_SEED, depth_m)
        return sensor.sense(depth_m, camera, sensor.preset(name), noise_rng)

    return model


NOISE_MODELS: dict[str, Callable[[np.ndarray, Any, np.random.Generator], np.ndarray]] = {
    "exact": exact,
    "training": training_noise,
    "stereo_like": stereo_like,
    "structured_light": sensor_preset("structured_light"),
    "d415": sensor_preset("d415"),
}


def score(labels: np.ndarray, instance: np.ndarray, depth_m: np.ndarray) -> dict[str, int]:
    """One image's counts (COUNTS): visible boxes, those found (IoU > 0.5), segments, boxes
    over-segmented, segments under-segmenting, segments matching no box (stray); visible boxes
    with MIN_PIXELS pixels that the depth image `depth_m` returns (the rest lie mostly in a
    shadow or a step's gap: depth alone cannot see them), and those of them found."""
    k = int(labels.max(initial=0))
    table = np.bincount(
        labels.ravel().astype(np.int64) * 256 + instance.ravel(), minlength=(k + 1) * 256
    ).reshape(k + 1, 256)
    box_px, seg_px = table.sum(axis=0), table.sum(axis=1)
    boxes = np.flatnonzero(box_px[1:] >= MIN_PIXELS) + 1
    inter = table[1:][:, boxes]
    iou = inter / np.maximum(seg_px[1:, None] + box_px[None, boxes] - inter, 1)
    share = inter / box_px[None, boxes]
    found = iou.max(axis=0, initial=0.0) > 0.5
    returns = np.bincount(instance.ravel(), weights=(depth_m > 0).ravel(), minlength=256)
    returned = returns[boxes] >= MIN_PIXELS
    return {
        "visible": int(boxes.size),
        "found": int(found.sum()),
        "segments": k,
        "over": int(((share >= SHARE).sum(axis=0) >= 2).sum()),
        "under": int(((share >= SHARE).sum(axis=1) >= 2).sum()),
        "stray": int((iou.max(axis=1, initial=0.0) <= 0.5).sum()),
        "returned": int(returned.sum()),
        "found_returned": int((found & returned).sum()),
    }


def segmenters(min_pixels: int) -> dict[str, Callable[[Any, Any], np.ndarray]]:
    """Method name -> labels of (observation, ROI), at the methods' default params."""
    from clutterbench.perception.depth_segmentation import DepthSegmentationParams, segment_depth
    from clutterbench.perception.region_growing import RegionGrowingParams, segment_regions

    return {
        "depth": lambda obs, roi: segment_depth(obs, roi, DepthSegmentationParams(), min_pixels),
        "region_growing": lambda obs, roi: segment_regions(
            obs, roi, RegionGrowingParams(), min_pixels
        ),
    }


def start_views(params: Mapping[str, Any], scenes: int, size_px: int | None) -> list[Any]:
    """(observation, ROI) of the first `scenes` start scenes of STREAM, as the ch. 6 trials draw
    them (trials.ch6.episodes.ch6_jobs, job_spec), at image size `size_px` (None: the sim's)."""
    from clutterbench.config import BaseConfig
    from clutterbench.perception.depth_segmentation import shelf_roi
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.pull import SceneState, world_at
    from clutterbench.sim.render import observe
    from clutterbench.trials.ch6.episodes import ch6_jobs, job_spec
    from clutterbench.trials.config import ConditionConfig, TrialsConfig

    dev = load_dev(params)
    trials = load_section(TrialsConfig, "trials", params)
    check_dev_streams(dev, trials)
    if STREAM not in dev.streams:
        raise ClutterbenchError(f"dev.streams: no stream {STREAM} (experiments/params.yaml)")
    sim = load_section(SimConfig, "sim", params)
    if size_px is not None:
        sim = dataclasses.replace(sim, camera=dataclasses.replace(sim.camera, image_size=size_px))
    jobs = ch6_jobs(
        f"{NAME}/{STREAM}",
        ConditionConfig(planner="oracle", stream=STREAM, episodes=scenes),
        trials=trials,
        sim=sim,
        seed=load_section(BaseConfig, "base", params).seed,
        support=None,
        cp_max=0.0,
        model_path=OUT / "unused",
        stream_cfg=dev.streams[STREAM],
    )
    views = []
    for job in jobs:
        spec = job_spec(job)
        world = world_at(spec, SceneState.start(spec), job.physics, render=True)
        views.append((observe(world, job.camera), shelf_roi(spec.shelf)))
    return views


def measure(views: list[Any], models: Mapping[str, Callable]) -> list[dict[str, Any]]:
    """One row per (noise model, method): COUNTS summed over `views`, and mean ms per image."""
    methods = segmenters(MIN_PIXELS)
    rows = []
    for m, (model_name, model) in enumerate(models.items()):
        totals = {name: dict.fromkeys(COUNTS, 0) | {"seconds": 0.0} for name in methods}
        for i, (obs, roi) in enumerate(views):
            rng = np.random.default_rng([NOISE_SEED, i, m])
            noisy = dataclasses.replace(obs, depth_m=model(obs.depth_m, obs.camera, rng))
            for name, segment in methods.items():
                started = time.perf_counter()
                labels = segment(noisy, roi)
                totals[name]["seconds"] += time.perf_counter() - started
                for key, value in score(labels, obs.instance, noisy.depth_m).items():
                    totals[name][key] += value
        for name, t in totals.items():
            rows.append(
                {"noise": model_name, "method": name, "images": len(views)}
                | {k: t[k] for k in COUNTS}
                | {
                    "found_share": t["found"] / max(t["visible"], 1),
                    "found_returned_share": t["found_returned"] / max(t["returned"], 1),
                    "ms_per_image": 1000 * t["seconds"] / max(len(views), 1),
                }
            )
    return rows


def recheck(params: Mapping[str, Any]) -> dict[str, Any]:
    from clutterbench.perception.region_growing import RegionGrowingParams
    from clutterbench.sim.config import SimConfig

    started = time.perf_counter()
    size = load_section(SimConfig, "sim", params).camera.image_size
    rows = [r | {"size_px": size} for r in measure(start_views(params, SCENES, None), NOISE_MODELS)]
    for other in OTHER_SIZES:
        views = start_views(params, OTHER_SCENES, other)
        rows += [r | {"size_px": other} for r in measure(views, NOISE_MODELS)]
    main = {(r["noise"], r["method"]): r for r in rows if r["size_px"] == size}
    worst = min(main[(n, "region_growing")]["found_share"] for n in NOISE_MODELS if n != "exact")
    result = {
        "stream": STREAM,
        "scenes": SCENES,
        "other_sizes": list(OTHER_SIZES),
        "other_scenes": OTHER_SCENES,
        "min_pixels": MIN_PIXELS,
        "noise_seed": NOISE_SEED,
        "region_growing_params": as_dict(RegionGrowingParams()),
        "rows": rows,
    }
    result["shows"] = (
        f"region_growing finds {100 * main[('exact', 'region_growing')]['found_share']:.1f}% of "
        f"visible boxes on exact depth (depth: {100 * main[('exact', 'depth')]['found_share']:.1f}"
        f"%) and at least {100 * worst:.1f}% under every noise model (depth: at most "
        f"{100 * max(main[(n, 'depth')]['found_share'] for n in NOISE_MODELS if n != 'exact'):.1f}"
        f"%), {SCENES} scenes of {STREAM} at {size} px; of the boxes a sensor returns "
        f"{MIN_PIXELS} px of, it finds "
        + ", ".join(
            f"{100 * main[(n, 'region_growing')]['found_returned_share']:.1f}% ({n})"
            for n in NOISE_MODELS
            if n != "exact"
        )
    )
    return save(result, started, OUT, NAME, markdown)


def markdown(result: Mapping[str, Any]) -> str:
    lines = [
        "# Object masks from depth alone, under sensor noise",
        "",
        "`python -m experiments.depth_masks` (experiments/depth_masks.py): the first "
        f"{result['scenes']} start scenes of `{result['stream']}` (and {result['other_scenes']} "
        f"at {', '.join(str(s) for s in result['other_sizes'])} px), each segmented from exact "
        "depth and under each noise model by `depth` (perception/depth_segmentation.py) and "
        "`region_growing` (perception/region_growing.py). Found: a visible box (>= "
        f"{result['min_pixels']} px) covered by a segment with IoU > 0.5; over: boxes split into "
        "two segments of >= 20% each; under: segments holding >= 20% of two boxes; stray: "
        "segments matching no box; returned: visible boxes of which the noisy image has >= "
        f"{result['min_pixels']} px with depth (the rest lie mostly in a shadow or a step's "
        "gap, out of depth's reach). RegionGrowingParams' defaults were chosen on scenes 60-119 "
        "of the same stream.",
        "",
        f"**{result['shows']}.** Wall time {result['seconds'] / 60:.1f} min.",
        "",
        "| px | noise | method | found / visible | found | segments | over | under | stray "
        "| found / returned | found of returned | ms / image |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['size_px']} | {r['noise']} | {r['method']} | {r['found']} / {r['visible']} "
            f"| {100 * r['found_share']:.1f}% | {r['segments']} | {r['over']} | {r['under']} "
            f"| {r['stray']} | {r['found_returned']} / {r['returned']} "
            f"| {100 * r['found_returned_share']:.1f}% | {r['ms_per_image']:.1f} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    run_command(recheck, NAME)
