"""Arrangement boxes (thesis 5.2.1, eq. 5.1): detections of object clusters as image boxes
B = (x, y, w, h), centre and size in pixels, and the box geometry a detector needs: IoU and
per-class non-maximum suppression. Pure NumPy; no simulator (the class names are checked
equal to sim.clusters.CLASSES by a test)."""

from __future__ import annotations

import dataclasses

import numpy as np

ARRANGEMENT_CLASSES = ("C^h", "C^v", "C^r", "C^l")
"""Thesis 5.2.1: stacked, shelved, disorganized leaning right, leaning left (image sides)."""


@dataclasses.dataclass(frozen=True)
class Detection:
    """One arrangement cluster in an image."""

    cls: str
    """One of ARRANGEMENT_CLASSES."""
    box: np.ndarray
    """(4,) float (x, y, w, h): centre and size in pixels, thesis eq. (5.1)."""
    score: float
    """Confidence in [0, 1] (1.0 for ground truth)."""

    def __post_init__(self) -> None:
        assert self.cls in ARRANGEMENT_CLASSES, f"unknown arrangement class {self.cls!r}"
        assert self.box.shape == (4,), "box must be (x, y, w, h)"


def corners_px(boxes: np.ndarray) -> np.ndarray:
    """(N, 4) (x, y, w, h) centre boxes -> (N, 4) (x0, y0, x1, y1) corners."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    half = b[:, 2:] / 2
    return np.concatenate([b[:, :2] - half, b[:, :2] + half], axis=1)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, M) intersection over union of centre-format boxes a (N, 4) and b (M, 4); 0 where
    both boxes are empty."""
    ca, cb = corners_px(a), corners_px(b)
    lo = np.maximum(ca[:, None, :2], cb[None, :, :2])
    hi = np.minimum(ca[:, None, 2:], cb[None, :, 2:])
    inter = np.prod(np.clip(hi - lo, 0.0, None), axis=-1)
    area_a = np.prod(np.clip(ca[:, 2:] - ca[:, :2], 0.0, None), axis=1)
    area_b = np.prod(np.clip(cb[:, 2:] - cb[:, :2], 0.0, None), axis=1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)


def nms(
    boxes: np.ndarray, scores: np.ndarray, classes: np.ndarray, iou_threshold: float
) -> np.ndarray:
    """Indices of the boxes kept by greedy per-class non-maximum suppression: highest score
    first, a box is dropped when it overlaps a kept box of its class by IoU > iou_threshold
    (thesis 5.2.1: 0.45). Kept indices in order of decreasing score (ties: lower index)."""
    scores = np.asarray(scores, dtype=np.float64)
    classes = np.asarray(classes)
    order = np.lexsort((np.arange(len(scores)), -scores))
    iou = box_iou(boxes, boxes)
    kept: list[int] = []
    for i in order:
        same = [k for k in kept if classes[k] == classes[i]]
        if not same or iou[i, same].max() <= iou_threshold:
            kept.append(int(i))
    return np.array(kept, dtype=np.int64)


def detections_from_clusters(classes_idx: np.ndarray, boxes_px: np.ndarray) -> list[Detection]:
    """Ground-truth detections of one scene from its recorded clusters (class index into
    ARRANGEMENT_CLASSES, -1 = padding; boxes (x, y, w, h)); clusters with no visible pixel
    (zero-size box) are skipped. Score 1.0."""
    out = []
    for k, box in zip(np.asarray(classes_idx), np.asarray(boxes_px, dtype=np.float64)):
        if k < 0 or box[2] <= 0 or box[3] <= 0:
            continue
        out.append(Detection(ARRANGEMENT_CLASSES[int(k)], box.copy(), 1.0))
    return out
