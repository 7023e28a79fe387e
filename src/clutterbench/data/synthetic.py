"""Synthetic datasets in the generate stage's layout (manifest + shards), without physics.

For tests and benchmarks that need data of a given shape and size in seconds: boxes are
rectangles of tilted planes in front of a back wall, drawn in order (later ones occlude),
and the removal matrix (and, with pulls, the pull tensor) is random. Only the layout is
realistic, not the labels.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.io import save_npz, write_json
from clutterbench.sim.config import REJECT_REASONS

WALL_M = 0.8
"""Depth of the background (camera to back wall)."""


def synthetic_scenes(
    rng: np.random.Generator,
    scene_indices: list[int],
    size: int,
    n_objects: tuple[int, int],
    families: Mapping[str, float],
    pulls: bool = False,
    pull_outcomes: bool = False,
) -> dict[str, np.ndarray]:
    """Per-scene arrays of one shard (every key a generated shard has, but config_hash);
    `pull_outcomes`: also random pullout_* arrays (generate.datasets.<d>.pull_outcomes)."""
    s, n_max = len(scene_indices), n_objects[1]
    names = list(families)
    weights = np.array([families[f] for f in names], dtype=np.float64)
    n = rng.integers(n_objects[0], n_objects[1] + 1, size=s)
    # Tilted planes, as rendered faces are: every pixel differs, so shards compress (and
    # decompress) like rendered ones rather than like constant blocks.
    ramp = np.linspace(0.0, 0.02, size, dtype=np.float32)
    depth = np.broadcast_to(WALL_M + ramp[:, None] + ramp[None, :], (s, size, size)).copy()
    instance = np.zeros((s, size, size), np.uint8)
    removal = np.full((s, n_max, n_max), np.nan, np.float32)
    for k in range(s):
        for box in range(n[k]):
            h, w = rng.integers(size // 8, size // 3 + 1, size=2)
            top, left = rng.integers(0, size - h + 1), rng.integers(0, size - w + 1)
            tilt = rng.uniform(-0.5, 0.5) * ramp[top : top + h, None]
            depth[k, top : top + h, left : left + w] = rng.uniform(0.4, 0.7) + tilt
            instance[k, top : top + h, left : left + w] = box + 1
        # Mean 5 mm: about a third of the boxes count as moved at the 5 mm threshold.
        r = rng.exponential(0.005, size=(n[k], n[k])).astype(np.float32)
        np.fill_diagonal(r, 0.0)
        removal[k, : n[k], : n[k]] = r
    arrays = {
        "scene_index": np.array(scene_indices, dtype=np.int64),
        "n_objects": n.astype(np.int16),
        "family": np.array(
            [names[i] for i in rng.choice(len(names), s, p=weights / weights.sum())]
        ),
        "depth_m": depth,
        "instance": instance,
        "sizes_m": np.zeros((s, n_max, 3), np.float32),
        "poses": np.zeros((s, n_max, 7), np.float64),
        "removal_m": removal,
        "spec_json": np.array(["{}"] * s),
        "rejected": rng.poisson(0.3, size=(s, len(REJECT_REASONS))).astype(np.int32),
        "steps": rng.integers(100, 1000, size=s),
    }
    if pulls:
        arrays["pull_m"] = synthetic_pulls(rng, n, n_max)
    if pull_outcomes:
        arrays |= synthetic_pull_outcomes(rng, n, n_max)
    return arrays


def synthetic_pull_outcomes(
    rng: np.random.Generator, n: np.ndarray, n_max: int
) -> dict[str, np.ndarray]:
    """pullout_* arrays (S, n_max, n_max) as generate lays them out: row x = pulling box x;
    NaN (False) on the diagonal and beyond each scene's boxes; a tenth of the boxes leave
    the shelf."""
    s = len(n)
    out = {
        k: np.full((s, n_max, n_max), np.nan, np.float64)
        for k in ("pullout_displacement_m", "pullout_drop_m", "pullout_tilt_deg")
    }
    left = np.zeros((s, n_max, n_max), bool)
    for k, nk in enumerate(n):
        off = ~np.eye(nk, dtype=bool)
        disp = rng.exponential(0.005, size=(nk, nk))
        out["pullout_displacement_m"][k, :nk, :nk] = np.where(off, disp, np.nan)
        out["pullout_drop_m"][k, :nk, :nk] = np.where(off, disp / 2, np.nan)
        out["pullout_tilt_deg"][k, :nk, :nk] = np.where(off, 1000 * disp, np.nan)
        left[k, :nk, :nk] = off & (rng.random((nk, nk)) < 0.1)
    return out | {"pullout_left_shelf": left}


def synthetic_pulls(rng: np.random.Generator, n: np.ndarray, n_max: int) -> np.ndarray:
    """(S, n_max, n_max + 1, n_max) P[x, s, y] as generate lays it out: support slot n_max is
    "no support"; NaN where x == y, s == x or s == y, and beyond each scene's boxes."""
    pull = np.full((len(n), n_max, n_max + 1, n_max), np.nan, np.float64)
    for k, nk in enumerate(n):
        r = rng.exponential(0.005, size=(nk, nk + 1, nk))
        pull[k, :nk, :nk, :nk], pull[k, :nk, n_max, :nk] = r[:, :nk], r[:, nk]
        for x in range(nk):
            pull[k, x, :, x] = np.nan
            pull[k, x, x, :] = np.nan
            for s in range(nk):
                pull[k, x, s, s] = np.nan
    return pull


def write_synthetic_dataset(
    gen_dir: Path,
    name: str,
    n_scenes: int,
    shard_size: int,
    size: int,
    n_objects: tuple[int, int] = (5, 10),
    families: Mapping[str, float] | None = None,
    seed: int = 0,
    config_hash: str = "synthetic",
    pulls: bool = False,
    pull_outcomes: bool = False,
) -> dict[str, Any]:
    """Write gen_dir/name/{shard-NNNNN.npz, manifest.json}; returns the manifest."""
    families = families or {"random": 1.0}
    out = Path(gen_dir) / name
    shards, counts = [], dict.fromkeys(families, 0)
    rejected = dict.fromkeys(REJECT_REASONS, 0)
    for k, lo in enumerate(range(0, n_scenes, shard_size)):
        rng = np.random.default_rng([seed, k])  # each shard alone regenerable, like generate
        indices = list(range(lo, min(lo + shard_size, n_scenes)))
        arrays = synthetic_scenes(rng, indices, size, n_objects, families, pulls, pull_outcomes)
        shards.append(f"shard-{k:05d}.npz")
        save_npz(out / shards[-1], {**arrays, "config_hash": np.array(config_hash)})
        for f in arrays["family"]:
            counts[str(f)] += 1
        for reason, c in zip(REJECT_REASONS, arrays["rejected"].sum(axis=0)):
            rejected[reason] += int(c)
    manifest = {
        "dataset": name,
        "config_hash": config_hash,
        "n_scenes": n_scenes,
        "n_shards": len(shards),
        "shards": shards,
        "families": counts,
        "rejected": rejected,
    }
    write_json(out / "manifest.json", manifest)
    return manifest
