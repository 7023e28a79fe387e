"""A sensed chapter 6 row runs with what the support stage chose on the val scenes as its
sensor returned them (thresholds.json and box_fusion.json `sensed.<sensor>`); an ideal row
with what it chose on exact depth; a sensor the stage chose nothing for is one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.report.build import support_thresholds
from clutterbench.trials.ch6.episodes import box_fields, planner_support
from clutterbench.trials.ch6.planners import planner_info
from clutterbench.trials.config import Ch6TrialParams

CH6 = Ch6TrialParams()
RULE = "coverage_gap"


def _support(prob: float, score: float) -> dict:
    return {
        "rule": "coverage",
        "prob_threshold": prob,
        "score_threshold": score,
        "bbox_margin_px": 2,
        "adjacency_iou": 0.05,
        "max_gap_m": 0.07,
    }


def _choice(prob: float, score: float, edge: float) -> dict:
    methods = {planner_info(p).support_method(RULE, CH6.pull_map_meaning) for p in PLANNERS}
    heads = {
        "pull": {"edge": edge, "outcome": 0.5},
        "pull_collapse": {"edge": edge, "outcome": 0.45},
    }
    return {"chosen": {m: _support(prob, score) for m in methods}, "box_head": heads}


def _fusion(edge: float, w: float) -> dict:
    one = {"edge": edge, "outcome": 0.4, "weights": [w, 1.0, 2.0], "physics_edge": edge / 2}
    return {"chosen": {"pull": one, "pull_collapse": one}}


PLANNERS = ("multi_step", "multi_step_pull", "bimanual_box", "multi_step_box_physics")
IDEAL_HEAD = Path("models/box_head/best.pt")  # stage box_head's
D415_HEAD = Path("models/box_head_sensed/d415/best.pt")  # stage box_head_sensed's


@pytest.fixture
def project(tmp_path, monkeypatch) -> Path:
    """A project whose support stage chose apart on exact and on d415 val depth."""
    monkeypatch.chdir(tmp_path)
    for head in (IDEAL_HEAD, D415_HEAD):
        (tmp_path / head).parent.mkdir(parents=True)
        (tmp_path / head).write_bytes(b"")
    out = tmp_path / "reports/support"
    out.mkdir(parents=True)
    ideal, sensed = _choice(0.4, 0.2, 0.45), _choice(0.6, 0.5, 0.7)
    (out / "thresholds.json").write_text(json.dumps(ideal | {"sensed": {"d415": sensed}}))
    fusion = _fusion(0.3, 0.1) | {"sensed": {"d415": _fusion(0.8, 0.9)}}
    (out / "box_fusion.json").write_text(json.dumps(fusion))
    return out / "thresholds.json"


@pytest.mark.parametrize("planner", ["multi_step", "multi_step_pull"])
def test_a_cp_row_reads_the_thresholds_of_its_own_sensor(project, planner):
    ideal, _ = planner_support(project, planner, RULE, CH6)
    sensed, cp_max = planner_support(project, planner, RULE, CH6, "d415")
    assert (ideal.prob_threshold, ideal.score_threshold) == (0.4, 0.2)
    assert (sensed.prob_threshold, sensed.score_threshold) == (0.6, 0.5)
    assert cp_max == (CH6.cp_max if CH6.cp_max is not None else 0.5)


def test_a_box_row_reads_the_head_edges_and_fusion_of_its_own_sensor(project):
    box, _ = box_fields(project, "bimanual_box", CH6)
    assert (box["box_edge_threshold"], box["box_head_path"]) == (0.45, IDEAL_HEAD)
    box, _ = box_fields(project, "bimanual_box", CH6, "d415")
    assert (box["box_edge_threshold"], box["box_head_path"]) == (0.7, D415_HEAD)
    fused, _ = box_fields(project, "multi_step_box_physics", CH6)
    assert (fused["box_edge_threshold"], fused["box_fusion"][0]) == (0.3, 0.1)
    fused, _ = box_fields(project, "multi_step_box_physics", CH6, "d415")
    assert (fused["box_edge_threshold"], fused["box_fusion"][0]) == (0.8, 0.9)
    assert fused["box_head_path"] == D415_HEAD


def test_a_sensor_the_support_stage_chose_nothing_for_is_one_line(project):
    with pytest.raises(ClutterbenchError, match="structured_light to support.sensing"):
        planner_support(project, "multi_step_pull", RULE, CH6, "structured_light")
    with pytest.raises(
        ClutterbenchError, match="structured_light/best.pt missing .* box_head_sensed"
    ):
        box_fields(project, "bimanual_box_physics", CH6, "structured_light")
    head = Path("models/box_head_sensed/structured_light/best.pt")
    head.parent.mkdir(parents=True)
    head.write_bytes(b"")
    with pytest.raises(ClutterbenchError, match="box_fusion.json: nothing chosen"):
        box_fields(project, "bimanual_box_physics", CH6, "structured_light")


def test_table_6_2_shows_each_sensed_row_the_thresholds_it_ran_with(project):
    shown = support_thresholds(project, project.with_name("box_fusion.json"))
    pull = planner_info("multi_step_pull").support_method(RULE, CH6.pull_map_meaning)
    assert (shown[pull]["prob_threshold"], shown[f"{pull}@d415"]["prob_threshold"]) == (0.4, 0.6)
    assert (shown["pull_box"]["edge"], shown["pull_box@d415"]["edge"]) == (0.45, 0.7)
    assert (shown["pull_box_fused"]["edge"], shown["pull_box_fused@d415"]["edge"]) == (0.3, 0.8)
    assert shown["pull_physics_pull@d415"] == {"edge": 0.4}


def test_the_support_stage_refuses_a_sensor_whose_box_head_was_not_trained(project):
    """Its sensed choice and rows read the head of their sensor (stage box_head_sensed): one
    line naming that stage when it is missing, never the exact-depth head instead."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.support.run import sensed_box_head

    with pytest.raises(ClutterbenchError, match="structured_light depth; run stage box_head_sen"):
        sensed_box_head(None, Path("models/cp/best.pt"), SimConfig(), "structured_light")  # type: ignore[arg-type]
