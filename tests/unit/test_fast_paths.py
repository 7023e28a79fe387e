"""The fast paths of the box planners' per-observation work give the same numbers, bit for bit,
as the plain computations they replaced: the box head's per-mask peaks, the fit's convex hull,
the repair's remembered pair depths and the overlap test that stops at the first shallow
axis. The trials' outputs are byte-identical only while these hold."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.collapse.box_head import _masked_peaks
from clutterbench.perception.box_fit import _hull
from clutterbench.sim.estimated import resolve_overlaps
from clutterbench.sim.geometry import obb_penetration_m, random_quat
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import MAX_PENETRATION_M, deepest_overlap


def _peaks_by_broadcast(p: np.ndarray, masks: np.ndarray) -> np.ndarray:
    big = np.where(masks[None, None], p[:, :, None, :], -1.0)
    return big.max(-1).clip(0.0)


def _hull_numpy_scalars(xy: np.ndarray) -> np.ndarray:
    p = np.unique(np.round(xy, 7), axis=0)
    if len(p) < 3:
        return p

    def half(points):
        out: list[np.ndarray] = []
        for q in points:
            while len(out) >= 2:
                o, a = out[-2], out[-1]
                if (a[0] - o[0]) * (q[1] - o[1]) - (a[1] - o[1]) * (q[0] - o[0]) > 0:
                    break
                out.pop()
            out.append(q)
        return out

    lower, upper = half(p), half(p[::-1])
    return np.array(lower[:-1] + upper[:-1])


@pytest.mark.parametrize("seed", range(5))
def test_masked_peaks_equal_the_broadcast_maxima(seed):
    rng = np.random.default_rng(seed)
    k, c, n = 7, 3, 400
    p = rng.random((k, c, n), dtype=np.float32) - np.float32(0.9)  # some masks all below 0
    masks = rng.random((k, n)) < rng.uniform(0.0, 0.3, (k, 1))
    masks[seed % k] = False  # an empty mask: 0, as before
    got = _masked_peaks(p, masks)
    assert got.dtype == np.float32
    assert np.array_equal(got, _peaks_by_broadcast(p, masks))


def _face_points(rng: np.random.Generator) -> np.ndarray:
    """A box face's pixels projected on a plane: a rotated grid, sometimes noisy, sometimes
    collinear runs along its edges."""
    n = int(rng.integers(1, 600))
    grid = rng.integers(0, 30, (n, 2)) * 0.003
    if rng.random() < 0.5:
        grid = grid + rng.normal(0.0, 2e-4, grid.shape)
    th = rng.uniform(0.0, np.pi)
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return grid @ rot + rng.normal(0.0, 0.4, 2)


def test_hull_equals_the_numpy_scalar_chain():
    rng = np.random.default_rng(3)
    for _ in range(300):
        xy = _face_points(rng)
        got, want = _hull(xy), _hull_numpy_scalars(xy)
        assert got.dtype == want.dtype and np.array_equal(got, want)


def _pile(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    sizes = rng.uniform(0.04, 0.12, (n, 3))
    poses = np.zeros((n, 7))
    poses[:, 0] = rng.uniform(0.08, 0.2, n)
    poses[:, 1] = rng.uniform(-0.1, 0.1, n)
    poses[:, 2] = rng.uniform(0.03, 0.15, n)
    poses[:, 3:] = [random_quat(rng) for _ in range(n)]
    return sizes, poses


def test_shallow_overlap_answers_as_the_full_depth_does():
    """Asked only whether a pair is deeper than the spec's limit, the test gives the full
    depth whenever it is deeper, and a depth no deeper than the limit whenever it is not."""
    rng = np.random.default_rng(4)
    deep = shallow = 0
    for _ in range(800):
        sizes, poses = _pile(rng, 2)
        args = (poses[0, :3], poses[0, 3:], sizes[0], poses[1, :3], poses[1, 3:], sizes[1])
        full = obb_penetration_m(*args)
        quick = obb_penetration_m(*args, shallow_m=MAX_PENETRATION_M)
        if full > MAX_PENETRATION_M:
            assert quick == full
            deep += 1
        else:
            assert quick <= MAX_PENETRATION_M
            shallow += full > 0
    assert deep > 30 and shallow > 0


def test_remembered_pair_depths_give_the_same_repair():
    """Pushing boxes apart with the pair depths remembered between pushes ends where
    measuring every pair at every push ends, push for push."""
    rng = np.random.default_rng(5)
    shelf = Shelf()
    for _ in range(6):
        sizes, poses = _pile(rng, 5)
        got = resolve_overlaps(sizes, poses, shelf)
        want = _resolve_without_memo(sizes, poses, shelf)
        assert np.array_equal(got[0], want[0]) and got[1:] == want[1:]


def _resolve_without_memo(sizes, poses, shelf):
    import clutterbench.sim.estimated as estimated

    class Forgetful(dict):
        def get(self, key, default=None):
            return default

    calls = []
    real = estimated.deepest_overlap

    def measuring_all(s, p, memo=None):
        calls.append(1)
        return real(s, p, Forgetful())

    estimated.deepest_overlap = measuring_all
    try:
        return resolve_overlaps(sizes, poses, shelf)
    finally:
        estimated.deepest_overlap = real
        assert calls


def test_memo_is_keyed_by_the_boxes_not_their_order():
    rng = np.random.default_rng(6)
    sizes, poses = _pile(rng, 6)
    memo: dict[bytes, float] = {}
    first = deepest_overlap(sizes, poses, memo)
    assert deepest_overlap(sizes, poses, memo) == first == deepest_overlap(sizes, poses)
    moved = poses.copy()
    moved[:, 0] += 0.05  # every box moved: nothing remembered applies
    assert deepest_overlap(sizes, moved, memo) == deepest_overlap(sizes, moved)
