"""Chapter 4 trials: the E / S / C / B map of a hand-built pull, the judge, the planners,
one episode per planner and mode, and the Fig. 4.8 figure."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.data.labels import CLASS_B, CLASS_C, CLASS_E, CLASS_S, ch4_class_map
from clutterbench.observation import Observation
from clutterbench.perception.masks import masks_from_instance
from clutterbench.perception.seen import grasp_point
from clutterbench.planning.ch4.risk import risk_index, soft_collapse
from clutterbench.planning.ch4.risk_planner import plan_risk
from clutterbench.sim.config import CameraConfig, PhysicsConfig, SimConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.renderer import ensure_renderer
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch4.episodes import ch4_jobs, observe_and_segment, run_ch4_episode
from clutterbench.trials.ch4.execution import plan_oracle, pull_outcome
from clutterbench.trials.ch4.figure import draw_figure
from clutterbench.trials.config import (
    Ch4ConditionConfig,
    Ch4TrialParams,
    SceneStreamConfig,
    TrialsConfig,
)
from clutterbench.trials.core.harness import load_predictor

STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
CAM = CameraConfig(image_size=64)
THR = 0.005
CF = CollapseFreeConfig()


@pytest.fixture(scope="module")
def stack3() -> SceneSpec:
    return SceneSpec.load(STACK3)


def test_class_map_of_a_hand_built_pull(stack3, physics):
    """Stack bottom 0, middle 1, top 2: pulling the bottom while holding the top drags the
    middle box along (C = its pixels); holding the middle keeps everything in place."""
    ensure_renderer()
    world = BoxWorld.from_spec(stack3, physics, render=True)
    inst = observe(world, CAM).instance
    # the labels are the motion while the support is still held
    dragged = pull_outcome(stack3, physics, 0, 2, THR, CF)["displacement_held_m"]
    labels = ch4_class_map(inst, 0, 2, dragged, THR)
    assert np.array_equal(labels == CLASS_E, inst == 1)
    assert np.array_equal(labels == CLASS_S, inst == 3)
    assert np.array_equal(labels == CLASS_C, inst == 2) and (labels == CLASS_C).any()
    assert np.array_equal(labels == CLASS_B, inst == 0)
    held = pull_outcome(stack3, physics, 0, 1, THR, CF)["displacement_held_m"]
    assert not (ch4_class_map(inst, 0, 1, held, THR) == CLASS_C).any()


def test_a_pull_that_drags_a_neighbour_off_the_shelf_fails(stack3, physics):
    out = pull_outcome(stack3, physics, 0, 2, THR, CF)
    assert out["target_out"] and out["n_left_shelf"] == 1
    assert not out["success"] and not out["strict_success"]
    nothing_held = pull_outcome(stack3, physics, 0, None, THR, CF)
    assert nothing_held["n_left_shelf"] == 2 and not nothing_held["success"]


def test_a_clean_pull_succeeds_and_is_judged_after_the_release(stack3, physics):
    # Pulling the top box while holding the middle one: still once the middle is let go.
    out = pull_outcome(stack3, physics, 2, 1, THR, CF)
    assert out["success"] and out["strict_success"] and out["strict_success_held"]
    assert out["n_left_shelf"] == 0 and out["n_disturbed"] == 0
    # Pulling the bottom box from under the held middle one: clean while held; once released,
    # the middle box and the top one it carries drop onto the floor (on the shelf, but the
    # top box dropped: a collapse, and not a strict success either).
    out = pull_outcome(stack3, physics, 0, 1, THR, CF)
    assert out["success_held"] and out["strict_success_held"]
    assert not out["success"] and not out["strict_success"] and out["n_collapsed"] == 1
    assert out["n_left_shelf"] == 0 and out["n_disturbed"] == 1
    # The middle box from under the held top one: the released top box settles onto the
    # bottom one; it was manipulated, nothing else moved: strict success.
    out = pull_outcome(stack3, physics, 1, 2, THR, CF)
    assert out["success"] and out["strict_success"] and out["n_disturbed"] == 0


def test_oracle_keeps_a_strict_success(stack3, physics):
    pairs = [(0, 2), (1, 0), (0, 1), (2, 0)]
    k, tried, first = plan_oracle(stack3, physics, pairs, THR, CF, np.random.default_rng(0))
    assert first == k and pairs[k] in ((0, 1), (2, 0))
    assert 1 <= tried <= len(pairs)
    bad = [(0, 2), (1, 0), (0, None)]
    k, tried, first = plan_oracle(stack3, physics, bad, THR, CF, np.random.default_rng(0))
    assert first == -1 and tried == len(bad)
    assert bad[k] != (0, None)  # two boxes off the shelf is worse than one


def test_risk_planner_takes_the_argmin_of_the_network_risks(stack3, physics, tiny_ch4):
    ensure_renderer()
    obs: Observation = observe(BoxWorld.from_spec(stack3, physics, render=True), CAM)
    seg = masks_from_instance(obs, 5)
    predictor = load_predictor(tiny_ch4, 64)
    choice, pairs, risks, probs = plan_risk(predictor, obs, seg, None, 0.4)
    assert len(pairs) == 6 and probs.shape == (6, 4, 64, 64)
    assert np.allclose(probs.sum(axis=1), 1.0, atol=1e-4)
    assert np.array_equal(risks, risk_index(probs, 0.4))
    soft = soft_collapse(probs)  # equal risks: the least mean P(C), then candidate order
    best = int(np.lexsort((np.arange(len(pairs)), soft, risks))[0])
    assert (choice.extract, choice.support) == pairs[best]
    choice, pairs, _, _ = plan_risk(predictor, obs, seg, 1, 0.4)
    assert pairs == [(1, 0), (1, 2)] and choice.extract == 1


class ExtractCollapses(torch.nn.Module):
    """A stand-in network: predicts the extracted object's own pixels as C and everything else
    as B, so r_c is the extracted segment's share of the picture."""

    def forward(self, depth_m: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        c = 10.0 * masks[:, :1]
        zeros = torch.zeros_like(c)
        return torch.cat([5.0 + zeros, zeros, zeros, c], dim=1)  # B, E, S, C


def test_risk_planner_pulls_the_pair_of_least_predicted_collapse(stack3, physics):
    from clutterbench.collapse.predict import CollapsePredictor

    ensure_renderer()
    obs = observe(BoxWorld.from_spec(stack3, physics, render=True), CAM)
    seg = masks_from_instance(obs, 5)
    predictor = CollapsePredictor(ExtractCollapses(), precision="fp32", channels_last=False)
    choice, pairs, risks, _ = plan_risk(predictor, obs, seg, None, 0.4)
    area = seg.masks.sum(axis=(1, 2))
    assert choice.extract == int(np.argmin(area))
    assert choice.risk == pytest.approx(area.min() / seg.masks[0].size)
    assert len(set(risks.tolist())) == len(seg.ids)  # one risk per extracted segment


class FaintExtractCollapse(torch.nn.Module):
    """Everything background above 0.4, and a faint P(C) (~0.12) on the extracted object: every
    r_c is 0, and only the expected collapsing area tells the candidates apart."""

    def forward(self, depth_m: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        c = 3.0 * masks[:, :1]
        zeros = torch.zeros_like(c)
        return torch.cat([5.0 + zeros, zeros, zeros, c], dim=1)


def test_equal_risks_go_to_the_least_expected_collapse(stack3, physics):
    from clutterbench.collapse.predict import CollapsePredictor

    ensure_renderer()
    obs = observe(BoxWorld.from_spec(stack3, physics, render=True), CAM)
    seg = masks_from_instance(obs, 5)
    area = seg.masks.sum(axis=(1, 2))
    assert int(np.argmin(area)) != 0  # else the first candidate would win anyway
    predictor = CollapsePredictor(FaintExtractCollapse(), precision="fp32", channels_last=False)
    choice, _, risks, _ = plan_risk(predictor, obs, seg, None, 0.4)
    assert (risks == 0).all()
    assert choice.extract == int(np.argmin(area))


def _jobs(tiny_ch4: Path, **cond) -> list[dict]:
    stream = SceneStreamConfig(families={"pile": 1}, n_objects=(5, 5), catalogue="various")
    c = Ch4ConditionConfig(stream="s", episodes=2, **cond)
    params = Ch4TrialParams(min_pixels=5, min_target_pixels=10)
    cfg = TrialsConfig(
        streams={"s": stream},
        ch4_conditions={"c": c},
        ch4=params,
        max_attempts=30,
        mcap_images=True,
    )
    jobs = ch4_jobs(
        "c",
        cfg.ch4_conditions["c"],
        trials=cfg,
        sim=SimConfig(camera=CAM),
        seed=0,
        collapse_free=CollapseFreeConfig(),
    )
    return [
        dataclasses.replace(j, model_path=tiny_ch4 if c.model is not None else None) for j in jobs
    ]


@pytest.mark.parametrize(
    "cond",
    [
        {"planner": "risk", "model": "m"},
        {"planner": "risk", "model": "m", "perception": "depth"},
        {"planner": "risk", "model": "m", "perception": "depth", "sensing": "d415"},
        {"planner": "random"},
        {"planner": "random", "perception": "depth", "sensing": "structured_light"},
        {"planner": "oracle"},
        {"planner": "risk", "model": "m", "mode": "target"},
        {"planner": "oracle", "mode": "target"},
    ],
)
def test_every_planner_gives_a_judged_record(cond, tiny_ch4, physics):
    job = _jobs(tiny_ch4, **cond)[1]
    rec = run_ch4_episode(job).record
    again = run_ch4_episode(job).record
    assert rec == again  # deterministic
    assert rec["planner"] == cond["planner"] and rec["mode"] == cond.get("mode", "pair")
    assert rec["n_objects"] == 5 and rec["family"] == "pile"
    # collapse-free: out, and no other box left the shelf, dropped or tipped (criteria.py)
    assert rec["success"] == (rec["target_out"] and rec["collapse_free"])
    assert rec["collapse_free"] == (rec["n_left_shelf"] == 0 and rec["n_collapsed"] == 0)
    assert rec["strict_success"] == (rec["success"] and rec["n_disturbed"] == 0)
    if rec["mode"] == "target":
        assert rec["target"] is not None and rec["n_candidates"] <= 4
        if rec["success"]:
            assert rec["extract"] == rec["target"]
    else:
        assert rec["n_candidates"] == rec["n_segments"] * (rec["n_segments"] - 1)
    if cond["planner"] == "oracle":
        assert rec["strict_success"] or rec["valid"]  # the ceiling pulls real boxes


def test_a_sensed_condition_sees_the_sensor_and_pulls_what_its_grasps_take(tiny_ch4, physics):
    """Under a sensor the planner's depth is the sensor's, not the render's; its masks come
    from region growing on it; the box a mask's pull takes is the one under its grasp point
    (none: an invalid action); the harness keeps the simulator's instance image. Records say
    which sensor; exact-depth records keep their old fields."""
    job = _jobs(tiny_ch4, planner="random", perception="depth", sensing="d415")[1]
    spec = job.start.spec()
    world = BoxWorld.from_spec(spec, job.physics, render=True)
    obs, seg, boxes, failure = observe_and_segment(world, spec, job)
    exact = observe(world, job.camera)
    assert failure is None and seg.source == "depth" and len(seg.ids) >= 2
    assert not np.array_equal(obs.depth_m, exact.depth_m)
    assert np.array_equal(obs.instance, exact.instance)
    for mask, box in zip(seg.masks, boxes, strict=True):
        under = int(exact.instance[grasp_point(mask)]) - 1
        assert box == (under if under >= 0 else None)
    rec = run_ch4_episode(job).record
    assert rec["sensing"] == "d415" and rec["perception_failure"] is None
    x, s = rec["extract"], rec["support"]
    assert rec["valid"] == (x is not None and s is not None and x != s)
    ideal = run_ch4_episode(_jobs(tiny_ch4, planner="random", perception="depth")[1]).record
    assert "sensing" not in ideal and "perception_failure" not in ideal


def test_same_scenes_for_every_planner_on_one_stream(tiny_ch4):
    a = [run_ch4_episode(j).record for j in _jobs(tiny_ch4, planner="random")]
    b = [run_ch4_episode(j).record for j in _jobs(tiny_ch4, planner="oracle")]
    assert [r["n_segments"] for r in a] == [r["n_segments"] for r in b]


def test_figure_4_8_is_drawn(tiny_ch4, tmp_path):
    job = _jobs(tiny_ch4, planner="risk", model="m", mode="target")[0]
    draw_figure(job, tmp_path / "fig.png")
    assert (tmp_path / "fig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_condition_needs_a_model_exactly_for_the_risk_planner():
    with pytest.raises(ValueError, match="needs a ch. 4 network"):
        Ch4ConditionConfig(planner="risk", stream="s")
    with pytest.raises(ValueError, match="takes no network"):
        Ch4ConditionConfig(planner="oracle", stream="s", model="ch4_same")


def test_the_mcap_shows_the_scene_and_the_camera(tmp_path):
    """A ch. 4 trial's MCAP: the pile's boxes at their sizes on /scene, the camera's
    calibration beside the depth image, the pulled box taken off /scene once it is out."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    from clutterbench.data.trial_scenes import draw_trial_spec
    from clutterbench.trials.core.harness import write_mcap

    job = _jobs(Path("unused"), planner="random")[1]
    result = run_ch4_episode(job)
    path = tmp_path / "episodes.mcap"
    write_mcap(path, [result], {"condition": "c"})
    spec = draw_trial_spec(
        job.cond.stream,
        job.stream_cfg,
        job.seed,
        job.index,
        job.physics,
        job.camera,
        job.max_attempts,
    )
    topics = ["/scene", "/camera/calibration", "/camera/depth"]
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs: dict[str, list] = {}
        for _, channel, message, proto in reader.iter_decoded_messages(topics=topics):
            msgs.setdefault(channel.topic, []).append((message.log_time, proto))
    (_, start), *removals = msgs["/scene"]
    boxes = [e for e in start.entities if e.frame_id != "world"]
    assert [e.id for e in boxes] == [f"box_{k}" for k in range(spec.n)]
    sizes = [[e.cubes[0].size.x, e.cubes[0].size.y, e.cubes[0].size.z] for e in boxes]
    np.testing.assert_array_equal(sizes, spec.sizes_m)
    rec = result.record
    out = [f"box_{rec['extract']}"] if rec["extracted"] else []
    assert [d.id for _, u in removals for d in u.deletions] == out
    K = observe(BoxWorld.from_spec(spec, PhysicsConfig(), render=True), CAM).camera.K
    assert [t for t, _ in msgs["/camera/calibration"]] == [t for t, _ in msgs["/camera/depth"]]
    for _, cal in msgs["/camera/calibration"]:
        np.testing.assert_array_equal(np.reshape(cal.K, (3, 3)), K)
