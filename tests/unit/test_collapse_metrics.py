"""Focal loss (thesis eq. 6.1), pixel metrics (eq. 5.10, 5.11) and their per-pair means
(Table 4.2) against hand-computed values."""

import math

import numpy as np
import pytest
import torch

from clutterbench.collapse.losses import FocalConfig, bce_loss, focal_loss
from clutterbench.collapse.metrics import (
    PixelCounts,
    best_iou_row,
    pair_means,
    scores,
    sweep_row,
)
from clutterbench.collapse.predict import collapse_probs


def test_focal_loss_matches_hand_computed_values():
    # p = sigmoid(0) = 0.5 for a collapse pixel: -0.25 * 0.5^2 * ln 0.5 = 0.0433217
    # p(0) = 0.5 for a background pixel:        -0.75 * 0.5^2 * ln 0.5 = 0.1299651
    # p = sigmoid(ln 3) = 0.75, collapse pixel: -0.25 * 0.25^2 * ln 0.75 = 0.0044950
    logits = torch.tensor([0.0, 0.0, math.log(3.0)])
    target = torch.tensor([1.0, 0.0, 1.0])
    expected = (0.0433217 + 0.1299651 + 0.0044950) / 3
    assert float(focal_loss(logits, target, FocalConfig())) == pytest.approx(expected, abs=1e-6)


def test_focal_loss_with_gamma_zero_and_even_alpha_is_half_bce():
    logits = torch.randn(2, 1, 8, 8)
    target = (torch.rand(2, 1, 8, 8) > 0.7).float()
    cfg = FocalConfig(alpha_pos=0.5, alpha_neg=0.5, gamma=0.0)
    assert float(focal_loss(logits, target, cfg)) == pytest.approx(
        0.5 * float(bce_loss(logits, target)), rel=1e-5
    )


def test_scores_hand_computed():
    s = scores(tp=6, fp=2, fn=4, tn=88)
    assert s["pixel_accuracy"] == pytest.approx(94 / 100)
    assert s["iou"] == pytest.approx(6 / 12)
    assert s["precision"] == pytest.approx(6 / 8)
    assert s["recall"] == pytest.approx(6 / 10)
    assert math.isnan(scores(0, 0, 0, 5)["iou"])


