"""Object masks a planner may use: the simulator's instance image, or segments of the depth
image alone (what a robot without ground truth has). Every table says which one it used."""

from __future__ import annotations

import dataclasses

import numpy as np

from clutterbench.observation import Observation
from clutterbench.perception.depth_segmentation import (
    DepthSegmentationParams,
    ShelfROI,
    segment_depth,
)

METHODS = ("instance", "depth")
DEFAULT_MIN_PIXELS = 20
"""Smallest object a planner considers, in pixels (trials' min_pixels default)."""


@dataclasses.dataclass(frozen=True)
class Segmentation:
    """Disjoint object masks of one observation."""

    ids: list[int]
    """One id per mask: box ids from the instance image, segment numbers 0..K-1 from depth."""
    masks: np.ndarray
    """(K, H, W) bool."""
    source: str
    """"instance" or "depth"."""

    def __post_init__(self) -> None:
        assert self.masks.dtype == np.bool_ and self.masks.ndim == 3, "masks must be (K, H, W) bool"
        assert len(self.ids) == self.masks.shape[0] and self.source in METHODS

    def labels(self) -> np.ndarray:
        """(H, W) int32: 0 where no mask is, k + 1 on masks[k]."""
        out = np.zeros(self.masks.shape[1:], dtype=np.int32)
        for k, m in enumerate(self.masks):
            out[m] = k + 1
        return out


def masks_from_instance(obs: Observation, min_pixels: int) -> Segmentation:
    """Every box with at least `min_pixels` visible pixels, in ascending box id."""
    ids = obs.visible_boxes(min_pixels)
    masks = obs.instance[None] == (np.array(ids, dtype=np.int64) + 1)[:, None, None]
    return Segmentation(ids=ids, masks=masks, source="instance")


def masks_from_labels(labels: np.ndarray) -> Segmentation:
    """A depth label image (0 background, 1..K) as a Segmentation with ids 0..K-1."""
    assert labels.dtype == np.int32 and labels.ndim == 2, "labels must be (H, W) int32"
    k = int(labels.max(initial=0))
    masks = labels[None] == np.arange(1, k + 1, dtype=np.int32)[:, None, None]
    return Segmentation(ids=list(range(k)), masks=masks, source="depth")


def segment(
    obs: Observation,
    method: str,
    params: DepthSegmentationParams | None = None,
    min_pixels: int = DEFAULT_MIN_PIXELS,
    roi: ShelfROI | None = None,
) -> Segmentation:
    """Object masks by `method`: "instance" (the simulator's ids) or "depth" (depth alone;
    needs the shelf's `roi`, perception.depth_segmentation.shelf_roi)."""
    if method == "instance":
        return masks_from_instance(obs, min_pixels)
    if method == "depth":
        if roi is None:
            raise ValueError("segmentation method 'depth' needs the shelf's roi")
        labels = segment_depth(obs, roi, params or DepthSegmentationParams(), min_pixels)
        return masks_from_labels(labels)
    raise ValueError(f"unknown segmentation method '{method}' (known: {', '.join(METHODS)})")


def match_segments(seg: Segmentation, instance: np.ndarray) -> list[int | None]:
    """For each segment, the box (instance value - 1) covering most of its pixels; None where
    background covers more than any box (ties go to background, then to the lower id).

    For the trial harness only, which holds the world and must know which box the robot
    grasps when it grasps a segment; a planner never sees `instance`."""
    assert instance.shape == seg.masks.shape[1:], "instance image and masks differ in size"
    out: list[int | None] = []
    for m in seg.masks:
        votes = np.bincount(instance[m].astype(np.int64), minlength=1)
        best = int(np.argmax(votes))
        out.append(None if best == 0 else best - 1)
    return out
