"""The ch. 5 blocker-goal recheck on dev streams: its params, its jobs (each rule on dev
streams only, the rule reaching the planner), and the paired report from records."""

from __future__ import annotations

import pytest

import clutterbench.trials.ch5 as ch5
from clutterbench.config import load_params, load_section, parse
from clutterbench.dev.ch5_goal import comparisons, markdown, summary_rows, trial_jobs, what_it_shows
from clutterbench.dev.config import DevConfig
from clutterbench.errors import ClutterbenchError

SHELVED = {"families": {"replenish_shelved": 1}, "n_objects": [4, 6], "catalogue": "various"}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"streams": {"dev_a": SHELVED}, "ch5_goal": {"streams": ["dev_b"]}}, "unknown dev stream"),
        (
            {
                "streams": {"dev_a": SHELVED},
                "ch5_goal": {"streams": ["dev_a"], "goals": ["eq_5_6"]},
            },
            "two different rules",
        ),
        (
            {"streams": {"dev_a": SHELVED}, "ch5_goal": {"streams": ["dev_a"], "goals": ["far"]}},
            "goals",
        ),
    ],
)
def test_bad_ch5_goal_params_are_one_line(data, message):
    with pytest.raises(ClutterbenchError, match=message) as info:
        parse(DevConfig, data, "dev")
    assert "\n" not in str(info.value)


def test_jobs_run_each_rule_on_dev_streams_only(root, monkeypatch):
    monkeypatch.setattr(ch5, "check_models", lambda conds, params: None)
    monkeypatch.setattr(ch5, "collapse_threshold", lambda params: 0.5)
    params = load_params(root / "params.yaml")
    params["base"]["scale"] = "tiny"
    dev = load_section(DevConfig, "dev", params)
    cfg = dev.ch5_goal
    jobs = trial_jobs(dev, params)
    arms = len(cfg.perceptions) + cfg.oracle
    assert len(jobs) == len(cfg.streams) * len(cfg.goals) * arms * cfg.episodes
    seen = set()
    for job in jobs:
        label, stream = job["condition"].split("/")
        goal, planner, perception = label.split(":")
        seen.add((stream, goal, planner))
        assert stream in cfg.streams and stream.startswith("dev_") and job["cond"].stream == stream
        assert job["stream_cfg"] == dev.streams[stream] and not job["record_images"]
        assert job["params"].blocker_goal == goal
        assert ch5.planner_params(job).blocker_goal == goal
        assert (job["cond"].planner, job["cond"].perception) == (planner, perception)
    assert {g for _, g, _ in seen} == set(cfg.goals)
    assert {p for _, _, p in seen} == {"replenish", "oracle"}


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
        "eq_5_6:replenish:clusters": [True, False, False, False],
        "candidate:replenish:clusters": [True, True, True, False],
        "eq_5_6:oracle:clusters": [True] * 4,
        "candidate:oracle:clusters": [True] * 3 + [False],
    }
    records = [r for label, w in wins.items() for r in _records(label, "dev_a", w)]
    rows = summary_rows(records)
    below = {(r["goal"], r["planner"]): r["success_below_oracle_points"] for r in rows}
    assert below[("eq_5_6", "replenish")] == 75.0  # against its own rule's oracle
    assert below[("candidate", "replenish")] == 0.0
    assert below[("eq_5_6", "oracle")] is None
    assert [r["gave_up"] for r in rows] == [3, 1, 0, 1]
    comps = comparisons(records, ["eq_5_6", "candidate"], ["dev_a"])
    planner = [c for c in comps if c["arm"] == "replenish:clusters" and c["criterion"] == "success"]
    assert planner[0]["only_piles"] == 2 and planner[0]["only_against"] == 0
    assert planner[0]["difference_points"] == 50.0
    shows = what_it_shows(comps)
    assert "candidate against eq_5_6, success: 2 episodes won only by it, 1 lost" in shows
    result = {
        "scale": "tiny",
        "config": {"episodes": 4},
        "current": "candidate",
        "rows": rows,
        "comparisons": comps,
        "shows": shows,
        "n_trials": len(records),
        "seconds": 6.0,
    }
    text = markdown(result)
    assert "| dev_a | candidate | replenish | clusters | 3/4" in text
    assert "| dev_a | replenish:clusters | success | candidate vs eq_5_6 | 2 | 0 | +50.0 |" in text
