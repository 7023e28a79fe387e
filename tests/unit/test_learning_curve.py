"""The learning curve: the same training run on nested subsets of the training scenes."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.learning_curve import learning_curve, subset_split
from clutterbench.collapse.train import TrainPaths, train_model
from clutterbench.config import load_section
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.data.synthetic import write_synthetic_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json
from tests.toy_params import toy_train_params

RECORD = {"dataset": "toy", "config_hash": "h", "train": list(range(0, 40)), "val": [40, 41]}


def test_subsets_are_nested_seeded_and_leave_val_alone():
    quarter, half = (subset_split(RECORD, f, seed=0) for f in (0.25, 0.5))
    assert len(quarter["train"]) == 10 and len(half["train"]) == 20
    assert set(quarter["train"]) < set(half["train"]) < set(RECORD["train"])
    assert quarter["val"] == RECORD["val"] and quarter["config_hash"] == "h"
    assert subset_split(RECORD, 0.25, seed=0) == quarter
    assert subset_split(RECORD, 0.25, seed=1)["train"] != quarter["train"]
    assert len(subset_split(RECORD, 0.001, seed=0)["train"]) == 1
    with pytest.raises(ClutterbenchError, match="fraction 1.5"):
        subset_split(RECORD, 1.5, seed=0)


PARAMS = toy_train_params(12)


def test_each_point_trains_on_its_subset(tmp_path: Path):
    data = tmp_path / "data"
    write_synthetic_dataset(data / "generate", "toy", 12, 4, 32, (2, 4))
    split_dataset("toy", Fractions(0.75, 0.25, 0.0), 0, data / "generate", data / "split")
    # The full-data point is the pipeline's own train@m run.
    cfg = load_section(TrainConfig, "train", PARAMS)
    paths = TrainPaths(
        data / "generate",
        data / "split/toy.json",
        tmp_path / "models/m",
        tmp_path / "train/m",
        tmp_path / "timing/train_m.json",
    )
    full = train_model("m", cfg, 0.005, 0, paths)
    out = tmp_path / "curve"
    rows = learning_curve("m", [0.5], PARAMS, data, tmp_path / "train", tmp_path / "timing", out)
    assert [r["fraction"] for r in rows] == [0.5, 1.0]
    n_train = len(read_json(data / "split/toy.json")["train"])
    assert rows[0]["train_scenes"] == round(0.5 * n_train) and rows[1]["train_scenes"] == n_train
    assert rows[0]["train_pairs"] < rows[1]["train_pairs"] == full["train_pairs"]
    assert rows[1]["val_iou"] == full["best"]["val_iou"]
    frame = pd.read_csv(out / "m.csv")
    assert frame["train_scenes"].tolist() == [r["train_scenes"] for r in rows]
    assert (out / "m.png").stat().st_size > 0 and "Learning curve: m" in (out / "m.md").read_text()


def test_a_missing_full_run_is_one_clear_error(tmp_path: Path):
    data = tmp_path / "data"
    write_synthetic_dataset(data / "generate", "toy", 12, 4, 32, (2, 4))
    split_dataset("toy", Fractions(0.75, 0.25, 0.0), 0, data / "generate", data / "split")
    with pytest.raises(ClutterbenchError, match="run stage train@m first"):
        learning_curve("m", [0.5], PARAMS, data, tmp_path / "train", tmp_path / "t", tmp_path)
