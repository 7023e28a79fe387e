"""Thesis ch. 5 arrangements (Fig. 5.3, 5.5): clusters stacked (C^h) or shelved (C^v);
`disorganized` then gives half of the boxes random poses (thesis 5.2.2). Rows may start
tilted and fall onto a neighbour (C^r / C^l once settled). `leaning` adds rows of books
that lean on a side wall and on each other (C^r / C^l), rare in the other two, for the
arrangement detector's data (thesis 5.2.1)."""

from __future__ import annotations

import numpy as np

from clutterbench.sim.families.base import (
    GAP_M,
    WALL_MARGIN_M,
    Placement,
    SceneFamily,
    drop_on_top,
    random_xy,
)
from clutterbench.sim.families.shelved import STANDING, place_row
from clutterbench.sim.geometry import (
    box_aabb_half_extents,
    quat_from_axis_angle,
    quat_mul,
    quat_to_matrix,
    random_quat,
)
from clutterbench.sim.physics import BoxWorld

_CORNER_SIGNS = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], float)


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
        for j, (g, (y0, y1)) in enumerate(zip(slots, zip(edges[:-1], edges[1:]))):
            if len(g) == 0:
                continue
            walls = (j == 0, j == k - 1)
            groups.append(self.arrange_slot(world, sizes_m, g, y0, y1, rng, walls))
        for i in sorted(random_idx):
            drop_on_top(
                world,
                sizes_m[i],
                random_quat(rng),
                random_xy(world, rng, 4, (0.3, 1.0)),
                lift_m=rng.uniform(0, 0.03),
            )
        return Placement(groups)

    def arrange_slot(
        self,
        world: BoxWorld,
        sizes_m: np.ndarray,
        g: np.ndarray,
        y0: float,
        y1: float,
        rng: np.random.Generator,
        walls: tuple[bool, bool],
    ) -> list[int]:
        """Boxes `g` as one cluster between y0 > y1 (walls: whether the slot's left / right
        edge is a side wall); returns the boxes placed."""
        if rng.random() < 0.5:  # C^h: one stack in the middle of its slot
            return self.stack(world, sizes_m, g, y0, y1, rng)
        # C^v: a row of standing boxes; disorganized rows lean one way
        lean = 0.0
        if self.disorder > 0 and rng.random() < 0.5:
            lean = rng.uniform(15, 35) * rng.choice([-1, 1])
        placed, rest = place_row(world, sizes_m[g], rng, y0, y1, 0.01, lean)
        return placed + self.drop_rest(world, sizes_m, g[rest], rng)

    @staticmethod
    def stack(
        world: BoxWorld,
        sizes_m: np.ndarray,
        g: np.ndarray,
        y0: float,
        y1: float,
        rng: np.random.Generator,
    ) -> list[int]:
        members = []
        x = rng.uniform(0.35, 0.65) * world.shelf.depth_m
        for i in g:
            yaw = quat_from_axis_angle([0, 0, 1], np.deg2rad(rng.uniform(-8, 8)))
            xy = np.array([x, 0.5 * (y0 + y1)]) + rng.uniform(-0.1, 0.1, 2) * sizes_m[i, :2]
            idx = drop_on_top(world, sizes_m[i], yaw, xy)
            if idx is None:  # the stack reached the top board: start another one
                idx = drop_on_top(world, sizes_m[i], yaw, random_xy(world, rng, 8, (0.3, 0.7)))
            if idx is not None:
                members.append(idx)
        return members

    @staticmethod
    def drop_rest(
        world: BoxWorld, sizes_m: np.ndarray, rest: np.ndarray, rng: np.random.Generator
    ) -> list[int]:
        """What did not fit in a row lies flat on top of the scene."""
        placed = []
        for i in rest:
            idx = drop_on_top(
                world, sizes_m[i], np.array([1.0, 0, 0, 0]), random_xy(world, rng, 8, (0.3, 0.7))
            )
            if idx is not None:
                placed.append(idx)
        return placed


class Disorganized(Organized):
    name = "disorganized"
    disorder = 0.5  # thesis 5.2.2: "half of these objects were then assigned random poses"


