"""The ch. 4 sensed-training recheck: its networks differ only in their training sensor, its
trials are Table 4.1's sensed rows on dev streams beside the oracle, and its finding comes
from the paired numbers."""

from __future__ import annotations

import pytest

from clutterbench.config import load_params, load_section, parse
from clutterbench.errors import ClutterbenchError
from experiments.ch4_sensing import (
    LABEL,
    comparisons_of,
    markdown,
    summary_rows,
    trial_jobs,
    what_it_shows,
    with_training_sensing,
)
from experiments.config import DevConfig, with_dev

PILE = {"families": {"pile": 1}, "n_objects": [10, 10], "catalogue": "various"}
CPU = {"cpu_model": "X", "torch_cpu_capability": "AVX2", "cpu_flags": {}, "torch_threads": 2}


def test_its_streams_must_be_dev_streams():
    with pytest.raises(ClutterbenchError, match="ch4_sensing.streams: unknown dev stream .dev_b."):
        parse(
            DevConfig,
            {
                "streams": {"dev_a": PILE},
                "ch4_piles": {"streams": ["dev_a"]},  # its defaults name other streams
                "ch4_sensing": {"streams": ["dev_b"]},
            },
            "dev",
        )


def test_a_candidate_changes_only_the_training_sensor(root):
    params = load_params(root / "params.yaml")
    before = repr(params)
    sensed = with_training_sensing(params, "d415")
    assert repr(params) == before  # the params given are left as they were
    assert sensed["train"]["sensing"]["preset"] == "d415"
    assert sensed["train"]["sensing"]["spread"] == params["train"]["sensing"]["spread"]
    rest = {k: v for k, v in sensed["train"].items() if k != "sensing"}
    assert rest == {k: v for k, v in params["train"].items() if k != "sensing"}


def test_trials_are_the_sensed_rows_on_dev_streams_beside_the_oracle(root):
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    dev = load_section(DevConfig, "dev", params)
    cfg = dev.ch4_sensing
    candidates = [{LABEL: "ideal", "checkpoint": "a/best.pt"}, {LABEL: "d415", "checkpoint": "b"}]
    jobs = trial_jobs(candidates, dev, params)
    assert len(jobs) == len(cfg.streams) * (len(candidates) + cfg.oracle) * cfg.episodes
    for job in jobs:
        label, stream = job.condition.split("/")
        assert stream in cfg.streams and job.stream_cfg == dev.streams[stream]
        if label == "oracle":  # reads the world: no sensor
            assert job.cond.planner == "oracle" and job.cond.sensing == "ideal"
            continue
        assert (job.cond.planner, job.cond.model) == ("risk", cfg.model)
        assert (job.cond.perception, job.cond.sensing) == ("depth", cfg.sensing)
        assert str(job.model_path) == ("a/best.pt" if label == "ideal" else "b")


def _records(label: str, wins: list[bool]) -> list[dict]:
    return [
        {"condition": f"{label}/dev_a", "episode": e, "success": w, "strict_success": w}
        | {"n_disturbed": 0 if w else 2}
        for e, w in enumerate(wins)
    ]


def _eight_episodes_on_dev_a() -> DevConfig:
    return parse(
        DevConfig,
        {
            "streams": {"dev_a": PILE},
            "ch4_piles": {"streams": ["dev_a"]},
            "ch4_sensing": {"streams": ["dev_a"], "episodes": 8},
        },
        "dev",
    )


@pytest.mark.parametrize(
    ("ideal_wins", "d415_wins", "finding"),
    [
        ([False] * 8, [True] * 8, "favour training on d415"),
        ([True] * 8, [False] * 8, "favour training on ideal"),
        ([True] * 3 + [False] * 5, [True] * 4 + [False] * 4, "no dev-stream rate beyond chance"),
    ],
)
def test_the_finding_follows_the_paired_numbers(ideal_wins, d415_wins, finding):
    dev = _eight_episodes_on_dev_a()
    records = _records("ideal", ideal_wins) + _records("d415", d415_wins)
    records += _records("oracle", [True] * 8)
    rows = summary_rows(records, dev, LABEL)
    comparisons = comparisons_of(records, dev.ch4_sensing, "ideal")
    assert {c[LABEL] for c in comparisons} == {"d415"}
    shows = what_it_shows(comparisons, rows, "ideal")
    assert finding in shows and "Below the oracle on dev_a" in shows
    text = markdown(
        {
            "scale": "tiny",
            "config": {"model": "ch4_various", "episodes": 8, "sensing": "d415"},
            "dataset": "ch4_various",
            "n_scenes": 3,
            "current": "ideal",
            "candidates": [],
            "rows": rows,
            "comparisons": comparisons,
            "shows": shows,
            "network_precision": "fp32",
            "cpu": CPU,
            "seconds": 60.0,
            "trials_seconds": 30.0,
        }
    )
    assert "## Trials under d415" in text and f"**What it shows.** {shows}" in text
    assert "| dev_a | success | d415 |" in text


def _toy_episode(job):
    """An episode that wins on even episodes for d415 only: a known paired difference."""
    from clutterbench.trials.core.harness import EpisodeLog, EpisodeResult

    label, e = job
    win = label.startswith("d415") and e % 2 == 0
    record = {"condition": label, "episode": e, "success": win, "strict_success": win}
    return EpisodeResult(record, EpisodeLog())


def test_the_recheck_runs_its_episodes_and_pairs_them_against_the_params_preset(root, tmp_path):
    from experiments.ch4_sensing import run_and_pair

    params = load_params(root / "params.yaml")
    params["trials"]["workers"] = 1
    dev = _eight_episodes_on_dev_a()
    jobs = [(f"{t}/dev_a", e) for t in ("ideal", "d415") for e in range(8)]
    records, seconds, against, comparisons = run_and_pair(
        "toy", _toy_episode, jobs, dev.ch4_sensing, params, tmp_path
    )
    assert against == params["train"]["sensing"]["preset"] == "ideal" and seconds >= 0
    assert [r["episode"] for r in records] == [e for _ in range(2) for e in range(8)]
    assert (tmp_path / "records.jsonl").read_text().count("\n") == 16
    success = next(c for c in comparisons if c["criterion"] == "success")
    assert (success[LABEL], success[f"only_{LABEL}"], success["only_against"]) == ("d415", 4, 0)
