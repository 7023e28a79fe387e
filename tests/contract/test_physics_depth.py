"""The physics-from-depth planner: boxes fitted to one observation, a valid
estimated scene, and a planner that sees the observation only."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from clutterbench.perception.box_fit import fit_boxes
from clutterbench.planning.ch6.physics_depth import PhysicsFromDepthPlanner
from clutterbench.sim.catalog import box_extents_m
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.estimated import estimated_scene, resolve_overlaps
from clutterbench.sim.geometry import quat_from_axis_angle
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec, deepest_overlap
from clutterbench.trials.ch6.episodes import PLANNERS, run_extraction
from clutterbench.trials.ch6.physics_model import box_errors
from clutterbench.trials.config import SceneStreamConfig, TrialsConfig
from tests.toy_jobs import toy_ch6_jobs

CAM = CameraConfig(image_size=128)
VARIOUS = box_extents_m("various")  # (D, W, H) of the five types
STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def _spec(sizes, poses) -> SceneSpec:
    return SceneSpec(
        sizes_m=np.array(sizes, dtype=np.float64), poses=np.array(poses, dtype=np.float64)
    )


def _observe(spec: SceneSpec, physics: PhysicsConfig):
    return observe(world_at(spec, SceneState.start(spec), physics, render=True), CAM)


def test_a_box_seen_head_on_is_fitted_in_place(physics):
    """Type 1 of the catalogue lying flat, its front face square to the camera, and type 3
    turned 25 degrees about the vertical: both fitted to their type, centre within 5 mm,
    yaw and tilt within 5 degrees."""
    d1, d3 = VARIOUS[1], VARIOUS[3]
    turned = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.deg2rad(25.0))
    spec = _spec(
        [d1, d3],
        [
            [0.10, 0.08, d1[2] / 2, *IDENTITY],
            [0.14, -0.07, d3[2] / 2, *turned],
        ],
    )
    est = fit_boxes(_observe(spec, physics), VARIOUS, min_pixels=20)
    assert est.ids == (0, 1)
    for j, box in enumerate(est.ids):
        e = box_errors(est.sizes_m[j], est.poses[j], spec.sizes_m[box], spec.poses[box])
        assert e["yaw_deg"] <= 5.0, (box, e)
        assert e["tilt_deg"] <= 5.0, (box, e)
        assert e["centre_m"] <= 0.005, (box, e)
        assert e["size_m"] <= 1e-9, (box, e)


def test_a_fit_a_sensed_image_defeats_leaves_that_box_out_not_an_exception(physics, monkeypatch):
    """A box whose fit fails (SVD that does not converge on noisy points) is not estimated;
    the others are."""
    from clutterbench.perception import box_fit

    d1, d3 = VARIOUS[1], VARIOUS[3]
    spec = _spec(
        [d1, d3], [[0.10, 0.08, d1[2] / 2, *IDENTITY], [0.14, -0.07, d3[2] / 2, *IDENTITY]]
    )
    obs = _observe(spec, physics)
    real_axes = box_fit._axes

    def axes(pts, normals, face_px, ok, *rest):
        if face_px[obs.instance == 1].any():  # box 0's face
            raise np.linalg.LinAlgError("SVD did not converge")
        return real_axes(pts, normals, face_px, ok, *rest)

    monkeypatch.setattr(box_fit, "_axes", axes)
    est = fit_boxes(obs, VARIOUS, min_pixels=20)
    assert est.ids == (1,)


def test_a_hidden_box_is_missing_from_the_estimate(physics):
    """A flat box behind a tall panel is not seen at all: it is not estimated."""
    spec = _spec(
        [[0.05, 0.25, 0.16], VARIOUS[0]],
        [[0.03, 0.0, 0.08, *IDENTITY], [0.20, 0.0, VARIOUS[0][2] / 2, *IDENTITY]],
    )
    obs = _observe(spec, physics)
    assert not (obs.instance == 2).any(), "the scene must hide box 1"
    est = fit_boxes(obs, VARIOUS, min_pixels=1)
    assert est.ids == (0,)
    assert est.index_of(1) is None


def test_an_estimated_scene_is_valid_and_records_rest(physics):
    """Two fitted boxes overlapping by 1 cm are pushed apart into a spec that validates, and
    the settled estimate says whether it came to rest."""
    d = VARIOUS[1]
    poses = np.array([[0.10, 0.0, d[2] / 2, *IDENTITY], [0.10, 0.09, d[2] / 2, *IDENTITY]])
    sizes = np.array([d, d])
    assert deepest_overlap(sizes, poses) is not None
    fixed, kept, pushes = resolve_overlaps(sizes, poses, Shelf())
    assert kept == [0, 1] and pushes >= 1 and deepest_overlap(sizes, fixed) is None
    scene = estimated_scene(sizes, poses, (4, 7), Shelf(), CAM, physics, 0.5)
    assert scene.spec.meta["ids"] == [4, 7]
    assert scene.at_rest and scene.settle_move_m < 0.005


def _job(planner: str):
    stream = SceneStreamConfig(families={"stacked": 1}, n_objects=(3, 3), catalogue="same")
    cfg = TrialsConfig()
    cfg = dataclasses.replace(cfg, ch6=dataclasses.replace(cfg.ch6, physics_depth_node_budget=6))
    return toy_ch6_jobs(planner, stream, CAM, model_path=Path("x"), trials=cfg)[0]


@pytest.fixture(scope="module")
def stack3() -> SceneSpec:
    return SceneSpec.load(STACK3)


def test_the_planner_sees_the_observation_only(stack3, physics):
    """The planner a factory builds decides the same from the same observation whatever the
    true spec says of the boxes (here: every box moved and resized): it never reads the
    simulator's state, only the Observation (and the shelf, which a robot knows)."""
    obs = _observe(stack3, physics)
    poisoned = dataclasses.replace(
        stack3,
        sizes_m=stack3.sizes_m[::-1] * 0.5,
        poses=stack3.poses + np.array([0.05, 0.1, 0.1, 0, 0, 0, 0]),
    )
    for name in ("physics_from_depth", "physics_from_depth_hold"):
        job = _job(name)
        a = PLANNERS[name].factory(job, stack3)
        b = PLANNERS[name].factory(job, poisoned)
        assert isinstance(a, PhysicsFromDepthPlanner) and not hasattr(a, "state")
        da, db = a.decide(obs, 2, frozenset()), b.decide(obs, 2, frozenset())
        assert (da.pull, da.hold, da.state) == (db.pull, db.hold, db.state)


