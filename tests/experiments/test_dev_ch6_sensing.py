"""The ch. 6 sensed-training recheck: its trials are Table 6.3's sensed CP pull rows on dev
streams, each network with its own val-chosen thresholds, beside their baselines under the same
sensing and the oracles; its finding comes from the paired numbers."""

from __future__ import annotations

import dataclasses
import json
import shutil

import pytest

from clutterbench.config import load_params, load_section, parse
from clutterbench.errors import ClutterbenchError
from experiments.ch6_sensing import (
    BASELINE,
    LABEL,
    PARTS,
    by_part,
    check_planners,
    comparisons,
    markdown,
    part_label,
    parts_of,
    pull_scores,
    summary_rows,
    trial_jobs,
    what_it_shows,
)
from experiments.ch6_sensing_report import parts_table, parts_text, scores_table
from experiments.command import open_recheck
from experiments.config import DevConfig, with_dev

STREAM = {"families": {"random": 1}, "n_objects": [3, 5], "catalogue": "various"}
CPU = {"cpu_model": "X", "torch_cpu_capability": "AVX2", "cpu_flags": {}, "torch_threads": 2}
THRESHOLDS = "reports/support/thresholds.json"


def _dev(**ch6_sensing) -> DevConfig:
    return parse(
        DevConfig,
        {
            "streams": {"dev_ch6_a": STREAM},
            "ch4_piles": {"streams": ["dev_ch6_a"]},  # their defaults name other streams
            "ch4_sensing": {"streams": ["dev_ch6_a"]},
            "ch6_sensing": {"streams": ["dev_ch6_a"], **ch6_sensing},
        },
        "dev",
    )


def test_its_streams_sensor_and_planners_are_checked():
    with pytest.raises(ClutterbenchError, match="ch6_sensing.streams: unknown dev stream .dev_b."):
        _dev(streams=["dev_b"])
    with pytest.raises(ClutterbenchError, match="ch6_sensing.sensing: a sensor preset"):
        _dev(sensing="ideal")
    with pytest.raises(ClutterbenchError, match="two or more different presets"):
        _dev(training=["d415", "d415"])
    for other in ("multi_step_box", "physics_from_depth"):  # reads the box head too; no network
        with pytest.raises(ClutterbenchError, match=f"{other} reads .*not the collapse predictor"):
            check_planners(_dev(planners=["multi_step_pull", other]).ch6_sensing)
    cfg = _dev(planners=["multi_step_pull", "bimanual_pull", "multi_step"]).ch6_sensing
    assert check_planners(cfg) == ["physics_from_depth", "physics_from_depth_hold"]


@pytest.fixture
def tiny_params(root):
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    return params


def test_trials_are_the_sensed_rows_with_each_networks_thresholds(
    tiny_params, root, tmp_path, monkeypatch
):
    dev = load_section(DevConfig, "dev", tiny_params)
    cfg = dev.ch6_sensing
    monkeypatch.chdir(tmp_path)
    (tmp_path / THRESHOLDS).parent.mkdir(parents=True)
    shutil.copy(root / THRESHOLDS, tmp_path / THRESHOLDS)
    stage = json.loads((root / THRESHOLDS).read_text())
    candidates = []
    for k, preset in enumerate(cfg.training):  # each network its own thresholds
        own = json.loads(json.dumps(stage))
        for chosen in own["chosen"].values():
            if "score_threshold" in chosen:
                chosen["score_threshold"] = 0.11 * (k + 1)
        (tmp_path / preset).mkdir()
        (tmp_path / preset / "thresholds.json").write_text(json.dumps(own))
        candidates.append(
            {LABEL: preset, "checkpoint": f"{preset}/best.pt"}
            | {"thresholds": str(tmp_path / preset / "thresholds.json")}
        )
    baselines = check_planners(cfg)
    per_stream = len(candidates) * len(cfg.planners) + len(baselines) + 2 * cfg.oracle
    parts = len(PARTS) * (len(cfg.planners) + len(baselines))
    no_parts = dataclasses.replace(dev, ch6_sensing=dataclasses.replace(cfg, parts=False))
    assert len(trial_jobs(candidates, no_parts, tiny_params)) == per_stream * cfg.episodes
    jobs = trial_jobs(candidates, dev, tiny_params)
    assert len(jobs) == len(cfg.streams) * (per_stream + parts) * cfg.episodes
    seen = set()
    for job in jobs:
        label, stream = job.condition.split("/")
        training, planner = label.split(":")
        seen.add((training, planner))
        assert stream in cfg.streams and job.stream_cfg == dev.streams[stream]
        assert job.planner == planner and not job.record_images
        if planner.startswith("oracle"):  # read the world: no sensor, the simulator's masks
            assert (job.sensing, job.perception, job.model_path) == ("ideal", "instance", None)
            continue
        network, _, part = training.partition(" (")
        if part:  # the params' own network (ideal) or a baseline, under one of PARTS
            assert part == f"{job.sensing}, {job.perception} masks)"
            assert (job.sensing, job.perception) != (cfg.sensing, "depth")
        else:
            assert (job.sensing, job.perception) == (cfg.sensing, "depth")
        if network == BASELINE:
            assert job.model_path is None
            continue
        k = [c[LABEL] for c in candidates].index(network)
        assert str(job.model_path) == candidates[k]["checkpoint"]
        assert job.support.score_threshold == pytest.approx(0.11 * (k + 1))
        assert job.cp_max == pytest.approx(0.11 * (k + 1))
    expected = {(t, p) for t in cfg.training for p in cfg.planners}
    expected |= {(BASELINE, b) for b in baselines} | {("-", "oracle"), ("-", "oracle_hold")}
    for sensing, masks in parts_of(cfg):
        expected |= {(part_label("ideal", sensing, masks), p) for p in cfg.planners}
        expected |= {(part_label(BASELINE, sensing, masks), b) for b in baselines}
    assert seen == expected


