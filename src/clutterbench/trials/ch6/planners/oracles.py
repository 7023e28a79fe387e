"""The search oracles, one arm and holding: the ceilings every other row is measured against
(trials/ch6/oracle.py; they read the true scene)."""

from __future__ import annotations

from clutterbench.trials.ch6.planners._registry import register_planner

ORACLE = {"world": "truth", "role": "oracle", "cost": "search"}


@register_planner("oracle", label="search oracle, one arm (ceiling)", **ORACLE)
def _oracle(job, spec):
    from clutterbench.trials.ch6.oracle import SearchOracle

    params = job.params
    return SearchOracle(
        spec, job.physics, job.camera, params.pull, params.search, False, job.collapse_free
    )


@register_planner(
    "oracle_hold", label="search oracle, may hold one box (ceiling)", holds=True, **ORACLE
)
def _oracle_hold(job, spec):
    """May hold one box during any pull: the ceiling of every planner that holds, the
    bimanual pull planners' idle hold included."""
    from clutterbench.trials.ch6.oracle import SearchOracle

    return SearchOracle(
        spec,
        job.physics,
        job.camera,
        job.params.pull,
        job.params.search,
        True,
        job.collapse_free,
        hold_any_pull=True,
    )
