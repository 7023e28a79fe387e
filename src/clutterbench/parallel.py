"""One way to run independent jobs in worker processes: one renderer and one torch thread per
worker, results in job order with a progress bar. So a job's bits do not depend on how many
workers run it, nor on which backend (params.yaml `parallel`, docs/scaling.md):

- `processes` (the default): spawned worker processes on this machine (no forked GL);
- `ray`: one Ray task per job, on a local Ray instance of `workers` CPUs or on a cluster
  joined by address; a job whose worker process dies is rerun (`max_retries`), a job that
  raises is not. `import ray` happens only here, only for this backend.

A job that raises ends the run with one line naming the run (its label: the stage), the job
(condition, episode or game, shard) and its seed, then the exception: a ClutterbenchError the
stage prints as it prints any other (CLUTTERBENCH_TRACEBACK=1 keeps the whole trace). Either
backend hands results back to the caller, which writes the outputs (atomically): a failed
run leaves nothing half-written."""

from __future__ import annotations

import dataclasses
import logging
import multiprocessing as mp
import os
import re
import socket
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal, TypeVar

from clutterbench.config import bounded
from clutterbench.errors import ClutterbenchError
from clutterbench.progress import progress_bar

R = TypeVar("R")

BACKENDS = ("processes", "ray")
LOCAL = (None, "local")
"""Addresses that start a local Ray instance of `workers` CPUs."""
_RAY_CLIENT = re.compile(r"^ray://(?P<host>[^:/\s]+):(?P<port>\d+)$")
REACH_TIMEOUT_S = 5.0
"""How long a cluster's address may take to accept a connection before the run stops."""
SHIPPED_ENV_PREFIX = "CLUTTERBENCH_"
"""Environment variables with this prefix (inference precision, tracebacks, the benchmark
scenes' switch) travel with every Ray task, as a spawned worker inherits them."""


@dataclasses.dataclass(frozen=True)
class ParallelConfig:
    """params.yaml `parallel`: where the simulation stages (generate, slides, support's test
    scenes, every trials stage) run their jobs; the stages' own `workers` say how many."""

    backend: Literal["processes", "ray"] = "processes"
    """processes: worker processes on this machine (no Ray needed); ray: one Ray task per job."""
    address: str | None = None
    """ray only: null or local (a local Ray instance of `workers` CPUs, shut down at the end),
    auto (the cluster this machine joined with `ray start`) or ray://host:port (a cluster's
    Ray Client server, e.g. its head node's port 10001)."""
    max_retries: int = bounded(3, ge=0)
    """ray only: reruns of a job whose worker process died (never of a job that raised)."""

    def __post_init__(self) -> None:
        a = self.address
        if a is not None and a not in ("local", "auto") and not _RAY_CLIENT.match(a):
            raise ValueError(f"address {a!r} is not null, local, auto or ray://host:port")


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
"""The fields of a job (a dict's keys, a job dataclass's attributes) that name it in an
error, in this order, where present."""


def job_name(job: Any) -> str:
    """'condition multi_step, stream ch6_3_10, index 7, seed 0' for a job dict or a job
    dataclass (trials.core.jobs: its fields of the same names); repr otherwise."""
    if isinstance(job, dict):
        named = [f"{k} {job[k]}" for k in JOB_KEYS if k in job and _plain(job[k])]
        if named:
            return ", ".join(named)
    elif dataclasses.is_dataclass(job) and not isinstance(job, type):
        values = [(k, getattr(job, k)) for k in JOB_KEYS if hasattr(job, k)]
        named = [f"{k} {v}" for k, v in values if _plain(v)]
        if named:
            return ", ".join(named)
    text = repr(job)
    return text if len(text) <= 80 else text[:77] + "..."


def _plain(value: Any) -> bool:
    return isinstance(value, str | int | float) and len(str(value)) <= 60


def _one_line(label: str, job: Any, what: Any) -> str:
    return " ".join(f"{label}: {job_name(job)}: {what}".split())


def _call(args: tuple[str, Callable[[Any], Any], Any]) -> Any:
    label, fn, job = args
    try:
        return fn(job)
    except Exception as exc:
        if os.environ.get("CLUTTERBENCH_TRACEBACK"):
            raise
        what = f"{type(exc).__name__}: {exc}" if not isinstance(exc, ClutterbenchError) else exc
        raise ClutterbenchError(_one_line(label, job, what)) from None


