"""Object segments from a noisy depth image (the contract of `depth_segmentation.segment_depth`,
made to survive a real sensor: noise growing with depth squared, holes, flying pixels, shadows),
after PCL's region growing and LCCP (Rabbani et al. 2006, Stein et al. 2014): inverse depth is
fitted with planes over a window the measured noise sets, at nine placements per pixel, the
best taken (edge-preserving; flying pixels dropped, holes filled); SLIC supervoxels on the
fitted cloud, split where fitted points jump apart, merge into faces most alike first; faces
merge into objects where their junction is convex (a box's front turning into its top) and they
do not cross, while a concave one (a box resting or leaning on another) stays a cut.

A real sensor's marks (perception/sensor_marks.py, sim/sensor.py's presets): noise correlated
over a block matcher's window hides from neighbours' differences, so it is measured at its span,
and widens the window as fewer independent points would; a pixel with no return (a shadow, a
depth step, dropout) is filled by the fit but counts only hole_weight towards a segment's size,
so slivers of filled holes along depth steps are no objects. Exact depth has neither mark: it is
segmented as it was before them.

Depth cannot separate faces in one plane (the fronts of a flush stack, or of boxes side by side
touching: the seam is narrower than a pixel), nor, as noise widens the tolerances, boxes meeting
with a smaller step or fold (a box leaning a few degrees on another, a stack offset by a
millimetre or two); a face narrower than the window (a thin side seen obliquely) has no clean
normal, and may stand alone or join a neighbour.
"""

from __future__ import annotations

import dataclasses
import heapq
import math

import cv2
import numpy as np

from clutterbench.config import bounded
from clutterbench.observation import Observation
from clutterbench.perception.depth_segmentation import ShelfROI
from clutterbench.perception.sensor_marks import depth_noise, support_weight, window_side


