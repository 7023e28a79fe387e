"""map_in_workers: a job that raises ends the run with one line naming the run, the job and
its seed, in-process and in worker processes; params.yaml `parallel` is checked,
and the default backend runs without Ray (its own tests: test_parallel_ray.py)."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys

import pytest

from clutterbench.config import load_section
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.parallel import ParallelConfig, job_name, map_in_workers
from clutterbench.trials.core.jobs import EpisodeJob


def _episode(job: dict) -> int:
    if job["index"] == 1:
        raise KeyError("box_6")
    return job["index"]


JOBS = [{"condition": "multi_step", "stream": "ch6_3_10", "index": i, "seed": 7} for i in range(3)]


def test_a_job_is_named_by_its_fields():
    assert job_name(JOBS[1] | {"params": object()}) == (
        "condition multi_step, stream ch6_3_10, index 1, seed 7"
    )
    assert job_name(3) == "3"


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class _PlannerJob(EpisodeJob):
    """A trial job as the chapters' are: a frozen dataclass on EpisodeJob."""

    stream: str
    planner: str
    params: object = None


def _job(index: int) -> _PlannerJob:
    return _PlannerJob(
        condition="c",
        stream="s",
        planner="p",
        index=index,
        seed=0,
        record_images=False,
        collapse_free=CollapseFreeConfig(),
    )


def _job_episode(job: _PlannerJob) -> int:
    if job.index == 1:
        raise KeyError("box_6")
    return job.index


def test_a_job_dataclass_is_named_by_its_fields_as_a_dict_was():
    assert job_name(_job(1)) == "condition c, stream s, planner p, index 1, seed 0"
    as_dict = {k: getattr(_job(1), k) for k in ("condition", "stream", "planner", "index")}
    assert job_name(_job(1)) == job_name(as_dict | {"seed": 0, "params": None})


@pytest.mark.parametrize("workers", [1, 2])
def test_a_raising_job_dataclass_is_one_line_naming_it(workers, monkeypatch):
    monkeypatch.delenv("CLUTTERBENCH_TRACEBACK", raising=False)
    with pytest.raises(ClutterbenchError) as err:
        map_in_workers("trials", _job_episode, [_job(i) for i in range(3)], workers)
    assert str(err.value) == (
        "trials: condition c, stream s, planner p, index 1, seed 0: KeyError: 'box_6'"
    )


@pytest.mark.parametrize("workers", [1, 2])
def test_a_raising_job_is_one_line_naming_it(workers, monkeypatch):
    monkeypatch.delenv("CLUTTERBENCH_TRACEBACK", raising=False)
    with pytest.raises(ClutterbenchError) as err:
        map_in_workers("trials", _episode, JOBS, workers)
    message = str(err.value)
    assert "\n" not in message
    assert message == (
        "trials: condition multi_step, stream ch6_3_10, index 1, seed 7: KeyError: 'box_6'"
    )


def test_jobs_that_do_not_raise_come_back_in_order():
    assert map_in_workers("trials", _episode, [JOBS[0], JOBS[2]], 1) == [0, 2]


def test_the_parallel_section_is_checked_in_one_line():
    base = {"base": {"seed": 0}}
    got = load_section(ParallelConfig, "parallel", base | {"parallel": {"backend": "ray"}})
    assert got == ParallelConfig(backend="ray", address=None, max_retries=3)
    for section, expected in (
        ({"backend": "dask"}, "parallel.backend: 'dask' is not one of processes, ray"),
        ({"address": "10.0.0.1"}, "parallel: address '10.0.0.1' is not null, local, auto or"),
        ({"max_retries": -1}, "parallel.max_retries: -1 is out of range (must be >= 0)"),
    ):
        with pytest.raises(ClutterbenchError, match=re.escape(expected)):
            load_section(ParallelConfig, "parallel", base | {"parallel": section})


def test_the_processes_backend_never_imports_ray():
    probe = (
        "import sys\n"
        "from clutterbench.parallel import map_in_workers\n"
        "assert map_in_workers('t', abs, [-1, 2], 1) == [1, 2]\n"
        "print('ray' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_a_ray_task_on_a_node_without_the_project_is_one_line(monkeypatch):
    """A cluster node that lacks the driver's project directory runs no job (it would draw
    scenes without the benchmark artifact): one line naming the job and the node."""
    from clutterbench.parallel import _Failed, _ray_task

    monkeypatch.setattr(os, "environ", dict(os.environ))  # the task sets the driver's env
    out = _ray_task("trials", abs, JOBS[0], {"__cwd__": "/no/such/project"})
    assert isinstance(out, _Failed)
    assert out.message.startswith(
        "trials: condition multi_step, stream ch6_3_10, index 0, seed 7: the project "
        "directory /no/such/project is not on Ray node "
    )


def _blas_threads(_job: int) -> str | None:
    return os.environ.get("OPENBLAS_NUM_THREADS")


def test_spawned_workers_run_numpys_blas_on_one_thread_unless_the_user_set_it(monkeypatch):
    """An OpenBLAS thread per core in every worker spins between small products and takes
    cores from the other workers: spawned workers get OPENBLAS_NUM_THREADS=1, a count the
    user set is kept, and this process' environment is left as it was."""
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    assert map_in_workers("blas", _blas_threads, [0, 1], 2) == ["1", "1"]
    assert "OPENBLAS_NUM_THREADS" not in os.environ
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    assert map_in_workers("blas", _blas_threads, [0, 1], 2) == ["2", "2"]
    assert os.environ["OPENBLAS_NUM_THREADS"] == "2"
