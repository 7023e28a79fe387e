"""What a real depth sensor returns for an exact depth image (docs/sensing.md).

The renderer's depth (`sim/render.py`) is exact. `sense` turns it into what a phase-shift
structured-light camera or an active-stereo camera would return, from the sensor's geometry:

- depth noise from a disparity error: d = f * b / z, Gaussian disparity noise of the sensor's
  subpixel RMS (correlated over the block-matching window where there is one), quantised to
  the disparity step, z = f * b / d back; so sigma_z ~ z^2 * sigma_d / (f * b). f is the
  sensor's own focal length in its own pixels, so the metric noise is the hardware's
  whatever our image's size;
- shadows: a pixel whose point the second view (the projector, or the second camera) cannot
  see has no depth, found by reprojecting the image into that view and z-buffering it;
- foreground fattening: block matching spreads the foreground over the background by half
  its window (native pixels, converted to ours with the two focal lengths);
- missing and flying pixels at depth steps, and a small random dropout.

Pure numpy and OpenCV. `sim/noise.py` is the older parametric training augmentation, kept as
it is; `PRESETS["ideal"]` (None) leaves the image exact.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from typing import Literal

import cv2
import numpy as np

from clutterbench.config import bounded
from clutterbench.errors import ClutterbenchError
from clutterbench.observation import CameraModel

_FAR = 1e6
"""Stands in for 'no return' where a minimum over depths is taken (metres)."""
_MAX_GAP_PX = 4
"""Gaps up to this many columns between the reprojections of two neighbouring pixels of one
surface are filled in the second view's z-buffer (a surface it sees stretched)."""


@dataclasses.dataclass(frozen=True)
class SensorConfig:
    """A triangulating depth sensor: the depth camera and a second view at `baseline_m`."""

    kind: Literal["structured_light", "active_stereo"] = "active_stereo"
    """Principle: phase-shift structured light (each pixel decodes its own phase: no
    matching window) or active stereo (block matching on a projected dot texture)."""
    baseline_m: float = bounded(0.055, gt=0.0)
    """Distance from the depth camera to the second view (m): the projector, or the second
    camera."""
    second_view: Literal["+x", "-x"] = "+x"
    """Side of the second view along the depth camera's x axis (OpenCV: +x is image right).
    Its shadows fall on the other side of each foreground object."""
    focal_px: float = bounded(1004.6, gt=0.0)
    """The sensor's own focal length, in its own (native) pixels: disparity = focal_px * b / z."""
    width_px: int = bounded(1280, ge=1)
    """The sensor's own image width (px); with focal_px, its horizontal field of view."""
    subpixel_px: float = bounded(0.08, ge=0.0)
    """Disparity error, RMS, in native pixels."""
    disparity_step_px: float = bounded(1 / 32, ge=0.0)
    """Disparity quantisation step (native px); 0: continuous."""
    window_px: float = bounded(7.0, ge=0.0)
    """Block-matching window side (native px): the noise is correlated over it and the
    foreground spreads over the background by half of it. 0: per-pixel correspondences (no
    fattening, white noise)."""
    min_range_m: float = bounded(0.45, ge=0.0)
    """Nearest depth returned (m); nearer measured depths are no return."""
    max_range_m: float = bounded(10.0, gt=0.0)
    """Farthest depth returned (m)."""
    dropout: float = bounded(0.005, ge=0.0, le=1.0)
    """Fraction of pixels that return nothing, at random."""
    step_m: float = bounded(0.01, gt=0.0)
    """A depth difference between 4-neighbours above this, beyond the surface's own slope, is
    a step (m: `step_pairs`); also the tolerance of the shadow test (a point farther than what
    the second view sees by more than this is hidden from it)."""
    step_missing: float = bounded(0.5, ge=0.0, le=1.0)
    """Probability that a pixel beside a step returns nothing."""
    step_flying: float = bounded(0.2, ge=0.0, le=1.0)
    """Probability that a pixel beside a step returns a depth between its own and its
    neighbour's across the step (a flying pixel); at most 1 - step_missing."""

    def __post_init__(self) -> None:
        if self.step_missing + self.step_flying > 1.0 + 1e-12:
            raise ValueError("step_missing + step_flying: more than 1")
        if self.min_range_m >= self.max_range_m:
            raise ValueError(f"min_range_m {self.min_range_m} >= max_range_m {self.max_range_m}")

    @property
    def hfov_deg(self) -> float:
        """The sensor's own horizontal field of view (degrees)."""
        return math.degrees(2 * math.atan(self.width_px / 2 / self.focal_px))


