"""The perturbed-fit recheck's own parts: the noise it adds, and its params."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.observation import Observation
from clutterbench.trials.config import SceneStreamConfig
from experiments.config import DevConfig, PerturbedFitConfig


def test_noise_lands_on_depth_pixels_only_and_is_seeded():
    from experiments.perturbed_fit import perturbed

    depth = np.full((8, 8), 0.5, dtype=np.float32)
    depth[0] = 0.0  # no depth there
    obs = Observation(depth_m=depth, instance=np.zeros((8, 8), np.uint8), camera=None)
    a = perturbed(obs, 0.002, np.random.default_rng(1)).depth_m
    b = perturbed(obs, 0.002, np.random.default_rng(1)).depth_m
    assert np.array_equal(a, b) and (a[0] == 0).all()
    assert 0.0005 < np.std(a[1:] - 0.5) < 0.004


def test_one_noise_level_per_seed():
    with pytest.raises(ValueError, match="one depth_noise_m per seed"):
        PerturbedFitConfig(seeds=(1, 2), depth_noise_m=(0.001,))
    with pytest.raises(ValueError, match="perturbed_fit.streams: unknown dev stream"):
        stream = SceneStreamConfig(families={"pile": 1}, n_objects=(5, 5), catalogue="various")
        DevConfig(
            streams={"dev_ch4_10": stream, "dev_ch4_5": stream},
            perturbed_fit=PerturbedFitConfig(streams=("ch6_3_10",)),
        )
