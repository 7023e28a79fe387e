"""The kinematic executor of every simulated step (ARCHITECTURE "one canonical start for every
action"): the state between two steps, a fresh world built at it, one pull executed in it, and
which other boxes the pull moved. The trials' protocol (trials/core/protocol.py) judges what this
executes; the arm-level executor (maniskill/executor.py) returns the same `PullResult` and is
judged by the same `moved_others`, so both executors share one judgement."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.spec import SceneSpec


@dataclasses.dataclass(frozen=True)
class SceneState:
    """Where every box is between two steps: (N, 7) poses and the boxes taken out."""

    poses: np.ndarray
    removed: frozenset[int]

    @classmethod
    def start(cls, spec: SceneSpec) -> SceneState:
        return cls(np.asarray(spec.poses, dtype=np.float64), frozenset())

    @classmethod
    def of(cls, world: BoxWorld) -> SceneState:
        return cls(world.poses(), frozenset(world.removed))


def world_at(
    spec: SceneSpec, state: SceneState, physics: PhysicsConfig, render: bool = False
) -> BoxWorld:
    """The canonical start of a step: a fresh world at `state`."""
    return BoxWorld.from_state(spec, state.poses, state.removed, physics, render=render)


@dataclasses.dataclass(frozen=True)
class PullResult:
    """What executing one pull did, before any judgement."""

    increments: int
    """Pull increments executed (0: the box never moved)."""
    aborted: bool
    """The pull was stopped before the box was out."""
    extracted: bool
    """The pulled box left the shelf (it is out of the scene)."""
    displacement_held_m: np.ndarray
    """(N,) displacement of every box from the step's start, settled, second arm holding."""
    displacement_m: np.ndarray
    """(N,) the same after every held box was released and the scene settled again."""
    on_shelf: np.ndarray
    """(N,) bool: each box's centre inside the shelf at the end (False for boxes out)."""
    poses_start: np.ndarray
    """(N, 7) every box's pose [x, y, z, qw, qx, qy, qz] at the step's start."""
    poses_end: np.ndarray
    """(N, 7) the same at the settled end, after every held box was released."""
    on_shelf_start: np.ndarray | None = None
    """(N,) bool: each box's centre inside the shelf at the step's start (None: all that
    were in the scene). A box already off the shelf then is no collapse of this step."""


def execute_pull(
    world: BoxWorld,
    box: int,
    hold: int | None,
    increment_m: float,
    lift_m: float,
    go_on: Callable[[int], bool] | None = None,
    *,
    return_aborted: bool = False,
    lower_held: bool = False,
) -> PullResult:
    """Pull `box` out toward the camera in increments of `increment_m` (raised by `lift_m`
    first) while `hold` is held, from a freshly built world; before each increment `go_on(k)`
    (k increments done) may stop it. Out -> the box leaves the scene; stopped -> it is let go
    where it is (`return_aborted`: first put back where the pull started). The scene settles
    (held judgement), every held box is released (`lower_held`: first set down onto what is
    below it), the scene settles again. The one code path of executed steps and of the
    oracles' simulations (trials.ch6.abort_release and held_release choose the two options)."""
    assert world.steps_taken == 0, "a step starts from a freshly built world (world_at)"
    poses_start = world.poses()
    if hold is not None:
        world.hold([hold])
    travel = world.pull_travel_m(box)
    pulled, increments, aborted = 0.0, 0, False
    while pulled < travel - 1e-9:
        if go_on is not None and not go_on(increments):
            aborted = True
            break
        step = min(increment_m, travel - pulled)
        world.pull_step(box, step, lift_m)
        pulled += step
        increments += 1
    if aborted:
        if increments:
            if return_aborted:
                world.return_pull(box, lift_m)
            world.release([box])
            world.settle_action()
    else:
        world.lift_out(box)
    held = world.displacements()
    if hold is not None:
        if lower_held:
            world.lower_onto_support(hold)
        world.release([hold])
        world.settle_action()
    released = world.displacements() if hold is not None else held
    on_shelf = world.shelf.contains(world.positions())
    on_shelf[sorted(world.removed)] = False
    return PullResult(
        increments,
        aborted,
        box in world.removed,
        held,
        released,
        on_shelf,
        poses_start,
        world.poses(),
        world.shelf.contains(poses_start[:, :3]),
    )


def moved_others(
    displacement_m: np.ndarray,
    on_shelf: np.ndarray,
    exclude: set[int],
    gone: frozenset[int],
    threshold_m: float,
) -> tuple[int, float]:
    """(boxes other than `exclude` that moved beyond the threshold or left the shelf, their
    summed displacement) among the boxes still in the scene at the step's start."""
    others = [k for k in range(len(displacement_m)) if k not in exclude and k not in gone]
    if not others:
        return 0, 0.0
    disp = np.nan_to_num(displacement_m[others], nan=np.inf)
    moved = (disp > threshold_m) | ~on_shelf[others]
    return int(moved.sum()), float(np.sum(np.where(np.isfinite(disp), disp, 0.0)))
