"""The ch. 3 POMDP that chooses between observing again and sliding the target (thesis 3.4).

States (3.4.1): the target Shogi piece in one of 4 basic poses x 8 yaws of 45 deg = 32 discrete
states. An observation o_a is the target's observed points; a state's point cloud o_s is the
CAD model (`shogi_piece`) posed in that state and ray-cast from the same eye(s), past the same
occluders, so both clouds are what a depth sensor would return. The fit e(o_s, o_a) is the
mean nearest-neighbour distance between them (both ways) after a small ICP correction; it
gives a weight (eq. 3.5) that scales the belief, which is never normalised (eq. 3.4), so its
mass (eq. 3.8) falls as observations rule states out. Observing at a candidate viewpoint
(3.4.3) is worth alpha V1 + beta V2 (eq. 3.12): the mass it is expected to remove (eqs. 3.9,
3.10) and the share of the workspace grid it would reveal (eq. 3.11); sliding is worth the
belief on the flat states times the reward (eqs. 3.6, 3.7); the larger wins (eq. 3.3).

Frames and units: the chapter 3 world, metres: the board's top surface is z = 0, its centre the
origin, z up. Every point array is (N, 3) float64 in that frame. Cameras are OpenCV frames
(x right, y down, z forward), as in `observation.CameraModel`.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import numpy as np
import open3d as o3d

from clutterbench.shogi_piece import piece_mesh, piece_surface_points, piece_vertices

BASIC_POSES = ("standing", "side", "flat", "leaning")
"""Thesis Fig. 3.7 (a)-(d), in state order: (a) standing on the base edge, wide faces vertical;
(b) standing on a long side edge; (c) lying flat, a wide face on the board; (d) leaning at
45 deg, resting on the base edge (as on another piece)."""
N_YAWS = 8
"""Rotations of 45 deg about the vertical axis per basic pose (thesis Fig. 3.8)."""
N_STATES = len(BASIC_POSES) * N_YAWS
"""|S| = 32 (thesis 3.4.1); state s = basic index * 8 + yaw index."""
SLIDABLE_STATES = tuple(range(2 * N_YAWS, 3 * N_YAWS))
"""S_slide of eq. (3.6): the 8 flat states (thesis 3.5.1: the piece whose wide side touches
the board is the one that slides out)."""
LEAN_DEG = 45.0
"""Inclination of basic pose (d) (thesis 3.4.1)."""

N_MODEL_POINTS = 400
"""Points of `model_cloud` (~4 mm apart on the 66.7 cm^2 piece surface)."""
VIEW_RADIUS_M = 0.056
"""Half-width, at the target, of the ray fan that renders a model view: the piece's ~38 mm
radius plus how far its origin can sit from the aim point (up to ~15 mm)."""
VOXEL_M = 0.003
"""Observed clouds are voxel-downsampled to this before fitting, and model views are rendered
and downsampled at it, so both have one density (and few hundred points: speed)."""
MAX_CORRESPONDENCE_M = 0.01
"""ICP pairs only points closer than this (see `icp_error`)."""
ICP_ITERATIONS = 5
"""ICP iterations per fit (see `icp_error`)."""
MAX_ICP_ROTATION_DEG = 10.0
"""Largest rotation ICP may apply; a larger result is discarded (see `icp_error`)."""
E_TH_M = 0.006
"""Default e_th of eq. (3.5): the fit error at which a state's weight reaches 0. The thesis
gives no value; on ray-cast views (1 mm noise) of every state from the 8 candidate viewpoints,
the true state fits to 1.6 mm (median; 95%: 2.3 mm), or 1.8 (4.7) mm when the piece is 10 deg
and 3 mm off its state; other yaws of the same basic pose to 7.4 mm (5%: 2.4 mm), other
basic poses to 11.8 mm (5%: 6.2 mm). At 6 mm the true state keeps ~0.7 and most other basic
poses get 0."""
MIN_OBSERVED_POINTS = 5
"""An observation with fewer points is no evidence: every weight is 1."""
ALPHA, BETA = 0.9, 0.1
"""Weights of uncertainty and visibility in eq. (3.12) (thesis 3.4.3)."""
PIXEL_M = 0.0025
"""Footprint (at the look-at distance) of a z-buffer pixel used for occlusion by other points."""
SPLAT_PIXELS = 1
"""An occluder point covers (2 k + 1)^2 z-buffer pixels, so ~3 mm clouds leave no holes."""
DEPTH_TOLERANCE_M = 0.003
"""A point is hidden only by occluders nearer to the eye than this margin."""
LOOK_AT_HEIGHT_M = 0.02
"""Height above the target's centre at which model views and occlusion z-buffers aim."""
BOARD_CLEARANCE_M = 0.002
"""Observed points lower than this are the board, not objects, for the occupancy grid."""


