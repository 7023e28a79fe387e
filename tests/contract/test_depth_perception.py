"""Chapter 6 trials with object masks from depth (`perception: depth`): the planner reads
segments of the sensed depth image, a pull takes the box under the chosen segment's grasp
point, a grasp on no box is a recorded failed step, and the records say so."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import CameraConfig, SimConfig
from clutterbench.trials.ch6 import episodes as ch6_episodes
from clutterbench.trials.ch6.episodes import condition_jobs, run_ch6_episode
from clutterbench.trials.ch6.seeing import Eyes
from clutterbench.trials.config import ConditionConfig, SceneStreamConfig, TrialsConfig
from tests.toy_jobs import toy_ch6_jobs

STREAM = SceneStreamConfig(families={"stacked": 1, "random": 1}, n_objects=(3, 6))
CAM = CameraConfig(image_size=96)


def _jobs(planner: str, episodes: int = 2, sensing: str = "ideal"):
    return [
        dataclasses.replace(job, perception="depth", sensing=sensing)
        for job in toy_ch6_jobs(planner, STREAM, CAM, episodes=episodes)
    ]


@pytest.mark.parametrize("sensing", ["ideal", "d415"])
@pytest.mark.parametrize("planner", ["random", "physics_from_depth"])
def test_depth_perception_runs_whole_episodes_and_says_so(planner, sensing):
    for job in _jobs(planner, sensing=sensing):
        rec = run_ch6_episode(job).record
        assert rec["perception"] == "depth"
        assert rec["perception_failures"] >= 0 and rec["target_unpointed"] >= 0
        assert rec["success"] == (rec["end"] == "target_out")
        for step in rec["steps"]:  # the executed box is a real box, or the grasp took none
            assert step["box"] is None or 0 <= step["box"] < rec["n_objects"]
            assert (step["box"] is None) == (step.get("grasp") == "no box")


def test_the_planner_reads_segments_not_the_simulator_s_masks(monkeypatch):
    """The observation a planner decides on is the segmentation's, and the pull acts on the
    box its grasp takes (the harness's mapping)."""
    seen_by_planner = []
    real_pointed = Eyes.pointed

    def spy(self, box):
        seen_by_planner.append((self.seen, self.truth))
        return real_pointed(self, box)

    monkeypatch.setattr(Eyes, "pointed", spy)
    job = _jobs("random", episodes=1)[0]
    rec = run_ch6_episode(job).record
    assert seen_by_planner and rec["steps"]
    seen, truth = seen_by_planner[0]
    assert seen is not None and seen.obs.instance.shape == truth.instance.shape
    assert np.array_equal(seen.obs.depth_m, truth.depth_m)
    first = rec["steps"][0]
    pulled = first.get("seen_pull", first["box"])
    assert seen.box_of(pulled) == first["box"]


def test_a_grasp_on_no_box_is_a_failed_step_that_ends_the_episode(monkeypatch):
    monkeypatch.setattr(Eyes, "grasped", lambda self, seen_id: None)
    job = _jobs("random", episodes=1)[0]
    rec = run_ch6_episode(job).record
    assert rec["end"] == "missed_grasp" and not rec["success"] and not rec["strict_success"]
    (step,) = rec["steps"]
    assert step["grasp"] == "no box" and step["box"] is None and not step["executed"]
    assert step["success"] is False and step["seen_pull"] is not None


@pytest.mark.parametrize(("planner", "executor"), [("oracle", "kinematic"), ("random", "arm")])
def test_depth_perception_is_refused_where_it_cannot_hold(planner, executor):
    trials = TrialsConfig(streams={"s": STREAM})
    cond = ConditionConfig(planner=planner, stream="s", perception="depth", executor=executor)
    with pytest.raises(ClutterbenchError, match="perception depth"):
        condition_jobs(
            "c",
            cond,
            trials=trials,
            sim=SimConfig(camera=CAM),
            seed=0,
            thresholds=Path("no_thresholds.json"),
        )


def test_instance_perception_reads_the_simulator_s_masks_as_before():
    job = toy_ch6_jobs("random", STREAM, CAM, episodes=1)[0]
    assert job.perception == "instance"
    rec = run_ch6_episode(job).record
    assert rec["perception"] == "instance" and "perception_failures" not in rec
    assert all("seen_pull" not in s for s in rec["steps"])
    assert ch6_episodes.Eyes is Eyes


def test_a_hold_whose_grasp_takes_the_pulled_box_leaves_the_second_arm_idle(monkeypatch):
    """Two segments of one box, one pulled and one held: the second arm finds the box taken."""
    from clutterbench.planning.ch6.extraction import Decision

    job = _jobs("random", episodes=1)[0]
    spec = ch6_episodes.job_spec(job)
    episode = ch6_episodes.Extraction(spec, job)
    monkeypatch.setattr(Eyes, "grasped", lambda self, seen_id: None if seen_id is None else 0)
    step = episode.step(Decision(pull=0, hold=7, state={}), planner=object())
    assert step["box"] == 0 and step["hold"] is None
    assert step["grasp"] == "hold on the pulled box"
    assert step["seen_hold"] == 7
