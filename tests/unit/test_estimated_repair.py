"""The estimate's repair is total: any fit of boxes to a depth image becomes a
scene that `validate_spec` accepts. A property test over adversarial fits (centres outside
every wall and above the top board, boxes inside each other, lifted boxes pushed out of the
top, sizes from every catalogue, fits that are no box) and the fit that stopped a whole
`make repro` (a centre in front of the opening)."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.sim import estimated
from clutterbench.sim.catalog import CATALOGUES, box_extents_m
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.estimated import estimated_scene, is_box, repair
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec, deepest_overlap, validate_spec

SHELF = Shelf()
SIZES = np.concatenate([box_extents_m(name) for name in CATALOGUES])
FITS = 2000
"""Fits of 1-4 boxes, under a push cap of CHEAP_PUSHES (the repair costs O(boxes^2) per push:
a lower cap reaches the drop path sooner and costs less; validity may not depend on it)..."""
CHEAP_PUSHES = 6
PILES = 16
"""... and fits of 5-12 boxes under the real cap."""


def _random_quat(rng: np.random.Generator, upright: bool) -> np.ndarray:
    if upright:  # yaw only, as most fits are
        a = rng.uniform(-np.pi, np.pi) / 2
        return np.array([np.cos(a), 0.0, 0.0, np.sin(a)])
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _adversarial_fit(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n boxes: catalogue sizes (sometimes scaled past the shelf), centres anywhere from
    well outside every wall to above the top board, piled into one spot or into each other."""
    sizes = SIZES[rng.integers(0, len(SIZES), n)] * rng.choice([1.0, 1.0, 1.0, 0.3, 2.5], (n, 1))
    lo = np.array([-0.15, -SHELF.width_m, -0.1])
    hi = np.array([SHELF.depth_m + 0.15, SHELF.width_m, SHELF.height_m + 0.2])
    centres = rng.uniform(lo, hi, (n, 3))
    mode = rng.integers(0, 4)
    if mode == 1:  # everything in one spot
        centres[:] = centres[0] + rng.normal(scale=0.01, size=(n, 3))
    elif mode == 2:  # a tower lifted out of the top
        centres[:, :2] = centres[0, :2]
        centres[:, 2] = SHELF.height_m - 0.02 + 0.03 * np.arange(n)
    elif mode == 3:  # in front of the opening, near the front edge (the fit that stopped a run)
        centres[:, 0] = rng.uniform(-0.06, 0.01, n)
    upright = rng.random() < 0.7
    quats = np.array([_random_quat(rng, upright) for _ in range(n)])
    return sizes, np.hstack([centres, quats])


def _valid(sizes: np.ndarray, poses: np.ndarray, kept: list[int]) -> SceneSpec:
    return validate_spec(
        SceneSpec(sizes_m=sizes[kept], poses=poses[kept], shelf=SHELF, camera=CameraConfig()),
        "repaired",
    )


def test_every_adversarial_fit_repairs_into_a_valid_scene(monkeypatch):
    rng = np.random.default_rng(53)
    dropped = outside = 0
    counts = [int(rng.integers(1, 5)) for _ in range(FITS)]
    for i, n in enumerate(counts + [int(rng.integers(5, 13)) for _ in range(PILES)]):
        cap = CHEAP_PUSHES if i < FITS else estimated.MAX_PUSHES
        monkeypatch.setattr(estimated, "MAX_PUSHES", cap)
        sizes, poses = _adversarial_fit(rng, n)
        fix = repair(sizes, poses, SHELF)
        spec = _valid(sizes, fix.poses, fix.kept)  # raises on any box a world cannot hold
        assert deepest_overlap(spec.sizes_m, spec.poses) is None
        assert fix.kept == sorted(set(fix.kept))
        assert 0 <= fix.outside <= len(sizes) - len(fix.kept)
        dropped += len(sizes) - len(fix.kept)
        outside += fix.outside
    # the generator does reach the cases it is for
    assert outside > 50 and dropped > outside


def test_fits_that_are_no_box_are_dropped_and_counted():
    sizes = np.array([[0.05, 0.05, 0.05]] * 5)
    poses = np.tile([0.1, 0.0, 0.03, 1.0, 0.0, 0.0, 0.0], (5, 1))
    poses[:, 1] = [-0.12, -0.06, 0.0, 0.06, 0.12]
    sizes[1, 2] = np.nan
    sizes[2, 0] = 0.0
    poses[3, 3:] = [0.0, 0.0, 0.0, 0.0]
    poses[4, 0] = np.inf
    assert [is_box(s, p) for s, p in zip(sizes, poses)] == [True] + [False] * 4
    fix = repair(sizes, poses, SHELF)
    assert fix.kept == [0] and fix.invalid == 4 and fix.outside == 0
    assert repair(sizes[1:], poses[1:], SHELF).kept == []


def test_a_box_bigger_than_the_shelf_is_dropped_as_outside():
    """Deeper than the shelf: the back wall pushes its centre out of the opening."""
    sizes = np.array([[0.60, 0.05, 0.05], [0.05, 0.05, 0.05]])
    poses = np.array([[0.14, 0.0, 0.03, 1, 0, 0, 0], [0.1, 0.1, 0.03, 1, 0, 0, 0]], float)
    fix = repair(sizes, poses, SHELF)
    assert fix.kept == [1] and fix.outside == 1


@pytest.fixture(scope="module")
def physics() -> PhysicsConfig:
    from clutterbench.sim.renderer import ensure_renderer

    ensure_renderer()
    return PhysicsConfig()


def test_the_fit_that_stopped_make_repro_gives_a_scene(physics):
    """The box that stopped a run: a centre 8 mm in front of the opening, 0.1 m to the side.
    Before the repair was total it raised 'centre ... is outside the shelf' and ended the
    support stage; now it is dropped, counted, and the other box stays."""
    sizes = np.array([[0.06, 0.10, 0.166], [0.06, 0.06, 0.06]])
    poses = np.array(
        [[-0.0084, 0.0994, 0.083, 1, 0, 0, 0], [0.15, -0.05, 0.03, 1, 0, 0, 0]], dtype=float
    )
    scene = estimated_scene(sizes, poses, (7, 2), SHELF, CameraConfig(), physics, 0.2)
    assert scene.spec.meta["ids"] == [2]
    assert scene.info()["dropped"] == 1 and scene.info()["outside"] == 1
