"""What a robot sees: a depth image, object masks and the camera model (no SAPIEN here).

Planners (`planning/`) and perception take an `Observation`; the simulator (`sim/render.py`)
makes one. Frames: the camera frame is OpenCV's (x right, y down, z forward); the world is the
shelf frame (x from the opening into the shelf, y to the camera's left, z up; metres).
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics and pose of the depth camera."""

    K: np.ndarray
    """(3, 3) intrinsics: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (pixels)."""
    T_world_from_cam: np.ndarray
    """(4, 4) pose of the OpenCV camera frame in the shelf frame."""

    def __post_init__(self) -> None:
        assert self.K.shape == (3, 3) and self.T_world_from_cam.shape == (4, 4)

    def pixel_to_world(self, u: np.ndarray, v: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """Back-project pixel coordinates (continuous; a pixel's centre is index + 0.5) with
        their depth (metres along the optical axis) to (..., 3) shelf-frame points."""
        u, v, z = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (u, v, depth_m)))
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        p_cam = np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z, np.ones_like(z)], axis=-1)
        return (p_cam @ self.T_world_from_cam.T)[..., :3]

    def world_to_pixel(self, p_world_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project (..., 3) shelf-frame points to continuous pixel coordinates (u, v) and their
        depth (metres); the inverse of `pixel_to_world`."""
        p = np.asarray(p_world_m, dtype=np.float64)
        T_cam_from_world = np.linalg.inv(self.T_world_from_cam)
        p_cam = p @ T_cam_from_world[:3, :3].T + T_cam_from_world[:3, 3]
        z = p_cam[..., 2]
        u = self.K[0, 0] * p_cam[..., 0] / z + self.K[0, 2]
        v = self.K[1, 1] * p_cam[..., 1] / z + self.K[1, 2]
        return u, v, z

    def depth_to_points(self, depth_m: np.ndarray) -> np.ndarray:
        """(H, W, 3) shelf-frame point of every pixel centre (NaN where depth is 0)."""
        assert depth_m.dtype == np.float32, "depth must be float32 metres"
        h, w = depth_m.shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
        pts = self.pixel_to_world(u, v, depth_m)
        pts[depth_m <= 0] = np.nan
        return pts


@dataclasses.dataclass(frozen=True)
class Observation:
    """One rendered view: what a planner may use, and nothing else."""

    depth_m: np.ndarray
    """(H, W) float32 depth along the optical axis, metres; 0 where nothing was hit."""
    instance: np.ndarray
    """(H, W) uint8 object ids: 0 background, k + 1 = box k."""
    camera: CameraModel

    def mask(self, box: int) -> np.ndarray:
        """Binary (uint8) mask of box `box`."""
        return (self.instance == box + 1).astype(np.uint8)

    def visible_boxes(self, min_pixels: int = 1) -> list[int]:
        """Indices of the boxes with at least `min_pixels` visible pixels."""
        counts = np.bincount(self.instance.ravel(), minlength=256)
        return [int(j) for j in np.nonzero(counts[1:] >= min_pixels)[0]]
