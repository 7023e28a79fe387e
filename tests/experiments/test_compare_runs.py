"""experiments/compare_runs.py: two runs' trials side by side, from their records alone."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from clutterbench.errors import ClutterbenchError
from experiments import compare_runs


def _run(root: Path, condition: str, rows: list[dict]) -> None:
    d = root / compare_runs.TRIALS / condition
    d.mkdir(parents=True)
    (d / "records.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))


def _rec(e: int, target: int, ok: bool, **kw) -> dict:
    base = {"episode": e, "target": target, "success": ok, "strict_success": ok}
    return base | {"stream": "s", "planner": "physics_from_depth"} | kw


def test_targets_repairs_and_rates_side_by_side(tmp_path, monkeypatch):
    monkeypatch.setattr(compare_runs, "artifact_targets", lambda: {("s", 0): 3, ("s", 1): 9})
    _run(
        tmp_path / "a",
        "pfd",
        [
            _rec(0, 3, True, estimate_dropped=[1, 0], estimate_outside=[1, 0], perception_failed=0),
            _rec(1, 4, False, estimate_dropped=[2], estimate_outside=[0], perception_failed=1),
        ],
    )
    _run(tmp_path / "b", "pfd", [_rec(0, 3, True), _rec(1, 5, True)])
    text = "\n".join(compare_runs.compare(tmp_path / "a", tmp_path / "b"))
    assert "| pfd | s | 1/2 (50.0%) | 2/2 (100.0%) |" in text
    assert "| 1/2 | 1/2 targets |" in text  # episode 1's target differs; one equals the artifact's
    assert "| pfd | ours | 3 | 3 | 1 | 1 |" in text  # decisions, dropped, outside, failed
    assert "| pfd | theirs | (records before the repair's counts)" in text


def test_episode_by_episode_what_differs(tmp_path, monkeypatch):
    monkeypatch.setattr(compare_runs, "artifact_targets", lambda: {})
    steps = [{"box": 2}, {"box": 3}]
    ours = [
        _rec(0, 3, True, scene="h0", steps=steps),
        _rec(1, 3, True, scene="h1", steps=steps),
        _rec(2, 3, False, scene="h2", steps=steps),
    ]
    theirs = [
        _rec(0, 3, True, scene="h0", steps=steps),  # identical
        _rec(1, 3, True, scene="h1", steps=steps[::-1]),  # same outcome, other order
        _rec(2, 3, True, scene="hX", steps=steps),  # other start, other outcome
    ]
    _run(tmp_path / "a", "c", ours)
    _run(tmp_path / "b", "c", theirs)
    text = "\n".join(compare_runs.compare(tmp_path / "a", tmp_path / "b"))
    # targets differ | start = benchmark | scenes differ | outcome | pulled | identical
    assert "| 0/3 | 0/3 targets | 1/3 | 1 | 1 | 1 |" in text
    assert "| **all 1** | | | | | | 0/3 | | 1/3 | 1 | 1 | 1 |" in text


def test_a_directory_without_trials_is_one_line(tmp_path):
    with pytest.raises(ClutterbenchError, match="no trials reports"):
        compare_runs.compare(tmp_path, tmp_path)
