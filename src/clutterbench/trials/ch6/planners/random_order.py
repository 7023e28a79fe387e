"""The floor of Table 6.3: a uniformly random visible box each step."""

from __future__ import annotations

from clutterbench.trials.ch6.planners._registry import register_planner


@register_planner("random", label="random (floor)", role="floor")
def _random(job, spec):
    from clutterbench.data.trial_scenes import policy_rng
    from clutterbench.planning.ch6.extraction import RandomOrderPlanner

    rng = policy_rng(job.seed, job.stream, job.index, job.planner)
    return RandomOrderPlanner(rng, job.params.min_pixels)
