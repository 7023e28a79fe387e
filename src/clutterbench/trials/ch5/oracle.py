"""The floor and the ceiling of Table 5.2: every action the planner could take from an
observation (`action_set`), and the oracle that simulates them from the present state exactly
as they would be executed and takes the first that succeeds."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from clutterbench.observation import Observation
from clutterbench.perception.boxes import Detection
from clutterbench.planning.ch5.replenish import (
    Move,
    Plan,
    ReplenishParams,
    WorkingSpace,
    box_points,
    candidates,
    carried,
    in_working_space,
    move_goal,
    new_box_extent_m,
    owner_map,
    path_blockers,
    place_clusters,
    rearrange_goal,
)
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch5.execution import execute
from clutterbench.trials.config import Ch5TrialParams

if TYPE_CHECKING:
    from clutterbench.trials.ch5.jobs import Ch5Job


# -- the floor and the ceiling -------------------------------------------------------------
def action_set(
    obs: Observation,
    dets: list[Detection],
    size_m: np.ndarray,
    params: ReplenishParams,
    space: WorkingSpace,
    contact: bool = True,
) -> list[list[Plan]]:
    """Every action the planner could take from this observation, as step sequences: a
    placement at every candidate; a blocker carried aside as the planner would carry it
    (move_goal and carried under params' blocker_goal / upright_footprint) and held while
    placing; an obstacle of the blocker moved per eq. (5.9) first, then the same.

    `contact` False: only those that keep what they move off the other boxes (the thesis'
    assumption, kept by the thesis' planners): no placement at an occupied candidate, no
    carry whose way is blocked (planning.replenish.path_blockers; of a sequence, its first
    move, the next is judged on a scene not yet seen)."""
    points = box_points(obs, space)
    clusters = place_clusters(obs, dets, space, points)
    owner = owner_map(obs, clusters)
    cands = candidates(obs, clusters, size_m, params, space, points, owner)
    if params.upright_footprint:  # as the planner carries them (planning.replenish.carried)
        moved = [carried(c, points, params.min_points) for c in clusters]
    else:
        moved = clusters

    def clear(m: Move) -> bool:
        if contact:
            return True
        s = moved[m.cluster]
        return not path_blockers(points, owner, clusters, s, m.goal_m, params.min_points)

    simple = [[Plan("simple", c, None)] for c in cands if contact or c.free]
    held, first = [], []
    g = params.finger_m
    for c in cands:
        if not c.occupants or c.occupants[0] < 0 or c.occupants[0] == c.cluster:
            continue
        s = moved[c.occupants[0]]
        w_new, h_new = new_box_extent_m(size_m, c.side)
        goal = move_goal(
            s.rect_m, c.side, w_new, h_new, g, c.rect_m if params.goal_from_candidate else None
        )
        if not in_working_space(np.array([*goal, *s.rect_m[2:]]), space):
            continue
        move_s = Move.carrying(s, goal)
        if clear(move_s):
            held.append([Plan("bimanual", c, move_s)])
        for k in moved:
            if k.index in (s.index, c.cluster):
                continue
            goal_k = rearrange_goal(k.rect_m, s.rect_m, g, goal)
            if not in_working_space(np.array([*goal_k, *k.rect_m[2:]]), space):
                continue
            move_k = Move.carrying(k, goal_k)
            if clear(move_k):
                first.append([Plan("rearrange", None, move_k), Plan("bimanual", c, move_s)])
    return simple + held + first


def oracle_choice(
    spec: SceneSpec,
    state: SceneState,
    obs: Observation,
    views: list[list[Detection]],
    size_m: np.ndarray,
    rp: ReplenishParams,
    space: WorkingSpace,
    job: Ch5Job,
) -> tuple[list[Plan], int]:
    """The first action sequence (in action_set's order, for each set of detections in
    `views` in turn) that succeeds under the strict criterion when simulated from the present
    state exactly as it would be executed, else the first that is collapse-free (a ceiling
    under each criterion: a strict success is collapse-free); none: the first one (it
    fails), or no plan."""
    contact = job.cond.planner != "oracle_no_contact"
    options = [seq for dets in views for seq in action_set(obs, dets, size_m, rp, space, contact)]
    params: Ch5TrialParams = job.params
    physics: PhysicsConfig = job.physics
    tried = 0
    free: list[Plan] | None = None
    for seq in options[: params.oracle_budget]:
        tried += 1
        now, view = state, obs
        ok = {"strict_success": True, "success": True}
        for k, plan in enumerate(seq):
            world = world_at(spec, now, physics, render=k > 0)
            if k > 0:  # what execution will see before its next step
                view = observe(world, job.camera)
            out = execute(world, view, plan, size_m, params, now.removed, job.collapse_free)
            lost = out.placed_box is None and plan.candidate is not None
            ok = {key: ok[key] and out.record[key] and not lost for key in ok}
            if not ok["success"]:
                break
            now = SceneState.of(world)
        if ok["strict_success"]:
            return seq, tried
        if ok["success"] and free is None:
            free = seq
    if free is not None:
        return free, tried
    if options:
        return options[0], tried
    return [Plan("none", None, None)], tried