STRUCTURED_LIGHT = SensorConfig(
    kind="structured_light",
    # YOODS YCAM3D (the thesis' YCAM3D-10L's family; no 10L datasheet found): the rectified
    # pair in YOODS' public ROS driver (github.com/YOODS/rovi, yaml/ycam3sxga.yaml):
    # P_right[0,3] = -167.32 with f = 2070.32 px -> 80.8 mm; SXGA 1280 x 1024; depth is
    # computed in the left camera, the right one sits at +x.
    baseline_m=0.0808,
    second_view="+x",
    focal_px=2070.3,
    width_px=1280,
    # phase-shift correspondence ~1% of the imaged fringe period (Optics Express 21(18)
    # 21119, 2013, citing phase-stepping practice); the driver decodes fringes >= 8-10 px
    # wide (rovi's parameter phase_wd_min) -> 0.1 px
    subpixel_px=0.1,
    disparity_step_px=0.0,  # phase is continuous
    window_px=0.0,  # each pixel decodes its own phase
    # rovi's parallax search (max_parallax 500 px, principal-point offset 395 px):
    # 167.3 / 895 = 0.19 m; no far limit is published: the renderer's far plane (2 m)
    min_range_m=0.19,
    max_range_m=2.0,
    dropout=0.005,  # assumed (as sim/noise.py's augmentation)
    step_m=0.01,  # assumed
    step_missing=0.5,  # assumed, the same for every preset: no published rate
    step_flying=0.2,  # assumed, likewise
)
"""The thesis' sensor class: a phase-shift structured-light camera (YOODS YCAM3D)."""

D415 = SensorConfig(
    kind="active_stereo",
    baseline_m=0.055,  # Intel D400-series datasheet
    second_view="+x",  # depth is in the left imager's frame, the right imager at +x
    focal_px=1280 / 2 / math.tan(math.radians(65 / 2)),  # 1280 px over 65 deg HFOV: 1004.6
    width_px=1280,
    subpixel_px=0.08,  # Intel's tuning white paper; Keselman et al. 2017 for the formula
    disparity_step_px=1 / 32,  # D4 subpixel resolution (Intel, subpixel-linearity paper)
    # census aggregation window 7 x 7 (Keselman et al. 2017, for the R200; the D4's own
    # window is not published: assumed the same)
    window_px=7.0,
    min_range_m=0.45,  # datasheet Min-Z at 1280 x 720 (~0.16 m only at lower resolutions)
    max_range_m=10.0,  # datasheet: up to ~10 m
    dropout=0.005,  # assumed (as sim/noise.py's augmentation)
    step_m=0.01,  # assumed
    step_missing=0.5,  # assumed, the same for every preset: no published rate
    step_flying=0.2,  # assumed, likewise
)
"""Intel RealSense D415 class consumer active stereo (1280 x 720 depth)."""

PRESETS: dict[str, SensorConfig | None] = {
    "ideal": None,
    "structured_light": STRUCTURED_LIGHT,
    "d415": D415,
}
"""The sensors by name: `ideal` is the renderer's exact depth (the ceiling)."""

RANDOMIZED_FIELDS = ("subpixel_px", "window_px", "dropout", "step_missing", "step_flying")
"""What `randomized` varies: the noise, not the hardware's geometry (baseline, focal length,
ranges, quantisation step)."""


def preset(name: str) -> SensorConfig | None:
    """The preset called `name`; an unknown name is a one-line error naming the known ones."""
    if name not in PRESETS:
        raise ClutterbenchError(f"unknown sensor preset {name!r} (known: {', '.join(PRESETS)})")
    return PRESETS[name]


def randomized(
    cfg: SensorConfig | None, rng: np.random.Generator, spread: float
) -> SensorConfig | None:
    """`cfg` with each of RANDOMIZED_FIELDS scaled by its own factor drawn uniformly in
    [1 - spread, 1 + spread] (probabilities kept <= 1); None stays None."""
    if not 0.0 <= spread < 1.0:
        raise ClutterbenchError(f"sensor spread {spread}: not in [0, 1)")
    if cfg is None:
        return None
    factors = rng.uniform(1.0 - spread, 1.0 + spread, size=len(RANDOMIZED_FIELDS))
    new = {k: getattr(cfg, k) * float(f) for k, f in zip(RANDOMIZED_FIELDS, factors)}
    new["dropout"] = min(new["dropout"], 1.0)
    at_steps = new["step_missing"] + new["step_flying"]
    if at_steps > 1.0:
        new["step_missing"] /= at_steps
        new["step_flying"] /= at_steps
    return dataclasses.replace(cfg, **new)


