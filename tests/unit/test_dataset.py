"""The lazy, sharded datasets: same items as loading everything, bounded memory,
shard-local shuffling, the split's data hash checked; ch. 4 pull samples and their flip."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import torch

from clutterbench.data import shards as shards_module
from clutterbench.data.dataset import (
    CollapseDataset,
    GroupedLoader,
    PullPairDataset,
    SceneGroupBatchSampler,
    open_pairs,
    scene_group_order,
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
from clutterbench.sim.noise import DepthNoiseConfig

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
    for _ in GroupedLoader(ds, sampler=ds.group_sampler(3, 2, seed=1)):
        pass
    assert set(reads.values()) == {1} and len(reads) == len(set(ds.pair_shards.tolist()))


def grouped_layout():
    """7 shards of 1-3 scenes of 1-9 samples; returns (pair_scenes, scene_shards)."""
    rng = np.random.default_rng(3)
    scene_shards = np.repeat(np.arange(7), [2, 1, 3, 2, 3, 1, 2])
    pair_scenes = np.repeat(np.arange(len(scene_shards)), rng.integers(1, 10, len(scene_shards)))
    return pair_scenes, scene_shards


def test_scene_group_order_is_a_shard_local_permutation_in_scene_runs():
    pair_scenes, scene_shards = grouped_layout()
    pair_shards = scene_shards[pair_scenes]
    order = scene_group_order(pair_scenes, scene_shards, 3, 2, np.random.default_rng(0))
    assert sorted(order.tolist()) == list(range(len(pair_scenes)))
    # Consecutive windows of 3, 3 then 1 shards, never mixed across windows.
    seen = list(dict.fromkeys(pair_shards[order].tolist()))
    windows = [set(seen[w : w + 3]) for w in range(0, 7, 3)]
    bounds = np.cumsum([0, *(np.isin(pair_shards, list(w)).sum() for w in windows)])
    for w, lo, hi in zip(windows, bounds[:-1], bounds[1:]):
        assert set(pair_shards[order[lo:hi]].tolist()) == w

    # A scene's samples come together when `group` allows it, and in pieces when not.
    def n_runs(group: int) -> int:
        o = scene_group_order(pair_scenes, scene_shards, 3, group, np.random.default_rng(0))
        return 1 + np.count_nonzero(np.diff(pair_scenes[o]))

    n_scenes = len(scene_shards)
    assert n_runs(9) == n_scenes and n_runs(2) > n_scenes
    assert order.tolist() != sorted(order.tolist())  # shuffled


def test_scene_group_order_visits_shards_in_random_order():
    pair_scenes, scene_shards = grouped_layout()
    firsts = {
        tuple(
            dict.fromkeys(
                scene_shards[pair_scenes[scene_group_order(pair_scenes, scene_shards, 1, 8, rng)]]
            )
        )
        for rng in map(np.random.default_rng, range(4))
    }
    assert len(firsts) > 1


def test_group_sampler_is_seeded_and_reshuffles_each_epoch():
    pair_scenes, scene_shards = grouped_layout()
    a, b = (SceneGroupBatchSampler(pair_scenes, scene_shards, 2, 5, 3, 7) for _ in range(2))
    first_a, first_b = list(a), list(b)
    assert first_a == first_b and len(first_a) == len(a) == -(-len(pair_scenes) // 5)
    assert all(len(batch) == 5 for batch in first_a[:-1])
    assert sorted(i for batch in first_a for i in batch) == list(range(len(pair_scenes)))
    assert list(a) != first_a  # epoch 2 differs from epoch 1
    assert list(SceneGroupBatchSampler(pair_scenes, scene_shards, 2, 5, 3, 8)) != first_a


@pytest.mark.parametrize("noise", [False, True])
def test_a_grouped_batch_gives_each_sample_its_own_scene(data, noise):
    """Dataset.batch: one depth image per run of a scene's samples, scene_of pointing each
    sample at it; masks and labels as the items themselves."""
    kw = {"noise": DepthNoiseConfig()} if noise else {}
    ds = open_ds(data, split="train", **kw)
    indices = [i for batch in ds.group_sampler(6, 3, seed=2) for i in batch][:12]
    batch = ds.batch(indices)
    scenes = ds.pairs[indices, 0]
    assert len(batch["depth_m"]) == 1 + np.count_nonzero(np.diff(scenes))
    assert len(batch["depth_m"]) < len(indices)  # some scene gives several samples
    plain = open_ds(data, split="train")
    for j, i in enumerate(indices):
        item = plain[i]
        depth = batch["depth_m"][int(batch["scene_of"][j])]
        for k in ("target", "collapse"):
            assert torch.equal(batch[k][j], item[k])
        if noise:  # noised, but around this sample's own scene
            assert 0 < float((depth - item["depth_m"]).abs().median()) < 0.01
        else:
            assert torch.equal(depth, item["depth_m"])


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
