"""Shared fixtures: the repository root and a tiny-scale sim config."""

from __future__ import annotations

from pathlib import Path

import pytest

from clutterbench.sim.config import CameraConfig, PhysicsConfig

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def physics() -> PhysicsConfig:
    return PhysicsConfig()


@pytest.fixture(scope="session")
def camera() -> CameraConfig:
    return CameraConfig(image_size=64)
