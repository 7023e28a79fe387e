"""Physics from depth (planning/ch6/physics_depth.py): the training-free baseline the
learned planners are paired against: boxes fitted to each observation, searched in SAPIEN by
the oracle's code, one arm and holding."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

from clutterbench.trials.ch6.planners._registry import register_planner

if TYPE_CHECKING:
    from clutterbench.sim.spec import SceneSpec
    from clutterbench.trials.ch6.jobs import Ch6Job

FITTED = {"world": "fitted", "cost": "search"}


def physics_from_depth_planner(job: Ch6Job, spec: SceneSpec, holding: bool):
    """The physics-from-depth planner (planning/ch6/physics_depth.py): boxes fitted to each
    observation, searched in SAPIEN by the oracle's code on that estimate, with the action
    set of the oracle it mirrors (`holding`: oracle_hold's, a box may be held during any
    pull). Of the episode's spec it gets the shelf only (fixed, a robot knows it); of its
    stream the catalogue."""
    from clutterbench.perception.fitted_scenes import make_estimator
    from clutterbench.planning.ch6.physics_depth import PhysicsFromDepthPlanner
    from clutterbench.trials.ch6.oracle import SearchOracle
    from clutterbench.trials.ch6.physics_model import EstimatedWorldModel

    params = job.params
    model = EstimatedWorldModel(
        spec.shelf,
        job.camera,
        job.physics,
        params,
        holding,
        job.collapse_free,
        functools.partial(SearchOracle, hold_any_pull=True),
    )
    estimate = make_estimator(job.stream_cfg.catalogue, params.min_pixels)
    return PhysicsFromDepthPlanner(estimate, model, holding)


@register_planner(
    "physics_from_depth",
    label="physics from depth: search on boxes fitted to the depth image, one arm",
    **FITTED,
)
def _pfd(job: Ch6Job, spec: SceneSpec):
    return physics_from_depth_planner(job, spec, holding=False)


@register_planner(
    "physics_from_depth_hold", label="physics from depth, may hold one box", holds=True, **FITTED
)
def _pfd_hold(job: Ch6Job, spec: SceneSpec):
    return physics_from_depth_planner(job, spec, holding=True)
