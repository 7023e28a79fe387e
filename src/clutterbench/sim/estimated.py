"""A scene a world can hold from estimated boxes (sizes and poses fitted to one depth image,
perception/box_fit.py): the physics-from-depth planner's model of the shelf.

Fitted boxes may poke through the shelf's boards or into each other by the fit's errors; a
spec may hold neither (sim/spec.py). So: every centre is moved inside the shelf (the box's
bounding box above the floor, inside the side and back walls), then the deepest overlapping
pair is pushed apart along the axis that separates them fastest (the upper box lifted when
that axis is mostly vertical, else both moved half-way), until no pair overlaps more than the
spec allows; a box still overlapping after that is dropped (counted). A box whose centre is
then still outside the shelf (in front of the opening: a fit too deep or pushed out; above the
top board: a fit taller than the shelf), and a fit that is not a box (a size or pose that is
not finite, a size that is not positive, a rotation that is no quaternion), is dropped too
(counted as `outside` and `invalid`). So the repair is total:
any fit gives a scene that passes `validate_spec` (tests/unit/test_estimated_repair.py feeds
it adversarial fits). Then the scene settles briefly, and whether it came to rest is recorded:
an estimated scene that does not stand still is itself information (a box balanced on a
hidden support, a wrong size).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.geometry import box_aabb_half_extents, quat_to_matrix
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import (
    MAX_PENETRATION_M,
    QUAT_NORM_TOL,
    SceneSpec,
    deepest_overlap,
    validate_spec,
)

GAP_M = 0.0005
"""Boxes pushed apart end this far apart (under the spec's 1 mm overlap)."""
MAX_PUSHES = 60


def is_box(size_m: np.ndarray, pose: np.ndarray) -> bool:
    """Whether a fit can be a box of a spec: finite, positive sizes, a near-unit quaternion."""
    size_m, pose = np.asarray(size_m, dtype=np.float64), np.asarray(pose, dtype=np.float64)
    if size_m.shape != (3,) or pose.shape != (7,):
        return False
    if not (np.all(np.isfinite(size_m)) and np.all(np.isfinite(pose)) and np.all(size_m > 0)):
        return False
    return abs(float(np.linalg.norm(pose[3:])) - 1.0) <= QUAT_NORM_TOL


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
    outside: int = 0
    """Boxes dropped because the repair found them no place inside the shelf."""
    invalid: int = 0
    """Boxes dropped because the fit was no box (not finite, no positive size, no rotation)."""

    def info(self) -> dict[str, Any]:
        return {
            "at_rest": self.at_rest,
            "settle_move_mm": round(1000 * self.settle_move_m, 2),
            "pushes": self.pushes,
            "dropped": int(self.spec.meta.get("given", 0)) - len(self.kept),
            "outside": self.outside,
            "invalid": self.invalid,
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
    still overlap after MAX_PUSHES dropped, then boxes whose centre is still outside the shelf
    dropped. Every box must be a box (`is_box`; `repair` drops those that are not)."""
    poses, kept, pushes, _ = _resolve(sizes_m, poses, shelf)
    return poses, kept, pushes


def _resolve(
    sizes_m: np.ndarray, poses: np.ndarray, shelf: Shelf, memo: dict[bytes, float] | None = None
) -> tuple[np.ndarray, list[int], int, int]:
    """resolve_overlaps, and how many boxes it dropped for having no place in the shelf.
    `memo`: deepest_overlap's pair depths (a push moves one or two boxes: the other pairs'
    depths are not measured again)."""
    poses = inside_shelf(sizes_m, poses, shelf)
    kept = list(range(len(poses)))
    pushes = 0
    memo = {} if memo is None else memo
    while True:
        worst = deepest_overlap(sizes_m[kept], poses[kept], memo)
        if worst is None:
            # dropping a box makes no new overlap, so the outside ones go last
            inside = shelf.contains(poses[kept, :3]) if kept else []  # validate_spec's test
            placed = [k for k, ok in zip(kept, inside) if ok]
            return poses, placed, pushes, len(kept) - len(placed)
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


@dataclasses.dataclass(frozen=True)
class Repair:
    """What `repair` made of a fit: the poses (every box's, repaired where kept), the boxes
    kept, and the counts of its changes."""

    poses: np.ndarray
    kept: list[int]
    pushes: int
    outside: int
    """Boxes that are boxes, overlap nothing kept, and still found no place in the shelf."""
    invalid: int


def repair(
    sizes_m: np.ndarray, poses: np.ndarray, shelf: Shelf, memo: dict[bytes, float] | None = None
) -> Repair:
    """Any fit (N boxes of any sizes and poses) -> poses and kept boxes a spec may hold: the
    boxes that are no box (`is_box`) dropped, then `_resolve` (validate_spec normalizes the
    near-unit quaternions)."""
    sizes_m = np.asarray(sizes_m, dtype=np.float64).reshape(-1, 3)
    poses = np.array(poses, dtype=np.float64).reshape(-1, 7)
    boxes = [k for k in range(len(poses)) if is_box(sizes_m[k], poses[k])]
    if not boxes:
        return Repair(poses, [], 0, 0, len(poses))
    fixed, kept, pushes, outside = _resolve(sizes_m[boxes], poses[boxes], shelf, memo)
    poses[boxes] = fixed
    return Repair(poses, [boxes[k] for k in kept], pushes, outside, len(poses) - len(boxes))


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
    memo: dict[bytes, float] = {}  # the repair's pair depths, which the spec's check reads
    fix = repair(sizes_m, poses, shelf, memo)
    fixed, kept, pushes = fix.poses, fix.kept, fix.pushes
    spec = validate_spec(
        SceneSpec(
            sizes_m=sizes_m[kept],
            poses=fixed[kept],
            shelf=shelf,
            camera=camera,
            meta={"ids": [int(ids[k]) for k in kept], "given": len(ids)},
        ),
        "estimated scene",
        memo,
    )
    if spec.n == 0:
        return EstimatedScene(spec, tuple(kept), True, 0.0, pushes, 0, fix.outside, fix.invalid)
    world = BoxWorld.from_spec(spec, physics)
    settled = world.settle(settle_s)
    moved = float(np.nanmax(world.displacements())) if spec.n else 0.0
    after = world.poses()
    off = int(np.sum(~shelf.contains(after[:, :3])))
    spec = dataclasses.replace(spec, poses=after)
    assert MAX_PENETRATION_M > GAP_M
    return EstimatedScene(
        spec, tuple(kept), settled.at_rest, moved, pushes, off, fix.outside, fix.invalid
    )
