"""Table 6.2's physics-from-depth row (stage support): each test scene's boxes fitted to its
depth image and settled (perception/fitted_scenes.py, the physics-from-depth planners' model),
every visible box lifted out of that estimated scene, and what moved read as support edges
through the oracle-map row's rule and thresholds, so that the two rows differ only in where
the removals were simulated.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from clutterbench.errors import PerceptionError
from clutterbench.observation import Observation
from clutterbench.perception.fitted_scenes import make_estimator, scene_of
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.shelf import Shelf

SUPPORT_METHOD = "physics_from_depth"
"""Table 6.2's row of support edges from removals simulated in the estimated scene."""
SUPPORT_RULE = "oracle_coverage_gap"
"""Its rule and thresholds: the oracle-map row's (the true moved masks through the trials'
rule), so that the two rows differ only in where the removals were simulated."""


def estimated_moved(
    obs: Observation,
    ids: list[int],
    catalogue: str,
    min_pixels: int,
    shelf: Shelf,
    camera: CameraConfig,
    physics: PhysicsConfig,
    settle_s: float,
    threshold_m: float,
) -> tuple[np.ndarray, dict[str, Any]]:
    """(K, K) bool over the visible boxes `ids`: ids[b] moved beyond the threshold when ids[a]
    was lifted out of the estimated scene (fitted to `obs`, settled), each removal from a
    fresh world at the settled estimate, as the dataset labels are; boxes not estimated move
    nothing and are moved by nothing. And the estimated scene's info."""
    from clutterbench.sim.physics import BoxWorld

    est = make_estimator(catalogue, min_pixels)(obs)
    scene = scene_of(est, shelf, camera, physics, settle_s)
    box_ids = [int(b) for b in scene.spec.meta["ids"]]
    at = {b: ids.index(b) for b in box_ids if b in ids}
    moved = np.zeros((len(ids), len(ids)), dtype=bool)
    for a, box in enumerate(box_ids):
        if box not in at:
            continue
        world = BoxWorld.from_spec(scene.spec, physics)
        disp = np.nan_to_num(world.lift_out(a).displacement_m, nan=0.0)
        for b, other in enumerate(box_ids):
            if b != a and other in at and disp[b] > threshold_m:
                moved[at[box], at[other]] = True
    return moved, scene.info()


class PhysicsDepthSupport:
    """Table 6.2's physics-from-depth row for the support stage's test scenes: support edges
    from `estimated_moved` through the oracle-map row's rule and thresholds."""

    def __init__(self, cfg: Any, sim: Any, params: Any, settle_s: float):
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.render import camera_model

        self.cfg, self.sim, self.params, self.settle_s = cfg, sim, params, settle_s
        self.shelf = Shelf()
        # the fixed camera of every test scene (rendered from the same config)
        self.camera = camera_model(BoxWorld(self.shelf, sim.physics, render=True), sim.camera)
        self.not_at_rest = 0

    def row(self, scene: Any) -> dict[str, Any]:
        """The scene's row of scenes.csv; a perception failure (PerceptionError) is recorded in
        it (`perception_failed`, nothing inferred), never raised."""
        from clutterbench.planning.ch6.support import (
            edge_precision_recall,
            infer_support,
            oracle_heatmaps,
        )

        instance = np.zeros(scene.depth_m.shape, dtype=np.uint8)
        for k, box in enumerate(scene.ids):
            instance[scene.masks[k]] = box + 1
        obs = Observation(depth_m=scene.depth_m, instance=instance, camera=self.camera)
        pred: set[tuple[int, int]] = set()
        info: dict[str, Any] = {}
        failed = 0
        if len(scene.ids) > 1:
            try:
                moved, info = estimated_moved(
                    obs,
                    scene.ids,
                    self.cfg.test.catalogue,
                    self.cfg.min_pixels,
                    self.shelf,
                    self.sim.camera,
                    self.sim.physics,
                    self.settle_s,
                    self.cfg.moved_threshold_m,
                )
            except PerceptionError:
                failed = 1
            else:
                self.not_at_rest += not info["at_rest"]
                heat = oracle_heatmaps(moved, scene.masks)
                found = infer_support(heat, scene.masks, scene.ids, self.params, scene.gaps_m)
                pred = {(e.supporter, e.supported) for e in found}
        truth = scene.true_edges
        precision, recall = edge_precision_recall(pred, truth)
        return {
            "scene": scene.index,
            "family": scene.family,
            "n_objects": scene.n_objects,
            "visible": len(scene.ids),
            "method": SUPPORT_METHOD,
            "n_true": len(truth),
            "n_pred": len(pred),
            "tp": len(pred & truth),
            "precision": precision,
            "recall": recall,
            "est_dropped": int(info.get("dropped", 0)),
            "est_outside": int(info.get("outside", 0)),
            "perception_failed": failed,
        }