# --- states (thesis 3.4.1) -------------------------------------------------------------------


def _rot_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector a onto unit vector b (not antiparallel)."""
    v, c = np.cross(a, b), float(np.dot(a, b))
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def _settle_on_face(R_nominal: np.ndarray) -> np.ndarray:
    """R_nominal tipped by the few degrees that put the hull face nearest to facing down flat
    on the board (the piece tapers and its sides converge, so no face is axis-aligned)."""
    normals_world = piece_mesh().face_normals @ R_nominal.T
    down = np.array([0.0, 0.0, -1.0])
    n = normals_world[np.argmax(normals_world @ down)]
    return _rotation_between(n, down) @ R_nominal


@functools.cache
def _basic_rotations() -> tuple[np.ndarray, ...]:
    """Piece-frame -> world rotation of each basic pose at yaw 0."""
    standing = _settle_on_face(_rot_x(np.pi / 2))  # base (-y face) down, tip up, faces along y
    side = _settle_on_face(_rot_y(-np.pi / 2))  # the -x side down, tip along +y
    flat = _settle_on_face(np.eye(3))  # the -z face down, tip along +y
    leaning = _rot_x(np.deg2rad(LEAN_DEG))  # tip raised 45 deg, on the base edge, no face down
    return standing, side, flat, leaning


def _check_state(s: int) -> int:
    assert 0 <= int(s) < N_STATES, f"state must be in 0..{N_STATES - 1}, got {s}"
    return int(s)


def state_basic(s: int) -> str:
    """The basic pose of state s: one of BASIC_POSES."""
    return BASIC_POSES[_check_state(s) // N_YAWS]


def state_yaw(s: int) -> float:
    """The rotation of state s about the vertical axis, radians (multiples of pi / 4)."""
    return (_check_state(s) % N_YAWS) * (2.0 * np.pi / N_YAWS)


def state_rotation(s: int) -> np.ndarray:
    """(3, 3) piece-frame -> world rotation of state s: basic pose, then yaw about world z."""
    s = _check_state(s)
    return _rot_z(state_yaw(s)) @ _basic_rotations()[s // N_YAWS]


def state_pose(s: int, centre_xy: Sequence[float]) -> np.ndarray:
    """(4, 4) T_world_from_piece of state s resting on the board: its lowest point at z = 0,
    the piece origin (its bounding-box centre) above centre_xy (metres)."""
    R = state_rotation(s)
    T = np.eye(4)
    T[:3, :3] = R
    T[:2, 3] = np.asarray(centre_xy, dtype=np.float64)[:2]
    T[2, 3] = -float((piece_vertices() @ R.T)[:, 2].min())
    return T


@functools.cache
def equivalent_states(s: int) -> tuple[int, ...]:
    """The states with the same posed shape as s (s included): the piece is symmetric under a
    half turn about its base->tip axis (mirror pentagon, faces alike), so standing (a) at yaw
    k and k + 4 coincide; no other pair does (a flat pentagon turned 180 deg is another
    shape)."""
    v = piece_vertices() @ state_rotation(s).T
    same = []
    for t in range(N_STATES):
        u = piece_vertices() @ state_rotation(t).T
        d = np.linalg.norm(v[:, None] - u[None], axis=-1)
        if d.min(axis=1).max() < 1e-9 and d.min(axis=0).max() < 1e-9:
            same.append(t)
    return tuple(same)


# --- model clouds and visibility -------------------------------------------------------------


def model_cloud(s: int, centre_xy: Sequence[float], n: int = N_MODEL_POINTS, seed: int = 0):
    """(n, 3) the piece's CAD surface points posed in state s above centre_xy (metres), all
    round (no viewpoint); the same points for the same (n, seed)."""
    T = state_pose(s, centre_xy)
    return piece_surface_points(n, seed) @ T[:3, :3].T + T[:3, 3]


def look_at_pose(eye_m: Sequence[float], target_m: Sequence[float]) -> np.ndarray:
    """(4, 4) T_world_from_cam of an OpenCV camera at eye_m whose optical axis (z) points at
    target_m, image x horizontal (y down as far as the view allows)."""
    eye, target = np.asarray(eye_m, np.float64), np.asarray(target_m, np.float64)
    z = target - eye
    assert np.linalg.norm(z) > 0, "eye and target coincide"
    z /= np.linalg.norm(z)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    T[:3, 3] = eye
    return T


class _OccluderBuffer:
    """A coarse pinhole z-buffer of occluder points seen from one eye: each occluder writes its
    distance to the eye into (2k+1)^2 pixels of `pixel_m` footprint at the look-at distance."""

    MAX_HALF_WIDTH_PIXELS = 400
    """Occluders further off-axis than this cannot hide anything near the target."""

    def __init__(self, eye, look_at, occluders, pixel_m, splat_pixels, tolerance_m):
        self.eye = np.asarray(eye, np.float64)
        self.R_cam_from_world = look_at_pose(self.eye, look_at)[:3, :3].T
        self.angle = pixel_m / np.linalg.norm(np.asarray(look_at, np.float64) - self.eye)
        self.tol = float(tolerance_m)
        uv, rng, _ = self._project(np.asarray(occluders, np.float64))
        keep = np.all(np.abs(uv) < self.MAX_HALF_WIDTH_PIXELS, axis=1)
        uv, rng = uv[keep], rng[keep]
        self.zbuf = None
        if len(uv) == 0:
            return
        k = int(splat_pixels)
        self.lo = uv.min(axis=0) - k
        self.zbuf = np.full(tuple(uv.max(axis=0) + k - self.lo + 1), np.inf)
        for du in range(-k, k + 1):
            for dv in range(-k, k + 1):
                ij = uv + (du, dv) - self.lo
                np.minimum.at(self.zbuf, (ij[:, 0], ij[:, 1]), rng)

    def _project(self, p: np.ndarray):
        q = (p.reshape(-1, 3) - self.eye) @ self.R_cam_from_world.T
        front = q[:, 2] > 1e-9
        z = np.where(front, q[:, 2], 1.0)
        uv = np.floor(q[:, :2] / z[:, None] / self.angle).astype(np.int64)
        return uv[front], np.linalg.norm(q, axis=1)[front], front

    def hidden(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: behind the eye, or behind an occluder in the same pixel."""
        uv, rng, front = self._project(points)
        hidden = ~front
        if self.zbuf is None or len(uv) == 0:
            return hidden
        ij = uv - self.lo
        inside = np.all((ij >= 0) & (ij < self.zbuf.shape), axis=1)
        nearest = np.full(len(uv), np.inf)
        nearest[inside] = self.zbuf[ij[inside, 0], ij[inside, 1]]
        hidden[np.flatnonzero(front)[nearest < rng - self.tol]] = True
        return hidden


