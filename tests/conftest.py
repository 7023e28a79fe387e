"""Shared fixtures: the repository root and a tiny-scale sim config."""

from __future__ import annotations

from pathlib import Path

import pytest

from clutterbench.sim.config import CameraConfig, PhysicsConfig

ROOT = Path(__file__).resolve().parents[1]


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The slow end-to-end tests first: `make test` runs two workers, one file each at a
    time (pytest-xdist, --dist loadfile, in collection order), so the tiny repro starts at
    once on one worker while the other works through every other file."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def physics() -> PhysicsConfig:
    return PhysicsConfig()


@pytest.fixture(scope="session")
def camera() -> CameraConfig:
    return CameraConfig(image_size=64)


def _untrained(tmp_path_factory, name: str, meta: dict | None = None, **net) -> Path:
    """An untrained collapse-map network (64 px, seed 0) saved as a checkpoint: the planners'
    plumbing, not skill."""
    import torch

    from clutterbench.models import build_model
    from clutterbench.models.checkpoint import save_checkpoint
    from clutterbench.models.collapse_map import CollapseMapConfig
    from clutterbench.models.vgg import VGGConfig

    torch.manual_seed(0)
    cfg = CollapseMapConfig(
        input_size=64, encoder=VGGConfig(width=0.125), decoder_channels=(32, 16, 16, 8, 8), **net
    )
    path = tmp_path_factory.mktemp(name) / "best.pt"
    save_checkpoint(path, "collapse_map", build_model("collapse_map", cfg), meta or {"epoch": 0})
    return path


@pytest.fixture(scope="session")
def tiny_ch4(tmp_path_factory) -> Path:
    """An untrained 4-class ch. 4 network (2 masks in)."""
    return _untrained(tmp_path_factory, "ch4", n_masks=2, n_classes=4)


@pytest.fixture(scope="session")
def tiny_cp(tmp_path_factory) -> Path:
    """An untrained collapse predictor (one deletion head)."""
    return _untrained(tmp_path_factory, "cp")


@pytest.fixture(scope="session")
def tiny_cp_heads(tmp_path_factory) -> Path:
    """An untrained collapse predictor with a deletion and a pull head."""
    meta = {"epoch": 0, "heads": ["deletion", "pull"]}
    return _untrained(tmp_path_factory, "cp_heads", meta, n_classes=2)


@pytest.fixture(scope="session")
def tiny_cp_three_heads(tmp_path_factory) -> Path:
    """An untrained collapse predictor with a deletion, a pull and a pull_collapse head."""
    meta = {"epoch": 0, "heads": ["deletion", "pull", "pull_collapse"]}
    return _untrained(tmp_path_factory, "cp_three_heads", meta, n_classes=3)


@pytest.fixture(scope="session")
def tiny_box_head(tmp_path_factory, tiny_cp_three_heads) -> Path:
    """An untrained box head over tiny_cp_three_heads' maps (its checkpoint names that CP)."""
    import torch

    from clutterbench.collapse.box_head import BoxHead, BoxHeadMeta, feature_names, save_box_head
    from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint

    torch.manual_seed(0)
    heads = tuple(checkpoint_heads(load_checkpoint(tiny_cp_three_heads)))
    meta = BoxHeadMeta(tiny_cp_three_heads.parent.name, heads, feature_names(heads), 8, 64)
    path = tmp_path_factory.mktemp("box_head") / "best.pt"
    save_box_head(BoxHead(len(meta.features), meta.hidden), meta, path)
    return path


@pytest.fixture(scope="session")
def toy_networks(tiny_cp, tiny_cp_heads, tiny_cp_three_heads, tiny_box_head, tiny_ch4):
    """Every untrained network a ch. 6 planner may read (tests/toy_jobs.py ToyNetworks)."""
    from tests.toy_jobs import ToyNetworks

    return ToyNetworks(tiny_cp, tiny_cp_heads, tiny_cp_three_heads, tiny_box_head, tiny_ch4)
