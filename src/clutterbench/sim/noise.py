"""Parametric depth noise (the thesis adds random noise to simulated depth, 5.2.2)."""

from __future__ import annotations

import dataclasses
from typing import Literal, Protocol

import numpy as np

from clutterbench.config import bounded


@dataclasses.dataclass(frozen=True)
class DepthNoiseConfig:
    sigma_m: float = bounded(0.001, ge=0.0)
    """Depth-independent Gaussian noise (m)."""
    sigma_quadratic_per_m: float = bounded(0.002, ge=0.0)
    """Depth-dependent term: sigma += k * depth^2, as structured-light sensors behave."""
    dropout: float = bounded(0.005, ge=0.0, le=1.0)
    """Fraction of pixels set to 0 (missing returns)."""

    def apply(self, depth_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The training augmentation's call: `add_depth_noise` with this configuration."""
        return add_depth_noise(depth_m, self, rng)


def add_depth_noise(
    depth_m: np.ndarray, cfg: DepthNoiseConfig, rng: np.random.Generator
) -> np.ndarray:
    """Noisy copy of `depth_m` (float32 metres); invalid (0) pixels stay 0."""
    assert depth_m.dtype == np.float32, "depth must be float32 metres"
    valid = depth_m > 0
    sigma = cfg.sigma_m + cfg.sigma_quadratic_per_m * depth_m.astype(np.float64) ** 2
    noisy = depth_m + (rng.standard_normal(depth_m.shape) * sigma).astype(np.float32)
    noisy[rng.random(depth_m.shape) < cfg.dropout] = 0.0
    noisy[~valid] = 0.0
    return noisy.astype(np.float32)


class DepthAugmentation(Protocol):
    """What the training datasets call on each depth image they serve: the parametric noise
    above (`DepthNoiseConfig`) or a depth sensor's model (`sim.sensor.SensedAugmentation`)."""

    def apply(self, depth_m: np.ndarray, rng: np.random.Generator) -> np.ndarray: ...


@dataclasses.dataclass(frozen=True)
class TrainSensingConfig:
    """The depth sensor the networks train on: train.sensing, detector.sensing,
    support.box_head.sensing (sim/sensor.py, docs/sensing.md)."""

    preset: Literal["ideal", "structured_light", "d415"] = "ideal"
    """A preset of sim/sensor.py PRESETS: its model replaces the parametric noise (train.noise)
    on every training image of a model with `noise: true`; ideal: the parametric noise."""
    spread: float = bounded(0.2, ge=0.0, le=0.95)
    """Each image's sensor noise is the preset's, each randomised field scaled by a factor
    drawn in [1 - spread, 1 + spread] (sim.sensor.randomized)."""