@dataclasses.dataclass(frozen=True)
class SensedAugmentation:
    """The training augmentation of a sensor preset: each depth image passes through `sense`
    with the preset's noise randomised around it (`randomized`, `spread`), so a network sees
    the sensor it will meet and not one fixed instance of it. `fx_px`: our images' focal
    length (pixels), from the camera they were rendered with."""

    sensor: SensorConfig
    fx_px: float
    spread: float = 0.2

    def apply(self, depth_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        camera = pinhole(self.fx_px, depth_m.shape[-2:])
        return sense(depth_m, camera, randomized(self.sensor, rng, self.spread), rng)


def pinhole(fx_px: float, shape: tuple[int, ...]) -> CameraModel:
    """The camera `sense` needs for an image of `shape` (H, W) rendered without a world at
    hand (a stored depth image): focal length fx_px, principal point at the centre, as the
    renderer makes it; the pose (unused by `sense`) the identity."""
    h, w = shape
    K = np.array([[fx_px, 0.0, w / 2], [0.0, fx_px, h / 2], [0.0, 0.0, 1.0]])
    return CameraModel(K=K, T_world_from_cam=np.eye(4))


def focal_px(image_size: int, fovy_deg: float) -> float:
    """The focal length (pixels) of a square image `image_size` wide seen over `fovy_deg`, as
    the renderer makes it (f = (H / 2) / tan(fovy / 2))."""
    return (image_size / 2) / math.tan(math.radians(fovy_deg) / 2)


def observation_rng(seed: int, depth_m: np.ndarray) -> np.random.Generator:
    """A generator seeded by `seed` and a hash of the image (its dtype, shape and bytes): the
    same observation always gets the same noise, different observations different noise."""
    a = np.ascontiguousarray(depth_m)
    h = hashlib.blake2b(f"{a.dtype.str}{a.shape}".encode(), digest_size=8)
    h.update(a.tobytes())
    return np.random.default_rng([int(seed), int.from_bytes(h.digest(), "little")])


def sense_images(depth_m: np.ndarray, name: str, fovy_deg: float, seed: int) -> np.ndarray:
    """Stored depth images (N, H, W), rendered over `fovy_deg`, as the preset `name` returns
    each (`sense`, seeded by `seed` and the image: a rerun sees the same returns); `ideal`
    returns `depth_m` itself. A network trained on a sensor is validated and scored on these."""
    cfg = preset(name)
    if cfg is None:
        return depth_m
    camera = pinhole(focal_px(depth_m.shape[-1], fovy_deg), depth_m.shape[-2:])
    return np.stack([sense(d, camera, cfg, observation_rng(seed, d)) for d in depth_m])


def sense(
    depth_m: np.ndarray,
    camera: CameraModel,
    cfg: SensorConfig | None,
    rng: np.random.Generator,
) -> np.ndarray:
    """What the sensor `cfg` returns for the exact depth `depth_m` (float32 metres along the
    optical axis, 0 = no return) seen by `camera`: float32, same shape, 0 = no return, never
    NaN or inf; a pixel with no exact depth stays 0. cfg None returns `depth_m` itself.

    Four full-image random fields are drawn from `rng` whatever the configuration (disparity
    noise, step, flying-depth and dropout draws), so turning one effect off leaves the
    others' draws as they were."""
    if cfg is None:
        return depth_m
    assert depth_m.dtype == np.float32 and depth_m.ndim == 2, "depth must be (H, W) float32"
    if depth_m.size == 0:
        return depth_m.copy()
    shape = depth_m.shape
    white = rng.standard_normal(shape)
    step_u, flying_t, drop_u = rng.random(shape), rng.random(shape), rng.random(shape)

    exact = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, 0.0).astype(np.float64)
    fx = float(camera.K[0, 0])
    ours_per_native = fx / cfg.focal_px
    z = fatten(exact, 0.5 * cfg.window_px * ours_per_native, cfg.step_m)
    at_step, across = _steps(z, cfg.step_m)
    flying = at_step & (step_u >= cfg.step_missing)
    flying &= step_u < cfg.step_missing + cfg.step_flying
    z = np.where(flying, z + flying_t * (across - z), z)
    z[at_step & (step_u < cfg.step_missing)] = 0.0
    z[shadowed(exact, fx, cfg.baseline_m, cfg.second_view, cfg.step_m)] = 0.0
    z = _disparity_noise(z, cfg, white, cfg.window_px * ours_per_native)
    z[(z < cfg.min_range_m) | (z > cfg.max_range_m) | (drop_u < cfg.dropout)] = 0.0
    out = z.astype(np.float32)
    out[~np.isfinite(out) | (exact <= 0)] = 0.0
    return out