def test_the_holding_planner_searches_with_oracle_hold_s_actions(stack3):
    """physics_from_depth_hold runs the search of oracle_hold (a box may be held during any
    pull) on its estimate; physics_from_depth the one-arm oracle's (no hold at all)."""
    for name, holds_any in (("physics_from_depth", False), ("physics_from_depth_hold", True)):
        model = PLANNERS[name].factory(_job(name), stack3).search
        search = model.search_cls(
            stack3, model.physics, model.camera, model.pull, model.limits, model.holding, model.cf
        )
        assert (search.holding, search.hold_any_pull) == (holds_any, holds_any), name


def test_an_episode_runs_and_records_its_estimates(stack3):
    """Through the harness: the top box of a 3-stack comes out first time, and the record
    scores the first estimate against the truth."""
    rec = run_extraction(stack3, _job("physics_from_depth"), target=2).record
    assert rec["success"] and rec["strict_success"]
    assert [s["box"] for s in rec["steps"]] == [2]
    start = rec["estimate_start"]
    assert start["n_boxes"] == 3 and start["missing"] == 0
    assert max(b[1] for b in start["boxes"]) < 10.0  # centre error, mm
    assert rec["estimate_not_at_rest"] == 0


def test_support_from_the_estimated_scene_finds_the_stack(stack3, physics):
    """Table 6.2's physics-from-depth row: removals simulated in the boxes fitted to the
    depth image of a 3-stack: taking out the bottom box moves the two above it, taking out
    the top one moves nothing."""
    from clutterbench.support.physics_depth import estimated_moved

    obs = _observe(stack3, physics)
    moved, info = estimated_moved(obs, [0, 1, 2], "same", 20, Shelf(), CAM, physics, 0.5, 0.005)
    assert info["at_rest"]
    assert moved[0, 1] and moved[0, 2] and not moved[2].any()


