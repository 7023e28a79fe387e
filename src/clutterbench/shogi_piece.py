"""The Shogi piece of chapter 3 (thesis Fig. 3.6): its CAD model, known to the simulator and
to the robot alike (no SAPIEN here, so `planning/` may use it for its state model clouds).

The piece frame: x across the piece (width), y from the base to the tip (length), z through
its thickness; the origin is the centre of the bounding box, so a piece lying flat on a board
has its origin `PIECE_SIZE_M[2] / 2` above it. The outline is the Shogi pentagon (a straight
base, two sides rising to shoulders, two edges meeting at the tip); the piece tapers from
`PIECE_SIZE_M[2]` thick at the base to `TIP_THICKNESS_M` at the tip, both faces alike.
"""

from __future__ import annotations

import functools

import numpy as np

PIECE_SIZE_M = (0.0520, 0.0525, 0.0155)
"""Width (x), length base to tip (y), thickness at the base (z): thesis 3.5, ~52.0 x 52.5 x
15.5 mm."""
PIECE_MASS_KG = 0.009
"""~9 g of ABS resin (thesis 3.5)."""
TIP_THICKNESS_M = 0.0100
"""Thickness at the tip (the taper of a real piece)."""
SHOULDER_Y_FRACTION = 0.70
"""Where the sides end and the tip edges begin, as a fraction of the length from the base."""
SHOULDER_WIDTH_FRACTION = 0.86
"""Width at the shoulders, as a fraction of the base width."""


@functools.cache
def piece_vertices() -> np.ndarray:
    """(10, 3) vertices of the piece's convex hull in the piece frame (metres): the pentagon
    outline at +z and at -z, thickness interpolated linearly along y."""
    width, length, thick = PIECE_SIZE_M
    y0 = -length / 2
    y_sh = y0 + SHOULDER_Y_FRACTION * length
    outline = [
        (-width / 2, y0),
        (width / 2, y0),
        (SHOULDER_WIDTH_FRACTION * width / 2, y_sh),
        (0.0, length / 2),
        (-SHOULDER_WIDTH_FRACTION * width / 2, y_sh),
    ]
    verts = []
    for sign in (1.0, -1.0):
        for x, y in outline:
            t = (y - y0) / length
            half = (thick + t * (TIP_THICKNESS_M - thick)) / 2
            verts.append((x, y, sign * half))
    v = np.array(verts, dtype=np.float64)
    v.setflags(write=False)
    return v


@functools.cache
def piece_mesh():
    """The piece's convex hull as a trimesh.Trimesh (faces outward)."""
    import trimesh

    return trimesh.convex.convex_hull(piece_vertices())


def piece_surface_points(n: int, seed: int = 0) -> np.ndarray:
    """(n, 3) points spread evenly over the piece's surface, in the piece frame; the same
    points for the same (n, seed)."""
    import trimesh

    pts, _ = trimesh.sample.sample_surface(piece_mesh(), int(n), seed=int(seed))
    return np.asarray(pts, dtype=np.float64)


def piece_volume_m3() -> float:
    return float(piece_mesh().volume)
