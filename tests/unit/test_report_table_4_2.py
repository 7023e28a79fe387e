"""Table 4.2 from evaluate metrics: per-pair means of class C beside the thesis' figures."""

from __future__ import annotations

import pandas as pd
import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.models.checkpoint import save_checkpoint
from clutterbench.models.collapse_map import CollapseMapConfig, CollapseMapNet
from clutterbench.models.vgg import VGGConfig
from clutterbench.report.table_4_2 import table_4_2
from clutterbench.report.tables import load_thesis_figures
from clutterbench.report.tables_5_1_6_1 import RunSources

ROWS = {
    "same_model/same_size_gt": "s_on_s",
    "same_model/various_size_gt": "s_on_v",
    "various_model/same_size_gt": "v_on_s",
    "various_model/various_size_gt": None,
}
RUN_MODELS = {"s_on_s": "ch4_same", "s_on_v": "ch4_same", "v_on_s": "ch4_various"}
TRAIN = {"lr": 0.001, "epochs": 4, "lr_schedule": "cosine", "batch_size": 16, "loss": "ce"}


def metrics(iou: float, dataset: str) -> dict:
    return {
        "model": "m",
        "dataset": dataset,
        "split": "test",
        "threshold": 0.4,
        "iou": 0.2,
        "pairs": 440,
        "scenes": 15,
        "pair_mean_iou": iou,
        "pair_mean_recall": 0.6,
        "pair_mean_precision": 0.5,
        "pair_mean_iou_empty_as_one": 0.7,
        "samples_empty_both": 100,
    }


@pytest.fixture()
def sources(tmp_path) -> RunSources:
    net = CollapseMapConfig(input_size=32, encoder=VGGConfig(width=0.0625), n_masks=2, n_classes=4)
    for model, dataset in (("ch4_same", "ch4_same"), ("ch4_various", "ch4_various")):
        meta = {"dataset": dataset, "image_size": 128, "train": TRAIN}
        save_checkpoint(
            tmp_path / "models" / model / "best.pt", "collapse_map", CollapseMapNet(net), meta
        )
        write_json(tmp_path / "train" / model / "summary.json", {"epochs_run": 3})
    for run, iou in (("s_on_s", 0.31), ("s_on_v", 0.32), ("v_on_s", 0.33)):
        dataset = "ch4_various" if run.endswith("_v") else "ch4_same"
        write_json(tmp_path / "eval" / run / "metrics.json", metrics(iou, dataset))
    return RunSources(tmp_path / "eval", tmp_path / "models", tmp_path / "train")


def test_table_4_2_puts_per_pair_means_beside_the_thesis(root, sources, tmp_path):
    figures = load_thesis_figures(root / "reports/thesis_figures.yaml")
    thresholds = dict.fromkeys(RUN_MODELS, 0.4)
    ours = table_4_2(ROWS, RUN_MODELS, thresholds, figures, sources, tmp_path / "t", "default")
    assert set(ours) == {r for r, run in ROWS.items() if run}
    frame = pd.read_csv(tmp_path / "t/table_4_2.csv")
    assert len(frame) == 4
    assert frame["avg. IoU"].tolist()[:3] == [0.31, 0.32, 0.33] and frame["avg. IoU"].isna()[3]
    # The thesis column is the data file's, row by row (its numbers live only there).
    thesis = {r["row"]: r for r in figures["table_4_2"]["rows"]}
    for key, column in (
        ("iou", "avg. IoU"),
        ("recall", "avg. recall"),
        ("precision", "avg. precision"),
    ):
        assert frame[f"{column} (thesis)"].tolist() == [thesis[row][key] for row in ROWS]
    assert frame["IoU over all pixels"].tolist()[:3] == [0.2] * 3
    label = frame.iloc[0, 0]
    assert label.startswith("Trained with same-size objects / Same-size target [s_on_s]")
    assert "[not run]" in frame.iloc[3, 0]
    differs = frame["differs from thesis"][0]
    assert "128 px (thesis 256)" in differs and "batch 16 (thesis 1)" in differs
    text = (tmp_path / "t/table_4_2.md").read_text()
    assert "P(C) > 0.4" in text and "thesis: 0.4" in text and "thesis: 100 samples" in text


def test_table_4_2_refuses_metrics_at_another_threshold(root, sources, tmp_path):
    figures = load_thesis_figures(root / "reports/thesis_figures.yaml")
    thresholds = dict.fromkeys(RUN_MODELS, 0.4) | {"s_on_v": 0.5}
    with pytest.raises(ClutterbenchError, match="s_on_v/metrics.json is at threshold 0.4, not 0.5"):
        table_4_2(ROWS, RUN_MODELS, thresholds, figures, sources, tmp_path / "t", "default")


def test_table_4_2_says_when_the_training_piles_differ_from_the_thesis(root, sources, tmp_path):
    figures = load_thesis_figures(root / "reports/thesis_figures.yaml")
    thresholds = dict.fromkeys(RUN_MODELS, 0.4)
    piles = {"ch4_same": (5, 10), "ch4_various": (6, 6)}
    table_4_2(ROWS, RUN_MODELS, thresholds, figures, sources, tmp_path / "t", "default", piles)
    differs = pd.read_csv(tmp_path / "t/table_4_2.csv")["differs from thesis"]
    assert "trained on scenes of 5-10 boxes (thesis 6)" in differs[0]
    assert "boxes (thesis" not in differs[2]  # ch4_various: piles of 6, as the thesis'
