"""One way to run independent jobs in worker processes: spawn (no forked GL), one renderer
and one torch thread per worker, results in job order with a progress bar. So a job's bits do
not depend on how many workers run it."""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

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


def _call(args: tuple[Callable[[Any], Any], Any]) -> Any:
    fn, job = args
    return fn(job)


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
                results.append(fn(job))
                advance(1)
        else:
            ctx = mp.get_context("spawn")
            with ctx.Pool(min(workers, len(jobs)), worker_init, (1,)) as pool:
                for result in pool.imap(_call, [(fn, job) for job in jobs]):
                    results.append(result)
                    advance(1)
    return results
