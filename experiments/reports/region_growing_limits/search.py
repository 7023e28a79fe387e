"""How far can region growing's settings take masks from sensed depth? A record, not a recheck
(its README says what it found): run from the repository root, after `make setup`,

    python experiments/reports/region_growing_limits/search.py      # ~20 min on 2 cores

Scenes: the start scenes 60-179 of dev stream dev_ch6_3_10 at the sim's image size, as
experiments/depth_masks.py draws them (0-59 are that report's measured scenes and are not
read). Images: exact, and the structured_light and d415 presets, seeded as that report seeds
them. Scored as that report scores (a box found by a segment with IoU > 0.5).

1. The committed settings, with and without one structural change, 'holes cut': a pixel with
   no return in a hole of two or more pixels (a shadow, a step's gap, not an isolated
   dropout) is a cut that no link crosses, and takes, at the end, the segment of its
   4-neighbour of nearest fitted depth.
2. A coordinate search from (1) with holes cut: each RegionGrowingParams field below, at the
   two values beside its default, kept where the sum of boxes found over the three kinds of
   image on scenes 60-119 rises; one round.
3. The three settings on scenes 120-179, which chose nothing.

Writes search.json beside this file.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path.cwd()))  # the repository root: experiments/ and params.yaml

from clutterbench.config import load_params  # noqa: E402
from clutterbench.perception import region_growing as rg  # noqa: E402
from clutterbench.perception.sensor_marks import support_weight  # noqa: E402
from experiments import depth_masks as dm  # noqa: E402

OUT = Path(__file__).with_name("search.json")
KINDS = ("exact", "structured_light", "d415")
GRID = {
    "edge_jump_px": (1.2, 2.0),
    "jump_noise_k": (3.5, 7.0),
    "flat_noise_k": (2.0, 4.0),
    "flat_deg": (2.0, 4.5),
    "convex_tol_px": (0.1, 0.5),
    "merge_share": (0.2, 0.45),
    "smooth_noise_k": (2.0, 4.0),
    "patch_plane_k": (1.5, 3.0),
    "hole_weight": (0.0, 0.5),
    "singular_deg": (20.0, 45.0),
    "curvature_k": (1.5, 3.0),
    "normal_noise_deg": (4.0, 7.0),
    "outlier_k": (3.0, 6.0),
    "fragment_windows": (1.0, 3.0),
    "absorb": (0.1, 0.5),
    "max_window_px": (9, 13),
}


def holes(depth: np.ndarray) -> np.ndarray:
    """Pixels with no return in 8-connected holes of two or more pixels."""
    hole = ~(np.isfinite(depth) & (depth > 0)).astype(bool)
    _, comp, stats, _ = cv2.connectedComponentsWithStats(hole.astype(np.uint8), connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= 2
    big[0] = False
    return big[comp]


def fill(labels: np.ndarray, todo: np.ndarray, z: np.ndarray) -> np.ndarray:
    """`todo` pixels take, ring by ring, the label of the 4-neighbour of nearest fitted depth."""
    out = labels.copy()
    out[todo] = 0
    h, w = out.shape
    for _ in range(8):
        ys, xs = np.nonzero(todo & (out == 0))
        if ys.size == 0:
            break
        best, dist = np.zeros(ys.size, np.int32), np.full(ys.size, np.inf)
        for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            yy, xx = np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)
            lab, d = out[yy, xx], np.abs(z[yy, xx] - z[ys, xs])
            take = (lab > 0) & (d < dist)
            best, dist = np.where(take, lab, best), np.where(take, d, dist)
        if not (best > 0).any():
            break
        out[ys, xs] = best
    return out


def segment(obs, roi, p: rg.RegionGrowingParams, cut_holes: bool) -> np.ndarray:
    """rg.segment_regions, step for step, but for the hole cuts when `cut_holes`."""
    if not cut_holes:
        return rg.segment_regions(obs, roi, p, dm.MIN_PIXELS)
    fit = rg.fit_planes(obs, p)
    T = obs.camera.T_world_from_cam
    margin = p.board_margin_m + p.board_noise_k * np.nan_to_num(fit.fit_sigma_m)
    fg = roi.contains(fit.points @ T[:3, :3].T + T[:3, 3], margin) & np.isfinite(fit.flat)
    if not fg.any():
        return np.zeros(fg.shape, dtype=np.int32)
    fx = float(obs.camera.K[0, 0])
    cut = holes(np.asarray(obs.depth_m))
    jumps = []
    for axis in (0, 1):
        a, b = rg._pairs(cut, axis)
        jumps.append(rg._jumps(fit, fx, axis, p) | a | b)
    s = max(p.patch_px, fit.window)
    smooth_deg = max(p.smooth_deg, p.smooth_noise_k * fit.normal_deg)
    plane_m = p.patch_plane_k * np.nan_to_num(fit.sigma_m, nan=1.0)
    patches = rg._supervoxels(fit, fg, s, smooth_deg, plane_m)
    same = [
        ~j & (a == b) for j, (a, b) in zip(jumps, (rg._pairs(patches, 0), rg._pairs(patches, 1)))
    ]
    footprint = np.nan_to_num(fit.points[..., 2]) / fx
    tol_m = p.flat_noise_k * np.nan_to_num(fit.sigma_m) + p.flat_tol_px * footprint
    least = max(1, int(p.absorb * s * s))
    patches = rg._absorb(rg._components(fg & ~cut, *same), fit, jumps, least, tol_m, p.curvature_k)
    sigma = p.flat_noise_k * float(np.nan_to_num(fit.fit_sigma_m)[fg].mean())
    faces = rg._faces(patches, fit, jumps, p.flat_tol_px * np.median(footprint[fg]) + sigma, p)
    pairs = rg._adjacent(faces, jumps, p.merge_share)
    if pairs.size:
        centroid, normal = rg.patch_planes(faces, fit, p.curvature_k)
        near = rg._near_centroids(faces, np.nan_to_num(fit.points), pairs, s)
        tol = p.convex_tol_px * near[..., 2].mean(axis=0) / fx + sigma
        convex = rg.convex_junction(normal[pairs.T], centroid[pairs.T], near, tol, p.singular_deg)
        faces = rg._join(faces, pairs[convex])
    objects = rg._fragments(faces, jumps, int(p.fragment_windows * s * s))
    objects = fill(objects, fg & cut, np.nan_to_num(fit.points[..., 2], nan=1e9))
    return rg._finish(objects, dm.MIN_PIXELS, support_weight(obs.depth_m, p.hole_weight))


def images(views, first: int) -> dict[str, list]:
    """Per kind of image: (observation as sensed, ROI, instance image); the presets seed their
    noise by the image itself, as in depth_masks."""
    out = {}
    for m, kind in enumerate(dm.NOISE_MODELS):
        if kind not in KINDS:
            continue
        out[kind] = []
        for i, (obs, roi) in enumerate(views):
            rng = np.random.default_rng([dm.NOISE_SEED, first + i, m])
            depth = dm.NOISE_MODELS[kind](obs.depth_m, obs.camera, rng)
            out[kind].append((dataclasses.replace(obs, depth_m=depth), roi, obs.instance))
    return out


def found(data, p: rg.RegionGrowingParams, cut_holes: bool) -> dict[str, int]:
    return {
        kind: sum(
            dm.score(segment(o, r, p, cut_holes), inst, o.depth_m)["found"] for o, r, inst in v
        )
        for kind, v in data.items()
    }


def main() -> None:
    started = time.perf_counter()
    views = dm.start_views(load_params("params.yaml"), 180, None)
    tune, hold = images(views[60:120], 60), images(views[120:180], 120)
    visible = {
        name: {k: sum(dm.score(i, i, o.depth_m)["visible"] for o, _, i in v) for k, v in d.items()}
        for name, d in (("60-119", tune), ("120-179", hold))
    }
    base = rg.RegionGrowingParams()
    result = {"visible": visible, "committed": {}, "holes_cut": {}, "search": []}
    result["committed"]["60-119"] = found(tune, base, False)
    result["holes_cut"]["60-119"] = best_found = found(tune, base, True)
    best, total = base, sum(best_found.values())
    for field, values in GRID.items():
        for value in values:
            p = dataclasses.replace(best, **{field: value})
            got = found(tune, p, True)
            kept = sum(got.values()) > total
            result["search"].append({"field": field, "value": value, "found": got, "kept": kept})
            print(field, value, got, "kept" if kept else "", flush=True)
            if kept:
                best, total = p, sum(got.values())
    result["searched"] = {f: getattr(best, f) for f in GRID if getattr(best, f) != getattr(base, f)}
    result["searched_found"] = {"60-119": found(tune, best, True)}
    result["committed"]["120-179"] = found(hold, base, False)
    result["holes_cut"]["120-179"] = found(hold, base, True)
    result["searched_found"]["120-179"] = found(hold, best, True)
    result["minutes"] = (time.perf_counter() - started) / 60
    OUT.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k != "search"}, indent=1))


if __name__ == "__main__":
    main()