def test_pixel_counts_threshold_is_strictly_greater_and_sweep_agrees():
    prob = torch.tensor([0.9, 0.5, 0.2, 0.7, 0.1, 0.55])
    truth = torch.tensor([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    counts = PixelCounts(0.5)
    counts.update(prob, truth)
    assert (counts.tp, counts.fp, counts.fn, counts.tn) == (1, 2, 2, 1)
    at_06 = counts.sweep()[60]
    assert at_06["threshold"] == pytest.approx(0.6)
    assert at_06["precision"] == pytest.approx(1 / 2)  # 0.9 and 0.7 are >= 0.6
    assert at_06["recall"] == pytest.approx(1 / 3)


def test_prob_exactly_at_the_threshold_is_negative_in_summary_and_sweep():
    # 0.5 and 0.25 are exact in float32: a pixel at the threshold is not "higher than" it.
    prob = torch.tensor([0.5, 0.5, 0.25, 0.75])
    truth = torch.tensor([1.0, 0.0, 1.0, 0.0])
    counts = PixelCounts(0.5)
    counts.update(prob, truth)
    assert (counts.tp, counts.fp, counts.fn, counts.tn) == (0, 1, 2, 1)
    at_05 = sweep_row(counts.sweep(), 0.5)
    assert at_05["precision"] == 0.0 and at_05["recall"] == 0.0
    at_025 = sweep_row(counts.sweep(), 0.25)
    assert at_025["recall"] == pytest.approx(1 / 2)  # 0.5 counts, 0.25 does not


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_every_sweep_row_equals_the_summary_at_its_threshold(dtype):
    # Half the probabilities sit exactly on sweep thresholds (as rounded to `dtype`), where
    # "> t" and ">= t" disagree; the rest are random.
    gen = torch.Generator().manual_seed(0)
    on_grid = torch.tensor([k / 100 for k in range(101)], dtype=dtype).repeat(20)
    prob = torch.cat([on_grid, torch.rand(2020, generator=gen, dtype=dtype)])
    truth = (torch.rand(len(prob), generator=gen) < 0.4).float()
    counts = PixelCounts()
    counts.update(prob, truth)
    sweep = counts.sweep()
    for row in sweep:
        single = PixelCounts(row["threshold"])
        single.update(prob, truth)
        assert {k: v for k, v in row.items() if k != "threshold"} == single.summary(), row


def test_best_iou_row_skips_undefined_and_prefers_the_lowest_threshold():
    nan = float("nan")
    rows = [
        {"threshold": 0.1, "iou": nan},
        {"threshold": 0.2, "iou": 0.5},
        {"threshold": 0.3, "iou": 0.5},
        {"threshold": 0.4, "iou": 0.25},
    ]
    assert best_iou_row(rows)["threshold"] == 0.2


def test_pair_means_average_each_pairs_ratios_and_say_how_empty_pairs_count():
    # pair 0: tp 2, fp 2, fn 0 -> IoU 0.5, precision 0.5, recall 1
    # pair 1: nothing true, 1 predicted -> IoU 0, precision 0, recall undefined
    # pair 2: 2 true, nothing predicted -> IoU 0, precision undefined, recall 0
    # pair 3: empty in both -> all three undefined
    m = pair_means(np.array([2, 0, 0, 0]), np.array([2, 1, 0, 0]), np.array([0, 0, 2, 0]))
    assert m["pair_mean_iou"] == pytest.approx(0.5 / 3)
    assert m["pair_mean_precision"] == pytest.approx(0.25)
    assert m["pair_mean_recall"] == pytest.approx(0.5)
    assert (m["pair_mean_iou_samples"], m["pair_mean_precision_samples"]) == (3, 2)
    assert m["pair_mean_recall_samples"] == 2 and m["samples_empty_both"] == 1
    assert m["pair_mean_iou_empty_as_one"] == pytest.approx(1.5 / 4)
    assert m["pair_mean_precision_empty_as_one"] == pytest.approx(2.5 / 4)
    assert m["pair_mean_recall_empty_as_one"] == pytest.approx(3.0 / 4)
    assert math.isnan(pair_means(np.zeros(2), np.zeros(2), np.zeros(2))["pair_mean_iou"])


def test_pixel_counts_keep_per_sample_counts_beside_the_sums():
    # Two 1x2x2 samples: the per-pair mean differs from the pooled IoU.
    prob = torch.tensor([[[[0.9, 0.9], [0.1, 0.1]]], [[[0.9, 0.1], [0.1, 0.1]]]])
    truth = torch.tensor([[[[1.0, 0.0], [0.0, 0.0]]], [[[1.0, 1.0], [1.0, 1.0]]]])
    counts = PixelCounts(0.4)
    counts.update(prob, truth)  # one batch of two samples
    counts.update(prob[1:], 0 * truth[1:])  # and one more: IoU 0
    assert counts.summary()["iou"] == pytest.approx(2 / 7)
    assert counts.pair_means()["pair_mean_iou"] == pytest.approx((1 / 2 + 1 / 4 + 0) / 3)
    assert (counts.tp, counts.fp, counts.fn, counts.tn) == (2, 2, 3, 5)


def test_collapse_probability_is_the_sigmoid_or_the_last_class():
    one = torch.tensor([[[[0.0, math.log(3.0)]]]])
    assert collapse_probs(one).flatten().tolist() == pytest.approx([0.5, 0.75])
    four = torch.log(torch.tensor([0.1, 0.2, 0.3, 0.4])).reshape(1, 4, 1, 1)  # B, E, S, C
    prob = collapse_probs(four)
    assert prob.shape == (1, 1, 1, 1) and float(prob) == pytest.approx(0.4)
