"""Trials under a depth sensor model: a sensed condition's planner sees the sensor's depth,
its record says which sensor, and no observation a sensor can return crashes a planner."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from clutterbench.observation import Observation
from clutterbench.sim.config import CameraConfig
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch6.episodes import ch6_jobs, run_ch6_episode
from clutterbench.trials.ch6.planners import BUILT_IN, make_planner, planner_info
from clutterbench.trials.config import ConditionConfig, SceneStreamConfig, TrialsConfig
from tests.toy_jobs import TOY_SUPPORT, toy_ch6_jobs, toy_planner_jobs

STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
STREAM = SceneStreamConfig(families={"stacked": 1, "random": 1}, n_objects=(3, 6))
CAM = CameraConfig(image_size=64)
SENSORS = ("structured_light", "d415")


def test_the_picture_passes_through_the_camera_s_sensor(physics):
    spec = SceneSpec.load(STACK3)
    world = world_at(spec, SceneState.start(spec), physics, render=True)
    exact = observe(world, CAM)
    for sensing in SENSORS:
        seen = observe(world, CAM, sensing)
        again = observe(world, CAM, sensing)
        assert seen.depth_m.dtype == np.float32 and np.isfinite(seen.depth_m).all()
        assert not np.array_equal(seen.depth_m, exact.depth_m)
        assert np.array_equal(seen.depth_m, again.depth_m)  # seeded by the picture
        assert np.array_equal(seen.instance, exact.instance)  # masks stay the simulator's
        hit = (seen.depth_m > 0) & (exact.depth_m > 0)
        assert np.median(np.abs(seen.depth_m[hit] - exact.depth_m[hit])) < 0.005


def test_a_sensed_condition_says_its_sensor_and_an_ideal_one_says_nothing():
    trials = TrialsConfig(streams={"s": STREAM})
    for sensing in ("ideal", "d415"):
        cond = ConditionConfig(planner="random", stream="s", episodes=1, sensing=sensing)
        from clutterbench.sim.config import SimConfig

        job = ch6_jobs(
            "c",
            cond,
            trials=trials,
            sim=SimConfig(camera=CAM),
            seed=0,
            support=TOY_SUPPORT,
            cp_max=0.3,
            model_path=None,
        )[0]
        assert job.sensing == sensing
        rec = run_ch6_episode(job).record
        assert rec.get("sensing") == (None if sensing == "ideal" else sensing)


@pytest.mark.parametrize("sensing", SENSORS)
@pytest.mark.parametrize("planner", ["physics_from_depth", "physics_from_depth_hold"])
def test_physics_from_depth_runs_whole_sensed_episodes(planner, sensing):
    for job in toy_ch6_jobs(planner, STREAM, CAM, episodes=2):
        rec = run_ch6_episode(dataclasses.replace(job, sensing=sensing)).record
        assert rec["sensing"] == sensing and rec["steps"]
        assert rec["success"] == (rec["end"] == "target_out")


def _defeating(obs: Observation, rng: np.random.Generator) -> dict[str, Observation]:
    """Depth images a sensor can return that defeat perception: no return at all, mostly
    holes, one flat wall, heavy noise, speckle of flying pixels."""
    d = obs.depth_m
    holed = d.copy()
    holed[rng.random(d.shape) < 0.7] = 0.0
    noisy = np.where(d > 0, d + rng.normal(0.0, 0.02, d.shape), 0.0).astype(np.float32)
    flying = d.copy()
    spots = rng.random(d.shape) < 0.1
    flying[spots] = rng.uniform(0.2, 1.5, int(spots.sum())).astype(np.float32)
    images = {
        "empty": np.zeros_like(d),
        "holed": holed,
        "wall": np.full_like(d, float(np.median(d[d > 0]))),
        "noisy": noisy,
        "flying": flying,
    }
    return {k: dataclasses.replace(obs, depth_m=v.astype(np.float32)) for k, v in images.items()}


ROBOT_PLANNERS = [p for p in BUILT_IN if planner_info(p).world != "truth"]
"""Every built-in planner a robot could run: it reads the picture (and networks, or boxes
fitted to the picture), not the true scene."""


@pytest.mark.parametrize("planner", ROBOT_PLANNERS)
def test_no_depth_image_crashes_a_planner(planner, physics, toy_networks):
    """A planner handed a depth image that defeats its perception decides (or gives up with
    ValueError, the harness' gave_up); nothing else may escape."""
    spec = SceneSpec.load(STACK3)
    obs = observe(world_at(spec, SceneState.start(spec), physics, render=True), CAM)
    job = toy_planner_jobs(planner, STREAM, CAM, toy_networks)[0]
    for name, seen in _defeating(obs, np.random.default_rng(0)).items():
        decider = make_planner(job, spec)
        try:
            decision = decider.decide(seen, 2, frozenset())
        except ValueError:
            continue  # no action left: the episode ends gave_up
        assert decision.pull in range(spec.n), (name, decision)


@pytest.mark.parametrize("planner", ROBOT_PLANNERS)
def test_every_planner_a_robot_could_run_ends_sensed_episodes_with_masks_from_depth(
    planner, toy_networks
):
    """Whole episodes under the D415-class sensor with masks from depth, the networks untrained:
    an episode ends judged (or gave up), counted in the record, never an exception."""
    for job in toy_planner_jobs(planner, STREAM, CAM, toy_networks, episodes=2):
        rec = run_ch6_episode(dataclasses.replace(job, sensing="d415", perception="depth")).record
        assert (rec["sensing"], rec["perception"]) == ("d415", "depth")
        assert rec["success"] == (rec["end"] == "target_out")
        assert rec["end"] in ("target_out", "collapse", "target_fell", "gave_up", "max_steps")
