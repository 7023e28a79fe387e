"""The search oracles' action sets and states on toy worlds (no physics): what a holding oracle
may do, and what the search must tell apart to be complete."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from clutterbench.trials.ch6.oracle import SearchOracle, SeenStates
from clutterbench.trials.config import Ch6TrialParams

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


def _state(removed=(), poses=None) -> SimpleNamespace:
    poses = np.tile(IDENTITY, (3, 1)) if poses is None else poses
    return SimpleNamespace(removed=frozenset(removed), poses=poses)


def _toy_oracle(clean, after=None, holding=True, hold_any_pull=True) -> SearchOracle:
    """Boxes 0 (the target), 1 and 2; `clean(state, action)` says whether a step is clean,
    `after(state, action)` the poses it leaves (default: where they stood)."""
    params = Ch6TrialParams()
    oracle = SearchOracle(
        None, None, None, params.pull, params.search, holding, None, hold_any_pull=hold_any_pull
    )

    def simulate(state, action, cut_short=True):
        ok = clean(state, action)
        poses = state.poses if after is None else after(state, action)
        step = {"success": ok, "strict_success": ok}
        return step, _state(state.removed | {action[0]}, poses), np.zeros(3)

    oracle.simulate = simulate
    oracle.candidates = lambda state, target: [k for k in range(3) if k not in state.removed]
    return oracle


@pytest.mark.parametrize("hold_any_pull", [False, True])
def test_the_holding_oracle_holds_during_another_box_s_pull_only_when_allowed(hold_any_pull):
    """The target's pull is clean only once box 1 is out; box 1's pull is clean only while
    box 2 is held; box 2's pull is never clean."""

    def clean(state, action):
        box, hold = action
        return {0: 1 in state.removed, 1: hold == 2, 2: False}[box]

    oracle = _toy_oracle(clean, hold_any_pull=hold_any_pull)
    plan, _, exhausted = oracle.search(_state(), 0)
    assert not exhausted
    if hold_any_pull:  # the bimanual pull planners' idle hold: pull 1 holding 2, then 0
        assert [action for action, _ in plan] == [(1, 2), (0, None)]
    else:  # holds only during the target's pull: no clean sequence
        assert plan is None


def test_two_orders_that_take_out_the_same_boxes_are_two_states():
    """Taking out 1 then 2 leaves the target where its pull collapses the shelf; 2 then 1
    leaves it 5 cm away, where it comes out clean. A search that remembers a state by the
    boxes out alone meets {1, 2} first by the bad order and never looks at the good one."""

    def after(state, action):
        poses = state.poses.copy()
        if action[0] == 1 and 2 in state.removed:  # 1 after 2: the target shifts
            poses[0, 0] += 0.05
        return poses

    def clean(state, action):
        return action[0] != 0 or state.poses[0, 0] > 0.01

    plan, _, exhausted = _toy_oracle(clean, after, holding=False).search(_state(), 0)
    assert not exhausted and plan is not None
    assert [action for action, _ in plan] == [(2, None), (1, None), (0, None)]


def test_every_clean_hold_of_a_pull_is_searched():
    """Box 1 comes out clean alone and while 2 is held; only the held pull leaves the target
    where its own pull is clean. A search that keeps the first clean hold misses it."""

    def after(state, action):
        poses = state.poses.copy()
        if action == (1, 2):
            poses[0, 0] += 0.05
        return poses

    def clean(state, action):
        box, _ = action
        return {0: state.poses[0, 0] > 0.01, 1: True, 2: False}[box]

    plan, _, exhausted = _toy_oracle(clean, after).search(_state(), 0)
    assert not exhausted and plan is not None
    assert [action for action, _ in plan] == [(1, 2), (0, None)]


def test_seen_states_hold_within_the_tolerance_only():
    seen = SeenStates(same_m=0.001, same_deg=1.0)  # coarse, to test the arithmetic
    seen.add(_state())
    moved = np.tile(IDENTITY, (3, 1))
    moved[2, 1] = 0.0009
    assert seen.contains(_state(poses=moved))
    moved[2, 1] = 0.0011
    assert not seen.contains(_state(poses=moved))
    turned = np.tile(IDENTITY, (3, 1))
    half = np.radians(1.5) / 2.0  # 1.5 degrees about z
    turned[1, 3:] = [np.cos(half), 0.0, 0.0, np.sin(half)]
    assert not seen.contains(_state(poses=turned))
    turned[1, 3:] = -turned[1, 3:]  # -q is the same rotation as q
    assert not seen.contains(_state(poses=turned))
    half = np.radians(0.5) / 2.0
    turned[1, 3:] = [-np.cos(half), 0.0, 0.0, -np.sin(half)]
    assert seen.contains(_state(poses=turned))
    assert not seen.contains(_state(removed={2}))  # other boxes out: another state
    far = np.tile(IDENTITY, (3, 1))
    far[2, 0] = 1.0  # box 2 is out: where it lies does not matter
    seen.add(_state(removed={2}))
    assert seen.contains(_state(removed={2}, poses=far))
