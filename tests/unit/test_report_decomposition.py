"""Table 6.3 decomposed: a CP row's gap to its oracle = planning part + perception part."""

from __future__ import annotations

import pytest

from clutterbench.report.decomposition import decompose, decomposition_table


def _records(planner: str, stream: str, wins: int, n: int = 10, strict_wins: int | None = None):
    strict_wins = wins if strict_wins is None else strict_wins
    return [
        {
            "planner": planner,
            "stream": stream,
            "episode": e,
            "success": e < wins,
            "strict_success": e < strict_wins,
        }
        for e in range(n)
    ]


def test_the_gap_splits_into_planning_and_perception():
    by_condition = {
        "multi_step": _records("multi_step", "s", 3, strict_wins=2),
        "multi_step_truth": _records("multi_step_truth", "s", 6, strict_wins=4),
        "oracle": _records("oracle", "s", 8, strict_wins=5),
        "bimanual": _records("bimanual", "s", 5),
        "oracle_hold": _records("oracle_hold", "s", 9),
    }
    rows = {r["key"]: r for r in decompose(by_condition) if r["planner"] == "multi_step"}
    free, strict = rows["success"], rows["strict_success"]
    assert free["planning"] == pytest.approx(20.0) and free["perception"] == pytest.approx(30.0)
    assert free["gap"] == pytest.approx(50.0) and free["oracle_condition"] == "oracle"
    assert strict["planning"] == pytest.approx(10.0) and strict["perception"] == pytest.approx(20.0)
    for r in rows.values():
        assert r["planning_lo"] <= r["planning"] <= r["planning_hi"]
    # bimanual has no truth row on this stream: no decomposition for it
    assert all(r["planner"] != "bimanual" for r in decompose(by_condition))


def test_with_pull_truth_maps_the_gap_splits_three_ways(tmp_path):
    by_condition = {
        "multi_step": _records("multi_step", "s", 3),
        "multi_step_truth": _records("multi_step_truth", "s", 4),
        "multi_step_pull_truth": _records("multi_step_pull_truth", "s", 7),
        "oracle": _records("oracle", "s", 8),
    }
    free = next(r for r in decompose(by_condition) if r["key"] == "success")
    assert free["planning"] == pytest.approx(10.0)  # oracle - pull truth
    assert free["meaning"] == pytest.approx(30.0)  # pull truth - deletion truth
    assert free["perception"] == pytest.approx(10.0)
    assert free["gap"] == pytest.approx(free["planning"] + free["meaning"] + free["perception"])
    assert free["pull_truth_condition"] == "multi_step_pull_truth"
    decomposition_table(by_condition, tmp_path, "tiny")
    text = (tmp_path / "table_6_3_decomposition.md").read_text()
    assert "what the map predicts" in text and "30.0 [" in text


def test_parts_are_taken_over_the_episodes_all_three_rows_ran():
    by_condition = {
        "m": _records("multi_step", "s", 2, n=4),
        "t": _records("multi_step_truth", "s", 4, n=10),
        "o": _records("oracle", "s", 4, n=10),
        "m_other": _records("multi_step", "other", 0),  # no truth / oracle on its stream
    }
    (free, _) = decompose(by_condition)
    assert free["episodes"] == 4 and free["perception"] == pytest.approx(50.0)
    assert free["stream"] == "s"


def test_the_table_is_written_with_its_figure(tmp_path):
    by_condition = {
        "multi_step": _records("multi_step", "s", 3),
        "multi_step_truth": _records("multi_step_truth", "s", 6),
        "oracle": _records("oracle", "s", 8),
    }
    raw = decomposition_table(by_condition, tmp_path, "tiny")
    assert raw is not None and len(raw) == 2
    text = (tmp_path / "table_6_3_decomposition.md").read_text()
    assert "planning part" in text and "30.0 [" in text
    assert (tmp_path / "table_6_3_decomposition.png").stat().st_size > 0
    assert decomposition_table({"oracle": by_condition["oracle"]}, tmp_path / "x", "tiny") is None


def test_the_robust_oracles_gap_is_beside_the_decomposition(tmp_path):
    """The noise stage's robust oracle on the stream: its rate and the CP row's points below
    it, paired over the episodes both ran; no such columns without it."""
    by_condition = {
        "multi_step": _records("multi_step", "s", 3),
        "multi_step_truth": _records("multi_step_truth", "s", 6),
        "oracle": _records("oracle", "s", 8),
    }
    decomposition_table(by_condition, tmp_path, "tiny")
    assert "robust oracle" not in (tmp_path / "table_6_3_decomposition.md").read_text()
    robust = {"oracle_robust": _records("oracle_robust", "s", 7, n=8)}
    free = next(r for r in decompose(by_condition | robust) if r["key"] == "success")
    assert free["robust_condition"] == "oracle_robust" and free["robust_episodes"] == 8
    assert free["robust_pct"] == pytest.approx(7 / 8 * 100)
    assert free["robust_gap"] == pytest.approx(50.0)  # 7 of 8 against 3 of 8
    assert free["robust_gap_lo"] <= free["robust_gap"] <= free["robust_gap_hi"]
    decomposition_table(by_condition | robust, tmp_path, "tiny")
    text = (tmp_path / "table_6_3_decomposition.md").read_text()
    assert "points below the robust oracle" in text and "50.0 [" in text


def test_every_planner_that_may_hold_is_measured_against_the_holding_oracle():
    from clutterbench.report.table_6_3 import ceiling
    from clutterbench.trials.ch6.planners import BUILT_IN, planner_info

    holding = [p for p in BUILT_IN if planner_info(p).holds]
    assert set(holding) == {
        "single_step",
        "bimanual",
        "bimanual_truth",
        "bimanual_pull_truth",
        "bimanual_pull",
        "bimanual_box",
        "bimanual_box_physics",
        "oracle_hold",
        "physics_from_depth_hold",
    }
    for planner in BUILT_IN:
        assert ceiling(planner) == ("oracle_hold" if planner in holding else "oracle"), planner
    # a planner's truth row and its baseline hold exactly when it does
    for planner in BUILT_IN:
        for other in (planner_info(planner).truth, planner_info(planner).baseline):
            if other is not None:
                assert planner_info(other).holds == (planner in holding), (planner, other)


def test_a_sensed_cp_row_adds_the_sensing_part(tmp_path):
    sensed = [
        r | {"sensing": "d415", "perception": "depth"} for r in _records("multi_step", "s", 1)
    ]
    by_condition = {
        "multi_step": _records("multi_step", "s", 3),
        "multi_step_truth": _records("multi_step_truth", "s", 6),
        "oracle": _records("oracle", "s", 8),
        "multi_step_d415": sensed,
    }
    (free,) = [r for r in decompose(by_condition) if r["key"] == "success"]
    assert free["condition"] == "multi_step" and free["sensed_condition"] == "multi_step_d415"
    assert free["gap"] == pytest.approx(50.0) and free["perception"] == pytest.approx(30.0)
    assert free["sensing"] == pytest.approx(20.0) and free["sensed_pct"] == pytest.approx(10.0)
    assert free["sensed_gap"] == pytest.approx(free["gap"] + free["sensing"])
    decomposition_table(by_condition, tmp_path, "tiny")
    text = (tmp_path / "table_6_3_decomposition.md").read_text()
    assert "sensing part" in text and "sensed multi_step_d415" in text
    # without the sensed row the table is as before: no sensing column
    del by_condition["multi_step_d415"]
    decomposition_table(by_condition, tmp_path, "tiny")
    assert "sensing part" not in (tmp_path / "table_6_3_decomposition.md").read_text()