def shadowed(
    depth_m: np.ndarray, fx_px: float, baseline_m: float, side: str, tol_m: float
) -> np.ndarray:
    """(H, W) bool: the pixels whose point a second view cannot see. The second view has the
    camera's orientation and intrinsics and sits `baseline_m` along the camera's x axis
    (`side` "+x" or "-x"), so a point reprojects on its own row, shifted by its disparity
    fx * b / z; z-buffered there, a pixel farther than the nearest point landing in its
    column by more than `tol_m` is hidden. Points reprojected outside the image count as
    seen (the sensor's field of view is taken to cover ours)."""
    h, w = depth_m.shape
    z = depth_m.astype(np.float64)
    valid = z > 0
    sign = 1.0 if side == "+x" else -1.0
    u2 = (np.arange(w) + 0.5)[None, :] - sign * fx_px * baseline_m / np.where(valid, z, 1.0)
    col = np.floor(u2).astype(np.int64)
    inside = valid & (col >= 0) & (col < w)
    row_start = (np.arange(h, dtype=np.int64) * w)[:, None]
    flat = row_start + np.clip(col, 0, w - 1)
    zbuf = np.full(h * w, np.inf)
    np.minimum.at(zbuf, flat[inside], z[inside])
    # a surface the second view sees stretched reprojects with gaps between neighbours
    a, b, ca, cb = z[:, :-1], z[:, 1:], col[:, :-1], col[:, 1:]
    lo, hi = np.minimum(ca, cb), np.maximum(ca, cb)
    gap = valid[:, :-1] & valid[:, 1:] & (np.abs(a - b) <= tol_m) & (hi - lo > 1)
    lo, hi, zfar = lo[gap], hi[gap], np.maximum(a, b)[gap]
    starts = np.broadcast_to(row_start, gap.shape)[gap]
    for k in range(1, _MAX_GAP_PX + 1):
        c = lo + k
        fill = (c < hi) & (c >= 0) & (c < w)
        np.minimum.at(zbuf, (starts + c)[fill], zfar[fill])
    return inside & (z > zbuf[flat] + tol_m)


