"""How a ch. 5 plan is executed and judged (thesis 5.3.2): which boxes a detection holds (what
the robot grasps, decided from the instance image, never by the planner), carrying a cluster
aside and holding it, inserting the new box through the shelf's front, releasing, settling,
and the judgement from physics."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from clutterbench import criteria
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.observation import Observation
from clutterbench.planning.ch5.replenish import (
    DROP_M,
    Plan,
    rect_mask,
)
from clutterbench.sim.clusters import box_tilt
from clutterbench.sim.geometry import aabb_overlap_xy, box_aabb_half_extents
from clutterbench.sim.physics import BoxWorld
from clutterbench.trials.config import Ch5TrialParams

FRONT_CLEARANCE_M = 0.005
"""The new box starts its way in this far in front of the shelf's open front."""
MEMBER_FRACTION = 0.5
"""A box belongs to a detection (is grasped with it) when at least this fraction of its
visible pixels lie inside the detection's image box."""


# -- execution -----------------------------------------------------------------------------
def members(obs: Observation, det_box_px: np.ndarray) -> list[int]:
    """The boxes a detection holds: those with >= MEMBER_FRACTION of their visible pixels
    inside its image box (what a gripper closing on the detection would take)."""
    inside = rect_mask(det_box_px, obs.instance.shape)
    total = np.bincount(obs.instance.ravel(), minlength=256)
    within = np.bincount(obs.instance[inside].ravel(), minlength=256)
    ids = np.nonzero((total[1:] > 0) & (within[1:] >= MEMBER_FRACTION * total[1:]))[0]
    return [int(k) for k in ids]


def upright_angle_rad(world: BoxWorld, boxes: list[int]) -> float:
    """The turn about x (`BoxWorld.carry_group`'s, right-handed: a positive turn tips a top
    toward -y) that sets a leaning cluster upright: the mean lean of its standing boxes
    (`box_tilt`'s, positive with the top toward +y), a gripper closing on the cluster aligns
    it."""
    poses = world.poses()
    leans = [box_tilt(np.asarray(world.sizes_m[i]), poses[i, 3:]) for i in boxes]
    standing = [a for flat, a in leans if not flat]
    return float(np.deg2rad(np.mean(standing))) if standing else 0.0


def floor_lift_m(world: BoxWorld, boxes: list[int], move: np.ndarray, turn: float) -> float:
    """How far to raise a carried cluster so that, turned upright, no box dips into the floor."""
    if turn == 0.0:
        return 0.0
    lo, _ = world.aabbs()
    return float(max(0.0, 0.002 - (lo[boxes, 2].min() + move[2])) + 0.01)


def set_down(world: BoxWorld, boxes: list[int]) -> None:
    """Lower held boxes straight down until DROP_M above what lies under them (the floor or
    a box), as a gripper sets its load down before it opens: a blocker lifted clear of B^top
    comes to rest on the new box instead of being dropped onto it (thesis Fig. 5.9 c)."""
    lo, hi = world.aabbs()
    glo, ghi = lo[boxes].min(axis=0), hi[boxes].max(axis=0)
    tops = [
        hi[i, 2]
        for i in range(world.n)
        if i not in boxes
        and i not in world.removed
        and hi[i, 2] <= glo[2] + 0.002
        and aabb_overlap_xy(glo, ghi, lo[i], hi[i])
    ]
    drop = glo[2] - max(tops, default=0.0) - DROP_M
    if drop > 0.001:
        world.carry_group(boxes, np.array([0.0, 0.0, -drop]))


def insert_from_front(world: BoxWorld, size_m: np.ndarray, pose: np.ndarray) -> int:
    """Carry the new box in through the shelf's open front (x = 0) along +x, at its place's
    height and attitude, held (kinematic: what stands in its way is pushed, and judged), let
    it go at its place and settle (the blocker, if any, still held). A box made to appear at
    its place would push what it overlaps aside by depenetration, through no motion a robot
    could make. Returns the new box's index."""
    pose = np.asarray(pose, dtype=np.float64)
    half_x = float(box_aabb_half_extents(np.asarray(size_m, float), pose[3:])[0])
    start = pose.copy()
    start[0] = min(float(pose[0]), -half_x - FRONT_CLEARANCE_M)
    placed = world.add_box(size_m, start)
    world.hold([placed])
    world.carry_group([placed], np.array([float(pose[0] - start[0]), 0.0, 0.0]))
    world.release([placed])
    world.settle_action()
    return placed


