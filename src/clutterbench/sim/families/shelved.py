"""`shelved` (thesis Fig. 6.4a, ch. 5 C^v): boxes standing like books, with random gaps."""

from __future__ import annotations

import numpy as np

from clutterbench.sim.families.base import (
    GAP_M,
    Placement,
    SceneFamily,
    drop_on_top,
    random_xy,
)
from clutterbench.sim.geometry import box_aabb_half_extents, quat_from_axis_angle, quat_mul
from clutterbench.sim.physics import BoxWorld

# Standing: the box's thickness (local z) along world y, its width (local y) vertical.
STANDING = quat_from_axis_angle([1, 0, 0], np.pi / 2)


def place_row(
    world: BoxWorld,
    sizes_m: np.ndarray,
    rng: np.random.Generator,
    y_start: float,
    y_end: float,
    max_gap_m: float,
    lean_deg: float = 0.0,
) -> tuple[list[int], list[int]]:
    """Stand boxes left (+y) to right between y_start > y_end; returns (placed, left over).

    With lean_deg != 0 each box starts tilted about x and falls onto its neighbour.
    """
    placed, rest = [], []
    y = y_start
    for i, size in enumerate(sizes_m):
        quat = quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(lean_deg)), STANDING)
        half = box_aabb_half_extents(size, quat)
        gap = rng.uniform(0.0, max_gap_m)
        centre_y = y - gap - half[1]
        if centre_y - half[1] < y_end:
            rest.append(i)
            continue
        x = rng.uniform(
            half[0] + 0.005, max(half[0] + 0.005, world.shelf.depth_m - half[0] - 0.005)
        )
        z = half[2] + GAP_M
        if z + half[2] > world.shelf.height_m:
            rest.append(i)
            continue
        placed.append(world.add_box(size, np.array([x, centre_y, z, *quat])))
        y = centre_y - half[1]
    return placed, rest


class Shelved(SceneFamily):
    name = "shelved"
    max_gap_m = 0.03
    """Largest random gap between neighbouring books."""
    lean_prob = 0.3
    """Probability that a box starts tilted and leans on its neighbour."""

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        s = world.shelf
        placed, rest = [], []
        y = s.width_m / 2 - rng.uniform(0.0, self.max_gap_m)
        for i, size in enumerate(sizes_m):
            lean = rng.uniform(8, 25) * rng.choice([-1, 1]) if rng.random() < self.lean_prob else 0
            row, left = place_row(world, size[None], rng, y, -s.width_m / 2, self.max_gap_m, lean)
            if row:
                placed += row
                y = world.aabbs()[0][row[0], 1]
            else:
                rest.append(i)
        # What did not fit in the row lies flat on top of it.
        for i in rest:
            idx = drop_on_top(
                world, sizes_m[i], np.array([1.0, 0, 0, 0]), random_xy(world, rng, 8, (0.3, 0.7))
            )
            if idx is not None:
                placed.append(idx)
        return Placement([placed])
