"""Detection metrics of the arrangement detector: VOC-style average precision per class
(all-point interpolation, greedy matching at an IoU threshold) and its mean, mAP@0.5.

Pure NumPy over per-image arrays: detections (boxes (K, 4) (x, y, w, h) px, scores (K,),
class indices (K,)) and ground truth (boxes (G, 4), class indices (G,)).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from clutterbench.perception.boxes import ARRANGEMENT_CLASSES, box_iou

Dets = tuple[np.ndarray, np.ndarray, np.ndarray]
"""One image's detections: boxes (K, 4), scores (K,), class indices (K,)."""
Truth = tuple[np.ndarray, np.ndarray]
"""One image's ground truth: boxes (G, 4), class indices (G,)."""


@dataclasses.dataclass(frozen=True)
class ClassPR:
    """Precision-recall of one class over a set of images."""

    n_truth: int
    """Ground-truth boxes of the class."""
    scores: np.ndarray
    """(D,) scores of the class's detections, best first."""
    tp: np.ndarray
    """(D,) bool: detection matched an unmatched truth box (IoU >= threshold)."""

    @property
    def recall(self) -> np.ndarray:
        return np.cumsum(self.tp) / max(self.n_truth, 1)

    @property
    def precision(self) -> np.ndarray:
        return np.cumsum(self.tp) / np.arange(1, len(self.tp) + 1)

    def ap(self) -> float:
        """All-point interpolated AP (VOC 2010+); NaN without ground truth."""
        if self.n_truth == 0:
            return float("nan")
        return voc_ap(self.recall, self.precision)

    def at_score(self, threshold: float) -> tuple[float, float]:
        """(precision, recall) of the detections scoring >= threshold (precision 1.0 when
        there is none, recall NaN without ground truth)."""
        k = int((self.scores >= threshold).sum())
        tp = int(self.tp[:k].sum())
        recall = tp / self.n_truth if self.n_truth else float("nan")
        return (tp / k if k else 1.0), recall


def voc_ap(recall: np.ndarray, precision: np.ndarray) -> float:
    """Area under the precision envelope (precision made non-increasing in recall), summed
    where recall changes: VOC's all-point average precision."""
    mrec = np.concatenate([[0.0], np.asarray(recall, np.float64), [1.0]])
    mpre = np.concatenate([[0.0], np.asarray(precision, np.float64), [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]
    step = np.nonzero(mrec[1:] != mrec[:-1])[0]
    return float(np.sum((mrec[step + 1] - mrec[step]) * mpre[step + 1]))


def class_pr(dets: Sequence[Dets], truth: Sequence[Truth], cls: int, iou: float = 0.5) -> ClassPR:
    """Match class `cls`'s detections over all images, best score first (ties: image, then
    detection order), each to the unmatched truth box of its image it overlaps most (VOC:
    the best-overlapping truth box; already matched -> a false positive)."""
    assert len(dets) == len(truth), "one detection set per image"
    found = []  # (score, image, detection)
    for i, (_, scores, classes) in enumerate(dets):
        found += [(-float(scores[k]), i, k) for k in np.nonzero(classes == cls)[0]]
    found.sort()
    gt = [boxes[classes == cls] for boxes, classes in truth]
    used = [np.zeros(len(g), bool) for g in gt]
    tp = np.zeros(len(found), bool)
    for n, (_, i, k) in enumerate(found):
        if len(gt[i]) == 0:
            continue
        overlaps = box_iou(dets[i][0][k][None], gt[i])[0]
        j = int(np.argmax(overlaps))
        if overlaps[j] >= iou and not used[i][j]:
            used[i][j] = tp[n] = True
    scores = np.array([-s for s, _, _ in found], np.float64)
    return ClassPR(sum(len(g) for g in gt), scores, tp)


def mean_ap(
    dets: Sequence[Dets], truth: Sequence[Truth], n_classes: int, iou: float = 0.5
) -> tuple[float, list[ClassPR]]:
    """(mAP over the classes that have ground truth, per-class PR) at IoU `iou`."""
    prs = [class_pr(dets, truth, c, iou) for c in range(n_classes)]
    aps = [p.ap() for p in prs if p.n_truth > 0]
    return (float(np.mean(aps)) if aps else float("nan")), prs


def pr_rows(prs: list[ClassPR]) -> list[dict[str, Any]]:
    """PR curve, long format: per class, one row at each true positive (where recall rises;
    the points AP is computed from) and one at the last detection."""
    rows = []
    for name, pr in zip(ARRANGEMENT_CLASSES, prs):
        for k in np.nonzero(pr.tp | (np.arange(len(pr.tp)) == len(pr.tp) - 1))[0]:
            rows.append(
                {
                    "class": name,
                    "score": float(pr.scores[k]),
                    "recall": float(pr.recall[k]),
                    "precision": float(pr.precision[k]),
                }
            )
    return rows