def _spans_3d(points: np.ndarray) -> bool:
    """Whether the points are not all on one plane (else qhull, under hidden point removal,
    fails; such a set hides nothing of itself)."""
    if len(points) < 5:
        return False
    sv = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(sv[2] > 1e-9 * sv[0])


def visible_mask(
    points: np.ndarray,
    eye_m: Sequence[float],
    occluders: np.ndarray | None = None,
    *,
    self_occlusion: bool = True,
    look_at_m: Sequence[float] | None = None,
    pixel_m: float = PIXEL_M,
    splat_pixels: int = SPLAT_PIXELS,
    depth_tolerance_m: float = DEPTH_TOLERANCE_M,
    hpr_radius_factor: float = 100.0,
) -> np.ndarray:
    """(N,) bool: which points an eye at eye_m sees.

    Self-occlusion (`self_occlusion`): open3d's hidden point removal (Katz et al. 2007; radius
    = `hpr_radius_factor` x the cloud's extent); none for points coplanar with the eye.
    Occlusion by other objects: a point is hidden when an `occluders` point falls in the same
    pixel of a pinhole z-buffer aimed at `look_at_m` (default: the points' centroid; each
    occluder covers (2 `splat_pixels` + 1)^2 pixels so a ~3 mm cloud leaves no holes) nearer
    to the eye by over `depth_tolerance_m`.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    eye = np.asarray(eye_m, np.float64)
    mask = np.ones(len(pts), bool)
    if self_occlusion and _spans_3d(np.vstack([pts, eye])):
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        extent = max(float(np.linalg.norm(np.ptp(pts, axis=0))), 1e-6)
        _, idx = pcd.hidden_point_removal(eye, hpr_radius_factor * extent)
        mask[:] = False
        mask[np.asarray(idx, dtype=np.int64)] = True
    if occluders is not None and len(occluders) and mask.any():
        target = pts.mean(axis=0) if look_at_m is None else look_at_m
        buf = _OccluderBuffer(eye, target, occluders, pixel_m, splat_pixels, depth_tolerance_m)
        mask[mask] = ~buf.hidden(pts[mask])
    return mask


def visible_points(points: np.ndarray, eye_m: Sequence[float], occluders=None, **kw):
    """(M, 3) the points an eye at eye_m sees (`visible_mask`, same keywords)."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    return pts[visible_mask(pts, eye_m, occluders, **kw)]


