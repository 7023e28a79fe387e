"""The sensor's marks as region growing reads them (perception/sensor_marks.py): the noise of
1 / depth, white or correlated, measured on planes with edges; what a missing return counts."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from clutterbench.perception.sensor_marks import depth_noise, lag_noise, support_weight

SIGMA = 0.01
FLOOR = 1e-4


def planes(size: int = 128) -> np.ndarray:
    """1 / depth of two tilted planes meeting at a step down the middle (values ~1.5-2.5)."""
    v, u = np.mgrid[0:size, 0:size] / size
    return np.where(u < 0.5, 2.0 + 0.3 * u - 0.2 * v, 1.5 + 0.1 * u + 0.4 * v)


def correlated(shape: tuple[int, int], sigma_px: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance Gaussian noise smoothed over `sigma_px` pixels."""
    white = rng.standard_normal(shape)
    k = cv2.getGaussianKernel(2 * int(np.ceil(3 * sigma_px)) + 1, sigma_px, cv2.CV_64F)
    smooth = cv2.sepFilter2D(white, cv2.CV_64F, k, k, borderType=cv2.BORDER_REFLECT_101)
    return smooth / np.sqrt(np.sum(k**2) ** 2)


def test_planes_and_steps_have_no_noise():
    w = planes()
    valid = np.ones(w.shape, dtype=bool)
    assert lag_noise(w, valid, 1) < 1e-9
    assert depth_noise(w, valid, FLOOR, 3, 1.25) == (lag_noise(w, valid, 1), 1)


def test_white_noise_is_measured_at_lag_one():
    rng = np.random.default_rng(0)
    w = planes() + SIGMA * rng.standard_normal((128, 128))
    valid = rng.random(w.shape) > 0.05  # holes are skipped
    sigma, corr = depth_noise(w, valid, FLOOR, 3, 1.25)
    assert corr == 1
    assert sigma == pytest.approx(SIGMA, rel=0.1)


@pytest.mark.parametrize("sigma_px", [0.7, 1.0])
def test_correlated_noise_is_measured_at_its_span(sigma_px):
    """Neighbours' differences see a fraction of correlated noise; the longest lag nearly all."""
    rng = np.random.default_rng(1)
    noise = correlated((256, 256), sigma_px, rng)
    assert noise.std() == pytest.approx(1.0, rel=0.1)
    w = planes(256) + SIGMA * noise
    valid = np.ones(w.shape, dtype=bool)
    assert lag_noise(w, valid, 1) < 0.6 * SIGMA
    sigma, corr = depth_noise(w, valid, FLOOR, 3, 1.25)
    assert corr > 1
    assert 0.7 * SIGMA < sigma <= 1.1 * SIGMA
    # Below the floor the noise counts as none (exact depth): white, whatever its lags say.
    assert depth_noise(w, valid, 10 * SIGMA, 3, 1.25)[1] == 1


def test_a_missing_return_counts_the_hole_weight():
    depth = np.array([[0.6, 0.0, np.nan, -1.0]], dtype=np.float32)
    assert support_weight(depth, 0.25).tolist() == [[1.0, 0.25, 0.25, 0.25]]
