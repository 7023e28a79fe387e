"""The lazy, sharded datasets: same items as loading everything, bounded memory,
shard-local shuffling, the split's data hash checked; ch. 4 pull samples and their flip."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from clutterbench.data import shards as shards_module
from clutterbench.data.dataset import (
    CollapseDataset,
    PullPairDataset,
    ShardShuffleSampler,
    open_pairs,
    shard_window_order,
)
from clutterbench.data.labels import (
    CLASS_C,
    ch4_class_map,
    collapse_mask,
    moved_matrix,
    target_mask,
)
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.data.synthetic import write_synthetic_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.io import load_npz, read_json, write_json

SHARD_SIZE, N_SCENES, SIZE = 4, 22, 32  # 6 shards, the last one short


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("data")
    write_synthetic_dataset(root / "gen", "toy", N_SCENES, SHARD_SIZE, SIZE, (2, 5))
    split_dataset("toy", Fractions(0.6, 0.2, 0.2), 0, root / "gen", root / "split")
    return root


def open_ds(data: Path, split: str = "train", **kw) -> CollapseDataset:
    return CollapseDataset(data / "gen", data / "split/toy.json", split, 0.005, **kw)


def eager(data: Path) -> dict[str, np.ndarray]:
    """Every scene in memory, by scene index: the reference the lazy reads must match."""
    parts = [load_npz(p) for p in sorted((data / "gen/toy").glob("shard-*.npz"))]
    return {k: np.concatenate([p[k] for p in parts]) for k in ("depth_m", "instance", "removal_m")}


def test_items_match_the_eagerly_loaded_scenes(data):
    ds, ref = open_ds(data), eager(data)
    split = read_json(data / "split/toy.json")["train"]
    assert ds.scenes["scene_index"].tolist() == split
    assert ds.scenes["depth_m"].shape == (len(split), SIZE, SIZE)
    assert len(ds) > len(split)  # several targets per scene
    for i in range(len(ds)):
        s, x = ds.pairs[i]
        scene = split[s]
        n = int(ds.scenes["n_objects"][s])
        moved = moved_matrix(ref["removal_m"][scene, :n, :n], 0.005)[x]
        item = ds[i]
        np.testing.assert_array_equal(item["depth_m"][0].numpy(), ref["depth_m"][scene])
        np.testing.assert_array_equal(item["target"][0], target_mask(ref["instance"][scene], x))
        truth = collapse_mask(ref["instance"][scene], moved)
        np.testing.assert_array_equal(item["collapse"][0], truth)
        np.testing.assert_array_equal(
            ds.scenes["removal_m"][s, :n, :n], ref["removal_m"][scene, :n, :n]
        )


def test_pairs_are_the_visible_boxes(data):
    ds, ref = open_ds(data, min_target_pixels=40), eager(data)
    split = read_json(data / "split/toy.json")["train"]
    expected = [
        (s, x)
        for s, scene in enumerate(split)
        for x in range(int(ds.scenes["n_objects"][s]))
        if (ref["instance"][scene] == x + 1).sum() >= 40
    ]
    assert [tuple(p) for p in ds.pairs.tolist()] == expected


def test_memory_holds_at_most_the_cached_shards(data):
    ds = open_ds(data, cache_shards=2)
    assert len(ds.store.cached_shards()) <= 2
    for i in range(len(ds)):
        ds[i]
        assert len(ds.store.cached_shards()) <= 2


def count_shard_reads(monkeypatch) -> Counter:
    reads: Counter = Counter()
    real = shards_module.load_npz

    def counting(path, keys=None):
        reads[Path(path).name] += 1
        return real(path, keys)

    monkeypatch.setattr(shards_module, "load_npz", counting)
    return reads


def test_a_shuffled_epoch_reads_each_shard_once(data, monkeypatch):
    ds = open_ds(data, split="train", cache_shards=2)
    reads = count_shard_reads(monkeypatch)
    for _ in DataLoader(ds, batch_size=3, sampler=ds.shard_sampler(seed=1)):
        pass
    assert set(reads.values()) == {1} and len(reads) == len(set(ds.pair_shards.tolist()))


def test_shard_window_order_is_a_shard_local_permutation():
    pair_shards = np.repeat(np.arange(7), [3, 1, 4, 2, 5, 3, 2])
    order = shard_window_order(pair_shards, 3, np.random.default_rng(0))
    assert sorted(order.tolist()) == list(range(len(pair_shards)))
    # Consecutive windows: pairs of 3, 3 then 1 shards, never mixed across windows.
    seen = []
    for shard in pair_shards[order]:
        if shard not in seen:
            seen.append(shard)
    windows = [set(seen[w : w + 3]) for w in range(0, 7, 3)]
    sizes = [sum(np.isin(pair_shards, list(w))) for w in windows]
    bounds = np.cumsum([0, *sizes])
    for w, lo, hi in zip(windows, bounds[:-1], bounds[1:]):
        assert set(pair_shards[order[lo:hi]].tolist()) == w
    assert order.tolist() != sorted(order.tolist())  # shuffled within windows


def test_shard_window_order_visits_shards_in_random_order():
    pair_shards = np.repeat(np.arange(6), 2)
    firsts = {
        tuple(dict.fromkeys(pair_shards[shard_window_order(pair_shards, 1, rng)].tolist()))
        for rng in map(np.random.default_rng, range(4))
    }
    assert len(firsts) > 1


def test_sampler_is_seeded_and_reshuffles_each_epoch():
    pair_shards = np.repeat(np.arange(10), 5)
    a, b = ShardShuffleSampler(pair_shards, 2, 7), ShardShuffleSampler(pair_shards, 2, 7)
    first_a, first_b = list(a), list(b)
    assert first_a == first_b and len(a) == 50
    assert list(a) != first_a  # epoch 2 differs from epoch 1
    assert list(ShardShuffleSampler(pair_shards, 2, 8)) != first_a


def test_split_made_for_other_data_is_refused(data, tmp_path):
    record = read_json(data / "split/toy.json")
    write_json(tmp_path / "toy.json", {**record, "config_hash": "0123abcd"})
    with pytest.raises(ClutterbenchError) as err:
        CollapseDataset(data / "gen", tmp_path / "toy.json", "train", 0.005)
    msg = str(err.value)
    assert "0123abcd" in msg and "synthetic" in msg and "rerun split" in msg
    assert "\n" not in msg


def test_split_naming_absent_scenes_is_refused(data, tmp_path):
    record = read_json(data / "split/toy.json")
    write_json(tmp_path / "toy.json", {**record, "train": [0, N_SCENES + 3]})
    with pytest.raises(ClutterbenchError, match=f"scene {N_SCENES + 3} "):
        CollapseDataset(data / "gen", tmp_path / "toy.json", "train", 0.005)


# --- thesis ch. 4: (scene, extract, support) samples labelled by the pull tensor ---


@pytest.fixture(scope="module")
def pulls(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("pulls")
    write_synthetic_dataset(root / "gen", "piles", 9, 4, SIZE, (4, 6), pulls=True)
    split_dataset("piles", Fractions(0.6, 0.2, 0.2), 0, root / "gen", root / "split")
    return root


def open_pulls(root: Path, split: str = "train", **kw) -> PullPairDataset:
    return PullPairDataset(root / "gen", root / "split/piles.json", split, 0.005, **kw)


def eager_pulls(root: Path) -> dict[str, np.ndarray]:
    parts = [load_npz(p) for p in sorted((root / "gen/piles").glob("shard-*.npz"))]
    return {k: np.concatenate([p[k] for p in parts]) for k in ("depth_m", "instance", "pull_m")}


def test_pull_samples_are_ordered_pairs_of_visible_boxes(pulls):
    ds, ref = open_pulls(pulls), eager_pulls(pulls)
    split = read_json(pulls / "split/piles.json")["train"]
    expected = []
    for s, scene in enumerate(split):
        visible = [
            x
            for x in range(int(ds.scenes["n_objects"][s]))
            if (ref["instance"][scene] == x + 1).sum() >= 10
        ]
        expected += [(s, x, y) for x in visible for y in visible if x != y]
    assert [tuple(p) for p in ds.pairs.tolist()] == expected and len(expected) > 20


def test_pull_items_are_the_class_maps_of_the_pull_tensor(pulls):
    ds, ref = open_pulls(pulls), eager_pulls(pulls)
    split = read_json(pulls / "split/piles.json")["train"]
    collapsing = 0
    for i in range(len(ds)):
        s, x, sup = ds.pairs[i]
        scene, n = split[s], int(ds.scenes["n_objects"][s])
        classes = ch4_class_map(
            ref["instance"][scene], x, sup, ref["pull_m"][scene, x, sup, :n], 0.005
        )
        item = ds[i]
        assert item["target"].shape == (2, SIZE, SIZE) and item["classes"].dtype == torch.int64
        np.testing.assert_array_equal(item["depth_m"][0], ref["depth_m"][scene])
        np.testing.assert_array_equal(item["target"][0], target_mask(ref["instance"][scene], x))
        np.testing.assert_array_equal(item["target"][1], target_mask(ref["instance"][scene], sup))
        np.testing.assert_array_equal(item["classes"], classes)
        np.testing.assert_array_equal(item["collapse"][0], classes == CLASS_C)
        # some other box moves (it may be hidden, so without C pixels)
        disp = np.delete(ref["pull_m"][scene, x, sup, :n], [x, sup])
        assert ds.pair_collapses(i) == bool((disp > 0.005).any())
        collapsing += ds.pair_collapses(i)
    assert 0 < collapsing < len(ds)  # both kinds of pairs are exercised


def test_flip_flips_image_masks_and_labels_together(pulls):
    plain = open_pulls(pulls)
    flipped_any = unflipped_any = False
    for seed in range(6):
        aug = open_pulls(pulls, flip=True, seed=seed)
        for i in (0, 7):
            a, b = plain[i], aug[i]
            flipped = {k: v.flip(-1) for k, v in a.items()}
            if all(torch.equal(b[k], flipped[k]) for k in a):
                flipped_any = True
            else:
                assert all(torch.equal(b[k], a[k]) for k in a), "flipped only some arrays"
                unflipped_any = True
    assert flipped_any and unflipped_any
    assert not torch.equal(plain[0]["classes"], plain[0]["classes"].flip(-1))  # flips show


def test_open_pairs_picks_the_samples_of_the_network_inputs(pulls, data):
    assert isinstance(
        open_pairs(2, pulls / "gen", pulls / "split/piles.json", "val", 0.005), PullPairDataset
    )
    assert isinstance(
        open_pairs(1, pulls / "gen", pulls / "split/piles.json", "val", 0.005), CollapseDataset
    )
    with pytest.raises(ClutterbenchError, match="dataset 'toy' holds no pull labels"):
        open_pairs(2, data / "gen", data / "split/toy.json", "val", 0.005)
    with pytest.raises(ClutterbenchError, match="no dataset feeds 3 masks"):
        open_pairs(3, data / "gen", data / "split/toy.json", "val", 0.005)
