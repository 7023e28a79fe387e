"""What every scene family shares: placing a box on top of what is already there."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from clutterbench.sim.geometry import aabb_overlap_xy, box_aabb_half_extents
from clutterbench.sim.physics import BoxWorld

GAP_M = 0.001  # clearance between a new box and what it is placed on: no initial overlap
WALL_MARGIN_M = 0.002


@dataclasses.dataclass
class Placement:
    """What a family reports besides the boxes: the groups it arranged together (a stack, a
    row). They seed the arrangement clusters, which are classified from the settled scene
    (sim/clusters.py), not from what the family intended."""

    groups: list[list[int]] = dataclasses.field(default_factory=list)


class SceneFamily:
    """A way of arranging boxes on the shelf. Subclasses implement `place`.

    The shelf is built by BoxWorld (build); a family only randomizes the boxes (ManiSkill's
    _load_scene / _initialize_episode split). `place` may step the physics (drops).
    """

    name: ClassVar[str]
    max_objects: ClassVar[int | None] = None
    """The most boxes the family can arrange (None: any): a scene drawn with more gets this
    many, so that a dataset mixing families can share one n_objects range."""

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        raise NotImplementedError


def support_height(world: BoxWorld, lo: np.ndarray, hi: np.ndarray) -> float:
    """Top z of the highest placed box whose AABB overlaps the footprint [lo, hi] in x-y."""
    if world.n == 0:
        return 0.0
    blo, bhi = world.aabbs()
    tops = [bhi[i, 2] for i in range(world.n) if aabb_overlap_xy(lo, hi, blo[i], bhi[i])]
    return max(tops, default=0.0)


def clamp_into_shelf(world: BoxWorld, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Move a centre in x-y so that a footprint of half extents `half` fits the interior."""
    s = world.shelf
    c = centre.copy()
    x_lo, x_hi = half[0] + WALL_MARGIN_M, s.depth_m - half[0] - WALL_MARGIN_M
    y_lim = s.width_m / 2 - half[1] - WALL_MARGIN_M
    c[0] = np.clip(c[0], x_lo, max(x_lo, x_hi))
    c[1] = np.clip(c[1], -max(y_lim, 0.0), max(y_lim, 0.0))
    return c


def drop_on_top(
    world: BoxWorld, size_m: np.ndarray, quat: np.ndarray, xy: np.ndarray, lift_m: float = 0.0
) -> int | None:
    """Add a box just above whatever lies under it, at the lowest of the candidate (x, y)
    positions `xy` ((2,) or (K, 2)); None if it fits under the shelf's top board nowhere."""
    half = box_aabb_half_extents(size_m, quat)
    best = None
    for cand in np.atleast_2d(xy):
        centre = clamp_into_shelf(world, np.array([cand[0], cand[1], 0.0]), half)
        centre[2] = support_height(world, centre - half, centre + half) + GAP_M + half[2]
        if best is None or centre[2] < best[2]:
            best = centre
    assert best is not None
    best[2] = min(best[2] + lift_m, world.shelf.height_m - GAP_M - half[2])
    if best[2] + half[2] > world.shelf.height_m - GAP_M + 1e-9:
        return None
    return world.add_box(size_m, np.concatenate([best, quat]))


def random_xy(
    world: BoxWorld, rng: np.random.Generator, k: int, x_frac: tuple[float, float]
) -> np.ndarray:
    """k random (x, y) points over the shelf width, x within a fraction range of its depth."""
    s = world.shelf
    return rng.uniform(
        [x_frac[0] * s.depth_m, -s.width_m / 2], [x_frac[1] * s.depth_m, s.width_m / 2], size=(k, 2)
    )
