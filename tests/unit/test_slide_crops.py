"""The chapter 3 raster scan and slide crops: 800 candidates, crops turned so the slide
points up (thesis 3.3.1)."""

import numpy as np
import pytest

from clutterbench.data.slide_crops import ScanConfig, piece_under, raster_candidates, slide_crop
from clutterbench.observation import CameraModel, Observation

HEIGHT_M = 0.5


def top_camera(size: int = 128, fov_m: float = 0.4) -> CameraModel:
    """A camera HEIGHT_M above the board centre looking straight down."""
    f = size / 2 / (fov_m / 2 / HEIGHT_M)
    K = np.array([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # OpenCV x = world x, y = -world y, z = -world z
    T[2, 3] = HEIGHT_M
    return CameraModel(K=K, T_world_from_cam=T)


def board_xy(cam: CameraModel, size: int) -> np.ndarray:
    depth = np.full((size, size), HEIGHT_M, dtype=np.float32)
    return cam.depth_to_points(depth)[..., :2]


def bump_heights(cam: CameraModel, size: int, at_xy, radius_m: float = 0.012) -> np.ndarray:
    xy = board_xy(cam, size)
    return np.where(np.hypot(*(xy - np.asarray(at_xy)).transpose(2, 0, 1)) < radius_m, 0.02, 0.0)


def test_raster_scan_has_800_candidates_on_a_10x10_grid_and_8_directions():
    cands = raster_candidates(ScanConfig())
    assert len(cands) == 800
    assert len(np.unique(cands.start_xy, axis=0)) == 100
    assert sorted(np.unique(cands.direction)) == list(range(8))
    np.testing.assert_allclose(np.unique(cands.angle_rad), np.arange(8) * np.pi / 4)


@pytest.mark.parametrize("direction", range(8))
def test_crop_turns_the_slide_direction_up(direction):
    size, crop_px = 128, 64
    cam = top_camera(size)
    start = np.array([0.03, -0.02])
    theta = direction * np.pi / 4
    d = np.array([np.cos(theta), np.sin(theta)])
    right = np.array([d[1], -d[0]])
    ahead = slide_crop(bump_heights(cam, size, start + 0.06 * d), cam, start, theta, 0.16, crop_px)
    rows, cols = np.nonzero(ahead > 0.01)
    start_row = 0.75 * crop_px
    # 0.06 m ahead = 24 px up from the start row, on the centre column
    assert abs(rows.mean() - (start_row - 0.06 / 0.16 * crop_px)) < 1.5
    assert abs(cols.mean() - crop_px / 2) < 1.5
    beside = slide_crop(
        bump_heights(cam, size, start + 0.04 * right), cam, start, theta, 0.16, crop_px
    )
    rows, cols = np.nonzero(beside > 0.01)
    assert abs(rows.mean() - start_row) < 1.5
    assert abs(cols.mean() - (crop_px / 2 + 0.04 / 0.16 * crop_px)) < 1.5


def test_piece_under_reads_the_instance_at_board_points():
    size = 128
    cam = top_camera(size)
    xy = board_xy(cam, size)
    instance = np.where(xy[..., 0] > 0.05, 3, 0).astype(np.uint8)
    obs = Observation(np.full((size, size), HEIGHT_M, np.float32), instance, cam)
    assert list(piece_under(obs, np.array([[0.1, 0.0], [-0.1, 0.02]]))) == [2, -1]


def test_piece_under_with_a_margin_leaves_out_edges():
    size = 128
    cam = top_camera(size)
    xy = board_xy(cam, size)
    instance = np.where(xy[..., 0] > 0.05, 3, 0).astype(np.uint8)
    obs = Observation(np.full((size, size), HEIGHT_M, np.float32), instance, cam)
    px_m = 0.4 / size
    points = np.array([[0.05 + 1.5 * px_m, 0.0], [0.05 + 6 * px_m, 0.0]])
    assert list(piece_under(obs, points)) == [2, 2]
    assert list(piece_under(obs, points, margin_px=3)) == [-1, 2]
