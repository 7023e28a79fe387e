"""Reading generated data a shard at a time: manifests, checked split records, a shard cache.

A dataset is a manifest plus shards (data/generate/<name>/shard-NNNNN.npz). Decompressed, a
paper-scale dataset is ~16 GB (ch6: 50,000 scenes of 256x256 depth + instance images), so
nothing here holds more than a few shards, and of those only the arrays asked for.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.io import load_npz, npz_names, read_json


def read_manifest(gen_dir: Path, dataset: str) -> dict[str, Any]:
    path = Path(gen_dir) / dataset / "manifest.json"
    manifest = read_json(path)
    if not isinstance(manifest, dict) or not {"config_hash", "shards"} <= manifest.keys():
        raise ClutterbenchError(f"corrupt manifest {path}; rerun generate")
    return manifest


def load_split(split_file: Path, gen_dir: Path) -> dict[str, Any]:
    """The split record in `split_file`, checked against the data it names."""
    record = read_json(split_file)
    if not isinstance(record, dict) or "dataset" not in record:
        raise ClutterbenchError(f"corrupt split file {split_file}; rerun split")
    data_dir = Path(gen_dir) / record["dataset"]
    made_for, holds = record.get("config_hash"), read_manifest(gen_dir, record["dataset"])
    # Regenerated data reuses scene indices for different scenes: an old split would leak
    # scenes across train / test and mislabel what it names.
    if made_for != holds["config_hash"]:
        raise ClutterbenchError(
            f"{split_file} was made for data hash {made_for} but {data_dir} holds "
            f"{holds['config_hash']}; rerun split"
        )
    return record


class ShardStore:
    """A dataset's shards, decompressed on demand array by array; the `cache_shards` most
    recently used shards stay in memory (LRU)."""

    def __init__(self, gen_dir: Path, dataset: str, cache_shards: int = 4):
        if cache_shards < 1:
            raise ValueError("cache_shards must be >= 1")
        self.dataset = dataset
        self.manifest = read_manifest(gen_dir, dataset)
        self.paths = [Path(gen_dir) / dataset / name for name in self.manifest["shards"]]
        self.cache_shards = cache_shards
        self._cache: OrderedDict[int, dict[str, np.ndarray]] = OrderedDict()

    @property
    def n_shards(self) -> int:
        return len(self.paths)

    def load(self, shard: int, keys: Sequence[str]) -> dict[str, np.ndarray]:
        """Arrays `keys` of shard `shard` (all its scenes); reads only what is not cached."""
        entry = self._cache.pop(shard, None)
        if entry is None:
            entry = {}
            while len(self._cache) >= self.cache_shards:
                self._cache.popitem(last=False)
        self._cache[shard] = entry  # most recently used last
        todo = [k for k in keys if k not in entry]
        if todo:
            fresh = "config_hash" not in entry
            entry.update(load_npz(self.paths[shard], todo + ["config_hash"] * fresh))
            if fresh and str(entry["config_hash"]) != self.manifest["config_hash"]:
                raise ClutterbenchError(
                    f"{self.paths[shard]} was made under another config than its manifest; "
                    "rerun generate"
                )
        return {k: entry[k] for k in keys}

    def array(self, shard: int, key: str) -> np.ndarray:
        return self.load(shard, (key,))[key]

    def array_names(self) -> list[str]:
        """Names of the per-scene arrays (as the first shard holds them)."""
        names = npz_names(self.paths[0]) if self.paths else []
        return [n for n in names if n != "config_hash"]

    def cached_shards(self) -> list[int]:
        """Shards in memory, least recently used first."""
        return list(self._cache)


def iter_shards(
    gen_dir: Path, dataset: str, keys: Sequence[str]
) -> Iterator[dict[str, np.ndarray]]:
    """Arrays `keys` of each shard in turn; one shard in memory at a time."""
    store = ShardStore(gen_dir, dataset, cache_shards=1)
    for shard in range(store.n_shards):
        yield store.load(shard, keys)


class LazyColumn:
    """One array of a selection of scenes, read from the scene's shard when indexed:
    column[s] or column[s, ...] (s: position in the selection)."""

    def __init__(self, store: ShardStore, shards: np.ndarray, rows: np.ndarray, key: str):
        self.store, self.shards, self.rows, self.key = store, shards, rows, key

    def __len__(self) -> int:
        return len(self.rows)

    def _first(self) -> np.ndarray:
        return self.store.array(int(self.shards[0]) if len(self) else 0, self.key)

    @property
    def shape(self) -> tuple[int, ...]:
        return (len(self), *self._first().shape[1:])

    @property
    def dtype(self) -> np.dtype:
        return self._first().dtype

    def __getitem__(self, index: Any) -> np.ndarray:
        first, rest = (index[0], index[1:]) if isinstance(index, tuple) else (index, ())
        if not isinstance(first, int | np.integer):
            raise TypeError(f"'{self.key}' is read lazily: index one scene at a time")
        s = range(len(self))[first]  # bounds and negative indices as a list has them
        return self.store.array(int(self.shards[s]), self.key)[self.rows[s]][rest]


class SceneColumns(Mapping):
    """Mapping array name -> the selected scenes' array: small per-scene arrays held in
    memory (`resident`), every other one a LazyColumn."""

    def __init__(
        self,
        store: ShardStore,
        shards: np.ndarray,
        rows: np.ndarray,
        resident: Mapping[str, np.ndarray],
        names: Sequence[str],
    ):
        self.store, self.shards, self.rows = store, shards, rows
        self.resident, self.names = dict(resident), list(names)

    def __getitem__(self, key: str) -> np.ndarray | LazyColumn:
        if key in self.resident:
            return self.resident[key]
        if key not in self.names:
            raise KeyError(key)
        return LazyColumn(self.store, self.shards, self.rows, key)

    def __iter__(self) -> Iterator[str]:
        return iter(self.names)

    def __len__(self) -> int:
        return len(self.names)
