"""Collapse network designs at equal training time: each design trains for as many epochs as
its measured speed fits in the same minutes, and the one with the best validation IoU is
named."""

from __future__ import annotations

import copy
from pathlib import Path

import pandas as pd
import pytest

from clutterbench.collapse.designs import best_rows, compare_designs
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.data.synthetic import write_synthetic_dataset
from clutterbench.errors import ClutterbenchError
from tests.toy_params import toy_train_params


def params(designs: dict) -> dict:
    p = copy.deepcopy(toy_train_params(12))
    p["designs"] = {"model": "m", "minutes": 0.02, "probe_batches": 3, "designs": designs}
    return p


def test_each_design_gets_the_same_minutes_and_the_best_val_iou_is_chosen(tmp_path: Path):
    data = tmp_path / "data"
    write_synthetic_dataset(data / "generate", "toy", 12, 4, 32, (2, 4))
    split_dataset("toy", Fractions(0.75, 0.25, 0.0), 0, data / "generate", data / "split")
    designs = {"full": {}, "half": {"output_stride": 2}}
    rows = compare_designs(params(designs), data, tmp_path / "out")
    assert {r["design"] for r in rows} == set(designs)
    for r in rows:  # epochs sized by the design's own speed: minutes x pairs/s of pairs
        assert r["epochs"] == max(1, round(0.02 * 60 * r["pairs_per_s"] / r["train_pairs"]))
        # the row's rate is rounded to 0.1 pairs/s: on a loaded machine (a few pairs/s) that
        # alone moves the minutes by a few percent
        assert r["minutes"] == pytest.approx(
            r["epoch"] * r["train_pairs"] / r["pairs_per_s"] / 60,
            rel=0.05 / r["pairs_per_s"],
            abs=1e-3,
        )
    assert rows[-1]["parameters"] < rows[0]["parameters"]  # the half-size decoder is smaller
    best = best_rows(rows)
    assert [r["design"] for r in best] == ["full", "half"]
    chosen = max(best, key=lambda r: r["val_iou_best"])["design"]
    md = (tmp_path / "out/designs.md").read_text()
    assert f"| {chosen} **(chosen)** |" in md and md.count("(chosen)") == 1
    frame = pd.read_csv(tmp_path / "out/designs.csv")
    assert len(frame) == len(rows) and (tmp_path / "out/designs.png").stat().st_size > 0


def test_bad_designs_are_one_line_errors(tmp_path: Path):
    (tmp_path / "split").mkdir(parents=True)
    (tmp_path / "split/toy.json").write_text("{}")
    with pytest.raises(ClutterbenchError, match="no design"):
        compare_designs(params({}), tmp_path, tmp_path / "out")
    with pytest.raises(ClutterbenchError, match="output_stride"):
        compare_designs(params({"bad": {"output_stride": 3}}), tmp_path, tmp_path / "out")
