"""Chapter 5 trial scenes (thesis 5.3.2, Fig. 5.9, 5.10): an arrangement the new box belongs
to, its placement candidate taken by an obstacle, and, in part of the scenes, a box that rests
on the obstacle, so that moving the obstacle blindly drops it.

- `replenish_stacked` (Fig. 5.9 c, d): a stack (C^h) with a box lying across its top (the
  obstacle on B^top, overhanging one side); with probability `dependent_prob` a book stands
  beside the stack leaning on the obstacle's overhang. Lifting the obstacle drops the book.
- `replenish_shelved` (Fig. 5.9 a, b): a row of standing books (C^v) against one side wall,
  a book leaning on the row in its open side (the obstacle on B^left / B^right; a lone
  leaning box is C^r / C^l), or, in part of the scenes, standing there with a further book
  leaning on it from outside. No candidate is free at the start; moving the upright obstacle
  aside pushes that book over.
- `replenish_random` (Fig. 5.10): either layout, mirrored, with one more box dropped in a
  random pose (thesis 5.2.2's disorganized boxes).

Every role is its own group (sim/clusters.py seeds one cluster per group), so the obstacle and
the book resting on it are separate clusters, as the thesis' planner needs them. Sizes are
drawn by the generator; a family only assigns them to roles (the obstacle is the widest box,
a dependent book shorter than what it leans on)."""

from __future__ import annotations

import numpy as np

from clutterbench.sim.config import FAMILY_MAX_OBJECTS
from clutterbench.sim.families.arrangement import _CORNER_SIGNS
from clutterbench.sim.families.base import (
    GAP_M,
    WALL_MARGIN_M,
    Placement,
    SceneFamily,
    drop_on_top,
    random_xy,
)
from clutterbench.sim.families.shelved import STANDING
from clutterbench.sim.geometry import (
    box_aabb_half_extents,
    quat_from_axis_angle,
    quat_mul,
    quat_to_matrix,
    random_quat,
)
from clutterbench.sim.physics import BoxWorld

FLAT = np.array([1.0, 0.0, 0.0, 0.0])


def stand(world: BoxWorld, size: np.ndarray, y: float, x: float) -> int:
    """A book standing upright (thickness across, width up) with its centre at (x, y)."""
    half = box_aabb_half_extents(size, STANDING)
    return world.add_box(size, np.array([x, y, half[2] + GAP_M, *STANDING]))


def lean_against(
    world: BoxWorld, size: np.ndarray, face_y: float, side: int, lean_deg: float, x: float
) -> int:
    """A book on the floor tilted `lean_deg` toward `side` (+1: +y) with its top corner at
    y = face_y, the face it leans on (settling lets it come to rest on that face's edge)."""
    quat = quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(-side * lean_deg)), STANDING)
    corners = (0.5 * size * _CORNER_SIGNS) @ quat_to_matrix(quat).T
    y = face_y - side * np.max(side * corners[:, 1]) - side * 0.0005
    z = GAP_M - corners[:, 2].min()
    return world.add_box(size, np.array([x, y, z, *quat]))


def row_from_wall(
    world: BoxWorld, sizes: np.ndarray, side: int, x: float, rng: np.random.Generator
) -> tuple[list[int], float]:
    """Standing books from the wall `side` inward, 0-3 mm apart; (boxes, y of the row's
    open face)."""
    s = world.shelf
    face = side * (s.width_m / 2 - WALL_MARGIN_M)
    out = []
    for size in sizes:
        t = float(size[2])
        out.append(stand(world, size, face - side * t / 2, x))
        face -= side * (t + rng.uniform(0.0, 0.003))
    return out, face


