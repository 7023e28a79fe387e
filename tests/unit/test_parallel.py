"""map_in_workers: a job that raises ends the run with one line naming the run, the job and
its seed (issue 53), in-process and in worker processes."""

from __future__ import annotations

import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.parallel import job_name, map_in_workers


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
