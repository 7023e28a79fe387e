"""Chapter 6 trials on hand-built and drawn scenes: physics truth, the judge, determinism."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from clutterbench.logs.mcap_episode import read_episode
from clutterbench.models import build_model
from clutterbench.models.checkpoint import save_checkpoint
from clutterbench.models.collapse_map import CollapseMapConfig
from clutterbench.models.vgg import VGGConfig
from clutterbench.planning.extraction import Decision, TargetFirstPlanner
from clutterbench.planning.support import SupportParams
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch6 import OraclePlanner, ch6_jobs, pull_out, run_ch6_episode
from clutterbench.trials.config import ConditionConfig, SceneStreamConfig, TrialsConfig
from clutterbench.trials.harness import EpisodeLog, run_episodes, write_mcap
from clutterbench.trials.records import read_records, write_records
from clutterbench.trials.scenes import pull_consequences, truth_moved_contact

STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
CAM = CameraConfig(image_size=64)
THR = 0.005


@pytest.fixture(scope="module")
def stack3() -> SceneSpec:
    return SceneSpec.load(STACK3)


def test_truth_support_graph_of_a_stack_is_bottom_middle_top(stack3, physics):
    moved, contact = truth_moved_contact(stack3, physics, THR)
    truth = {(int(a), int(b)) for a, b in zip(*np.nonzero(moved & contact))}
    # Removing the bottom box moves both others, but it touches only the middle one.
    assert moved[0, 1] and moved[0, 2]
    assert truth == {(0, 1), (1, 2)}


def test_boxes_side_by_side_give_no_edge(physics):
    """Two boxes standing side by side on the floor (touching): neither supports the other."""
    size = np.array([0.1, 0.1, 0.08])
    poses = np.array([[0.14, y, 0.04, 1.0, 0.0, 0.0, 0.0] for y in (-0.0501, 0.0501)])
    spec = SceneSpec(sizes_m=np.stack([size, size]), poses=poses)
    moved, contact = truth_moved_contact(spec, physics, THR)
    assert not moved.any()
    assert not (moved & contact).any()


def test_pulling_the_top_is_clean_and_pulling_the_bottom_fails(stack3, physics):
    params = TrialsConfig().ch6
    for box, expect in ((2, True), (0, False)):
        world = BoxWorld.from_spec(stack3, physics, render=True)
        step = pull_out(
            world, Decision(box, None, {}), TargetFirstPlanner(), CAM, params, 1.0, EpisodeLog()
        )
        assert step["extracted"] is True
        assert step["success"] is expect, (box, step)
        assert (step["n_disturbed"] == 0) is expect


def test_holding_the_middle_box_makes_pulling_the_bottom_clean(stack3, physics):
    """Bimanual (Fig. 6.7): the held box keeps what it supports in place."""
    world = BoxWorld.from_spec(stack3, physics, render=True)
    params = TrialsConfig().ch6
    step = pull_out(world, Decision(0, 1, {}), TargetFirstPlanner(), CAM, params, 1.0, EpisodeLog())
    assert step["extracted"] and step["success"], step


def test_pull_consequences_match_the_judge(stack3, physics):
    disp = pull_consequences(stack3, physics, [0, 2])
    assert np.nanmax(disp[0]) > THR
    assert np.nanmax(disp[2]) <= THR


def test_the_oracle_pulls_the_top_first_and_knows_it_is_the_only_safe_pull(stack3, physics):
    world = BoxWorld.from_spec(stack3, physics, render=True)
    params = TrialsConfig().ch6
    decision = OraclePlanner(world, stack3, physics, params).decide(
        observe(world, CAM), 0, frozenset()
    )
    assert decision.pull == 2 and decision.state["safe"] == [2]
    assert [1, 2] in [e[:2] for e in decision.state["edges"]]


@pytest.fixture(scope="module")
def tiny_cp(tmp_path_factory) -> Path:
    torch.manual_seed(0)
    cfg = CollapseMapConfig(
        input_size=64, encoder=VGGConfig(width=0.125), decoder_channels=(32, 16, 16, 8, 8)
    )
    path = tmp_path_factory.mktemp("cp") / "best.pt"
    save_checkpoint(path, "collapse_map", build_model("collapse_map", cfg), {"epoch": 0})
    return path


def _jobs(planner: str, cp: Path, episodes: int = 2) -> list[dict]:
    stream = SceneStreamConfig(families={"stacked": 1, "random": 1}, n_objects=(3, 5))
    cfg = TrialsConfig(
        streams={"s": stream},
        conditions={"c": ConditionConfig(planner=planner, stream="s", episodes=episodes)},
    )
    support = SupportParams("coverage", 0.5, 0.3, 2, 0.0)
    return ch6_jobs(
        "c", cfg.conditions["c"], cfg, stream, 0, PhysicsConfig(), CAM, support, 0.3, cp
    )


@pytest.mark.parametrize("planner", ["single_step", "multi_step", "bimanual", "oracle", "random"])
def test_every_planner_gives_a_judged_record(planner, tiny_cp):
    rec = run_ch6_episode(_jobs(planner, tiny_cp, 1)[0]).record
    assert rec["planner"] == planner and rec["steps"]
    assert rec["success"] == (rec["target_out"] and all(s["others_still"] for s in rec["steps"]))
    for s in rec["steps"]:
        assert s["success"] == (s["extracted"] and s["n_disturbed"] == 0)
    assert rec["end"] in ("target_out", "max_steps", "stuck")


def test_same_scenes_and_targets_on_one_stream(tiny_cp):
    a = [run_ch6_episode(j).record for j in _jobs("single_step", tiny_cp)]
    b = [run_ch6_episode(j).record for j in _jobs("random", tiny_cp)]
    assert [(r["family"], r["n_objects"], r["target"]) for r in a] == [
        (r["family"], r["n_objects"], r["target"]) for r in b
    ]


def test_records_and_mcap_are_byte_identical_across_worker_counts(tiny_cp, tmp_path):
    jobs = _jobs("multi_step", tiny_cp)
    one = run_episodes("t", run_ch6_episode, jobs, workers=1)
    two = run_episodes("t", run_ch6_episode, jobs, workers=2)
    for name, results in (("one", one), ("two", two)):
        write_records(tmp_path / name / "records.jsonl", [r.record for r in results])
        write_mcap(tmp_path / name / "episodes.mcap", results, {"condition": "c"})
    for f in ("records.jsonl", "episodes.mcap"):
        assert (tmp_path / "one" / f).read_bytes() == (tmp_path / "two" / f).read_bytes(), f
    assert read_records(tmp_path / "one" / "records.jsonl") == [r.record for r in one]
    topics = read_episode(tmp_path / "one" / "episodes.mcap")["topics"]
    assert topics["/trial/episode"] == 2 and topics["/trial/outcome"] == 2
    assert topics["/camera/depth"] >= 2 and topics["/planner/decision"] >= 2
