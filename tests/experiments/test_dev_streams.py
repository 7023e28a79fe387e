"""Dev streams and the ch. 4 training-pile recheck: dev streams never share a table's
scenes, the paired test, the finding in words, and the reuse of data and networks."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from clutterbench.config import load_params, load_section, parse
from clutterbench.data.trial_scenes import stream_key
from clutterbench.errors import ClutterbenchError
from clutterbench.io import save_npz, write_json
from clutterbench.trials.config import TrialsConfig
from experiments.ch4_piles import (
    candidate_network,
    made_with,
    markdown,
    summary_rows,
    trial_jobs,
    what_it_shows,
)
from experiments.check import check_experiments
from experiments.config import DevConfig, check_dev_streams, with_dev
from experiments.stats import mcnemar_p, paired, paired_cells
from tests.toy_params import toy_train_params

PILE = {"families": {"pile": 1}, "n_objects": [5, 5], "catalogue": "various"}


@pytest.mark.parametrize("scale", ["tiny", "default", "paper"])
def test_repo_dev_streams_share_no_scenes_with_the_tables(root, scale):
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = scale
    dev = load_section(DevConfig, "dev", params)
    trials = load_section(TrialsConfig, "trials", params)
    check_dev_streams(dev, trials)
    assert dev.streams and all(name.startswith("dev_") for name in dev.streams)
    table_keys = {stream_key(s) for s in trials.streams} | {stream_key("support")}
    assert not {stream_key(s) for s in dev.streams} & table_keys
    for group in ("conditions", "ch4_conditions", "ch5_conditions"):
        assert not {c.stream for c in getattr(trials, group).values()} & set(dev.streams)


def test_no_stage_reads_the_dev_section(root):
    stages = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    for name, stage in stages.items():
        for entry in stage.get("params", []):
            keys = entry if isinstance(entry, dict) else {entry: None}
            assert not any(str(k).split(".")[0] == "dev" for k in keys), name


def test_a_table_condition_cannot_run_on_a_dev_stream(root):
    params = with_dev(load_params(root / "params.yaml"))
    params["trials"]["ch4_conditions"]["x"] = {"planner": "oracle", "stream": "dev_ch4_10"}
    with pytest.raises(ClutterbenchError, match="unknown stream 'dev_ch4_10'"):
        load_section(TrialsConfig, "trials", params)


def test_a_table_stream_named_like_a_dev_stream_is_refused():
    trials = parse(TrialsConfig, {"streams": {"dev_x": PILE}}, "trials")
    dev = parse(DevConfig, {"streams": {"dev_ch4_10": PILE, "dev_ch4_5": PILE}}, "dev")
    with pytest.raises(ClutterbenchError, match=r"trials\.streams\.dev_x: a table stream"):
        check_dev_streams(dev, trials)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"streams": {"ch4_same_10": PILE}}, "streams.ch4_same_10: a dev stream's name starts"),
        ({"streams": {"dev_a": PILE}, "ch4_piles": {"streams": ["dev_b"]}}, "unknown dev stream"),
        (
            {
                "streams": {"dev_a": PILE},
                "ch4_piles": {"streams": ["dev_a"], "pile_ranges": [[6, 6]]},
            },
            "two or more different ranges",
        ),
        (
            {
                "streams": {"dev_a": PILE},
                "ch4_piles": {"streams": ["dev_a"], "pile_ranges": [[6, 5], [5, 10]]},
            },
            r"\[6, 5\] is not a range",
        ),
    ],
)
def test_bad_dev_params_are_one_line(data, message):
    with pytest.raises(ClutterbenchError, match=message) as info:
        parse(DevConfig, data, "dev")
    assert "\n" not in str(info.value)


def test_mcnemar_exact_by_hand():
    assert mcnemar_p(0, 0) == 1.0
    assert mcnemar_p(5, 0) == pytest.approx(2 / 32)  # 2 * (1/2)^5
    assert mcnemar_p(0, 6) == pytest.approx(2 / 64)
    assert mcnemar_p(3, 1) == pytest.approx(2 * (1 + 4) / 16)
    assert mcnemar_p(4, 4) == 1.0


def test_a_tiny_p_keeps_its_digits_in_the_dev_table():
    cells = paired_cells(
        {"only_piles": 34, "only_against": 87, "difference_points": -8.8, "p": mcnemar_p(34, 87)}
    )
    assert cells == "34 | 87 | -8.8 | 1.6e-06 |"  # printed as 0.000 before


def _records(label: str, stream: str, wins: list[bool]) -> list[dict]:
    return [
        {"condition": f"{label}/{stream}", "episode": e, "success": w, "strict_success": w}
        for e, w in enumerate(wins)
    ]


def _rows(stream: str, gaps: dict[str, float]) -> list[dict]:
    return [
        {
            "stream": stream,
            "piles": p,
            "n_objects": [10, 10],
            "success_below_oracle_points": g,
            "strict_success_below_oracle_points": g,
        }
        for p, g in gaps.items()
    ]


@pytest.mark.parametrize(
    ("six", "ours", "finding"),
    [
        ([True] * 20, [True] * 20, "no evidence for 5-10 over 6-6, nor against it"),
        ([True] * 20, [False] * 12 + [True] * 8, "the dev streams favour 6-6 over 5-10"),
        ([False] * 12 + [True] * 8, [True] * 20, "the dev streams support 5-10 over 6-6"),
    ],
)
def test_the_finding_is_computed_from_the_paired_outcomes(six, ours, finding):
    records = _records("6-6", "dev_ch4_10", six) + _records("5-10", "dev_ch4_10", ours)
    comparisons = [paired(records, "6-6", "5-10", "dev_ch4_10", k) for k in ("success",)]
    c = comparisons[0]
    assert c["only_piles"] == sum(a and not b for a, b in zip(six, ours))
    assert c["difference_points"] == pytest.approx(100 * (sum(six) - sum(ours)) / 20)
    shows = what_it_shows(comparisons, _rows("dev_ch4_10", {"6-6": 3.0, "5-10": 7.0}), "5-10")
    assert finding in shows
    assert "Below the oracle on dev_ch4_10 (success / strict, points): 6-6 3 / 3, 5-10 7 / 7" in (
        shows
    )


def test_paired_refuses_different_episodes():
    records = _records("6-6", "dev_a", [True] * 3) + _records("5-10", "dev_a", [True] * 2)
    with pytest.raises(ClutterbenchError, match="ran different episodes"):
        paired(records, "6-6", "5-10", "dev_a", "success")


def test_made_with_checks_every_shard(tmp_path):
    d = tmp_path / "ch4_various"
    for s in range(2):
        save_npz(d / f"shard-{s:05d}.npz", {"config_hash": np.array("abc")})
    write_json(
        d / "manifest.json",
        {"config_hash": "abc", "shards": ["shard-00000.npz", "shard-00001.npz"]},
    )
    assert made_with(d, "abc")
    assert not made_with(d, "abd") and not made_with(tmp_path / "nothing", "abc")
    save_npz(d / "shard-00001.npz", {"config_hash": np.array("old")})
    assert not made_with(d, "abc")
    (d / "shard-00001.npz").unlink()
    assert not made_with(d, "abc")


PARAMS = toy_train_params(8)


def test_a_network_is_reused_only_for_the_same_data_and_training(tmp_path):
    from clutterbench.data.synthetic import write_synthetic_dataset

    gen = tmp_path / "generate"
    write_synthetic_dataset(gen, "toy", 8, 4, 32, (2, 4))
    first = candidate_network("m", PARAMS, gen, "h1", tmp_path / "piles")
    assert not first["network_reused"] and Path(first["checkpoint"]).exists()
    assert first["train_scenes"] == 6 and first["summary"]["epochs_run"] == 1
    again = candidate_network("m", PARAMS, gen, "h1", tmp_path / "piles")
    assert again["network_reused"] and again["summary"] == first["summary"]
    assert not candidate_network("m", PARAMS, gen, "h2", tmp_path / "piles")["network_reused"]


def test_trials_run_each_network_and_the_oracle_on_dev_streams_only(root):
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    dev = load_section(DevConfig, "dev", params)
    candidates = [
        {"piles": "6-6", "checkpoint": "a/best.pt"},
        {"piles": "5-10", "checkpoint": "b/best.pt"},
    ]
    jobs = trial_jobs(candidates, dev, params)
    cfg = dev.ch4_piles
    assert len(jobs) == len(cfg.streams) * (len(candidates) + cfg.oracle) * cfg.episodes
    for job in jobs:
        label, stream = job.condition.split("/")
        assert stream in cfg.streams and job.cond.stream == stream
        assert job.stream_cfg == dev.streams[stream] and not job.record_images
        if label == "oracle":
            assert job.cond.planner == "oracle" and job.model_path is None
        else:
            assert job.cond.planner == "risk" and job.cond.model == cfg.model
            assert str(job.model_path) == f"{'a' if label == '6-6' else 'b'}/best.pt"


def test_rows_and_report_from_records():
    dev = parse(
        DevConfig,
        {
            "streams": {"dev_a": {**PILE, "n_objects": [10, 10]}},
            "ch4_piles": {"streams": ["dev_a"]},
        },
        "dev",
    )
    wins = {"6-6": [True, True, False, False], "5-10": [True] * 3 + [False], "oracle": [True] * 4}
    records = [
        r | {"n_disturbed": 0 if r["success"] else 2}
        for label, w in wins.items()
        for r in _records(label, "dev_a", w)
    ]
    rows = summary_rows(records, dev)
    assert [r["piles"] for r in rows] == ["6-6", "5-10", "oracle"]
    assert [r["success_below_oracle_points"] for r in rows] == [50.0, 25.0, None]
    assert rows[0]["mean_n_disturbed"] == 1.0 and rows[0]["n_objects"] == [10, 10]
    comparisons = [
        paired(records, "6-6", "5-10", "dev_a", k) for k in ("success", "strict_success")
    ]
    result = {
        "scale": "tiny",
        "config": {"model": "ch4_various", "episodes": 4},
        "dataset": "ch4_various",
        "n_scenes": 3,
        "current": "5-10",
        "candidates": [],
        "rows": rows,
        "comparisons": comparisons,
        "shows": what_it_shows(comparisons, rows, "5-10"),
        "network_precision": "fp32",
        "cpu": {
            "cpu_model": "X",
            "torch_cpu_capability": "AVX2",
            "cpu_flags": {},
            "torch_threads": 2,
        },
        "seconds": 60.0,
        "trials_seconds": 30.0,
    }
    text = markdown(result)
    assert "| dev_a | 10 | various | 6-6 | 2/4 = 50.0% [15.0, 85.0] |" in text
    assert "| dev_a | success | 6-6 | 0 | 1 | -25.0 | 1 |" in text
    assert "**What it shows.** Training on piles of 6-6 instead of 5-10" in text


def test_the_dev_section_lives_in_experiments_and_passes_its_check(root):
    assert "dev" not in load_params(root / "params.yaml")  # no stage reads it
    assert check_experiments(root / "params.yaml", root / "experiments" / "params.yaml") == []


def test_the_experiments_check_finds_a_bad_recheck(root, tmp_path):
    raw = yaml.safe_load((root / "experiments" / "params.yaml").read_text())
    raw["dev"]["ch6_pull"]["planners"] = ["no_such_planner"]
    raw["dev"]["ch6_pull"]["streams"] = ["dev_nowhere"]
    raw["dev"]["streams"]["ch6_table_like"] = raw["dev"]["streams"]["dev_ch6_3_10"]
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(raw))
    found = "\n".join(check_experiments(root / "params.yaml", path))
    assert "dev.ch6_pull.planners" in found and "no_such_planner" in found
    assert "dev.ch6_pull.streams" in found and "dev_nowhere" in found
    assert "dev.streams.ch6_table_like: a dev stream's name starts with 'dev_'" in found


def test_nothing_in_the_package_or_the_stages_imports_experiments(root):
    files = [*(root / "src").rglob("*.py"), *(root / "stages").glob("*.py")]
    found = [
        p.relative_to(root).as_posix()
        for p in files
        if re.search(r"^\s*(from|import)\s+experiments\b", p.read_text(), re.M)
    ]
    assert not found
