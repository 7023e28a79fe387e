"""The detector's sensed-training recheck: its networks differ only in their training sensor,
its val images are the sensor's returns of the same scenes, and its finding comes from the
bootstrapped differences."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.config import load_params, parse
from clutterbench.sim import sensor
from clutterbench.sim.sensor import sense_images
from experiments.config import DetectorSensingConfig, DevConfig, load_dev
from experiments.detector_sensing import markdown, what_it_shows

CPU = {"cpu_model": "X", "torch_cpu_capability": "AVX2", "cpu_flags": {}, "torch_threads": 2}


@pytest.mark.parametrize(
    ("section", "match"),
    [
        ({"training": ["d415"]}, "need two or more different presets"),
        ({"training": ["d415", "d415"]}, "need two or more different presets"),
        ({"scored_on": []}, "one or more different presets"),
        ({"training": ["ideal", "kinect"]}, "kinect"),
    ],
)
def test_bad_settings_are_named(section, match):
    with pytest.raises(Exception, match=match):
        parse(DevConfig, {"detector_sensing": section}, "dev")


def test_the_repository_settings_parse(root):
    cfg = load_dev(load_params(root / "params.yaml")).detector_sensing
    assert isinstance(cfg, DetectorSensingConfig) and cfg.training[0] == "ideal"


def _scenes(n: int = 3, size: int = 32) -> np.ndarray:
    rng = np.random.default_rng(0)
    depth = np.full((n, size, size), 0.9, dtype=np.float32)
    for d in depth:  # a box in front of the shelf's back, somewhere different in each
        r, c = rng.integers(4, size - 14, size=2)
        d[r : r + 10, c : c + 10] = 0.7
    return depth


def test_ideal_images_are_the_renderers():
    depth = _scenes()
    assert sense_images(depth, "ideal", 42.0, 7) is depth


def test_sensed_images_are_the_sensors_returns_seeded_per_image():
    depth = _scenes()
    once, again = sense_images(depth, "d415", 42.0, 7), sense_images(depth, "d415", 42.0, 7)
    assert once.shape == depth.shape and once.dtype == np.float32
    assert np.array_equal(once, again)  # a rerun sees the same returns
    assert not np.array_equal(once, depth)
    fx = sensor.focal_px(depth.shape[-1], 42.0)
    camera = sensor.pinhole(fx, depth.shape[-2:])
    for d, got in zip(depth, once):  # each image as `sense` returns it alone
        want = sensor.sense(d, camera, sensor.preset("d415"), sensor.observation_rng(7, d))
        assert np.array_equal(got, want)
    assert not np.array_equal(sense_images(depth, "d415", 42.0, 8), once)  # the seed matters


@pytest.mark.parametrize(
    ("ci", "word"),
    [((0.01, 0.05), "beyond"), ((-0.05, -0.01), "beyond"), ((-0.01, 0.02), "within")],
)
def test_the_finding_follows_the_interval(ci, word):
    diff = {"scored_on": "d415", "training": "d415", "against": "ideal", "ci": list(ci)}
    shows = what_it_shows([diff | {"difference": float(np.mean(ci))}])
    assert shows.startswith("On val images through d415")
    assert f"{word} chance" in shows


def test_the_report_holds_every_row():
    per_class = {"C^h": {"ap50": 0.5, "precision_at_threshold": 0.8, "recall_at_threshold": 0.4}}
    rows = [
        {"training": t, "scored_on": s, "map50": m, "per_class": per_class}
        for t, s, m in (("ideal", "ideal", 0.6), ("d415", "ideal", 0.58), ("ideal", "d415", 0.3))
    ]
    diffs = [{"scored_on": "d415", "training": "d415", "against": "ideal"}]
    diffs[0] |= {"difference": 0.2, "ci": [0.1, 0.3]}
    cand = {"summary": {"best": {"epoch": 3, "val_map50": 0.6}, "epochs_run": 5}}
    cand |= {"seconds": 60.0, "network_reused": False}
    result = {
        "scale": "tiny",
        "config": {"bootstrap": 20},
        "dataset": "ch5_arrangement",
        "val_images": 9,
        "data_reused": True,
        "candidates": [cand | {"training": "ideal"}, cand | {"training": "d415"}],
        "rows": rows,
        "differences": diffs,
        "shows": what_it_shows(diffs),
        "cpu": CPU,
        "seconds": 90.0,
    }
    md = markdown(result)
    assert md.count("| ideal | ideal | 0.600 |") == 1 and "| d415 | ideal | 0.300 |" in md
    assert "| d415 | d415 | ideal | +0.200 | [+0.100, +0.300] |" in md
    assert "beyond chance" in md and "9 val images" in md
