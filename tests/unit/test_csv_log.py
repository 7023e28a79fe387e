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
    with pytest.raises(KeyError, match="unknown columns"):
        log.append({"lr": 1})