def step_pairs(z: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The depth steps of `z` between 4-neighbours: (H, W - 1) bool for each pixel and its right
    neighbour, (H - 1, W) bool for each pixel and the one below. A step is a discontinuity of
    the surface, not a steep slope: the pair's depth difference exceeds `step_m`, and so does its
    difference from the next pair's on either side along the same line (the surface's own
    slope, where both pixels of that pair have a return). A surface sampled at our pixels, far
    coarser than the sensor's own, changes depth by a centimetre per pixel where it is seen at a
    grazing angle; the sensor, at its own resolution, sees no step there. A pair with no
    neighbouring pair to compare with is a step by its difference alone."""
    return _pairs_along(z, step_m), _pairs_along(z.T, step_m).T


def _pairs_along(z: np.ndarray, step_m: float) -> np.ndarray:
    """step_pairs along each row of `z`: (H, W - 1) bool. Only the pairs whose difference
    exceeds `step_m` (few: the edges of objects) are compared with their neighbours."""
    valid = z > 0
    both = valid[:, :-1] & valid[:, 1:]
    d = z[:, 1:] - z[:, :-1]
    out = both & (np.abs(d) > step_m)
    i, j = np.nonzero(out)
    if i.size == 0:
        return out
    last = d.shape[1] - 1
    jl, jr = np.maximum(j - 1, 0), np.minimum(j + 1, last)
    has_l, has_r = (j > 0) & both[i, jl], (j < last) & both[i, jr]
    dij = d[i, j]
    by_l, by_r = np.abs(dij - d[i, jl]), np.abs(dij - d[i, jr])
    beside = np.where(has_l, np.where(has_r, np.minimum(by_l, by_r), by_l), by_r)
    residual = np.where(has_l | has_r, beside, np.abs(dij))  # neither side: the difference
    out[i, j] = residual > step_m
    return out


def fatten(depth_m: np.ndarray, radius_px: float, step_m: float) -> np.ndarray:
    """Block matching's foreground fattening: across each depth step (`step_pairs`), every
    pixel of the far side within `radius_px` (rounded; a disc) of the step's near pixel takes
    the nearest such depth, if nearer by more than `step_m`. A slope is no step, so a surface
    seen at a grazing angle keeps its own depth. Pixels with no return stay 0."""
    r = int(math.floor(radius_px + 0.5))
    if r < 1:
        return depth_m
    near, far = _step_sides(depth_m, step_pairs(depth_m, step_m))
    edge = np.where(near, depth_m, _FAR)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    nearest = cv2.erode(edge, disc, borderType=cv2.BORDER_REPLICATE)
    if r > 1:
        band = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r - 1, 2 * r - 1))
        far = cv2.dilate(far.astype(np.uint8), band).astype(bool)
    grow = far & (depth_m > 0) & (depth_m - nearest > step_m)
    return np.where(grow, nearest, depth_m)


def _step_sides(z: np.ndarray, pairs: tuple[np.ndarray, np.ndarray]):
    """(H, W) bool of the near pixels and of the far pixels of the steps `pairs`."""
    near, far = np.zeros(z.shape, bool), np.zeros(z.shape, bool)
    right, down = pairs
    for step, a, b, ia, ib in (
        (right, z[:, :-1], z[:, 1:], np.s_[:, :-1], np.s_[:, 1:]),
        (down, z[:-1], z[1:], np.s_[:-1], np.s_[1:]),
    ):
        first_near = step & (a < b)
        near[ia] |= first_near
        far[ib] |= first_near
        near[ib] |= step & ~first_near
        far[ia] |= step & ~first_near
    return near, far


def _steps(z: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) bool of the pixels beside a step (`step_pairs`) and the depth across the largest
    of their steps (the pixel's own elsewhere; of equal steps, the first of above, below,
    left, right)."""
    right, down = step_pairs(z, step_m)
    h, w = z.shape
    row, col = np.zeros((1, w), bool), np.zeros((h, 1), bool)
    steps = (
        (np.vstack([row, down]), -1, 0),  # the pixel above
        (np.vstack([down, row]), 1, 0),  # below
        (np.hstack([col, right]), 0, -1),  # left
        (np.hstack([right, col]), 0, 1),  # right
    )
    i, j = np.nonzero(steps[0][0] | steps[1][0] | steps[2][0] | steps[3][0])
    zij = z[i, j]
    biggest = np.zeros_like(zij)
    across_ij = zij.copy()
    for step, di, dj in steps:
        nb = z[np.clip(i + di, 0, h - 1), np.clip(j + dj, 0, w - 1)]
        diff = np.where(step[i, j], np.abs(nb - zij), 0.0)
        bigger = diff > biggest
        biggest = np.where(bigger, diff, biggest)
        across_ij = np.where(bigger, nb, across_ij)
    at_step = np.zeros(z.shape, bool)
    at_step[i, j] = biggest > 0
    across = z.copy()
    across[i, j] = across_ij
    return at_step, across


def _disparity_noise(
    z: np.ndarray, cfg: SensorConfig, white: np.ndarray, window_ours_px: float
) -> np.ndarray:
    """Depth through the sensor's disparity: d = f * b / z in native pixels, plus noise of
    RMS subpixel_px (white, or correlated over the window), quantised, and back to depth."""
    valid = z > 0
    fb = cfg.focal_px * cfg.baseline_m
    d = fb / np.where(valid, z, 1.0) + cfg.subpixel_px * correlated(white, window_ours_px)
    if cfg.disparity_step_px > 0:
        d = np.round(d / cfg.disparity_step_px) * cfg.disparity_step_px
    ok = valid & (d > 0)
    return np.where(ok, fb / np.where(ok, d, 1.0), 0.0)


def correlated(white: np.ndarray, window_px: float) -> np.ndarray:
    """Unit-variance Gaussian noise correlated over a window of `window_px` (our pixels):
    `white` smoothed by a Gaussian with a box window's second moment (sigma = w / sqrt(12))
    and renormalised by the kernel's norm. Below half a pixel of sigma it stays white."""
    sigma = window_px / math.sqrt(12.0)
    if sigma < 0.5:
        return white
    k = cv2.getGaussianKernel(2 * math.ceil(3 * sigma) + 1, sigma, cv2.CV_64F)
    smooth = cv2.sepFilter2D(white, cv2.CV_64F, k, k, borderType=cv2.BORDER_REFLECT_101)
    return smooth / float(np.sum(k**2))
