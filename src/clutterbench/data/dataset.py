"""PyTorch Datasets over (scene, target) pairs and, for thesis ch. 4, (scene, extract,
support) triples; masks and labels derived at load time.

Shards are read lazily (clutterbench.data.shards): memory holds the pair index and a few
shards, whatever the dataset's size. Training draws batches with SceneGroupBatchSampler: a
shuffled epoch still reads each shard once, and a batch takes each of its scenes' targets
together so that the depth image is encoded once for them (GroupedLoader, Dataset.batch).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset, Sampler

from clutterbench.data.labels import (
    CLASS_C,
    LABEL_ARRAYS,
    LABEL_KINDS,
    ch4_class_map,
    collapse_mask,
    label_matrix,
    target_mask,
)
from clutterbench.data.shards import SceneColumns, ShardStore, load_split
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.noise import DepthAugmentation

CACHE_SHARDS = 4
"""Shards kept decompressed per dataset; also the shuffle window of SceneGroupBatchSampler."""


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
        noise: DepthAugmentation | None = None,
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

    def group_sampler(self, batch_size: int, group: int, seed: int) -> SceneGroupBatchSampler:
        """Shuffled batches of `batch_size` samples in which a scene's samples come together,
        in runs of at most `group` (scene_group_order); each shard read once per epoch."""
        return SceneGroupBatchSampler(
            self.pairs[:, 0], self.index.shard, self.store.cache_shards, batch_size, group, seed
        )

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        """Sample `i`: depth_m (1, H, W) and the sample's masks and labels."""
        batch = self.batch([i])
        del batch["scene_of"]
        return {k: v[0] for k, v in batch.items()}

    def batch(self, indices: Sequence[int]) -> dict[str, torch.Tensor]:
        """Samples `indices` as one batch grouped by scene: depth_m (S, 1, H, W) once per run
        of consecutive samples of the same scene, scene_of (P,) int64 (the depth image of
        each sample), and the samples' masks and labels stacked (P, ...). A run shares its
        augmentation (the depth noise, the flip), as the targets of one observed scene do."""
        depths: list[np.ndarray] = []
        scene_of: list[int] = []
        items: list[dict[str, np.ndarray]] = []
        last = -1
        for i in indices:
            row = self.pairs[int(i)]
            s = int(row[0])
            shard = self.store.load(int(self.index.shard[s]), self.arrays)
            r, n = int(self.index.row[s]), int(self.index.n_objects[s])
            if s != last:
                flip = self._draw_augmentation(shard["depth_m"][r], depths)
                last = s
            item = self._sample(shard, r, n, row[1:])
            items.append({k: a[..., ::-1] for k, a in item.items()} if flip else item)
            scene_of.append(len(depths) - 1)
        out = {"depth_m": _float_tensor(np.stack(depths))[:, None]}
        out["scene_of"] = torch.tensor(scene_of, dtype=torch.int64)
        for k in items[0] if items else ():
            stacked = np.stack([item[k] for item in items])
            if k == "classes":
                out[k] = torch.from_numpy(np.array(stacked, dtype=np.int64))
            else:
                out[k] = _float_tensor(stacked)
        return out

    def _draw_augmentation(self, depth_m: np.ndarray, depths: list[np.ndarray]) -> bool:
        """Append `depth_m` to `depths`, noised (if configured) and flipped left-right with
        probability 1/2 (if configured); returns whether it was flipped."""
        if self.noise is not None:
            depth_m = self.noise.apply(depth_m, self.rng)
        flip = bool(self.flip and self.rng.random() < 0.5)
        depths.append(depth_m[..., ::-1] if flip else depth_m)
        return flip

    arrays: tuple[str, ...] = ("depth_m", "instance")
    """Shard arrays a sample is built from."""

    def _sample(
        self, shard: dict[str, np.ndarray], r: int, n: int, sample: np.ndarray
    ) -> dict[str, np.ndarray]:
        """The masks and labels (each with a leading channel axis, (1 or 2, H, W), except
        `classes` (H, W)) of the sample `sample` (its row of `pairs` after the scene) of
        scene row `r` (n boxes) of `shard`."""
        raise NotImplementedError

    def pair_collapses(self, i: int) -> bool:
        """Whether some box moves in sample `i` (reads its scene's shard)."""
        raise NotImplementedError


