"""Boxes from one observation: each visible box fitted as an oriented box in the shelf frame
(the physics-from-depth planner's scene estimate, planning/ch6/physics_depth.py).

From the depth image, the instance masks and the camera model only (numpy; no simulator):

1. **Points.** Every pixel of box k's mask is back-projected to the shelf frame.
2. **The dominant face.** Per-pixel normals from the depth image (cross product of central
   differences, where the 3x3 neighbourhood is the same box) vote for the face seen best;
   its plane is refined by a least-squares (SVD) fit of its points. Its normal, turned to
   face the camera, is one box axis.
3. **The other two axes.** Every mask point is projected onto that face's plane: a box seen
   along one of its axes projects onto a rectangle, so the minimum-area rectangle around the
   projected points (rotating calipers on their convex hull) gives the two in-plane axes and
   the visible extents along them.
4. **Sizes: the catalogue's nearest box type.** A warehouse robot knows its item types, and
   the face a camera sees from the front gives only two of a box's three sizes: the box is the
   catalogue type and orientation whose two face sizes are nearest the visible extents (a
   catalogue size may exceed a visible extent, which occlusion shortens, but not fall short
   of it), and the hidden depth is that type's third size (also no shorter than the extent
   seen along the face normal, e.g. on a side face). We chose this over "extend to the next
   surface behind": the surface behind a box is hidden by the box itself, so that rule would
   have to guess as well, while the catalogue is what the scenes are drawn from.
5. **Placement.** The box's front face lies on the fitted plane and it extends away from the
   camera. Along an in-plane axis where the catalogue size exceeds the visible extent, the
   box is extended toward the side where something nearer to the camera borders its mask
   (the occluder), or symmetrically when neither side is occluded.

Boxes with fewer than `min_pixels` visible pixels, and boxes not seen at all, are missing
from the estimate: a robot cannot know them.
"""

from __future__ import annotations

import dataclasses
from itertools import permutations

import numpy as np

from clutterbench.observation import Observation
from clutterbench.sim.geometry import matrix_to_quat

FACE_COS = float(np.cos(np.deg2rad(15.0)))
"""A pixel's normal within 15 degrees of a face's normal belongs to that face."""
OCCLUDER_M = 0.005
"""A pixel next to a mask occludes it when its surface is this much nearer than the box's
front plane along its ray."""
SIZE_TOL_M = 0.004
"""A catalogue size may fall this much short of a visible extent (pixel quantization)."""
SIDE_FACE_M = 0.010
"""An extent of at least this along the face normal means a side face is seen."""
SIDE_WEIGHT = 0.03
OCCLUDED_WEIGHT = 0.1
SHORT_PENALTY = 100.0
"""Weight of a catalogue size falling short of a visible extent beyond SIZE_TOL_M."""


@dataclasses.dataclass(frozen=True)
class BoxEstimate:
    """The visible boxes of one observation, fitted as oriented boxes in the shelf frame."""

    ids: tuple[int, ...]
    """World box index of each estimated box (its instance id - 1, from the masks)."""
    sizes_m: np.ndarray
    """(K, 3) extents along each box's local x, y, z (a catalogue type's (D, W, H))."""
    poses: np.ndarray
    """(K, 7) poses [x, y, z, qw, qx, qy, qz] in the shelf frame."""
    types: np.ndarray
    """(K,) catalogue type of each box."""
    visible_m: np.ndarray
    """(K, 3) extents seen: along the face normal, then the two in-plane axes."""
    pixels: np.ndarray
    """(K,) visible pixels of each box."""

    @property
    def n(self) -> int:
        return len(self.ids)

    def index_of(self, box: int) -> int | None:
        """The estimate's index of world box `box`, or None when it is missing."""
        return self.ids.index(box) if box in self.ids else None


def fit_boxes(
    obs: Observation, catalogue_m: np.ndarray, min_pixels: int, face_min_pixels: int = 3
) -> BoxEstimate:
    """Fit every box with at least `min_pixels` visible pixels of `obs` (ids in increasing
    order) to the nearest of the catalogue's types `catalogue_m` ((T, 3) local extents
    (D, W, H), sim.catalog.box_extents_m)."""
    catalogue_m = np.asarray(catalogue_m, dtype=np.float64).reshape(-1, 3)
    pts = obs.camera.depth_to_points(obs.depth_m)
    normals, same = _normals(pts, obs.instance)
    eye = obs.camera.T_world_from_cam[:3, 3]
    counts = np.bincount(obs.instance.ravel(), minlength=256)
    ids, sizes, poses, types, visible, pixels = [], [], [], [], [], []
    for inst in np.flatnonzero(counts[1:] >= min_pixels) + 1:
        mask = obs.instance == inst
        ok = mask & np.isfinite(pts[..., 0])
        if ok.sum() < 3:
            continue
        try:  # a sensed image may defeat a fit (no face, degenerate points): not estimated
            R, extents, lohi = _axes(pts, normals, mask & same, ok, eye, face_min_pixels)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            continue
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(lohi))):
            continue
        occ = _occluder_coords(obs, pts, mask, R, lohi[0, 0], eye)
        ends = _occluded_ends(occ, lohi)
        t, dims = _nearest_type(extents, catalogue_m, ends.any(axis=1))
        centre = _place(R, dims, lohi, ends)
        # local axis j of the catalogue box (D, W, H) is the fitted axis that got size j
        order = np.argsort(dims[1])  # dims[1][i] = which catalogue axis fitted axis i is
        R_local = R[:, order]
        if np.linalg.det(R_local) < 0:
            R_local[:, 0] = -R_local[:, 0]
        ids.append(int(inst) - 1)
        sizes.append(catalogue_m[t])
        poses.append(np.concatenate([centre, matrix_to_quat(R_local)]))
        types.append(t)
        visible.append(extents)
        pixels.append(int(mask.sum()))
    k = len(ids)
    return BoxEstimate(
        ids=tuple(ids),
        sizes_m=np.array(sizes, dtype=np.float64).reshape(k, 3),
        poses=np.array(poses, dtype=np.float64).reshape(k, 7),
        types=np.array(types, dtype=np.int64),
        visible_m=np.array(visible, dtype=np.float64).reshape(k, 3),
        pixels=np.array(pixels, dtype=np.int64),
    )


