"""The search oracles' action sets on a toy world (no physics): what a holding oracle may do."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from clutterbench.trials.ch6.oracle import SearchOracle
from clutterbench.trials.config import Ch6TrialParams


def _toy_oracle(hold_any_pull: bool) -> SearchOracle:
    """Boxes 0 (the target), 1 and 2. The target's pull is clean only once box 1 is out; box
    1's pull is clean only while box 2 is held; box 2's pull is never clean."""
    oracle = SearchOracle(
        None, None, None, Ch6TrialParams(), True, None, hold_any_pull=hold_any_pull
    )

    def simulate(state, action, cut_short=True):
        box, hold = action
        clean = {0: 1 in state.removed, 1: hold == 2, 2: False}[box]
        step = {"success": clean, "strict_success": clean}
        after = SimpleNamespace(removed=state.removed | {box})
        return step, after, np.zeros(3)

    oracle.simulate = simulate
    oracle.candidates = lambda state, target: [k for k in range(3) if k not in state.removed]
    return oracle


@pytest.mark.parametrize("hold_any_pull", [False, True])
def test_the_holding_oracle_holds_during_another_box_s_pull_only_when_allowed(hold_any_pull):
    start = SimpleNamespace(removed=frozenset())
    plan, _, exhausted = _toy_oracle(hold_any_pull).search(start, 0)
    assert not exhausted
    if hold_any_pull:  # the bimanual pull planners' idle hold: pull 1 holding 2, then 0
        assert [action for action, _ in plan] == [(1, 2), (0, None)]
    else:  # holds only during the target's pull: no clean sequence
        assert plan is None
