"""Stage `split`: train / val / test by scene (never by target), seeded."""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from clutterbench.config import bounded
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json


@dataclasses.dataclass(frozen=True)
class Fractions:
    train: float = bounded(0.9, ge=0.0, le=1.0)
    """Fraction of scenes for training."""
    val: float = bounded(0.1, ge=0.0, le=1.0)
    """Fraction for validation (early stopping)."""
    test: float = bounded(0.0, ge=0.0, le=1.0)
    """Fraction held out for evaluation."""

    def __post_init__(self) -> None:
        if abs(self.train + self.val + self.test - 1.0) > 1e-6:
            raise ValueError("train + val + test must sum to 1")


@dataclasses.dataclass(frozen=True)
class SplitConfig:
    datasets: Mapping[str, Fractions] = dataclasses.field(default_factory=dict)
    """Dataset name -> fractions."""


def split_scenes(n_scenes: int, fr: Fractions, seed: int, dataset: str) -> dict[str, list[int]]:
    """Seeded permutation of scene indices cut by the fractions (rounded, test gets the rest)."""
    rng = np.random.default_rng([seed, zlib.crc32(dataset.encode()), 1])
    order = rng.permutation(n_scenes)
    # Every non-empty part gets at least one scene, so tiny runs exercise every split.
    n_val = max(1, int(round(fr.val * n_scenes))) if fr.val > 0 else 0
    n_test = max(1, int(round(fr.test * n_scenes))) if fr.test > 0 else 0
    n_train = n_scenes - n_val - n_test
    if n_train < 0 or (fr.train > 0 and n_train < 1):
        raise ClutterbenchError(
            f"split.datasets.{dataset}: {n_scenes} scenes are too few to give every split a scene"
        )
    if fr.train == 0:
        n_test += n_train
        n_train = 0
    parts = {
        "train": order[:n_train],
        "val": order[n_train : n_train + n_val],
        "test": order[n_train + n_val :],
    }
    return {k: sorted(int(i) for i in v) for k, v in parts.items()}


def split_dataset(name: str, fr: Fractions, seed: int, gen_dir: Path, out_dir: Path) -> dict:
    manifest = read_json(gen_dir / name / "manifest.json")
    if not isinstance(manifest, dict) or "n_scenes" not in manifest:
        raise ClutterbenchError(f"corrupt manifest for dataset '{name}' in {gen_dir / name}")
    parts = split_scenes(int(manifest["n_scenes"]), fr, seed, name)
    record = {"dataset": name, "config_hash": manifest["config_hash"], **parts}
    write_json(out_dir / f"{name}.json", record)
    return {k: len(v) for k, v in parts.items()}
