"""The physics judge of trials: named booleans and the disturbance, on hand-made motions."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.trials.judge import Disturbance, disturbance, judge_episode, judge_step

THR = 0.005


def test_disturbance_counts_only_other_boxes_beyond_the_threshold():
    before = np.zeros((4, 3))
    after = before.copy()
    after[0, 0] = -0.30  # the pulled box: excluded
    after[1, 2] = -0.02  # fell 2 cm: counted
    after[2, 1] = 0.004  # slid 4 mm: under the threshold, still summed
    after[3, 0] = 0.5  # gone before this step: ignored
    d = disturbance(before, after, exclude={0}, gone={3}, threshold_m=THR)
    assert d.n_disturbed == 1
    assert d.disturbance_m == pytest.approx(0.024)


def test_step_succeeds_only_when_extracted_and_nothing_else_moved():
    still, moved = Disturbance(0, 0.001), Disturbance(1, 0.03)
    assert judge_step(True, False, still)["success"] is True
    assert judge_step(True, False, moved)["success"] is False
    aborted = judge_step(False, True, still)
    assert aborted["success"] is False and aborted["others_still"] is True


def test_episode_needs_the_target_out_and_every_step_still():
    ok = judge_step(True, False, Disturbance(0, 0.0))
    bad = judge_step(True, False, Disturbance(2, 0.1))
    aborted = judge_step(False, True, Disturbance(0, 0.0))
    assert judge_episode(True, [aborted, ok], Disturbance(0, 0.0))["success"] is True
    assert judge_episode(True, [bad, ok], Disturbance(2, 0.1))["success"] is False
    assert judge_episode(False, [ok], Disturbance(0, 0.0))["success"] is False
    assert judge_episode(True, [aborted, ok], Disturbance(0, 0.0))["aborted_steps"] == 1
