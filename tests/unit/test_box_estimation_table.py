"""The box estimation table (report/box_estimation.py) from trial records."""

from __future__ import annotations

import pytest

from clutterbench.report.box_estimation import estimation_rows, estimation_table


def _rec(planner: str, episode: int, boxes: list, missing: int, rest: int, steps: int) -> dict:
    return {
        "planner": planner,
        "stream": "s",
        "episode": episode,
        "estimate_start": {"n_boxes": len(boxes) + missing, "missing": missing, "boxes": boxes},
        "estimate_not_at_rest": rest,
        "estimate_settle_mm": [0.1] * steps,
    }


def test_rows_count_each_scene_once_and_every_decision():
    boxes = [[0, 1.0, 0.0, 0.5, 0.2], [1, 3.0, 19.0, 1.5, 0.4]]
    records = {
        "a": [_rec("physics_from_depth", 0, boxes, 1, 1, 2)],
        # the holding planner saw the same first observation: its boxes are not counted twice
        "b": [_rec("physics_from_depth_hold", 0, boxes, 1, 0, 2)],
        "c": [{"planner": "oracle", "stream": "s", "episode": 0}],
    }
    (row,) = estimation_rows(records)
    assert row["scenes"] == 1 and row["boxes"] == 3 and row["missing"] == 1
    assert row["centre_median_mm"] == pytest.approx(2.0)
    assert row["size_wrong_pct"] == pytest.approx(50.0)
    assert row["not_at_rest"] == 1 and row["decisions"] == 4


def test_no_physics_from_depth_condition_writes_nothing(tmp_path):
    assert estimation_table({"c": [{"planner": "oracle"}]}, tmp_path, "tiny") is None
    assert not list(tmp_path.iterdir())


def test_a_sensed_condition_s_estimates_get_their_own_row(tmp_path):
    boxes = [[0, 1.0, 0.0, 0.5, 0.2]]
    sensed = _rec("physics_from_depth", 0, [[0, 9.0, 4.0, 3.0, 2.0]], 2, 1, 3)
    records = {
        "a": [_rec("physics_from_depth", 0, boxes, 0, 0, 2)],
        "a_d415": [sensed | {"sensing": "d415", "perception": "depth"}],
    }
    ideal, seen = estimation_rows(records)
    assert "seen" not in ideal and ideal["decisions"] == 2 and ideal["missing"] == 0
    assert seen["stream"] == "s" and seen["seen"] == "d415, depth masks"
    assert seen["missing"] == 2 and seen["centre_median_mm"] == pytest.approx(9.0)
    estimation_table(records, tmp_path, "tiny")
    assert "d415, depth masks" in (tmp_path / "box_estimation.md").read_text()