def _records(label: str, wins: list[bool]) -> list[dict]:
    return [
        {"condition": f"{label}/dev_ch6_a", "episode": e, "success": w, "strict_success": w}
        | {"end": "cleared" if w else "gave_up", "n_disturbed": 0}
        for e, w in enumerate(wins)
    ]


@pytest.mark.parametrize(
    ("ideal_wins", "d415_wins", "finding"),
    [
        ([False] * 8, [True] * 8, "favour training on the sensor"),
        ([True] * 8, [False] * 8, "favour training on ideal"),
        ([True] * 3 + [False] * 5, [True] * 4 + [False] * 4, "No training changes"),
    ],
)
def test_the_finding_follows_the_paired_numbers(ideal_wins, d415_wins, finding):
    cfg = _dev(episodes=8, planners=["multi_step_pull"]).ch6_sensing
    records = _records("ideal:multi_step_pull", ideal_wins)
    records += _records("d415:multi_step_pull", d415_wins)
    records += _records(f"{BASELINE}:physics_from_depth", [False] * 8)
    records += _records("-:oracle", [True] * 8) + _records("-:oracle_hold", [True] * 8)
    rows = summary_rows(records)
    by = {(r[LABEL], r["planner"]): r for r in rows}
    assert by["ideal", "multi_step_pull"]["gave_up"] == ideal_wins.count(False)
    assert by["-", "oracle"]["success_below_oracle_points"] is None
    # the CP's score per pull: only a row that reads the CP has one
    assert "pulls_safe" in by["ideal", "multi_step_pull"]
    assert "pulls_safe" not in by[BASELINE, "physics_from_depth"]
    gap = 100 * d415_wins.count(False) / 8
    assert by["d415", "multi_step_pull"]["success_below_oracle_points"] == pytest.approx(gap)
    by_training, by_baseline = comparisons(records, cfg, "ideal")
    assert {c[LABEL] for c in by_training} == {"d415"}
    assert {(c[LABEL], c["baseline"]) for c in by_baseline} == {
        ("ideal", "physics_from_depth"),
        ("d415", "physics_from_depth"),
    }
    d415 = next(c for c in by_baseline if c[LABEL] == "d415" and c["criterion"] == "success")
    assert d415["only_piles"] == d415_wins.count(True) and d415["only_against"] == 0
    shows = what_it_shows(by_training, by_baseline, rows, "ideal")
    assert finding in shows
    beyond = "beyond chance" in shows.split("against physics_from_depth")[-1]
    assert beyond == (d415_wins.count(True) == 8)  # 8 / 0 pairs: p = 0.0078
    summary = {"best": {"epoch": 2, "val_loss": 0.5, "val_iou": 0.4}, "epochs_run": 2}
    chosen = {"pull_collapse_coverage": {"prob_threshold": 0.4, "score_threshold": 0.3}}
    candidates = [
        {LABEL: t, "model": "cp_focal", "dataset": "ch6", "data_reused": True}
        | {"network_reused": False, "summary": summary, "seconds": 10.0, "chosen": chosen}
        for t in ("ideal", "d415")
    ]
    text = markdown(
        {
            "scale": "tiny",
            "config": {"episodes": 8, "sensing": "d415", "planners": ["multi_step_pull"]},
            "current": "ideal",
            "candidates": candidates,
            "pull_method": "pull_collapse_coverage",
            "rows": rows,
            "by_training": by_training,
            "by_baseline": by_baseline,
            "shows": shows,
            "network_precision": "fp32",
            "n_episodes": len(records),
            "cpu": CPU,
            "seconds": 60.0,
            "trials_seconds": 30.0,
        }
    )
    assert (
        "## Trials under d415, masks from depth" in text and f"**What it shows.** {shows}" in text
    )
    assert (
        "| d415 | the pipeline's | trained by this run | 2 / 2 | 0.5000 | 0.400 | 0.4 / 0.3 |"
        in text
    )
    assert "| dev_ch6_a | multi_step_pull (d415) | success | physics_from_depth |" in text


