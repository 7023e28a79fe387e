"""A scene a world can hold from estimated boxes (sizes and poses fitted to one depth image,
perception/box_fit.py): the physics-from-depth planner's model of the shelf.

Fitted boxes may poke through the shelf's boards or into each other by the fit's errors; a
spec may hold neither (sim/spec.py). So: every centre is moved inside the shelf (the box's
bounding box above the floor, inside the side and back walls), then the deepest overlapping
pair is pushed apart along the axis that separates them fastest (the upper box lifted when
that axis is mostly vertical, else both moved half-way), until no pair overlaps more than the
spec allows; a box still overlapping after that is dropped (counted). The result passes
`validate_spec`; then the scene settles briefly, and whether it came to rest is recorded: an
estimated scene that does not stand still is itself information (a box balanced on a hidden
support, a wrong size).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.geometry import box_aabb_half_extents, quat_to_matrix
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import MAX_PENETRATION_M, SceneSpec, deepest_overlap, validate_spec

GAP_M = 0.0005
"""Boxes pushed apart end this far apart (under the spec's 1 mm overlap)."""
MAX_PUSHES = 60


@dataclasses.dataclass(frozen=True)
class EstimatedScene:
    spec: SceneSpec
    """The estimated boxes, settled (poses after the settling); `meta["ids"]` maps each box to
    the observation's box (instance id - 1)."""
    kept: tuple[int, ...]
    """Indices (into the estimate given) of the boxes kept; the others overlapped beyond
    repair."""
    at_rest: bool
    """The estimated scene came to rest within the settling time."""
    settle_move_m: float
    """The farthest a box moved while settling (m)."""
    pushes: int
    """Overlapping pairs pushed apart."""
    off_shelf: int
    """Boxes whose centre left the shelf while settling."""

    def info(self) -> dict[str, Any]:
        return {
            "at_rest": self.at_rest,
            "settle_move_mm": round(1000 * self.settle_move_m, 2),
            "pushes": self.pushes,
            "dropped": int(self.spec.meta.get("given", 0)) - len(self.kept),
            "off_shelf": self.off_shelf,
        }


def _sat_axis(pa: np.ndarray, sa: np.ndarray, pb: np.ndarray, sb: np.ndarray) -> np.ndarray:
    """Unit axis (from a to b) of least overlap among the 15 separating-axis candidates."""
    Ra, Rb = quat_to_matrix(pa[3:]), quat_to_matrix(pb[3:])
    ha, hb = 0.5 * sa, 0.5 * sb
    d = pb[:3] - pa[:3]
    axes = [Ra[:, i] for i in range(3)] + [Rb[:, i] for i in range(3)]
    axes += [np.cross(Ra[:, i], Rb[:, j]) for i in range(3) for j in range(3)]
    best, best_overlap = np.array([0.0, 0.0, 1.0]), np.inf
    for axis in axes:
        norm = np.linalg.norm(axis)
        if norm < 1e-9:
            continue
        axis = axis / norm
        overlap = (
            np.sum(ha * np.abs(Ra.T @ axis)) + np.sum(hb * np.abs(Rb.T @ axis)) - abs(d @ axis)
        )
        if overlap < best_overlap:
            best, best_overlap = (axis if d @ axis >= 0 else -axis), overlap
    return best


def inside_shelf(sizes_m: np.ndarray, poses: np.ndarray, shelf: Shelf) -> np.ndarray:
    """The poses with every box's bounding box moved above the floor and inside the side and
    back walls (a box may hang out of the opening)."""
    out = np.array(poses, dtype=np.float64, copy=True)
    for k in range(len(out)):
        half = box_aabb_half_extents(sizes_m[k], out[k, 3:])
        out[k, 2] = max(out[k, 2], half[2] + GAP_M)
        out[k, 0] = min(out[k, 0], shelf.depth_m - half[0] - GAP_M)
        limit = max(shelf.width_m / 2 - half[1] - GAP_M, 0.0)
        out[k, 1] = float(np.clip(out[k, 1], -limit, limit))
        out[k, 2] = min(out[k, 2], max(shelf.height_m - half[2] - GAP_M, half[2]))
    return out


def resolve_overlaps(
    sizes_m: np.ndarray, poses: np.ndarray, shelf: Shelf
) -> tuple[np.ndarray, list[int], int]:
    """(poses, kept box indices, pairs pushed): overlapping boxes pushed apart, boxes that
    still overlap after MAX_PUSHES dropped."""
    poses = inside_shelf(sizes_m, poses, shelf)
    kept = list(range(len(poses)))
    pushes = 0
    while True:
        worst = deepest_overlap(sizes_m[kept], poses[kept])
        if worst is None:
            return poses, kept, pushes
        a, b, depth = kept[worst[0]], kept[worst[1]], worst[2]
        if pushes >= MAX_PUSHES:
            kept.remove(b)  # the later box of the worst pair
            continue
        axis = _sat_axis(poses[a], sizes_m[a], poses[b], sizes_m[b])
        move = depth + GAP_M
        if abs(axis[2]) > 0.7:  # stacked: lift the upper box
            upper = b if axis[2] > 0 else a
            poses[upper, 2] += move
        else:
            poses[a, :3] -= axis * move / 2
            poses[b, :3] += axis * move / 2
        poses = inside_shelf(sizes_m, poses, shelf)
        pushes += 1


def estimated_scene(
    sizes_m: np.ndarray,
    poses: np.ndarray,
    ids: tuple[int, ...],
    shelf: Shelf,
    camera: CameraConfig,
    physics: PhysicsConfig,
    settle_s: float,
) -> EstimatedScene:
    """The estimated boxes as a valid, settled scene (module docstring)."""
    from clutterbench.sim.physics import BoxWorld

    sizes_m = np.asarray(sizes_m, dtype=np.float64).reshape(-1, 3)
    fixed, kept, pushes = resolve_overlaps(sizes_m, np.asarray(poses, float), shelf)
    assert deepest_overlap(sizes_m[kept], fixed[kept]) is None
    spec = validate_spec(
        SceneSpec(
            sizes_m=sizes_m[kept],
            poses=fixed[kept],
            shelf=shelf,
            camera=camera,
            meta={"ids": [int(ids[k]) for k in kept], "given": len(ids)},
        ),
        "estimated scene",
    )
    if spec.n == 0:
        return EstimatedScene(spec, tuple(kept), True, 0.0, pushes, 0)
    world = BoxWorld.from_spec(spec, physics)
    settled = world.settle(settle_s)
    moved = float(np.nanmax(world.displacements())) if spec.n else 0.0
    after = world.poses()
    off = int(np.sum(~shelf.contains(after[:, :3])))
    spec = dataclasses.replace(spec, poses=after)
    assert MAX_PENETRATION_M > GAP_M
    return EstimatedScene(spec, tuple(kept), settled.at_rest, moved, pushes, off)