def voxel_downsample(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """(M, 3) one point (the mean) per occupied voxel of edge voxel_m."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    if len(pts) == 0 or voxel_m <= 0:
        return pts
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    return np.asarray(pcd.voxel_down_sample(voxel_m).points)


@functools.cache
def _piece_raycasting_scene() -> o3d.t.geometry.RaycastingScene:
    """The CAD piece, in its own frame, for ray casting."""
    mesh = piece_mesh()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)),
    )
    return scene


def _aim_point(centre_xy: Sequence[float]) -> np.ndarray:
    c = np.asarray(centre_xy, np.float64)
    return np.array([c[0], c[1], LOOK_AT_HEIGHT_M])


class _EyeView:
    """What one eye shares across the views of many poses: a fan of rays (a pinhole camera
    aimed at `look_at_m`, `pixel_m` pixels there, covering VIEW_RADIUS_M around it) and the
    z-buffer of the occluders."""

    def __init__(self, eye_m, look_at_m, occluders, pixel_m: float):
        self.eye = np.asarray(eye_m, np.float64)
        look_at = np.asarray(look_at_m, np.float64)
        R_world_from_cam = look_at_pose(self.eye, look_at)[:3, :3]
        half = int(np.ceil(VIEW_RADIUS_M / pixel_m))
        grid = (np.arange(-half, half) + 0.5) * (pixel_m / np.linalg.norm(look_at - self.eye))
        u, v = np.meshgrid(grid, grid, indexing="ij")
        d_cam = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)
        self.dirs = d_cam / np.linalg.norm(d_cam, axis=1, keepdims=True) @ R_world_from_cam.T
        self.buffer = None
        if occluders is not None and len(occluders):
            self.buffer = _OccluderBuffer(
                self.eye, look_at, occluders, PIXEL_M, SPLAT_PIXELS, DEPTH_TOLERANCE_M
            )

    def see(self, T_world_from_piece: np.ndarray) -> np.ndarray:
        """(M, 3) the first hits of the rays on the piece at this pose, less occluded ones."""
        R, t = T_world_from_piece[:3, :3], T_world_from_piece[:3, 3]
        origin = np.broadcast_to((self.eye - t) @ R, self.dirs.shape)  # rays in the piece frame
        rays = np.concatenate([origin, self.dirs @ R], axis=1).astype(np.float32)
        t_hit = _piece_raycasting_scene().cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        ok = np.isfinite(t_hit)
        pts = self.eye + t_hit[ok, None].astype(np.float64) * self.dirs[ok]
        if self.buffer is not None and len(pts):
            pts = pts[~self.buffer.hidden(pts)]
        return pts


def piece_view(
    T_world_from_piece: np.ndarray,
    eye_m: Sequence[float],
    occluders: np.ndarray | None = None,
    *,
    pixel_m: float = VOXEL_M,
) -> np.ndarray:
    """(M, 3) what a depth sensor at eye_m sees of a piece at any pose: the CAD model ray-cast
    through `pixel_m` pixels (at the piece; the camera aimed at its origin), exact
    self-occlusion, fewer points on faces seen obliquely, less the points that `occluders`
    hide (z-buffer, as in `visible_mask`)."""
    T = np.asarray(T_world_from_piece, np.float64)
    return _EyeView(eye_m, T[:3, 3], occluders, pixel_m).see(T)


def model_view(
    s: int,
    centre_xy: Sequence[float],
    eye_m: Sequence[float],
    occluders: np.ndarray | None = None,
    *,
    pixel_m: float = VOXEL_M,
) -> np.ndarray:
    """(M, 3) o_s as seen from eye_m: `piece_view` of state s's pose above centre_xy, the
    camera aimed LOOK_AT_HEIGHT_M above centre_xy (as every state's view from this eye)."""
    view = _EyeView(eye_m, _aim_point(centre_xy), occluders, pixel_m)
    return view.see(state_pose(_check_state(s), centre_xy))


# --- fit and belief (thesis eqs. 3.4, 3.5, 3.8) ---------------------------------------------


def _rotation_angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def icp_error(
    observed: np.ndarray,
    model: np.ndarray,
    max_correspondence_m: float = MAX_CORRESPONDENCE_M,
    *,
    iterations: int = ICP_ITERATIONS,
    max_rotation_deg: float = MAX_ICP_ROTATION_DEG,
    symmetric: bool = True,
) -> float:
    """e(o_s, o_a), metres: the average distance between the corresponding points of the two
    clouds after a small ICP correction (thesis 3.4.1; ICP [74, 75]).

    ICP: open3d point-to-point, observed -> model, from the identity, `iterations` rounds,
    pairing only points closer than `max_correspondence_m` (1 cm). It only absorbs a small
    misplacement: a result turning more than `max_rotation_deg` (10 deg, well under the 45 deg
    between neighbouring yaws) or moving the observed centroid more than `max_correspondence_m`
    is dropped for the identity, so a wrong state stays wrong. Then every point is paired with
    its nearest neighbour in the other cloud, unpaired-by-ICP ones included (the outliers are
    what tells a wrong state): the mean of observed -> model and (`symmetric`) model ->
    observed distances, so a state is charged both for what was seen where it has no surface
    and for surface it shows the eye that was not seen. inf when either cloud is empty or no
    observed point lies within `max_correspondence_m` of the model.
    """
    obs = np.asarray(observed, np.float64).reshape(-1, 3)
    mod = np.asarray(model, np.float64).reshape(-1, 3)
    if len(obs) == 0 or len(mod) == 0:
        return float("inf")
    # about the observed centroid, so T's rotation does not turn into a translation
    c = obs.mean(axis=0)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(obs - c))
    dst = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(mod - c))
    result = o3d.pipelines.registration.registration_icp(
        src,
        dst,
        max_correspondence_m,
        np.eye(4),
        o3d.pipelines.registration.TransformationEstimationPointToPoint(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=int(iterations)),
    )
    T = np.asarray(result.transformation)
    small = (
        _rotation_angle_deg(T[:3, :3]) <= max_rotation_deg
        and np.linalg.norm(T[:3, 3]) <= max_correspondence_m
    )
    if small and result.fitness > 0:
        src.transform(T)
    d_obs = np.asarray(src.compute_point_cloud_distance(dst))
    if not np.any(d_obs < max_correspondence_m):
        return float("inf")
    if not symmetric:
        return float(d_obs.mean())
    d_mod = np.asarray(dst.compute_point_cloud_distance(src))
    return 0.5 * float(d_obs.mean() + d_mod.mean())