@dataclasses.dataclass
class StepOutcome:
    record: dict[str, Any]
    placed_box: int | None


def execute(
    world: BoxWorld,
    obs: Observation,
    plan: Plan,
    size_m: np.ndarray,
    params: Ch5TrialParams,
    gone: frozenset[int],
    cf: CollapseFreeConfig,
) -> StepOutcome:
    """Execute a plan from the step's canonical start (`world`, fresh): carry the moved
    cluster (held for a placement, set down and let go for a rearrangement), insert the new
    box at the candidate, set every held box down, release it, settle, judge."""
    assert world.steps_taken == 0, "a step starts from a freshly built world"
    start = world.poses().copy()
    n_before = world.n
    moved: list[int] = []
    if plan.move is not None:
        moved = members(obs, plan.move.box_px)
        if moved:
            shift = plan.move.translation_m
            # a gripper closing on standing boxes aligns them: a leaning cluster (C^r / C^l,
            # thesis 5.2.3) and a lone leaning box (classed C^v) alike
            turn = upright_angle_rad(world, moved)
            shift = shift + np.array([0.0, 0.0, floor_lift_m(world, moved, shift, turn)])
            world.carry_group(moved, shift, turn)
            if plan.branch == "rearrange":
                set_down(world, moved)
                world.release(moved)
                world.settle_action()
    placed = None
    if plan.candidate is not None:
        placed = insert_from_front(world, size_m, plan.candidate.pose)
    if world.held():
        set_down(world, world.held())
    world.release(world.held())
    world.settle_action()
    return StepOutcome(
        judge_step(world, start, n_before, moved, placed, plan, params, gone, cf), placed
    )


def judge_step(
    world: BoxWorld,
    start_poses: np.ndarray,
    n_before: int,
    moved: list[int],
    placed: int | None,
    plan: Plan,
    params: Ch5TrialParams,
    gone: frozenset[int],
    cf: CollapseFreeConfig,
) -> dict[str, Any]:
    """A step's named outcome from physics under both criteria (criteria.py), after
    every held box was released and settled: every box but the moved ones is judged, the
    moved ones (carried, then let go) only on staying on the shelf; the new box must rest at
    its place."""
    poses = world.poses()
    now = poses[:, :3]
    on_shelf = world.shelf.contains(now)
    others = [k for k in range(n_before) if k not in moved and k not in gone]
    motion = criteria.box_motion(
        start_poses, poses[:n_before], on_shelf, others, [k for k in moved if k not in gone]
    )
    disp = np.linalg.norm(now[:n_before] - start_poses[:, :3], axis=1)
    at_place = None
    if placed is not None:
        goal = plan.candidate.pose[:3]  # type: ignore[union-attr]
        off = now[placed, 1:] - goal[1:]
        # across (y) within the tolerance; up (z): resting, so not above the drop height and
        # not sunk below its place by more than the tolerance
        at_place = bool(
            on_shelf[placed]
            and abs(off[0]) <= params.place_tol_m
            and abs(off[1]) <= params.place_tol_m
        )
    others_still = criteria.still(motion, params.moved_threshold_m, cf)
    free = criteria.collapse_free(motion, cf)
    placed_ok = at_place if placed is not None else True
    return {
        "branch": plan.branch,
        "moved_boxes": moved,
        "placed": placed is not None,
        "at_place": at_place,
        # a replenishment step always acts (nothing aborts): executed and judged
        "executed": True,
        "aborted_before_motion": False,
        "aborted_after_motion": False,
        "extracted": False,
        "others_still": others_still,
        "collapse_free": free,
        "judged": True,
        "counted": True,
        "strict_counted": True,
        "success": bool(free and placed_ok),
        "strict_success": bool(others_still and placed_ok),
        "n_disturbed": criteria.n_disturbed(motion, params.moved_threshold_m, cf),
        "n_collapsed": criteria.n_collapsed(motion, cf),
        "disturbance_m": float(np.sum(disp[others])) if others else 0.0,
        "box_motion": motion,
    }
