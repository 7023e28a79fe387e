"""Pixel metrics of the collapse class (thesis eq. 5.10, 5.11), summed over a whole set, and
their average over samples (thesis Table 4.2)."""

from __future__ import annotations

import math

import numpy as np
import torch

SWEEP_BINS = 100
"""Threshold sweep resolution: thresholds 0.00, 0.01, ..., 0.99."""


class PixelCounts:
    """Accumulates TP / FP / FN / TN at one threshold and a histogram for the sweep.

    A pixel counts as collapse when its probability is higher than the threshold (5.3.1),
    in the summary and in every sweep row alike, so the sweep row at t equals the summary
    at t exactly. Each sample's own TP / FP / FN at the threshold are kept too, for the
    per-sample averages of thesis Table 4.2 (`pair_means`).
    """

    def __init__(self, threshold: float = 0.5):
        self.threshold = threshold
        self.tp = self.fp = self.fn = self.tn = 0
        # Bin j holds the pixels above exactly j sweep thresholds (j = 0 ... SWEEP_BINS).
        self.hist_pos = np.zeros(SWEEP_BINS + 1, dtype=np.int64)
        self.hist_neg = np.zeros(SWEEP_BINS + 1, dtype=np.int64)
        self.per_sample: list[np.ndarray] = []
        """(B, 3) TP, FP, FN of each sample of each update."""

    def update(self, prob: torch.Tensor, truth: torch.Tensor) -> None:
        """prob, truth: (B, ...) collapse probabilities and 0/1 truth of B samples (a 1-D
        pair: one sample)."""
        pred = prob > self.threshold
        pos = truth > 0.5
        n = len(pred) if pred.ndim > 1 else 1
        per_sample = torch.stack(
            [m.reshape(n, -1).sum(dim=1) for m in (pred & pos, pred & ~pos, ~pred & pos)], dim=1
        ).numpy()
        self.per_sample.append(per_sample.astype(np.int64))
        tp, fp, fn = (int(c) for c in per_sample.sum(axis=0))
        self.tp, self.fp, self.fn = self.tp + tp, self.fp + fp, self.fn + fn
        self.tn += int((~pred & ~pos).sum())
        # The sweep thresholds in prob's own dtype, as `prob > self.threshold` compares them:
        # bucketize counts the thresholds strictly below each prob, so a prob exactly at a
        # threshold is negative there, as in the summary.
        edges = torch.tensor(sweep_thresholds(), dtype=prob.dtype)
        bins = torch.bucketize(prob.contiguous(), edges, right=False)
        self.hist_pos += torch.bincount(bins[pos], minlength=SWEEP_BINS + 1).numpy()
        self.hist_neg += torch.bincount(bins[~pos], minlength=SWEEP_BINS + 1).numpy()

    def summary(self) -> dict[str, float]:
        return scores(self.tp, self.fp, self.fn, self.tn)

    def pair_means(self) -> dict[str, float]:
        """Per-sample scores at the threshold averaged over samples (pair_means)."""
        counts = np.concatenate(self.per_sample) if self.per_sample else np.zeros((0, 3))
        return pair_means(counts[:, 0], counts[:, 1], counts[:, 2])

    def sweep(self) -> list[dict[str, float]]:
        """Scores at thresholds k / 100, counting a pixel positive when prob > k / 100."""
        # Pixels above threshold k are those in bins k + 1 and up.
        pos_above = np.cumsum(self.hist_pos[::-1])[::-1]
        neg_above = np.cumsum(self.hist_neg[::-1])[::-1]
        n_pos, n_neg = int(self.hist_pos.sum()), int(self.hist_neg.sum())
        rows = []
        for k, threshold in enumerate(sweep_thresholds()):
            tp, fp = int(pos_above[k + 1]), int(neg_above[k + 1])
            rows.append({"threshold": threshold, **scores(tp, fp, n_pos - tp, n_neg - fp)})
        return rows


def sweep_thresholds() -> list[float]:
    return [k / SWEEP_BINS for k in range(SWEEP_BINS)]


def scores(tp: int, fp: int, fn: int, tn: int) -> dict[str, float]:
    """Pixel accuracy (5.10), IoU (5.11), precision and recall; NaN where undefined."""

    def ratio(a: int, b: int) -> float:
        return a / b if b else float("nan")

    return {
        "pixel_accuracy": ratio(tp + tn, tp + tn + fp + fn),
        "iou": ratio(tp, tp + fp + fn),
        "precision": ratio(tp, tp + fp),
        "recall": ratio(tp, tp + fn),
    }


def pair_means(tp: np.ndarray, fp: np.ndarray, fn: np.ndarray) -> dict[str, float]:
    """IoU, precision and recall of each sample (from its TP, FP, FN), averaged over samples:
    thesis Table 4.2 averages its metrics over its test samples, not over all pixels.

    A sample's ratio is undefined when its denominator is 0: IoU when neither truth nor
    prediction holds a collapse pixel, precision when nothing is predicted, recall when
    nothing collapses. `pair_mean_<m>` averages over the samples where <m> is defined
    (`pair_mean_<m>_samples` of them; NaN if none); `pair_mean_<m>_empty_as_one` over every
    sample, an undefined ratio counting as 1 (nothing predicted wrongly / nothing missed)."""
    tp, fp, fn = (np.asarray(a, dtype=np.float64) for a in (tp, fp, fn))
    out: dict[str, float] = {}
    for name, denom in (("iou", tp + fp + fn), ("precision", tp + fp), ("recall", tp + fn)):
        defined = denom > 0
        ratio = np.divide(tp, denom, out=np.ones_like(tp), where=defined)
        out[f"pair_mean_{name}"] = float(ratio[defined].mean()) if defined.any() else math.nan
        out[f"pair_mean_{name}_samples"] = int(defined.sum())
        out[f"pair_mean_{name}_empty_as_one"] = float(ratio.mean()) if len(ratio) else math.nan
    out["samples_empty_both"] = int(((tp + fp + fn) == 0).sum())
    return out


def best_iou_row(sweep: list[dict[str, float]]) -> dict[str, float]:
    """The sweep row with the highest IoU (NaN rows, where IoU is undefined, never win;
    ties go to the lowest threshold)."""
    return max(sweep, key=lambda r: -1.0 if math.isnan(r["iou"]) else r["iou"])


def sweep_row(sweep: list[dict[str, float]], threshold: float) -> dict[str, float]:
    """The sweep row at exactly `threshold` (one of sweep_thresholds())."""
    for row in sweep:
        if row["threshold"] == threshold:
            return row
    raise ValueError(f"threshold {threshold} is not on the sweep grid")
