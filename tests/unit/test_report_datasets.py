"""Datasets table statistics on two hand-made shards: realized mix beside params' ask."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from clutterbench.data import shards as shards_module
from clutterbench.data.config import DatasetConfig
from clutterbench.io import save_npz, write_json
from clutterbench.report.datasets import dataset_stats, datasets_table
from clutterbench.sim.config import REJECT_REASONS

NAN = np.nan
ASKED = DatasetConfig(
    n_scenes=5, families={"shelved": 1, "stacked": 1, "random": 3}, n_objects=(2, 4)
)


def rejected(*scenes: dict[str, int]) -> np.ndarray:
    """(S, reasons) rejection counts, naming only the non-zero ones."""
    return np.array([[s.get(r, 0) for r in REJECT_REASONS] for s in scenes], np.int32)


def by_reason(**counts: int) -> dict[str, int]:
    return dict.fromkeys(REJECT_REASONS, 0) | counts


def removal(*rows: list[float]) -> np.ndarray:
    """A 3x3 removal matrix (m) padded with NaN beyond the given rows."""
    out = np.full((3, 3), NAN, np.float32)
    out[: len(rows), : len(rows)] = rows
    return out


SHARDS = [
    {
        "scene_index": np.array([0, 1, 2]),
        "n_objects": np.array([2, 3, 2], np.int16),
        "family": np.array(["shelved", "random", "random"]),
        # moved (> 5 mm) per removal: scene 0 -> [1, 0], scene 1 -> [2, 0, 1], scene 2 -> [0, 0]
        "removal_m": np.stack(
            [
                removal([0, 0.01], [0.001, 0]),
                removal([0, 0.01, 0.01], [0, 0, 0], [0.01, 0, 0]),
                removal([0, 0], [0, 0]),
            ]
        ),
        "rejected": rejected({"moving": 1, "no_room": 2}, {"fell": 1}, {}),
    },
    {
        "scene_index": np.array([3, 4]),
        "n_objects": np.array([3, 3], np.int16),
        "family": np.array(["random", "stacked"]),
        "removal_m": np.stack([removal([0] * 3, [0] * 3, [0] * 3)] * 2),
        "rejected": rejected({"no_room": 1}, {"moving": 2}),
    },
]


@pytest.fixture()
def gen(tmp_path) -> Path:
    for k, arrays in enumerate(SHARDS):
        images = np.zeros((len(arrays["n_objects"]), 8, 8), np.float32)
        save_npz(
            tmp_path / f"gen/toy/shard-{k:05d}.npz",
            {**arrays, "depth_m": images, "config_hash": np.array("h")},
        )
    manifest = {
        "dataset": "toy",
        "config_hash": "h",
        "n_scenes": 5,
        "shards": ["shard-00000.npz", "shard-00001.npz"],
        "families": {"random": 3, "shelved": 1, "stacked": 1},
        "rejected": by_reason(fell=1, moving=3, no_room=3),
    }
    write_json(tmp_path / "gen/toy/manifest.json", manifest)
    split = {"dataset": "toy", "config_hash": "h", "train": [0, 1, 2], "val": [3], "test": [4]}
    write_json(tmp_path / "split/toy.json", split)
    return tmp_path


def test_realized_mix_beside_the_asked_one(gen):
    s = dataset_stats(gen / "gen", gen / "split", "toy", 0.005, pulls=False, ds=ASKED)
    assert s["n_samples"] == 2 + 3 + 2 + 3 + 3
    assert s["objects_mean"] == pytest.approx(13 / 5)
    assert s["objects_mean_asked"] == 3.0
    assert s["moved_per_removal"] == pytest.approx((0.5 + 1.0) / 5)
    assert s["family_share"] == pytest.approx({"random": 0.6, "shelved": 0.2, "stacked": 0.2})
    assert s["family_share_asked"] == pytest.approx({"random": 0.6, "shelved": 0.2, "stacked": 0.2})
    assert s["objects_hist"] == {"2": 2, "3": 3, "4": 0}
    assert s["objects_hist_asked"] == pytest.approx({"2": 5 / 3, "3": 5 / 3, "4": 5 / 3})
    assert s["rejected_by_family"] == {
        "random": by_reason(fell=1, no_room=1),
        "shelved": by_reason(moving=1, no_room=2),
        "stacked": by_reason(moving=2),
    }
    assert (s["train"], s["val"], s["test"]) == (3, 1, 1)


def test_pulls_count_target_support_samples(gen):
    s = dataset_stats(gen / "gen", gen / "split", "toy", 0.005, pulls=True)
    assert s["n_samples"] == 4 + 9 + 4 + 9 + 9
    assert s["objects_mean_asked"] is None and s["objects_hist"] == {"2": 2, "3": 3}


def test_statistics_never_read_images(gen, monkeypatch):
    real = shards_module.load_npz

    def no_images(path, keys=None):
        assert keys is not None and not {"depth_m", "instance"} & set(keys), keys
        return real(path, keys)

    monkeypatch.setattr(shards_module, "load_npz", no_images)
    dataset_stats(gen / "gen", gen / "split", "toy", 0.005, pulls=False, ds=ASKED)


def test_tables_show_asked_beside_realized(gen, tmp_path):
    stats = {"toy": dataset_stats(gen / "gen", gen / "split", "toy", 0.005, False, ASKED)}
    datasets_table(stats, {"datasets": {"rows": []}}, tmp_path / "tables")
    families = pd.read_csv(tmp_path / "tables/datasets_families.csv").set_index("family")
    assert families.loc["random", "share"] == pytest.approx(0.6)
    assert families.loc["stacked", "share asked"] == pytest.approx(0.2)
    assert families.loc["stacked", "rejected: moving"] == 2
    assert families.loc["random", "rejected / scene"] == pytest.approx(2 / 3)
    objects = pd.read_csv(tmp_path / "tables/datasets_objects.csv").set_index("objects")
    assert objects.loc[4, "scenes"] == 0 and objects.loc[4, "scenes asked"] == pytest.approx(5 / 3)
    assert (
        "| toy | random | 3 | 0.600 | 0.600 |"
        in (tmp_path / "tables/datasets_families.md").read_text()
    )
    assert "objects / scene asked" in (tmp_path / "tables/datasets.md").read_text()


def test_cluster_classes_counted_per_split(tmp_path):
    # scenes 0, 1 train, scene 2 test; scene 1's C^l cluster shows no pixel
    classes = np.array([[0, 2, -1], [1, 3, -1], [1, 1, 2]], np.int8)
    boxes = np.zeros((3, 3, 4), np.float32)
    boxes[classes >= 0] = [10, 10, 4, 4]
    boxes[1, 1] = 0
    save_npz(
        tmp_path / "gen/toy/shard-00000.npz",
        {
            **{k: v[:3] for k, v in SHARDS[0].items()},
            "cluster_class": classes,
            "cluster_bbox_px": boxes,
            "config_hash": np.array("h"),
        },
    )
    write_json(
        tmp_path / "gen/toy/manifest.json",
        {
            "dataset": "toy",
            "config_hash": "h",
            "n_scenes": 3,
            "shards": ["shard-00000.npz"],
            "families": {"random": 2, "shelved": 1},
            "rejected": by_reason(),
        },
    )
    split = {"dataset": "toy", "config_hash": "h", "train": [0, 1], "val": [], "test": [2]}
    write_json(tmp_path / "split/toy.json", split)
    s = dataset_stats(tmp_path / "gen", tmp_path / "split", "toy", 0.005, pulls=False)
    assert s["clusters"]["train"] == {"C^h": 1, "C^v": 1, "C^r": 1, "C^l": 0}
    assert s["clusters"]["test"] == {"C^h": 0, "C^v": 2, "C^r": 1, "C^l": 0}
    assert sum(s["clusters"]["val"].values()) == 0
    datasets_table({"toy": s}, {"datasets": {"rows": []}}, tmp_path / "tables")
    table = pd.read_csv(tmp_path / "tables/datasets_clusters.csv").set_index("split")
    assert table.loc["test", "C^v"] == 2 and table.loc["train", "clusters"] == 3
    assert table.loc["train", "scenes"] == 2 and "val" not in table.index  # no val scenes
