"""A new ch. 6 planner in two files: its own module and its conditions in params.yaml.

Its declaration alone decides how everything else treats it: the trials run it, the report
labels its row and measures it against the ceiling it declares, the decomposition and the
paired table pair it with the rows it names, the bench and the environments see what it
needs. No other file knows its name."""

from __future__ import annotations

import dataclasses
import sys

import pytest

from clutterbench.report.decomposition import decompose
from clutterbench.report.paired import paired_rows
from clutterbench.report.table_6_3 import oracle_gaps, row_label
from clutterbench.sim.config import CameraConfig
from clutterbench.trials.ch6.episodes import load_planners, run_ch6_episode
from clutterbench.trials.ch6.planners import PLANNERS, planner_info
from clutterbench.trials.config import ConditionConfig, SceneStreamConfig, TrialsConfig
from tests.toy_jobs import toy_ch6_jobs

MODULE = """
from clutterbench.planning.ch6.extraction import TargetFirstPlanner
from clutterbench.trials.ch6.planners import register_planner


@register_planner(
    "throwaway_hold",
    label="throwaway: pull the target at once (declared as holding)",
    holds=True,
    truth="bimanual_truth",
    baseline="physics_from_depth_hold",
)
def make(job, spec):
    return TargetFirstPlanner()
"""

STREAM = SceneStreamConfig(families={"stacked": 1, "random": 1}, n_objects=(3, 4))
CAM = CameraConfig(image_size=64)
EPISODES = 2


@pytest.fixture
def throwaway(tmp_path, monkeypatch):
    (tmp_path / "throwaway_planner.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "throwaway_planner"
    PLANNERS.pop("throwaway_hold", None)
    sys.modules.pop("throwaway_planner", None)


def _records(planner: str) -> list[dict]:
    jobs = toy_ch6_jobs(planner, STREAM, CAM, episodes=EPISODES)
    return [run_ch6_episode(dataclasses.replace(j, condition=planner)).record for j in jobs]


def test_a_planner_in_its_own_module_is_run_reported_and_decomposed(throwaway):
    # params.yaml: its module in trials.planner_modules, a condition naming it
    conditions = {"mine": ConditionConfig(planner="throwaway_hold", stream="s", episodes=2)}
    trials = TrialsConfig(
        planner_modules=(throwaway,), streams={"s": STREAM}, conditions=conditions
    )
    load_planners(trials.planner_modules, [c.planner for c in trials.conditions.values()])
    declared = planner_info("throwaway_hold")
    assert declared.agent and not declared.networks and declared.ceiling == "oracle_hold"

    names = ("throwaway_hold", "bimanual_truth", "oracle_hold", "physics_from_depth_hold")
    records = {name: _records(name) for name in names}
    assert all(r["planner"] == "throwaway_hold" for r in records["throwaway_hold"])
    assert all(r["collapse_maps"] is None for r in records["throwaway_hold"])

    # the report: its label, and the holding search as its ceiling
    assert row_label("throwaway_hold") == "throwaway: pull the target at once (declared as holding)"
    assert oracle_gaps(records)["throwaway_hold"]["oracle"] == "oracle_hold"
    # the decomposition: its declared truth row and ceiling, on the same episodes
    rows = [r for r in decompose(records) if r["planner"] == "throwaway_hold"]
    assert {r["key"] for r in rows} == {"success", "strict_success"}
    assert all(r["truth_condition"] == "bimanual_truth" for r in rows)
    assert all(r["oracle_condition"] == "oracle_hold" for r in rows)
    assert all(r["episodes"] == EPISODES for r in rows)
    # the paired table: its declared baseline
    paired = [r for r in paired_rows(records, resamples=50) if r["planner"] == "throwaway_hold"]
    assert paired and all(r["baseline_condition"] == "physics_from_depth_hold" for r in paired)


def test_the_bench_and_the_environments_read_the_declaration(throwaway):
    from clutterbench.bench.workloads import mix_conditions
    from clutterbench.envs.agents import agent_planners

    load_planners([throwaway], ["throwaway_hold"])
    conditions = {
        "mine": ConditionConfig(planner="throwaway_hold", stream="s"),
        "cp": ConditionConfig(planner="multi_step", stream="s"),
    }
    assert mix_conditions(TrialsConfig(streams={"s": STREAM}, conditions=conditions)) == ["mine"]
    assert "throwaway_hold" in agent_planners()
    assert "oracle" not in agent_planners() and "multi_step_box" not in agent_planners()
