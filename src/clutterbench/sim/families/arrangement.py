"""Thesis ch. 5 arrangements (Fig. 5.3, 5.5): clusters stacked (C^h) or shelved (C^v);
`disorganized` then gives half of the boxes random poses (thesis 5.2.2). Rows may start
tilted and fall onto a neighbour (C^r / C^l once settled)."""

from __future__ import annotations

import numpy as np

from clutterbench.sim.families.base import Placement, SceneFamily, drop_on_top, random_xy
from clutterbench.sim.families.shelved import place_row
from clutterbench.sim.geometry import quat_from_axis_angle, random_quat
from clutterbench.sim.physics import BoxWorld


class Organized(SceneFamily):
    name = "organized"
    max_clusters = 2
    disorder = 0.0
    """Fraction of boxes given random poses after the organized arrangement."""

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        s = world.shelf
        n = len(sizes_m)
        random_idx = set(rng.choice(n, size=int(round(self.disorder * n)), replace=False).tolist())
        ordered = [i for i in range(n) if i not in random_idx]
        k = int(rng.integers(1, self.max_clusters + 1))
        slots = np.array_split(np.array(ordered, dtype=int), k)
        edges = np.linspace(s.width_m / 2, -s.width_m / 2, k + 1)
        groups: list[list[int]] = []
        for g, (y0, y1) in zip(slots, zip(edges[:-1], edges[1:])):
            if len(g) == 0:
                continue
            if rng.random() < 0.5:  # C^h: one stack in the middle of its slot
                members = []
                x = rng.uniform(0.35, 0.65) * s.depth_m
                for i in g:
                    yaw = quat_from_axis_angle([0, 0, 1], np.deg2rad(rng.uniform(-8, 8)))
                    xy = np.array([x, 0.5 * (y0 + y1)]) + rng.uniform(-0.1, 0.1, 2) * sizes_m[i, :2]
                    idx = drop_on_top(world, sizes_m[i], yaw, xy)
                    if idx is None:  # the stack reached the top board: start another one
                        idx = drop_on_top(
                            world, sizes_m[i], yaw, random_xy(world, rng, 8, (0.3, 0.7))
                        )
                    if idx is not None:
                        members.append(idx)
                groups.append(members)
            else:  # C^v: a row of standing boxes; disorganized rows lean one way
                lean = 0.0
                if self.disorder > 0 and rng.random() < 0.5:
                    lean = rng.uniform(15, 35) * rng.choice([-1, 1])
                placed, rest = place_row(world, sizes_m[g], rng, y0, y1, 0.01, lean)
                for j in rest:
                    idx = drop_on_top(
                        world,
                        sizes_m[g[j]],
                        np.array([1.0, 0, 0, 0]),
                        random_xy(world, rng, 8, (0.3, 0.7)),
                    )
                    if idx is not None:
                        placed.append(idx)
                groups.append(placed)
        for i in sorted(random_idx):
            drop_on_top(
                world,
                sizes_m[i],
                random_quat(rng),
                random_xy(world, rng, 4, (0.3, 1.0)),
                lift_m=rng.uniform(0, 0.03),
            )
        return Placement(groups)


class Disorganized(Organized):
    name = "disorganized"
    disorder = 0.5  # thesis 5.2.2: "half of these objects were then assigned random poses"
