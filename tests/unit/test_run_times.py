"""The measured record of a whole run, from the stages' own timing files."""

from __future__ import annotations

import os

import pytest

from clutterbench.bench.run_times import collect, table
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.stage import stage_name


def timing(d, stage, seconds, cpu="CPU X", **shares):
    write_json(
        d / f"{stage}.json",
        {
            "stage": stage,
            "seconds": seconds,
            "scale": "default",
            "cores": 2,
            "cpu_model": cpu,
            "logical_cpus": 2,
        }
        | shares,
    )


def test_a_clock_reading_counts_the_jobs_own_cores_and_the_rest_of_the_machines(tmp_path):
    from clutterbench.platform_info import cpu_clock, cpu_shares

    hz = os.sysconf("SC_CLK_TCK")
    stat = tmp_path / "stat"
    # user nice system idle iowait irq softirq steal
    stat.write_text(f"cpu  {10 * hz} 0 {2 * hz} {50 * hz} {hz} 0 0 {hz} 0 0\ncpu0 1 2 3\n")
    a = cpu_clock(stat)
    assert a["machine"] == pytest.approx(12.0) and a["steal"] == pytest.approx(1.0)
    b = dict(a, own=a["own"] + 19.0, machine=a["machine"] + 29.0, steal=a["steal"] + 2.0)
    # 10 s of wall: the job kept 1.9 cores busy, the machine 2.9, 0.2 stolen
    assert cpu_shares(a, b, 10.0) == {"busy_cores": 1.9, "other_cores": 1.0, "steal_cores": 0.2}
    stat.write_text("garbage")
    unread = cpu_clock(stat)
    assert unread["machine"] is None and unread["steal"] is None
    assert cpu_shares(unread, unread, 1.0)["other_cores"] is None


def test_a_stage_timing_says_whether_it_had_the_cores(tmp_path, monkeypatch):
    from clutterbench import stage
    from clutterbench.config import BaseConfig
    from clutterbench.io import read_json

    readings = iter(
        [
            {"own": 0.0, "machine": 100.0, "steal": 0.0},
            {"own": 18.0, "machine": 128.0, "steal": 0.0},
        ]
    )
    monkeypatch.setattr(stage, "cpu_clock", lambda: next(readings))
    monkeypatch.setattr(stage, "STAGE_TIMING", tmp_path)
    monkeypatch.setattr(stage.sys, "argv", ["stages/report.py"])
    stage.record_wall_time(10.0, BaseConfig(), stage.cpu_clock())
    rec = read_json(tmp_path / "report.json")
    assert rec["busy_cores"] == 1.8 and rec["other_cores"] == 1.0 and rec["seconds"] == 10.0


def test_a_record_names_the_stages_that_shared_the_cores_and_leaves_dev_timings_out(tmp_path):
    alone = {"busy_cores": 1.9, "other_cores": 0.02, "steal_cores": 0.0}
    timing(tmp_path, "train@a", 120.0, **alone)
    timing(tmp_path, "report", 30.0, busy_cores=1.0, other_cores=0.9, steal_cores=0.0)
    timing(tmp_path, "trials", 60.0, busy_cores=1.5, other_cores=0.0, steal_cores=0.4)
    timing(tmp_path, "ch6_pull@ch6_hold", 600.0, **alone)
    rec = collect(tmp_path, {"train@a", "report", "trials"})
    assert rec["shared"] == ["report", "trials"] and rec["ignored"] == ["ch6_pull@ch6_hold"]
    assert rec["total_minutes"] == 3.5
    md = table(rec)
    assert "`report` (other work 0.90 cores, stolen 0.00)" in md
    assert "`trials` (other work 0.00 cores, stolen 0.40)" in md and "`train@a` (" not in md
    for name in ("report", "trials"):
        timing(tmp_path, name, 30.0, **alone)
    rec = collect(tmp_path, {"train@a", "report", "trials"})
    assert rec["shared"] == [] and "had the cores to itself" in table(rec)
    # a stage of a second or two: dvc's own work beside it is no sharing worth naming
    timing(tmp_path, "report", 2.0, busy_cores=0.9, other_cores=4.8, steal_cores=0.0)
    assert collect(tmp_path, {"train@a", "report", "trials"})["shared"] == []


def test_stage_name_is_dvc_s():
    assert stage_name(["stages/train.py", "cp_focal"]) == "train@cp_focal"
    assert stage_name(["stages/report.py"]) == "report"


def test_a_debugging_run_of_many_conditions_gets_a_name_a_file_can_have(tmp_path):
    many = ["stages/trials.py", *(f"multi_step_box_physics_{i}_d415" for i in range(12))]
    name = stage_name(many)
    assert name.startswith("trials@multi_step_box_physics_0_d415_and_11_more_")
    assert len(name) <= 120 and name != stage_name([*many[:-1], "random_d415"])
    (tmp_path / f".{name}.json.tmp-123456").write_text("{}")  # as write_json's temp file


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


