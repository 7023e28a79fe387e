"""Table 6.3 paired: a CP row against physics from depth, episode by episode."""

from __future__ import annotations

import pytest

from clutterbench.report.paired import mcnemar_p, paired_rows, paired_table


def _records(planner: str, stream: str, wins: set[int], n: int = 10):
    return [
        {
            "planner": planner,
            "stream": stream,
            "episode": e,
            "success": e in wins,
            "strict_success": e in wins,
        }
        for e in range(n)
    ]


def test_rows_pair_episodes_and_count_the_discordant_ones(tmp_path):
    by_condition = {
        "multi_step_pull": _records("multi_step_pull", "s", {0, 1, 2, 3, 4, 5}),
        "physics_from_depth": _records("physics_from_depth", "s", {0, 1, 2, 6}),
        "bimanual_pull": _records("bimanual_pull", "s", {0}),
        "physics_from_depth_hold": _records("physics_from_depth_hold", "t", {0}),
    }
    rows = paired_rows(by_condition)
    # bimanual_pull's baseline ran another stream: no pair
    assert {r["planner"] for r in rows} == {"multi_step_pull"}
    free = next(r for r in rows if r["key"] == "success")
    assert (free["only_cp"], free["only_baseline"]) == (3, 1)
    assert free["difference"] == pytest.approx(20.0)
    assert free["cp_pct"] == pytest.approx(60.0) and free["baseline_pct"] == pytest.approx(40.0)
    assert free["difference_lo"] <= free["difference"] <= free["difference_hi"]
    assert free["p"] == pytest.approx(0.625)  # 2 * (1 + 4) / 16
    paired_table(by_condition, tmp_path, "tiny")
    text = (tmp_path / "table_6_3_paired.md").read_text()
    assert "+20.0 [" in text and "physics_from_depth]" in text


def test_the_holding_planners_meet_the_holding_baseline():
    by_condition = {
        "bimanual": _records("bimanual", "s", {0, 1}),
        "physics_from_depth": _records("physics_from_depth", "s", set(range(10))),
        "physics_from_depth_hold": _records("physics_from_depth_hold", "s", {1, 2}),
    }
    (free, _) = paired_rows(by_condition)
    assert free["baseline_condition"] == "physics_from_depth_hold"
    assert (free["only_cp"], free["only_baseline"]) == (1, 1)


def test_mcnemar_p_by_hand():
    assert mcnemar_p(0, 0) == 1.0
    assert mcnemar_p(5, 0) == pytest.approx(2 / 32)
    assert mcnemar_p(13, 10) == mcnemar_p(10, 13) > 0.5


def _sensed(records, sensing="d415", perception="depth"):
    return [r | {"sensing": sensing, "perception": perception} for r in records]


def test_sensed_rows_meet_the_baseline_that_saw_alike():
    by_condition = {
        "multi_step_pull": _records("multi_step_pull", "s", {0, 1, 2}),
        "physics_from_depth": _records("physics_from_depth", "s", {0}),
        "multi_step_pull_d415": _sensed(_records("multi_step_pull", "s", {0, 1, 5, 6})),
        "physics_from_depth_d415": _sensed(_records("physics_from_depth", "s", {5})),
        # under another sensor: no baseline saw alike
        "bimanual_pull_sl": _sensed(_records("bimanual_pull", "s", {0}), "structured_light"),
        "physics_from_depth_hold_d415": _sensed(_records("physics_from_depth_hold", "s", {0})),
    }
    rows = [r for r in paired_rows(by_condition) if r["key"] == "success"]
    assert [(r["condition"], r["baseline_condition"]) for r in rows] == [
        ("multi_step_pull", "physics_from_depth"),
        ("multi_step_pull_d415", "physics_from_depth_d415"),
    ]
    ideal, sensed = rows
    assert "seen" not in ideal and sensed["seen"] == ("d415", "depth")
    assert (sensed["only_cp"], sensed["only_baseline"]) == (3, 0)
