"""The episode protocol's judge (trials/core/protocol.py) and the disturbance, on hand-made
motions."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.criteria import CollapseFreeConfig, tilt_change_deg
from clutterbench.sim.pull import PullResult
from clutterbench.trials.core.judge import disturbance
from clutterbench.trials.core.protocol import STEP_FIELDS, counted, episode_end, judge_episode
from clutterbench.trials.core.protocol import judge_pull as _judge_pull

THR = 0.005
CF = CollapseFreeConfig(drop_m=0.010, tilt_deg=15.0)


def judge_pull(result, box, hold, gone, threshold_m):
    return _judge_pull(result, box, hold, gone, threshold_m, CF)


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


def _result(held, released, increments=10, aborted=False, extracted=True, on_shelf=None, end=None):
    """Displacements as drops (the box's centre went down by it), unless `end` poses say."""
    n = len(released)
    start = np.tile([0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0], (n, 1))
    if end is None:
        end = start.copy()
        end[:, 2] -= np.nan_to_num(np.array(released, float))
    return PullResult(
        increments,
        aborted,
        extracted,
        np.array(held, float),
        np.array(released, float),
        np.ones(n, bool) if on_shelf is None else np.array(on_shelf),
        start,
        np.asarray(end, float),
    )


def test_a_step_is_judged_after_the_release_and_also_as_while_held():
    # box 0 pulled out, box 1 held: once released it drops 3 cm with box 2 on it.
    r = _result([np.nan, 0.0, 0.001], [np.nan, 0.03, 0.03])
    step = judge_pull(r, box=0, hold=1, gone=frozenset(), threshold_m=THR)
    assert set(STEP_FIELDS) <= set(step)
    assert step["success_held"] is True and step["others_still_held"] is True
    assert step["success"] is False and step["others_still"] is False
    assert step["n_disturbed"] == 1  # box 2; the released box 1 may settle lower
    # the released box alone settles lower: success; the released box off the shelf: failure
    alone = _result([np.nan, 0.0, 0.001], [np.nan, 0.03, 0.001])
    assert judge_pull(alone, 0, 1, frozenset(), THR)["success"] is True
    off = _result([np.nan, 0.0, 0.0], [np.nan, 0.2, 0.0], on_shelf=[False, False, True])
    assert judge_pull(off, 0, 1, frozenset(), THR)["success"] is False


def test_a_box_off_the_shelf_fails_the_step_even_below_the_threshold():
    r = _result([np.nan, 0.001], [np.nan, 0.001], on_shelf=[False, False])
    assert judge_pull(r, 0, None, frozenset(), THR)["success"] is False


def test_an_abort_before_motion_is_not_a_collapse_and_is_not_judged():
    for r in (None, _result([np.nan, 0.0], [np.nan, 0.0], increments=0, aborted=True)):
        step = judge_pull(r, 0, None, frozenset(), THR)
        assert step["aborted_before_motion"] is True and step["executed"] is False
        assert step["others_still"] is True and step["success"] is None
        assert not counted(step) and step["counted"] is False and step["judged"] is False
        assert episode_end(step | {"box": 0}, False, True) is None


def test_an_abort_after_motion_that_moved_nothing_is_an_abort():
    r = _result([0.05, 0.0], [0.05, 0.0], increments=3, aborted=True, extracted=False)
    step = judge_pull(r, 0, None, frozenset(), THR)
    assert step["aborted_after_motion"] and step["executed"] and not step["extracted"]
    assert step["others_still"] and not counted(step) and step["counted"] is False
    assert step["judged"] is True  # executed, so judged from physics: it counts apart
    assert step["success"] is None and step["success_held"] is None  # neither won nor lost
    moved = judge_pull(
        _result([0.05, 0.02], [0.05, 0.02], 3, True, False), 0, None, frozenset(), THR
    )
    assert counted(moved) and not moved["success"]


def _step(box, success, others_still=None, strict=None, **kw):
    """A step whose collapse-free outcome is `success`; `strict`: its strict one (default
    the same)."""
    still = success if others_still is None else others_still
    strict = (success and still) if strict is None else strict
    base = {
        "box": box,
        "executed": True,
        "aborted_before_motion": False,
        "aborted_after_motion": False,
        "extracted": True,
        "others_still": strict if others_still is None else still,
        "collapse_free": success if others_still is None else still,
        "judged": True,
        "counted": True,
        "strict_counted": True,
        "success": success,
        "strict_success": strict,
        "others_still_held": still,
        "success_held": success,
    }
    return base | kw


def test_the_episode_ends_at_its_first_failed_step():
    assert episode_end(_step(3, False), target_out=False, target_on_shelf=True) == "collapse"
    assert episode_end(_step(3, True), target_out=False, target_on_shelf=True) is None
    assert episode_end(_step(0, True), target_out=True, target_on_shelf=True) == "target_out"
    # the target pulled out but it disturbed the pile: a collapse, not a success
    assert episode_end(_step(0, False), target_out=True, target_on_shelf=True) == "collapse"
    assert episode_end(_step(3, True), target_out=False, target_on_shelf=False) == "target_fell"


def test_the_episode_succeeds_only_when_it_ended_with_the_target_out():
    ok = judge_episode([_step(2, True), _step(0, True)], "target_out", target=0)
    assert ok["success"] and ok["target_extracted"] and ok["counted_steps"] == 2
    bad = judge_episode([_step(2, True), _step(1, False)], "collapse", target=0)
    assert not bad["success"] and not bad["success_held"]
    # the target came out cleanly while held; its release disturbed the pile
    held = _step(0, False) | {"success_held": True, "others_still_held": True}
    released = judge_episode([held], "collapse", target=0)
    assert not released["success"] and released["success_held"]
    aborted = _step(1, False, True, executed=False, aborted_before_motion=True, extracted=False)
    gave_up = judge_episode([aborted], "gave_up", target=0)
    assert gave_up["aborted_before_motion"] == 1 and gave_up["counted_steps"] == 0


def _tipped(deg: float, dz: float = 0.0) -> np.ndarray:
    """End poses of two boxes: box 0 pulled out, box 1 turned `deg` about the shelf's x axis
    in place (its centre `dz` lower)."""
    half = np.radians(deg) / 2
    end = np.tile([0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0], (2, 1))
    end[1, 3:] = [np.cos(half), np.sin(half), 0.0, 0.0]
    end[1, 2] -= dz
    return end


def test_a_box_tipped_40_degrees_in_place_is_not_collapse_free():
    r = _result([np.nan, 0.0], [np.nan, 0.0], end=_tipped(40.0))
    step = judge_pull(r, 0, None, frozenset(), THR)
    assert step["box_motion"][0]["tilt_change_deg"] == pytest.approx(40.0, abs=1e-3)
    assert step["collapse_free"] is False and step["success"] is False
    assert step["strict_success"] is False  # a strict success is always collapse-free
    # a turn about the vertical is no tilt (a slide with a twist)
    q = [np.cos(np.radians(20)), 0.0, 0.0, np.sin(np.radians(20))]
    assert tilt_change_deg(np.array([1.0, 0, 0, 0]), np.array(q)) == pytest.approx(0.0, abs=1e-6)


def test_a_box_that_slid_8_mm_is_collapse_free_but_not_a_strict_success():
    end = np.tile([0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0], (2, 1))
    end[1, 1] += 0.008
    r = _result([np.nan, 0.008], [np.nan, 0.008], end=end)
    step = judge_pull(r, 0, None, frozenset(), THR)
    assert step["box_motion"][0]["displacement_m"] == pytest.approx(0.008)
    assert step["strict_success"] is False and step["others_still"] is False
    assert step["success"] is True and step["collapse_free"] is True
    # ... and a drop of 2 cm is a collapse under both
    drop = judge_pull(_result([np.nan, 0.02], [np.nan, 0.02]), 0, None, frozenset(), THR)
    assert drop["success"] is False and drop["strict_success"] is False


def test_every_step_carries_the_per_box_fields():
    from clutterbench.criteria import MOTION_FIELDS

    r = _result([np.nan, 0.0, 0.001], [np.nan, 0.03, 0.001])
    step = judge_pull(r, box=0, hold=1, gone=frozenset(), threshold_m=THR)
    assert [e["box"] for e in step["box_motion"]] == [1, 2]
    assert [e["held"] for e in step["box_motion"]] == [True, False]
    for e in step["box_motion"]:
        assert set(e) == set(MOTION_FIELDS)


def test_the_strict_episode_is_the_prefix_up_to_its_first_strict_failure():
    # step 1 slid a box 8 mm (a strict failure, collapse-free); the episode goes on and the
    # target comes out: a collapse-free success, a strict failure after 2 strict steps
    slid = _step(2, True, strict=False)
    ep = judge_episode([_step(1, True), slid, _step(0, True)], "target_out", target=0)
    assert ep["success"] is True and ep["strict_success"] is False
    assert ep["strict_steps"] == 2 and ep["strict_counted_steps"] == 2
    assert ep["counted_steps"] == 3


def test_strict_step_counts_stop_at_the_first_strict_failure():
    from clutterbench.trials.core.stats import aggregate

    slid = _step(2, True, strict=False)
    rec = {"condition": "c", "episode": 0, "success": True, "strict_success": False}
    rec["steps"] = [_step(1, True), slid, _step(3, True), _step(0, True)]
    row = aggregate([rec]).iloc[0]
    assert (row["step_success_k"], row["step_success_n"]) == (4, 4)
    # strict: steps 0 and 1 only (the strict episode ended at step 1)
    assert (row["step_strict_success_k"], row["step_strict_success_n"]) == (1, 2)


def test_an_executed_judged_step_is_never_aborted_before_motion():
    from clutterbench.trials.core.executors import judge_arm_step

    # an arm that gave up before pulling but knocked a box off its bed
    r = _result([np.nan, 0.03], [np.nan, 0.03], increments=0, aborted=True, extracted=False)
    step = judge_arm_step(r, 0, None, frozenset(), THR, CF)
    assert step["executed"] and step["judged"] and step["success"] is False
    assert step["aborted_before_motion"] is False and step["aborted_after_motion"] is True
    for case in (r, _result([np.nan, 0.0], [np.nan, 0.0], increments=0, aborted=True)):
        s = judge_arm_step(case, 0, None, frozenset(), THR, CF)
        assert not (s["executed"] and s["aborted_before_motion"])
        assert not (s["judged"] and s["aborted_before_motion"])


def test_an_invalid_ch4_action_is_never_counted_a_success():
    from clutterbench.trials.ch4.episodes import OUTCOMES, count_if_valid

    clean = dict.fromkeys(OUTCOMES, True) | {"others_still": True}
    assert not any(count_if_valid(clean, valid=False)[k] for k in OUTCOMES)
    assert all(count_if_valid(clean, valid=True)[k] for k in OUTCOMES)


def _entry(box, displacement=0.0, drop=0.0, tilt=0.0, left=False, held=False):
    return {
        "box": box,
        "held": held,
        "displacement_m": displacement,
        "drop_m": drop,
        "tilt_change_deg": tilt,
        "left_shelf": left,
    }


def test_rejudge_reads_ch4_and_ch5_records_from_the_per_box_fields():
    from clutterbench.trials.rejudge import rejudge

    ch4 = {
        "condition": "c4",
        "episode": 0,
        "executed": True,
        "extracted": True,
        "valid": True,
        "target": None,
        "extract": 1,
        "box_motion": [_entry(0, displacement=0.008), _entry(2, drop=0.03, held=True)],
    }
    (row,) = rejudge([ch4], THR, CF)
    assert row["success"] is True and row["strict_success"] is False
    (row,) = rejudge([ch4 | {"valid": False}], THR, CF)
    assert row["success"] is False  # an invalid action is never a success
    step = {"executed": True, "placed": True, "at_place": True, "box_motion": [_entry(0)]}
    ch5 = {"condition": "c5", "episode": 0, "branch": "simple", "end": "placed"}
    (row,) = rejudge([ch5 | {"steps": [step]}], THR, CF)
    assert row["success"] is True and row["strict_success"] is True
    tipped = step | {"box_motion": [_entry(0, tilt=40.0)]}
    (row,) = rejudge([ch5 | {"steps": [tipped], "end": "collapse"}], THR, CF)
    assert row["success"] is False and row["strict_success"] is False
