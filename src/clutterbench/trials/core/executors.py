"""The executor of a trials step (ARCHITECTURE: one canonical start for every action): the
kinematic pull (sim/pull.py) by default, or (`executor: arm`) the Pandas of the ManiSkill tasks
(maniskill/executor.py), which pull what a planner chose in place of the kinematic executor,
judged by the same judge. Every chapter's trials import this module, not each other; the
Pandas are loaded only when a condition runs arm-level, so kinematic trials never load
ManiSkill.

A planner still sees only what the camera sees: when it monitors a pull (Algorithm 1), the
picture between increments is rendered from the box poses of the arm's scene in a BoxWorld
without the arms (the arms stand between the camera and the shelf and would hide it).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.maniskill.config import ArmConfig
from clutterbench.observation import Observation
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.pull import PullResult, SceneState, moved_others, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.core.harness import EpisodeLog
from clutterbench.trials.core.protocol import judge_pull

JOINTS_TOPIC = "/arm/joint_states"
"""Each arm's 7 joint positions (rad) at every control step, as JSON
({"name": [...], "position": [...]}, one message per arm and step, frame `arm<k>`)."""
ARM_TOPIC = "/arm/step"
"""What the arms did in a step (ArmStep.record): outcome, failed arm, boxes touched."""
JOINT_NAMES = [f"panda_joint{k}" for k in range(1, 8)]

_EXECUTORS: dict[tuple, Any] = {}


@dataclasses.dataclass(frozen=True)
class ArmPull:
    """One arm-level pull, beside the PullResult the judge reads."""

    result: PullResult
    fields: dict[str, Any]
    """The step record's arm fields (ArmStep.record)."""
    state: SceneState
    """Where the step left the boxes."""
    elapsed_s: float
    """Its simulated duration."""
    on_shelf_held: np.ndarray
    """(N,) each box's centre inside the shelf while the holding arm still held."""


def arm_executor(physics: PhysicsConfig, arm: ArmConfig, bimanual: bool):
    """This process's arm executor (one ManiSkill env each for one and for two arms, made on
    first use and kept: making one costs seconds, a step's scene rebuild a fraction)."""
    from clutterbench.maniskill.executor import ArmExecutor

    key = (physics, arm, bimanual)
    if key not in _EXECUTORS:
        _EXECUTORS[key] = ArmExecutor(physics, arm, bimanual)
    return _EXECUTORS[key]


def arm_pull(
    spec: SceneSpec,
    state: SceneState,
    box: int,
    hold: int | None,
    increment_m: float,
    lift_m: float,
    physics: PhysicsConfig,
    arm: ArmConfig,
    log: EpisodeLog,
    t0_s: float,
    go_on: Callable[[int, Observation | None], bool] | None = None,
    camera: CameraConfig | None = None,
    sensing: str = "ideal",
) -> ArmPull:
    """Pull `box` (holding `hold`) with the Pandas from a fresh scene at `state`; before each
    increment k > 0, `go_on(k, picture)` sees an arm-free picture of the boxes where they are
    now (rendered with `camera`); `go_on(0, None)` decides on the step's own observation.
    -> the ArmPull (its PullResult for the project's judge). Joint states and box poses go
    to `log` from `t0_s`."""
    executor = arm_executor(physics, arm, bimanual=hold is not None)

    def monitor(k: int, poses: np.ndarray) -> bool:
        if go_on is None:
            return True
        if k == 0:
            return go_on(0, None)
        removed = frozenset(executor.u.removed)
        world = world_at(spec, SceneState(poses, removed), physics, render=True)
        return go_on(k, observe(world, camera, sensing))

    result, step, end = executor.execute_pull(
        spec, state, box, hold, increment_m, lift_m, go_on=monitor
    )
    dt = executor.dt_s
    for t, joints in step.joint_log:
        for k, q in enumerate(joints):
            log.json(
                t0_s + t,
                JOINTS_TOPIC,
                {"frame_id": f"arm{k}", "name": JOINT_NAMES, "position": q},
            )
    for t, poses in step.pose_log:
        log.poses(t0_s + t, poses)
    fields = step.record(dt)
    log.json(t0_s + step.control_steps * dt, ARM_TOPIC, {"box": box, "hold": hold} | fields)
    return ArmPull(result, fields, end, step.control_steps * dt, step.on_shelf_held)


def judge_arm_step(
    result: PullResult,
    box: int,
    hold: int | None,
    gone: frozenset[int],
    threshold_m: float,
    cf: CollapseFreeConfig,
) -> dict[str, Any]:
    """judge_pull for an arm-level step. An arm that gave up before pulling (unreachable,
    no path, stopped short) has still moved through the shelf: when it moved a box beyond the
    threshold or off the shelf, the step is executed and judged (a failure, aborted after
    motion: the arm's own), not passed over as an abort that disturbed nothing."""
    manipulated = {box} | ({hold} if hold is not None else set())
    if result.increments == 0:
        n, _ = moved_others(result.displacement_m, result.on_shelf, manipulated, gone, threshold_m)
        if n:
            motion = dataclasses.replace(result, increments=1, aborted=True)
            return judge_pull(motion, box, hold, gone, threshold_m, cf)
    return judge_pull(result, box, hold, gone, threshold_m, cf)