def test_where_the_points_go_is_each_part_against_exact_depth_and_simulator_masks():
    cfg = _dev(episodes=8, planners=["multi_step_pull"]).ch6_sensing
    wins = {  # (sensing, masks) -> episodes won, out of 8
        ("ideal", "instance"): 8,
        ("d415", "instance"): 6,
        ("ideal", "depth"): 5,
    }
    records = []
    for label in ("ideal", BASELINE):
        planner = "multi_step_pull" if label == "ideal" else "physics_from_depth"
        for (sensing, masks), k in wins.items():
            records += _records(
                f"{part_label(label, sensing, masks)}:{planner}", [True] * k + [False] * (8 - k)
            )
        records += _records(f"{label}:{planner}", [True] * 2 + [False] * 6)  # d415, depth masks
    records += _records("d415:multi_step_pull", [True] * 8)
    parts = by_part(records, cfg, "ideal")
    assert [(c["row"], c["sensing"], c["masks"]) for c in parts] == [
        (row, s, m)
        for row in ("ideal", BASELINE)
        for s, m in (("d415", "instance"), ("ideal", "depth"), ("d415", "depth"))
    ]
    assert [c["difference_points"] for c in parts[:3]] == [-25.0, -37.5, -75.0]
    assert parts[2]["piles"] == "ideal:multi_step_pull"  # the sensed row itself, not a part
    assert not by_part(records, dataclasses.replace(cfg, parts=False), "ideal")
    text = parts_text(parts)
    assert "multi_step_pull (ideal): -25.0 with d415 depth and simulator masks" in text
    assert "-75.0 with d415 depth and masks from depth (p = 0.031)" in text
    rows = summary_rows(records + _records("-:oracle", [True] * 8))
    table = "\n".join(parts_table({"by_part": parts, "rows": rows, "current": "ideal"}))
    assert (
        "| stream | planner (network) | exact depth, simulator masks | d415 depth and simulator "
        "masks | exact depth and masks from depth | d415 depth and masks from depth |" in table
    )
    assert "| dev_ch6_a | physics_from_depth (baseline) | 8/8 = 100.0%" in table
    assert "2/8 = 25.0% [7.1, 59.1]: -75.0 (0 / 6), p = 0.031 |" in table


def test_each_rows_collapse_scores_are_read_apart_for_safe_and_collapsing_pulls():
    steps = [
        {"max_cp": 0.1, "collapse_free": True, "aborted_before_motion": False},
        {"max_cp": 0.3, "collapse_free": True, "aborted_after_motion": True},
        {"max_cp": 0.9, "collapse_free": False},
        {"max_cp": None, "collapse_free": True},  # a step without a score is no pull read
    ]
    records = _records("ideal:multi_step_pull", [True, False])
    records[0]["steps"], records[1]["steps"] = steps[:2], steps[2:]
    assert pull_scores(records) == {
        "pulls_safe": 2,
        "score_safe": pytest.approx(0.2),
        "pulls_collapsed": 1,
        "score_collapsed": pytest.approx(0.9),
        "aborted": 1,
    }
    assert pull_scores(records[:1])["score_collapsed"] is None
    row = {"stream": "dev_ch6_a", LABEL: "ideal", "planner": "multi_step_pull"}
    table = "\n".join(scores_table({"rows": [row | pull_scores(records)]}))
    assert "| dev_ch6_a | ideal | multi_step_pull | 2, 0.20 | 1, 0.90 | 1 |" in table


def test_a_recheck_opens_with_its_section_and_refuses_one_without_streams(tiny_params):
    base, dev, trials, cfg = open_recheck(tiny_params, "ch6_sensing")
    assert cfg == dev.ch6_sensing and base.scale == "tiny" and trials.ch6.model == "cp_focal"
    tiny_params["dev"]["ch6_sensing"]["streams"] = []
    with pytest.raises(ClutterbenchError, match="dev.ch6_sensing.streams: no dev stream to run"):
        open_recheck(tiny_params, "ch6_sensing")