def fit_weight(error_m, e_th_m: float):
    """omega = 1 - min(e / e_th, 1): 1 for a perfect fit, 0 at or beyond e_th."""
    assert e_th_m > 0, "e_th must be a positive distance in metres"
    return 1.0 - np.minimum(np.asarray(error_m, np.float64) / e_th_m, 1.0)  # thesis eq. (3.5)


def uniform_belief() -> np.ndarray:
    """(32,) b(s_i) = 1/32: the initial belief (thesis 3.4.1)."""
    return np.full(N_STATES, 1.0 / N_STATES)


def update_belief(belief: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """b'(s) = omega(o_s, o_a) b(s), not normalised, as the thesis writes it, so the mass falls
    with every state an observation rules out."""
    b, w = np.asarray(belief, np.float64), np.asarray(weights, np.float64)
    assert b.shape == w.shape == (N_STATES,), "belief and weights must be (32,)"
    assert np.all((w >= 0) & (w <= 1)), "weights must be in [0, 1]"
    return w * b  # thesis eq. (3.4)


def belief_mass(belief: np.ndarray) -> float:
    """M = sum_s b(s): the uncertainty left (1 at the start; small once states are ruled out)."""
    return float(np.sum(belief))  # thesis eq. (3.8)


def _occluder_cloud(occluders: np.ndarray | None, voxel_m: float) -> np.ndarray | None:
    """The occluders that matter, thinned: the board (below BOARD_CLEARANCE_M) hides nothing
    on it, and a voxel_m cloud is dense enough for the splatted z-buffer."""
    if occluders is None:
        return None
    pts = np.asarray(occluders, np.float64).reshape(-1, 3)
    return voxel_downsample(pts[pts[:, 2] >= BOARD_CLEARANCE_M], voxel_m)


def _seen(s: int, centre_xy, views: Sequence[_EyeView], voxel_m: float) -> np.ndarray:
    """o_s seen from every eye (union), voxel-downsampled like an observation."""
    T = state_pose(s, centre_xy)
    return voxel_downsample(np.concatenate([v.see(T) for v in views], axis=0), voxel_m)


def state_errors(
    observed: np.ndarray,
    centre_xy: Sequence[float],
    *,
    eye_m: np.ndarray,
    occluders: np.ndarray | None = None,
    voxel_m: float = VOXEL_M,
    max_correspondence_m: float = MAX_CORRESPONDENCE_M,
) -> np.ndarray:
    """(32,) e(o_s, o_a) of every state for the observed target points (metres).

    o_a: `observed` voxel-downsampled to `voxel_m`. o_s: `model_view` from each eye in `eye_m`
    ((3,) or (k, 3): where o_a was seen from) past `occluders` (the other objects' observed
    points; any below BOARD_CLEARANCE_M, the board, are dropped), joined and downsampled
    alike. `centre_xy` must be within ~1 cm of the piece's true centre (ICP's reach).
    """
    obs = voxel_downsample(observed, voxel_m)
    eyes = np.asarray(eye_m, np.float64).reshape(-1, 3)
    occluders = _occluder_cloud(occluders, voxel_m)
    views = [_EyeView(e, _aim_point(centre_xy), occluders, voxel_m) for e in eyes]
    errors = [
        icp_error(obs, _seen(s, centre_xy, views, voxel_m), max_correspondence_m)
        for s in range(N_STATES)
    ]
    return np.array(errors)


def state_weights(
    observed: np.ndarray, centre_xy: Sequence[float], e_th_m: float = E_TH_M, **kw
) -> np.ndarray:
    """(32,) omega(o_s, o_a) of every state: eq. (3.5) on `state_errors` (same keywords:
    `eye_m` required, `occluders`, ...); all 1 when fewer than MIN_OBSERVED_POINTS were
    observed (no evidence, no update)."""
    if len(np.asarray(observed).reshape(-1, 3)) < MIN_OBSERVED_POINTS:
        return np.ones(N_STATES)
    return fit_weight(state_errors(observed, centre_xy, **kw), e_th_m)


# --- viewpoints (thesis 3.4.3, Fig. 3.10) ----------------------------------------------------


@functools.cache
def _icosahedron_face_normals() -> np.ndarray:
    """(20, 3) unit normals of the faces of the regular icosahedron with vertices
    (0, +-1, +-phi) and cyclic permutations: the directions of a dodecahedron's vertices."""
    phi = (1.0 + 5**0.5) / 2.0
    cube = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    rest = []
    for a in (-1 / phi, 1 / phi):
        for b in (-phi, phi):
            rest += [(0.0, a, b), (a, b, 0.0), (b, 0.0, a)]
    d = np.array(cube + rest, dtype=np.float64)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def viewpoint_candidates(
    centre_m: Sequence[float], distances_m: Sequence[float], min_elevation_deg: float
) -> np.ndarray:
    """(K, 3) candidate eye positions (thesis Fig. 3.10): on the 20 lines from centre_m through
    the faces of a regular icosahedron centred there, at each distance, keeping those at least
    `min_elevation_deg` above the board plane (with 0 < min <= 20.9: 8 lines, elevations 20.9,
    35.3 and 69.1 deg). Each looks at centre_m (`look_at_pose`). Ordered by distance, then
    elevation (high first), then azimuth."""
    centre = np.asarray(centre_m, np.float64)
    dirs = _icosahedron_face_normals()
    elev = np.degrees(np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0)))
    keep = (elev >= min_elevation_deg - 1e-9) & (elev > 0)
    dirs, elev = dirs[keep], elev[keep]
    azim = np.mod(np.arctan2(dirs[:, 1], dirs[:, 0]), 2 * np.pi)
    order = np.lexsort((np.round(azim, 9), -np.round(elev, 9)))
    dirs = dirs[order]
    eyes = [centre + float(r) * dirs for r in sorted(float(r) for r in distances_m)]
    return np.concatenate(eyes, axis=0) if eyes else np.zeros((0, 3))


