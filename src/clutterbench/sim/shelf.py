"""The shelf: thesis ch. 5 interior W330 x D280 x H330 mm, open towards the camera.

World frame: x points from the shelf opening (x = 0) into the shelf (back wall at x = depth),
y points to the camera's left, z up; the shelf floor is z = 0 and the interior spans
y in [-width/2, width/2].
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Shelf:
    width_m: float = 0.330
    """Interior width (thesis 5.2.3: W330 mm)."""
    depth_m: float = 0.280
    """Interior depth (D280 mm)."""
    height_m: float = 0.330
    """Interior height (H330 mm)."""
    board_m: float = 0.018
    """Board thickness of the shelf walls (not given in the thesis; a plywood shelf)."""

    def boards(self) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """(name, half extents, centre) of the floor, top, side and back boards."""
        w, d, h, t = self.width_m, self.depth_m, self.height_m, self.board_m
        span_y = w / 2 + t
        return [
            ("floor", np.array([d / 2, span_y, t / 2]), np.array([d / 2, 0.0, -t / 2])),
            ("top", np.array([d / 2, span_y, t / 2]), np.array([d / 2, 0.0, h + t / 2])),
            ("left", np.array([d / 2, t / 2, h / 2]), np.array([d / 2, w / 2 + t / 2, h / 2])),
            ("right", np.array([d / 2, t / 2, h / 2]), np.array([d / 2, -w / 2 - t / 2, h / 2])),
            ("back", np.array([t / 2, span_y, h / 2 + t]), np.array([d + t / 2, 0.0, h / 2])),
        ]

    def contains(self, pos_m: np.ndarray, tol_m: float = 0.005) -> np.ndarray:
        """Whether each centre (N, 3) lies inside the interior (a box hanging out is fine)."""
        p = np.atleast_2d(pos_m)
        return (
            (p[:, 0] >= -tol_m)
            & (p[:, 0] <= self.depth_m + tol_m)
            & (np.abs(p[:, 1]) <= self.width_m / 2 + tol_m)
            & (p[:, 2] >= -tol_m)
            & (p[:, 2] <= self.height_m + tol_m)
        )
