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