# --- occupancy grid (thesis 3.4.3, eq. 3.11) -------------------------------------------------


@dataclasses.dataclass(frozen=True)
class OccupancyGrid:
    """The workspace around the target, in cubic cells (thesis 3.4.3, after [49, 77])."""

    origin_m: np.ndarray
    """(3,) world corner of cell (0, 0, 0) (its lowest x, y, z)."""
    cell_m: float
    """Edge of a cell, metres."""
    occupied: np.ndarray
    """(nx, ny, nz) bool: a cell holding an observed point."""
    occluded: np.ndarray
    """(nx, ny, nz) bool: not occupied and hidden behind occupied cells from every eye that
    has observed the scene (unknown space)."""

    def centres(self) -> np.ndarray:
        """(nx, ny, nz, 3) world centre of every cell."""
        idx = np.stack(np.indices(self.occupied.shape), axis=-1)
        return self.origin_m + (idx + 0.5) * self.cell_m


def visible_cells(
    grid: OccupancyGrid, eye_m: Sequence[float], cells: np.ndarray | None = None
) -> np.ndarray:
    """(nx, ny, nz) bool: cells whose centre the eye sees, i.e. the segment from the centre
    towards the eye (sampled every half cell, from 3/4 of a cell out, within the grid) meets
    no occupied cell. An occupied cell is visible when nothing occupied is in front of it.
    Only the cells in the `cells` mask (default: all) are traced; the others read False."""
    shape = np.array(grid.occupied.shape)
    todo = np.ones(grid.occupied.shape, bool) if cells is None else np.asarray(cells, bool)
    centres = grid.centres()[todo]
    to_eye = np.asarray(eye_m, np.float64) - centres
    dist = np.linalg.norm(to_eye, axis=1)
    step = 0.5 * grid.cell_m
    t = np.arange(1.5 * step, float(np.linalg.norm(shape * grid.cell_m)) + step, step)
    p = centres[:, None, :] + (t[None, :, None] * (to_eye / dist[:, None])[:, None, :])
    ijk = np.floor((p - grid.origin_m) / grid.cell_m).astype(np.int64)
    inside = np.all((ijk >= 0) & (ijk < shape), axis=2) & (t[None, :] < dist[:, None])
    ijk = np.where(inside[..., None], ijk, 0)
    hit = inside & grid.occupied[ijk[..., 0], ijk[..., 1], ijk[..., 2]]
    seen = np.zeros(grid.occupied.shape, bool)
    seen[todo] = ~hit.any(axis=1)
    return seen