@dataclasses.dataclass(frozen=True)
class RegionGrowingParams:
    board_margin_m: float = bounded(0.002, ge=0.0)
    """Points nearer than this to a face of the shelf ROI (floor, top, sides, back): boards ..."""
    board_noise_k: float = bounded(3.0, ge=0.0)
    """... a margin widened by this many standard deviations of the fitted depth."""
    min_noise_px: float = bounded(0.1, gt=0.0)
    """Least depth noise assumed (pixel footprints: depth / focal length), for flying pixels."""
    normal_noise_deg: float = bounded(5.0, gt=0.0, le=45.0)
    """The plane-fit window is the smallest whose normals err this much at the image's noise ..."""
    corr_max_lag: int = bounded(3, ge=1)
    """... measured white, or correlated over up to this many pixels (sensor_marks.depth_noise;
    scenes 60-119: 4 lets edges and folds lift white noise's ratio below to 1.27) ..."""
    corr_ratio: float = bounded(1.25, gt=1.0)
    """... when the noise between pixels that far apart exceeds their neighbours' by this ratio.
    Scenes 60-119 of dev_ch6_3_10, every image: at most 1.16 for white noise (every model, 64-256
    px), at least 1.33 for d415 at 256 px (correlated over ~2 px): 1.25 parts them ..."""
    max_window_px: int = bounded(11, ge=3)
    """... but no wider than this many pixels."""
    shift_cost: float = bounded(0.3, ge=0.0)
    """An off-centre window must fit better than the centred one by this many noise variances."""
    outlier_k: float = bounded(4.0, gt=0.0)
    """Returns more than this many sigma off their plane (flying pixels) are dropped, refitted."""
    curvature_k: float = bounded(2.0, gt=0.0)
    """A window fits a plane (PCL's curvature test) if its rms residual is under this many sigma."""
    edge_jump_m: float = bounded(0.004, gt=0.0)
    """Neighbouring fitted points farther apart than this may be on two objects ..."""
    edge_jump_px: float = bounded(1.5, gt=1.0)
    """... if also farther than this many footprints, stretched by 1 / sin(incidence) ..."""
    jump_noise_k: float = bounded(5.0, ge=0.0)
    """... and than this many standard deviations of the fitted depth."""
    min_incidence_deg: float = bounded(10.0, gt=0.0, le=90.0)
    """Faces seen more obliquely than this stretch the jump threshold no further."""
    patch_px: int = bounded(3, ge=2)
    """Supervoxels are seeded every this many pixels, or every window side if wider; ..."""
    smooth_deg: float = bounded(4.0, gt=0.0, le=90.0)
    """... a pixel's normal counts as far from a seed's at this angle (PCL's smoothness) ..."""
    smooth_noise_k: float = bounded(3.0, ge=0.0)
    """... or at this many times the normals' expected error, if more, ..."""
    patch_plane_k: float = bounded(2.0, gt=0.0)
    """... and its point as far from the seed's plane at this many sigma of noise."""
    absorb: float = bounded(0.25, ge=0.0)
    """Supervoxel fragments under this share of a seed's cell dissolve into their neighbours."""
    flat_deg: float = bounded(3.0, gt=0.0, le=90.0)
    """Patches are one face if their normals differ less than this (or flat_noise_k errors) ..."""
    flat_tol_px: float = bounded(0.3, ge=0.0)
    """... and each centroid lies within this many footprints of the other's plane ..."""
    flat_noise_k: float = bounded(3.0, ge=0.0)
    """... plus this many sigma of the fitted depth and of the plane's tilt."""
    merge_share: float = bounded(0.3, gt=0.0, le=1.0)
    """Faces meet where at least this share of the links between them crosses no jump ..."""
    convex_tol_px: float = bounded(0.25, ge=0.0)
    """... and one object if each one's part next to the other is this many footprints behind ..."""
    singular_deg: float = bounded(30.0, ge=0.0, le=90.0)
    """... unless they cross: the step between them within this angle of the planes' meeting."""
    fragment_windows: float = bounded(2.0, ge=0.0)
    """Segments under this many supervoxel cells join the neighbour they share most links with."""
    hole_weight: float = bounded(0.25, ge=0.0, le=1.0)
    """A pixel with no return (filled by the fit) counts this much of a measured one towards
    min_pixels. Scenes 60-119 of dev_ch6_3_10, 128 px, structured_light / d415 (steps as
    sim/sensor.py marks them, discontinuities): 1 (as before), 0.5, 0.25, 0 find 349, 349, 348,
    348 / 340 of 375 boxes, with 43 / 100, 34 / 78, 32 / 69, 31 / 65 stray segments; 0.25
    was chosen when every steep slope was a step (0 then found 1 / 2 fewer of 115 at 64 px)."""


@dataclasses.dataclass(frozen=True)
class PlaneFit:
    """Per-pixel local planes (camera frame): fitted points (H, W, 3), unit normals facing the
    camera (NaN: no window fits), `flat` (best window's rms residual / noise: ~1 on a face), the
    noise at the fitted depth and of the fitted depth (m), window side, normal error (deg)."""

    points: np.ndarray
    normals: np.ndarray
    flat: np.ndarray
    sigma_m: np.ndarray
    fit_sigma_m: np.ndarray
    window: int
    normal_deg: float


