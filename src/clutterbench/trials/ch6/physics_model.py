"""The physics-from-depth planner's world model in SAPIEN (planning/ch6/physics_depth.py): the
estimated boxes as a settled scene (sim/estimated.py), searched with the search oracle's own
code (`SearchOracle.plan_from`, the trials' own pull, judged as an executed step is) on that
estimated scene instead of the true one; and the scoring of estimates against the truth
(which only the trials, holding the world, can do).

Nothing here reads the world's state: `EstimatedWorldModel` is built from params, the shelf
and the camera (fixed, known to a robot) and the catalogue of box types; it sees a
`BoxEstimate` and nothing else.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.errors import ClutterbenchError, PerceptionError
from clutterbench.observation import Observation
from clutterbench.perception.box_fit import BoxEstimate, fit_boxes
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.estimated import EstimatedScene, estimated_scene
from clutterbench.sim.geometry import quat_to_matrix
from clutterbench.sim.pull import SceneState
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import Ch6TrialParams


class EstimatedWorldModel:
    """estimate -> settled estimated scene -> the oracle's search over sequences in it."""

    def __init__(
        self,
        shelf: Shelf,
        camera: CameraConfig,
        physics: PhysicsConfig,
        params: Ch6TrialParams,
        holding: bool,
        cf: CollapseFreeConfig,
        search_cls: Any,
    ):
        self.shelf, self.camera, self.physics, self.holding, self.cf = (
            shelf,
            camera,
            physics,
            holding,
            cf,
        )
        self.search_cls = search_cls
        """The search: trials.ch6.SearchOracle, passed in (trials/ch6/episodes.py imports this
        module; importing it back would be a loop)."""
        # the search's node budget is the planner's own (a robot's time per decision)
        self.params = dataclasses.replace(
            params, search_node_budget=params.physics_depth_node_budget
        )
        self.last: EstimatedScene | None = None

    def scene(self, est: BoxEstimate) -> EstimatedScene:
        self.last = scene_of(
            est, self.shelf, self.camera, self.physics, self.params.physics_depth_settle_s
        )
        return self.last

    def __call__(self, est: BoxEstimate, target: int) -> tuple[list | None, dict[str, Any]]:
        scene = self.scene(est)
        info: dict[str, Any] = {"estimate": scene.info()}
        if target not in scene.kept:
            return None, info | {"target_dropped": True}
        t = scene.kept.index(target)
        oracle = self.search_cls(
            scene.spec, self.physics, self.camera, self.params, self.holding, self.cf
        )
        plan, found, search_info = oracle.plan_from(SceneState.start(scene.spec), t)
        info |= search_info | {"found": found}
        if plan is None:
            return None, info
        # back to the estimate's indices
        return [(scene.kept[p], None if h is None else scene.kept[h]) for (p, h), _ in plan], info


def scene_of(
    est: BoxEstimate, shelf: Shelf, camera: CameraConfig, physics: PhysicsConfig, settle_s: float
) -> EstimatedScene:
    """The estimate as a settled scene (sim/estimated.py, whose repair is total); anything a
    world still refuses is this observation's PerceptionError, never the stage's end."""
    try:
        return estimated_scene(est.sizes_m, est.poses, est.ids, shelf, camera, physics, settle_s)
    except PerceptionError:
        raise
    except ClutterbenchError as exc:
        raise PerceptionError(f"estimated scene: {exc}") from None


def fitted_scenes(
    estimate: Any,
    obs: Observation,
    shelf: Shelf,
    camera: CameraConfig,
    physics: PhysicsConfig,
    settle_s: float,
    hypotheses: int = 1,
    noise_m: float = 0.0,
) -> list[EstimatedScene]:
    """The settled scenes fitted to one observation (`scene_of`): the fit of its depth image,
    then `hypotheses - 1` fits of that image with Gaussian noise of `noise_m` on every pixel
    that saw something, as a depth sensor's error could make them. The noise is seeded by
    the image's bytes: the same observation gives the same scenes, in any process. A fit the
    observation gives no model for (a PerceptionError) is left out, so the list may be
    empty."""
    scenes = []
    seed = zlib.crc32(np.ascontiguousarray(obs.depth_m).tobytes())
    for h in range(hypotheses):
        seen = obs
        if h > 0:
            noise = np.random.default_rng([seed, h]).normal(0.0, noise_m, obs.depth_m.shape)
            depth = np.where(obs.depth_m > 0, obs.depth_m + noise, obs.depth_m)
            seen = dataclasses.replace(obs, depth_m=depth.astype(obs.depth_m.dtype))
        try:
            scenes.append(scene_of(estimate(seen), shelf, camera, physics, settle_s))
        except PerceptionError:
            continue
    return scenes


def contact_share(k: int, fits: Sequence[tuple[Sequence[int], Sequence[tuple[int, int]]]]):
    """(K, K) the share of the fitted scenes in which boxes x and y touch; `fits`: per fitted
    scene, where its boxes are (fitted box a is box at[a]; a negative: none of the K) and its
    touching pairs of fitted boxes (sim.labelling.settled_contacts). NaN where no fit holds
    both boxes."""
    touch, both = np.zeros((k, k)), np.zeros((k, k))
    for at, pairs in fits:
        held = [x for x in at if 0 <= x < k]
        both[np.ix_(held, held)] += 1.0
        for a, b in pairs:
            x, y = at[a], at[b]
            if 0 <= x < k and 0 <= y < k:
                touch[x, y] += 1.0
                touch[y, x] += 1.0
    return np.where(both > 0, touch / np.maximum(both, 1.0), np.nan)


