"""The action API on hand-built specs: observe, pull in increments, hold / release, lift out,
carry, insert, contacts, rest; each measured against the canonical start."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.families.shelved import STANDING
from clutterbench.sim.geometry import quat_from_axis_angle, quat_mul
from clutterbench.sim.labelling import act_on_spec
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec

STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
THRESHOLD_M = 0.005
CAM = CameraConfig(image_size=64)


@pytest.fixture(scope="module")
def stack3() -> SceneSpec:
    return SceneSpec.load(STACK3)


def test_observation_maps_pixels_to_shelf_metres_and_back(stack3, physics):
    world = BoxWorld.from_spec(stack3, physics, render=True)
    obs = observe(world, CAM)
    assert obs.depth_m.dtype == np.float32 and obs.instance.dtype == np.uint8
    assert obs.visible_boxes() == [0, 1, 2]
    # The front face centre of each box projects onto that box's mask ...
    for k in range(3):
        front = stack3.poses[k, :3] - [stack3.sizes_m[k, 0] / 2, 0, 0]
        u, v, z = obs.camera.world_to_pixel(front)
        assert obs.instance[int(v), int(u)] == k + 1
        assert z == pytest.approx(CAM.distance_m + front[0], abs=1e-6)
    # ... and every pixel of a box back-projects onto that box's surface (front or top).
    pts = obs.camera.depth_to_points(obs.depth_m)
    for k in range(3):
        on_box = pts[obs.instance == k + 1]
        lo = stack3.poses[k, :3] - stack3.sizes_m[k] / 2 - 2e-3
        hi = stack3.poses[k, :3] + stack3.sizes_m[k] / 2 + 2e-3
        assert np.all((on_box > lo) & (on_box < hi))
        assert np.any(np.abs(on_box[:, 0] - lo[0]) < 4e-3)  # its front face is seen
    u, v = np.array([10.5, 40.25]), np.array([3.5, 60.0])
    back = obs.camera.world_to_pixel(obs.camera.pixel_to_world(u, v, np.array([0.6, 0.7])))
    assert np.allclose(back[0], u) and np.allclose(back[1], v)


def test_lean_sign_matches_the_rendered_image(physics):
    """A box whose top leans toward -y must show its top to the right of its bottom."""
    size = np.array([0.10, 0.12, 0.03])
    quat = quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(25.0)), STANDING)
    spec = SceneSpec(sizes_m=size[None], poses=np.array([[0.14, 0.0, 0.07, *quat]]))
    obs = observe(BoxWorld.from_spec(spec, physics, render=True), CAM)
    rows, cols = np.nonzero(obs.instance == 1)
    top, bottom = cols[rows <= np.percentile(rows, 10)], cols[rows >= np.percentile(rows, 90)]
    assert top.mean() > bottom.mean() + 3  # image right; box_tilt calls this lean < 0: C^r


def test_pull_increments_compose_exactly(stack3, physics):
    one = BoxWorld.from_spec(stack3, physics)
    one.pull_step(1, 0.10)
    many = BoxWorld.from_spec(stack3, physics)
    for _ in range(10):
        r = many.pull_step(1, 0.01)
    assert np.array_equal(one.poses(), many.poses())
    assert r.displacement_m[1] == pytest.approx(0.10, abs=1e-3)  # the gripped box followed
    assert many.held() == [1]


def test_pull_with_hold_keeps_the_support_and_without_moves_it(stack3, physics):
    held = act_on_spec(stack3, physics, "pull", 0, support=1)
    free = act_on_spec(stack3, physics, "pull", 0)
    assert held[1] < 1e-4 and held[2] < THRESHOLD_M  # held box and the one on it stay
    assert free[1] > THRESHOLD_M and free[2] > THRESHOLD_M  # without the hold they fall
    assert np.isnan(held[0]) and np.isnan(free[0])


def test_lift_out_release_and_rest(stack3, physics):
    world = BoxWorld.from_spec(stack3, physics)
    world.hold([1])
    r = world.lift_out(0)
    assert r.at_rest and np.isnan(r.displacement_m[0]) and r.displacement_m[1] < 1e-4
    world.release([1])
    r = world.settle_action()
    assert r.at_rest and r.displacement_m[1] == pytest.approx(0.02, abs=2e-3)  # fell a box
    with pytest.raises(ValueError, match="taken out"):
        world.hold([0])


def test_carry_places_a_box_where_asked(stack3, physics):
    """Carry the top box sideways off the stack and let go: it drops onto the floor."""
    world = BoxWorld.from_spec(stack3, physics)
    goal = stack3.poses[2].copy()
    goal[1] += 0.11
    r = world.carry(2, goal)
    assert r.at_rest and world.held() == []
    assert np.allclose(world.positions()[2], [goal[0], goal[1], 0.01], atol=2e-3)
    assert r.displacement_m[:2].max() < THRESHOLD_M


def test_insert_and_contacts(stack3, physics):
    world = BoxWorld.from_spec(stack3, physics)
    world.step(1)
    assert world.contact_pairs() == [(0, 1), (1, 2)]  # a stack: neighbours only
    idx, r = world.insert(np.array([0.1, 0.1, 0.02]), np.array([0.14, 0.0, 0.0705, 1, 0, 0, 0]))
    assert idx == 3 and r.at_rest and r.displacement_m.shape == (4,)
    assert r.displacement_m[3] < 2e-3  # it landed on the stack
    assert (2, 3) in world.contact_pairs()


def test_removal_order_changes_nothing(stack3, physics):
    forward = [act_on_spec(stack3, physics, "remove", x) for x in range(3)]
    backward = [act_on_spec(stack3, physics, "remove", x) for x in reversed(range(3))][::-1]
    assert np.array_equal(np.array(forward), np.array(backward), equal_nan=True)


def test_density_from_the_spec_changes_the_mass(stack3):
    d = stack3.to_dict()
    d["boxes"][0]["density_kg_m3"] = 900.0
    d["boxes"][0]["type"] = 2
    spec = SceneSpec.from_dict(d)
    assert SceneSpec.from_json(spec.to_json()).to_dict() == spec.to_dict()
    world = BoxWorld.from_spec(spec, PhysicsConfig())
    masses = [b.mass for b in world.bodies]
    assert masses[0] == pytest.approx(3 * masses[1], rel=1e-4)


TOWER6 = Path(__file__).resolve().parents[1] / "data" / "tower6.json"


def test_a_lifted_pull_slides_clear_of_the_box_below(physics):
    """A settled 6-box stack from the ch. 6 trial stream: pulling its top box flat drags the
    box below and topples the stack; raised by 3 mm first, it slides out and nothing moves."""
    tower = SceneSpec.load(TOWER6)
    flat = act_on_spec(tower, physics, "pull", 5)
    lifted = act_on_spec(tower, physics, "pull", 5, lift_m=0.003)
    assert np.nanmax(flat) > 0.05
    assert np.nanmax(lifted) < THRESHOLD_M
    assert np.isnan(flat[5]) and np.isnan(lifted[5])


def test_lift_happens_once_per_pull_and_increments_still_compose(stack3, physics):
    one = BoxWorld.from_spec(stack3, physics)
    one.pull_step(2, 0.06, lift_m=0.004)
    many = BoxWorld.from_spec(stack3, physics)
    for _ in range(6):
        many.pull_step(2, 0.01, lift_m=0.004)
    assert np.array_equal(one.poses(), many.poses())
    assert one.poses()[2, 2] == pytest.approx(stack3.poses[2, 2] + 0.004, abs=1e-4)


def test_camera_points_of_a_stored_depth_match_the_rendering_camera(stack3, physics):
    """Support evaluation back-projects stored depth images with the configured pinhole; its
    points must be the rendering camera's up to a rigid motion (same distances)."""
    from clutterbench.support.evaluate import camera_points

    obs = observe(BoxWorld.from_spec(stack3, physics, render=True), CAM)
    ours = camera_points(obs.depth_m, CAM)[obs.instance > 0]
    theirs = obs.camera.depth_to_points(obs.depth_m)[obs.instance > 0]
    pick = np.linspace(0, len(ours) - 1, 40).astype(int)
    d_ours = np.linalg.norm(ours[pick, None] - ours[None, pick], axis=-1)
    d_theirs = np.linalg.norm(theirs[pick, None] - theirs[None, pick], axis=-1)
    assert np.allclose(d_ours, d_theirs, atol=1e-5)


