"""The ch. 5 sensed-training recheck: its trials are Table 5.2's sensed replenishment rows on
dev streams, each network with its own val threshold, beside the oracle; it needs the sensor's
detector; its finding comes from the paired numbers."""

from __future__ import annotations

import pytest

from clutterbench.config import load_params, load_section, parse
from clutterbench.errors import ClutterbenchError
from experiments.ch4_sensing import comparisons_of, what_it_shows
from experiments.ch5_sensing import LABEL, markdown, summary_rows, trial_jobs
from experiments.config import DevConfig, with_dev

STREAM = {"families": {"replenish_stacked": 1}, "n_objects": [4, 5], "catalogue": "various"}
CPU = {"cpu_model": "X", "torch_cpu_capability": "AVX2", "cpu_flags": {}, "torch_threads": 2}


def _dev(**ch5_sensing) -> DevConfig:
    return parse(
        DevConfig,
        {
            "streams": {"dev_ch5_a": STREAM},
            "ch4_piles": {"streams": ["dev_ch5_a"]},  # their defaults name other streams
            "ch4_sensing": {"streams": ["dev_ch5_a"]},
            "ch5_sensing": {"streams": ["dev_ch5_a"], **ch5_sensing},
        },
        "dev",
    )


def test_its_streams_must_be_dev_streams_and_its_sensor_a_sensor():
    with pytest.raises(ClutterbenchError, match="ch5_sensing.streams: unknown dev stream .dev_b."):
        _dev(streams=["dev_b"])
    with pytest.raises(ClutterbenchError, match="ch5_sensing.sensing: a sensor preset"):
        _dev(sensing="ideal")
    with pytest.raises(ClutterbenchError, match="two or more different presets"):
        _dev(training=["d415", "d415"])


@pytest.fixture
def tiny_params(root):
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    return params


CANDIDATES = [
    {LABEL: "ideal", "checkpoint": "a/best.pt", "prob_threshold": 0.3},
    {LABEL: "d415", "checkpoint": "b/best.pt", "prob_threshold": 0.6},
]


def test_trials_are_the_sensed_rows_on_dev_streams_beside_the_oracle(
    tiny_params, tmp_path, monkeypatch
):
    dev = load_section(DevConfig, "dev", tiny_params)
    cfg = dev.ch5_sensing
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ClutterbenchError, match="detector_d415/best.pt missing; run dvc repro"):
        trial_jobs(CANDIDATES, dev, tiny_params)
    (tmp_path / "models" / "detector_d415").mkdir(parents=True)
    (tmp_path / "models" / "detector_d415" / "best.pt").write_bytes(b"")
    jobs = trial_jobs(CANDIDATES, dev, tiny_params)
    assert len(jobs) == len(cfg.streams) * (len(CANDIDATES) + cfg.oracle) * cfg.episodes
    seen = set()
    for job in jobs:
        label, stream = job.condition.split("/")
        seen.add(label)
        assert stream in cfg.streams and job.stream_cfg == dev.streams[stream]
        assert job.scene_type == stream.removeprefix("dev_ch5_")
        if label == "oracle":  # reads the world: no sensor, the generator's clusters
            assert (job.cond.planner, job.cond.perception) == ("oracle", "clusters")
            assert job.cond.sensing == "ideal"
            continue
        mine = next(c for c in CANDIDATES if c[LABEL] == label)
        assert (job.cond.planner, job.cond.perception) == ("replenish", "detector")
        assert job.cond.sensing == cfg.sensing
        assert str(job.model_path) == mine["checkpoint"]
        assert job.prob_threshold == mine["prob_threshold"]
        assert str(job.detector_path) == f"models/detector_{cfg.sensing}/best.pt"
    assert seen == {"ideal", "d415", "oracle"}


def _records(label: str, wins: list[bool]) -> list[dict]:
    return [
        {"condition": f"{label}/dev_ch5_a", "episode": e, "success": w, "strict_success": w}
        | {"end": "placed" if w else "gave_up", "n_disturbed": 0}
        for e, w in enumerate(wins)
    ]


@pytest.mark.parametrize(
    ("ideal_wins", "d415_wins", "finding"),
    [
        ([False] * 8, [True] * 8, "favour training on d415"),
        ([True] * 8, [False] * 8, "favour training on ideal"),
        ([True] * 3 + [False] * 5, [True] * 4 + [False] * 4, "no dev-stream rate beyond chance"),
    ],
)
def test_the_finding_follows_the_paired_numbers(ideal_wins, d415_wins, finding):
    dev = _dev(episodes=8)
    records = _records("ideal", ideal_wins) + _records("d415", d415_wins)
    records += _records("oracle", [True] * 8)
    rows = summary_rows(records, dev)
    assert {r[LABEL]: r["gave_up"] for r in rows}["ideal"] == ideal_wins.count(False)
    comparisons = comparisons_of(records, dev.ch5_sensing, "ideal")
    assert {c[LABEL] for c in comparisons} == {"d415"}
    shows = what_it_shows(comparisons, rows, "ideal")
    assert finding in shows and "Below the oracle on dev_ch5_a" in shows
    summary = {"best": {"epoch": 2, "val_loss": 0.5, "val_iou": 0.4}, "epochs_run": 2}
    candidates = [
        c
        | {"model": "cmn_bs32", "dataset": "ch5", "data_reused": True, "network_reused": False}
        | {"summary": summary, "val_iou_at_threshold": 0.45, "seconds": 10.0}
        for c in CANDIDATES
    ]
    text = markdown(
        {
            "scale": "tiny",
            "config": {"episodes": 8, "sensing": "d415"},
            "current": "ideal",
            "candidates": candidates,
            "rows": rows,
            "comparisons": comparisons,
            "shows": shows,
            "detector": {"path": "models/detector_d415/best.pt", "sha256": "ab" * 32},
            "network_precision": "fp32",
            "cpu": CPU,
            "seconds": 60.0,
            "trials_seconds": 30.0,
        }
    )
    assert "## Trials under d415" in text and f"**What it shows.** {shows}" in text
    assert "| dev_ch5_a | success | d415 |" in text
    assert "| d415 | the pipeline's | trained by this run | 2 / 2 |" in text
    assert "| 0.60 (0.450) |" in text
