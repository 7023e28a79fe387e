"""Chapter 3 (Yamakuzushi): a pile of Shogi pieces on a board in SAPIEN 3 (PhysX CPU), the
finger's slide that takes a piece off the board, its judge, and the depth cameras.

World frame: the board's top surface is z = 0, its centre the origin, z up; metres. Pieces
are indexed 0..N-1 (instance id k + 1). As in sim/physics.py, every action starts from a
freshly built world holding the pieces at their poses (the canonical start), so the same
slide on the same pile gives the same bits everywhere.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from typing import Any

import numpy as np
import sapien
from sapien import physx

from clutterbench.errors import ClutterbenchError
from clutterbench.observation import CameraModel, Observation
from clutterbench.shogi_piece import (
    PIECE_MASS_KG,
    PIECE_SIZE_M,
    TIP_THICKNESS_M,
    piece_mesh,
    piece_vertices,
    piece_volume_m3,
)
from clutterbench.sim import benchmark
from clutterbench.sim.geometry import (
    displacement_m,
    quat_from_axis_angle,
    quat_mul,
    quat_to_matrix,
)
from clutterbench.sim.pile_config import PileCameraConfig, PileConfig, SlideConfig
from clutterbench.sim.renderer import add_depth_camera

sapien.set_log_level("error")

# A piece taken out is parked here: kinematic, far below the floor, touching nothing.
_PARK_POSE = sapien.Pose([0.0, 0.0, -50.0])


# -- pure geometry ---------------------------------------------------------------------------
def piece_points_m(pose: np.ndarray) -> np.ndarray:
    """(10, 3) world positions of the piece's hull vertices at pose [x, y, z, qw, qx, qy, qz]."""
    pose = np.asarray(pose, dtype=np.float64)
    return piece_vertices() @ quat_to_matrix(pose[3:]).T + pose[:3]


def flat_piece_pose(
    x_m: float, y_m: float, tip_direction_rad: float, surface_z_m: float = 0.0
) -> np.ndarray:
    """Pose [x, y, z, qw, qx, qy, qz] of a piece lying on a face on a level surface at height
    `surface_z_m`, centred over (x_m, y_m), its tip pointing along `tip_direction_rad` (0 = +x,
    counter-clockwise).

    The piece tapers, so its faces slope in its own frame (~3 deg): lying flat it is turned
    about its x axis until the lower face is level."""
    slope = (PIECE_SIZE_M[2] - TIP_THICKNESS_M) / (2 * PIECE_SIZE_M[1])  # lower face dz/dy
    q = quat_mul(
        quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), tip_direction_rad - np.pi / 2),
        quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), -np.arctan(slope)),
    )
    pose = np.array([x_m, y_m, 0.0, *q])
    pose[2] = surface_z_m - piece_points_m(pose)[:, 2].min()
    return pose


def on_board(poses: np.ndarray, board_size_m: tuple[float, float]) -> np.ndarray:
    """(N,) whether each piece's centre is above the board's top (NaN rows: False)."""
    half = 0.5 * np.asarray(board_size_m)
    return np.all(np.abs(poses[:, :2]) <= half, axis=1) & (poses[:, 2] > 0.0)


def beyond_edge(points_xy: np.ndarray, half_extents_m: np.ndarray) -> bool:
    """Whether every point lies beyond one and the same edge of the rectangle
    [-hx, hx] x [-hy, hy] (a footprint wholly off the board on one side)."""
    p, h = np.asarray(points_xy), np.asarray(half_extents_m)
    return bool(np.any(np.all(p > h, axis=0)) or np.any(np.all(p < -h, axis=0)))


def exit_travel_m(points_xy: np.ndarray, direction_rad: float, half_extents_m: np.ndarray) -> float:
    """How far points must travel along `direction_rad` (0 = +x, counter-clockwise) until all
    of them lie beyond one edge of the rectangle [-hx, hx] x [-hy, hy] (see `beyond_edge`)."""
    d = np.array([np.cos(direction_rad), np.sin(direction_rad)])
    p, h = np.asarray(points_xy), np.asarray(half_extents_m)
    travel = np.inf
    for axis in range(2):
        if abs(d[axis]) < 1e-12:
            continue
        edge = h[axis] * np.sign(d[axis])  # the edge ahead along this axis
        need = (edge - p[:, axis]) / d[axis]
        travel = min(travel, float(need.max()))
    return max(travel, 0.0)


