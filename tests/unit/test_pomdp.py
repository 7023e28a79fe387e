"""The ch. 3 POMDP (thesis 3.4): states, fit weights, belief, viewpoints, values and decision,
on synthetic point clouds ray-cast from the Shogi piece's CAD model."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.planning.ch3.pomdp import (
    BASIC_POSES,
    E_TH_M,
    N_STATES,
    SLIDABLE_STATES,
    belief_mass,
    decide,
    equivalent_states,
    fit_weight,
    icp_error,
    look_at_pose,
    model_cloud,
    model_view,
    observation_value,
    occupancy_grid,
    piece_view,
    slide_value,
    state_basic,
    state_pose,
    state_rotation,
    state_weights,
    state_yaw,
    uncertainty_reduction,
    uniform_belief,
    update_belief,
    viewpoint_candidates,
    visibility_value,
    visible_points,
    voxel_downsample,
)
from clutterbench.shogi_piece import PIECE_SIZE_M, piece_vertices

EYE_TOP = np.array([0.0, -0.15, 0.35])
"""The first observation's viewpoint: above the board, 67 deg up, looking at the centre."""
STANDING = [s for s in range(N_STATES) if state_basic(s) == "standing"]
FLAT = [s for s in range(N_STATES) if state_basic(s) == "flat"]


def observe(T_world_from_piece: np.ndarray, eye, seed: int = 0, occluders=None) -> np.ndarray:
    """A depth sensor's view of a piece: 1 mm pixels, 1 mm Gaussian noise."""
    pts = piece_view(T_world_from_piece, eye, occluders, pixel_m=0.001)
    return pts + np.random.default_rng(seed).normal(0.0, 0.001, pts.shape)


# --- states ----------------------------------------------------------------------------------


def test_thirty_two_states_four_basic_poses_eight_yaws():
    assert N_STATES == 32
    assert [state_basic(s) for s in range(0, 32, 8)] == list(BASIC_POSES)
    assert [state_yaw(s) for s in range(8)] == pytest.approx(np.arange(8) * np.pi / 4)
    assert SLIDABLE_STATES == tuple(FLAT) and len(FLAT) == 8