def _refuse(*args, **kwargs):
    from clutterbench.errors import ClutterbenchError

    raise ClutterbenchError("estimated scene: box 7: centre [-0.0084, 0.0994, 0.083] m is outside")


def test_a_perception_failure_is_recorded_in_the_episode_not_raised(stack3, monkeypatch):
    """An observation the world model cannot make a scene of ends nothing: the
    step records the failure, the planner pulls the target, the record counts it."""
    from clutterbench.perception import fitted_scenes

    monkeypatch.setattr(fitted_scenes, "estimated_scene", _refuse)
    rec = run_extraction(stack3, _job("physics_from_depth"), target=2).record
    assert [s["box"] for s in rec["steps"]] == [2]  # the target, as without a plan
    assert rec["perception_failed"] == 1
    assert rec["estimate_dropped"] == [None]


def test_a_perception_failure_in_table_6_2_is_a_row_not_an_end(stack3, physics, monkeypatch):
    """The support stage's physics-from-depth row records a scene whose estimate failed."""
    from clutterbench.perception import fitted_scenes
    from clutterbench.support import physics_depth

    with pytest.raises(physics_depth.PerceptionError, match="outside"):
        monkeypatch.setattr(fitted_scenes, "estimated_scene", _refuse)
        obs = _observe(stack3, physics)
        physics_depth.estimated_moved(obs, [0, 1, 2], "same", 20, Shelf(), CAM, physics, 0.5, 0.01)
    support = physics_depth.PhysicsDepthSupport.__new__(physics_depth.PhysicsDepthSupport)
    sim = dataclasses.make_dataclass("Sim", ["camera", "physics"])(CAM, physics)
    cfg = dataclasses.make_dataclass("Cfg", ["test", "min_pixels", "moved_threshold_m"])(
        dataclasses.make_dataclass("Test", ["catalogue"])("same"), 20, 0.005
    )
    support.cfg, support.sim, support.settle_s, support.not_at_rest = cfg, sim, 0.5, 0
    support.shelf, support.camera = Shelf(), obs.camera
    masks = np.stack([obs.instance == k + 1 for k in range(3)])
    scene = dataclasses.make_dataclass(
        "Scene",
        ["index", "family", "n_objects", "ids", "depth_m", "masks", "true_edges", "gaps_m"],
    )(5, "stacked", 3, [0, 1, 2], obs.depth_m, masks, {(0, 1), (1, 2)}, None)
    row = support.row(scene)
    assert row["perception_failed"] == 1 and row["n_pred"] == 0 and row["n_true"] == 2


def test_the_physics_from_depth_baseline_says_a_stacks_bottom_pull_collapses_the_rest():
    """The leaderboard's physics-from-depth row on a rendered three-box stack: the boxes are
    fitted from the depth image alone, and pulling the bottom one collapses those above it,
    pulling the top one nothing."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.render import render_depth_instance
    from clutterbench.support.baselines import physics_from_depth
    from clutterbench.trials.config import TrialsConfig

    spec = SceneSpec.load(Path(__file__).resolve().parents[1] / "data" / "stack3.json")
    sim = SimConfig()
    depth, instance = render_depth_instance(
        BoxWorld.from_spec(spec, sim.physics, render=True), sim.camera
    )
    masks = np.stack([instance == k + 1 for k in range(spec.n)])
    thresholds = {"drop_m": 0.01, "tilt_deg": 15.0}
    predict = physics_from_depth(sim, TrialsConfig().ch6, "various", 20, thresholds)
    bottom = int(np.argmin(np.asarray(spec.poses)[:, 2]))
    top = int(np.argmax(np.asarray(spec.poses)[:, 2]))
    k = np.eye(3, dtype=bool)
    assert predict(depth.astype(np.float32), masks, None, bottom)[~k[bottom]].tolist() == [1.0, 1.0]
    assert predict(depth.astype(np.float32), masks, None, top).tolist() == [0.0, 0.0, 0.0]
