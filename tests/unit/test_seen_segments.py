"""Chapter 6's depth perception: segments named by the box their grasp takes
(perception/seen.py)."""

from __future__ import annotations

import numpy as np

from clutterbench.observation import CameraModel, Observation
from clutterbench.perception.depth_segmentation import ShelfROI
from clutterbench.perception.seen import (
    grasp_point,
    label_by_grasp,
    pointed_segment,
    see_segments,
)


def _instance() -> np.ndarray:
    """Box 0 on the left (cols 0-4), box 1 on the right (cols 5-9), background row 9."""
    inst = np.zeros((10, 10), dtype=np.uint8)
    inst[:9, :5] = 1
    inst[:9, 5:] = 2
    return inst


def test_grasp_point_is_inside_and_central():
    mask = np.zeros((9, 9), dtype=bool)
    mask[2:7, 1:8] = True
    assert grasp_point(mask) == (4, 4)
    ring = np.zeros((9, 9), dtype=bool)  # centroid outside the segment: the nearest pixel of it
    ring[1, 1:8] = ring[7, 1:8] = ring[1:8, 1] = ring[1:8, 7] = True
    r, c = grasp_point(ring)
    assert ring[r, c]


def test_one_segment_per_box_keeps_the_box_ids():
    inst = _instance()
    labels = np.zeros((10, 10), dtype=np.int32)
    labels[:9, :5] = 2  # segment numbering differs from the box ids
    labels[:9, 5:] = 1
    out, grasps = label_by_grasp(labels, inst, n_boxes=2)
    assert grasps == {0: 0, 1: 1}
    assert np.array_equal(out, inst)


def test_a_split_box_gets_an_alias_and_the_larger_part_its_id():
    inst = _instance()
    labels = np.zeros((10, 10), dtype=np.int32)
    labels[:6, :5] = 1  # the larger part of box 0
    labels[6:9, :5] = 2  # its smaller part
    labels[:9, 5:] = 3
    out, grasps = label_by_grasp(labels, inst, n_boxes=2)
    assert grasps == {0: 0, 1: 1, 2: 0}
    assert set(np.unique(out[6:9, :5])) == {3}  # id 2 -> value 3
    assert set(np.unique(out[:6, :5])) == {1}


def test_a_grasp_on_no_box_takes_nothing_and_a_merge_hides_a_box():
    inst = _instance()
    labels = np.zeros((10, 10), dtype=np.int32)
    labels[:9, :] = 1  # both boxes in one segment: its grasp point is on one of them
    labels[9, :] = 2  # a segment on the background row
    out, grasps = label_by_grasp(labels, inst, n_boxes=2)
    assert len(grasps) == 2 and None in grasps.values()
    seen_boxes = {b for b in grasps.values() if b is not None}
    assert len(seen_boxes) == 1  # the other box is not seen
    stray = [k for k, b in grasps.items() if b is None]
    assert stray == [2]  # past the scene's two boxes


def test_the_pointed_segment_covers_most_of_the_true_mask():
    inst = _instance()
    labels = np.zeros((10, 10), dtype=np.int32)
    labels[:6, :5] = 1
    labels[6:9, :5] = 2
    labels[:9, 5:] = 3
    out, grasps = label_by_grasp(labels, inst, n_boxes=2)
    cam = CameraModel(K=np.eye(3), T_world_from_cam=np.eye(4))
    from clutterbench.perception.seen import SeenSegments

    seen = SeenSegments(Observation(np.ones((10, 10), np.float32), out, cam), grasps)
    assert pointed_segment(seen, inst == 1) == 0
    assert pointed_segment(seen, inst == 2) == 1
    assert pointed_segment(seen, np.zeros((10, 10), dtype=bool)) is None
    assert seen.box_of(2) == 0 and seen.box_of(None) is None and seen.box_of(7) is None


def test_degenerate_depth_gives_no_segments_not_an_exception():
    cam = CameraModel(
        K=np.array([[50.0, 0, 16], [0, 50.0, 16], [0, 0, 1]]), T_world_from_cam=np.eye(4)
    )
    roi = ShelfROI(-1.0, 1.0, -1.0, 1.0, 0.0, 2.0)
    inst = np.zeros((32, 32), dtype=np.uint8)
    inst[8:24, 8:24] = 1
    for depth in (
        np.zeros((32, 32), np.float32),
        np.full((32, 32), np.nan, np.float32),
        np.full((32, 32), 0.5, np.float32),
    ):
        seen = see_segments(Observation(depth, inst, cam), roi, n_boxes=1, min_pixels=5)
        assert seen.obs.instance.dtype == np.uint8
        assert seen.obs.instance.shape == (32, 32)
        assert all(b in (0, None) for b in seen.grasps.values())
