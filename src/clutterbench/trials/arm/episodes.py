"""Arm-level trials (Table arm): a ch. 6 extraction or a ch. 4 trial whose steps the Pandas
execute (trials/core/executors.py), one episode function for both chapters."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from clutterbench.trials.ch4.jobs import Ch4Job
    from clutterbench.trials.ch6.jobs import Ch6Job


def run_arm_episode(job: Ch4Job | Ch6Job):
    """One episode of an arm-level condition: a ch. 6 extraction or a ch. 4 trial (the job
    says which), executed by the Pandas."""
    import time

    from clutterbench.trials.ch4.episodes import run_ch4_episode
    from clutterbench.trials.ch4.jobs import Ch4Job
    from clutterbench.trials.ch6.episodes import run_ch6_episode

    start = time.perf_counter()
    result = run_ch4_episode(job) if isinstance(job, Ch4Job) else run_ch6_episode(job)
    result.wall_s = time.perf_counter() - start
    return result