def test_a_spec_not_at_rest_is_named_with_its_creeping_box(physics):
    """A box floating 50 mm above the floor falls: the start is not at rest, and the warning
    names that box and how far it moved; a resting spec gets none."""
    from clutterbench.sim.labelling import creep_warning, start_creep

    size = np.array([0.1, 0.1, 0.04])
    resting = np.array([[0.14, 0.0, 0.0201, 1.0, 0.0, 0.0, 0.0]])
    floating = np.array([[0.14, 0.0, 0.0201, 1.0, 0.0, 0.0, 0.0], [0.14, 0.12, 0.07, 1.0, 0, 0, 0]])
    assert start_creep(SceneSpec(sizes_m=size[None], poses=resting), physics) is None
    spec = SceneSpec(sizes_m=np.stack([size, size]), poses=floating)
    box, dist = start_creep(spec, physics)
    assert box == 1 and dist > 0.04
    assert creep_warning(spec, physics, "s.json").startswith("warning: s.json: box 1 moves 5")


def test_a_held_box_is_set_down_onto_what_is_below_it(stack3, physics):
    """lower_onto_support: the top box, held while the middle one is taken out, comes down
    until it is 1 mm above the bottom box; held in the air over nothing, onto the floor."""
    world = BoxWorld.from_spec(stack3, physics)
    world.hold([2])
    world.park(1)
    world.lower_onto_support(2)
    lo, _ = world.aabbs()
    assert lo[2, 2] == pytest.approx(0.02 + 0.001, abs=2e-4)
    world = BoxWorld.from_spec(stack3, physics)
    world.hold([2])
    world.park(0)
    world.park(1)
    world.lower_onto_support(2)
    assert world.aabbs()[0][2, 2] == pytest.approx(0.001, abs=2e-4)


