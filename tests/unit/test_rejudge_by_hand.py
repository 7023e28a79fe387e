"""Re-judging against outcomes worked out by hand: the re-judging test of
the trials re-judges with the same criteria.py that judged, so it cannot catch a bug there.
Here every expected outcome is written down from the thresholds alone, never computed by
criteria.py: a bug in collapse_free, still or the episode rule fails this test."""

from __future__ import annotations

import pytest

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.trials.rejudge import rejudge, summarize

CF = CollapseFreeConfig(drop_m=0.010, tilt_deg=15.0)
MOVED_M = 0.005


def _box(k, disp=0.0, drop=0.0, tilt=0.0, off=False, held=False):
    return {
        "box": k,
        "held": held,
        "displacement_m": disp,
        "drop_m": drop,
        "tilt_change_deg": tilt,
        "left_shelf": off,
    }


def _step(*motion, executed=True):
    return {"box": 0, "executed": executed, "box_motion": list(motion)}


def _episode(i, end, *steps):
    return {"condition": "c", "episode": i, "end": end, "steps": list(steps)}


# (episode, collapse-free success, strict success), each worked out by hand:
CASES = [
    # 0: nothing else moved, target out: both succeed
    (_episode(0, "target_out", _step(_box(1), _box(2))), True, True),
    # 1: a neighbour slid 8 mm (> 5 mm moved, no drop, no tilt): collapse-free, not strict
    (_episode(1, "target_out", _step(_box(1, disp=0.008))), True, False),
    # 2: slid exactly 5 mm: "beyond the threshold" is strictly more, so still
    (_episode(2, "target_out", _step(_box(1, disp=0.005))), True, True),
    # 3: dropped 12 mm (> 10 mm): a collapse under both
    (_episode(3, "collapse", _step(_box(1, disp=0.012, drop=0.012))), False, False),
    # 4: dropped 9 mm and moved 9 mm: collapse-free (9 < 10), not strict (9 > 5)
    (_episode(4, "target_out", _step(_box(1, disp=0.009, drop=0.009))), True, False),
    # 5: tipped 20 degrees in place (> 15): a collapse under both
    (_episode(5, "collapse", _step(_box(1, tilt=20.0))), False, False),
    # 6: tipped 14 degrees, did not move: both succeed
    (_episode(6, "target_out", _step(_box(1, tilt=14.0))), True, True),
    # 7: left the shelf after moving 1 mm: a collapse under both
    (_episode(7, "collapse", _step(_box(1, disp=0.001, off=True))), False, False),
    # 8: a held box released 3 cm lower, still on the shelf: neither criterion counts it
    (_episode(8, "target_out", _step(_box(1, disp=0.03, drop=0.03, held=True))), True, True),
    # 9: a held box released off the shelf: a collapse
    (_episode(9, "collapse", _step(_box(1, disp=0.2, off=True, held=True))), False, False),
    # 10: two clean steps, then a step that moved a box 7 mm, target out: not strict
    (
        _episode(10, "target_out", _step(_box(1)), _step(_box(2)), _step(_box(3, disp=0.007))),
        True,
        False,
    ),
    # 11: an abort before motion (not executed) moved nothing counted, then a clean step
    (
        _episode(11, "target_out", _step(_box(1, disp=0.5), executed=False), _step(_box(1))),
        True,
        True,
    ),
    # 12: clean steps, but the planner gave up: no success under either
    (_episode(12, "gave_up", _step(_box(1))), False, False),
]


@pytest.mark.parametrize(
    "record, success, strict", CASES, ids=[str(c[0]["episode"]) for c in CASES]
)
def test_each_episode_is_judged_as_worked_out_by_hand(record, success, strict):
    row = rejudge([record], MOVED_M, CF)[0]
    assert (row["success"], row["strict_success"]) == (success, strict)


def test_the_counts_are_the_hand_counts():
    counts = summarize(rejudge([c[0] for c in CASES], MOVED_M, CF))["c"]
    # collapse-free: episodes 0, 1, 2, 4, 6, 8, 10, 11; strict: 0, 2, 6, 8, 11
    assert (counts["episodes"], counts["success_k"], counts["strict_success_k"]) == (13, 8, 5)


def test_a_stricter_drop_threshold_turns_the_9_mm_drop_into_a_collapse():
    """Episode 4 under drop_m = 8 mm: 9 mm > 8 mm, a collapse (worked out by hand)."""
    row = rejudge([CASES[4][0]], MOVED_M, CollapseFreeConfig(drop_m=0.008, tilt_deg=15.0))[0]
    assert (row["success"], row["strict_success"]) == (False, False)


def test_a_more_lenient_threshold_cannot_rescue_an_episode_that_stopped_at_a_collapse():
    """Episode 3 stopped at its 12 mm drop; under drop_m = 20 mm the drop is forgiven, but
    what the episode would have done next was never run: unknown (None), not a success."""
    row = rejudge([CASES[3][0]], 0.05, CollapseFreeConfig(drop_m=0.020, tilt_deg=15.0))[0]
    assert row["success"] is None
