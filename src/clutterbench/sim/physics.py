"""A SAPIEN 3 (PhysX CPU) shelf scene with boxes: settling, removal and pull actions."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import sapien
from sapien import physx

from clutterbench.config import bounded
from clutterbench.sim.geometry import box_aabb_half_extents, displacement_m
from clutterbench.sim.shelf import Shelf

sapien.set_log_level("error")

ROOM_FLOOR_BELOW_SHELF_M = 0.4
# Where a removed box is parked: far below the floor, kinematic, so it touches nothing.
_PARK_POSE = sapien.Pose([0.0, 0.0, -50.0])


@dataclasses.dataclass(frozen=True)
class PhysicsConfig:
    timestep_s: float = bounded(1 / 240, gt=0.0, le=0.02)
    """Physics step (s). 240 Hz keeps 20 mm boxes from tunnelling."""
    density_kg_m3: float = bounded(300.0, gt=0.0)
    """Box density. The thesis' 1.0 kg/m^3 gives 2 g boxes the solver handles badly;
    300 kg/m^3 (a filled carton) gives 60-800 g boxes."""
    static_friction: float = bounded(0.9, ge=0.0)
    """Static friction of boxes and shelf (thesis 4.2.1)."""
    dynamic_friction: float = bounded(0.8, ge=0.0)
    """Dynamic friction (thesis 4.2.1)."""
    restitution: float = bounded(0.1, ge=0.0, le=1.0)
    """Coefficient of restitution (thesis 4.2.1)."""
    settle_max_s: float = bounded(4.0, gt=0.0)
    """Longest a scene may take to come to rest after generation; longer -> rejected."""
    action_settle_max_s: float = bounded(3.0, gt=0.0)
    """Longest to simulate after an action before displacements are measured."""
    check_every_steps: int = bounded(8, ge=1)
    """Rest is checked every this many steps."""
    rest_linear_m_s: float = bounded(0.004, gt=0.0)
    """A body is at rest when its linear speed is below this (m/s) ..."""
    rest_angular_rad_s: float = bounded(0.04, gt=0.0)
    """... and its angular speed below this (rad/s)."""
    pull_speed_m_s: float = bounded(0.2, gt=0.0)
    """Speed of a horizontal pull toward the camera (thesis ch. 4 extraction)."""


@dataclasses.dataclass(frozen=True)
class SettleResult:
    steps: int
    at_rest: bool


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
        self.sizes_m: list[np.ndarray] = []
        self.bodies: list[physx.PhysxRigidDynamicComponent] = []
        self.entities: list[sapien.Entity] = []
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

    # -- building ---------------------------------------------------------------------------
    def add_box(self, size_m: np.ndarray, pose: np.ndarray) -> int:
        """Add a dynamic box of full extents `size_m` at pose [x, y, z, qw, qx, qy, qz]."""
        size_m = np.asarray(size_m, dtype=np.float64)
        assert size_m.shape == (3,) and np.all(size_m > 0), "size_m must be 3 positive metres"
        b = self.scene.create_actor_builder()
        b.add_box_collision(
            half_size=size_m / 2, material=self.material, density=self.cfg.density_kg_m3
        )
        if self.render:
            b.add_box_visual(half_size=size_m / 2)
        b.set_initial_pose(sapien.Pose(pose[:3], pose[3:]))
        entity = b.build(name=f"box_{len(self.bodies)}")
        self.entities.append(entity)
        self.bodies.append(entity.find_component_by_type(physx.PhysxRigidDynamicComponent))
        self.sizes_m.append(size_m)
        return len(self.bodies) - 1

    @property
    def n(self) -> int:
        return len(self.bodies)

    # -- state ------------------------------------------------------------------------------
    def poses(self) -> np.ndarray:
        """(N, 7) float64 poses [x, y, z, qw, qx, qy, qz]."""
        out = np.empty((self.n, 7))
        for i, e in enumerate(self.entities):
            p = e.pose
            out[i, :3], out[i, 3:] = p.p, p.q
        return out

    def positions(self) -> np.ndarray:
        return np.array([e.pose.p for e in self.entities], dtype=np.float64).reshape(-1, 3)

    def aabbs(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), each (N, 3): world AABBs of the boxes at their current poses."""
        poses = self.poses()
        half = np.array([box_aabb_half_extents(s, q[3:]) for s, q in zip(self.sizes_m, poses)])
        half = half.reshape(-1, 3)
        return poses[:, :3] - half, poses[:, :3] + half

    def save(self) -> bytes:
        return self.system.pack()

    def restore(self, state: bytes) -> None:
        for body in self.bodies:
            if body.kinematic:
                body.set_kinematic(False)
        self.system.unpack(state)
        for body in self.bodies:
            body.wake_up()

    # -- stepping ---------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        t0 = time.perf_counter()
        for _ in range(n):
            self.scene.step()
        self.sapien_s += time.perf_counter() - t0
        self.steps_taken += n

    def at_rest(self) -> bool:
        lin, ang = self.cfg.rest_linear_m_s, self.cfg.rest_angular_rad_s
        for body in self.bodies:
            if body.kinematic:
                continue
            if (
                np.abs(body.linear_velocity).max() > lin
                or np.abs(body.angular_velocity).max() > ang
            ):
                return False
        return True

    def settle(self, max_s: float | None = None) -> SettleResult:
        """Step until every box is at rest (checked every few steps) or `max_s` passes."""
        max_steps = int(round((max_s or self.cfg.settle_max_s) / self.cfg.timestep_s))
        every = self.cfg.check_every_steps
        steps = 0
        while steps < max_steps:
            self.step(every)
            steps += every
            if self.at_rest():
                return SettleResult(steps, True)
        return SettleResult(steps, False)

    # -- actions ----------------------------------------------------------------------------
    def _hold(self, i: int, pose: sapien.Pose) -> None:
        body = self.bodies[i]
        body.set_kinematic(True)
        body.set_kinematic_target(pose)
        self.entities[i].set_pose(pose)

    def _park_and_measure(self, target: int, before: np.ndarray) -> np.ndarray:
        """Take `target` out of the scene, let the rest settle, return displacements (m)."""
        self._hold(target, _PARK_POSE)
        for body in self.bodies:
            if not body.kinematic:
                body.wake_up()
        self.settle(self.cfg.action_settle_max_s)
        disp = displacement_m(before, self.positions())
        disp[target] = np.nan
        return disp

    def remove(self, target: int, support: int | None = None) -> np.ndarray:
        """Lift `target` out of the scene at once, settle, return each box's displacement (m).

        The target's entry is NaN. With `support`, that box is held fixed (kinematic)
        throughout, as the thesis' second arm does (ch. 6 bimanual).
        """
        before = self.positions()
        if support is not None:
            self._hold(support, self.entities[support].pose)
        return self._park_and_measure(target, before)

    def pull(self, target: int, support: int | None = None) -> np.ndarray:
        """Pull `target` horizontally toward the camera (-x) until it has left the shelf,
        then settle; returns displacements (m) as `remove` does (thesis 4.2.1)."""
        before = self.positions()
        if support is not None:
            self._hold(support, self.entities[support].pose)
        start = self.entities[target].pose
        lo, hi = self.aabbs()
        travel = hi[target, 0] + 0.01  # until its back face passes the opening, plus 1 cm
        self.bodies[target].set_kinematic(True)
        dx = self.cfg.pull_speed_m_s * self.cfg.timestep_s
        n_steps = int(np.ceil(travel / dx))
        for k in range(1, n_steps + 1):
            p = np.array(start.p) - np.array([min(k * dx, travel), 0.0, 0.0])
            self.bodies[target].set_kinematic_target(sapien.Pose(p, start.q))
            self.step()
        return self._park_and_measure(target, before)
