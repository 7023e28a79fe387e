"""The leaderboard's baseline predictors (stage testset), each a scorecard PredictFn: a
constant 1/2 (no information), the truth of deleting the box (the thesis' labels, asked what
pulling does), the collapse predictor's heads read per box, the box head, physics from depth
(the trials' pull simulated in the boxes fitted to the depth image, no training), and the
pull's own truth (the ceiling).

The scorer asks about one pulled box at a time; the network and physics baselines answer for
every box of a scene at once (one batch, one fit) and keep that scene's answers (per_scene)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.collapse.box_head import OUTPUTS
from clutterbench.collapse.box_predict import BoxMaps
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.data.testset_load import labels, visible
from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint
from clutterbench.sim.config import CameraConfig, SimConfig
from clutterbench.support.scorecard import PredictFn


def constant(_depth, masks, _cam, _i) -> np.ndarray:
    return np.full(len(masks), 0.5)


def truth_of(ts: dict, kind: str) -> PredictFn:
    """The labels of `kind` as a predictor (scene found by its depth image)."""
    lab = labels(ts, kind)
    scene_of = {ts["depth_m"][s].astype(np.float32).tobytes(): s for s in range(len(lab))}

    def predict(depth, masks, _cam, i):
        s = scene_of[depth.tobytes()]
        ids = visible(ts, s)
        return lab[s, ids[i], ids].astype(np.float64)

    return predict


def per_scene(answer_all: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]) -> PredictFn:
    """A PredictFn from a function answering for every pulled box of a scene at once (row i:
    pulling box i), called once per scene (the scorer asks a scene's boxes in turn)."""
    last: dict[str, object] = {"key": None, "value": None}

    def predict(depth, masks, cam, i):
        key = (depth.tobytes(), masks.tobytes())
        if last["key"] != key:
            last["key"], last["value"] = key, answer_all(depth, masks, cam)
        return last["value"][i]

    return predict


def cp_head(model: Path, image_size: int, head: str) -> PredictFn:
    """The collapse predictor's `head` map of pulling the box (read per box by the scorer);
    every box of a scene in one batch."""
    predictor = CollapsePredictor.from_checkpoint(model, image_size=image_size, head=head)
    return per_scene(lambda depth, masks, _cam: predictor(depth, masks.astype(np.uint8)))


def box_head(model: Path, box: Path, camera: CameraConfig) -> PredictFn:
    """The box head's probability that pulling the box collapses each other one."""
    maps = BoxMaps.from_paths(model, box, camera, "pull_collapse", 0.5)
    out = OUTPUTS.index("pull_collapse")
    return per_scene(
        lambda depth, masks, _cam: maps.probs(depth, masks)[:, :, out].astype(np.float64)
    )


def physics_from_depth(
    sim: SimConfig, ch6: Any, catalogue: str, min_pixels: int, thresholds: dict
) -> PredictFn:
    """Physics from depth (the trials' physics_from_depth planners' model, no training): the
    boxes fitted to the depth image and masks, settled (perception/fitted_scenes.py), each
    visible box pulled out of them by the trials' executor (sim.labelling.pull_outcomes, the
    labels' own code path) -> 1 for each box the pull collapses there (left the shelf, dropped
    or tipped beyond the test set's thresholds), else 0; a box not fitted: 0; a scene the fit
    fails on: 0 for every box."""
    from clutterbench.errors import PerceptionError
    from clutterbench.observation import Observation
    from clutterbench.perception.fitted_scenes import make_estimator, scene_of
    from clutterbench.sim.labelling import pull_outcomes
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.render import camera_model
    from clutterbench.sim.shelf import Shelf

    shelf = Shelf()
    camera = camera_model(BoxWorld(shelf, sim.physics, render=True), sim.camera)
    estimate = make_estimator(catalogue, min_pixels)
    pull = (ch6.pull_increment_m, ch6.grasp_lift_m)

    def answer_all(depth, masks, _cam):
        k = len(masks)
        instance = np.zeros(depth.shape, dtype=np.uint8)
        for j, m in enumerate(masks):
            instance[m] = j + 1
        out = np.zeros((k, k))
        try:
            scene = scene_of(
                estimate(Observation(depth_m=depth, instance=instance, camera=camera)),
                shelf,
                sim.camera,
                sim.physics,
                ch6.physics_depth_settle_s,
            )
        except PerceptionError:
            return out
        po = pull_outcomes(scene.spec, sim.physics, pull)
        collapse = (
            (np.nan_to_num(po.drop_m) > thresholds["drop_m"])
            | (np.nan_to_num(po.tilt_deg) > thresholds["tilt_deg"])
            | po.left_shelf
        )
        at = [int(b) for b in scene.spec.meta["ids"]]  # fitted box a is mask at[a]
        for a, x in enumerate(at):
            for b, y in enumerate(at):
                if a != b and x < k and y < k:
                    out[x, y] = float(collapse[a, b])
        return out

    return per_scene(answer_all)


def baselines(
    ts: dict, model: Path, box: Path, sim: SimConfig, physics: tuple | None = None
) -> dict[str, tuple[Callable[[], PredictFn], str]]:
    """name -> (a factory of its PredictFn, what it is). `physics`: (trials.ch6, catalogue,
    min_pixels) for the physics-from-depth row (None: no such row)."""
    camera = sim.camera
    heads = checkpoint_heads(load_checkpoint(model))
    out: dict[str, tuple[Callable[[], PredictFn], str]] = {
        "constant": (lambda: constant, "1/2 for every box: no information"),
        "deletion_truth": (
            lambda: truth_of(ts, "deletion_moved"),
            "physics truth of deleting the box (the thesis' labels), asked what pulling does",
        ),
    }
    for h in heads:
        out[f"cp_{h}"] = (
            lambda h=h: cp_head(model, camera.image_size, h),
            f"the collapse predictor's {h} head, its mean over each box",
        )
    out["box_head"] = (
        lambda: box_head(model, box, camera),
        "the box head (per box, over the collapse predictor's maps)",
    )
    if physics is not None:
        ch6, catalogue, min_pixels = physics
        thresholds = ts["manifest"]["thresholds"]
        out["physics_from_depth"] = (
            lambda: physics_from_depth(sim, ch6, catalogue, min_pixels, thresholds),
            "the trials' pull simulated in the boxes fitted to the depth image (no training)",
        )
    out["pull_truth"] = (
        lambda: truth_of(ts, "pull_collapse"),
        "physics truth of what the pull collapses: the ceiling",
    )
    return out
