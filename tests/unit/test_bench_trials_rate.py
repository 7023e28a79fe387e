"""The trials_rate bench part's report (bench/trials_rate.py): conditions ranked by their
extrapolated minutes, planners summed, committed steps beside the sample's."""

from __future__ import annotations

import json

import pytest

from clutterbench.bench.trials_rate import _episodes, committed_steps, markdown
from clutterbench.errors import ClutterbenchError


def _row(name, planner, per, episodes=200, steps=(1, 2)):
    return {
        "condition": name,
        "planner": planner,
        "sensing": "ideal",
        "episodes_sampled": len(steps),
        "episodes_stage": episodes,
        "wall_s_per_episode": per,
        "cpu_s_per_episode": per,
        "steps": list(steps),
        "stage_min_one_core": round(per * episodes / 60.0, 2),
    }


def test_the_report_ranks_conditions_and_sums_planners(tmp_path):
    rows = [_row("a", "p", 0.3), _row("b", "q", 6.0), _row("c", "p", 0.9)]
    (tmp_path / "trials" / "b").mkdir(parents=True)
    (tmp_path / "trials" / "b" / "records.jsonl").write_text(
        "\n".join(
            json.dumps({"condition": "b", "episode": i, "steps": [0] * n})
            for i, n in enumerate((2, 3, 4))
        )
        + "\n"
    )
    committed_steps(rows, tmp_path)
    assert rows[1]["committed_steps"] == [2, 3] and rows[0]["committed_steps"] is None
    res = {
        "machine": {"cpu_model": "CPU", "cpu_family": 25, "cpu_model_number": 17},
        "scale": "default",
        "precision": "bf16",
        "episodes_per_condition": 2,
        "workers": 2,
        "conditions": rows,
        "stage_min_one_core": 24.0,
        "stage_min_wall": 12.0,
    }
    md = markdown(res)
    lines = md.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("| b |"))
    assert first < next(i for i, line in enumerate(lines) if line.startswith("| c |"))
    assert "| 3 / 5 | 20.0 | 83.3 % |" in lines[first]
    assert "| p | 4.0 | 16.7 % |" in md and "**24.0 min on one core, 12.0 min over 2" in md


def test_the_episodes_knob_is_checked(monkeypatch):
    monkeypatch.setenv("CLUTTERBENCH_TRIALS_RATE_EPISODES", "0")
    with pytest.raises(ClutterbenchError, match="integer >= 1"):
        _episodes()
    monkeypatch.setenv("CLUTTERBENCH_TRIALS_RATE_EPISODES", "5")
    assert _episodes() == 5