def map_in_workers(
    label: str,
    fn: Callable[[Any], R],
    jobs: Sequence[Any],
    workers: int,
    parallel: ParallelConfig | None = None,
) -> list[R]:
    """`fn(job)` for every job (a module-level `fn`, so workers can import it), in worker
    processes when workers > 1 or on Ray (`parallel`; None: processes); results in job
    order."""
    return list(iter_in_workers(label, fn, jobs, workers, parallel))


def iter_in_workers(
    label: str,
    fn: Callable[[Any], R],
    jobs: Sequence[Any],
    workers: int,
    parallel: ParallelConfig | None = None,
    units: Sequence[int] | None = None,
    completed: int = 0,
) -> Iterator[R]:
    """map_in_workers, one result at a time as it comes in job order (the caller writes each
    and lets it go); the progress bar counts `units[k]` for job k (default 1) on top of
    `completed` done before."""
    parallel = parallel or ParallelConfig()
    units = list(units) if units is not None else [1] * len(jobs)
    total = completed + sum(units)
    with progress_bar(label, total=total, completed=completed) as advance:
        if parallel.backend == "ray":
            yield from _ray_map(label, fn, jobs, workers, parallel, units, advance)
        elif workers == 1 or len(jobs) <= 1:
            with _torch_threads_kept():
                worker_init(1)
                for job, n in zip(jobs, units):
                    result = _call((label, fn, job))
                    advance(n)
                    yield result
        else:
            ctx = mp.get_context("spawn")
            with _one_blas_thread(), ctx.Pool(min(workers, len(jobs)), worker_init, (1,)) as pool:
                results = pool.imap(_call, [(label, fn, job) for job in jobs])
                for n, result in zip(units, results):
                    advance(n)
                    yield result


BLAS_THREADS = "OPENBLAS_NUM_THREADS"
"""numpy's OpenBLAS reads it once, when numpy loads. Unset, every worker process starts one
OpenBLAS thread per core, which spins between the small products of box fits and geometry:
with one worker per core they take cores from the other workers (0.5 of a core measured
beside one physics-from-depth episode)."""


@contextmanager
def _one_blas_thread() -> Iterator[None]:
    """Spawned workers inherit this process' environment: one OpenBLAS thread each, as torch
    has one thread each (worker_init), unless the user set a count."""
    if BLAS_THREADS in os.environ:
        yield
        return
    os.environ[BLAS_THREADS] = "1"
    try:
        yield
    finally:
        del os.environ[BLAS_THREADS]


@contextmanager
def _torch_threads_kept() -> Iterator[None]:
    """Jobs run in this process on one torch thread, as in a worker; the caller's thread
    count comes back afterwards."""
    import torch

    threads = torch.get_num_threads()
    try:
        yield
    finally:
        torch.set_num_threads(threads)


# --- the Ray backend -------------------------------------------------------------------------


class _Failed:
    """A job that raised, as its one-line message (returned, not raised, so Ray never retries
    it and the driver raises the same ClutterbenchError as the processes backend)."""

    def __init__(self, message: str) -> None:
        self.message = message


_WORKER_READY = False


def _ray_task(label: str, fn: Callable[[Any], Any], job: Any, env: dict[str, str]) -> Any:
    """One job in a Ray worker process: the driver's CLUTTERBENCH_* settings and working
    directory (jobs read the project's files by relative path: the networks, the benchmark
    scenes), the worker set up once per process (worker_init), then `fn(job)`."""
    global _WORKER_READY
    for key in [k for k in os.environ if k.startswith(SHIPPED_ENV_PREFIX) and k not in env]:
        del os.environ[key]
    cwd = env.pop("__cwd__")
    os.environ.update(env)
    if not os.path.isdir(cwd):  # a cluster node without the project: never other bytes
        where = f"the project directory {cwd} is not on Ray node {socket.gethostname()}"
        return _Failed(_one_line(label, job, f"{where} (a shared filesystem: docs/scaling.md)"))
    if os.getcwd() != cwd:
        os.chdir(cwd)  # jobs' relative paths (models/, data/benchmark/) as the driver's
    if not _WORKER_READY:
        worker_init(1)
        _WORKER_READY = True
    try:
        return _call((label, fn, job))
    except ClutterbenchError as exc:
        return _Failed(str(exc))


