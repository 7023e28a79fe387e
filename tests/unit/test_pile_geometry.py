"""Pure functions of the ch. 3 pile (sim/pile.py): a piece lying flat, the board's edges, the
slide's travel and its judge, the look-at camera, on hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.sim.pile import (
    beyond_edge,
    exit_travel_m,
    flat_piece_pose,
    judge_slide,
    look_at_rotation,
    on_board,
    piece_points_m,
)
from clutterbench.sim.pile_config import SlideConfig

HALF = np.array([0.2, 0.1])  # a 0.4 x 0.2 m rectangle


def test_flat_piece_lies_on_a_level_face_with_its_tip_as_asked():
    pose = flat_piece_pose(0.03, -0.02, np.pi / 2, surface_z_m=0.01)
    pts = piece_points_m(pose)
    low = np.sort(pts[:, 2])[:5]
    assert low == pytest.approx(np.full(5, 0.01), abs=1e-9)  # the whole lower face touches
    assert pose[:2] == pytest.approx([0.03, -0.02])
    tip = pts[np.argmax(pts[:, 1])]  # tip along +y (pi / 2)
    assert tip[0] == pytest.approx(0.03, abs=1e-9)
    assert np.linalg.norm(pose[3:]) == pytest.approx(1.0)


def test_on_board_by_centre_and_height():
    poses = np.zeros((4, 7))
    poses[:, 3] = 1.0
    poses[:, :3] = [[0.1, 0.05, 0.01], [0.25, 0.0, 0.01], [0.0, 0.0, -0.05], [0.0, 0.0, 0.0]]
    poses = np.vstack([poses, np.full((1, 7), np.nan)])
    assert on_board(poses, (0.4, 0.2)).tolist() == [True, False, False, False, False]


def test_beyond_edge_needs_every_point_past_one_edge():
    assert beyond_edge(np.array([[0.21, 0.0], [0.3, 0.05]]), HALF)
    assert beyond_edge(np.array([[0.0, -0.11], [0.1, -0.2]]), HALF)
    assert not beyond_edge(np.array([[0.21, 0.0], [0.19, 0.0]]), HALF)  # straddles
    # past the corner but through two different edges: not beyond one edge
    assert not beyond_edge(np.array([[0.25, 0.0], [0.0, 0.15]]), HALF)


def test_exit_travel_hand_computed():
    pts = np.array([[0.0, 0.0], [0.05, 0.02], [-0.03, -0.01]])
    assert exit_travel_m(pts, 0.0, HALF) == pytest.approx(0.23)  # +x: last point at -0.03
    assert exit_travel_m(pts, np.pi, HALF) == pytest.approx(0.25)
    assert exit_travel_m(pts, np.pi / 2, HALF) == pytest.approx(0.11)
    # 45 deg: through the top edge (y: 0.11 / sin 45) before the right one (x: 0.23 / cos 45)
    assert exit_travel_m(pts, np.pi / 4, HALF) == pytest.approx(0.11 * np.sqrt(2))
    moved = pts + exit_travel_m(pts, 2.0, HALF) * np.array([np.cos(2.0), np.sin(2.0)])
    assert beyond_edge(moved + 1e-9 * np.array([np.cos(2.0), np.sin(2.0)]), HALF)
    assert exit_travel_m(pts + [1.0, 0.0], 0.0, HALF) == 0.0  # already out


@pytest.mark.parametrize(
    "eye", [np.array([0.3, -0.2, 0.25]), np.array([0.0, 0.0, 0.5]), np.array([-0.1, 0.4, 0.05])]
)
def test_look_at_rotation_is_a_rotation_looking_at_the_target(eye):
    target = np.array([0.02, 0.01, 0.0])
    R = look_at_rotation(eye, target)
    assert R @ R.T == pytest.approx(np.eye(3), abs=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    fwd = (target - eye) / np.linalg.norm(target - eye)
    assert R[:, 0] == pytest.approx(fwd)
    assert R[2, 1] == pytest.approx(0.0, abs=1e-12)  # no roll: the camera's left is level


def test_straight_down_view_has_world_y_up_and_x_right():
    R = look_at_rotation(np.array([0.0, 0.0, 0.5]), np.zeros(3))
    assert R[:, 1] == pytest.approx([-1.0, 0.0, 0.0])  # camera left = world -x
    assert R[:, 2] == pytest.approx([0.0, 1.0, 0.0])  # camera up = world +y


def test_judge_names_each_failure():
    board = (0.4, 0.2)
    before = np.array([flat_piece_pose(x, 0.0, 0.0) for x in (0.0, 0.1, -0.1, 0.05)])
    before[3] = np.nan  # taken out earlier: not judged
    exit_pose = flat_piece_pose(0.25, 0.0, 0.0)  # footprint past the +x edge
    after = before.copy()
    after[0] = exit_pose
    after[1, 1] += 0.005  # nudged less than the threshold
    cfg = SlideConfig(moved_threshold_m=0.01)

    ok = judge_slide(before, after, 0, cfg, board, steps=7)
    assert ok.target_out and ok.others_still and ok.success
    assert ok.moved == () and ok.steps == 7
    assert np.isnan(ok.displacement_m[[0, 3]]).all()
    assert ok.displacement_m[1] == pytest.approx(0.005)

    shoved = after.copy()
    shoved[2, 0] -= 0.02  # moved on the board
    r = judge_slide(before, shoved, 0, cfg, board)
    assert (r.target_out, r.others_still, r.success, r.moved) == (True, False, False, (2,))

    edge_before, fell = before.copy(), after.copy()
    edge_before[2, 0] = -0.198  # at the -x edge ...
    fell[2, 0] = -0.203  # ... tipped over it: moved 5 mm, but off the board
    r = judge_slide(edge_before, fell, 0, cfg, board)
    assert r.moved == (2,) and r.displacement_m[2] < cfg.moved_threshold_m

    stuck = after.copy()
    stuck[0] = flat_piece_pose(0.19, 0.0, 0.0)  # still over the edge
    r = judge_slide(before, stuck, 0, cfg, board)
    assert (r.target_out, r.others_still, r.success) == (False, True, False)