@pytest.mark.parametrize("s", range(N_STATES))
def test_state_pose_rests_on_the_board_above_the_centre(s):
    R = state_rotation(s)
    assert R @ R.T == pytest.approx(np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    T = state_pose(s, (0.03, -0.02))
    z = (piece_vertices() @ T[:3, :3].T + T[:3, 3])[:, 2]
    assert z.min() == pytest.approx(0.0, abs=1e-12)
    assert T[:2, 3] == pytest.approx([0.03, -0.02])


def test_basic_poses_have_their_shape():
    width, length, thick = PIECE_SIZE_M
    heights = {state_basic(s): model_cloud(s, (0, 0))[:, 2].max() for s in range(0, 32, 8)}
    assert heights["standing"] == pytest.approx(length, abs=1e-3)  # tip up
    assert heights["side"] == pytest.approx(width, abs=2e-3)  # a side edge down
    assert heights["flat"] == pytest.approx(thick, abs=1e-3)  # a wide face down
    assert length * np.sin(np.pi / 4) < heights["leaning"] < (length + thick) * np.sin(np.pi / 4)
    tip_up = state_rotation(24) @ [0.0, 1.0, 0.0]  # leaning: base -> tip 45 deg up
    assert np.degrees(np.arcsin(tip_up[2])) == pytest.approx(45.0)


def test_only_standing_half_turns_are_equivalent():
    # The piece is symmetric under a half turn about its base -> tip axis (mirror pentagon,
    # faces alike): standing, that is a half turn about the vertical. A flat pentagon turned
    # 180 deg points its tip the other way: a different state.
    for s in range(N_STATES):
        expected = {s, (s + 4) % 8} if s in STANDING else {s}
        assert set(equivalent_states(s)) == expected


# --- fit and belief --------------------------------------------------------------------------


@pytest.mark.parametrize("s", range(N_STATES))
def test_the_true_state_fits_best(s):
    observed = observe(state_pose(s, (0.0, 0.0)), EYE_TOP, seed=s)
    w = state_weights(observed, (0.0, 0.0), eye_m=EYE_TOP)
    others = [t for t in range(N_STATES) if t not in equivalent_states(s)]
    assert w[s] > 0.4
    assert w[s] > w[others].max()
    for t in equivalent_states(s):
        assert w[t] == pytest.approx(w[s], abs=0.1)


def test_standing_and_flat_are_told_apart():
    flat, standing = FLAT[0], STANDING[0]
    w_flat = state_weights(observe(state_pose(flat, (0, 0)), EYE_TOP), (0, 0), eye_m=EYE_TOP)
    assert np.all(w_flat[STANDING] < 0.2 * w_flat[flat])
    w_std = state_weights(observe(state_pose(standing, (0, 0)), EYE_TOP), (0, 0), eye_m=EYE_TOP)
    assert np.all(w_std[FLAT] < 0.2 * w_std[standing])


def test_icp_absorbs_a_small_shift_but_not_a_wrong_yaw():
    T = state_pose(FLAT[0], (0.0, 0.0))
    model = model_view(FLAT[0], (0.0, 0.0), EYE_TOP)
    shifted = T.copy()
    shifted[:2, 3] += (0.003, 0.002)
    assert icp_error(voxel_downsample(observe(shifted, EYE_TOP), 0.003), model) < 0.002
    turned = state_pose(FLAT[1], (0.0, 0.0))  # the same piece turned 45 deg
    assert icp_error(voxel_downsample(observe(turned, EYE_TOP), 0.003), model) > 0.0025
    assert icp_error(np.zeros((0, 3)), model) == np.inf
    assert icp_error(model + (0.0, 0.0, 0.5), model) == np.inf  # no correspondence at all


def test_fit_weight_is_clipped_at_the_threshold():
    e = np.array([0.0, 0.25, 0.5, 1.0, 3.0, np.inf]) * E_TH_M
    assert fit_weight(e, E_TH_M) == pytest.approx([1.0, 0.75, 0.5, 0.0, 0.0, 0.0])


def test_the_belief_is_not_normalised_and_its_mass_falls():
    b0 = uniform_belief()
    assert b0 == pytest.approx(np.full(32, 1 / 32)) and belief_mass(b0) == pytest.approx(1.0)
    s = FLAT[2]
    w = state_weights(observe(state_pose(s, (0, 0)), EYE_TOP), (0, 0), eye_m=EYE_TOP)
    b1 = update_belief(b0, w)
    assert b1 == pytest.approx(w * b0)
    assert belief_mass(b1) < 0.5 * belief_mass(b0)
    assert b1[s] / belief_mass(b1) > 2 / 32  # the true state's share grows
    assert int(np.argmax(b1)) == s
    with pytest.raises(AssertionError):
        update_belief(b0, np.full(32, 1.5))


def test_an_empty_observation_leaves_the_belief_alone():
    assert state_weights(np.zeros((0, 3)), (0, 0), eye_m=EYE_TOP) == pytest.approx(np.ones(32))


# --- visibility ------------------------------------------------------------------------------


def test_visible_points_hides_points_behind_an_occluder():
    x, y = np.meshgrid(np.linspace(-0.02, 0.02, 21), np.linspace(-0.02, 0.02, 21))
    target = np.stack([x.ravel(), y.ravel(), np.full(x.size, 0.01)], axis=1)
    ox, oy = np.meshgrid(np.arange(-0.06, 0.0, 0.002), np.arange(-0.06, 0.06, 0.002))
    wall = np.stack([ox.ravel(), oy.ravel(), np.full(ox.size, 0.1)], axis=1)  # over x < 0
    eye = (0.0, 0.0, 0.5)
    seen = visible_points(target, eye, wall)
    assert np.all(seen[:, 0] > -0.003)
    assert np.count_nonzero(target[:, 0] > 0.003) == np.count_nonzero(seen[:, 0] > 0.003)
    assert len(visible_points(target, eye)) == len(target)  # a plane facing the eye


def test_visible_points_removes_the_far_side_of_a_sphere():
    d = np.random.default_rng(0).normal(size=(500, 3))
    sphere = 0.02 * d / np.linalg.norm(d, axis=1, keepdims=True)
    seen = visible_points(sphere, (0.0, 0.0, 0.5))
    # hidden point removal is approximate at the horizon (z = r^2 / d = 0.8 mm here)
    assert np.all(seen[:, 2] > -0.004) and len(seen) > 0.35 * len(sphere)


def test_visible_points_takes_degenerate_clouds():
    line = np.stack([np.linspace(0.0, 0.1, 20), np.zeros(20), np.zeros(20)], axis=1)
    assert len(visible_points(line, (0.0, 0.0, 0.5))) == 20  # coplanar with the eye
    assert visible_points(np.zeros((0, 3)), (0.0, 0.0, 0.5)).shape == (0, 3)


def test_model_view_sees_the_near_side_and_not_what_is_occluded():
    s = FLAT[0]
    top = model_view(s, (0, 0), (0.0, 0.0, 0.4))
    assert np.all(top[:, 2] > 0.009)  # the upper face only, never the bottom
    cover = model_cloud(s, (0, 0)) + (0.0, 0.0, 0.03)  # a piece-sized cloud right above it
    assert len(model_view(s, (0, 0), (0.0, 0.0, 0.4), cover)) < 0.1 * len(top)


# --- viewpoints ------------------------------------------------------------------------------


@pytest.mark.parametrize("min_elevation_deg, per_distance", [(10, 8), (30, 6), (60, 2)])
def test_viewpoint_candidates_are_above_the_board_looking_at_the_centre(
    min_elevation_deg, per_distance
):
    centre = np.array([0.01, -0.02, 0.0])
    eyes = viewpoint_candidates(centre, (0.3, 0.45), min_elevation_deg)
    assert eyes.shape == (2 * per_distance, 3)
    offsets = eyes - centre
    r = np.linalg.norm(offsets, axis=1)
    assert r == pytest.approx([0.3] * per_distance + [0.45] * per_distance)
    assert np.all(np.degrees(np.arcsin(offsets[:, 2] / r)) >= min_elevation_deg)
    for eye in eyes:
        T = look_at_pose(eye, centre)
        assert T[:3, :3] @ T[:3, :3].T == pytest.approx(np.eye(3))
        assert T[:3, 2] == pytest.approx((centre - eye) / np.linalg.norm(centre - eye))
    assert np.array_equal(eyes, viewpoint_candidates(centre, (0.45, 0.3), min_elevation_deg))


def test_the_icosahedron_lines_are_face_normals():
    dirs = viewpoint_candidates((0, 0, 0), (1.0,), -90)
    assert len(dirs) == 8  # 10 of the 20 face normals point up, 2 of them horizontally
    angles = np.degrees(np.arccos(np.clip(dirs @ dirs.T, -1, 1)))
    # the normals of neighbouring faces of an icosahedron are 41.8 deg apart
    assert np.sort(angles, axis=1)[:, 1] == pytest.approx(np.full(8, 41.81), abs=0.01)


# --- values and decision ---------------------------------------------------------------------


def test_visibility_value_prefers_the_view_behind_a_wall():
    y, z = np.meshgrid(np.arange(-0.08, 0.08, 0.004), np.arange(0.004, 0.07, 0.004))
    wall = np.stack([np.full(y.size, 0.02), y.ravel(), z.ravel()], axis=1)
    seen_from = np.array([-0.3, 0.0, 0.1])
    grid = occupancy_grid(wall, seen_from, (0.0, 0.0))
    assert grid.occupied.any() and grid.occluded.any()
    behind = visibility_value(grid, (0.3, 0.0, 0.1))
    same_side = visibility_value(grid, (-0.3, 0.05, 0.1))
    above = visibility_value(grid, (-0.3, 0.05, 0.15))  # sees just over the wall's top
    assert behind > 0.2 and same_side == 0.0 and 0.0 < above < 0.2 * behind
    both_sides = occupancy_grid(wall, [seen_from, (0.3, 0.0, 0.1)], (0.0, 0.0))
    assert visibility_value(both_sides, (0.3, 0.0, 0.1)) == 0.0  # nothing left to reveal


def test_slide_and_observation_values():
    b = np.zeros(32)
    b[FLAT[3]], b[STANDING[1]] = 0.2, 0.5
    assert slide_value(b, 2.0) == pytest.approx(0.4)  # only flat states pay the reward
    assert observation_value(0.5, 0.2) == pytest.approx(0.9 * 0.5 + 0.1 * 0.2)


@pytest.fixture(scope="module")
def pile():
    """A flat target at the centre with a flat and a standing neighbour, seen from EYE_TOP."""
    neighbours = [state_pose(FLAT[2], (0.06, 0.0)), state_pose(STANDING[3], (-0.05, 0.03))]
    occluders = voxel_downsample(np.concatenate([observe(T, EYE_TOP) for T in neighbours]), 0.003)
    target = observe(state_pose(FLAT[0], (0.0, 0.0)), EYE_TOP, occluders=occluders)
    grid = occupancy_grid(np.concatenate([target, occluders]), EYE_TOP, (0.0, 0.0))
    viewpoints = viewpoint_candidates((0.0, 0.0, 0.0), (0.35,), 15.0)
    return target, occluders, grid, viewpoints


def test_decide_observes_first_then_slides(pile):
    target, occluders, grid, viewpoints = pile
    b = uniform_belief()
    first = decide(b, viewpoints, (0, 0), grid, occluders, reward=1.0)
    assert first.kind == "observe" and first.viewpoint is not None
    assert first.slide_value == pytest.approx(8 / 32)
    assert max(first.uncertainty_reductions) > 0.5  # most states differ from s* = 0 somewhere
    assert len(first.observe_values) == len(viewpoints)

    b = update_belief(b, state_weights(target, (0, 0), eye_m=EYE_TOP, occluders=occluders))
    assert int(np.argmax(b)) in FLAT and b[FLAT].sum() > 0.9 * belief_mass(b)
    second = decide(b, viewpoints, (0, 0), grid, occluders, reward=1.0)
    assert second.kind == "slide" and second.viewpoint is None
    assert second.slide_value > max(second.observe_values)


def test_decide_slides_on_a_certain_flat_belief_and_observes_on_a_flat_reward(pile):
    _, occluders, grid, viewpoints = pile
    b = np.zeros(32)
    b[FLAT[0]] = 1 / 32
    certain = decide(b, viewpoints, (0, 0), grid, occluders, reward=1.0)
    assert certain.kind == "slide"
    assert certain.uncertainty_reductions == pytest.approx(np.zeros(len(viewpoints)))
    b[STANDING[0]] = 1 / 32
    torn = decide(b, viewpoints, (0, 0), grid, occluders, reward=1.0)
    assert torn.kind == "observe"  # a view tells flat from standing: worth more than 1/64
    assert torn == decide(b, viewpoints, (0, 0), grid, occluders, reward=1.0)  # deterministic


def test_uncertainty_reduction_is_zero_for_a_view_that_sees_nothing(pile):
    _, _, _, viewpoints = pile
    x, y = np.meshgrid(np.arange(-0.1, 0.1, 0.002), np.arange(-0.1, 0.1, 0.002))
    lid = np.stack([x.ravel(), y.ravel(), np.full(x.size, 0.08)], axis=1)
    b = uniform_belief()
    assert viewpoints[0][2] > 0.3  # looks down through the lid
    assert uncertainty_reduction(b, viewpoints[0], (0, 0), lid) == 0.0
    assert uncertainty_reduction(b, viewpoints[0], (0, 0)) > 0.5