def _float_tensor(a: np.ndarray) -> torch.Tensor:
    # np.array copies: an item never shares memory with the shard cache.
    return torch.from_numpy(np.array(a, dtype=np.float32))


class CollapseDataset(_ShardPairs):
    """Items are dicts of float32 tensors (1, H, W): depth_m, target, and collapse (K, H, W):
    one channel per label kind of `labels`, in that order (data.labels.LABEL_KINDS: the
    boxes that move when the target is deleted, or when the trials pull it out).

    One item per (scene, target box) pair: thesis 5.2.2 / 6.2.1 sample a target per
    simulation; we use every visible box of every scene, since the removal matrix labels
    them all. `scenes[key]` gives a split's per-scene arrays (image arrays read lazily).
    """

    n_masks = 1
    arrays = ("depth_m", "instance", "removal_m")

    def __init__(
        self,
        gen_dir: Path,
        *args,
        labels: Sequence[str] = ("deletion",),
        collapse_free: tuple[float, float] | None = None,
        **kwargs,
    ):
        super().__init__(gen_dir, *args, **kwargs)
        self.labels = tuple(labels)
        unknown = [k for k in self.labels if k not in LABEL_KINDS]
        if unknown or not self.labels or len(set(self.labels)) < len(self.labels):
            raise ClutterbenchError(
                f"labels {list(self.labels)}: each of {', '.join(LABEL_KINDS)} at most once"
            )
        if "pull_collapse" in self.labels and collapse_free is None:
            raise ClutterbenchError(
                "labels pull_collapse need the collapse-free thresholds (trials.collapse_free)"
            )
        self.collapse_free = collapse_free
        """(drop_m, tilt_deg) of the pull_collapse labels (trials.collapse_free)."""
        need = dict.fromkeys(a for k in self.labels for a in LABEL_ARRAYS[k])
        pulled = {a for k in self.labels if k != "deletion" for a in LABEL_ARRAYS[k]}
        if not pulled <= set(self.store.array_names()):
            name = self.store.dataset
            raise ClutterbenchError(
                f"dataset '{name}' holds no pull labels (pullout_*); generate it with "
                f"generate.datasets.{name}.pull_outcomes: true"
            )
        if self.labels != ("deletion",):
            self.arrays = ("depth_m", "instance", *need)

    def _moved(self, row: Callable[[str], np.ndarray], n: int, kind: str) -> np.ndarray:
        """(n, n) bool moved matrix of one scene under label kind `kind`; row(key) is the
        scene's array `key`."""
        return label_matrix(kind, row, n, self.threshold_m, self.collapse_free)

    def _sample(
        self, shard: dict[str, np.ndarray], r: int, n: int, sample: np.ndarray
    ) -> dict[str, np.ndarray]:
        x = int(sample[0])
        instance = shard["instance"][r]
        maps = [
            collapse_mask(instance, self._moved(lambda k: shard[k][r], n, kind)[x])
            for kind in self.labels
        ]
        return {"target": target_mask(instance, x)[None], "collapse": np.stack(maps)}

    def pair_collapses(self, i: int) -> bool:
        """Whether some box moves in sample `i` under any of its label kinds."""
        s, x = (int(v) for v in self.pairs[i])
        n = int(self.index.n_objects[s])
        row = lambda k: self.scenes[k][s]  # noqa: E731
        return any(bool(self._moved(row, n, kind)[x].any()) for kind in self.labels)


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

    arrays = ("depth_m", "instance", "pull_m")

    def _sample(
        self, shard: dict[str, np.ndarray], r: int, n: int, sample: np.ndarray
    ) -> dict[str, np.ndarray]:
        x, sup = (int(v) for v in sample)
        instance = shard["instance"][r]
        classes = ch4_class_map(instance, x, sup, shard["pull_m"][r, x, sup, :n], self.threshold_m)
        return {
            "target": np.stack([target_mask(instance, x), target_mask(instance, sup)]),
            "collapse": (classes == CLASS_C)[None],
            "classes": classes,
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


def open_pairs(
    n_masks: int,
    *args,
    labels: Sequence[str] = ("deletion",),
    collapse_free: tuple[float, float] | None = None,
    **kwargs,
) -> PairDataset:
    """The dataset for a network with `n_masks` input masks (arguments as CollapseDataset):
    (scene, target) pairs labelled by removal and / or the trials' pull (`labels`, one
    channel each), or (scene, extract, support) labelled by pulling (thesis ch. 4)."""
    if n_masks not in DATASETS:
        raise ClutterbenchError(f"no dataset feeds {n_masks} masks (known: {sorted(DATASETS)})")
    if n_masks == CollapseDataset.n_masks:
        return CollapseDataset(*args, labels=labels, collapse_free=collapse_free, **kwargs)
    if tuple(labels) != ("deletion",):
        raise ClutterbenchError(f"labels {list(labels)}: {n_masks}-mask samples have their own")
    return DATASETS[n_masks](*args, **kwargs)


def scene_group_order(
    pair_scenes: np.ndarray,
    scene_shards: np.ndarray,
    window: int,
    group: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """A permutation of sample positions in which each scene's samples come in runs of at
    most `group` (a scene with more samples, e.g. the 90 ordered pairs of a 10-box ch. 4
    pile, is cut into several runs, which meet again only by chance). Shards are visited in
    random order, `window` at a time; the runs of a window are shuffled together, the
    samples of a run too, so an LRU cache of `window` shards reads each shard once per
    epoch."""
    if group < 1:
        raise ValueError("group must be >= 1")
    by_scene = np.argsort(pair_scenes, kind="stable")
    scenes, starts = np.unique(pair_scenes[by_scene], return_index=True)
    samples = np.split(by_scene, starts[1:]) if len(by_scene) else []
    shards = scene_shards[scenes]
    parts = []
    visit = rng.permutation(np.unique(shards))
    for w in range(0, len(visit), window):
        runs = []
        for k in np.flatnonzero(np.isin(shards, visit[w : w + window])):
            mine = rng.permutation(samples[k])
            runs += [mine[j : j + group] for j in range(0, len(mine), group)]
        parts += [runs[j] for j in rng.permutation(len(runs))]
    return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)


class SceneGroupBatchSampler(Sampler[list[int]]):
    """Batches of `batch_size` sample positions (the last may be smaller) cut from
    scene_group_order: a batch holds few scenes, each with several targets, so the depth
    encoder runs once per scene (Dataset.batch, collapse.train). Epoch e is seeded by
    (seed, e)."""

    def __init__(
        self,
        pair_scenes: np.ndarray,
        scene_shards: np.ndarray,
        window: int,
        batch_size: int,
        group: int,
        seed: int,
    ):
        super().__init__()
        if window < 1 or batch_size < 1 or group < 1:
            raise ValueError("window, batch_size and group must be >= 1")
        self.pair_scenes, self.scene_shards = np.asarray(pair_scenes), np.asarray(scene_shards)
        self.window, self.batch_size, self.group, self.seed = window, batch_size, group, seed
        self.epoch = 0

    def __len__(self) -> int:
        return -(-len(self.pair_scenes) // self.batch_size)

    def __iter__(self) -> Iterator[list[int]]:
        rng = np.random.default_rng([self.seed, self.epoch])
        self.epoch += 1
        order = scene_group_order(
            self.pair_scenes, self.scene_shards, self.window, self.group, rng
        ).tolist()
        return iter([order[j : j + self.batch_size] for j in range(0, len(order), self.batch_size)])


class GroupedLoader:
    """Batches of a dataset (its `batch`: a scene's consecutive samples share one depth
    image) in the order of a batch sampler, or, without one, in order `batch_size` at a time
    (samples are stored scene by scene, so a batch holds few scenes)."""

    def __init__(
        self,
        dataset: PairDataset,
        batch_size: int | None = None,
        sampler: Sampler[list[int]] | None = None,
    ):
        if (batch_size is None) == (sampler is None):
            raise ValueError("give batch_size or sampler")
        self.dataset, self.batch_size, self.sampler = dataset, batch_size, sampler

    def _batches(self) -> Iterator[list[int]]:
        if self.sampler is not None:
            return iter(self.sampler)
        n, b = len(self.dataset), self.batch_size
        return (list(range(j, min(j + b, n))) for j in range(0, n, b))

    def __len__(self) -> int:
        if self.sampler is not None:
            return len(self.sampler)
        return -(-len(self.dataset) // self.batch_size)

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        return (self.dataset.batch(indices) for indices in self._batches())
