"""Thesis 5.2.3 placement candidates and moves (eqs. 5.2-5.9), hand-computed."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.planning.ch5.replenish import (
    WorkingSpace,
    candidate_rect,
    in_working_space,
    move_goal,
    new_box_extent_m,
    rearrange_goal,
    rect_iou_mask,
)

B = np.array([0.0, -0.05, 0.10, 0.10])  # a cluster 10 cm wide and high, centred at x = 0
G = 0.01


def test_left_candidate_is_left_of_the_cluster_and_right_is_right():
    left = candidate_rect(B, "left", 0.03, 0.08, G)
    right = candidate_rect(B, "right", 0.03, 0.08, G)
    # eq. (5.4)/(5.3) with right = +x: centres at x_i -/+ (w_i/2 + w'/2 + g)
    assert left[0] == pytest.approx(-0.05 - 0.015 - 0.01)
    assert right[0] == pytest.approx(0.05 + 0.015 + 0.01)
    assert left[0] + left[2] / 2 <= B[0] - B[2] / 2 + 1e-12  # wholly left of the cluster
    assert right[0] - right[2] / 2 >= B[0] + B[2] / 2 - 1e-12
    # both rest where the cluster rests: bottoms at y_i + h_i / 2
    for r in (left, right):
        assert r[1] + r[3] / 2 == pytest.approx(B[1] + B[3] / 2)
        assert r[2] == pytest.approx(0.03 + 2 * G) and r[3] == pytest.approx(0.08)


def test_top_candidate_sits_above_flush_left():
    top = candidate_rect(B, "top", 0.12, 0.03, G)
    # eq. (5.2): x_i - w_i/2 + w'/2, y_i - h_i/2 - h'/2 - g (y down: above is smaller y)
    assert top == pytest.approx([-0.05 + 0.06, -0.05 - 0.05 - 0.015 - 0.01, 0.12 + 2 * G, 0.03])
    assert top[1] + top[3] / 2 < B[1] - B[3] / 2


def test_move_goal_clears_the_candidate_side():
    s = np.array([0.1, -0.05, 0.04, 0.1])
    assert move_goal(s, "right", 0.03, 0.08, G)[0] == pytest.approx(0.1 + 0.015 + 0.02 + 0.01)
    assert move_goal(s, "left", 0.03, 0.08, G)[0] == pytest.approx(0.1 - 0.015 - 0.02 - 0.01)
    up = move_goal(s, "top", 0.12, 0.03, G)
    assert up[0] == pytest.approx(0.1) and up[1] == pytest.approx(-0.05 - 0.03 - 2 * G)


def test_move_goal_given_the_candidate_is_eq_5_6_for_a_blocker_centred_on_it():
    right = candidate_rect(B, "right", 0.03, 0.08, G)
    s = np.array([right[0], -0.04, 0.05, 0.08])
    assert move_goal(s, "right", 0.03, 0.08, G, right) == pytest.approx(
        move_goal(s, "right", 0.03, 0.08, G)
    )


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("width", [0.02, 0.16])
def test_move_goal_puts_the_blockers_near_edge_at_the_candidates_far_edge(side, width):
    """A blocker flush against the cluster, thin or wide (off the candidate's centre): eq.
    (5.6) as printed would leave a thin one in the candidate and carry a wide one farther
    than needed; given the candidate it goes exactly as far as clears it."""
    cand = candidate_rect(B, side, 0.09, 0.08, G)
    sign = 1.0 if side == "right" else -1.0
    edge = B[0] + sign * B[2] / 2  # the cluster's side the candidate touches
    s = np.array([edge + sign * width / 2, -0.04, width, 0.08])
    goal = move_goal(s, side, 0.09, 0.08, G, cand)
    near_edge = goal[0] - sign * width / 2
    far_edge = cand[0] + sign * cand[2] / 2
    assert near_edge == pytest.approx(far_edge)


def test_move_goal_leaves_a_blocker_already_clear_of_the_candidate_where_it_is():
    cand = candidate_rect(B, "right", 0.03, 0.08, G)
    s = np.array([cand[0] + cand[2] / 2 + 0.05, -0.04, 0.04, 0.08])
    assert move_goal(s, "right", 0.03, 0.08, G, cand)[0] == pytest.approx(s[0])


def test_a_lifted_blocker_clears_the_top_candidate():
    """B_s lying on a stack is lifted clear of B^top (which starts g above the stack, eq.
    5.2) with g to spare: the new box is never let go into the held blocker."""
    stack = np.array([0.0, -0.05, 0.12, 0.1])  # top edge at y = -0.1
    s = np.array([0.0, -0.12, 0.13, 0.04])  # lying on it: bottom edge at y = -0.1
    top = candidate_rect(stack, "top", 0.12, 0.03, G)
    up = move_goal(s, "top", 0.12, 0.03, G)
    blocker_bottom = up[1] + s[3] / 2
    assert blocker_bottom <= top[1] - top[3] / 2 - G + 1e-9


def test_rearrange_goal_is_beside_the_blocker_on_its_side():
    s = np.array([0.0, -0.05, 0.04, 0.1])
    k_left, k_right = np.array([-0.1, -0.05, 0.06, 0.1]), np.array([0.1, -0.05, 0.06, 0.1])
    assert rearrange_goal(k_left, s, G)[0] == pytest.approx(-0.02 - 0.03 - 0.01)  # eq. (5.9)
    assert rearrange_goal(k_right, s, G)[0] == pytest.approx(0.02 + 0.03 + 0.01)


def test_rearrange_goal_makes_room_for_the_blockers_own_move():
    s = np.array([0.0, -0.05, 0.04, 0.1])
    k_right = np.array([0.1, -0.05, 0.06, 0.1])
    # B_s will move right to x = 0.05: B_k, on its right, goes beside that goal
    assert rearrange_goal(k_right, s, G, np.array([0.05, -0.05]))[0] == pytest.approx(0.11)
    # B_s moves left, away from B_k: eq. (5.9) as printed
    assert rearrange_goal(k_right, s, G, np.array([-0.05, -0.05]))[0] == pytest.approx(0.06)
    # a lift (no sideways motion): as printed
    assert rearrange_goal(k_right, s, G, np.array([0.0, -0.1]))[0] == pytest.approx(0.06)


def test_new_box_lies_on_a_stack_and_stands_beside_a_row():
    size = np.array([0.1, 0.12, 0.03])  # (D, W, H)
    assert new_box_extent_m(size, "top") == (0.12, 0.03)
    assert new_box_extent_m(size, "left") == (0.03, 0.12)


def test_working_space_bounds():
    space = WorkingSpace(0.33, 0.28, 0.33)
    assert in_working_space(np.array([0.0, -0.05, 0.1, 0.1]), space)
    assert not in_working_space(np.array([0.14, -0.05, 0.1, 0.1]), space)  # past the side
    assert not in_working_space(np.array([0.0, 0.02, 0.1, 0.1]), space)  # below the floor
    assert not in_working_space(np.array([0.0, -0.3, 0.1, 0.1]), space)  # above the top


def test_iou_of_a_box_and_a_region():
    region = np.zeros((10, 10), dtype=bool)
    region[0:4, 0:4] = True
    assert rect_iou_mask(np.array([2.0, 2.0, 4.0, 4.0]), region) == pytest.approx(1.0)
    assert rect_iou_mask(np.array([4.0, 2.0, 4.0, 4.0]), region) == pytest.approx(8 / 24)
    assert rect_iou_mask(np.array([8.0, 8.0, 2.0, 2.0]), region) == 0.0