def _normals(pts: np.ndarray, instance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) unit normals from central differences (NaN at the border) and (H, W) bool:
    the pixel's 3x3 neighbourhood is one box, so its normal is a face's."""
    h, w = instance.shape
    normals = np.full((h, w, 3), np.nan)
    du = pts[1:-1, 2:] - pts[1:-1, :-2]
    dv = pts[2:, 1:-1] - pts[:-2, 1:-1]
    n = np.cross(du, dv)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals[1:-1, 1:-1] = n / norm
    same = np.zeros((h, w), dtype=bool)
    core = instance[1:-1, 1:-1]
    inner = np.ones_like(core, dtype=bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inner &= instance[1 + dy : h - 1 + dy, 1 + dx : w - 1 + dx] == core
    same[1:-1, 1:-1] = inner & (core > 0)
    same &= np.all(np.isfinite(normals), axis=-1)
    return normals, same


def _plane_normal(points: np.ndarray) -> np.ndarray:
    """The least-squares plane normal of (n, 3) points (the smallest singular direction)."""
    centred = points - points.mean(axis=0)
    return np.linalg.svd(centred, full_matrices=False)[2][-1]


def _axes(
    pts: np.ndarray,
    normals: np.ndarray,
    face_px: np.ndarray,
    ok: np.ndarray,
    eye: np.ndarray,
    face_min_pixels: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R: columns = the face normal pointing away from the camera, then the two in-plane
    axes; visible extents along them; (3, 2) lo/hi of the points along each axis)."""
    P = pts[ok]
    N = normals[face_px]
    toward = eye - pts[face_px]
    if len(N) >= face_min_pixels:
        flip = np.sum(N * toward, axis=1) < 0
        N = np.where(flip[:, None], -N, N)
        cand = N[:: max(1, len(N) // 200)]
        votes = (cand @ N.T > FACE_COS).sum(axis=1)
        n1 = cand[int(np.argmax(votes))]
        inliers = pts[face_px][N @ n1 > FACE_COS]
        if len(inliers) >= 3:
            fitted = _plane_normal(inliers)
            if abs(fitted @ n1) > FACE_COS:
                n1 = fitted if fitted @ n1 > 0 else -fitted
    else:  # too few pixels for a normal: the face toward the camera
        n1 = eye - P.mean(axis=0)
        n1 = n1 / np.linalg.norm(n1)
    u = -n1  # into the box, away from the camera
    # the in-plane axes: the minimum-area rectangle of the points projected along u
    seed = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(seed, u)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    xy = np.stack([P @ e1, P @ e2], axis=1)
    angle = _min_area_angle(xy)
    c, s = np.cos(angle), np.sin(angle)
    a = c * e1 + s * e2
    b = np.cross(u, a)
    R = np.stack([u, a, b], axis=1)
    proj = P @ R
    lohi = np.stack([proj.min(axis=0), proj.max(axis=0)], axis=1)
    extents = lohi[:, 1] - lohi[:, 0]
    return R, extents, lohi


def _hull(xy: np.ndarray) -> np.ndarray:
    """Convex hull (monotone chain) of (n, 2) points, counter-clockwise."""
    p = np.unique(np.round(xy, 7), axis=0)
    if len(p) < 3:
        return p
    # Python floats: the same IEEE double products and differences as numpy's scalars, at a
    # fraction of their overhead per point
    pts = p.tolist()

    def half(points):
        out: list[list[float]] = []
        for q in points:
            while len(out) >= 2:
                o, a = out[-2], out[-1]
                if (a[0] - o[0]) * (q[1] - o[1]) - (a[1] - o[1]) * (q[0] - o[0]) > 0:
                    break
                out.pop()
            out.append(q)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _min_area_angle(xy: np.ndarray) -> float:
    """Angle of one side of the minimum-area rectangle around (n, 2) points (rotating
    calipers: one side lies along an edge of the convex hull)."""
    hull = _hull(xy)
    if len(hull) < 3:
        return 0.0
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    best, best_area = 0.0, np.inf
    for ang in angles:
        c, s = np.cos(ang), np.sin(ang)
        r = hull @ np.array([[c, -s], [s, c]])
        area = np.prod(r.max(axis=0) - r.min(axis=0))
        if area < best_area - 1e-12:
            best, best_area = float(ang), area
    return best


def _nearest_type(
    extents: np.ndarray, catalogue_m: np.ndarray, occluded: np.ndarray
) -> tuple[int, tuple[np.ndarray, np.ndarray]]:
    """(catalogue type, (sizes along the fitted axes (u, a, b), the catalogue axis each one
    is)): the type and orientation nearest the visible extents (squared differences), never
    much shorter than any of them. A size longer than an extent that something nearer hides
    at one end (`occluded`, (3,) bool) costs OCCLUDED_WEIGHT as much: occlusion shortens
    extents. The extent along the face normal counts only where a side face shows it (>=
    SIDE_FACE_M), and then little (SIDE_WEIGHT: a side face is seen foreshortened and
    mostly hidden by the boxes beside it); otherwise that size is the type's hidden one."""
    best, best_cost = None, np.inf
    weight = np.where(occluded, OCCLUDED_WEIGHT, 1.0)
    weight[0] = SIDE_WEIGHT if extents[0] >= SIDE_FACE_M else 0.0
    for t, dims in enumerate(catalogue_m):
        for perm in permutations(range(3)):
            c = dims[list(perm)]
            short = np.clip(extents - c - SIZE_TOL_M, 0.0, None)
            longer = np.clip(c - extents, 0.0, None)
            near = np.where(c >= extents, weight * longer**2, (c - extents) ** 2)
            cost = float(np.sum(near) + SHORT_PENALTY * np.sum(short**2))
            if cost < best_cost - 1e-15:
                best, best_cost = (t, (c, np.array(perm))), cost
    assert best is not None
    return best


def _occluded_ends(occ: np.ndarray, lohi: np.ndarray) -> np.ndarray:
    """(3, 2) bool: something nearer borders the box's visible points at the low / high end
    of each fitted axis (row 0, the face normal, never)."""
    ends = np.zeros((3, 2), dtype=bool)
    if not len(occ):
        return ends
    for i in (1, 2):
        lo, hi = lohi[i]
        band = max(0.25 * (hi - lo), 0.005)
        near_lo, near_hi = int(np.sum(occ[:, i] < lo + band)), int(np.sum(occ[:, i] > hi - band))
        ends[i] = (near_lo > near_hi, near_hi > near_lo)
    return ends


def _place(
    R: np.ndarray, dims: tuple[np.ndarray, np.ndarray], lohi: np.ndarray, ends: np.ndarray
) -> np.ndarray:
    """The box's centre: front face on the fitted plane, extending away from the camera;
    along an in-plane axis where the catalogue size exceeds the visible extent, extended
    toward the occluded end (`ends`), or both ways alike when neither end is."""
    size = dims[0]
    centre = np.empty(3)
    centre[0] = lohi[0, 0] + size[0] / 2
    for i in (1, 2):
        lo, hi = lohi[i]
        if size[i] <= hi - lo or ends[i, 0] == ends[i, 1]:
            centre[i] = (lo + hi) / 2
        elif ends[i, 0]:
            centre[i] = hi - size[i] / 2
        else:
            centre[i] = lo + size[i] / 2
    return R @ centre


def _occluder_coords(
    obs: Observation,
    pts: np.ndarray,
    mask: np.ndarray,
    R: np.ndarray,
    front: float,
    eye: np.ndarray,
) -> np.ndarray:
    """(m, 3) fitted-frame coordinates where the rays of the pixels bordering `mask` (2 px)
    meet the box's front plane, for those pixels whose surface lies nearer to the camera than
    that plane (something in front of the box hides it there)."""
    ring = _dilate(mask, 2) & ~mask
    vv, uu = np.nonzero(ring)
    if len(vv) == 0:
        return np.zeros((0, 3))
    u = R[:, 0]
    seen = pts[vv, uu]
    # the ray through each ring pixel, from the eye
    far = obs.camera.pixel_to_world(uu + 0.5, vv + 0.5, np.ones(len(uu)))
    ray = far - eye
    denom = ray @ u
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (front - eye @ u) / denom
    hit = eye + t[:, None] * ray
    d_plane = np.linalg.norm(hit - eye, axis=1)
    d_seen = np.linalg.norm(seen - eye, axis=1)
    nearer = np.isfinite(d_seen) & (d_seen < d_plane - OCCLUDER_M) & (t > 0)
    return hit[nearer] @ R


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    out = mask.copy()
    h, w = mask.shape
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            ys, yd = slice(max(0, dy), h + min(0, dy)), slice(max(0, -dy), h + min(0, -dy))
            xs, xd = slice(max(0, dx), w + min(0, dx)), slice(max(0, -dx), w + min(0, -dx))
            out[yd, xd] |= mask[ys, xs]
    return out
