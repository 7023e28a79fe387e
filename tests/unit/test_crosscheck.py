"""The cross-check's statistics against hand-computed values, and its pass / fail rows."""

from __future__ import annotations

import copy

import pytest

from clutterbench.crosscheck import (
    DIGESTED,
    byte_identity,
    compare,
    table,
    two_mean_p,
    two_proportion_p,
    wilson_interval,
)


def test_wilson_interval_by_hand():
    # 8/10: centre (0.8 + 1.96^2/20) / (1 + 1.96^2/10) = 0.7167,
    # half 1.96 sqrt(0.016 + 1.96^2/400) / 1.3841 = 0.2266
    lo, hi = wilson_interval(8, 10)
    assert (lo, hi) == (pytest.approx(0.4902, abs=1e-4), pytest.approx(0.9433, abs=1e-4))
    assert wilson_interval(0, 10)[0] == 0.0


def test_two_proportion_p_by_hand():
    # 10/100 vs 20/100: pooled 0.15, se sqrt(0.15 * 0.85 * 0.02) = 0.0505, z = 1.980,
    # two-sided p = 2 (1 - Phi(1.980)) = 0.0477
    assert two_proportion_p(10, 100, 20, 100) == pytest.approx(0.0477, abs=2e-4)
    assert two_proportion_p(20, 100, 10, 100) == two_proportion_p(10, 100, 20, 100)
    # 80/200 vs 40/200: pooled 0.3, se 0.0458, z = 4.364, p = 1.3e-5
    assert two_proportion_p(80, 200, 40, 200) == pytest.approx(1.28e-5, rel=0.05)
    assert two_proportion_p(5, 50, 10, 100) == 1.0  # the same share
    assert two_proportion_p(0, 50, 0, 80) == 1.0  # never seen on either machine


def test_two_mean_p_by_hand():
    # 7.5 vs 7.0, SD 1.7, n 100 each: se = 1.7 sqrt(0.02) = 0.2404, z = 2.080, p = 0.0375
    assert two_mean_p(7.5, 1.7, 100, 7.0, 1.7, 100) == pytest.approx(0.0375, abs=2e-4)
    assert two_mean_p(5.0, 0.0, 10, 5.0, 0.0, 10) == 1.0
    assert two_mean_p(5.0, 0.0, 10, 6.0, 0.0, 10) == 0.0


def measurement() -> dict:
    return {
        "dataset": {
            "n_scenes": 100,
            "families": {"random": 100},
            "rejected": {"fell": 10, "overlap": 0},
            "attempts": 110,
            "n_objects": {"mean": 7.5, "sd": 1.7, "n": 100},
        },
        "trials": {"multi_step": {"k": 80, "n": 200}, "oracle": {"k": 150, "n": 200}},
        "digests": {p: "d" for p in DIGESTED},
        "run": {"environment": {"cpu_model": "A", "torch_threads": 2}},
    }


def test_identical_results_pass_every_row():
    rows = compare(measurement(), measurement())
    # family random, rejected fell / overlap, objects mean, two trial conditions
    assert len(rows) == 6 and all(r.passed and r.p == 1.0 for r in rows)
    assert "80/200 = 40.0%" in rows[-2].expected
    assert "PASS" not in table(rows) and "FAIL" not in table(rows)


def test_a_halved_success_rate_fails_its_row_only():
    got = measurement()
    got["trials"]["multi_step"]["k"] = 40  # p = 1.3e-5 < 0.01 / 6
    rows = {r.name: r for r in compare(measurement(), got)}
    assert not rows["trials multi_step episode success"].passed
    assert sum(not r.passed for r in rows.values()) == 1
    assert "FAIL" in table(list(rows.values()))


def test_rows_fail_below_alpha_over_the_number_of_rows():
    # rejected 'fell' 10/110 vs 20/120 attempts: pooled 30/230 = 0.1304,
    # se sqrt(0.1304 * 0.8696 * (1/110 + 1/120)) = 0.0445, z = (0.1667 - 0.0909) / 0.0445
    # = 1.704, p = 2 (1 - Phi(1.704)) = 0.088
    got = measurement()
    got["dataset"]["rejected"]["fell"] = 20
    got["dataset"]["attempts"] = 120
    assert two_proportion_p(10, 110, 20, 120) == pytest.approx(0.088, abs=0.002)
    fell = "ch6_test rejected 'fell' / attempts"
    at_1pct = {r.name: r for r in compare(measurement(), got, alpha=0.01)}
    assert at_1pct[fell].passed  # p >= 0.01 / 6
    at_60pct = {r.name: r for r in compare(measurement(), got, alpha=0.6)}
    assert not at_60pct[fell].passed  # p < 0.6 / 6 = 0.1
    assert all(r.passed for n, r in at_60pct.items() if n != fell)


def test_byte_identity_names_the_outputs_that_differ():
    e, g = measurement(), copy.deepcopy(measurement())
    assert byte_identity(e, g) == {
        "byte_identical": True,
        "differing_outputs": [],
        "same_cpu_model_and_threads": True,
    }
    g["digests"][DIGESTED[0]] = "other"
    g["run"]["environment"]["cpu_model"] = "B"
    ident = byte_identity(e, g)
    assert not ident["byte_identical"] and ident["differing_outputs"] == [DIGESTED[0]]
    assert not ident["same_cpu_model_and_threads"]