def _ray_map(
    label: str,
    fn: Callable[[Any], R],
    jobs: Sequence[Any],
    workers: int,
    parallel: ParallelConfig,
    units: Sequence[int],
    advance: Callable[[int], None],
) -> Iterator[R]:
    if not jobs:
        return
    ray = _import_ray()
    started = connect_ray(parallel, workers)
    pending: list[Any] = []  # submitted, not seen finished
    try:
        task = ray.remote(_ray_task).options(
            num_cpus=1, max_retries=parallel.max_retries, retry_exceptions=False
        )
        env = {k: v for k, v in os.environ.items() if k.startswith(SHIPPED_ENV_PREFIX)}
        env["__cwd__"] = os.getcwd()
        # at most a window of jobs ahead of the one handed back next (8 per CPU: a slow job
        # leaves no CPU idle), so finished results (shards) wait in Ray's object store a
        # window at a time, not a whole stage's
        window = 8 * max(1, int(ray.cluster_resources().get("CPU", workers)))
        refs: list[Any] = []
        index: dict[Any, int] = {}
        finished: set[Any] = set()
        for head in range(len(jobs)):
            while len(refs) < len(jobs) and len(refs) - head < window:
                ref = task.remote(label, fn, jobs[len(refs)], dict(env))
                index[ref] = len(refs)
                refs.append(ref)
                pending.append(ref)
            while refs[head] not in finished:
                ready, pending = ray.wait(pending, num_returns=1)
                for ref in ready:
                    finished.add(ref)
                    advance(units[index[ref]])
            ref, refs[head] = refs[head], None
            result = _ray_result(ray, label, jobs[head], ref, parallel.max_retries)
            finished.discard(ref)
            del index[ref], ref  # Ray frees the result once nothing refers to it
            yield result
    finally:
        if started:
            ray.shutdown()
        # an instance this run did not start goes on: the jobs already submitted (a window
        # at most) run to their end there, their results dropped with the references. Not
        # ray.cancel: a cancel that races a finishing task aborts this process inside Ray
        # ("Tried to complete task that was not pending", seen with ray 2.58 on 2 cores)


def _ray_result(ray: Any, label: str, job: Any, ref: Any, retries: int) -> Any:
    try:
        result = ray.get(ref)
    except ray.exceptions.RayError as exc:
        if os.environ.get("CLUTTERBENCH_TRACEBACK"):
            raise  # the job's own exception with the worker's trace, or Ray's
        if isinstance(exc, ray.exceptions.RayTaskError):  # not an Exception (SystemExit)
            what = f"{type(exc.cause).__name__}: {exc.cause}"
        else:
            what = f"{type(exc).__name__} (its Ray worker died; {retries} retries)"
        raise ClutterbenchError(_one_line(label, job, what)) from None
    if isinstance(result, _Failed):
        raise ClutterbenchError(result.message)
    return result


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ClutterbenchError(
            "parallel.backend: ray needs the ray package (pip install -c requirements.lock "
            "'ray[client]'; make setup installs it)"
        ) from None
    return ray


def connect_ray(parallel: ParallelConfig, workers: int) -> bool:
    """Connect this process to Ray as `parallel` says, unless it is connected already (then
    that instance is used as it is); True when this call started or joined it (the caller
    shuts it down). An unreachable address is one line, before any job starts."""
    ray = _import_ray()
    if ray.is_initialized():
        return False
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    options: dict[str, Any] = {
        "include_dashboard": False,
        "logging_level": logging.WARNING,
    }
    if parallel.address in LOCAL:
        # a local instance: its workers inherit this process's environment and import the
        # package from this venv, as spawned workers do, and run at this process's priority
        # as they do (Ray's default renices its workers to 15: on a busy machine they starve)
        os.environ.setdefault("RAY_worker_niceness", "0")
        ray.init(address="local", num_cpus=workers, **options)
        return True
    address = parallel.address
    match = _RAY_CLIENT.match(address)
    if match:
        _check_reachable(address, match["host"], int(match["port"]))
    try:
        ray.init(address=address, runtime_env=_runtime_env(), **options)
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise ClutterbenchError(
            f"parallel.address: cannot join the Ray cluster at {address} "
            f"({type(exc).__name__}: {first})"
        ) from None
    return True


def _check_reachable(address: str, host: str, port: int) -> None:
    try:
        with socket.create_connection((host, port), timeout=REACH_TIMEOUT_S):
            pass
    except OSError as exc:
        raise ClutterbenchError(
            f"parallel.address: the Ray cluster at {address} is unreachable "
            f"({exc.strerror or type(exc).__name__})"
        ) from None


def _runtime_env() -> dict[str, Any]:
    """What a cluster's workers get: this checkout's package (so they run the driver's code),
    and the driver's hash seed (workers' Python starts with it)."""
    package = Path(__file__).resolve().parent
    env: dict[str, Any] = {
        "py_modules": [str(package)],
        "excludes": ["__pycache__", "*.pyc"],
    }
    if "PYTHONHASHSEED" in os.environ:
        env["env_vars"] = {"PYTHONHASHSEED": os.environ["PYTHONHASHSEED"]}
    return env
