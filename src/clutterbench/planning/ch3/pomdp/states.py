"""The 32 discrete states of the target piece (thesis 3.4.1): 4 basic poses x 8 yaws."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from clutterbench.shogi_piece import piece_mesh, piece_vertices

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


def check_state(s: int) -> int:
    assert 0 <= int(s) < N_STATES, f"state must be in 0..{N_STATES - 1}, got {s}"
    return int(s)


def state_basic(s: int) -> str:
    """The basic pose of state s: one of BASIC_POSES."""
    return BASIC_POSES[check_state(s) // N_YAWS]


def state_yaw(s: int) -> float:
    """The rotation of state s about the vertical axis, radians (multiples of pi / 4)."""
    return (check_state(s) % N_YAWS) * (2.0 * np.pi / N_YAWS)


def state_rotation(s: int) -> np.ndarray:
    """(3, 3) piece-frame -> world rotation of state s: basic pose, then yaw about world z."""
    s = check_state(s)
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