def look_at_rotation(eye_m: np.ndarray, target_m: np.ndarray) -> np.ndarray:
    """(3, 3) world rotation of a SAPIEN camera (x forward, y left, z up) at `eye_m` looking
    at `target_m`: world z is up in the image; looking straight down, world +y is up."""
    fwd = np.asarray(target_m, dtype=np.float64) - np.asarray(eye_m, dtype=np.float64)
    assert np.linalg.norm(fwd) > 1e-9, "eye and target must differ"
    fwd /= np.linalg.norm(fwd)
    left = np.cross([0.0, 0.0, 1.0], fwd)
    if np.linalg.norm(left) < 1e-6:  # looking straight down (or up)
        left = np.cross([0.0, 1.0, 0.0], fwd)
    left /= np.linalg.norm(left)
    return np.stack([fwd, left, np.cross(fwd, left)], axis=1)


# -- the pile --------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class PileSpec:
    """A settled pile: what every slide on it starts from."""

    seed: int
    """Seed it was generated from (-1: made by hand)."""
    poses: np.ndarray
    """(N, 7) settled piece poses [x, y, z, qw, qx, qy, qz] (world frame, metres)."""

    @property
    def n(self) -> int:
        return int(self.poses.shape[0])

    def to_dict(self) -> dict[str, Any]:
        # Python floats are written repr-exact by json: a reloaded spec is bit-identical.
        return {"seed": int(self.seed), "poses": [[float(v) for v in row] for row in self.poses]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PileSpec:
        poses = np.asarray(d["poses"], dtype=np.float64)
        if poses.ndim != 2 or poses.shape[1] != 7 or not np.all(np.isfinite(poses)):
            raise ClutterbenchError("pile spec: poses must be rows of 7 finite numbers")
        return cls(seed=int(d["seed"]), poses=poses)


@functools.cache
def _render_mesh() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat-shaded piece mesh (vertices, triangles, normals), one vertex per face corner."""
    mesh = piece_mesh()
    verts = mesh.vertices[mesh.faces].reshape(-1, 3).astype(np.float32)
    normals = np.repeat(mesh.face_normals, 3, axis=0).astype(np.float32)
    tris = np.arange(len(verts), dtype=np.uint32).reshape(-1, 3)
    return verts, tris, normals


def _cpu_system(enable_pcm: bool) -> physx.PhysxCpuSystem:
    """A PhysX CPU system with persistent contact manifolds (PCM) on or off. SAPIEN reads the
    process-wide scene config when a system is created: it is changed for that moment only."""
    config = physx.get_scene_config()
    default = config.enable_pcm
    config.enable_pcm = enable_pcm
    physx.set_scene_config(config)
    try:
        return physx.PhysxCpuSystem()
    finally:
        config.enable_pcm = default
        physx.set_scene_config(config)


class PileWorld:
    """One board with Shogi pieces. Build a world with `from_spec` / `from_poses`."""

    def __init__(self, cfg: PileConfig, render: bool = False):
        self.cfg, self.render = cfg, render
        self.system = _cpu_system(cfg.persistent_contacts)
        systems: list = [self.system]
        if render:
            systems.append(sapien.render.RenderSystem())
        self.scene = sapien.Scene(systems)
        self.scene.set_timestep(cfg.timestep_s)
        self.material = physx.PhysxMaterial(
            cfg.static_friction, cfg.dynamic_friction, cfg.restitution
        )
        self.bodies: list[physx.PhysxRigidDynamicComponent] = []
        self.entities: list[sapien.Entity] = []
        self.removed: set[int] = set()
        """Pieces taken off the board (parked); they have no pose (NaN rows)."""
        self.steps_taken = 0
        self.top_camera = None  # each created once, on its first picture
        self.view_camera = None
        # The floor the board stands on, so a piece pushed off comes to rest (not rendered).
        self.scene.add_ground(-cfg.board_thickness_m, render=False, material=self.material)
        half = np.array(
            [cfg.board_size_m[0] / 2, cfg.board_size_m[1] / 2, cfg.board_thickness_m / 2]
        )
        b = self.scene.create_actor_builder()
        b.add_box_collision(half_size=half, material=self.material)
        if render:
            b.add_box_visual(half_size=half)
        b.set_initial_pose(sapien.Pose([0.0, 0.0, -half[2]]))
        b.build_static(name="board")

    @classmethod
    def from_poses(cls, poses: np.ndarray, cfg: PileConfig, render: bool = False) -> PileWorld:
        """A fresh world with piece k at `poses[k]` ((N, 7)), at rest; a NaN row is a piece
        already taken off the board (parked, so piece k keeps index k)."""
        world = cls(cfg, render=render)
        for pose in np.asarray(poses, dtype=np.float64):
            if np.all(np.isfinite(pose)):
                world.add_piece(pose)
            else:
                world.park(world.add_piece(None))
        return world

    @classmethod
    def from_spec(cls, spec: PileSpec, cfg: PileConfig, render: bool = False) -> PileWorld:
        """The canonical start: a fresh world holding the spec's settled pile."""
        return cls.from_poses(spec.poses, cfg, render=render)

    def add_piece(self, pose: np.ndarray | None) -> int:
        """Add a dynamic piece at pose [x, y, z, qw, qx, qy, qz] (None: parked)."""
        shape = physx.PhysxCollisionShapeConvexMesh(
            vertices=piece_vertices().astype(np.float32),
            scale=[1.0, 1.0, 1.0],
            material=self.material,
        )
        shape.set_density(PIECE_MASS_KG / piece_volume_m3())
        body = physx.PhysxRigidDynamicComponent()
        body.attach(shape)
        body.set_solver_position_iterations(self.cfg.solver_position_iterations)
        body.set_solver_velocity_iterations(self.cfg.solver_velocity_iterations)
        entity = sapien.Entity()
        entity.add_component(body)
        if self.render:
            visual = sapien.render.RenderBodyComponent()
            verts, tris, normals = _render_mesh()
            uvs = np.zeros((len(verts), 2), dtype=np.float32)
            visual.attach(
                sapien.render.RenderShapeTriangleMesh(
                    verts, tris, normals, uvs, sapien.render.RenderMaterial()
                )
            )
            entity.add_component(visual)
        entity.name = f"piece_{len(self.bodies)}"
        entity.pose = _PARK_POSE if pose is None else sapien.Pose(pose[:3], pose[3:])
        self.scene.add_entity(entity)
        self.entities.append(entity)
        self.bodies.append(body)
        return len(self.bodies) - 1

    @property
    def n(self) -> int:
        return len(self.bodies)

    def poses(self) -> np.ndarray:
        """(N, 7) float64 poses [x, y, z, qw, qx, qy, qz]; NaN rows for removed pieces."""
        out = np.full((self.n, 7), np.nan)
        for k, e in enumerate(self.entities):
            if k not in self.removed:
                out[k, :3], out[k, 3:] = e.pose.p, e.pose.q
        return out

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.scene.step()
        self.steps_taken += n

    def _still(self, before: np.ndarray, after: np.ndarray, dt: float) -> bool:
        """No piece moved or turned faster than the rest speeds between two pose samples.
        From poses, as in sim/physics.py: PhysX reports residual velocities at rest."""
        live = np.all(np.isfinite(before), axis=1)
        move = np.linalg.norm(after[live, :3] - before[live, :3], axis=1)
        dots = np.abs(np.sum(after[live, 3:] * before[live, 3:], axis=1))
        turn = 2.0 * np.arccos(np.clip(dots, 0.0, 1.0))
        return bool(
            np.all(move <= self.cfg.rest_linear_m_s * dt)
            and np.all(turn <= self.cfg.rest_angular_rad_s * dt)
        )

    def settle(self, max_s: float) -> bool:
        """Step until the pieces are at rest (two still windows of pile.rest_window_s in a
        row) or `max_s` passes; whether they came to rest."""
        every = max(1, int(round(self.cfg.rest_window_s / self.cfg.timestep_s)))
        max_steps = int(round(max_s / self.cfg.timestep_s))
        steps, still, prev = 0, 0, self.poses()
        while steps < max_steps:
            self.step(every)
            steps += every
            now = self.poses()
            still = still + 1 if self._still(prev, now, every * self.cfg.timestep_s) else 0
            if still >= 2:
                return True
            prev = now
        return False

    def park(self, k: int) -> None:
        """Take piece k off the board at once (kinematic, far away); nothing is stepped."""
        body = self.bodies[k]
        body.set_kinematic(True)
        body.set_kinematic_target(_PARK_POSE)
        self.entities[k].set_pose(_PARK_POSE)
        self.removed.add(k)

    def wake_all(self) -> None:
        for k, body in enumerate(self.bodies):
            if k not in self.removed:
                body.wake_up()


# -- generation ------------------------------------------------------------------------------
def _drop_pose(cfg: PileConfig, rng: np.random.Generator, pile_top_m: float) -> np.ndarray:
    """A random pose above the pile: uniform in the drop disc, random yaw and tilt, its lowest
    point a random gap above `pile_top_m`."""
    r = cfg.drop_radius_m * np.sqrt(rng.uniform())
    a = rng.uniform(0.0, 2 * np.pi)
    pose = flat_piece_pose(r * np.cos(a), r * np.sin(a), rng.uniform(0.0, 2 * np.pi))
    tilt_axis_rad = rng.uniform(0.0, 2 * np.pi)
    tilt = quat_from_axis_angle(
        np.array([np.cos(tilt_axis_rad), np.sin(tilt_axis_rad), 0.0]),
        np.deg2rad(rng.uniform(0.0, cfg.drop_tilt_deg)),
    )
    pose[3:] = quat_mul(tilt, pose[3:])
    gap = rng.uniform(*cfg.drop_height_m)
    pose[2] += pile_top_m + gap - piece_points_m(pose)[:, 2].min()
    return pose


def _drop_pile(cfg: PileConfig, n: int, rng: np.random.Generator) -> np.ndarray | str:
    """Drop n pieces one after another, each onto the settled pile; the settled poses, or why
    the attempt failed ("moving", "fell")."""
    world = PileWorld(cfg)
    for _ in range(n):
        tops = [piece_points_m(p)[:, 2].max() for p in world.poses()]
        world.add_piece(_drop_pose(cfg, rng, max(tops, default=0.0)))
        if not world.settle(cfg.settle_max_s):
            return "moving"
    poses = world.poses()
    if not np.all(on_board(poses, cfg.board_size_m)):
        return "fell"
    return poses


def idle_creep_m(spec: PileSpec, cfg: PileConfig) -> np.ndarray:
    """(N,) how far each piece moves in pile.rest_check_s, left alone from the spec's canonical
    start (NaN for removed pieces). A start at rest stays below pile.rest_check_m."""
    world = PileWorld.from_spec(spec, cfg)
    world.step(int(round(cfg.rest_check_s / cfg.timestep_s)))
    return displacement_m(spec.poses[:, :3], world.poses()[:, :3])


def generate_pile(cfg: PileConfig, seed: int) -> PileSpec:
    """A settled pile of n pieces (n drawn from the seed), dropped one after another into the
    drop disc. An attempt is redrawn (next sub-seed) when the pile does not come to rest, a
    piece ends off the board, or its canonical start creeps; the same (cfg, seed) gives
    bit-identical poses. A pile in the benchmark scenes (sim/benchmark.py: Fig. 3.15's games)
    is read from them."""
    key, stored = benchmark.lookup("pile", {"cfg": cfg, "seed": seed})
    if stored is not None:
        return PileSpec(seed=seed, poses=np.array(stored["poses"], dtype=np.float64))
    spec = _generate_pile(cfg, seed)
    value = {"poses": spec.poses.tolist(), "scene_hash": pile_hash(spec)}
    benchmark.remember(key, "pile", "ch3_games", seed, value)
    return spec


def pile_hash(spec: PileSpec) -> str:
    """A pile's name in records: the sha256 of its poses' bytes (16 hex digits)."""
    data = np.ascontiguousarray(spec.poses, dtype=np.float64).tobytes()
    return hashlib.sha256(data).hexdigest()[:16]


def _generate_pile(cfg: PileConfig, seed: int) -> PileSpec:
    n = int(np.random.default_rng(seed).integers(cfg.n_pieces[0], cfg.n_pieces[1] + 1))
    rejected: dict[str, int] = {}
    for attempt in range(cfg.max_attempts):
        result = _drop_pile(cfg, n, np.random.default_rng([seed, attempt]))
        if isinstance(result, str):
            rejected[result] = rejected.get(result, 0) + 1
            continue
        spec = PileSpec(seed=seed, poses=result)
        if np.nanmax(idle_creep_m(spec, cfg)) > cfg.rest_check_m:
            rejected["creeping"] = rejected.get("creeping", 0) + 1
            continue
        return spec
    why = ", ".join(f"{k}: {v}" for k, v in sorted(rejected.items()))
    raise ClutterbenchError(
        f"pile seed {seed}: no pile of {n} pieces at rest on the board in "
        f"{cfg.max_attempts} attempts ({why})"
    )


# -- the slide and its judge -----------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class SlideResult:
    """What a slide did, judged from poses after the remaining pieces settled."""

    target_out: bool
    """The slid piece's whole footprint ended beyond an edge of the board."""
    others_still: bool
    """No other piece moved more than slide.moved_threshold_m or fell off the board."""
    success: bool
    """target_out and others_still (thesis 3.5: removed without the others collapsing)."""
    displacement_m: np.ndarray
    """(N,) centre displacement of every piece from its pose before the slide; NaN for the
    target and for pieces removed before."""
    moved: tuple[int, ...]
    """The other pieces that moved too far or fell off the board."""
    poses_after: np.ndarray
    """(N, 7) poses after settling; the target's row is its pose at the end of its travel
    (just before it was taken out), NaN rows for pieces removed before."""
    steps: int
    """Physics steps of the slide and the settling after it."""


def judge_slide(
    before_poses: np.ndarray,
    after_poses: np.ndarray,
    target: int,
    cfg: SlideConfig,
    board_size_m: tuple[float, float],
    steps: int = 0,
) -> SlideResult:
    """Judge a slide from the poses before it and after it settled (`SlideResult`); pieces
    with NaN poses before (removed earlier) are not judged."""
    others = np.all(np.isfinite(before_poses), axis=1)
    others[target] = False
    disp = displacement_m(before_poses[:, :3], after_poses[:, :3])
    disp[~others] = np.nan
    bad = others & ((disp > cfg.moved_threshold_m) | ~on_board(after_poses, board_size_m))
    footprint = piece_points_m(after_poses[target])[:, :2]
    target_out = beyond_edge(footprint, 0.5 * np.asarray(board_size_m))
    others_still = not bad.any()
    return SlideResult(
        target_out=target_out,
        others_still=others_still,
        success=target_out and others_still,
        displacement_m=disp,
        moved=tuple(int(k) for k in np.nonzero(bad)[0]),
        poses_after=after_poses,
        steps=steps,
    )


def slide(world: PileWorld, piece: int, direction_rad: float, cfg: SlideConfig) -> SlideResult:
    """The finger presses `piece` and slides it off the board (thesis Fig. 3.9): the piece
    turns kinematic and moves horizontally along `direction_rad` (0 = +x, counter-clockwise)
    at slide.speed_m_s, keeping its orientation, until its whole footprint is
    slide.exit_margin_m beyond a board edge; pieces resting on it are dragged by friction.
    Then it is taken out, the others settle, and the judge reads their motion.

    Not modelled: the finger's pressing force. A kinematic piece weighs nothing on what it
    lies on, so a piece underneath the slid one is pushed only where they collide, not
    dragged by friction."""
    if piece in world.removed or not 0 <= piece < world.n:
        raise ValueError(f"piece {piece} is not on the board")
    steps0 = world.steps_taken
    before = world.poses()
    half = 0.5 * np.asarray(world.cfg.board_size_m) + cfg.exit_margin_m
    travel = exit_travel_m(piece_points_m(before[piece])[:, :2], direction_rad, half)
    n_steps = max(1, int(np.ceil(travel / (cfg.speed_m_s * world.cfg.timestep_s))))
    step_m = travel / n_steps * np.array([np.cos(direction_rad), np.sin(direction_rad), 0.0])
    body, start = world.bodies[piece], world.entities[piece].pose
    body.set_kinematic(True)
    for k in range(1, n_steps + 1):
        body.set_kinematic_target(sapien.Pose(np.array(start.p) + k * step_m, start.q))
        world.step()
    exit_pose = world.poses()[piece]
    world.park(piece)
    world.wake_all()
    world.settle(cfg.settle_max_s)
    after = world.poses()
    after[piece] = exit_pose
    return judge_slide(
        before, after, piece, cfg, world.cfg.board_size_m, steps=world.steps_taken - steps0
    )


# -- cameras ---------------------------------------------------------------------------------
def _add_camera(world: PileWorld, cam: PileCameraConfig, name: str):
    assert world.render, "PileWorld must be built with render=True"
    size = cam.image_size
    return add_depth_camera(
        world.scene, name, size, np.deg2rad(cam.fovy_deg), cam.near_m, cam.far_m
    )


def _set_look_at(camera, eye_m: np.ndarray, target_m: np.ndarray) -> None:
    T = np.eye(4)
    T[:3, :3] = look_at_rotation(eye_m, target_m)
    T[:3, 3] = eye_m
    camera.entity.set_pose(sapien.Pose(T))


def _observe(world: PileWorld, camera) -> Observation:
    """Depth (float32 m along the optical axis, 0: nothing hit), instance ids (k + 1 = piece
    k, 0 = board or background) and the OpenCV camera model, as sim/render.py makes them."""
    world.scene.update_render()
    camera.take_picture()
    position = camera.get_picture("Position")  # OpenGL camera frame: depth = -z
    seg = camera.get_picture("Segmentation")[..., 1]  # per-scene entity id
    depth_m = (-position[..., 2]).astype(np.float32)
    depth_m[position[..., 3] >= 1.0] = 0.0  # w >= 1: nothing hit before the far plane
    lut = np.zeros(int(seg.max()) + 1, dtype=np.uint8)
    for k, entity in enumerate(world.entities):
        if entity.per_scene_id < lut.size and k not in world.removed:
            lut[entity.per_scene_id] = k + 1
    T_cam_from_world = np.eye(4)
    T_cam_from_world[:3, :] = camera.get_extrinsic_matrix()  # world -> OpenCV camera
    model = CameraModel(
        K=np.asarray(camera.get_intrinsic_matrix(), dtype=np.float64),
        T_world_from_cam=np.linalg.inv(T_cam_from_world),
    )
    return Observation(depth_m=depth_m, instance=lut[seg], camera=model)


def top_observation(world: PileWorld, cam: PileCameraConfig) -> Observation:
    """The fixed camera pile_camera.top_height_m above the board centre, looking straight down
    (image up = world +y, image right = world +x). Created on the first call with `cam`."""
    if world.top_camera is None:
        world.top_camera = _add_camera(world, cam, "top")
        _set_look_at(world.top_camera, np.array([0.0, 0.0, cam.top_height_m]), np.zeros(3))
    return _observe(world, world.top_camera)


def view_observation(
    world: PileWorld, cam: PileCameraConfig, eye_m: np.ndarray, target_m: np.ndarray
) -> Observation:
    """The arm's movable depth sensor placed at `eye_m` looking at `target_m` (world z up in
    the image; see `look_at_rotation`). One sensor per world, moved for every picture."""
    if world.view_camera is None:
        world.view_camera = _add_camera(world, cam, "view")
    _set_look_at(world.view_camera, np.asarray(eye_m, float), np.asarray(target_m, float))
    return _observe(world, world.view_camera)


def piece_at(obs: Observation, u: int, v: int) -> int | None:
    """The piece seen at pixel column `u`, row `v`; None where the board or nothing is seen."""
    k = int(obs.instance[v, u])
    return None if k == 0 else k - 1
