"""The one trials aggregator: Wilson intervals, k/n text, per-episode and per-step rates."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.trials.core.stats import (
    Rate,
    aggregate,
    cluster_bootstrap_interval,
    rate,
    step_rate,
    wilson_interval,
)

Z2 = 1.959963984540054**2


def test_wilson_interval_matches_hand_values():
    # k = 0, n = 1: centre = (z^2/2) / (1 + z^2) = half-width, so hi = z^2 / (1 + z^2).
    assert wilson_interval(0, 1) == (0.0, pytest.approx(Z2 / (1 + Z2), abs=1e-12))
    # k = n = 1: the mirror image, lo = 1 / (1 + z^2).
    assert wilson_interval(1, 1) == (pytest.approx(1 / (1 + Z2), abs=1e-12), 1.0)
    # 52/57 by hand: p = 0.912281, centre = (p + z^2/114) / (1 + z^2/57) = 0.886252,
    # half = z * sqrt(p (1 - p) / 57 + z^2 / (4 * 57^2)) / (1 + z^2/57) = 0.075701.
    lo, hi = wilson_interval(52, 57)
    assert lo == pytest.approx(0.810551, abs=2e-6)
    assert hi == pytest.approx(0.961948, abs=2e-6)
    # 3/7: the interval is centred on (p + z^2/2n) / (1 + z^2/n), not on p.
    lo, hi = wilson_interval(3, 7)
    assert (lo + hi) / 2 == pytest.approx((3 / 7 + Z2 / 14) / (1 + Z2 / 7), abs=1e-12)
    # The bounds at k = 0 and k = n are exactly 0 and 1 (computed, they come out as
    # -1.4e-17 for 0/21 and 0.9999999999999999 for 10/10).
    assert wilson_interval(0, 21)[0] == 0.0 and wilson_interval(10, 10)[1] == 1.0
    assert all(math.isnan(x) for x in wilson_interval(0, 0))
    with pytest.raises(ValueError):
        wilson_interval(3, 2)


def test_rate_text_and_empty_rate():
    assert Rate(52, 57).text() == "52/57 = 91.2% [81.1, 96.2]"
    assert Rate(0, 1).text() == "0/1 = 0.0% [0.0, 79.3]"
    assert Rate(0, 0).text() == "—"
    assert math.isnan(Rate(0, 0).rate)


def step(ok: bool, **kw) -> dict:
    return {"success": ok, "extracted": ok, "others_still": True, **kw}


def episode(condition: str, ok: bool, steps: list[dict], n_dist: int, dist_m: float) -> dict:
    return {
        "condition": condition,
        "success": ok,
        "steps": steps,
        "n_disturbed": n_dist,
        "disturbance_m": dist_m,
    }


RECORDS = [
    episode("b", True, [step(True), step(True), step(False)], 1, 0.010),
    episode("a", False, [step(False)], 2, 0.030),
    episode("b", False, [step(True)], 0, 0.002),
    episode("b", True, [step(True), step(True)], 3, 0.006),
]


def test_aggregate_pools_steps_and_keeps_the_order_of_first_appearance():
    frame = aggregate(RECORDS)
    assert list(frame["condition"]) == ["b", "a"]
    b = frame.iloc[0]
    assert (b["episodes"], b["success_k"], b["success_n"]) == (3, 2, 3)
    # steps pooled over episodes: 2 + 1 + 2 successes out of 3 + 1 + 2
    assert (b["step_success_k"], b["step_success_n"]) == (5, 6)
    assert b["step_success_rate"] == pytest.approx(5 / 6)
    # per step: the episode-cluster bootstrap, not Wilson (steps of an episode go together)
    assert (b["step_success_lo"], b["step_success_hi"]) == pytest.approx(
        cluster_bootstrap_interval([(2, 3), (1, 1), (2, 2)])
    )
    assert b["mean_steps"] == pytest.approx(2.0)
    assert b["mean_n_disturbed"] == pytest.approx(4 / 3)
    assert b["mean_disturbance_m"] == pytest.approx(0.006)
    a = frame.iloc[1]
    assert (a["success_k"], a["step_success_k"], a["step_success_n"]) == (0, 0, 1)
    assert (a["success_lo"], a["success_hi"]) == pytest.approx(wilson_interval(0, 1))
    assert "strict_success_k" not in frame.columns
    # a group without steps: its step counts are missing, the others' stay integers
    frame = aggregate([*RECORDS, {"condition": "c", "success": True}])
    c = frame.iloc[2]
    assert c["condition"] == "c" and c["step_success_k"] is pd.NA and c["success_k"] == 1
    assert str(frame["step_success_k"].dtype) == "Int64"


def test_aggregate_leaves_out_the_columns_of_fields_no_record_has():
    records = [{"condition": "x", "success": True}, {"condition": "x", "success": False}]
    frame = aggregate(records)
    assert list(frame.columns) == [
        "condition",
        "episodes",
        "success_k",
        "success_n",
        "success_rate",
        "success_lo",
        "success_hi",
    ]
    records = [r | {"strict_success": r["success"], "planner": "p"} for r in records]
    frame = aggregate(records, group_by="planner")
    assert list(frame["planner"]) == ["p"]
    assert (frame.iloc[0]["strict_success_k"], frame.iloc[0]["strict_success_n"]) == (1, 2)


def test_rate_and_step_rate_count_named_booleans():
    assert rate(RECORDS, "success") == Rate(2, 4)
    assert step_rate(RECORDS) == Rate(5, 7)
    assert step_rate(RECORDS, "extracted") == Rate(5, 7)


def test_bad_records_fail_with_a_message_naming_the_record():
    with pytest.raises(ClutterbenchError, match="episode 4.*'success' must be true or false"):
        rate([{"condition": "c", "episode": 4, "success": 1}], "success")
    mixed = [RECORDS[0], {"condition": "b", "success": True}]
    with pytest.raises(ClutterbenchError, match="1 of 2 have 'steps'"):
        aggregate(mixed)
    with pytest.raises(ClutterbenchError, match="has no 'condition'"):
        aggregate([{"success": True}])


def test_cluster_bootstrap_resamples_whole_episodes():
    # Every episode is all-success or all-failure: resampling episodes can only give rates
    # that are shares of whole episodes' steps, never a step-level mix (10 of 20 steps in
    # one episode move together).
    per = [(10, 10), (0, 10)]
    lo, hi = cluster_bootstrap_interval(per, resamples=500, seed=1)
    assert lo == 0.0 and hi == 1.0
    assert cluster_bootstrap_interval(per, 500, 1) == (lo, hi)  # seeded: reproducible
    # With steps clustered in episodes the interval is wider than Wilson's on pooled steps.
    many = [(3, 3)] * 30 + [(0, 3)] * 10
    blo, bhi = cluster_bootstrap_interval(many)
    wlo, whi = wilson_interval(90, 120)
    assert bhi - blo > whi - wlo
    assert blo < 0.75 < bhi
    assert all(np.isnan(cluster_bootstrap_interval([(0, 0)])))


def test_aborts_that_moved_nothing_are_not_judged_steps():
    judged = {"executed": True, "aborted_before_motion": False, "aborted_after_motion": False}
    ok = judged | {"success": True, "extracted": True, "others_still": True}
    abort = {
        "executed": False,
        "aborted_before_motion": True,
        "aborted_after_motion": False,
        "success": False,
        "extracted": False,
        "others_still": True,
    }
    recs = [episode("c", True, [abort, ok], 0, 0.0)]
    row = aggregate(recs).iloc[0]
    assert (row["step_success_k"], row["step_success_n"]) == (1, 1)
    assert row["aborts"] == 1 and row["aborts_before_motion"] == 1


def test_per_step_rates_read_the_counted_flag_and_the_old_judged_one():
    base = {"aborted_before_motion": False, "extracted": False, "others_still": True}
    ok = base | {"executed": True, "extracted": True, "success": True}
    # an abort after motion that collapsed nothing: judged from physics, not counted
    abort = base | {"executed": True, "aborted_after_motion": True, "success": None}
    new = abort | {"judged": True, "counted": False, "strict_counted": False}
    old = abort | {"judged": False, "strict_judged": False}  # before the rename
    for step in (new, old):
        recs = [episode("c", True, [step, ok | {"aborted_after_motion": False}], 0, 0.0)]
        row = aggregate(recs).iloc[0]
        assert (row["step_success_k"], row["step_success_n"]) == (1, 1)
        assert row["aborts"] == 1
