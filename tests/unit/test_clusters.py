"""Arrangement clusters (thesis 5.2.1): class from the settled tilt, membership, image box."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.sim.clusters import (
    assign_clusters,
    box_tilt,
    classify_cluster,
    cluster_bbox_px,
)
from clutterbench.sim.families.shelved import STANDING
from clutterbench.sim.geometry import quat_from_axis_angle, quat_mul

BOOK = np.array([0.10, 0.12, 0.03])  # local (D, W, H): standing, W is vertical, H along y
FLAT = np.array([1.0, 0.0, 0.0, 0.0])


def leaning(deg: float) -> np.ndarray:
    """A standing box rotated about the shelf's x axis (the camera's optical axis)."""
    return quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(deg)), STANDING)


def test_flat_and_standing_boxes():
    assert box_tilt(BOOK, FLAT) == (True, pytest.approx(0.0, abs=1e-9))
    flat, lean = box_tilt(BOOK, leaning(0.0))
    assert not flat and lean == pytest.approx(0.0, abs=1e-6)


def test_lean_sign_left_and_right():
    # Rotating +20 deg about x takes the top toward -y: the camera's right.
    _, right = box_tilt(BOOK, leaning(20.0))
    _, left = box_tilt(BOOK, leaning(-20.0))
    assert right == pytest.approx(-20.0, abs=1e-6) and left == pytest.approx(20.0, abs=1e-6)
    two = np.stack([BOOK, BOOK])
    assert classify_cluster(two, np.stack([leaning(20.0), leaning(25.0)])) == "C^r"
    assert classify_cluster(two, np.stack([leaning(-20.0), leaning(-25.0)])) == "C^l"
    assert classify_cluster(two, np.stack([leaning(3.0), leaning(-4.0)])) == "C^v"
    assert classify_cluster(two, np.stack([FLAT, FLAT])) == "C^h"
    # thesis 5.2.1: a single object is C^v, unless it leans (Fig. 5.9: C^r / C^l by its lean)
    assert classify_cluster(BOOK[None], leaning(0.0)[None]) == "C^v"
    assert classify_cluster(BOOK[None], leaning(8.0)[None]) == "C^v"
    assert classify_cluster(BOOK[None], FLAT[None]) == "C^v"
    assert classify_cluster(BOOK[None], leaning(30.0)[None]) == "C^r"
    assert classify_cluster(BOOK[None], leaning(-30.0)[None]) == "C^l"


def test_membership_every_box_once():
    # groups {0, 1} and {2}; box 3 touches 2; boxes 4 and 5 touch each other only; 6 alone.
    cluster_of = assign_clusters(7, [[0, 1], [2]], [(2, 3), (4, 5), (1, 2)])
    assert cluster_of.tolist() == [0, 0, 1, 1, 2, 2, 3]
    # a box touching two clusters joins the one it touches most
    assert assign_clusters(4, [[0], [1, 2]], [(0, 3), (1, 3), (2, 3)]).tolist() == [0, 1, 1, 1]


def test_bbox_from_instance_pixels():
    inst = np.zeros((10, 10), dtype=np.uint8)
    inst[2:4, 1:5] = 1  # box 0
    inst[6:9, 3:4] = 3  # box 2
    assert cluster_bbox_px(inst, [0, 2]).tolist() == [3.0, 5.5, 4.0, 7.0]  # x, y, w, h
    assert cluster_bbox_px(inst, [1]).tolist() == [0, 0, 0, 0]  # box 1 is not visible
