"""A SAPIEN 3 (PhysX CPU) shelf scene with boxes, and the actions planners and trials use.

Every action is measured against one reference: the box positions the world was built with
(`BoxWorld.from_spec`: the settled spec, fresh). Labels, CLI replays and trial judges all
start from that canonical state, so the same action on the same scene gives the same bits
everywhere (a world reused through `system.unpack` would keep PhysX's contact cache and
drift by a few millimetres). A later step of an episode starts the same way, from a fresh
world built from the state the previous step left (`BoxWorld.from_state`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
import sapien
from sapien import physx

from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.geometry import box_aabb_half_extents, displacement_m, quat_mul
from clutterbench.sim.shelf import Shelf

if TYPE_CHECKING:
    from clutterbench.sim.spec import SceneSpec

sapien.set_log_level("error")

ROOM_FLOOR_BELOW_SHELF_M = 0.4
# Where a removed box is parked: far below the floor, kinematic, so it touches nothing.
_PARK_POSE = sapien.Pose([0.0, 0.0, -50.0])
PULL_CLEARANCE_M = 0.01
RESTING_OVERLAP_M = 0.003
"""A box whose top is at most this far above another's bottom (within their common footprint)
may be what that box rests on (resting contacts overlap a little, a tilted box's bounds more)."""
"""A pulled box counts as out once its back face is this far in front of the opening."""
CONTACT_SEPARATION_M = 0.001
"""Two boxes touch when PhysX reports a contact point closer than this."""
_PACKED = 13  # floats per dynamic body in PhysxCpuSystem.pack(): q, p, velocities


@dataclasses.dataclass(frozen=True)
class SettleResult:
    steps: int
    at_rest: bool


@dataclasses.dataclass(frozen=True)
class ActionResult:
    """What an action did, measured against the world's reference (its canonical start)."""

    displacement_m: np.ndarray
    """(N,) centre displacement of every box from its reference position; NaN for boxes
    taken out of the scene."""
    at_rest: bool
    """Whether every dynamic box came to rest before the time limit."""
    steps: int
    """Physics steps the action took (including the settling after it)."""


class BoxWorld:
    """One shelf scene. Boxes are indexed 0..N-1 in the order they were added."""

    def __init__(self, shelf: Shelf, cfg: PhysicsConfig, render: bool = False):
        self.shelf, self.cfg = shelf, cfg
        self.system = physx.PhysxCpuSystem()
        systems: list = [self.system]
        if render:
            systems.append(sapien.render.RenderSystem())
        self.scene = sapien.Scene(systems)
        self.scene.set_timestep(cfg.timestep_s)
        self.material = physx.PhysxMaterial(
            cfg.static_friction, cfg.dynamic_friction, cfg.restitution
        )
        self.render = render
        self.camera = None  # created once, on the first picture (sim/render.py)
        self.sizes_m: list[np.ndarray] = []
        self.bodies: list[physx.PhysxRigidDynamicComponent] = []
        self.entities: list[sapien.Entity] = []
        self.reference: list[np.ndarray] = []
        """Each box's position when it entered the world: what displacements are measured
        against."""
        self.removed: set[int] = set()
        self._pulls: dict[int, tuple[sapien.Pose, int]] = {}  # target -> (start pose, steps)
        self.steps_taken = 0
        self.sapien_s = 0.0  # wall time inside SAPIEN step/render calls (for the benchmark)
        # The room floor under the shelf, so a box that falls out comes to rest (not rendered).
        self.scene.add_ground(-ROOM_FLOOR_BELOW_SHELF_M, render=False, material=self.material)
        for name, half, centre in shelf.boards():
            b = self.scene.create_actor_builder()
            b.add_box_collision(half_size=half, material=self.material)
            if render:
                b.add_box_visual(half_size=half)
            b.set_initial_pose(sapien.Pose(centre))
            b.build_static(name=f"shelf_{name}")

    @classmethod
    def from_spec(cls, spec: SceneSpec, cfg: PhysicsConfig, render: bool = False) -> BoxWorld:
        """The canonical start: a fresh world holding the spec's boxes at their settled poses,
        at rest. Every label, replay and trial begins here."""
        return cls.from_state(spec, spec.poses, (), cfg, render=render)

    @classmethod
    def from_state(
        cls,
        spec: SceneSpec,
        poses: np.ndarray,
        removed: Iterable[int],
        cfg: PhysicsConfig,
        render: bool = False,
    ) -> BoxWorld:
        """A fresh world holding the spec's boxes at `poses` ((N, 7)), at rest, with the boxes
        in `removed` already taken out (parked): the canonical start of a later step of an
        episode. Box k keeps index k (and instance id k + 1) whatever was removed."""
        world = cls(spec.shelf, cfg, render=render)
        for k in range(spec.n):
            world.add_box(spec.sizes_m[k], poses[k], spec.density(k, cfg.density_kg_m3))
        for k in sorted(removed):
            world.park(k)
        return world

    # -- building ---------------------------------------------------------------------------
    def add_box(
        self, size_m: np.ndarray, pose: np.ndarray, density_kg_m3: float | None = None
    ) -> int:
        """Add a dynamic box of full extents `size_m` at pose [x, y, z, qw, qx, qy, qz]."""
        size_m = np.asarray(size_m, dtype=np.float64)
        assert size_m.shape == (3,) and np.all(size_m > 0), "size_m must be 3 positive metres"
        b = self.scene.create_actor_builder()
        b.add_box_collision(
            half_size=size_m / 2,
            material=self.material,
            density=density_kg_m3 or self.cfg.density_kg_m3,
        )
        if self.render:
            b.add_box_visual(half_size=size_m / 2)
        b.set_initial_pose(sapien.Pose(pose[:3], pose[3:]))
        entity = b.build(name=f"box_{len(self.bodies)}")
        self.entities.append(entity)
        self.bodies.append(entity.find_component_by_type(physx.PhysxRigidDynamicComponent))
        self.sizes_m.append(size_m)
        self.reference.append(np.array(entity.pose.p, dtype=np.float64))
        return len(self.bodies) - 1

    @property
    def n(self) -> int:
        return len(self.bodies)

    # -- state ------------------------------------------------------------------------------
    def _packed(self) -> np.ndarray:
        """(N, 13) float32: the boxes' PhysX state (q, p, velocities) in one call, in the order
        they were added (the only dynamic bodies); the entities' poses to the bit (a test)."""
        raw = np.frombuffer(self.system.pack(), dtype=np.float32, count=self.n * _PACKED)
        return raw.reshape(self.n, _PACKED)

    def poses(self) -> np.ndarray:
        """(N, 7) float64 poses [x, y, z, qw, qx, qy, qz]."""
        packed = self._packed()
        out = np.empty((self.n, 7))
        out[:, :3], out[:, 3:] = packed[:, 4:7], packed[:, :4]
        return out

    def entity_poses(self) -> np.ndarray:
        """`poses` read box by box from the entities (the definition `poses` matches)."""
        poses = [(*e.pose.p, *e.pose.q) for e in self.entities]
        return np.array(poses, dtype=np.float64).reshape(-1, 7)

    def positions(self) -> np.ndarray:
        return self._packed()[:, 4:7].astype(np.float64)

    def aabbs(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), each (N, 3): world AABBs of the boxes at their current poses."""
        poses = self.poses()
        half = np.array([box_aabb_half_extents(s, q[3:]) for s, q in zip(self.sizes_m, poses)])
        half = half.reshape(-1, 3)
        return poses[:, :3] - half, poses[:, :3] + half

    def displacements(self) -> np.ndarray:
        """(N,) distance of each box's centre from its reference; NaN for removed boxes."""
        disp = displacement_m(np.array(self.reference).reshape(-1, 3), self.positions())
        disp[sorted(self.removed)] = np.nan
        return disp

    def contact_pairs(self) -> list[tuple[int, int]]:
        """Pairs (i < j) of boxes touching after the last step (PhysX contacts); empty before
        the first step."""
        index = {e.per_scene_id: k for k, e in enumerate(self.entities)}
        pairs = set()
        for c in self.system.get_contacts():
            a, b = (index.get(body.entity.per_scene_id) for body in c.bodies)
            if a is None or b is None or a == b:
                continue
            if any(pt.separation < CONTACT_SEPARATION_M for pt in c.points):
                pairs.add((min(a, b), max(a, b)))
        return sorted(pairs)

    # -- stepping ---------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        t0 = time.perf_counter()
        for _ in range(n):
            self.scene.step()
        self.sapien_s += time.perf_counter() - t0
        self.steps_taken += n

    def _still(self, before: np.ndarray, after: np.ndarray, steps: int) -> bool:
        """Whether no dynamic box moved faster, on average over `steps`, than the rest speeds.

        Judged from poses, not from PhysX's reported velocities: a resting box whose settled
        pose overlaps a neighbour by a fraction of a millimetre reports a residual solver
        velocity (~20 mm/s measured) while it does not move at all.
        """
        dt = steps * self.cfg.timestep_s
        dynamic = np.array([not b.kinematic for b in self.bodies], dtype=bool)
        dynamic[sorted(self.removed)] = False
        if not dynamic.any():
            return True
        # np.linalg.norm's and np.clip's arithmetic without their wrappers; turns if no move
        shift = after[dynamic, :3] - before[dynamic, :3]
        move = np.sqrt(np.add.reduce(shift * shift, axis=1))
        if not (move <= self.cfg.rest_linear_m_s * dt).all():
            return False
        dots = np.abs(np.add.reduce(after[dynamic, 3:] * before[dynamic, 3:], axis=1))
        turn = 2.0 * np.arccos(np.minimum(dots, 1.0))
        return bool((turn <= self.cfg.rest_angular_rad_s * dt).all())

    def settle(self, max_s: float | None = None) -> SettleResult:
        """Step until every box is at rest or `max_s` passes. At rest: two check windows in a
        row (sim.physics.check_every_steps each) in which no box moved faster than the rest
        speeds."""
        max_steps = int(round((max_s or self.cfg.settle_max_s) / self.cfg.timestep_s))
        every = self.cfg.check_every_steps
        steps, still, prev = 0, 0, self.poses()
        while steps < max_steps:
            self.step(every)
            steps += every
            now = self.poses()
            still = still + 1 if self._still(prev, now, every) else 0
            if still >= 2:
                return SettleResult(steps, True)
            prev = now
        return SettleResult(steps, False)

    # -- actions ----------------------------------------------------------------------------
    def _result(self, steps_before: int, at_rest: bool) -> ActionResult:
        return ActionResult(self.displacements(), at_rest, self.steps_taken - steps_before)

    def _settle_action(self, steps_before: int) -> ActionResult:
        for body in self.bodies:
            if not body.kinematic:
                body.wake_up()
        settled = self.settle(self.cfg.action_settle_max_s)
        return self._result(steps_before, settled.at_rest)

    def _check(self, *boxes: int) -> None:
        for i in boxes:
            if not 0 <= i < self.n:
                raise IndexError(f"no box {i} (the world holds boxes 0..{self.n - 1})")
            if i in self.removed:
                raise ValueError(f"box {i} was taken out of the scene")

    def hold(self, boxes: Iterable[int]) -> None:
        """Hold boxes fixed where they are (kinematic), as a robot's second arm does."""
        for i in boxes:
            self._check(i)
            self.bodies[i].set_kinematic(True)
            self.bodies[i].set_kinematic_target(self.entities[i].pose)

    def release(self, boxes: Iterable[int]) -> None:
        """Let held boxes go (dynamic again), at rest where they are; nothing is stepped."""
        for i in boxes:
            self._check(i)
            self.bodies[i].set_kinematic(False)
            # An opening gripper does not throw the box: the kinematic motion's speed is not
            # carried over.
            self.bodies[i].set_linear_velocity(np.zeros(3))
            self.bodies[i].set_angular_velocity(np.zeros(3))
            self._pulls.pop(i, None)
        for body in self.bodies:
            if not body.kinematic:
                body.wake_up()

    def held(self) -> list[int]:
        return [i for i, b in enumerate(self.bodies) if b.kinematic and i not in self.removed]

    def settle_action(self) -> ActionResult:
        """Let the scene come to rest (at most sim.physics.action_settle_max_s)."""
        return self._settle_action(self.steps_taken)

    def lift_out(self, target: int) -> ActionResult:
        """Take `target` out of the scene at once (a straight lift), then let the rest settle."""
        self._check(target)
        before = self.steps_taken
        self.park(target)
        return self._settle_action(before)

    def park(self, target: int) -> None:
        """Take `target` out of the scene at once (kinematic, far below the floor, touching
        nothing); nothing is stepped."""
        self._check(target)
        body = self.bodies[target]
        body.set_kinematic(True)
        body.set_kinematic_target(_PARK_POSE)
        self.entities[target].set_pose(_PARK_POSE)
        self.removed.add(target)
        self._pulls.pop(target, None)

    def pull_travel_m(self, target: int) -> float:
        """How far `target` must be pulled toward the camera (-x) from where it is now to be
        out of the shelf (back face past the opening plus a clearance)."""
        _, hi = self.aabbs()
        return float(hi[target, 0] + PULL_CLEARANCE_M)

    def pull_step(self, target: int, distance_m: float, lift_m: float = 0.0) -> ActionResult:
        """Pull `target` toward the camera (-x) by `distance_m` at sim.physics.pull_speed_m_s,
        gripped (kinematic); the other boxes react but are not settled afterwards, so a
        planner can observe mid-pull and stop. Increments compose exactly: pulling 0.1 m once
        steps the same poses as ten pulls of 0.01 m.

        `lift_m` > 0: on the first increment the gripper first raises the box straight up by
        that much (at the same speed), so it slides clear of what it rests on; later
        increments of the same pull ignore it."""
        self._check(target)
        assert lift_m >= 0.0, "lift_m must be >= 0"
        before = self.steps_taken
        dx = self.cfg.pull_speed_m_s * self.cfg.timestep_s
        if target not in self._pulls:
            self.hold([target])
            start = self.entities[target].pose
            if lift_m > 0.0:
                n_lift = int(np.ceil(lift_m / dx - 1e-9))
                for k in range(1, n_lift + 1):
                    p = np.array(start.p) + np.array([0.0, 0.0, lift_m * k / n_lift])
                    self.bodies[target].set_kinematic_target(sapien.Pose(p, start.q))
                    self.step()
                start = sapien.Pose(np.array(start.p) + np.array([0.0, 0.0, lift_m]), start.q)
            self._pulls[target] = (start, 0)
        start, done = self._pulls[target]
        n_steps = int(np.ceil(distance_m / dx - 1e-9))
        if n_steps == 0:
            return self._result(before, self._still(self.poses(), self.poses(), 1))
        path = np.tile(np.array(start.p), (n_steps, 1)).astype(np.float64)
        path[:, 0] -= np.arange(done + 1, done + n_steps + 1) * dx
        body, q = self.bodies[target], start.q  # the targets above: k * dx from the start
        physx_step, clock = self.system.step, time.perf_counter
        inside = 0.0  # wall time inside the PhysX steps, as `step` counts it
        for p in path[:-1]:
            body.set_kinematic_target(sapien.Pose(p, q))
            t0 = clock()
            physx_step()
            inside += clock() - t0
        self.sapien_s += inside
        body.set_kinematic_target(sapien.Pose(path[-1], q))
        prev = self.poses()
        self.step()
        self.steps_taken += n_steps - 1
        self._pulls[target] = (start, done + n_steps)
        # at_rest here: nothing but the gripped box moved during the last step.
        return self._result(before, self._still(prev, self.poses(), 1))

    def return_pull(self, target: int, lift_m: float = 0.0) -> None:
        """Move a box gripped mid-pull (pull_step) back along its pull to where the pull
        started, then down by the pull's `lift_m`, at the pull's speed: a gripper putting back
        what it took instead of letting go of it half out. The box stays gripped; the others
        react; nothing is settled."""
        self._check(target)
        start, done = self._pulls[target]
        dx = self.cfg.pull_speed_m_s * self.cfg.timestep_s
        for k in range(done - 1, -1, -1):
            p = np.array(start.p) - np.array([k * dx, 0.0, 0.0])
            self.bodies[target].set_kinematic_target(sapien.Pose(p, start.q))
            self.step()
        self._lower_by(target, lift_m)

    def lower_onto_support(self, target: int, clearance_m: float = 0.001) -> None:
        """Lower a held box straight down at the pull's speed until its bottom is `clearance_m`
        above the highest top below it (a box in the scene whose footprint overlaps its own,
        else the shelf floor): a second arm setting down what it held instead of opening in
        mid-air. It stays held; nothing is settled."""
        self._check(target)
        lo, hi = self.aabbs()
        tops = [0.0]
        for k in range(self.n):
            if k == target or k in self.removed:
                continue
            apart = np.any(hi[k, :2] <= lo[target, :2]) or np.any(lo[k, :2] >= hi[target, :2])
            # below it, or touching it from below (resting contacts overlap a little): a box
            # it still rests on keeps it where it is
            if not apart and hi[k, 2] <= lo[target, 2] + RESTING_OVERLAP_M:
                tops.append(float(hi[k, 2]))
        self._lower_by(target, float(lo[target, 2]) - max(tops) - clearance_m)

    def _lower_by(self, target: int, distance_m: float) -> None:
        if distance_m <= 0.0:
            return
        dx = self.cfg.pull_speed_m_s * self.cfg.timestep_s
        start = self.entities[target].pose
        n = int(np.ceil(distance_m / dx - 1e-9))
        for k in range(1, n + 1):
            p = np.array(start.p) - np.array([0.0, 0.0, distance_m * k / n])
            self.bodies[target].set_kinematic_target(sapien.Pose(p, start.q))
            self.step()

    def carry(self, target: int, pose: np.ndarray, speed_m_s: float | None = None) -> ActionResult:
        """Carry `target` in a straight line to `pose` [x, y, z, qw, qx, qy, qz] (orientation
        interpolated), release it there and let the scene settle (ch. 5 moves/placements)."""
        self._check(target)
        before = self.steps_taken
        self.hold([target])
        start = self.entities[target].pose
        goal = sapien.Pose(
            np.asarray(pose[:3], dtype=np.float64), np.asarray(pose[3:], dtype=np.float64)
        )
        speed = speed_m_s or self.cfg.pull_speed_m_s
        dist = float(np.linalg.norm(np.array(goal.p) - np.array(start.p)))
        n_steps = max(1, int(np.ceil(dist / (speed * self.cfg.timestep_s))))
        q0, q1 = np.array(start.q), np.array(goal.q)
        if np.dot(q0, q1) < 0:  # the short way round
            q1 = -q1
        for k in range(1, n_steps + 1):
            t = k / n_steps
            q = (1 - t) * q0 + t * q1  # nlerp: enough for a straight carry
            p = (1 - t) * np.array(start.p) + t * np.array(goal.p)
            self.bodies[target].set_kinematic_target(sapien.Pose(p, q / np.linalg.norm(q)))
            self.step()
        self.release([target])
        return self._settle_action(before)

    def carry_group(
        self,
        boxes: Iterable[int],
        translation_m: np.ndarray,
        rotation_x_rad: float = 0.0,
        speed_m_s: float | None = None,
    ) -> None:
        """Carry `boxes` together by one rigid motion (ch. 5: a cluster moved aside): turned
        by `rotation_x_rad` about the world x axis (the camera's view axis: setting a leaning
        cluster upright) around their centroid while translated by `translation_m`, at
        sim.physics.pull_speed_m_s along the farthest-travelling box. They stay held
        (kinematic) where they end; `release` lets them go. Nothing settles afterwards."""
        boxes = list(boxes)
        self._check(*boxes)
        self.hold(boxes)
        starts = [self.entities[i].pose for i in boxes]
        p0 = np.array([np.array(s.p) for s in starts])
        pivot = p0.mean(axis=0)
        shift = np.asarray(translation_m, dtype=np.float64)
        # the farthest a box travels: the shift plus its arc about the pivot
        arc = np.abs(rotation_x_rad) * np.linalg.norm((p0 - pivot)[:, 1:], axis=1)
        dist = float(np.linalg.norm(shift) + (arc.max() if len(arc) else 0.0))
        speed = speed_m_s or self.cfg.pull_speed_m_s
        n_steps = max(1, int(np.ceil(dist / (speed * self.cfg.timestep_s))))
        for k in range(1, n_steps + 1):
            t = k / n_steps
            a = t * rotation_x_rad
            c, s = np.cos(a), np.sin(a)
            R = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
            q_rot = np.array([np.cos(a / 2), np.sin(a / 2), 0.0, 0.0])
            for j, i in enumerate(boxes):
                p = pivot + R @ (p0[j] - pivot) + t * shift
                q = quat_mul(q_rot, np.array(starts[j].q))
                self.bodies[i].set_kinematic_target(sapien.Pose(p, q))
            self.step()

    def insert(
        self, size_m: np.ndarray, pose: np.ndarray, density_kg_m3: float | None = None
    ) -> tuple[int, ActionResult]:
        """Put a new box at `pose` and let the scene settle; its reference is that pose."""
        before = self.steps_taken
        idx = self.add_box(size_m, pose, density_kg_m3)
        return idx, self._settle_action(before)

    def idle_creep_m(self) -> np.ndarray:
        """(N,) how far each box moves in sim.physics.rest_check_s with no action at all, from
        this (fresh) world's start. A canonical start is at rest when every value is below
        sim.physics.rest_check_m; otherwise a box creeps during every action, with no cause."""
        assert self.steps_taken == 0, "measured on a freshly built world"
        self.step(int(round(self.cfg.rest_check_s / self.cfg.timestep_s)))
        return self.displacements()

    # -- the labelled actions (thesis ch. 4-6) ----------------------------------------------
    def remove(self, target: int, support: int | None = None) -> np.ndarray:
        """Lift `target` out, settle, return each box's displacement (m); NaN for the target.

        With `support`, that box is held fixed (kinematic) throughout, as the thesis' second
        arm does (ch. 6 bimanual).
        """
        if support is not None:
            self.hold([support])
        return self.lift_out(target).displacement_m

    def pull(self, target: int, support: int | None = None, lift_m: float = 0.0) -> np.ndarray:
        """Pull `target` horizontally toward the camera (-x) until it has left the shelf
        (raised by `lift_m` first, see `pull_step`), then settle; returns displacements (m)
        as `remove` does (thesis 4.2.1)."""
        if support is not None:
            self.hold([support])
        self.pull_step(target, self.pull_travel_m(target), lift_m)
        return self.lift_out(target).displacement_m
