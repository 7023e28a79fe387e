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
