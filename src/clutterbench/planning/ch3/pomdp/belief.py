"""The fit of each state to an observation and the unnormalised belief it scales (thesis eqs.
3.4, 3.5, 3.8)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import open3d as o3d

from clutterbench.planning.ch3.pomdp.states import N_STATES, state_pose
from clutterbench.planning.ch3.pomdp.views import (
    BOARD_CLEARANCE_M,
    VOXEL_M,
    EyeView,
    aim_point,
    voxel_downsample,
)

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


def occluder_cloud(occluders: np.ndarray | None, voxel_m: float) -> np.ndarray | None:
    """The occluders that matter, thinned: the board (below BOARD_CLEARANCE_M) hides nothing
    on it, and a voxel_m cloud is dense enough for the splatted z-buffer."""
    if occluders is None:
        return None
    pts = np.asarray(occluders, np.float64).reshape(-1, 3)
    return voxel_downsample(pts[pts[:, 2] >= BOARD_CLEARANCE_M], voxel_m)


def seen_cloud(s: int, centre_xy, views: Sequence[EyeView], voxel_m: float) -> np.ndarray:
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
    occluders = occluder_cloud(occluders, voxel_m)
    views = [EyeView(e, aim_point(centre_xy), occluders, voxel_m) for e in eyes]
    errors = [
        icp_error(obs, seen_cloud(s, centre_xy, views, voxel_m), max_correspondence_m)
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
