"""The arm-level executor: Pandas in a ManiSkill scene execute a planner's pull, the second
executor of the trials beside BoxWorld's kinematic one (trials/protocol.execute_pull).

One step, from a fresh scene at the step's state (the canonical start, as the kinematic
executor): the holding arm (if any) approaches its box's front face and takes hold, then the
pulling arm does; the pull raises the box by the grasp lift and draws it out toward the
camera in the planner's increments along straight tool paths (mplib screw motions), the
planner's `go_on` checked before each; out of the shelf, the box leaves the scene (as the
kinematic executor's lift-out); the pulling arm goes back to its ready pose; the scene
settles with the holding arm still holding (the *held* judgement); the holding arm lets go
and goes back; the scene settles again. The same PullResult comes out as from the
kinematic executor, so the same judge (trials/protocol.judge_pull) decides the step.

The grasp is suction-like: when the tool's tip has come within `arm.attach_tolerance_m` of
the face, the box is held rigidly in the tool's frame (kinematic, following the tool every
physics step) until released. What the kinematic executor assumes away is measured here and
named in `ArmStep.outcome`: a face out of the arm's reach (`unreachable`), a path that would
leave the joint limits or hit the shelf (`planning_failed`), a tool stopped by other boxes
before the face (`no_contact`); and `arm_contacts`, the boxes an arm touched other than the
ones it holds.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from typing import Any

import numpy as np

from clutterbench.maniskill.config import ArmConfig
from clutterbench.maniskill.motion import (
    NEAR_LINKS,
    SIDE_BY_SIDE_ROLLS_DEG,
    SIDE_BY_SIDE_YAWS_DEG,
    TOOL_ROLLS_DEG,
    face_pose,
    link_points,
    make_planner,
    plan_joint_line,
    plan_line,
    shelf_points,
)
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.geometry import box_aabb_half_extents, quat_to_matrix
from clutterbench.sim.physics import CONTACT_SEPARATION_M, PULL_CLEARANCE_M
from clutterbench.sim.pull import PullResult, SceneState
from clutterbench.sim.spec import SceneSpec

ARM_OUTCOMES = ("ok", "unreachable", "planning_failed", "no_contact")
"""How an arm's part of a step ended: done; no joint state puts the tool at the box's face;
no straight path there inside the joint limits and clear of the shelf; the tool stopped
short of the face (other boxes in the way)."""
POSE_LOG_EVERY = 4
"""Box poses are logged every this many control steps (and after every motion)."""
FACE_MARGIN_M = 0.02
"""With two arms at work, each takes its box this far in from the face's edge on its side."""
PULL_ARM, HOLD_ARM = 0, 1
"""The arms' indices when the pulled box is right of the held one (or, nothing held, right of
the shelf's middle); otherwise they swap, so that no arm reaches across the other."""


@dataclasses.dataclass
class ArmStep:
    """What the arms did in one step (beside the PullResult that is judged)."""

    outcome: str = "ok"
    """One of ARM_OUTCOMES (the first arm that failed)."""
    failed_arm: str | None = None
    """"pull" or "hold": which arm's approach failed (None when none did)."""
    arm_contacts: list[int] = dataclasses.field(default_factory=list)
    """Boxes an arm touched other than the ones it pulls or holds (sorted)."""
    pull_arm: int = 0
    """Which Panda pulled (0: the one on the camera's right; with two, the one on the pulled
    box's side)."""
    retract_failed: list[int] = dataclasses.field(default_factory=list)
    """Arms that found no path back to their ready pose (they stay where they let go)."""
    control_steps: int = 0
    """Control steps simulated (each 1 / arm.control_freq_hz seconds)."""
    joint_log: list[tuple[float, list[list[float]]]] = dataclasses.field(default_factory=list)
    """(time s from the step's start, each arm's 7 joint positions), at every control step."""
    pose_log: list[tuple[float, np.ndarray]] = dataclasses.field(default_factory=list)
    """(time s, (N, 7) box poses), every POSE_LOG_EVERY control steps and after each motion."""
    on_shelf_held: np.ndarray | None = None
    """(N,) each box's centre inside the shelf, settled with the holding arm still holding."""

    def record(self, dt_s: float) -> dict[str, Any]:
        """The step record's arm fields."""
        return {
            "arm_outcome": self.outcome,
            "arm_failed": self.failed_arm,
            "arm_contacts": self.arm_contacts,
            "arm_retract_failed": self.retract_failed,
            "arm_s": round(self.control_steps * dt_s, 3),
        }


