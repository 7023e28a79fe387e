"""trials.ch6.pull_map_meaning: a truth map of the pull marks every box the pull moves
(`moved`) or only those the collapse-free criterion calls collapsed (`collapse`)."""

from __future__ import annotations

import types

import numpy as np

import clutterbench.trials.ch6.truth_maps as truth_maps
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.sim.pull import PullResult, SceneState
from clutterbench.trials.ch6.truth_maps import TruthCollapseMaps

UP = [1.0, 0.0, 0.0, 0.0]


def _pull_of_box_0(*args, **kwargs) -> PullResult:
    """Box 0 pulled out; box 1 slides 20 mm level (moved, not collapsed); box 2 drops 30 mm
    (collapsed); box 3 stays."""
    start = np.array([[0.0, 0.0, 0.1, *UP]] * 4)
    end = start.copy()
    end[0, 1] = -0.3
    end[1, 0] += 0.02
    end[2, 2] -= 0.03
    on_shelf = np.array([False, True, True, True])
    disp = np.linalg.norm(end[:, :3] - start[:, :3], axis=1)
    return PullResult(1, False, True, disp, disp, on_shelf, start, end)


def test_moved_marks_the_slide_and_the_drop_collapse_only_the_drop(monkeypatch):
    monkeypatch.setattr(truth_maps, "pull_outcome", _pull_of_box_0)
    spec = types.SimpleNamespace(n=4)
    state = SceneState(np.zeros((4, 7)), frozenset())
    instance = np.zeros((2, 2), np.uint8)
    pull = (0.02, 0.003)
    moves = TruthCollapseMaps(spec, None, 0.005, pull)
    falls = TruthCollapseMaps(spec, None, 0.005, pull, CollapseFreeConfig())
    for maps in (moves, falls):
        maps.at(state, instance)
    assert list(np.flatnonzero(moves.moved_by_removing(0))) == [1, 2]
    assert list(np.flatnonzero(falls.moved_by_removing(0))) == [2]
