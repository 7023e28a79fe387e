"""The measured record of a whole run, from the stages' own timing files."""

from __future__ import annotations

import pytest

from clutterbench.bench.run_times import collect, table
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.stage import stage_name


def timing(d, stage, seconds, cpu="CPU X"):
    write_json(
        d / f"{stage}.json",
        {
            "stage": stage,
            "seconds": seconds,
            "scale": "default",
            "cores": 2,
            "cpu_model": cpu,
            "logical_cpus": 2,
        },
    )


def test_stage_name_is_dvc_s():
    assert stage_name(["stages/train.py", "cp_focal"]) == "train@cp_focal"
    assert stage_name(["stages/report.py"]) == "report"


def test_minutes_per_stage_group_and_their_sum(tmp_path):
    timing(tmp_path, "train@a", 120.0)
    timing(tmp_path, "train@b", 60.0)
    timing(tmp_path, "report", 30.0)
    rec = collect(tmp_path)
    assert rec["groups"] == {"report": 0.5, "train": 3.0}
    assert rec["total_minutes"] == 3.5
    md = table(rec)
    assert "| `train` | 3.0 | a 2.0, b 1.0 |" in md and "**3.5**" in md


def test_a_record_mixes_no_machines(tmp_path):
    timing(tmp_path, "train@a", 1.0, cpu="CPU X")
    timing(tmp_path, "report", 1.0, cpu="CPU Y")
    with pytest.raises(ClutterbenchError, match="more than one cpu_model"):
        collect(tmp_path)


def test_no_timings_is_one_line(tmp_path):
    with pytest.raises(ClutterbenchError, match="no stage timings"):
        collect(tmp_path)
