"""One way to run independent jobs in worker processes: spawn (no forked GL), one renderer
and one torch thread per worker, results in job order with a progress bar. So a job's bits do
not depend on how many workers run it.

A job that raises ends the run with one line naming the run (its label: the stage), the job
(condition, episode or game, shard) and its seed, then the exception: a ClutterbenchError the
stage prints as it prints any other (CLUTTERBENCH_TRACEBACK=1 keeps the whole trace)."""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from clutterbench.errors import ClutterbenchError
from clutterbench.progress import progress_bar

R = TypeVar("R")


def worker_init(torch_threads: int = 1) -> None:
    """The process-wide renderer, and torch on `torch_threads` threads."""
    from clutterbench.sim.renderer import ensure_renderer

    ensure_renderer()
    try:
        import torch

        torch.set_num_threads(torch_threads)
    except ImportError:  # pragma: no cover - torch is a dependency
        pass


JOB_KEYS = ("condition", "stream", "planner", "index", "episode", "game", "shard", "seed")
"""The fields of a job (a dict) that name it in an error, in this order, where present."""


def job_name(job: Any) -> str:
    """'condition multi_step, stream ch6_3_10, index 7, seed 0' for a job dict; repr otherwise."""
    if isinstance(job, dict):
        named = [f"{k} {job[k]}" for k in JOB_KEYS if k in job and _plain(job[k])]
        if named:
            return ", ".join(named)
    text = repr(job)
    return text if len(text) <= 80 else text[:77] + "..."


def _plain(value: Any) -> bool:
    return isinstance(value, str | int | float) and len(str(value)) <= 60


def _call(args: tuple[str, Callable[[Any], Any], Any]) -> Any:
    label, fn, job = args
    try:
        return fn(job)
    except Exception as exc:
        if os.environ.get("CLUTTERBENCH_TRACEBACK"):
            raise
        what = f"{type(exc).__name__}: {exc}" if not isinstance(exc, ClutterbenchError) else exc
        message = " ".join(f"{label}: {job_name(job)}: {what}".split())
        raise ClutterbenchError(message) from None


def map_in_workers(
    label: str, fn: Callable[[Any], R], jobs: Sequence[Any], workers: int
) -> list[R]:
    """`fn(job)` for every job (a module-level `fn`, so workers can import it), in worker
    processes when workers > 1; results in job order."""
    results: list[R] = []
    with progress_bar(label, total=len(jobs)) as advance:
        if workers == 1 or len(jobs) <= 1:
            worker_init(1)
            for job in jobs:
                results.append(_call((label, fn, job)))
                advance(1)
        else:
            ctx = mp.get_context("spawn")
            with ctx.Pool(min(workers, len(jobs)), worker_init, (1,)) as pool:
                for result in pool.imap(_call, [(label, fn, job) for job in jobs]):
                    results.append(result)
                    advance(1)
    return results
