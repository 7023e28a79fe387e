"""Focal loss (thesis eq. 6.1) and pixel metrics (eq. 5.10, 5.11) against hand-computed values."""

import math

import pytest
import torch

from clutterbench.collapse.losses import FocalConfig, bce_loss, focal_loss
from clutterbench.collapse.metrics import PixelCounts, scores


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
