"""The physics-from-depth planner's world model in SAPIEN (planning/ch6/physics_depth.py): the
estimated boxes as a settled scene (sim/estimated.py), searched with the search oracle's own
code (`SearchOracle.plan_from`, the trials' own pull, judged as an executed step is) on that
estimated scene instead of the true one; and the scoring of estimates against the truth
(which only the trials, holding the world, can do). The estimated scene itself is
perception/fitted_scenes.py's (the support stage simulates in it too), the figure of estimated
vs true boxes trials/ch6/box_figure.py's.

Nothing here reads the world's state: `EstimatedWorldModel` is built from params, the shelf
and the camera (fixed, known to a robot) and the catalogue of box types; it sees a
`BoxEstimate` and nothing else.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.perception.box_fit import BoxEstimate
from clutterbench.perception.fitted_scenes import scene_of
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.estimated import EstimatedScene
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
        self.pull, self.settle_s = params.pull, params.physics_depth_settle_s
        # the search's node budget is the planner's own (a robot's time per decision)
        self.limits = dataclasses.replace(
            params.search, node_budget=params.physics_depth_node_budget
        )
        self.last: EstimatedScene | None = None

    def scene(self, est: BoxEstimate) -> EstimatedScene:
        self.last = scene_of(est, self.shelf, self.camera, self.physics, self.settle_s)
        return self.last

    def __call__(self, est: BoxEstimate, target: int) -> tuple[list | None, dict[str, Any]]:
        scene = self.scene(est)
        info: dict[str, Any] = {"estimate": scene.info()}
        if target not in scene.kept:
            return None, info | {"target_dropped": True}
        t = scene.kept.index(target)
        oracle = self.search_cls(
            scene.spec, self.physics, self.camera, self.pull, self.limits, self.holding, self.cf
        )
        plan, found, search_info = oracle.plan_from(SceneState.start(scene.spec), t)
        info |= search_info | {"found": found}
        if plan is None:
            return None, info
        # back to the estimate's indices
        return [(scene.kept[p], None if h is None else scene.kept[h]) for (p, h), _ in plan], info


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
    (not estimated: hidden, or too few pixels). Under depth perception an estimate may stand
    on a segment that names no box's own id (perception/seen.py: a second piece of a box, or
    no box): those are counted as `spurious`, compared with nothing."""
    rows = []
    spurious = 0
    for j, box in enumerate(est.ids):
        if not 0 <= box < spec.n:
            spurious += 1
            continue
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
    out = {"n_boxes": spec.n, "missing": spec.n - len(rows), "boxes": rows}
    return out | ({"spurious": spurious} if spurious else {})


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
