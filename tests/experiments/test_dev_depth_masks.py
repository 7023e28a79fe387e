"""The depth-masks recheck's scoring: a box is found by a segment with IoU > 0.5, and a box the
sensor returns too few pixels of is counted apart."""

from __future__ import annotations

import numpy as np

from experiments.depth_masks import MIN_PIXELS, score


def _scene() -> tuple[np.ndarray, np.ndarray]:
    """Two 10 x 10 boxes side by side (ids 1 and 2) and depth returned everywhere."""
    instance = np.zeros((20, 30), dtype=np.uint8)
    instance[5:15, 2:12], instance[5:15, 15:25] = 1, 2
    return instance, np.full(instance.shape, 0.8, dtype=np.float32)


def test_a_segment_on_each_box_finds_both():
    instance, depth = _scene()
    got = score(instance.astype(np.int32), instance, depth)
    assert got["visible"] == got["found"] == got["segments"] == 2
    assert got["stray"] == got["over"] == got["under"] == 0
    assert got["returned"] == got["found_returned"] == 2


def test_a_box_in_a_shadow_is_not_returned():
    instance, depth = _scene()
    depth[instance == 2] = 0.0  # no return on box 2: all of it shadowed
    depth.reshape(-1)[np.flatnonzero(instance.ravel() == 1)[: 100 - MIN_PIXELS + 1]] = (
        0.0  # box 1: 19 left
    )
    labels = np.zeros(instance.shape, dtype=np.int32)
    labels[instance == 1] = 1  # box 1 found from what the fit filled in, box 2 missed
    got = score(labels, instance, depth)
    assert (got["visible"], got["found"]) == (2, 1)
    assert (got["returned"], got["found_returned"]) == (0, 0)
    depth[5, 2] = 0.8  # box 1 now has MIN_PIXELS pixels of depth: returned
    got = score(labels, instance, depth)
    assert (got["returned"], got["found_returned"]) == (1, 1)


def test_one_segment_over_two_boxes_finds_neither():
    instance, depth = _scene()
    labels = (instance > 0).astype(np.int32)
    got = score(labels, instance, depth)
    assert (got["found"], got["under"], got["stray"]) == (0, 1, 1)
