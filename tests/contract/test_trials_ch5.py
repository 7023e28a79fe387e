"""Chapter 5 replenishment on a hand-built shelf: the planner's branches, the executor's
release-then-judge order, one record per trial and its MCAP."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

import clutterbench.trials.ch5.episodes as ch5
import clutterbench.trials.ch5.execution as ch5_execution
import clutterbench.trials.ch5.perception as ch5_perception
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.logs.mcap_episode import read_episode
from clutterbench.planning.ch5.replenish import ReplenishParams, ReplenishPlanner
from clutterbench.sim.config import CameraConfig, PhysicsConfig, SimConfig
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import Ch5ConditionConfig, SceneStreamConfig, TrialsConfig
from clutterbench.trials.core.harness import write_mcap

CAM = CameraConfig(image_size=64)
STANDING = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # width up, thickness across
SIZE = np.array([0.1, 0.12, 0.03])  # (D, W, H): standing, 12 cm tall and 3 cm thick
NEW_BOX = np.array([0.1, 0.12, 0.03])
CF = CollapseFreeConfig()


def crowded_row() -> SceneSpec:
    """A row of three standing boxes in the middle and one more on each side of it, 1.2 cm
    away: every placement candidate inside the shelf is occupied (a new standing box plus its
    finger margins needs 5.4 cm), but a side box can be carried 4.2 cm toward its wall (eq.
    5.6) and held there."""
    ys = [-0.06, 0.0, 0.06, 0.102, -0.102]
    poses = np.array([[0.1, y, 0.06, *STANDING] for y in ys])
    return SceneSpec(
        sizes_m=np.tile(SIZE, (5, 1)),
        poses=poses,
        camera=CAM,
        meta={"groups": [[0, 1, 2], [3], [4]]},
    )


@pytest.fixture(scope="module")
def scene():
    physics = PhysicsConfig()
    spec = crowded_row()
    state = SceneState.start(spec)
    obs = observe(world_at(spec, state, physics, render=True), CAM)
    dets = ch5_perception.true_clusters(spec, state, physics, obs)
    return spec, state, obs, dets, physics


def test_ground_truth_clusters_of_the_row(scene):
    _, _, _, dets, _ = scene
    assert sorted(d.cls for d in dets) == ["C^v", "C^v", "C^v"]


def test_no_simple_replenishment_when_every_candidate_is_occupied(scene):
    spec, _, obs, dets, _ = scene
    planner = ReplenishPlanner(ReplenishParams(finger_m=0.012), ch5.space_of(spec))
    plan = planner.plan(obs, dets, NEW_BOX)
    assert plan.info["candidates"], "the row offers candidates inside the shelf"
    assert all(c["occupants"] for c in plan.info["candidates"])
    assert plan.branch != "simple"
    if plan.candidate is not None:
        assert not plan.candidate.free


def test_every_held_box_is_released_before_the_judge(scene, monkeypatch):
    spec, state, obs, dets, physics = scene
    planner = ReplenishPlanner(ReplenishParams(finger_m=0.012), ch5.space_of(spec))
    plan = planner.plan(obs, dets, NEW_BOX)
    assert plan.branch == "bimanual" and plan.move is not None
    seen = {}
    judge = ch5_execution.judge_step

    def spy(world, *args, **kwargs):
        seen["held"] = world.held()
        seen["moved"] = args[2]
        return judge(world, *args, **kwargs)

    monkeypatch.setattr(ch5_execution, "judge_step", spy)
    world = world_at(spec, state, physics, render=True)
    out = ch5_execution.execute(
        world, obs, plan, NEW_BOX, TrialsConfig().ch5, state.removed, CollapseFreeConfig()
    )
    assert seen["moved"], "the blocker's boxes were carried"
    assert seen["held"] == [], "judged while a box was still held"
    assert set(out.record) >= {"branch", "success", "others_still", "at_place", "n_disturbed"}


def test_episode_record_and_mcap(tmp_path):
    spec = crowded_row()
    cond = Ch5ConditionConfig(planner="no_collapse", stream="ch5_shelved", perception="clusters")
    job = ch5.ch5_jobs(
        "hand",
        cond,
        trials=TrialsConfig(max_attempts=5, mcap_images=True),
        sim=SimConfig(camera=CAM),
        seed=0,
        prob_threshold=0.5,
        scene_type="shelved",
        stream_cfg=SceneStreamConfig(families={"shelved": 1.0}, n_objects=(4, 6)),
        collapse_free=CollapseFreeConfig(),
    )[0]
    result = ch5.replenish(spec, job, NEW_BOX)
    rec = result.record
    assert rec["end"] in ch5.ENDS and isinstance(rec["success"], bool)
    assert rec["success"] == (rec["end"] == "placed")
    assert rec["steps"] and rec["branch"] in ("bimanual", "rearrange", "none")
    write_mcap(tmp_path / "e.mcap", [result], {"condition": "hand"})
    topics = read_episode(tmp_path / "e.mcap")["topics"]
    for topic in ("/perception/detections", "/planner/decision", "/camera/depth", "/trial/result"):
        assert topics.get(topic, 0) >= 1, topic


@pytest.mark.parametrize("rule", ["candidate", "eq_5_6"])
def test_the_planner_and_the_oracle_carry_a_blocker_by_the_params_rule(scene, monkeypatch, rule):
    """Both move a blocker by the rule of trials.ch5.blocker_goal: by the candidate it fills
    (planning.replenish.move_goal given the candidate's rectangle) or by eq. (5.6)'s fixed
    distance (no candidate given)."""
    import clutterbench.planning.ch5.replenish as replenish
    import clutterbench.trials.ch5.oracle as ch5_oracle

    spec, _, obs, dets, _ = scene
    given = []
    goal = replenish.move_goal

    def spy(s, side, w_new, h_new, g, cand=None):
        given.append(cand is not None)
        return goal(s, side, w_new, h_new, g, cand)

    monkeypatch.setattr(replenish, "move_goal", spy)
    monkeypatch.setattr(ch5_oracle, "move_goal", spy)
    job = SimpleNamespace(  # the fields planner_params reads
        params=dataclasses.replace(TrialsConfig().ch5, blocker_goal=rule, min_points=3),
        prob_threshold=0.5,
        cond=Ch5ConditionConfig(planner="replenish", stream="s"),
    )
    rp, space = ch5.planner_params(job), ch5.space_of(spec)
    plan = ReplenishPlanner(rp, space).plan(obs, dets, NEW_BOX)
    assert plan.branch == "bimanual" and given
    assert set(given) == {rule == "candidate"}
    given.clear()
    assert ch5_oracle.action_set(obs, dets, NEW_BOX, rp, space)
    assert given and set(given) == {rule == "candidate"}


FLAT = [1.0, 0.0, 0.0, 0.0]


def planned(spec: SceneSpec, new_box: np.ndarray, camera: CameraConfig = CAM, min_points: int = 3):
    physics = PhysicsConfig()
    state = SceneState.start(spec)
    obs = observe(world_at(spec, state, physics, render=True), camera)
    dets = ch5_perception.true_clusters(spec, state, physics, obs)
    rp = ReplenishParams(finger_m=0.012, min_points=min_points)
    planner = ReplenishPlanner(rp, ch5.space_of(spec))
    return planner.plan(obs, dets, new_box), dets


def covered_stack() -> SceneSpec:
    """A stack of two boxes with a deeper box lying across its top (thesis Fig. 5.9 c)."""
    sizes = np.array([[0.12, 0.1, 0.03], [0.12, 0.1, 0.03], [0.2, 0.13, 0.035]])
    poses = np.array(
        [
            [0.15, 0.0, 0.0155, *FLAT],
            [0.15, 0.0, 0.0465, *FLAT],
            [0.11, 0.0, 0.0795, *FLAT],
        ]
    )
    return SceneSpec(sizes_m=sizes, poses=poses, camera=CAM, meta={"groups": [[0, 1], [2]]})


def test_a_stack_covered_by_a_deeper_box_offers_its_top_occupied():
    """Thesis Fig. 5.9 (c): a box lying across a stack's top, deeper than the stack (it hides
    the stack's top surface from the camera): B^top is still a candidate, occupied by it, and
    the planner lifts it aside (bimanual), never gives up."""
    spec = covered_stack()
    # the default scale's image and occupancy count (trials.ch5.min_points)
    plan, dets = planned(spec, np.array([0.12, 0.1, 0.03]), CameraConfig(image_size=128), 25)
    assert sorted(d.cls for d in dets) == ["C^h", "C^v"]
    tops = [c for c in plan.info["candidates"] if c["side"] == "top"]
    assert tops and all(c["occupants"] for c in tops), plan.info["candidates"]
    assert plan.branch == "bimanual" and plan.candidate.side == "top"
    # let go on the stack's top (z 0.0615, hidden by the blocker), not inside the stack
    bottom = plan.candidate.pose[2] - 0.03 / 2
    assert 0.0615 <= bottom <= 0.0615 + 0.012, bottom


def row_with_a_box_in_front() -> SceneSpec:
    """A row of two standing boxes deep in the shelf and one more standing near the front,
    in front of the place right of the row (not inside it)."""
    ys = [0.12, 0.08]
    poses = [[0.2, y, 0.06, *STANDING] for y in ys] + [[0.06, 0.035, 0.06, *STANDING]]
    return SceneSpec(
        sizes_m=np.tile(SIZE, (3, 1)),
        poses=np.array(poses),
        camera=CAM,
        meta={"groups": [[0, 1], [2]]},
    )


def test_a_box_in_front_of_a_candidate_occupies_it():
    """The new box goes in from the front: a box standing nearer the camera than a row, in
    front of the place beside it, blocks that place although it is not inside it."""
    spec = row_with_a_box_in_front()
    plan, _ = planned(spec, NEW_BOX)
    # the row stands at shelf y 0.065-0.135 (image-aligned x about -0.1), the front box at 0.035
    row = [k for k, c in enumerate(plan.info["clusters"]) if c["rect_m"][0] < -0.07]
    assert len(row) == 1, plan.info["clusters"]
    right_of_row = [
        c for c in plan.info["candidates"] if c["side"] == "right" and c["cluster"] == row[0]
    ]
    assert right_of_row and right_of_row[0]["occupants"], plan.info["candidates"]


def test_a_lifted_blocker_is_set_down_before_it_is_let_go(monkeypatch):
    """Bimanual on B^top: the blocker held above the new box is lowered onto it before the
    gripper opens (not dropped from its lift height), and the step succeeds."""
    spec = covered_stack()
    physics = PhysicsConfig()
    state = SceneState.start(spec)
    obs = observe(world_at(spec, state, physics, render=True), CAM)
    dets = ch5_perception.true_clusters(spec, state, physics, obs)
    planner = ReplenishPlanner(ReplenishParams(finger_m=0.012), ch5.space_of(spec))
    new_box = np.array([0.12, 0.1, 0.03])
    plan = planner.plan(obs, dets, new_box)
    assert plan.branch == "bimanual" and plan.candidate.side == "top"
    gaps = []
    world = world_at(spec, state, physics)
    release = type(world).release

    def spy(self, boxes):
        boxes = list(boxes)
        if boxes:
            lo, hi = self.aabbs()
            others = [i for i in range(self.n) if i not in boxes]
            gaps.append(float(lo[boxes, 2].min() - hi[others, 2].max()))
        return release(self, boxes)

    monkeypatch.setattr(type(world), "release", spy)
    out = ch5_execution.execute(
        world, obs, plan, new_box, TrialsConfig().ch5, state.removed, CollapseFreeConfig()
    )
    assert gaps and max(gaps) < 0.005, gaps
    assert out.record["success"], out.record


@pytest.mark.parametrize("lean_deg", [20.0, -20.0])
def test_a_leaning_box_is_carried_upright(lean_deg):
    """The turn the executor gives a leaning cluster (thesis 5.2.3: C^r / C^l set upright)
    leaves it standing straight, whichever way it leaned (a sign slip doubles the lean)."""
    from clutterbench.sim.clusters import box_tilt
    from clutterbench.sim.geometry import quat_from_axis_angle, quat_mul

    quat = quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(-lean_deg)), STANDING)
    spec = SceneSpec(sizes_m=SIZE[None], poses=np.array([[0.1, 0.0, 0.08, *quat]]), camera=CAM)
    world = world_at(spec, SceneState.start(spec), PhysicsConfig())
    assert box_tilt(SIZE, world.poses()[0, 3:])[1] == pytest.approx(lean_deg, abs=0.5)
    world.carry_group([0], np.zeros(3), ch5_execution.upright_angle_rad(world, [0]))
    assert abs(box_tilt(SIZE, world.poses()[0, 3:])[1]) < 0.5


@pytest.mark.parametrize("lean_deg", [20.0, -25.0, 35.0])
def test_a_leaning_box_is_planned_with_its_upright_footprint(lean_deg):
    """A lone leaning box (C^r / C^l) on the floor is carried set upright, so the planner
    plans its goal and its way with its thickness across and its length up, from its front
    face alone, standing on the floor (at 35 degrees its centre is lower than half its
    length: turned upright about it, the box would dip into the floor)."""
    from clutterbench.planning.ch5.replenish import box_points, carried, place_clusters
    from clutterbench.sim.geometry import quat_from_axis_angle, quat_mul

    quat = quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(-lean_deg)), STANDING)
    a = np.deg2rad(abs(lean_deg))
    z = (SIZE[1] * np.cos(a) + SIZE[2] * np.sin(a)) / 2 + 0.001  # resting on its corner
    spec = SceneSpec(sizes_m=SIZE[None], poses=np.array([[0.1, 0.0, z, *quat]]), camera=CAM)
    state = SceneState.start(spec)
    obs = observe(world_at(spec, state, PhysicsConfig(), render=True), CAM)
    dets = ch5_perception.true_clusters(spec, state, PhysicsConfig(), obs)
    assert [d.cls for d in dets] == ["C^l" if lean_deg > 0 else "C^r"]
    space = ch5.space_of(spec)
    points = box_points(obs, space)
    (seen,) = place_clusters(obs, dets, space, points)
    up = carried(seen, points, min_points=3)
    thickness, length = SIZE[2], SIZE[1]
    assert seen.rect_m[2] > thickness + 0.03  # leaning: wide as seen
    assert up.rect_m[2] == pytest.approx(thickness, abs=0.006)
    assert up.rect_m[3] == pytest.approx(length, abs=0.008)
    assert up.rect_m[0] == pytest.approx(seen.rect_m[0], abs=0.01)
    assert up.rect_m[1] + up.rect_m[3] / 2 <= 1e-9  # its bottom (y down) not below the floor
    upright = dataclasses.replace(seen, cls="C^v")
    assert carried(upright, points, min_points=3) is upright


@pytest.mark.parametrize("upright", [True, False])
def test_the_planner_and_the_oracle_plan_moves_with_the_upright_footprint_when_asked(
    scene, monkeypatch, upright
):
    import clutterbench.planning.ch5.replenish as replenish
    import clutterbench.trials.ch5.oracle as ch5_oracle

    spec, _, obs, dets, _ = scene
    calls = []
    real = replenish.carried

    def spy(cluster, points, min_points):
        calls.append(cluster.index)
        return real(cluster, points, min_points)

    monkeypatch.setattr(replenish, "carried", spy)
    monkeypatch.setattr(ch5_oracle, "carried", spy)
    rp = ReplenishParams(finger_m=0.012, upright_footprint=upright)
    space = ch5.space_of(spec)
    ReplenishPlanner(rp, space).plan(obs, dets, NEW_BOX)
    assert bool(calls) == upright
    calls.clear()
    ch5_oracle.action_set(obs, dets, NEW_BOX, rp, space)
    assert bool(calls) == upright


@pytest.mark.parametrize("tilt_deg", [0.0, 20.0])
def test_a_tilted_box_on_a_stack_offers_no_place_on_top(tilt_deg):
    """A box lying tilted on a stack shows only a strip of top surface: a box let go there
    slides off, so no free B^top is offered (the level stack, tilt 0, offers it)."""
    from clutterbench.sim.geometry import quat_from_axis_angle

    t = np.deg2rad(tilt_deg)
    z_top = 0.0615 + 0.05 * np.sin(t) + 0.015 * np.cos(t) + 0.0005
    sizes = np.array([[0.12, 0.1, 0.03]] * 3)
    poses = np.array(
        [
            [0.15, 0.0, 0.0155, *FLAT],
            [0.15, 0.0, 0.0465, *FLAT],
            [0.15, 0.0, z_top, *quat_from_axis_angle([1, 0, 0], t)],
        ]
    )
    spec = SceneSpec(sizes_m=sizes, poses=poses, camera=CAM, meta={"groups": [[0, 1, 2]]})
    plan, dets = planned(spec, np.array([0.12, 0.1, 0.03]), CameraConfig(image_size=128), 25)
    assert [d.cls for d in dets] == ["C^h"]
    tops = [c for c in plan.info["candidates"] if c["side"] == "top"]
    assert bool(tops) == (tilt_deg == 0.0), plan.info["candidates"]


def test_the_new_box_is_carried_in_from_the_front_and_pushes_what_is_in_its_way():
    """Placing at the place behind the front box (forced: the planner calls it occupied)
    carries the new box through the front box, which is pushed and fails the step; a box
    made to appear at its place would leave the front box alone."""
    from clutterbench.planning.ch5.replenish import Plan, candidates, place_clusters

    spec = row_with_a_box_in_front()
    physics = PhysicsConfig()
    state = SceneState.start(spec)
    obs = observe(world_at(spec, state, physics, render=True), CAM)
    dets = ch5_perception.true_clusters(spec, state, physics, obs)
    rp = ReplenishParams(finger_m=0.012, min_points=3)
    clusters = place_clusters(obs, dets, ch5.space_of(spec))
    row = [c.index for c in clusters if c.rect_m[0] < -0.07]
    cands = candidates(obs, clusters, NEW_BOX, rp, ch5.space_of(spec))
    right = [c for c in cands if c.side == "right" and c.cluster == row[0]]
    assert right and right[0].occupants
    world = world_at(spec, state, physics)
    out = ch5_execution.execute(
        world,
        obs,
        Plan("simple", right[0], None),
        NEW_BOX,
        TrialsConfig().ch5,
        state.removed,
        CF,
    )
    assert out.record["placed"] and not out.record["others_still"], out.record
    assert out.record["n_disturbed"] >= 1


def test_without_prediction_skips_only_the_collapse_tests(scene):
    """Table 5.2's "without collapse prediction" is the same planner with the prediction
    removed and nothing else (thesis 5.3.2): a collapse map that flags every cluster makes
    the R_s test (eq. 5.5) refuse every blocker with prediction, while without it the map is
    never asked and a blocker whose way is clear is carried aside."""
    from clutterbench.planning.ch5.replenish import rect_mask

    spec, _, obs, dets, _ = scene
    calls = []

    def everything_collapses(o, mask):
        calls.append(mask.sum())
        region = np.zeros(o.depth_m.shape, bool)
        for d in dets:
            region |= rect_mask(d.box, o.depth_m.shape)
        return region.astype(float)

    space = ch5.space_of(spec)
    with_pred = ReplenishPlanner(ReplenishParams(finger_m=0.012), space, everything_collapses)
    assert with_pred.plan(obs, dets, NEW_BOX).branch != "bimanual"
    assert calls, "with prediction the blocker's collapse region is asked for"
    calls.clear()
    params = ReplenishParams(finger_m=0.012, use_collapse=False)
    without = ReplenishPlanner(params, space, everything_collapses).plan(obs, dets, NEW_BOX)
    assert without.branch == "bimanual" and without.move is not None
    assert calls == [], "the variant without prediction asked for a collapse map"


def test_shelved_starts_offer_no_free_place():
    """Thesis Fig. 5.9: in a shelved trial the obstacle stands where the new box must go, so
    no placement candidate is free at the start (seen through the ground-truth clusters, for
    the episode's own box), and in most starts it leans (a lone leaning box: C^r / C^l)."""
    stream = SceneStreamConfig(
        families={"replenish_shelved": 1.0}, n_objects=(4, 6), catalogue="various"
    )
    cond = Ch5ConditionConfig(planner="oracle", stream="ch5_shelved", perception="clusters")
    jobs = ch5.ch5_jobs(
        "shelved",
        cond,
        trials=TrialsConfig(streams={"ch5_shelved": stream}, max_attempts=40, mcap_images=False),
        sim=SimConfig(camera=CAM),
        seed=0,
        prob_threshold=0.5,
        scene_type="shelved",
        collapse_free=CollapseFreeConfig(),
    )
    leaning = 0
    for job in jobs[:12]:
        spec, size_m = ch5.draw_start(job)
        assert spec.family == "replenish_shelved"
        assert ch5.free_places(spec, job, size_m) == [], (job.index, spec.meta)
        state = SceneState.start(spec)
        obs = observe(world_at(spec, state, job.physics, render=True), CAM)
        classes = [d.cls for d in ch5_perception.true_clusters(spec, state, job.physics, obs)]
        leaning += any(c in ("C^r", "C^l") for c in classes)
    assert leaning >= 4, leaning


def walled_row() -> SceneSpec:
    """crowded_row with one more box flush with each wall: a side box's only goal (beside
    the candidate it fills) is where the wall box stands, so every carry pushes a box, and the
    wall box cannot be rearranged beside that goal (it would leave the shelf)."""
    ys = [-0.06, 0.0, 0.06, 0.102, -0.102, 0.15, -0.15]
    poses = np.array([[0.1, y, 0.06, *STANDING] for y in ys])
    return SceneSpec(
        sizes_m=np.tile(SIZE, (7, 1)),
        poses=poses,
        camera=CAM,
        meta={"groups": [[0, 1, 2], [3], [4], [5], [6]]},
    )


@pytest.mark.parametrize("planner", ["replenish", "contact", "no_collapse"])
def test_a_planner_may_push_only_as_the_contact_rows_and_only_a_movable_blocker(planner):
    """Beyond the thesis, Table 5.2's contact rows: where the thesis' planner gives up
    because every blocker's way is blocked, `contact` carries the first blocker anyway (what
    stands in its way is pushed) if its collapse region passes eq. (5.5), never one it
    predicts unsafe; the thesis' rows (with and without prediction) keep the no-contact rule.
    The oracle's action set holds the same carry, so it stays the ceiling."""
    from clutterbench.planning.ch5.replenish import rect_mask
    from clutterbench.trials.ch5.oracle import action_set

    spec = walled_row()
    physics = PhysicsConfig()
    state = SceneState.start(spec)
    obs = observe(world_at(spec, state, physics, render=True), CAM)
    dets = ch5_perception.true_clusters(spec, state, physics, obs)
    job = SimpleNamespace(  # the fields planner_params reads
        params=TrialsConfig().ch5,
        prob_threshold=0.5,
        cond=Ch5ConditionConfig(planner=planner, stream="s"),
    )
    rp, space = ch5.planner_params(job), ch5.space_of(spec)
    assert rp.contact == (planner == "contact")
    assert rp.use_collapse == (planner != "no_collapse")

    def nothing_collapses(o, mask):
        return np.zeros(o.depth_m.shape)

    def everything_collapses(o, mask):
        region = np.zeros(o.depth_m.shape, bool)
        for d in dets:
            region |= rect_mask(d.box, o.depth_m.shape)
        return region.astype(float)

    plan = ReplenishPlanner(rp, space, nothing_collapses).plan(obs, dets, NEW_BOX)
    why = [w for w in plan.info["why_not"] if w]
    if planner != "contact":
        assert plan.branch == "none" and any("way blocked" in w for w in why), why
        return
    assert plan.branch == "contact" and plan.move is not None and plan.candidate is not None
    assert plan.candidate.occupants[0] == plan.move.cluster != plan.candidate.cluster
    ceiling = [
        seq[0].move.goal_m
        for seq in action_set(obs, dets, NEW_BOX, rp, space)
        if len(seq) == 1 and seq[0].move is not None and seq[0].move.cluster == plan.move.cluster
    ]
    assert any(np.allclose(g, plan.move.goal_m) for g in ceiling)
    unsafe = ReplenishPlanner(rp, space, everything_collapses).plan(obs, dets, NEW_BOX)
    assert unsafe.branch == "none", "a blocker predicted to drop others was pushed"


def test_the_no_contact_oracle_keeps_exactly_the_moves_the_thesis_planner_may_take(scene):
    """oracle_no_contact simulates only actions that move no box into another: on the walled
    row (every blocker's way blocked) no carry and no placement at an occupied candidate is
    left, while the full action set has them; on the crowded row the thesis' planner's carry
    is in it."""
    from clutterbench.trials.ch5.oracle import action_set

    rp = ReplenishParams(finger_m=0.012)
    spec = walled_row()
    physics = PhysicsConfig()
    state = SceneState.start(spec)
    obs = observe(world_at(spec, state, physics, render=True), CAM)
    dets = ch5_perception.true_clusters(spec, state, physics, obs)
    space = ch5.space_of(spec)
    every = action_set(obs, dets, NEW_BOX, rp, space)
    kept = action_set(obs, dets, NEW_BOX, rp, space, contact=False)
    assert any(seq[0].branch == "bimanual" for seq in every)
    assert any(seq[0].branch == "simple" for seq in every)
    assert not [seq for seq in kept if seq[0].branch in ("simple", "bimanual")], kept
    spec, _, obs, dets, _ = scene
    plan = ReplenishPlanner(rp, ch5.space_of(spec)).plan(obs, dets, NEW_BOX)
    assert plan.branch == "bimanual"
    kept = action_set(obs, dets, NEW_BOX, rp, ch5.space_of(spec), contact=False)
    assert all(seq[0].candidate is None or seq[0].candidate.free or seq[0].move for seq in kept)
    assert any(
        seq[0].move is not None
        and seq[0].move.cluster == plan.move.cluster
        and np.allclose(seq[0].move.goal_m, plan.move.goal_m)
        for seq in kept
    )


@pytest.mark.parametrize("planner", ["oracle", "oracle_no_contact"])
def test_each_oracle_searches_its_own_action_set(scene, monkeypatch, planner):
    import clutterbench.trials.ch5.oracle as ch5_oracle

    spec, state, obs, dets, physics = scene
    asked = []
    monkeypatch.setattr(ch5_oracle, "action_set", lambda *args: asked.append(args[-1]) or [])
    job = SimpleNamespace(  # the fields oracle_choice reads before its action set
        params=TrialsConfig().ch5,
        physics=physics,
        cond=Ch5ConditionConfig(planner=planner, stream="s"),
    )
    rp = ReplenishParams(finger_m=0.012)
    seq, tried = ch5_oracle.oracle_choice(
        spec, state, obs, [dets], NEW_BOX, rp, ch5.space_of(spec), job
    )
    assert asked == [planner == "oracle"] and seq[0].branch == "none" and tried == 0
