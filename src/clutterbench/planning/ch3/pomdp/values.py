"""Where to look next and whether to slide (thesis 3.4.3, eqs. 3.3, 3.6, 3.7, 3.9-3.12): viewpoint
candidates, the occupancy grid, the values of observing and sliding, and the decision."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import numpy as np

from clutterbench.planning.ch3.pomdp.belief import (
    E_TH_M,
    MAX_CORRESPONDENCE_M,
    MIN_OBSERVED_POINTS,
    belief_mass,
    fit_weight,
    icp_error,
    occluder_cloud,
    seen_cloud,
)
from clutterbench.planning.ch3.pomdp.states import N_STATES, SLIDABLE_STATES
from clutterbench.planning.ch3.pomdp.views import BOARD_CLEARANCE_M, VOXEL_M, EyeView, aim_point

ALPHA, BETA = 0.9, 0.1
"""Weights of uncertainty and visibility in eq. (3.12) (thesis 3.4.3)."""


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
    occluders = occluder_cloud(occluders, voxel_m)
    views = [EyeView(eye_m, aim_point(centre_xy), occluders, voxel_m)]
    predicted = seen_cloud(int(np.argmax(b)), centre_xy, views, voxel_m)
    if len(predicted) < MIN_OBSERVED_POINTS:
        return belief_mass(b)
    w = np.zeros(N_STATES)
    for s in np.flatnonzero(b > 0):
        model = seen_cloud(int(s), centre_xy, views, voxel_m)
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
    occluders = occluder_cloud(occluders, VOXEL_M)
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
