"""Object segments from the depth image alone, as a real robot would compute them.

The thesis robot clusters its point cloud by region growing (4.2.3, ref. [86]); this is the
organized-image equivalent. Every pixel is back-projected to a shelf-frame point with the
camera model; the shelf itself is dropped (the robot knows its shelf: points outside the
interior, or within a margin of a board, are background); neighbouring pixels are then
disconnected where the surface jumps (an occlusion edge) or folds without being convex (one
object resting or leaning on another), and the connected rest are the objects.

Convex folds (a box's front face turning into its top face) stay connected, so a segment is a
whole visible box, as the simulator's instance masks are. What depth cannot separate: faces in
one continuous plane, e.g. the front faces of a flush stack, or of boxes standing side by side
touching, whose only boundary is a seam narrower than a pixel. Tuned on the simulator's
noise-free depth: per-pixel normals do not survive sensor noise (sim/noise.py) unsmoothed.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import cv2
import numpy as np

from clutterbench.config import bounded
from clutterbench.observation import Observation


@dataclasses.dataclass(frozen=True)
class ShelfROI:
    """Axis-aligned region of the shelf frame where objects can be (metres)."""

    x_min_m: float
    x_max_m: float
    y_min_m: float
    y_max_m: float
    z_min_m: float
    z_max_m: float

    def __post_init__(self) -> None:
        assert self.x_min_m < self.x_max_m and self.y_min_m < self.y_max_m
        assert self.z_min_m < self.z_max_m

    def contains(self, points_m: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """(..., 3) shelf-frame points -> (...) bool: inside by more than `margin_m` from every
        face; False for NaN points."""
        x, y, z = points_m[..., 0], points_m[..., 1], points_m[..., 2]
        m = margin_m
        with np.errstate(invalid="ignore"):
            return (
                (x > self.x_min_m + m)
                & (x < self.x_max_m - m)
                & (y > self.y_min_m + m)
                & (y < self.y_max_m - m)
                & (z > self.z_min_m + m)
                & (z < self.z_max_m - m)
            )


class ShelfDimensions(Protocol):
    """The shelf interior's size (sim.shelf.Shelf is one); perception does not import sim."""

    width_m: float
    depth_m: float
    height_m: float


def shelf_roi(shelf: ShelfDimensions) -> ShelfROI:
    """The interior of a shelf in its own frame (sim/shelf.py: x from the opening into the
    shelf, y centred, floor at z = 0). The opening has no board, so the region reaches one
    shelf depth out in front of it: a box hanging out, or half pulled, is still an object."""
    return ShelfROI(
        x_min_m=-shelf.depth_m,
        x_max_m=shelf.depth_m,
        y_min_m=-shelf.width_m / 2,
        y_max_m=shelf.width_m / 2,
        z_min_m=0.0,
        z_max_m=shelf.height_m,
    )


@dataclasses.dataclass(frozen=True)
class DepthSegmentationParams:
    board_margin_m: float = bounded(0.002, ge=0.0)
    """Points closer than this to a face of the shelf ROI (floor, top, sides, back) belong to
    the shelf's boards."""
    edge_jump_m: float = bounded(0.004, gt=0.0)
    """Neighbouring points farther apart than this may be on two objects (an occlusion edge) ..."""
    edge_jump_px: float = bounded(1.5, gt=1.0)
    """... if also farther apart than this many pixel footprints (depth / focal length, the
    spacing of points on a face seen head-on), stretched by 1 / sin(incidence) for a face seen
    obliquely; relative to the footprint, so one setting serves 64, 128 and 256 px images."""
    min_incidence_deg: float = bounded(10.0, gt=0.0, le=90.0)
    """Faces seen more obliquely than this stretch the jump threshold no further."""
    normal_jump_deg: float = bounded(2.0, gt=0.0, le=180.0)
    """Neighbours whose normals differ more than this, across a fold that is not convex, are
    two objects. Small: rendered depth is exact, and a box turned a few degrees on another
    meets it with no depth jump at all."""
    singular_deg: float = bounded(30.0, ge=0.0, le=90.0)
    """A fold whose step runs within this angle of the line where the two faces' planes meet
    is no fold but two faces crossing (a box turned on another): never convex."""


def _one_sided_step(points_m: np.ndarray, axis: int) -> np.ndarray:
    """(H, W, 3) step to the neighbouring point along `axis` (0: rows, 1: columns), taken on
    the side of each pixel where the surface runs on unbroken, so that a pixel at an edge takes
    its tangent from its own face. A central difference (cv2.Sobel) would blend the two faces
    of every edge into a normal that neither has."""
    n = points_m.shape[axis]

    def shifted(k: int) -> np.ndarray:
        # out[i] = points_m[i + k] along `axis`, NaN past the border.
        out = np.full_like(points_m, np.nan)
        src, dst = [slice(None)] * 3, [slice(None)] * 3
        src[axis] = slice(max(k, 0), n + min(k, 0))
        dst[axis] = slice(max(-k, 0), n - max(k, 0))
        out[tuple(dst)] = points_m[tuple(src)]
        return out

    p, m2, m1, p1, p2 = points_m, shifted(-2), shifted(-1), shifted(1), shifted(2)
    fwd, bwd = p1 - p, p - m1

    def size(v: np.ndarray) -> np.ndarray:
        return np.nan_to_num(np.linalg.norm(v, axis=-1), nan=np.inf)

    len_fwd, len_bwd = size(fwd), size(bwd)
    # A side is clean when the step after it continues the same way (second difference well
    # under the step): one face on both steps.
    clean_fwd = size(p2 - 2 * p1 + p) < 0.5 * len_fwd
    clean_bwd = size(p - 2 * m1 + m2) < 0.5 * len_bwd
    # One clean side: take it; both or neither (a face two pixels wide): the shorter step.
    use_fwd = np.where(clean_fwd != clean_bwd, clean_fwd, len_fwd <= len_bwd)
    return np.where(use_fwd[..., None], fwd, bwd)


