"""PyTorch Datasets over (scene, target) pairs and, for thesis ch. 4, (scene, extract,
support) triples; masks and labels derived at load time.

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

from clutterbench.data.labels import (
    CLASS_C,
    ch4_class_map,
    collapse_mask,
    moved_matrix,
    target_mask,
)
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


class _ShardPairs(Dataset):
    """What the datasets share: the split's scenes read lazily from their shards, the
    samples of those scenes (`pairs`, one row per sample, scene position first), and the
    training augmentation (depth noise, left-right flip)."""

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
        self.pairs = self._samples(index.pairs)
        self.scenes = SceneColumns(
            self.store,
            index.shard,
            index.row,
            {"n_objects": index.n_objects, "scene_index": index.scene_index},
            self.store.array_names(),
        )
        self.threshold_m, self.noise, self.flip = threshold_m, noise, flip
        self.rng = np.random.default_rng(seed)

    def _samples(self, visible: np.ndarray) -> np.ndarray:
        """The samples, from the (scene position, visible box) pairs."""
        return visible

    def __len__(self) -> int:
        return len(self.pairs)

    @property
    def pair_shards(self) -> np.ndarray:
        """(P,) shard number of each pair's scene."""
        return self.index.shard[self.pairs[:, 0]]

    def shard_sampler(self, seed: int) -> ShardShuffleSampler:
        """A shuffling sampler whose window matches this dataset's shard cache."""
        return ShardShuffleSampler(self.pair_shards, self.store.cache_shards, seed)

    def _augment(self, depth_m: np.ndarray, images: list[np.ndarray]) -> list[np.ndarray]:
        """[depth, *images], depth noised (if configured) and all flipped left-right together
        with probability 1/2 (if configured). Images may have leading channel axes."""
        if self.noise is not None:
            depth_m = add_depth_noise(depth_m, self.noise, self.rng)
        arrays = [depth_m, *images]
        if self.flip and self.rng.random() < 0.5:
            arrays = [a[..., ::-1] for a in arrays]
        return arrays

    def pair_collapses(self, i: int) -> bool:
        """Whether some box moves in sample `i` (reads its scene's shard)."""
        raise NotImplementedError


def _float_tensor(a: np.ndarray) -> torch.Tensor:
    # np.array copies: an item never shares memory with the shard cache.
    return torch.from_numpy(np.array(a, dtype=np.float32))


class CollapseDataset(_ShardPairs):
    """Items are dicts of float32 tensors (1, H, W): depth_m, target, collapse.

    One item per (scene, target box) pair: thesis 5.2.2 / 6.2.1 sample a target per
    simulation; we use every visible box of every scene, since the removal matrix labels
    them all. `scenes[key]` gives a split's per-scene arrays (image arrays read lazily).
    """

    n_masks = 1

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        s, x = (int(v) for v in self.pairs[i])
        n = int(self.index.n_objects[s])
        shard = self.store.load(int(self.index.shard[s]), ("depth_m", "instance", "removal_m"))
        r = int(self.index.row[s])
        instance = shard["instance"][r]
        moved = moved_matrix(shard["removal_m"][r, :n, :n], self.threshold_m)[x]
        arrays = self._augment(
            shard["depth_m"][r], [target_mask(instance, x), collapse_mask(instance, moved)]
        )
        names = ("depth_m", "target", "collapse")
        return {k: _float_tensor(a)[None] for k, a in zip(names, arrays)}

    def pair_collapses(self, i: int) -> bool:
        s, x = (int(v) for v in self.pairs[i])
        n = int(self.index.n_objects[s])
        return bool(moved_matrix(self.scenes["removal_m"][s, :n, :n], self.threshold_m)[x].any())


def extract_support_pairs(visible: np.ndarray) -> np.ndarray:
    """(P, 2) (scene position, visible box) -> (Q, 3) (scene position, extract, support):
    every ordered pair of two different visible boxes of each scene, scene by scene."""
    rows = []
    scenes, starts = np.unique(visible[:, 0], return_index=True)
    for s, boxes in zip(scenes, np.split(visible[:, 1], starts[1:])):
        rows += [(s, x, y) for x in boxes for y in boxes if x != y]
    return np.array(rows, dtype=np.int64).reshape(-1, 3)


class PullPairDataset(_ShardPairs):
    """Thesis ch. 4 samples: one item per (scene, extract box, support box), both visible.

    Items: depth_m (1, H, W), target (2, H, W) = extraction and support masks (float32),
    collapse (1, H, W) = class C (float32), classes (H, W) int64 = the thesis Fig. 4.4 label
    map (values index data.labels.PULL_CLASSES). Labels come from the generated pull tensor
    pull_m[x, s, y] (generate.datasets.<d>.pulls: true).
    """

    n_masks = 2

    def __init__(self, gen_dir: Path, *args, **kwargs):
        super().__init__(gen_dir, *args, **kwargs)
        if "pull_m" not in self.store.array_names():
            raise ClutterbenchError(
                f"dataset '{self.store.dataset}' holds no pull labels (pull_m); generate it "
                "with pulls: true"
            )

    def _samples(self, visible: np.ndarray) -> np.ndarray:
        return extract_support_pairs(visible)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        s, x, sup = (int(v) for v in self.pairs[i])
        n = int(self.index.n_objects[s])
        shard = self.store.load(int(self.index.shard[s]), ("depth_m", "instance", "pull_m"))
        r = int(self.index.row[s])
        instance = shard["instance"][r]
        classes = ch4_class_map(instance, x, sup, shard["pull_m"][r, x, sup, :n], self.threshold_m)
        masks = np.stack([target_mask(instance, x), target_mask(instance, sup)])
        depth, masks, classes = self._augment(shard["depth_m"][r], [masks, classes])
        return {
            "depth_m": _float_tensor(depth)[None],
            "target": _float_tensor(masks),
            "collapse": _float_tensor(classes == CLASS_C)[None],
            "classes": torch.from_numpy(np.array(classes, dtype=np.int64)),
        }

    def pair_collapses(self, i: int) -> bool:
        s, x, sup = (int(v) for v in self.pairs[i])
        n = int(self.index.n_objects[s])
        moved = np.nan_to_num(self.scenes["pull_m"][s, x, sup, :n], nan=0.0) > self.threshold_m
        moved[[x, sup]] = False
        return bool(moved.any())


PairDataset = CollapseDataset | PullPairDataset
DATASETS: dict[int, type[CollapseDataset] | type[PullPairDataset]] = {
    CollapseDataset.n_masks: CollapseDataset,
    PullPairDataset.n_masks: PullPairDataset,
}
"""Number of network input masks -> the dataset that feeds such a network."""


def open_pairs(n_masks: int, *args, **kwargs) -> PairDataset:
    """The dataset for a network with `n_masks` input masks (arguments as CollapseDataset):
    (scene, target) pairs labelled by removal, or (scene, extract, support) labelled by
    pulling (thesis ch. 4)."""
    if n_masks not in DATASETS:
        raise ClutterbenchError(f"no dataset feeds {n_masks} masks (known: {sorted(DATASETS)})")
    return DATASETS[n_masks](*args, **kwargs)


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
