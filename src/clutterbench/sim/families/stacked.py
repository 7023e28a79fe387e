"""`stacked` (thesis Fig. 6.4b, ch. 5 C^h): boxes lying flat, piled on each other."""

from __future__ import annotations

import numpy as np

from clutterbench.sim.families.base import Placement, SceneFamily, drop_on_top, random_xy
from clutterbench.sim.geometry import quat_from_axis_angle
from clutterbench.sim.physics import BoxWorld


class Stacked(SceneFamily):
    name = "stacked"
    max_stacks = 3
    """Boxes are spread over 1..max_stacks piles across the shelf width."""
    offset_frac = 0.2
    """Random offset of a box on its pile, as a fraction of its own footprint."""
    max_yaw_deg = 15.0

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        s = world.shelf
        k = int(rng.integers(1, self.max_stacks + 1))
        stack_y = (np.arange(k) + 0.5) / k * s.width_m - s.width_m / 2
        stack_x = rng.uniform(0.35, 0.65, size=k) * s.depth_m
        members: list[list[int]] = [[] for _ in range(k)]
        for size in sizes_m:
            quat = quat_from_axis_angle(
                [0, 0, 1], np.deg2rad(rng.uniform(-1, 1) * self.max_yaw_deg)
            )
            for j in [*rng.permutation(k), -1]:
                if j == -1:  # every pile reached the top board: lay it wherever is lowest
                    idx = drop_on_top(world, size, quat, random_xy(world, rng, 8, (0.3, 0.7)))
                    if idx is not None:
                        members[int(np.argmin([len(m) for m in members]))].append(idx)
                    break
                xy = (
                    np.array([stack_x[j], stack_y[j]])
                    + rng.uniform(-1, 1, 2) * self.offset_frac * size[:2]
                )
                idx = drop_on_top(world, size, quat, xy)
                if idx is not None:
                    members[j].append(idx)
                    break
        return Placement([m for m in members if m])


class Pile(Stacked):
    """Thesis ch. 4: a random pile (6 boxes) in the middle of the shelf."""

    name = "pile"
    max_stacks = 2
    offset_frac = 0.3
    max_yaw_deg = 30.0
