"""Object masks as a robot without ground truth has them (chapter 6's `perception: depth`, thesis
6.3.2: "segmenting point clouds with the region growing"): segments of the sensed depth image
(`region_growing.segment_regions`), each handed to the planner under the id of the box a grasp
of it would take.

A pull acts where the robot grasps: at a segment's grasp point (the pixel of the segment, eroded
by one pixel where it can be, nearest its centroid). The box under that point is the one
pulled; a grasp on no box (background, a board) takes nothing and is a failed step. The trial
harness holds the world, so it knows which box that is; the planner sees only the segments, and
the id is what a robot tracking its grasps across pictures would call it: two segments that
grasp one box (a box split in two) get two ids, the larger the box's own, the other an alias
past the scene's boxes; a segment holding two boxes (two merged) is the one box its grasp takes,
and the other is not seen. Every picture the planner reads, the mid-pull ones included, is
segmented this way, so a box keeps its id while it is seen.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from clutterbench.observation import Observation
from clutterbench.perception.depth_segmentation import ShelfROI
from clutterbench.perception.region_growing import RegionGrowingParams, segment_regions

MAX_IDS = 255
"""Observation.instance is uint8: ids 0 .. 254 (value id + 1)."""


@dataclasses.dataclass(frozen=True)
class SeenSegments:
    """One picture as the planner gets it under depth perception."""

    obs: Observation
    """The sensed depth, the segments as its instance image (value id + 1), the camera."""
    grasps: dict[int, int | None]
    """Every id the planner sees -> the box a grasp of it takes (None: no box)."""
    failure: str | None = None
    """Why the segmentation produced nothing (an exception's class name), None when it ran."""

    def box_of(self, seen_id: int | None) -> int | None:
        """The box a grasp of segment `seen_id` takes (None for None, or for no box)."""
        return None if seen_id is None else self.grasps.get(int(seen_id))


def grasp_point(mask: np.ndarray) -> tuple[int, int]:
    """(row, col) where a robot grasps a segment (H, W bool): the pixel of the segment, eroded by
    one pixel unless that empties it, nearest the segment's centroid."""
    assert mask.dtype == np.bool_ and mask.any(), "a grasp point needs a non-empty bool mask"
    inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    core = inner if inner.any() else mask
    rows, cols = np.nonzero(core)
    r0, c0 = np.nonzero(mask)
    d2 = (rows - r0.mean()) ** 2 + (cols - c0.mean()) ** 2
    k = int(np.argmin(d2))  # ties: the first in raster order
    return int(rows[k]), int(cols[k])


def label_by_grasp(
    labels: np.ndarray, instance: np.ndarray, n_boxes: int
) -> tuple[np.ndarray, dict[int, int | None]]:
    """Segment labels (H, W int32: 0 none, 1..K) -> (an instance image (H, W uint8: id + 1), id ->
    grasped box). Segments claim their grasped box's id largest first (ties: label order); a
    segment whose box is claimed, or that grasps no box, gets the next id past the scene's
    boxes (n_boxes, n_boxes + 1, ...). Segments past MAX_IDS ids are dropped."""
    assert labels.shape == instance.shape, "segment labels and instance image differ in size"
    k = int(labels.max(initial=0))
    sizes = np.bincount(labels.ravel(), minlength=k + 1)[1:]
    out = np.zeros(labels.shape, dtype=np.uint8)
    grasps: dict[int, int | None] = {}
    alias = n_boxes
    for s in sorted(range(k), key=lambda s: (-sizes[s], s)):
        mask = labels == s + 1
        if not mask.any():
            continue
        box = int(instance[grasp_point(mask)]) - 1
        grasped = box if 0 <= box < n_boxes else None
        if grasped is not None and grasped not in grasps:
            seen_id = grasped
        else:
            seen_id, alias = alias, alias + 1
        if seen_id >= MAX_IDS:
            continue
        grasps[seen_id] = grasped
        out[mask] = seen_id + 1
    return out, grasps


def see_segments(
    obs: Observation,
    roi: ShelfROI,
    n_boxes: int,
    min_pixels: int,
    params: RegionGrowingParams | None = None,
) -> SeenSegments:
    """The picture `obs` (sensed depth, the simulator's instance image) as the planner gets it:
    its depth segmented by region growing, each segment under the id of the box its grasp takes.
    A depth image that defeats the segmentation gives no segments and names why (a perception
    failure, recorded by the harness), never an exception."""
    try:
        with np.errstate(all="ignore"):
            labels = segment_regions(obs, roi, params or RegionGrowingParams(), min_pixels)
        failure = None
    except (ValueError, FloatingPointError, np.linalg.LinAlgError, cv2.error) as exc:
        labels, failure = np.zeros(obs.depth_m.shape, dtype=np.int32), type(exc).__name__
    instance, grasps = label_by_grasp(labels, obs.instance, n_boxes)
    seen = dataclasses.replace(obs, instance=instance)
    return SeenSegments(obs=seen, grasps=grasps, failure=failure)


def pointed_segment(seen: SeenSegments, true_mask: np.ndarray) -> int | None:
    """The segment a person pointing at a box (its true visible mask, H x W bool) means: the one
    covering most of it; None when no segment covers any of it (ties: the lower id)."""
    ids = seen.obs.instance[true_mask].astype(np.int64)
    votes = np.bincount(ids, minlength=1)
    votes[0] = 0
    return None if votes.max(initial=0) == 0 else int(np.argmax(votes)) - 1
