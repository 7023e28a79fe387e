"""The episode protocol every chapter's trials share (thesis 6.3.2; ARCHITECTURE "one episode
protocol").

- **One canonical start per step.** A step is executed in a fresh world built from the state
  the previous step left (`BoxWorld.from_state`): simulating an action from a state (the
  oracles' search) and executing it give the same bits.
- **Release, then judge.** The pulled box leaves the scene (or, aborted, is let go where it
  is); the scene settles with the second arm still holding (the *held* judgement, kept as a
  second column); then every held box is released, the scene settles again, and the step is
  judged from physics: no box other than the manipulated ones (pulled, held) may have moved
  beyond the threshold or left the shelf, and the released box must still be on the shelf.
- **An episode ends at its first failed step** (a box other than the pulled one moved beyond
  the threshold or left the shelf), when the target is out, when the target is no longer on
  the shelf (fell: a failure), or when the planner gives up.
- **An abort before any motion is an abort, not a collapse:** nothing moved, so nothing is
  judged; an abort after motion that disturbed nothing is an abort too. Per-step success
  counts the judged steps: the executed pulls that took the box out or disturbed the pile.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.spec import SceneSpec

STEP_FIELDS = (
    "executed",
    "aborted_before_motion",
    "aborted_after_motion",
    "extracted",
    "others_still",
    "judged",
    "success",
    "others_still_held",
    "success_held",
)
"""The named outcome of every step record (judged from physics). `success` and
`success_held` are booleans on judged steps and None on an abort that disturbed nothing
(neither a success nor a failure: the episode goes on)."""

EPISODE_ENDS = ("target_out", "collapse", "target_fell", "gave_up", "max_steps")
"""Why an episode ended: the target left the shelf after a clean step; a step moved another
box beyond the threshold; the target left the shelf without being pulled; the planner had no
action left; the attempt cap."""


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


def execute_pull(
    world: BoxWorld,
    box: int,
    hold: int | None,
    increment_m: float,
    lift_m: float,
    go_on: Callable[[int], bool] | None = None,
) -> PullResult:
    """Pull `box` out toward the camera in increments of `increment_m` (raised by `lift_m`
    first) while `hold` is held, from a freshly built world; before each increment `go_on(k)`
    (k increments done) may stop it. Out -> the box leaves the scene; stopped -> it is let go
    where it is. The scene settles (held judgement), every held box is released, the scene
    settles again. The one code path of executed steps and of the oracles' simulations."""
    assert world.steps_taken == 0, "a step starts from a freshly built world (world_at)"
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
            world.release([box])
            world.settle_action()
    else:
        world.lift_out(box)
    held = world.displacements()
    if hold is not None:
        world.release([hold])
        world.settle_action()
    released = world.displacements() if hold is not None else held
    on_shelf = world.shelf.contains(world.positions())
    on_shelf[sorted(world.removed)] = False
    return PullResult(increments, aborted, box in world.removed, held, released, on_shelf)


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


def judge_pull(
    result: PullResult | None, box: int, hold: int | None, gone: frozenset[int], threshold_m: float
) -> dict[str, Any]:
    """A step's named outcome from physics. `result` None: aborted before any motion (nothing
    was simulated, nothing moved). A step fails when a box other than the manipulated ones
    (pulled, held) moved beyond the threshold or left the shelf, judged after the release
    (what the released box carried or leaned on has settled; the released box itself may
    settle lower, but must stay on the shelf) and, as a second column, while still held.
    An abort that disturbed nothing is neither: `judged` false, `success` and `success_held`
    None (the episode goes on)."""
    if result is None or result.increments == 0:
        return {
            "executed": False,
            "aborted_before_motion": True,
            "aborted_after_motion": False,
            "extracted": False,
            "others_still": True,
            "judged": False,
            "success": None,
            "others_still_held": True,
            "success_held": None,
            "n_disturbed": 0,
            "disturbance_m": 0.0,
        }
    manipulated = {box} | ({hold} if hold is not None else set())
    n, total = moved_others(result.displacement_m, result.on_shelf, manipulated, gone, threshold_m)
    if hold is not None and not result.on_shelf[hold]:
        n += 1  # the released box fell off the shelf
    n_held, _ = moved_others(
        result.displacement_held_m, np.ones_like(result.on_shelf), manipulated, gone, threshold_m
    )
    step = {
        "executed": True,
        "aborted_before_motion": False,
        "aborted_after_motion": result.aborted,
        "extracted": result.extracted,
        "others_still": n == 0,
    }
    counts = judged(step)
    return step | {
        "judged": counts,
        "success": result.extracted and n == 0 if counts else None,
        "others_still_held": n_held == 0,
        "success_held": result.extracted and n_held == 0 if counts else None,
        "n_disturbed": n,
        "disturbance_m": total,
    }


def judged(step: dict[str, Any]) -> bool:
    """Whether a step counts in per-step success: an executed pull that took its box out or
    disturbed the pile (an abort that moved nothing else is an abort, counted apart)."""
    return bool(step["executed"] and (step["extracted"] or not step["others_still"]))


def episode_end(step: dict[str, Any], target_out: bool, target_on_shelf: bool) -> str | None:
    """Why the episode ends after `step`, or None to go on (thesis 6.3.2: each failed episode
    has exactly one failed step)."""
    if step["executed"] and not step["others_still"]:
        return "collapse"
    if target_out:
        return "target_out"
    if not target_on_shelf:
        return "target_fell"
    return None


def judge_episode(steps: list[dict[str, Any]], end: str, target: int) -> dict[str, Any]:
    """The episode's named outcome: success when the target came out and no step disturbed
    the pile (the episode ended at "target_out"). `success_held`: the same judged while the
    second arm still held, where that is decidable (it differs only when the last step pulled
    the target and its release disturbed the pile)."""
    assert end in EPISODE_ENDS, end
    last = steps[-1] if steps else None
    released_only = (
        end == "collapse" and last is not None and last["box"] == target and last["success_held"]
    )
    return {
        "end": end,
        "target_out": any(s["extracted"] and s["box"] == target for s in steps),
        "others_still": all(s["others_still"] for s in steps),
        "success": end == "target_out",
        "success_held": end == "target_out" or released_only,
        "aborted_before_motion": sum(bool(s["aborted_before_motion"]) for s in steps),
        "aborted_after_motion": sum(bool(s["aborted_after_motion"]) for s in steps),
        "judged_steps": sum(judged(s) for s in steps),
    }
