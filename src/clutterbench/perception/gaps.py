"""Geometry of the visible boxes from one depth image alone: the camera-frame points of a
depth image, and the closest visible surfaces of each pair of boxes where their masks meet
(the support rule's surface-gap test and the box head's features read them)."""

from __future__ import annotations

import itertools
from typing import Any

import cv2
import numpy as np


def camera_points(depth_m: np.ndarray, camera: Any) -> np.ndarray:
    """(H, W, 3) camera-frame points of a depth image rendered with `camera` (sim.config's
    CameraConfig, or anything with its fovy_deg; the pinhole
    SAPIEN renders with: f = (H / 2) / tan(fovy / 2), principal point at the centre); NaN
    where nothing was seen."""
    h, w = depth_m.shape
    f = (h / 2) / np.tan(np.deg2rad(camera.fovy_deg) / 2)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    z = depth_m.astype(np.float64)
    pts = np.stack([(u - w / 2) * z / f, (v - h / 2) * z / f, z], axis=-1)
    pts[depth_m <= 0] = np.nan
    return pts


def surface_gaps(points: np.ndarray, masks: np.ndarray, band_px: int = 2) -> np.ndarray:
    """(K, K) float64 distance (m) between the closest visible surface points of each pair of
    objects near where their masks meet in the image: `points` (H, W, 3) back-projected depth
    (any metric frame; NaN where nothing was seen), only pixels of one mask within `band_px`
    of the other compared; inf where the masks do not come that close, diagonal 0."""
    assert masks.ndim == 3 and masks.dtype == np.bool_, "masks must be (K, H, W) bool"
    assert points.shape == (*masks.shape[1:], 3), "points must be (H, W, 3) for the masks"
    k = masks.shape[0]
    kernel = np.ones((2 * band_px + 1, 2 * band_px + 1), np.uint8)
    grown = [cv2.dilate(m.astype(np.uint8), kernel) > 0 for m in masks]
    gaps = np.full((k, k), np.inf)
    np.fill_diagonal(gaps, 0.0)
    for a, b in itertools.combinations(range(k), 2):
        pa, pb = points[masks[a] & grown[b]], points[masks[b] & grown[a]]
        pa, pb = pa[~np.isnan(pa).any(axis=1)], pb[~np.isnan(pb).any(axis=1)]
        if len(pa) and len(pb):
            d2 = ((pa[:, None, :] - pb[None, :, :]) ** 2).sum(axis=-1)
            gaps[a, b] = gaps[b, a] = float(np.sqrt(d2.min()))
    return gaps
