"""PyTorch Dataset over (scene, target) pairs; masks and labels derived at load time.

Shards are read lazily (clutterbench.data.shards): memory holds the pair index and a few
shards, whatever the dataset's size. Training draws pairs with ShardShuffleSampler so that
a shuffled epoch still reads each shard once.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from clutterbench.data.labels import collapse_mask, moved_matrix, target_mask
from clutterbench.data.shards import SceneColumns, ShardStore, load_split
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.noise import DepthNoiseConfig, add_depth_noise

CACHE_SHARDS = 4
"""Shards kept decompressed per dataset; also the shuffle window of ShardShuffleSampler."""


@dataclasses.dataclass(frozen=True)
class SceneIndex:
    """Where each selected scene lives and which of its boxes can be targets."""

    shard: np.ndarray
    """(S,) shard number of each scene, in the order the split lists them."""
    row: np.ndarray
    """(S,) row of the scene in its shard."""
    n_objects: np.ndarray
    """(S,) boxes in the scene."""
    scene_index: np.ndarray
    """(S,) the scene's index in the dataset."""
    pairs: np.ndarray
    """(P, 2) int64 (position in the selection, target box), scene by scene."""


def index_scenes(store: ShardStore, indices: Sequence[int], min_target_pixels: int) -> SceneIndex:
    """Walk the shards once (n_objects and instance images only) to locate `indices`."""
    pos = {int(s): i for i, s in enumerate(indices)}
    if len(pos) < len(indices):
        raise ClutterbenchError(
            f"dataset '{store.dataset}': split lists a scene twice; rerun split"
        )
    shard = np.full(len(pos), -1, dtype=np.int64)
    row = np.zeros(len(pos), dtype=np.int64)
    n_objects = np.zeros(len(pos), dtype=np.int64)
    targets: list[np.ndarray] = [np.zeros(0, np.int64)] * len(pos)
    for k in range(store.n_shards):
        arrays = store.load(k, ("scene_index", "n_objects", "instance"))
        for r, s in enumerate(arrays["scene_index"]):
            i = pos.get(int(s))
            if i is None:
                continue
            n = int(arrays["n_objects"][r])
            shard[i], row[i], n_objects[i] = k, r, n
            # A box hidden behind others cannot be chosen as a target from the camera's view.
            visible = np.bincount(arrays["instance"][r].ravel(), minlength=256)[1 : n + 1]
            targets[i] = np.flatnonzero(visible >= min_target_pixels)
    missing = np.flatnonzero(shard < 0)
    if len(missing):
        raise ClutterbenchError(
            f"dataset '{store.dataset}': split names scene {indices[missing[0]]} "
            "that the shards do not hold; rerun split"
        )
    pairs = [np.stack([np.full(len(t), i), t], axis=1) for i, t in enumerate(targets)]
    return SceneIndex(
        shard=shard,
        row=row,
        n_objects=n_objects,
        scene_index=np.array(list(pos), dtype=np.int64),
        pairs=np.concatenate(pairs).astype(np.int64) if pairs else np.zeros((0, 2), np.int64),
    )


class CollapseDataset(Dataset):
    """Items are dicts of float32 tensors (1, H, W): depth_m, target, collapse.

    One item per (scene, target box) pair: thesis 5.2.2 / 6.2.1 sample a target per
    simulation; we use every visible box of every scene, since the removal matrix labels
    them all. `scenes[key]` gives a split's per-scene arrays (image arrays read lazily).
    """

    def __init__(
        self,
        gen_dir: Path,
        split_file: Path,
        split: str,
        threshold_m: float,
        noise: DepthNoiseConfig | None = None,
        flip: bool = False,
        seed: int = 0,
        min_target_pixels: int = 10,
        cache_shards: int = CACHE_SHARDS,
    ):
        record = load_split(split_file, gen_dir)
        if split not in record:
            raise ClutterbenchError(f"{split_file}: no '{split}' split")
        self.store = ShardStore(gen_dir, record["dataset"], cache_shards)
        index = index_scenes(self.store, record[split], min_target_pixels)
        self.index = index
        self.pairs = index.pairs
        self.scenes = SceneColumns(
            self.store,
            index.shard,
            index.row,
            {"n_objects": index.n_objects, "scene_index": index.scene_index},
            self.store.array_names(),
        )
        self.threshold_m, self.noise, self.flip = threshold_m, noise, flip
        self.rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return len(self.pairs)

    @property
    def pair_shards(self) -> np.ndarray:
        """(P,) shard number of each pair's scene."""
        return self.index.shard[self.pairs[:, 0]]

    def shard_sampler(self, seed: int) -> ShardShuffleSampler:
        """A shuffling sampler whose window matches this dataset's shard cache."""
        return ShardShuffleSampler(self.pair_shards, self.store.cache_shards, seed)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        s, x = (int(v) for v in self.pairs[i])
        n = int(self.index.n_objects[s])
        shard = self.store.load(int(self.index.shard[s]), ("depth_m", "instance", "removal_m"))
        r = int(self.index.row[s])
        depth, instance = shard["depth_m"][r], shard["instance"][r]
        moved = moved_matrix(shard["removal_m"][r, :n, :n], self.threshold_m)[x]
        if self.noise is not None:
            depth = add_depth_noise(depth, self.noise, self.rng)
        arrays = [depth, target_mask(instance, x), collapse_mask(instance, moved)]
        if self.flip and self.rng.random() < 0.5:
            arrays = [a[:, ::-1] for a in arrays]
        names = ("depth_m", "target", "collapse")
        # np.array copies: an item never shares memory with the shard cache.
        return {
            k: torch.from_numpy(np.array(a, dtype=np.float32))[None] for k, a in zip(names, arrays)
        }


def shard_window_order(
    pair_shards: np.ndarray, window: int, rng: np.random.Generator
) -> np.ndarray:
    """A permutation of pair positions: shards in random order, taken `window` at a time,
    the pairs of each window shuffled together. Every pair once; while a window is read only
    its `window` shards are in use, so an LRU cache of that many shards reads each once."""
    by_shard = np.argsort(pair_shards, kind="stable")
    _, starts = np.unique(pair_shards[by_shard], return_index=True)
    groups = np.split(by_shard, starts[1:]) if len(by_shard) else []
    visit = rng.permutation(len(groups))
    parts = [
        rng.permutation(np.concatenate([groups[g] for g in visit[w : w + window]]))
        for w in range(0, len(visit), window)
    ]
    return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)


class ShardShuffleSampler(Sampler[int]):
    """Shuffled epochs that stay shard-local (shard_window_order); epoch e is seeded by
    (seed, e), so the same seed gives the same sequence of epochs."""

    def __init__(self, pair_shards: np.ndarray, window: int, seed: int):
        super().__init__()
        if window < 1:
            raise ValueError("window must be >= 1")
        self.pair_shards, self.window, self.seed = np.asarray(pair_shards), window, seed
        self.epoch = 0

    def __len__(self) -> int:
        return len(self.pair_shards)

    def __iter__(self) -> Iterator[int]:
        rng = np.random.default_rng([self.seed, self.epoch])
        self.epoch += 1
        return iter(shard_window_order(self.pair_shards, self.window, rng).tolist())