def occupancy_grid(
    scene_points: np.ndarray,
    eyes_m: np.ndarray,
    centre_xy: Sequence[float],
    size_m: Sequence[float] = (0.16, 0.16, 0.08),
    cell_m: float = 0.01,
) -> OccupancyGrid:
    """The grid of a box `size_m` (x, y, z) standing on the board, centred on centre_xy: cells
    with an observed point (every object, the target included; the board's own points, below
    BOARD_CLEARANCE_M, left out) are Occupied; free cells that no eye in `eyes_m` ((3,) or
    (k, 3): the viewpoints observed so far) sees are Occluded."""
    size = np.asarray(size_m, np.float64)
    dims = np.maximum(np.round(size / cell_m).astype(np.int64), 1)
    c = np.asarray(centre_xy, np.float64)
    origin = np.array([c[0] - dims[0] * cell_m / 2, c[1] - dims[1] * cell_m / 2, 0.0])
    pts = np.asarray(scene_points, np.float64).reshape(-1, 3)
    pts = pts[pts[:, 2] >= BOARD_CLEARANCE_M]
    ijk = np.floor((pts - origin) / cell_m).astype(np.int64)
    ijk = ijk[np.all((ijk >= 0) & (ijk < dims), axis=1)]
    occupied = np.zeros(tuple(dims), bool)
    occupied[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = True
    grid = OccupancyGrid(origin, float(cell_m), occupied, np.zeros_like(occupied))
    seen = np.zeros_like(occupied)
    for eye in np.asarray(eyes_m, np.float64).reshape(-1, 3):
        seen |= visible_cells(grid, eye, cells=~occupied & ~seen)
    return dataclasses.replace(grid, occluded=~occupied & ~seen)


def visibility_value(grid: OccupancyGrid, eye_m: Sequence[float]) -> float:
    """V2(a') = n_occ / N_grid (thesis eq. 3.11), read as: n_occ = the currently Occluded cells
    (unknown space behind what was seen) whose centre the new eye would see past the Occupied
    cells, N_grid = all cells of the grid. So V2 is the share of the workspace a viewpoint
    would reveal ("the viewpoint that provides the largest area of point clouds")."""
    n_occ = int(np.count_nonzero(visible_cells(grid, eye_m, cells=grid.occluded)))
    return n_occ / grid.occupied.size  # thesis eq. (3.11)


# --- values and the decision (thesis eqs. 3.3, 3.6, 3.7, 3.9, 3.10, 3.12) -------------------


def expected_mass_after(
    belief: np.ndarray,
    eye_m: Sequence[float],
    centre_xy: Sequence[float],
    occluders: np.ndarray | None = None,
    e_th_m: float = E_TH_M,
    *,
    voxel_m: float = VOXEL_M,
    max_correspondence_m: float = MAX_CORRESPONDENCE_M,
) -> float:
    """M(o_a') = sum_s omega(o_s, o_a') b(s) for a viewpoint not yet visited (thesis eq. 3.9).

    The observation o_a' is predicted from the most likely state s* = argmax b: its
    `model_view` from the eye past `occluders` (the rest of the observed scene). Each state's
    o_s is seen the same way, so s* (and its symmetric equivalents) keep weight 1 and V1 counts
    the mass of the states this view would tell from s*. States with b(s) = 0 are skipped. A
    view that would show fewer than MIN_OBSERVED_POINTS of s* is no evidence: M(o_a') = M(o_a).
    """
    b = np.asarray(belief, np.float64)
    occluders = _occluder_cloud(occluders, voxel_m)
    views = [_EyeView(eye_m, _aim_point(centre_xy), occluders, voxel_m)]
    predicted = _seen(int(np.argmax(b)), centre_xy, views, voxel_m)
    if len(predicted) < MIN_OBSERVED_POINTS:
        return belief_mass(b)
    w = np.zeros(N_STATES)
    for s in np.flatnonzero(b > 0):
        model = _seen(int(s), centre_xy, views, voxel_m)
        w[s] = fit_weight(icp_error(predicted, model, max_correspondence_m), e_th_m)
    return float(np.sum(w * b))  # thesis eq. (3.9)


def uncertainty_reduction(belief: np.ndarray, eye_m, centre_xy, occluders=None, **kw) -> float:
    """V1(a') = M(o_a) - M(o_a') (thesis eq. 3.10): the belief mass a viewpoint is expected to
    rule out (`expected_mass_after`, same keywords)."""
    m_after = expected_mass_after(belief, eye_m, centre_xy, occluders, **kw)
    return belief_mass(belief) - m_after  # thesis eq. (3.10)


def observation_value(v1: float, v2: float, alpha: float = ALPHA, beta: float = BETA) -> float:
    """V(a') = alpha V1 + beta V2 of an observing action."""
    return alpha * v1 + beta * v2  # thesis eq. (3.12)


def slide_value(belief: np.ndarray, reward: float) -> float:
    """V(a) = sum_s b(s) R(s, a) with R = reward on S_slide (the flat states), 0 elsewhere."""
    b = np.asarray(belief, np.float64)
    assert b.shape == (N_STATES,), "belief must be (32,)"
    R = np.zeros(N_STATES)
    R[list(SLIDABLE_STATES)] = reward  # thesis eq. (3.6)
    return float(np.sum(b * R))  # thesis eq. (3.7)


@dataclasses.dataclass(frozen=True)
class Decision:
    """The action of eq. (3.3) and the values it was chosen from."""

    kind: str
    """"observe" (move the sensor to `viewpoint`) or "slide" (slide the target out)."""
    viewpoint: int | None
    """Index into the viewpoint candidates when observing, else None."""
    slide_value: float
    """V of sliding, eq. (3.7)."""
    observe_values: tuple[float, ...]
    """V(a') of each candidate viewpoint, eq. (3.12)."""
    uncertainty_reductions: tuple[float, ...]
    """V1(a') of each candidate viewpoint, eq. (3.10)."""
    visibility_values: tuple[float, ...]
    """V2(a') of each candidate viewpoint, eq. (3.11)."""
    belief_mass: float
    """M(o_a) of the belief decided on, eq. (3.8)."""
    most_likely_state: int
    """argmax b, the state the predicted observations come from."""


def decide(
    belief: np.ndarray,
    viewpoints_m: np.ndarray,
    centre_xy: Sequence[float],
    grid: OccupancyGrid,
    occluders: np.ndarray | None = None,
    *,
    reward: float,
    alpha: float = ALPHA,
    beta: float = BETA,
    e_th_m: float = E_TH_M,
) -> Decision:
    """a = argmax over {observe at each viewpoint, slide} of V(a) (thesis eq. 3.3): observe at
    the best viewpoint when its value is strictly above the slide value, else slide.

    Note the scales: V1 and the slide value shrink with the (unnormalised) belief mass, V2
    does not, so `reward` is relative to the visibility term as the mass falls."""
    b = np.asarray(belief, np.float64)
    eyes = np.asarray(viewpoints_m, np.float64).reshape(-1, 3)
    occluders = _occluder_cloud(occluders, VOXEL_M)
    v1 = [uncertainty_reduction(b, eye, centre_xy, occluders, e_th_m=e_th_m) for eye in eyes]
    v2 = [visibility_value(grid, eye) for eye in eyes]
    values = [observation_value(a, c, alpha, beta) for a, c in zip(v1, v2)]
    v_slide = slide_value(b, reward)
    best = int(np.argmax(values)) if values else None
    observe = best is not None and values[best] > v_slide  # thesis eq. (3.3)
    return Decision(
        kind="observe" if observe else "slide",
        viewpoint=best if observe else None,
        slide_value=v_slide,
        observe_values=tuple(float(v) for v in values),
        uncertainty_reductions=tuple(float(v) for v in v1),
        visibility_values=tuple(float(v) for v in v2),
        belief_mass=belief_mass(b),
        most_likely_state=int(np.argmax(b)),
    )
