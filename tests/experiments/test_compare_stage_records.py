"""experiments/compare_stage_records.py: one stage's records from two runs, episode by episode."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from clutterbench.errors import ClutterbenchError
from experiments import compare_stage_records as csr


def _write(d: Path, rows: list[dict]) -> Path:
    d.mkdir(parents=True)
    (d / "records.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return d


def _rec(condition: str, e: int, ok: bool, extract: int, **kw) -> dict:
    base = {"condition": condition, "episode": e, "success": ok, "strict_success": ok}
    return base | {"scene": f"h{e}", "target": 1, "extract": extract, "mode": "pull"} | kw


def test_each_difference_is_counted_where_it_is(tmp_path):
    ours = _write(
        tmp_path / "a",
        [
            _rec("c", 0, True, 2),
            _rec("c", 1, True, 2),
            _rec("c", 2, False, 3),
            _rec("c", 3, True, 1, scene="hA"),
            _rec("d", 0, True, 1),  # a condition theirs did not run: not compared
        ],
    )
    theirs = _write(
        tmp_path / "b",
        [
            _rec("c", 0, True, 2),  # identical
            _rec("c", 1, True, 2, n_disturbed=1),  # same success, other outcome field
            _rec("c", 2, True, 1),  # other action, other success
            _rec("c", 3, True, 1, scene="hB"),  # another start
        ],
    )
    text = "\n".join(csr.compare("trials_ch4", ours, theirs))
    # paired | success ours/theirs ... | start | success or strict | outcome | actions | identical
    assert "| c | 4 | 3/4 | 4/4 | 3/4 | 4/4 |" in text
    assert "| 1 | 1 | 2 | 1 | 1/4 |" in text
    assert "| d |" not in text and "(1 conditions compared)" in text


def test_missing_records_are_one_line(tmp_path):
    with pytest.raises(ClutterbenchError, match="no records"):
        csr.compare("trials_ch5", tmp_path, tmp_path)
    assert csr.main(["trials_ch5", str(tmp_path), str(tmp_path)]) == 2
