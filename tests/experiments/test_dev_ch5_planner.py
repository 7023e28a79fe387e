"""The ch. 5 planner recheck on dev streams: its params, its jobs (each variant on dev
streams only, its trials.ch5 fields reaching the planner), and the paired report from
records."""

from __future__ import annotations

import pytest

import clutterbench.trials.ch5.episodes as ch5
from clutterbench.config import load_params, load_section, parse
from clutterbench.errors import ClutterbenchError
from clutterbench.trials.config import TrialsConfig
from experiments.ch5_planner import (
    comparisons,
    current_variant,
    markdown,
    summary_rows,
    trial_jobs,
    what_it_shows,
)
from experiments.config import DevConfig, with_dev

SHELVED = {"families": {"replenish_shelved": 1}, "n_objects": [4, 6], "catalogue": "various"}


V = {"a": {"blocker_goal": "eq_5_6"}, "b": {"blocker_goal": "candidate"}}


def _dev(**planner):
    return {"streams": {"dev_a": SHELVED}, "ch5_planner": {"streams": ["dev_a"]} | planner}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            {"streams": {"dev_a": SHELVED}, "ch5_planner": {"streams": ["dev_b"], "variants": V}},
            "unknown dev stream",
        ),
        (_dev(variants={"a": {"blocker_goal": "eq_5_6"}}), "two or more variants"),
        (_dev(variants=V | {"c": {"blocker_goal": "far"}}), r"variants\.c\.blocker_goal: .far."),
        (_dev(variants=V | {"c": {"finger_m": 0.02}}), r"variants\.c\.finger_m: a variant sets"),
        (_dev(variants=V, perceptions=[]), "no perception"),
        (_dev(variants=V, planners=[]), "no planner"),
        (_dev(variants=V, planners=["replenish", "oracle"]), r"planners.*oracle"),
    ],
)
def test_bad_ch5_planner_params_are_one_line(data, message):
    with pytest.raises(ClutterbenchError, match=message) as info:
        parse(DevConfig, data, "dev")
    assert "\n" not in str(info.value)


def test_jobs_run_each_variant_on_dev_streams_only(root, monkeypatch):
    monkeypatch.setattr(ch5, "check_models", lambda conds, params: None)
    monkeypatch.setattr(ch5, "collapse_threshold", lambda params: 0.5)
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    dev = load_section(DevConfig, "dev", params)
    cfg = dev.ch5_planner
    assert len(cfg.variants) >= 2
    jobs = trial_jobs(dev, params)
    assert "contact" in cfg.planners
    arms = len(cfg.planners) * len(cfg.perceptions) + cfg.oracle
    assert len(jobs) == len(cfg.streams) * len(cfg.variants) * arms * cfg.episodes
    seen = set()
    for job in jobs:
        label, stream = job.condition.split("/")
        variant, planner, perception = label.split(":")
        seen.add((stream, variant, planner))
        assert stream in cfg.streams and stream.startswith("dev_") and job.cond.stream == stream
        assert job.stream_cfg == dev.streams[stream] and not job.record_images
        rp = ch5.planner_params(job)
        for key, value in cfg.variants[variant].items():
            assert getattr(job.params, key) == value and getattr(rp, key) == value
        assert (job.cond.planner, job.cond.perception) == (planner, perception)
    assert {v for _, v, _ in seen} == set(cfg.variants)
    assert {p for _, _, p in seen} == set(cfg.planners) | {"oracle"}
    assert current_variant(cfg.variants, load_section(TrialsConfig, "trials", params).ch5)


def _records(label: str, stream: str, wins: list[bool]) -> list[dict]:
    return [
        {
            "condition": f"{label}/{stream}",
            "episode": i,
            "success": w,
            "strict_success": w,
            "end": "placed" if w else "gave_up",
        }
        for i, w in enumerate(wins)
    ]


def test_rows_comparisons_and_report_from_records():
    wins = {
        "thesis:replenish:clusters": [True, False, False, False],
        "mine:replenish:clusters": [True, True, True, False],
        "thesis:oracle:clusters": [True] * 4,
        "mine:oracle:clusters": [True] * 3 + [False],
        "thesis:contact:clusters": [True, True, False, False],
        "mine:contact:clusters": [True, True, True, False],
    }
    records = [r for label, w in wins.items() for r in _records(label, "dev_a", w)]
    rows = summary_rows(records)
    below = {(r["variant"], r["planner"]): r["success_below_oracle_points"] for r in rows}
    assert below[("thesis", "replenish")] == 75.0  # against its own variant's oracle
    assert below[("mine", "replenish")] == 0.0
    assert below[("thesis", "oracle")] is None
    assert [r["gave_up"] for r in rows] == [3, 1, 0, 1, 2, 1]
    comps = comparisons(records, ["thesis", "mine"], ["dev_a"], ["replenish", "contact"])
    planner = [c for c in comps if c["arm"] == "replenish:clusters" and c["criterion"] == "success"]
    assert planner[0]["only_piles"] == 2 and planner[0]["only_against"] == 0
    assert planner[0]["difference_points"] == 50.0
    push = {
        c["name"]: c
        for c in comps
        if c["criterion"] == "success" and c["other"].endswith(":replenish")
    }
    assert set(push) == {"thesis:contact", "mine:contact"}
    assert (push["thesis:contact"]["only_piles"], push["thesis:contact"]["only_against"]) == (1, 0)
    assert push["mine:contact"]["only_piles"] == push["mine:contact"]["only_against"] == 0
    shows = what_it_shows(comps)
    assert "mine against thesis, success: 3 episodes won only by it, 1 lost" in shows
    assert "thesis:contact against thesis:replenish, success: 1 episodes won only by it" in shows
    result = {
        "scale": "tiny",
        "config": {"episodes": 4, "variants": {"thesis": {"blocker_goal": "eq_5_6"}}},
        "current": "mine",
        "rows": rows,
        "comparisons": comps,
        "shows": shows,
        "n_trials": len(records),
        "seconds": 6.0,
    }
    text = markdown(result)
    assert "| dev_a | mine | replenish | clusters | 3/4" in text
    assert "| dev_a | replenish:clusters | success | mine vs thesis | 2 | 0 | +50.0 |" in text
    row = "| dev_a | clusters | success | thesis:contact vs thesis:replenish | 1 | 0 | +25.0 |"
    assert row in text
    assert "`thesis`: blocker_goal eq_5_6" in text