def place_leaning_row(
    world: BoxWorld,
    sizes_m: np.ndarray,
    rng: np.random.Generator,
    side: int,
    y_limit: float,
    lean_deg: float,
    max_gap_m: float = 0.003,
) -> tuple[list[int], list[int]]:
    """Stand boxes tilted `lean_deg` toward the side wall `side` (+1: the +y wall, the
    image's left; -1: the -y wall, the image's right): the first one's top against the
    wall, each next one face to face on the one before (parallel, bottom edge on the floor),
    the row growing away from the wall up to y = y_limit. Returns (placed, left over)."""
    s = world.shelf
    # Rotating +a about x takes a standing box's top toward -y (sim/clusters.py).
    quat = quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(-side * lean_deg)), STANDING)
    R = quat_to_matrix(quat)
    up = R[:, 1] * np.sign(R[2, 1])  # the standing box's width axis, pointing up
    away = R[:, 2] * -side * np.sign(R[1, 2])  # its thickness axis, pointing off the wall
    placed, rest = [], []
    prev: tuple[np.ndarray, float] | None = None
    for i, size in enumerate(sizes_m):
        corners = (0.5 * size * _CORNER_SIGNS) @ R.T  # corner offsets from the centre
        if prev is None:  # top corner at the wall, lowest corner just above the floor
            y = side * (s.width_m / 2 - WALL_MARGIN_M) - side * np.max(side * corners[:, 1])
            centre = np.array([0.0, y, GAP_M - corners[:, 2].min()])
        else:
            centre_prev, thick_prev = prev
            gap = rng.uniform(0.0, max_gap_m)
            centre = centre_prev + (0.5 * (thick_prev + size[2]) + gap) * away
            # slide down along the faces until the lowest corner is just above the floor
            centre += (GAP_M - centre[2] - corners[:, 2].min()) / up[2] * up
        far = centre[1] + (corners[:, 1].max() if side < 0 else corners[:, 1].min())
        if side * (far - y_limit) < 0 or centre[2] + corners[:, 2].max() > s.height_m - GAP_M:
            rest.append(i)
            continue
        half = box_aabb_half_extents(size, quat)
        centre[0] = rng.uniform(half[0] + 0.005, max(half[0] + 0.005, s.depth_m - half[0] - 0.005))
        placed.append(world.add_box(size, np.concatenate([centre, quat])))
        prev = (centre, float(size[2]))
    return placed, rest


class Leaning(Organized):
    """Two clusters side by side: on one side a row leaning on that side wall (C^l on the
    left, C^r on the right; sometimes a row standing upright, C^v), on the other a stack
    (C^h) or a standing row (C^v); what the leaning row has no room for goes on the stack.
    No random boxes: clusters whose extent and class can be seen (the arrangement
    detector's data, thesis 5.2.1)."""

    name = "leaning"
    lean_prob = 0.8
    """Probability that the row leans (else it stands upright)."""
    lean_range_deg = (20.0, 38.0)
    """Tilt of a leaning row from vertical (under ~15 deg most boxes tip back upright)."""
    row_share = (0.5, 0.62)
    """Range of the fraction of the shelf's width the row may take."""

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        s = world.shelf
        n = len(sizes_m)
        side = int(rng.choice([-1, 1]))  # the row's wall: +1 the +y (image left) wall
        wall = side * s.width_m / 2
        split = wall - side * rng.uniform(*self.row_share) * s.width_m
        row, other = np.arange(n)[: -(-n // 2)], np.arange(n)[-(-n // 2) :]
        if rng.random() < self.lean_prob:
            lean = rng.uniform(*self.lean_range_deg)
            placed, rest = place_leaning_row(world, sizes_m[row], rng, side, split, lean)
        else:
            y0, y1 = (wall, split) if side > 0 else (split, wall)
            placed, rest = place_row(world, sizes_m[row], rng, y0, y1, 0.005)
        spill = row[rest]
        y0, y1 = (split, -wall) if side > 0 else (-wall, split)
        if len(spill) or rng.random() < 0.5:
            rest_group = self.stack(world, sizes_m, np.concatenate([other, spill]), y0, y1, rng)
        else:
            kept, left_over = place_row(world, sizes_m[other], rng, y0, y1, 0.005)
            rest_group = kept + self.drop_rest(world, sizes_m, other[left_over], rng)
        return Placement([g for g in (placed, rest_group) if g])