def _matrix(pose7) -> np.ndarray:
    """A 4x4 transform from [x, y, z, qw, qx, qy, qz]."""
    pose7 = np.asarray(pose7, dtype=np.float64)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = quat_to_matrix(pose7[3:]), pose7[:3]
    return m


class ArmExecutor:
    """Executes pulls with one Panda, or two when `bimanual` (a holding arm): one ManiSkill
    env per executor (made on the first step), rebuilt at every step's state."""

    def __init__(self, physics: PhysicsConfig, arm: ArmConfig, bimanual: bool):
        self.physics, self.cfg, self.bimanual = physics, arm, bimanual
        self.env = None
        self.planners: list = []
        self._shelf = None
        self._arm_points: list[dict[str, np.ndarray]] = []

    # -- set-up -----------------------------------------------------------------------------
    def _start(self, spec: SceneSpec, state: SceneState, box: int, hold: int | None) -> None:
        options = {
            "spec": spec,
            "poses": state.poses,
            "removed": tuple(sorted(state.removed)),
            "target": box,
            "hold": hold,
        }
        if self.env is None:
            import gymnasium as gym

            import clutterbench.maniskill.tasks  # noqa: F401  (registers the tasks)

            name = "ClutterShelfBimanual-v1" if self.bimanual else "ClutterShelfExtract-v1"
            self.env = gym.make(
                name,
                spec=spec,
                target=box,
                hold=hold,
                poses=state.poses,
                removed=options["removed"],
                physics=self.physics,
                arm=self.cfg,
                obs_mode="none",
                reward_mode="none",
            )
            self.u = self.env.unwrapped
            self.planners = [
                make_planner(agent, base, self.cfg.joint_speed_scale)
                for agent, base in zip(self.u.agents, self.u.arm_bases(), strict=True)
            ]
            self.uids = list(self.u.agent.agents_dict) if self.bimanual else None
            # points on each arm's near links, in the link frames (what the other arm's
            # planner sees of it; the links keep their shapes when the scene is rebuilt)
            self._arm_points = [
                {
                    link.get_name(): link_points(link._objs[0])
                    for link in agent.robot.get_links()
                    if link.get_name() in NEAR_LINKS
                }
                for agent in self.u.agents
            ]
        self.env.reset(options={"reconfigure": True} | options)
        if self._shelf != spec.shelf:
            self._shelf_cloud = shelf_points(spec.shelf)
            for planner in self.planners:
                planner.update_point_cloud(self._shelf_cloud, radius=self.cfg.collision_clearance_m)
            self._shelf = spec.shelf
        self.targets = [np.asarray(q, dtype=np.float64) for q in self.u.ready_qpos()]
        self.dt_s = 1.0 / self.cfg.control_freq_hz
        scene = self.u.scene.sub_scenes[0]
        self._scene = scene
        self._box_of = {b.entity.per_scene_id: k for k, b in enumerate(self.u.bodies)}
        self._arm_of = {
            link._objs[0].entity.per_scene_id: i
            for i, agent in enumerate(self.u.agents)
            for link in agent.robot.get_links()
        }

    # -- control ----------------------------------------------------------------------------
    def _qpos(self, arm: int) -> np.ndarray:
        return self.u.agents[arm].robot.get_qpos()[0].numpy().astype(np.float64)

    def _step(self, step: ArmStep) -> None:
        actions = [q.astype(np.float32) for q in self.targets]
        self.env.step(
            actions[0] if not self.bimanual else dict(zip(self.uids, actions, strict=True))
        )
        step.control_steps += 1
        if step.control_steps % POSE_LOG_EVERY == 0:  # the boxes beside the joints, 5 Hz
            step.pose_log.append((step.control_steps * self.dt_s, self.u.box_poses()))
        step.joint_log.append(
            (
                step.control_steps * self.dt_s,
                [self._qpos(i).round(5).tolist() for i in range(len(self.targets))],
            )
        )
        held = {self.u.target} | ({self.u.hold} if self.u.hold is not None else set())
        touched = set(step.arm_contacts)
        for c in self._scene.get_contacts():
            a, b = (body.entity.per_scene_id for body in c.bodies)
            arm_box = (a in self._arm_of and b in self._box_of and self._box_of[b] not in held) or (
                b in self._arm_of and a in self._box_of and self._box_of[a] not in held
            )
            if arm_box and min(p.separation for p in c.points) < CONTACT_SEPARATION_M:
                touched.add(self._box_of[b] if b in self._box_of else self._box_of[a])
        step.arm_contacts = sorted(touched)

    def _follow(self, arm: int, path: np.ndarray, step: ArmStep) -> None:
        for q in path:
            self.targets[arm] = np.asarray(q[:7], dtype=np.float64)
            self._step(step)
        for _ in range(3):  # let the PD controller close the last gap
            self._step(step)

    def _see_other_arm(self, arm: int, other_q: np.ndarray | None = None) -> None:
        """Arm `arm`'s planner sees the shelf and, with two arms, the other arm (points on its
        links' surfaces) where it is now, or at the joint state `other_q` it is planned to
        take: no path is planned through the other arm."""
        if not self.bimanual:
            return
        clouds = [self._shelf_cloud]
        other = 1 - arm
        links = self._arm_points[other]
        if other_q is None:
            for link in self.u.agents[other].robot.get_links():  # rebuilt with each scene
                if link.get_name() in links:
                    m = link._objs[0].entity_pose.to_transformation_matrix()
                    clouds.append(links[link.get_name()] @ m[:3, :3].T + m[:3, 3])
        else:
            planner = self.planners[other]
            model = planner.pinocchio_model
            model.compute_forward_kinematics(np.asarray(other_q, dtype=np.float64))
            base = _matrix(self.u.arm_bases()[other])
            for name, pts in links.items():
                m = base @ _matrix(model.get_link_pose(planner.link_name_2_idx[name]))
                clouds.append(pts @ m[:3, :3].T + m[:3, 3])
        self.planners[arm].update_point_cloud(
            np.concatenate(clouds), radius=self.cfg.collision_clearance_m
        )

    def _line(self, arm: int, pose: np.ndarray, step: ArmStep, check_shelf: bool) -> str:
        if check_shelf:
            self._see_other_arm(arm)
        status, path = plan_line(self.planners[arm], pose, self._qpos(arm), self.dt_s, check_shelf)
        if status == "ok":
            self._follow(arm, path, step)
        return status

    def _home(self, arm: int, step: ArmStep) -> None:
        """Back to the ready pose: straight out of the shelf (to the entry plane), then
        straight to the ready pose; a joint-space line if a straight path fails."""
        tip = np.asarray(self.u.tcp_pose(arm).p, dtype=np.float64)
        out = np.hstack(
            [[min(tip[0], -self.cfg.entry_clearance_m), tip[1], tip[2]], self.u.tcp_pose(arm).q]
        )
        ok = self._line(arm, out, step, check_shelf=False) == "ok"
        if not ok or self._line(arm, self.u.ready_poses()[arm], step, check_shelf=True) != "ok":
            ready = self.u.ready_qpos()[arm]
            status, path = plan_joint_line(
                self.planners[arm], ready, self._qpos(arm), self.dt_s, False
            )
            if status == "ok":
                self._follow(arm, path, step)
            else:  # the arm stays where it is (it holds nothing now); named, not hidden
                step.retract_failed.append(arm)

    def _settle(self, step: ArmStep) -> None:
        still, limit = 0, int(np.ceil(self.physics.action_settle_max_s / self.dt_s))
        prev = self.u.box_poses()[:, :3]
        for _ in range(limit):
            self._step(step)
            now = self.u.box_poses()[:, :3]
            speed = np.nan_to_num(np.linalg.norm(now - prev, axis=1), nan=0.0) / self.dt_s
            still = still + 1 if speed.max(initial=0.0) < self.physics.rest_linear_m_s else 0
            prev = now
            if still >= self.cfg.settle_control_steps:
                break

    def _face_point(self, arm: int, box: int, aside: bool) -> np.ndarray:
        """Where arm `arm` takes `box`: its front face's centre, or with `aside` (another arm
        works beside it) that face's edge on the arm's own side, FACE_MARGIN_M in, so the two
        tools and wrists stay apart (the grasp holds a box wherever on its face)."""
        face = self.u.front_face_m(box)
        if aside:
            pose = self.u.box_poses()[box]
            half = box_aabb_half_extents(self.u.scene_spec.sizes_m[box], pose[3:])[1]
            side = -1.0 if arm == 0 else 1.0  # arm 0 stands right of the shelf (y < 0)
            face[1] += side * max(half - FACE_MARGIN_M, 0.0)
        return face

    def _plan_reach(
        self, arm: int, box: int, aside: bool, other_q: np.ndarray | None = None
    ) -> tuple[str, list[tuple[float, list[np.ndarray]]]]:
        """Plan arm `arm`'s approach to `box`'s front face, the other arm where it is now or
        at `other_q`: the tool turns about its rod as TOOL_ROLLS_DEG lists (with `aside`,
        another arm working beside it: the face's edge on the arm's side, _face_point, and
        SIDE_BY_SIDE_ROLLS_DEG), each turn whose two straight paths (to the entry point, then
        to the face) plan is kept -> ("ok", [(roll, [to_entry, to_face]), ...]), or the first
        turn's failure and []."""
        face = self._face_point(arm, box, aside)
        self._see_other_arm(arm, other_q)
        planner, first, plans = self.planners[arm], None, []
        side = -1.0 if arm == 0 else 1.0  # outward: arm 0 stands right (y < 0)
        yaws = SIDE_BY_SIDE_YAWS_DEG if aside else (0.0,)
        for yaw, roll in itertools.product(
            yaws, SIDE_BY_SIDE_ROLLS_DEG if aside else TOOL_ROLLS_DEG
        ):
            yaw_deg = -side * yaw  # the tip toward the middle, the hand outward
            # the entry point: on the rod's line, entry_clearance_m in front of the opening
            back = (face[0] - min(face[0], 0.0) + self.cfg.entry_clearance_m) / np.cos(
                np.deg2rad(yaw)
            )
            status, to_entry = plan_line(
                planner,
                face_pose(face, back, arm, roll, yaw_deg),
                self._qpos(arm),
                self.dt_s,
                True,
            )
            if status == "ok":
                status, to_face = plan_line(
                    planner,
                    face_pose(face, self.cfg.contact_gap_m, arm, roll, yaw_deg),
                    to_entry[-1],
                    self.dt_s,
                    True,
                )
            if status == "ok":
                plans.append((roll, [to_entry, to_face]))
                if other_q is not None or not aside:
                    break  # one is enough: nothing else depends on which
            first = first or status
        return ("ok", plans) if plans else (first, [])

    def _take(self, arm: int, box: int, paths: list[np.ndarray], aside: bool, step: ArmStep) -> str:
        """Follow the approach `paths` and take hold of `box` -> "ok" or "no_contact"."""
        for path in paths:
            self._follow(arm, path, step)
        tip = np.asarray(self.u.tcp_pose(arm).p, dtype=np.float64)
        face = self._face_point(arm, box, aside)  # the box may have been pushed on the way
        if (
            np.linalg.norm(tip - (face - [self.cfg.contact_gap_m, 0.0, 0.0]))
            > self.cfg.attach_tolerance_m
        ):
            return "no_contact"
        self.u.attach(arm, box)
        return "ok"

    def _reach_both(
        self, hold_arm: int, hold: int, pull_arm: int, box: int, step: ArmStep
    ) -> tuple[str, str | None]:
        """Two arms side by side: each of the holding arm's planned approaches is tried with
        the pulling arm planned around where it would stand, the first pair that plans is
        executed (holding arm first) -> (ARM_OUTCOMES name, the arm that failed or None)."""
        status, holds = self._plan_reach(hold_arm, hold, aside=True)
        if status != "ok":
            return status, "hold"
        first = None
        for _, hold_paths in holds:
            status, pulls = self._plan_reach(pull_arm, box, True, other_q=hold_paths[-1][-1])
            if status == "ok":
                break
            first = first or status
        else:
            return first, "pull"
        outcome = self._take(hold_arm, hold, hold_paths, True, step)
        if outcome != "ok":
            return outcome, "hold"
        outcome = self._take(pull_arm, box, pulls[0][1], True, step)
        return outcome, None if outcome == "ok" else "pull"

    def _travel_m(self, box: int) -> float:
        pose = self.u.box_poses()[box]
        return float(
            pose[0]
            + box_aabb_half_extents(self.u.scene_spec.sizes_m[box], pose[3:])[0]
            + PULL_CLEARANCE_M
        )

    # -- one step ----------------------------------------------------------------------------
    def execute_pull(
        self,
        spec: SceneSpec,
        state: SceneState,
        box: int,
        hold: int | None,
        increment_m: float,
        lift_m: float,
        go_on: Callable[[int, np.ndarray], bool] | None = None,
    ) -> tuple[PullResult, ArmStep, SceneState]:
        """Pull `box` out while `hold` is held, from a fresh scene at `state`; before each
        increment `go_on(k, poses)` (k increments done, (N, 7) box poses now) may stop it.
        -> the PullResult (judged as the kinematic executor's), what the arms did, and the
        state the step left."""
        if hold is not None and not self.bimanual:
            raise ValueError("a held box needs the bimanual executor")
        self._start(spec, state, box, hold)
        poses_start = self.u.box_poses()
        step = ArmStep()
        step.pose_log.append((0.0, self.u.box_poses()))
        pull_arm, hold_arm = PULL_ARM, HOLD_ARM
        if self.bimanual and (
            state.poses[box, 1] > state.poses[hold, 1]
            if hold is not None
            else state.poses[box, 1] > 0.0
        ):
            pull_arm, hold_arm = HOLD_ARM, PULL_ARM  # the arm on each box's side takes it
        step.pull_arm = pull_arm
        increments, aborted = 0, False
        if hold is not None:
            step.outcome, step.failed_arm = self._reach_both(hold_arm, hold, pull_arm, box, step)
        else:
            status, plans = self._plan_reach(pull_arm, box, aside=False)
            if status == "ok":
                status = self._take(pull_arm, box, plans[0][1], False, step)
            if status != "ok":
                step.outcome, step.failed_arm = status, "pull"
        if step.outcome == "ok":
            increments, aborted = self._pull_out(pull_arm, box, increment_m, lift_m, go_on, step)
        self.u.detach(pull_arm)
        self._home(pull_arm, step)
        self._settle(step)
        held_disp, step.on_shelf_held = self.u.displacements()
        if hold is not None:
            self.u.detach(hold_arm)
            self._home(hold_arm, step)
            self._settle(step)
        disp, on_shelf = self.u.displacements()
        step.pose_log.append((step.control_steps * self.dt_s, self.u.box_poses()))
        result = PullResult(
            increments,
            aborted,
            box in self.u.removed,
            held_disp,
            disp,
            on_shelf,
            poses_start,
            self.u.box_poses(),
            self.u.scene_spec.shelf.contains(poses_start[:, :3]),
        )
        return result, step, SceneState(self.u.box_poses(), frozenset(self.u.removed))

    def _pull_out(
        self,
        pull_arm: int,
        box: int,
        increment_m: float,
        lift_m: float,
        go_on: Callable[[int, np.ndarray], bool] | None,
        step: ArmStep,
    ) -> tuple[int, bool]:
        """With `box` grasped by `pull_arm`: lift it by lift_m, then pull it out by
        increments (each after `go_on` lets it go on); a pull that ends parks the box, one
        stopped or failed lets it go. -> (increments made, aborted)."""
        increments, aborted = 0, False
        start = np.asarray(self.u.tcp_pose(pull_arm).p, dtype=np.float64)
        q_tool = np.asarray(self.u.tcp_pose(pull_arm).q, dtype=np.float64)
        if lift_m > 0.0:
            start = start + [0.0, 0.0, lift_m]
            self._line(pull_arm, np.hstack([start, q_tool]), step, check_shelf=False)
        travel, pulled = self._travel_m(box), 0.0
        while pulled < travel - 1e-9:
            if go_on is not None and not go_on(increments, self.u.box_poses()):
                aborted = True
                break
            pulled += min(increment_m, travel - pulled)
            goal = np.hstack([start - [pulled, 0.0, 0.0], q_tool])
            if self._line(pull_arm, goal, step, check_shelf=False) != "ok":
                step.outcome, step.failed_arm = "planning_failed", "pull"
                aborted = True
                break
            increments += 1
        step.pose_log.append((step.control_steps * self.dt_s, self.u.box_poses()))
        if aborted:
            self.u.detach(pull_arm)
        else:
            self.u.park(box)
        return increments, aborted
