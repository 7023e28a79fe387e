"""Algorithm 1 (multi-step extraction on a collapse-prediction graph), one arm and with the
bimanual hold (Fig. 6.7): on the collapse predictor's deletion head (the thesis' method), on
its pull head (`*_pull`: maps of the trials' pull, learnt from pull labels), and on
physics-truth maps of deleting a box or of the trials' pull (`*_truth`, `*_pull_truth`: the
perception ceilings, trials/ch6/truth_maps.py)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from clutterbench.data.trial_params import PULL_MAP_HEADS
from clutterbench.trials.ch6.planners._registry import register_planner

if TYPE_CHECKING:
    from clutterbench.sim.spec import SceneSpec
    from clutterbench.trials.ch6.jobs import Ch6Job

ONE_ARM = {"baseline": "physics_from_depth"}
HOLDING = {"holds": True, "baseline": "physics_from_depth_hold"}
PREDICTED = {"networks": frozenset({"cp"}), "cost": "network"}
TRUTH = {"world": "truth", "cost": "search"}


def load_predictor(path, image_size, head="deletion"):
    """The collapse predictor's `head` (trials/core/harness.py; a name tests can replace)."""
    from clutterbench.trials.core.harness import load_predictor as load

    return load(path, image_size, head)


def cpg_planner(job: Ch6Job, bimanual: bool, spec: SceneSpec | None = None, pull: bool = False):
    """Algorithm 1 with the collapse predictor, or (`spec` given) with physics-truth maps of
    that scene through the same interface (`pull`: maps of the trials' pull, else of
    deleting the box; the bimanual plan clears the held box's load first and an abort teaches
    the graph what it feared for, trials.ch6.abort_response): the same planner and
    rule. `pull` without `spec`: the collapse predictor's pull head, with the thresholds
    chosen for it (the job's `support`, Planner.support_method)."""
    from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
    from clutterbench.trials.ch6.truth_maps import TruthCollapseMaps

    params = job.params
    if spec is None:
        head = PULL_MAP_HEADS[params.pull_map_meaning] if pull else "deletion"
        predictor: Any = load_predictor(job.model_path, job.camera.image_size, head)
    else:
        how = params.pull
        action = (how.increment_m, how.grasp_lift_m) if pull else None
        falls = job.collapse_free if pull and params.pull_map_meaning == "collapse" else None
        predictor = TruthCollapseMaps(
            spec, job.physics, how.moved_threshold_m, action, falls, how.release()
        )
    simulate_hold = spec is not None and pull and bimanual and params.truth_hold == "simulate"
    levers = params.levers.kwargs() if pull else {}
    if pull and spec is not None:
        levers["watch_m"] = None  # truth maps already know the pull in progress
    return CollapseGraphPlanner(
        predictor,
        job.support,
        job.cp_max,
        params.min_pixels,
        bimanual=bimanual,
        predict_held=predictor.held if simulate_hold else None,
        **levers,
    )


@register_planner(
    "multi_step",
    label="multi-step extraction (CPG order, one arm)",
    maps="deletion",
    truth="multi_step_truth",
    pull_truth="multi_step_pull_truth",
    **PREDICTED,
    **ONE_ARM,
)
def _multi_step(job, spec):
    return cpg_planner(job, bimanual=False)


@register_planner(
    "bimanual",
    label="multi-step + bimanual hold",
    maps="deletion",
    truth="bimanual_truth",
    pull_truth="bimanual_pull_truth",
    **PREDICTED,
    **HOLDING,
)
def _bimanual(job, spec):
    return cpg_planner(job, bimanual=True)


@register_planner(
    "multi_step_truth",
    label="multi-step on physics-truth collapse maps (perception ceiling)",
    maps="truth",
    **TRUTH,
)
def _multi_step_truth(job, spec):
    return cpg_planner(job, bimanual=False, spec=spec)


@register_planner(
    "bimanual_truth",
    label="multi-step + bimanual hold on physics-truth maps (perception ceiling)",
    maps="truth",
    holds=True,
    **TRUTH,
)
def _bimanual_truth(job, spec):
    return cpg_planner(job, bimanual=True, spec=spec)


@register_planner(
    "multi_step_pull_truth",
    label="multi-step on physics-truth maps of the trials' pull",
    maps="pull_truth",
    **TRUTH,
)
def _multi_step_pull_truth(job, spec):
    return cpg_planner(job, bimanual=False, spec=spec, pull=True)


@register_planner(
    "bimanual_pull_truth",
    label="multi-step + bimanual hold on physics-truth maps of the pull",
    maps="pull_truth",
    holds=True,
    **TRUTH,
)
def _bimanual_pull_truth(job, spec):
    return cpg_planner(job, bimanual=True, spec=spec, pull=True)


@register_planner(
    "multi_step_pull",
    label="multi-step on the CP's pull head (maps of the trials' pull)",
    maps="pull",
    truth="multi_step_pull_truth",
    **PREDICTED,
    **ONE_ARM,
)
def _multi_step_pull(job, spec):
    return cpg_planner(job, bimanual=False, pull=True)


@register_planner(
    "bimanual_pull",
    label="multi-step + bimanual hold on the CP's pull head",
    maps="pull",
    truth="bimanual_pull_truth",
    **PREDICTED,
    **HOLDING,
)
def _bimanual_pull(job, spec):
    return cpg_planner(job, bimanual=True, pull=True)
