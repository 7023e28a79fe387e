"""What the chapter 3 ConvNet sees (thesis 3.3.1): the raster scan of slide candidates and,
for each, a square window of the board's height image around the slide's start point,
rotated so that the slide points up.

Raster scan: a grid x grid lattice of start points (cell centres of a square around the
board centre) times `n_directions` slide directions (k * 360 / n_directions degrees, 0 = +x,
counter-clockwise): thesis 10 x 10 x 8 = 800 candidates.

The top camera looks straight down at the board, whose top surface is the plane z = 0, so a
board point maps to a pixel by an affine map; one `cv2.warpAffine` cuts, rotates and scales
the window. Crop layout: the slide runs from the start point (column centre, row
`start_row_fraction` of the height from the top) toward row 0; the crop's right is the slide
direction turned 90 degrees clockwise seen from above (a view from above, not mirrored).
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from clutterbench.config import bounded
from clutterbench.observation import CameraModel, Observation


@dataclasses.dataclass(frozen=True)
class ScanConfig:
    grid: int = bounded(10, ge=1)
    """Start points per side of the raster (thesis 10)."""
    n_directions: int = bounded(8, ge=1)
    """Slide directions (thesis 8, every 45 degrees)."""
    scan_size_m: float = bounded(0.2, gt=0.0)
    """Side of the square around the board centre that the start points cover (the pile's
    area)."""
    crop_m: float = bounded(0.16, gt=0.0)
    """Side of a crop on the board (metres): the piece and the path ahead of it."""
    crop_px: int = bounded(64, ge=16)
    """Side of a crop in pixels (thesis 227); the ConvNet's input size."""
    start_row_fraction: float = bounded(0.75, gt=0.0, le=1.0)
    """Where the start point sits in a crop, as a fraction of its height from the top."""
    edge_margin_px: int = bounded(2, ge=0)
    """A candidate counts only when its start point is at least this many top-view pixels
    inside a piece's visible mask: on an edge, which piece the finger presses is a guess
    (for the labels and for the planner alike)."""


@dataclasses.dataclass(frozen=True)
class Candidates:
    start_xy: np.ndarray
    """(K, 2) start points on the board (metres)."""
    direction: np.ndarray
    """(K,) int direction index d: the slide runs at d * 2 pi / n_directions."""
    n_directions: int

    @property
    def angle_rad(self) -> np.ndarray:
        return self.direction * (2 * np.pi / self.n_directions)

    def __len__(self) -> int:
        return len(self.direction)


def raster_candidates(scan: ScanConfig) -> Candidates:
    """Every (start point, direction) of the raster scan: grid^2 * n_directions, ordered by
    row (y), column (x), direction."""
    cells = (np.arange(scan.grid) + 0.5) / scan.grid * scan.scan_size_m - scan.scan_size_m / 2
    yy, xx, dd = np.meshgrid(cells, cells, np.arange(scan.n_directions), indexing="ij")
    return Candidates(
        start_xy=np.column_stack([xx.ravel(), yy.ravel()]),
        direction=dd.ravel().astype(np.int64),
        n_directions=scan.n_directions,
    )


def interior(instance: np.ndarray, margin_px: int) -> np.ndarray:
    """The instance image with every object's mask eroded by `margin_px` pixels (0 where
    eroded away): a start point there is on that object, not on its edge."""
    if margin_px <= 0:
        return instance
    kernel = np.ones((2 * margin_px + 1, 2 * margin_px + 1), np.uint8)
    out = np.zeros_like(instance)
    for k in np.unique(instance[instance > 0]):
        out[cv2.erode((instance == k).astype(np.uint8), kernel) > 0] = k
    return out


def piece_under(obs: Observation, points_xy: np.ndarray, margin_px: int = 0) -> np.ndarray:
    """(K,) the object seen (from the top camera) at each board point: instance - 1, or -1
    where the board shows or, with `margin_px`, within that many pixels of an object's
    edge."""
    u, v, _ = obs.camera.world_to_pixel(np.column_stack([points_xy, np.zeros(len(points_xy))]))
    h, w = obs.instance.shape
    cols = np.clip(np.floor(u).astype(np.int64), 0, w - 1)
    rows = np.clip(np.floor(v).astype(np.int64), 0, h - 1)
    return interior(obs.instance, margin_px)[rows, cols].astype(np.int64) - 1


def height_image(obs: Observation) -> np.ndarray:
    """(H, W) float32 height above the board (metres, z of the back-projected pixel; 0 where
    nothing was hit or below the board)."""
    pts = obs.camera.depth_to_points(obs.depth_m)
    z = np.nan_to_num(pts[..., 2], nan=0.0)
    return np.clip(z, 0.0, None).astype(np.float32)


def crop_frame(
    start_xy: np.ndarray, direction_rad: float, crop_m: float, start_row_fraction: float
) -> np.ndarray:
    """(3, 2) board points (x, y) of the crop's top-left, top-right and bottom-left corners."""
    d = np.array([np.cos(direction_rad), np.sin(direction_rad)])
    right = np.array([d[1], -d[0]])  # d turned 90 degrees clockwise seen from above
    start = np.asarray(start_xy, dtype=np.float64)
    top_centre = start + d * crop_m * start_row_fraction
    top_left = top_centre - right * crop_m / 2
    return np.stack([top_left, top_left + right * crop_m, top_left - d * crop_m])


def slide_crop(
    heights: np.ndarray,
    camera: CameraModel,
    start_xy: np.ndarray,
    direction_rad: float,
    crop_m: float,
    crop_px: int,
    start_row_fraction: float = 0.75,
) -> np.ndarray:
    """(crop_px, crop_px) float32 heights (metres) of the window of side `crop_m` around the
    slide from `start_xy` (board metres) in `direction_rad` (0 = +x, counter-clockwise), the
    slide pointing up. Outside the image reads 0 (the board)."""
    corners = crop_frame(start_xy, direction_rad, crop_m, start_row_fraction)
    u, v, _ = camera.world_to_pixel(np.column_stack([corners, np.zeros(3)]))
    # pixel coordinates are continuous with a pixel's centre at index + 0.5 (observation.py)
    src = np.column_stack([u, v]).astype(np.float32) - 0.5
    dst = np.array([[0, 0], [crop_px, 0], [0, crop_px]], dtype=np.float32) - 0.5
    affine = cv2.getAffineTransform(dst, src)  # crop pixel -> image pixel
    return cv2.warpAffine(
        np.ascontiguousarray(heights, dtype=np.float32),
        affine,
        (crop_px, crop_px),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0.0,
    )


def slide_crops(heights: np.ndarray, camera: CameraModel, cands: Candidates, scan: ScanConfig):
    """(K, crop_px, crop_px) float32: `slide_crop` of every candidate."""
    out = np.zeros((len(cands), scan.crop_px, scan.crop_px), dtype=np.float32)
    for k, (start, theta) in enumerate(zip(cands.start_xy, cands.angle_rad)):
        out[k] = slide_crop(
            heights,
            camera,
            start,
            float(theta),
            scan.crop_m,
            scan.crop_px,
            scan.start_row_fraction,
        )
    return out


def subset(cands: Candidates, index: np.ndarray) -> Candidates:
    return Candidates(cands.start_xy[index], cands.direction[index], cands.n_directions)