def surface_normals(points_m: np.ndarray, camera_m: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals of an organized point image, turned toward the camera at
    `camera_m` (NaN where the point or both its neighbours on an axis are missing)."""
    n = np.cross(_one_sided_step(points_m, 1), _one_sided_step(points_m, 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        away = np.sum(n * (points_m - camera_m), axis=-1) > 0
    n[away] *= -1
    return n


def fold_is_convex(
    normal_a: np.ndarray, normal_b: np.ndarray, step_m: np.ndarray, singular_deg: float
) -> np.ndarray:
    """Whether the surface folds convexly between points a and b = a + step_m (..., 3) with
    unit normals facing the camera: one object's own edge (a box's front face turning into
    its top face), not two objects meeting.

    Convex: neither point lies in front of the other's tangent plane (LCCP's convexity test,
    Stein et al. 2014), and the step crosses the line where the two planes meet rather than
    running along it (their sanity test: two faces crossing, a box turned on another)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = step_m / np.linalg.norm(step_m, axis=-1, keepdims=True)
        in_front = np.maximum(np.sum(normal_a * unit, -1), -np.sum(normal_b * unit, -1))
        line = np.cross(normal_a, normal_b)
        along = np.abs(np.sum(line * unit, -1)) / np.linalg.norm(line, axis=-1)
        return (in_front < 0.0) & (along < np.cos(np.deg2rad(singular_deg)))


def _cuts(
    points_m: np.ndarray,
    normals: np.ndarray,
    stretch_m: np.ndarray,
    fg: np.ndarray,
    axis: int,
    params: DepthSegmentationParams,
) -> np.ndarray:
    """Whether each pair of neighbours along `axis` is on two objects (or background):
    (H - 1, W) for axis 0, (H, W - 1) for axis 1."""
    n = points_m.shape[axis]

    def a(x: np.ndarray) -> np.ndarray:
        return np.take(x, np.arange(n - 1), axis=axis)

    def b(x: np.ndarray) -> np.ndarray:
        return np.take(x, np.arange(1, n), axis=axis)

    step_m = b(points_m) - a(points_m)
    dist_m = np.linalg.norm(step_m, axis=-1)
    limit_m = np.maximum(params.edge_jump_m, np.maximum(a(stretch_m), b(stretch_m)))
    with np.errstate(invalid="ignore", divide="ignore"):
        jump = dist_m > limit_m
        folded = np.sum(a(normals) * b(normals), axis=-1) < np.cos(
            np.deg2rad(params.normal_jump_deg)
        )
        convex = fold_is_convex(a(normals), b(normals), step_m, params.singular_deg)
    return jump | (folded & ~convex) | ~a(fg) | ~b(fg)


def segment_depth(
    obs: Observation, roi: ShelfROI, params: DepthSegmentationParams, min_pixels: int
) -> np.ndarray:
    """(H, W) int32 labels from depth alone: 0 background, 1..K objects (numbered in raster
    order of their first pixel). Segments under `min_pixels` pixels, or one pixel thin, are
    background."""
    depth_m = obs.depth_m
    points_m = obs.camera.depth_to_points(depth_m)
    camera_m = obs.camera.T_world_from_cam[:3, 3]
    normals = surface_normals(points_m, camera_m)
    fg = (depth_m > 0) & roi.contains(points_m, params.board_margin_m)
    # The spacing of neighbours on an unbroken face: one footprint head-on, footprint /
    # sin(incidence) obliquely (incidence from the pixel's own normal).
    footprint_m = depth_m.astype(np.float64) / obs.camera.K[0, 0]
    rays = points_m - camera_m
    with np.errstate(invalid="ignore"):
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    sin_incidence = np.nan_to_num(np.abs(np.sum(normals * rays, axis=-1)), nan=1.0)
    sin_incidence = np.clip(sin_incidence, np.sin(np.deg2rad(params.min_incidence_deg)), 1.0)
    stretch_m = params.edge_jump_px * footprint_m / sin_incidence
    cut_v = _cuts(points_m, normals, stretch_m, fg, 0, params)
    cut_h = _cuts(points_m, normals, stretch_m, fg, 1, params)
    # Components on a doubled grid: pixel (i, j) at (2i, 2j), the link between two neighbours
    # in the cell between them, so a cut separates two pixels without deleting either.
    h, w = depth_m.shape
    grid = np.zeros((2 * h - 1, 2 * w - 1), dtype=np.uint8)
    grid[::2, ::2] = fg
    grid[1::2, ::2] = ~cut_v
    grid[::2, 1::2] = ~cut_h
    n, comp = cv2.connectedComponents(grid, connectivity=4)
    comp = np.where(fg, comp[::2, ::2], 0)
    # A sliver (a top or side face seen edge-on, one pixel wide) is no object: an object has
    # somewhere a 2 x 2 block of its own pixels.
    tl = comp[:-1, :-1]
    block = (tl == comp[1:, :-1]) & (tl == comp[:-1, 1:]) & (tl == comp[1:, 1:])
    has_block = np.bincount(tl[block], minlength=n) > 0
    big = np.bincount(comp.ravel(), minlength=n) >= min_pixels
    keep = np.flatnonzero(big & has_block)
    keep = keep[keep > 0]
    lut = np.zeros(n, dtype=np.int32)
    lut[keep] = np.arange(1, keep.size + 1, dtype=np.int32)
    return lut[comp]
