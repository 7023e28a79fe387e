"""Pure label, geometry, split and I/O functions against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.data.labels import (
    CLASS_B,
    CLASS_C,
    CLASS_E,
    CLASS_S,
    PULL_CLASSES,
    ch4_class_map,
    collapse_mask,
    moved_matrix,
    support_edges,
    target_mask,
)
from clutterbench.data.split import Fractions, split_scenes
from clutterbench.io import load_npz, save_npz
from clutterbench.sim.geometry import (
    box_aabb_half_extents,
    displacement_m,
    quat_from_axis_angle,
    quat_mul,
    quat_to_matrix,
)
from clutterbench.sim.noise import DepthNoiseConfig, add_depth_noise
from clutterbench.sim.shelf import Shelf

NAN = np.nan


def test_moved_matrix_thresholds_and_ignores_nan():
    d = np.array([[NAN, 0.02, 0.001], [0.0, NAN, 0.0], [0.006, 0.0049, NAN]])
    m = moved_matrix(d, 0.005)
    assert m.tolist() == [[False, True, False], [False, False, False], [True, False, False]]
    assert support_edges(d, 0.005) == [(0, 1), (2, 0)]


def test_masks_from_instance_image():
    inst = np.array([[0, 1, 1], [2, 3, 0]], dtype=np.uint8)
    assert target_mask(inst, 0).tolist() == [[0, 1, 1], [0, 0, 0]]
    assert collapse_mask(inst, np.array([False, True, True])).tolist() == [[0, 0, 0], [1, 1, 0]]
    with pytest.raises(AssertionError):
        target_mask(inst.astype(np.int32), 0)


def test_ch4_class_map_on_four_boxes():
    # Boxes 0..3 drawn as ids 1..4; box 0 is pulled out while box 2 is held.
    inst = np.array(
        [
            [0, 1, 1, 2, 2],
            [0, 1, 1, 2, 2],
            [3, 3, 4, 4, 0],
            [3, 3, 4, 4, 0],
        ],
        dtype=np.uint8,
    )
    # box 1 moves 6 mm (> 5 mm: C), box 3 moves 5 mm exactly (not more: B)
    disp = np.array([NAN, 0.006, NAN, 0.005])
    B, E, S, C = CLASS_B, CLASS_E, CLASS_S, CLASS_C
    expected = [[B, E, E, C, C], [B, E, E, C, C], [S, S, B, B, B], [S, S, B, B, B]]
    got = ch4_class_map(inst, 0, 2, disp, 0.005)
    assert got.dtype == np.uint8 and got.tolist() == expected
    assert PULL_CLASSES[C] == "C" and PULL_CLASSES[B] == "B" and C == len(PULL_CLASSES) - 1
    # The extracted and held boxes are E and S whatever their displacement; NaN never moves.
    disp = np.array([0.3, NAN, 0.2, 0.01])
    expected = [[B, E, E, B, B], [B, E, E, B, B], [S, S, C, C, B], [S, S, C, C, B]]
    assert ch4_class_map(inst, 0, 2, disp, 0.005).tolist() == expected
    # Swapping the roles swaps E and S.
    swapped = ch4_class_map(inst, 2, 0, disp, 0.005)
    assert (swapped == E).tolist() == (got == S).tolist()
    with pytest.raises(AssertionError):
        ch4_class_map(inst, 1, 1, disp, 0.005)


def test_quaternions_and_aabb():
    q = quat_from_axis_angle([0, 0, 1], np.pi / 2)
    assert np.allclose(quat_to_matrix(q) @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(quat_mul(q, q), quat_from_axis_angle([0, 0, 1], np.pi))
    assert np.allclose(box_aabb_half_extents(np.array([0.1, 0.2, 0.04]), q), [0.1, 0.05, 0.02])
    before, after = np.zeros((2, 3)), np.array([[0.0, 0.0, 0.0], [0.003, 0.004, 0.0]])
    assert np.allclose(displacement_m(before, after), [0.0, 0.005])


def test_shelf_contains():
    s = Shelf()
    pts = np.array([[0.1, 0.0, 0.05], [-0.05, 0.0, 0.05], [0.1, 0.2, 0.05], [0.1, 0, -0.3]])
    assert s.contains(pts).tolist() == [True, False, False, False]


def test_split_is_by_scene_seeded_and_complete():
    fr = Fractions(train=0.8, val=0.1, test=0.1)
    a, b = split_scenes(50, fr, 0, "ch5"), split_scenes(50, fr, 0, "ch5")
    assert a == b
    assert sorted(a["train"] + a["val"] + a["test"]) == list(range(50))
    assert (len(a["train"]), len(a["val"]), len(a["test"])) == (40, 5, 5)
    assert split_scenes(50, fr, 1, "ch5") != a
    tiny = split_scenes(3, Fractions(0.8, 0.1, 0.1), 0, "x")
    assert all(len(v) == 1 for v in tiny.values())


def test_save_npz_is_byte_identical_and_atomic(tmp_path):
    arrays = {"a": np.arange(10, dtype=np.float32), "s": np.array(["x", "yz"])}
    save_npz(tmp_path / "1.npz", arrays)
    save_npz(tmp_path / "2.npz", arrays)
    assert (tmp_path / "1.npz").read_bytes() == (tmp_path / "2.npz").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["1.npz", "2.npz"]
    assert load_npz(tmp_path / "1.npz")["s"].tolist() == ["x", "yz"]


def test_depth_noise_keeps_invalid_pixels_and_is_seeded():
    depth = np.full((32, 32), 0.6, dtype=np.float32)
    depth[0] = 0.0
    cfg = DepthNoiseConfig(sigma_m=0.002, sigma_quadratic_per_m=0.0, dropout=0.0)
    a = add_depth_noise(depth, cfg, np.random.default_rng(0))
    b = add_depth_noise(depth, cfg, np.random.default_rng(0))
    assert np.array_equal(a, b) and a.dtype == np.float32
    assert np.all(a[0] == 0) and 0.001 < np.std(a[1:] - 0.6) < 0.003
