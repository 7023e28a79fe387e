from __future__ import annotations

import pandas as pd
import pytest

from clutterbench.logs.csv_log import CsvLog


def test_rows_round_trip_through_pandas(tmp_path):
    log = CsvLog(tmp_path / "train.csv", ["epoch", "train_loss", "val_loss"])
    log.append({"epoch": 0, "train_loss": 0.5, "val_loss": 0.6})
    log.append({"epoch": 1, "train_loss": 0.25})
    frame = pd.read_csv(tmp_path / "train.csv")
    assert frame["epoch"].tolist() == [0, 1]
    assert frame["train_loss"].tolist() == [0.5, 0.25]
    assert list(tmp_path.iterdir()) == [tmp_path / "train.csv"]


def test_opening_starts_fresh_and_rows_are_appended_in_place(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("stale,file\n1,2\n")
    log = CsvLog(path, ["epoch", "loss"])
    assert path.read_text() == "epoch,loss\n"
    inode = path.stat().st_ino
    log.append({"epoch": 1, "loss": 0.5})
    log.append({"epoch": 2})
    assert path.read_text() == "epoch,loss\n1,0.5\n2,\n"
    assert path.stat().st_ino == inode  # appended to, not replaced by a rewritten copy


def test_a_row_with_unknown_columns_raises_and_writes_nothing(tmp_path):
    path = tmp_path / "log.csv"
    log = CsvLog(path, ["epoch", "loss"])
    log.append({"epoch": 1, "loss": 0.5})
    with pytest.raises(KeyError, match="unknown columns"):
        log.append({"epoch": 2, "lr": 1})
    assert path.read_text() == "epoch,loss\n1,0.5\n"