def test_a_run_that_missed_a_stage_is_no_whole_record_but_may_be_a_partial_one(tmp_path):
    from clutterbench.bench.run_times import readme_block

    timing(tmp_path, "train@a", 60.0)
    timing(tmp_path, "report", 30.0)
    expected = {"train@a", "train@b", "report", "trials"}
    with pytest.raises(ClutterbenchError, match=r"2 stage\(s\) have no timing.*train@b, trials"):
        collect(tmp_path, expected)
    rec = collect(tmp_path, expected, partial=True)
    assert rec["partial"] and rec["missing"] == ["train@b", "trials"]
    assert rec["total_minutes"] == 1.5
    md = table(rec)
    assert "**stages run**" in md and "Not run (partial record): train@b, trials." in md
    whole = collect(tmp_path, {"train@a", "report"})
    assert "partial" not in whole and "**all stages**" in table(whole)
    assert "No whole default-scale run" in readme_block([_record(100.0) | {"partial": True}])


def test_the_pipelines_stages_are_dvc_yamls_with_foreach_expanded():
    from pathlib import Path

    from clutterbench.bench.run_times import pipeline_stages

    names = pipeline_stages(Path(__file__).resolve().parents[2])
    assert {"train@cp_focal", "report", "trials", "generate@ch6"} <= names
    assert not any(n in ("train", "generate") for n in names)


def test_no_timings_is_one_line(tmp_path):
    with pytest.raises(ClutterbenchError, match="no stage timings"):
        collect(tmp_path)


def _record(total, cpu="AMD EPYC", family=25, bf16=True):
    return {
        "cpu_model": cpu,
        "cpu_family": family,
        "cpu_model_number": 17,
        "cpu_flags": {"avx2": True, "avx512f": True, "avx512_bf16": bf16, "amx_bf16": False},
        "cores": 2,
        "logical_cpus": 2,
        "scale": "default",
        "stages": {},
        "groups": {"train": total / 2, "trials": total / 2},
        "total_minutes": total,
        "date": "2026-11-29",
    }


def test_the_readme_table_has_a_row_per_recorded_default_run_within_budget_or_not():
    from clutterbench.bench.run_times import readme_block, record_name

    block = readme_block(
        [_record(180.0), _record(110.0, family=26), _record(5.0) | {"scale": "tiny"}]
    )
    rows = [line for line in block.splitlines() if line.startswith("| AMD")]
    assert len(rows) == 2 and "family 26" in rows[0] and "family 25" in rows[1]
    assert "| **110.0** | yes |" in rows[0] and "| **180.0** | no |" in rows[1]
    assert "AVX-512 BF16, no AMX" in rows[0] and "| 55.0 | 55.0 |" in rows[0]
    assert record_name(_record(1.0)) == "default_amd_epyc_f25m17"


def test_the_readmes_run_time_table_is_the_committed_records():
    """README.md quotes only measured records: its block is what `make run-times` writes
    from reports/run_times/ (a hand edit of the block, or a record without its rewrite, fails)."""
    from pathlib import Path

    from clutterbench.bench.run_times import (
        RUN_TIMES_BEGIN,
        RUN_TIMES_END,
        committed_records,
        readme_block,
    )

    root = Path(__file__).resolve().parents[2]
    text = (root / "README.md").read_text()
    block = text[text.index(RUN_TIMES_BEGIN) : text.index(RUN_TIMES_END) + len(RUN_TIMES_END)]
    assert block == readme_block(committed_records(root / "reports/run_times"))


def test_the_run_times_page_lists_whole_runs_then_partial_ones_each_linked(tmp_path):
    from clutterbench.bench.run_times import records_block

    whole = _record(140.0) | {"shares": {"trials": {}}, "shared": []}
    part = _record(60.0, cpu="Intel Xeon", family=6) | {"partial": True, "missing": ["trials"]}
    shared = _record(170.0, family=26) | {"shares": {"trials": {}}, "shared": ["trials"]}
    block = records_block([whole, shared], [part], "../")
    lines = block.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("- **140.0 min**"))
    assert lines.index("**Partial runs** (1):") > first
    assert "every stage had the cores to itself" in lines[first]
    assert "(../reports/run_times/default_amd_epyc_f25m17.md)" in lines[first]
    assert "1 stage(s) shared the cores" in block and "not run: trials" in block
    assert "(../reports/run_times/partial/default_intel_xeon_f6m17.md)" in block
    assert "training 70.0, everything else 70.0" in lines[first]
    assert "- none" in records_block([], [], "")