class ReplenishStacked(SceneFamily):
    name = "replenish_stacked"
    max_objects = FAMILY_MAX_OBJECTS[name]
    """Left-over books stand in one row from the wall beside the stack: with 8 boxes the row
    meets the stack in most draws (measured: 6 of 6 scenes needed redraws, 2 at most)."""
    dependent_prob = 0.5
    overhang_m = (0.012, 0.025)
    """How far the obstacle sticks out over the stack's side toward the dependent book."""
    lean_deg = (12.0, 22.0)

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        n = len(sizes_m)
        side = int(rng.choice([-1, 1]))  # where the dependent book stands (+1: +y)
        dep = n >= 4 and rng.random() < self.dependent_prob
        order = np.argsort(-sizes_m[:, 1], kind="stable")  # widest first
        obstacle, rest = order[0], list(order[1:])
        book = rest.pop(int(np.argmax(sizes_m[rest, 1]))) if dep else None
        stack, extra = rest[:2], rest[2:]
        if not dep and extra:
            stack, extra = stack + extra[:1], extra[1:]
        x = rng.uniform(0.4, 0.6) * world.shelf.depth_m
        y_stack = -side * rng.uniform(0.0, 0.03)
        groups: list[list[int]] = [[]]
        for i in stack:
            yaw = quat_from_axis_angle([0, 0, 1], np.deg2rad(rng.uniform(-4, 4)))
            xy = np.array([x, y_stack]) + rng.uniform(-0.03, 0.03, 2) * sizes_m[i, :2]
            k = drop_on_top(world, sizes_m[i], yaw, xy)
            if k is not None:
                groups[0].append(k)
        lo, hi = world.aabbs()
        edge = hi[groups[0], 1].max() if side > 0 else lo[groups[0], 1].min()
        w_o = sizes_m[obstacle, 1]
        y_o = edge + side * (rng.uniform(*self.overhang_m) - w_o / 2)
        k = drop_on_top(world, sizes_m[obstacle], FLAT, np.array([x, y_o]))
        groups.append([k] if k is not None else [])
        if book is not None and k is not None:
            lo, hi = world.aabbs()
            face = hi[k, 1] if side > 0 else lo[k, 1]
            lean = rng.uniform(*self.lean_deg)
            groups.append([lean_against(world, sizes_m[book], face, -side, lean, x)])
        self.extras(world, sizes_m, extra, -side, groups, rng)
        return Placement([g for g in groups if g])

    @staticmethod
    def extras(world, sizes_m, extra, side, groups, rng) -> None:
        """Left-over books stand against the wall `side`, each on its own."""
        if len(extra):
            placed, _ = row_from_wall(world, sizes_m[extra], side, world.shelf.depth_m / 2, rng)
            groups.extend([k] for k in placed)


class ReplenishShelved(SceneFamily):
    """Thesis Fig. 5.9 (a, b): a row of standing books against one side wall and one obstacle
    in the row's open side, where the new box would stand, so that no placement candidate is
    free at the start. In most scenes (`lean_prob`) the obstacle leans on the row: a lone
    leaning box is C^r / C^l (sim/clusters.py) and offers no place, and its foot fills the
    row's open side. Otherwise it stands upright `obstacle_gap_m` from the row (narrower than
    any new box plus the fingers' 2g) and a shorter book leans on it from outside, filling its
    outer side (else that side would be a free place: the shelf is wider than the scene) and
    falling when the obstacle is moved blindly. What the row has no room for lies on it."""

    name = "replenish_shelved"
    lean_prob = 0.6
    """Probability that the obstacle leans on the row (else it stands with a book on it)."""
    lean_deg = (15.0, 28.0)
    """Tilt of a leaning box: beyond sim.clusters.LEAN_DEG, so it is classed C^r / C^l."""
    obstacle_gap_m = (0.004, 0.012)

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        n = len(sizes_m)
        side = int(rng.choice([-1, 1]))  # the row's wall
        idx = list(rng.permutation(n))
        obstacle = idx.pop()
        shorter = [i for i in idx if sizes_m[i, 1] < sizes_m[obstacle, 1]]
        upright = n >= 3 and bool(shorter) and rng.random() >= self.lean_prob
        book = shorter[0] if upright else None
        if book is not None:
            idx.remove(book)
        row, extra = idx[:3], idx[3:]
        x = rng.uniform(0.4, 0.6) * world.shelf.depth_m
        placed, face = row_from_wall(world, sizes_m[row], side, x, rng)
        groups: list[list[int]] = [list(placed)]
        for i in extra:  # what the row has no room for lies on it
            k = drop_on_top(world, sizes_m[i], FLAT, np.array([x, face + side * 0.06]))
            if k is not None:
                groups[0].append(k)
        if book is None:
            lean = rng.uniform(*self.lean_deg)
            groups.append([lean_against(world, sizes_m[obstacle], face, side, lean, x)])
            return Placement(groups)
        t = float(sizes_m[obstacle, 2])
        y_o = face - side * (rng.uniform(*self.obstacle_gap_m) + t / 2)
        groups.append([stand(world, sizes_m[obstacle], y_o, x)])
        lean = rng.uniform(*self.lean_deg)
        groups.append([lean_against(world, sizes_m[book], y_o - side * t / 2, side, lean, x)])
        return Placement(groups)


class ReplenishRandom(SceneFamily):
    """Either layout with one more box dropped in a random pose (it joins what it touches)."""

    name = "replenish_random"
    max_objects = FAMILY_MAX_OBJECTS[name]  # the stacked layout's row and one dropped box

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        layout = ReplenishStacked() if rng.random() < 0.5 else ReplenishShelved()
        placement = layout.place(world, sizes_m[:-1], rng)
        drop_on_top(
            world,
            sizes_m[-1],
            random_quat(rng),
            random_xy(world, rng, 4, (0.3, 0.7)),
            lift_m=rng.uniform(0, 0.03),
        )
        return placement