def test_an_aborted_pull_can_put_its_box_back(stack3, physics):
    """return_pull: two increments out, then back along the pull and down by the lift: the
    box is where it started."""
    world = BoxWorld.from_spec(stack3, physics)
    start = world.poses()[2].copy()
    world.pull_step(2, 0.02, lift_m=0.003)
    world.pull_step(2, 0.02)
    assert world.poses()[2][0] < start[0] - 0.03
    world.return_pull(2, 0.003)
    assert np.allclose(world.poses()[2][:3], start[:3], atol=1e-5)


def test_the_executors_release_options(stack3, physics):
    """execute_pull: an aborted pull of the middle box, the top one held, leaves the middle
    box where the abort left it, or (return_aborted) back where it was; the held top box is
    let go where it is, or (lower_held) set down first: both end judged on the shelf."""
    from clutterbench.sim.pull import SceneState, execute_pull, world_at

    def pull(**options):
        world = world_at(stack3, SceneState.start(stack3), physics)
        return execute_pull(world, 1, 2, 0.02, 0.003, lambda done: done < 1, **options)

    left, back = pull(), pull(return_aborted=True)
    assert left.aborted and left.increments == 1 and back.increments == 1
    assert left.displacement_m[1] > 0.015 and back.displacement_m[1] < 0.003
    world = world_at(stack3, SceneState.start(stack3), physics)
    held = execute_pull(world, 1, 2, 0.02, 0.003, lower_held=True)
    assert held.extracted and held.on_shelf[[0, 2]].all()


def test_a_held_box_still_resting_on_another_is_not_lowered_into_it(stack3, physics):
    """The top box, held, sinks 0.5 mm into the one below (as resting contacts and tilted
    bounds can): setting it down leaves it where it is."""
    poses = np.asarray(stack3.poses).copy()
    poses[2, 2] -= 0.0005
    spec = SceneSpec(sizes_m=stack3.sizes_m, poses=poses)
    world = BoxWorld.from_spec(spec, physics)
    world.hold([2])
    before = world.poses()[2].copy()
    world.lower_onto_support(2)
    assert np.allclose(world.poses()[2][:3], before[:3], atol=1e-6)


def test_packed_poses_are_the_entities_poses_through_every_action(stack3, physics):
    """`poses` and `positions` read PhysX's packed state in one call; they must be the
    entities' own poses to the bit, whatever the boxes went through: held, gripped mid-pull,
    parked, released, inserted, rendered."""
    world = BoxWorld.from_spec(stack3, physics, render=True)

    def same() -> None:
        assert np.array_equal(world.poses(), world.entity_poses())
        assert np.array_equal(world.positions(), world.entity_poses()[:, :3])

    same()
    world.hold([1])
    world.pull_step(2, 0.03, lift_m=0.005)
    same()
    world.pull_step(2, 0.0)
    same()
    world.lift_out(0)
    same()
    world.release([1, 2])
    world.settle_action()
    same()
    world.insert(np.array([0.1, 0.1, 0.02]), np.array([0.14, 0.0, 0.0705, 1, 0, 0, 0]))
    observe(world, CAM)
    same()
