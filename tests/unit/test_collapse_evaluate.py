"""The threshold reported beside the params one is never chosen on the test set; ch. 4
pull samples are evaluated per pair (Table 4.2)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from clutterbench.collapse.config import EvaluateConfig
from clutterbench.collapse.evaluate import (
    SplitRef,
    check_val_split,
    evaluate_checkpoint,
    evaluate_sets,
    val_chosen_threshold,
)
from clutterbench.collapse.figure import collapse_figure
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.data.synthetic import write_synthetic_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.models.checkpoint import save_checkpoint
from clutterbench.models.collapse_map import CollapseMapConfig, CollapseMapNet
from clutterbench.models.vgg import VGGConfig


def ref(dataset: str, split: str) -> SplitRef:
    return SplitRef(dataset, Path(f"data/split/{dataset}.json"), split, 0.005)


def test_val_split_of_the_evaluated_or_the_training_dataset_is_accepted():
    check_val_split(ref("ch5", "test"), ref("ch5", "val"), "ch5", "key")
    check_val_split(ref("ch6_test", "test"), ref("ch6", "val"), "ch6", "key")


def test_choosing_on_the_evaluated_split_or_an_unrelated_dataset_is_refused():
    with pytest.raises(ClutterbenchError, match="key: would choose the threshold on the eval"):
        check_val_split(ref("ch5", "val"), ref("ch5", "val"), "ch5", "key")
    with pytest.raises(ClutterbenchError, match="neither the evaluated dataset 'ch6_test'"):
        check_val_split(ref("ch6_test", "test"), ref("ch4_same", "val"), "ch5", "key")


# --- Table 4.2: ch. 4 pull samples, per-pair means at the run's threshold ---


@pytest.fixture(scope="module")
def piles(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("piles")
    write_synthetic_dataset(root / "gen", "piles", 10, 4, 32, (4, 6), pulls=True)
    split_dataset("piles", Fractions(0.6, 0.2, 0.2), 0, root / "gen", root / "split")
    return root


def pile_ref(root: Path, split: str) -> SplitRef:
    return SplitRef("piles", root / "split/piles.json", split, 0.005)


def test_perfect_pull_predictor_scores_one_per_pair(piles):
    test_ds = pile_ref(piles, "test").load(piles / "gen", n_masks=2)
    val_ds = pile_ref(piles, "val").load(piles / "gen", n_masks=2)
    cfg = EvaluateConfig(threshold=0.4, batch_size=7, figure_samples=3)
    result = evaluate_sets(test_ds, val_ds, lambda batch: batch["collapse"], cfg)
    m = result.metrics
    assert m["threshold"] == 0.4 and m["pairs"] == len(test_ds)
    empty = sum(not bool(test_ds[i]["collapse"].any()) for i in range(len(test_ds)))
    assert m["samples_empty_both"] == empty and 0 < empty < len(test_ds)
    for key in ("iou", "precision", "recall"):
        assert m[f"pair_mean_{key}"] == 1.0 and m[f"pair_mean_{key}_empty_as_one"] == 1.0
    assert m["pair_mean_iou_samples"] == len(test_ds) - empty
    assert result.samples["target"].shape[1:] == (2, 32, 32)
    collapse_figure(result.samples, "perfect", piles / "figure.png")
    assert (piles / "figure.png").stat().st_size > 1000

    nothing = evaluate_sets(test_ds, val_ds, lambda batch: 0 * batch["collapse"], cfg).metrics
    assert nothing["pair_mean_iou"] == 0.0 and nothing["pair_mean_recall"] == 0.0
    assert math.isnan(nothing["pair_mean_precision"])  # never predicted: undefined everywhere
    assert nothing["pair_mean_precision_empty_as_one"] == 1.0


def test_a_two_mask_checkpoint_is_evaluated_on_pull_samples(piles, tmp_path):
    torch.manual_seed(0)
    net = CollapseMapConfig(
        input_size=32,
        encoder=VGGConfig(width=0.0625),
        decoder_channels=(8, 8, 8, 8, 8),
        n_masks=2,
        n_classes=4,
    )
    save_checkpoint(tmp_path / "best.pt", "collapse_map", CollapseMapNet(net), {"dataset": "piles"})
    cfg = EvaluateConfig(threshold=0.4, batch_size=16, figure_samples=2)
    result = evaluate_checkpoint(
        tmp_path / "best.pt", piles / "gen", pile_ref(piles, "test"), pile_ref(piles, "val"), cfg
    )
    test_ds = pile_ref(piles, "test").load(piles / "gen", n_masks=2)
    assert result.metrics["pairs"] == len(test_ds) and 0 <= result.metrics["pair_mean_iou"] <= 1


def test_the_val_threshold_alone_is_the_one_a_whole_evaluation_chooses(piles, tmp_path):
    torch.manual_seed(1)
    net = CollapseMapConfig(
        input_size=32, encoder=VGGConfig(width=0.0625), decoder_channels=(8, 8, 8, 8, 8)
    )
    save_checkpoint(tmp_path / "best.pt", "collapse_map", CollapseMapNet(net), {"dataset": "piles"})
    cfg = EvaluateConfig(threshold=0.4, batch_size=16, figure_samples=2)
    whole = evaluate_checkpoint(
        tmp_path / "best.pt", piles / "gen", pile_ref(piles, "test"), pile_ref(piles, "val"), cfg
    ).metrics
    alone = val_chosen_threshold(tmp_path / "best.pt", piles / "gen", pile_ref(piles, "val"), cfg)
    assert alone["threshold"] == whole["val_chosen_threshold"]
    assert alone["iou"] == whole["val_iou_at_chosen"]
