"""Pull the target at once, nothing held: the naive row of Table 6.3."""

from __future__ import annotations

from clutterbench.trials.ch6.planners._registry import register_planner


@register_planner("pull_target", label="pull the target at once, nothing held (naive)")
def _pull_target(job, spec):
    from clutterbench.planning.ch6.extraction import TargetFirstPlanner

    return TargetFirstPlanner()