_PLACEMENTS = ((0, 0), (-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
"""Window centres around a pixel, in window radii: centred, then at each corner or side."""


def _best_planes(w, mask, u, v, m: int, tol: np.ndarray, shift_cost: np.ndarray):
    """Per pixel, the best plane w = a + b u + c v (box-filtered moments) over the placements of
    an m x m window holding it, (value at the pixel, b, c, mean squared residual), NaN where none
    has half its pixels in `mask`; best: least residual, plus the pixel's own residual beyond
    `tol` squared (it keeps its depth), plus `shift_cost` off centre (a face shares a window)."""
    one, wm = mask.astype(np.float64), np.where(mask, w, 0.0)
    terms = (one, u * one, v * one, u * u * one, u * v * one, v * v * one, wm, wm * u, wm * v)
    r, (h, wd) = m // 2, w.shape
    sums = [
        np.pad(cv2.boxFilter(t, -1, (m, m), normalize=False, borderType=cv2.BORDER_CONSTANT), r)
        for t in (*terms, wm * wm)
    ]
    spread = (m * m - 1) / 12.0  # a full window's variance of u (and v)
    best = [np.full(w.shape, np.nan), np.zeros_like(w), np.zeros_like(w), np.full(w.shape, np.inf)]
    best_score = np.full(w.shape, np.inf)
    for dy, dx in _PLACEMENTS:
        y, x = r + dy * r, r + dx * r
        n, su, sv, suu, suv, svv, sw, swu, swv, sww = (a[y : y + h, x : x + wd] for a in sums)
        with np.errstate(invalid="ignore", divide="ignore"):
            mu, mv, mw = su / n, sv / n, sw / n
            cuu, cuv, cvv = suu / n - mu * mu, suv / n - mu * mv, svv / n - mv * mv
            cwu, cwv = swu / n - mw * mu, swv / n - mw * mv
            det = cuu * cvv - cuv * cuv
            b, c = (cwu * cvv - cwv * cuv) / det, (cwv * cuu - cwu * cuv) / det
            res = np.maximum(sww / n - mw * mw - b * cwu - c * cwv, 0.0)
            value = mw + b * (u - mu) + c * (v - mv)
            excess = np.maximum(np.abs(w - value) - tol, 0.0)
            score = res + np.where(mask, excess**2, 0.0) + (shift_cost if dy or dx else 0.0)
            ok = (n >= max(4, m * m // 2)) & (det > (0.5 * spread) ** 2) & (score < best_score)
        for k, val in enumerate((value, b, c, res)):
            best[k] = np.where(ok, val, best[k])
        best_score = np.where(ok, score, best_score)
    return tuple(best)


def fit_planes(obs: Observation, params: RegionGrowingParams) -> PlaneFit:
    """Local planes of the depth, fitted in inverse depth (affine in the pixel coordinates on a
    plane) over the window the noise asks for, refitted without outliers (outlier_k)."""
    depth = np.asarray(obs.depth_m, dtype=np.float64)
    valid = np.isfinite(depth) & (depth > 0)
    inv = np.where(valid, 1.0 / np.where(valid, depth, 1.0), 0.0)
    K, fx, fy = obs.camera.K, obs.camera.K[0, 0], obs.camera.K[1, 1]
    v, u = np.mgrid[0 : inv.shape[0], 0 : inv.shape[1]].astype(np.float64) + 0.5
    u, v = u - K[0, 2], v - K[1, 2]  # from the principal point
    w0 = float(np.median(inv[valid])) if valid.any() else 1.0
    floor_w = params.min_noise_px * w0 / fx
    sigma_w, corr = depth_noise(inv, valid, floor_w, params.corr_max_lag, params.corr_ratio)
    noise_px = max(sigma_w * fx / w0, params.min_noise_px)
    m, normal_deg = window_side(noise_px, params.max_window_px, params.normal_noise_deg, corr)
    # Noise of 1 / depth per pixel: the image's, or the floor (min_noise_px footprints).
    sigma_pix = np.maximum(sigma_w, params.min_noise_px * np.where(valid, inv, w0) / fx)
    tol, shift_cost = params.outlier_k * sigma_pix, params.shift_cost * sigma_pix**2
    value, b, c, res = _best_planes(inv - w0, valid, u, v, m, tol, shift_cost)
    with np.errstate(invalid="ignore"):
        outlier = valid & ~(np.abs(inv - w0 - value) <= tol)
    if outlier.any():
        value, b, c, res = _best_planes(inv - w0, valid & ~outlier, u, v, m, tol, shift_cost)
    w_fit = value + w0
    w_fit[~(w_fit > 0)] = np.nan  # no window, or a plane behind the camera
    q = np.stack([b * fx, c * fy, w_fit - b * u - c * v], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = -q / np.linalg.norm(q, axis=-1, keepdims=True)
        z = 1.0 / w_fit
        points = np.stack([u / fx * z, v / fy * z, z], axis=-1)
        sigma_pix = np.maximum(sigma_w, params.min_noise_px / (z * fx))
        flat = np.sqrt(res) / sigma_pix
    sigma_m = sigma_pix * z * z  # sigma(z) = sigma_w z^2; a fit errs by ~sqrt(7) / m of it
    return PlaneFit(points, normals, flat, sigma_m, sigma_m * np.sqrt(7.0) / m, m, normal_deg)


def _pairs(x: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel and its next neighbour along `axis`: (H - 1, W, ...) or (H, W - 1, ...)."""
    n = x.shape[axis]
    return np.take(x, np.arange(n - 1), axis=axis), np.take(x, np.arange(1, n), axis=axis)


def _jumps(fit: PlaneFit, fx: float, axis: int, params: RegionGrowingParams) -> np.ndarray:
    """Whether neighbours along `axis` jump apart: fitted points farther apart than a footprint
    stretched by the incidence (edge_jump_px), than edge_jump_m and than jump_noise_k sigma of
    the fitted depth; True where either has no fit."""
    p = fit.points
    with np.errstate(invalid="ignore", divide="ignore"):
        rays = p / np.linalg.norm(p, axis=-1, keepdims=True)
        sin_inc = np.nan_to_num(np.abs(np.sum(fit.normals * rays, axis=-1)), nan=1.0)
    sin_inc = np.clip(sin_inc, np.sin(np.deg2rad(params.min_incidence_deg)), 1.0)
    stretch = params.edge_jump_px * p[..., 2] / fx / sin_inc
    limit = np.maximum(
        np.maximum(stretch, params.jump_noise_k * fit.fit_sigma_m), params.edge_jump_m
    )
    (pa, pb), (la, lb) = _pairs(p, axis), _pairs(limit, axis)
    return ~(np.linalg.norm(pb - pa, axis=-1) <= np.maximum(la, lb))


def _components(nodes: np.ndarray, link_v: np.ndarray, link_h: np.ndarray) -> np.ndarray:
    """(H, W) int32 connected components of `nodes` joined by the True links between neighbours
    (link_v: (H - 1, W), link_h: (H, W - 1)), 0 off the nodes; on a doubled grid, pixel (i, j)
    at (2i, 2j) and a link in the cell between two pixels."""
    h, w = nodes.shape
    grid = np.zeros((2 * h - 1, 2 * w - 1), dtype=np.uint8)
    grid[::2, ::2] = nodes
    grid[1::2, ::2] = link_v & nodes[:-1] & nodes[1:]
    grid[::2, 1::2] = link_h & nodes[:, :-1] & nodes[:, 1:]
    _, comp = cv2.connectedComponents(grid, connectivity=4)
    return np.where(nodes, comp[::2, ::2], 0).astype(np.int32)


def _sums(labels: np.ndarray, vals: np.ndarray, n: int, weight=None) -> np.ndarray:
    """(n, D) sums of the rows of `vals` (N, D) by label (N,), optionally weighted."""
    w = 1.0 if weight is None else weight
    return np.stack([np.bincount(labels, w * vals[:, i], n) for i in range(vals.shape[1])], 1)


def _supervoxels(fit: PlaneFit, fg: np.ndarray, s: int, normal_deg: float, plane_m: np.ndarray):
    """(H, W) int32 patches of ~s x s pixels of `fg`: SLIC (Achanta et al. 2012) seeded at each
    cell's flattest pixel, by image distance / s, normal / `normal_deg`, off-plane / `plane_m`."""
    h, w = fg.shape
    gy, gx = -(-h // s), -(-w // s)
    score = np.full((gy * s, gx * s), np.inf)
    score[:h, :w] = np.where(fg, np.nan_to_num(fit.flat, nan=1e9), np.inf)
    blocks = score.reshape(gy, s, gx, s).transpose(0, 2, 1, 3).reshape(gy, gx, s * s)
    best = blocks.argmin(axis=2)
    seeded = np.isfinite(np.take_along_axis(blocks, best[..., None], axis=2)[..., 0])
    cy, cx = np.nonzero(seeded)
    grid = np.full((gy + 2, gx + 2), -1)  # seed index per cell, a border of none
    grid[1:-1, 1:-1][seeded] = np.arange(cy.size)
    seed_px = (cy * s + best[seeded] // s, cx * s + best[seeded] % s)
    pos = np.stack(seed_px, axis=1).astype(np.float64)
    centre, normal = fit.points[seed_px], fit.normals[seed_px]
    ii, jj = np.nonzero(fg)
    pts, nrm, tau = fit.points[ii, jj], fit.normals[ii, jj], plane_m[ii, jj]
    cand = np.stack([grid[ii // s + dy, jj // s + dx] for dy in range(3) for dx in range(3)])
    c, scale_n = np.maximum(cand, 0), 1.0 - np.cos(np.deg2rad(normal_deg))
    for _ in range(3):
        dist = ((ii - pos[c, 0]) ** 2 + (jj - pos[c, 1]) ** 2) / s**2
        dist += (1.0 - np.sum(normal[c] * nrm, axis=-1)) / scale_n
        dist += (np.sum(normal[c] * (pts - centre[c]), axis=-1) / tau) ** 2
        dist[cand < 0] = np.inf
        lab = c[np.argmin(dist, axis=0), np.arange(ii.size)]
        held = (count := np.bincount(lab, minlength=len(pos))) > 0
        for arr, vals in ((pos, np.stack([ii, jj], 1)), (centre, pts), (normal, nrm)):
            arr[held] = (_sums(lab, vals, len(pos)) / np.maximum(count, 1)[:, None])[held]
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    labels = np.zeros(fg.shape, dtype=np.int32)
    labels[ii, jj] = lab + 1
    return labels


def _plane_sums(labels: np.ndarray, fit: PlaneFit, curvature_k: float):
    """Per label (K + 1 rows): the weight, and weighted sums of fitted points and normals, over
    the pixels whose window fits a plane (flat within `curvature_k`) where there are any."""
    flat, k = labels.ravel(), int(labels.max(initial=0))
    weight = (np.nan_to_num(fit.flat, nan=np.inf).ravel() <= curvature_k) + 1e-3
    total = np.maximum(np.bincount(flat, weight, minlength=k + 1), 1e-9)
    pts, nrm = (np.nan_to_num(a.reshape(-1, 3)) for a in (fit.points, fit.normals))
    return total, _sums(flat, pts, k + 1, weight), _sums(flat, nrm, k + 1, weight)


def patch_planes(labels: np.ndarray, fit: PlaneFit, curvature_k: float):
    """(K + 1, 3) centroid and unit normal of each label's pixels (row 0: label 0): means of
    fitted points and normals (_plane_sums)."""
    total, psum, normal = _plane_sums(labels, fit, curvature_k)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return psum / total[:, None], np.nan_to_num(normal)


def _absorb(labels, fit: PlaneFit, jumps, least: int, tol_m: np.ndarray, curvature_k: float):
    """Patches under `least` pixels (SLIC's strays) dissolve: their pixels join, ring by ring, the
    neighbour (across no jump) whose plane passes nearest, within `tol_m`; the rest stay."""
    h, w = labels.shape
    small = np.flatnonzero((np.bincount(labels.ravel()) < least)[labels] & (labels > 0))
    out = labels.ravel().copy()
    out[small] = 0
    centroid, normal = patch_planes(out.reshape(h, w), fit, curvature_k)
    pts, tol = np.nan_to_num(fit.points).reshape(-1, 3), tol_m.ravel()
    free = [
        np.pad(~jumps[0], ((0, 1), (0, 0))).ravel(),
        np.pad(~jumps[1], ((0, 0), (0, 1))).ravel(),
    ]
    for _ in range(max(least, fit.window)):
        idx = small[out[small] == 0]
        best, best_d = np.zeros(idx.size, dtype=out.dtype), tol[idx]
        row, col = idx // w, idx % w
        for axis, step in ((0, -1), (0, 1), (1, -1), (1, 1)):
            r, c = row + step * (axis == 0), col + step * (axis == 1)
            inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
            nb = np.where(inside, r * w + c, 0)
            lab = np.where(
                inside & free[axis][np.minimum(idx, nb) if step < 0 else idx], out[nb], 0
            )
            d = np.abs(np.sum(normal[lab] * (pts[idx] - centroid[lab]), axis=-1))
            take = (lab > 0) & (d <= best_d)
            best, best_d = np.where(take, lab, best), np.where(take, d, best_d)
        if not (best > 0).any():
            break
        out[idx] = best
    out[small[out[small] == 0]] = labels.ravel()[small[out[small] == 0]] + out.max()
    return out.reshape(h, w).astype(np.int32)


def _faces(patches: np.ndarray, fit: PlaneFit, jumps, tol_m: float, p) -> np.ndarray:
    """Patches merged into faces, most alike first, each merge refitting the face's plane. Alike:
    normals within flat_noise_k errors (at least flat_deg), each centroid within `tol_m` plus
    flat_noise_k errors times their distance off the other's plane; errors fall as a face grows."""
    k = int(patches.max(initial=0))
    wsum, psum, nsum = (a.tolist() for a in _plane_sums(patches, fit, p.curvature_k))
    windows = (np.bincount(patches.ravel(), minlength=k + 1) / fit.window**2).tolist()
    err0, min_rad = math.radians(fit.normal_deg), math.radians(p.flat_deg)

    def plane(a: int) -> tuple[list[float], list[float], float]:  # centroid, normal, error
        n, e = math.hypot(*nsum[a]) or 1.0, err0 / math.sqrt(max(windows[a], 1.0))
        return [x / wsum[a] for x in psum[a]], [x / n for x in nsum[a]], e

    def cost(a: int, b: int) -> float:
        (cax, cay, caz), (nax, nay, naz), ea = node[a]
        (cbx, cby, cbz), (nbx, nby, nbz), eb = node[b]
        sx, sy, sz = cbx - cax, cby - cay, cbz - caz
        dist, cos = math.sqrt(sx * sx + sy * sy + sz * sz), nax * nbx + nay * nby + naz * nbz
        return max(
            math.acos(max(-1.0, min(1.0, cos))) / max(min_rad, p.flat_noise_k * math.hypot(ea, eb)),
            abs(nax * sx + nay * sy + naz * sz) / (tol_m + p.flat_noise_k * ea * dist),
            abs(nbx * sx + nby * sy + nbz * sz) / (tol_m + p.flat_noise_k * eb * dist),
        )

    node = [plane(a) for a in range(k + 1)]
    nbrs: list[set[int]] = [set() for _ in range(k + 1)]
    for a, b in _adjacent(patches, jumps).tolist():
        nbrs[a].add(b)
        nbrs[b].add(a)
    version = [0] * (k + 1)
    heap = [(cost(a, b), a, b, 0, 0) for a in range(k + 1) for b in nbrs[a] if a < b]
    heapq.heapify(heap)
    root = list(range(k + 1))
    while heap and heap[0][0] <= 1.0:
        _, a, b, va, vb = heapq.heappop(heap)
        if root[a] != a or root[b] != b or version[a] != va or version[b] != vb:
            continue  # stale: a or b merged or grown since
        root[b], wsum[a], windows[a] = a, wsum[a] + wsum[b], windows[a] + windows[b]
        psum[a], nsum[a] = ([x + y for x, y in zip(t[a], t[b])] for t in (psum, nsum))
        version[a], node[a] = version[a] + 1, plane(a)
        for x in nbrs[b]:
            nbrs[x].discard(b)
            nbrs[x].add(a)
        nbrs[a] = (nbrs[a] | nbrs[b]) - {a, b}
        for x in nbrs[a]:
            heapq.heappush(heap, (cost(a, x), a, x, version[a], version[x]))
    return _join(patches, np.array(list(enumerate(root))))


def convex_junction(normal, centroid, near, tol_m: np.ndarray, singular_deg: float) -> np.ndarray:
    """Whether faces a and b (axis 0: a's, then b's normal, centroid, and `near` centroid of its
    pixels next to the other) meet convexly, by LCCP's tests at the junction: each near part lies
    over `tol_m` behind the other's plane, their step not within `singular_deg` of the crease."""
    (na, nb), (ca, cb), (pa, pb) = normal, centroid, near
    behind = np.maximum(np.sum(na * (pb - ca), -1), np.sum(nb * (pa - cb), -1)) < -tol_m
    with np.errstate(invalid="ignore", divide="ignore"):
        step = pb - pa
        unit = step / np.linalg.norm(step, axis=-1, keepdims=True)
        line = np.cross(na, nb)
        along = np.abs(np.sum(line * unit, -1)) / np.linalg.norm(line, axis=-1)
    return behind & ~(along >= np.cos(np.deg2rad(singular_deg)))


def _links(labels: np.ndarray, jumps) -> list[np.ndarray]:
    """(a, b, 1 where no depth jump) of every link between two different labels > 0."""
    parts = []
    for axis, jump in enumerate(jumps):
        a, b = _pairs(labels, axis)
        sel = (a > 0) & (b > 0) & (a != b)
        parts.append((a[sel], b[sel], ~jump[sel]))
    return [np.concatenate(x).astype(np.int64) for x in zip(*parts)]


def _adjacent(labels: np.ndarray, jumps, share: float = 0.0) -> np.ndarray:
    """(P, 2) labels a < b with a jump-free link (with `share`: two, and that share of all)."""
    a, b, free = _links(labels, jumps)
    n = int(labels.max()) + 1
    keys, at = np.unique(np.minimum(a, b) * n + np.maximum(a, b), return_inverse=True)
    total, good = np.bincount(at), np.bincount(at, weights=free)
    pair = keys[(good >= 1 + (share > 0)) & (good >= share * total)]
    return np.stack([pair // n, pair % n], axis=1)


def _fragments(labels: np.ndarray, jumps, least: int) -> np.ndarray:
    """Segments under `least` pixels join the larger neighbour most linked to them (no jump)."""
    a, b, free = _links(labels, jumps)
    size, n, f = np.bincount(labels.ravel()), int(labels.max()) + 1, free > 0
    keys, count = np.unique(np.concatenate([a[f] * n + b[f], b[f] * n + a[f]]), return_counts=True)
    pick = (size[keys // n] < least) & (size[keys % n] > size[keys // n])
    keys = keys[pick][np.lexsort((-count[pick], keys[pick] // n))]
    keys = keys[np.unique(keys // n, return_index=True)[1]]  # each one's most linked
    return _join(labels, np.stack([keys // n, keys % n], axis=1))


def _near_centroids(labels: np.ndarray, points: np.ndarray, pairs: np.ndarray, reach: int):
    """(2, P, 3): per pair (a, b), the centroid of a's pixels within `reach` of b, then b's of a."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
    near = np.zeros((2, len(pairs), 3))
    for i, pair in enumerate(pairs):
        masks = [(labels == x).astype(np.uint8) for x in pair]
        for side in (0, 1):
            reached = cv2.dilate(masks[1 - side], kernel).astype(bool) & masks[side].astype(bool)
            near[side, i] = points[reached].mean(axis=0)
    return near


def _join(labels: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Labels with every pair in `pairs` made one (union-find), numbered by their least."""
    root = np.arange(int(labels.max(initial=0)) + 1)
    for a, b in pairs.tolist():
        while root[a] != a:
            a = root[a]
        while root[b] != b:
            b = root[b]
        root[max(a, b)] = min(a, b)
    while not np.array_equal(root, root[root]):
        root = root[root]
    return root[labels].astype(np.int32)


def _finish(labels: np.ndarray, min_pixels: int, weight: np.ndarray) -> np.ndarray:
    """Segments of `min_pixels` pixels, each counted by its `weight` (support_weight), with a 2 x 2
    block of their own (no sliver), numbered 1..K in raster order of their first pixel; the rest
    background."""
    n, tl = int(labels.max()) + 1, labels[:-1, :-1]
    block = (tl == labels[1:, :-1]) & (tl == labels[:-1, 1:]) & (tl == labels[1:, 1:])
    keep = np.bincount(tl[block], minlength=n) > 0
    keep &= np.bincount(labels.ravel(), weight.ravel(), minlength=n) >= min_pixels
    keep[0] = False
    flat = np.where(keep[labels], labels, 0).ravel()
    ids, first = np.unique(flat, return_index=True)
    ids, first = ids[ids > 0], first[ids > 0]
    lut = np.zeros(n, dtype=np.int32)
    lut[ids[np.argsort(first)]] = np.arange(1, ids.size + 1, dtype=np.int32)
    return lut[flat.reshape(labels.shape)]


def segment_regions(
    obs: Observation, roi: ShelfROI, params: RegionGrowingParams, min_pixels: int
) -> np.ndarray:
    """(H, W) int32 labels from depth alone, robust to sensor noise: 0 background, 1..K objects in
    raster order of their first pixel; segments under `min_pixels` (a pixel with no return
    counting hole_weight), or one pixel thin, dropped."""
    fit = fit_planes(obs, params)
    T = obs.camera.T_world_from_cam  # objects: fitted points clear of the boards by the margin
    margin = params.board_margin_m + params.board_noise_k * np.nan_to_num(fit.fit_sigma_m)
    fg = roi.contains(fit.points @ T[:3, :3].T + T[:3, 3], margin) & np.isfinite(fit.flat)
    if not fg.any():
        return np.zeros(fg.shape, dtype=np.int32)
    fx = float(obs.camera.K[0, 0])
    jumps = (_jumps(fit, fx, 0, params), _jumps(fit, fx, 1, params))
    s = max(params.patch_px, fit.window)
    smooth_deg = max(params.smooth_deg, params.smooth_noise_k * fit.normal_deg)
    plane_m = params.patch_plane_k * np.nan_to_num(fit.sigma_m, nan=1.0)
    patches = _supervoxels(fit, fg, s, smooth_deg, plane_m)
    # A patch is one piece: split where it jumps; fragments dissolve into their neighbours.
    same = [~j & (a == b) for j, (a, b) in zip(jumps, (_pairs(patches, 0), _pairs(patches, 1)))]
    footprint = np.nan_to_num(fit.points[..., 2]) / fx
    tol_m = params.flat_noise_k * np.nan_to_num(fit.sigma_m) + params.flat_tol_px * footprint
    least = max(1, int(params.absorb * s * s))
    patches = _absorb(_components(fg, *same), fit, jumps, least, tol_m, params.curvature_k)
    sigma = params.flat_noise_k * float(np.nan_to_num(fit.fit_sigma_m)[fg].mean())
    flat_tol = params.flat_tol_px * np.median(footprint[fg]) + sigma
    faces = _faces(patches, fit, jumps, flat_tol, params)
    pairs = _adjacent(faces, jumps, params.merge_share)
    if pairs.size == 0:
        return _finish(faces, min_pixels, support_weight(obs.depth_m, params.hole_weight))
    centroid, normal = patch_planes(faces, fit, params.curvature_k)
    near = _near_centroids(faces, np.nan_to_num(fit.points), pairs, s)
    tol_m = params.convex_tol_px * near[..., 2].mean(axis=0) / fx + sigma
    convex = convex_junction(normal[pairs.T], centroid[pairs.T], near, tol_m, params.singular_deg)
    objects = _join(faces, pairs[convex])
    objects = _fragments(objects, jumps, int(params.fragment_windows * s * s))
    return _finish(objects, min_pixels, support_weight(obs.depth_m, params.hole_weight))
