"""What a depth sensor leaves in its image, as region growing (perception/region_growing.py) reads
it: the noise of its returns, white or correlated over a few pixels (active stereo's block
matching smooths its disparity noise over its window: sim/sensor.py), and which pixels it
measured at all (no return: shadows, steps, dropout; the plane fit fills them, but a filled
pixel is no evidence that an object is there).

Both leave exact depth as it is: it has no noise above the floor and no hole inside the shelf."""

from __future__ import annotations

import numpy as np

_MAD_TO_SIGMA = 1.4826
"""Median absolute deviation to standard deviation, for Gaussian noise."""
PLANAR_K = 3.0
"""A lag-1 second difference over this many of its own standard deviations marks an edge or a
fold, not noise: the longer lags are measured only over spans free of such marks."""


def lag_noise(w: np.ndarray, valid: np.ndarray, lag: int, edge: float = np.inf) -> float:
    """Standard deviation of the noise of `w` (1 / depth) where `valid`, from second differences
    `lag` pixels apart (w[i - lag] - 2 w[i] + w[i + lag], zero on any plane) along columns and
    rows: their median absolute value over sqrt(6); only over spans whose lag-1 second
    differences are all valid and at most `edge`; 0.0 where there are none. Lag 1 is the white
    noise's estimate (edges are the median's outliers)."""
    found = []
    for a, ok in ((w, valid), (w.T, valid.T)):
        n = a.shape[0]
        if n <= 2 * lag:
            continue
        d1 = np.abs(a[:-2] - 2 * a[1:-1] + a[2:])
        flat = np.pad(ok[:-2] & ok[1:-1] & ok[2:] & (d1 <= edge), ((1, 1), (0, 0)))
        good = np.ones((n - 2 * lag, a.shape[1]), dtype=bool)
        for k in range(1 - lag, lag):  # every centre strictly inside the span
            good &= flat[lag + k : n - lag + k]
        found.append(np.abs(a[: n - 2 * lag] - 2 * a[lag : n - lag] + a[2 * lag :])[good])
    d2 = np.concatenate(found) if found else np.zeros(0)
    return float(_MAD_TO_SIGMA * np.median(d2) / np.sqrt(6.0)) if d2.size else 0.0


def depth_noise(
    w: np.ndarray, valid: np.ndarray, floor: float, max_lag: int, ratio: float
) -> tuple[float, int]:
    """(standard deviation of the noise of `w` = 1 / depth, pixels it is correlated over): the
    white noise's estimate (lag 1, correlation 1), unless the estimate at a longer lag (up to
    `max_lag`, over planar spans) exceeds it, or `floor` if more, by `ratio`: then the noise is
    correlated, the largest of those estimates its size and its lag the correlation. Correlated
    noise hides from adjacent pixels' differences (they move together) but bends the fitted
    planes over the span it is correlated over."""
    white = lag_noise(w, valid, 1)
    edge = PLANAR_K * np.sqrt(6.0) * white
    longer = [(lag_noise(w, valid, lag, edge), lag) for lag in range(2, max_lag + 1)]
    sigma, lag = max(longer, default=(0.0, 1))
    return (sigma, lag) if sigma > ratio * max(white, floor) else (white, 1)


def support_weight(depth_m: np.ndarray, hole_weight: float) -> np.ndarray:
    """(H, W) float: what each pixel counts towards a segment's size: 1 where the sensor
    returned a depth, `hole_weight` where it did not (0, NaN: filled in by the plane fit)."""
    measured = np.isfinite(depth_m) & (depth_m > 0)
    return np.where(measured, 1.0, hole_weight)


def window_side(
    noise_px: float, max_window_px: int, normal_noise_deg: float, corr_px: int = 1
) -> tuple[int, float]:
    """The plane-fit window's side (odd, pixels, at most `max_window_px`: the first whose
    normals err by at most `normal_noise_deg`) and its normals' expected error (degrees) at
    depth noise `noise_px` (footprints) correlated over `corr_px` pixels: a least-squares slope
    over m x m points one footprint apart errs by sqrt(12) sigma / (m sqrt(m^2 - 1)); correlated,
    the points are as many independent ones corr_px apart, n = m / corr_px to a side."""

    def error_deg(m: int) -> float:
        n2 = max((m / corr_px) ** 2 - 1.0, 1e-12)
        return float(np.rad2deg(np.sqrt(12.0) * noise_px / (m * np.sqrt(n2))))

    sides = range(3, max(3, max_window_px) + 1, 2)
    m = next((m for m in sides if error_deg(m) <= normal_noise_deg), sides[-1])
    return m, error_deg(m)