def catalogue_of(stream_catalogue: str) -> np.ndarray:
    from clutterbench.sim.catalog import box_extents_m

    return box_extents_m(stream_catalogue)


def make_estimator(catalogue: str, min_pixels: int):
    extents = catalogue_of(catalogue)
    return lambda obs: fit_boxes(obs, extents, min_pixels)


def box_errors(
    est_size: np.ndarray, est_pose: np.ndarray, true_size: np.ndarray, true_pose: np.ndarray
) -> dict[str, float]:
    """Errors of one fitted box against the true one: centre distance (m), size error (mean
    absolute difference of the sorted extents, m), tilt (angle between the axes nearest to
    vertical, degrees) and yaw (about the vertical, of the box's horizontal axes, modulo 90
    degrees since a box's faces repeat every quarter turn)."""
    Re, Rt = quat_to_matrix(est_pose[3:]), quat_to_matrix(true_pose[3:])
    ve, vt = int(np.argmax(np.abs(Re[2]))), int(np.argmax(np.abs(Rt[2])))
    tilt = np.degrees(np.arccos(np.clip(abs(Re[:, ve] @ Rt[:, vt]), 0.0, 1.0)))
    he = Re[:, (ve + 1) % 3]
    ht = Rt[:, (vt + 1) % 3]
    yaw_e, yaw_t = np.arctan2(he[1], he[0]), np.arctan2(ht[1], ht[0])
    d = np.mod(np.degrees(yaw_e - yaw_t), 90.0)
    return {
        "centre_m": float(np.linalg.norm(est_pose[:3] - true_pose[:3])),
        "size_m": float(np.mean(np.abs(np.sort(est_size) - np.sort(true_size)))),
        "tilt_deg": float(tilt),
        "yaw_deg": float(min(d, 90.0 - d)),
    }


def estimate_errors(est: BoxEstimate, spec: SceneSpec, poses: np.ndarray) -> dict[str, Any]:
    """The estimate of one observation against the true boxes at `poses` (all in the scene):
    per estimated box [box, centre mm, size mm, tilt deg, yaw deg], and the boxes missing
    (not estimated: hidden, or too few pixels)."""
    rows = []
    for j, box in enumerate(est.ids):
        e = box_errors(est.sizes_m[j], est.poses[j], spec.sizes_m[box], poses[box])
        rows.append(
            [
                int(box),
                round(1000 * e["centre_m"], 2),
                round(1000 * e["size_m"], 2),
                round(e["tilt_deg"], 2),
                round(e["yaw_deg"], 2),
            ]
        )
    return {"n_boxes": spec.n, "missing": spec.n - est.n, "boxes": rows}


def estimate_record(planner: Any, spec: SceneSpec) -> dict[str, Any]:
    """The physics-from-depth fields of an episode's record: the first estimate scored
    against the canonical start, and per decision whether the estimated scene was at rest,
    and the search's effort."""
    steps = planner.steps
    est = [s.get("estimate", {}) for s in steps]
    return {
        "estimate_start": estimate_errors(planner.first, spec, np.asarray(spec.poses))
        if planner.first is not None
        else None,
        "estimate_not_at_rest": sum(not e.get("at_rest", True) for e in est),
        "estimate_settle_mm": [e.get("settle_move_mm") for e in est],
        # per decision: boxes the repair dropped (sim/estimated.py), of them outside the shelf
        "estimate_dropped": [e.get("dropped") for e in est],
        "estimate_outside": [e.get("outside") for e in est],
        "perception_failed": sum("perception_error" in s for s in steps),
        "search_nodes": sum(
            int(s.get("strict_success_search_nodes", 0)) + int(s.get("success_search_nodes", 0))
            for s in steps
        ),
        "search_exhausted": sum(
            bool(s.get("strict_success_exhausted")) or bool(s.get("success_exhausted"))
            for s in steps
        ),
        "target_missing": sum(bool(s.get("target_missing")) for s in steps),
    }


def estimate_panels(
    stream: str,
    stream_cfg: Any,
    seed: int,
    indices: list[int],
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    min_pixels: int,
) -> list[dict[str, Any]]:
    """The figure's panels (report/box_estimation.py): scenes `indices` of a trial stream at
    their canonical start, the boxes fitted to their first observation beside the true ones."""
    from clutterbench.sim.pull import world_at
    from clutterbench.sim.render import observe
    from clutterbench.trials.core.scenes import draw_trial_spec

    estimator = make_estimator(stream_cfg.catalogue, min_pixels)
    panels = []
    for i in indices:
        spec = draw_trial_spec(stream, stream_cfg, seed, i, physics, camera, max_attempts)
        obs = observe(world_at(spec, SceneState.start(spec), physics, render=True), camera)
        est = estimator(obs)
        errors = estimate_errors(est, spec, np.asarray(spec.poses))
        centre = np.median([b[1] for b in errors["boxes"]]) if errors["boxes"] else float("nan")
        panels.append(
            {
                "depth_m": obs.depth_m,
                "camera": obs.camera,
                "true": (spec.sizes_m, spec.poses),
                "est": (est.sizes_m, est.poses),
                "title": f"{stream} scene {i} ({spec.family})\n{est.n}/{spec.n} boxes "
                f"estimated, median centre error {centre:.1f} mm",
            }
        )
    return panels


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
