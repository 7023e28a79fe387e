"""What a depth sensor sees of the piece: model clouds posed in a state and ray-cast from an
eye past occluders, and the observed cloud (thesis 3.4.2)."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
import open3d as o3d

from clutterbench.planning.ch3.pomdp.states import check_state, state_pose
from clutterbench.shogi_piece import piece_mesh, piece_surface_points

N_MODEL_POINTS = 400
"""Points of `model_cloud` (~4 mm apart on the 66.7 cm^2 piece surface)."""
VIEW_RADIUS_M = 0.056
"""Half-width, at the target, of the ray fan that renders a model view: the piece's ~38 mm
radius plus how far its origin can sit from the aim point (up to ~15 mm)."""
VOXEL_M = 0.003
"""Observed clouds are voxel-downsampled to this before fitting, and model views are rendered
and downsampled at it, so both have one density (and few hundred points: speed)."""
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


def aim_point(centre_xy: Sequence[float]) -> np.ndarray:
    c = np.asarray(centre_xy, np.float64)
    return np.array([c[0], c[1], LOOK_AT_HEIGHT_M])


class EyeView:
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
    return EyeView(eye_m, T[:3, 3], occluders, pixel_m).see(T)


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
    view = EyeView(eye_m, aim_point(centre_xy), occluders, pixel_m)
    return view.see(state_pose(check_state(s), centre_xy))
