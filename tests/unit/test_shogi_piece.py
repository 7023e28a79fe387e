"""The Shogi piece CAD model (thesis Fig. 3.6): a convex, tapered pentagon of the thesis'
size, with deterministic surface samples."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from clutterbench.shogi_piece import (
    PIECE_SIZE_M,
    TIP_THICKNESS_M,
    piece_mesh,
    piece_surface_points,
    piece_vertices,
)


def test_hull_is_convex_and_every_vertex_is_a_corner():
    v = piece_vertices()
    assert v.shape == (10, 3) and v.dtype == np.float64
    assert sorted(ConvexHull(v).vertices.tolist()) == list(range(10))
    mesh = piece_mesh()
    assert mesh.is_convex and mesh.is_watertight and mesh.volume > 0


def test_bounding_box_is_the_piece_size_centred_on_the_origin():
    v = piece_vertices()
    assert np.ptp(v, axis=0) == pytest.approx(PIECE_SIZE_M, abs=1e-12)
    assert (v.min(axis=0) + v.max(axis=0)) == pytest.approx(np.zeros(3), abs=1e-12)


def test_tapered_thinner_at_the_tip():
    v = piece_vertices()
    base = v[np.isclose(v[:, 1], v[:, 1].min())]
    tip = v[np.isclose(v[:, 1], v[:, 1].max())]
    assert np.ptp(base[:, 2]) == pytest.approx(PIECE_SIZE_M[2])
    assert np.ptp(tip[:, 2]) == pytest.approx(TIP_THICKNESS_M)
    assert TIP_THICKNESS_M < PIECE_SIZE_M[2]
    # the tip is a single edge on the centre line; the base is as wide as the piece
    assert np.allclose(tip[:, 0], 0.0) and np.ptp(base[:, 0]) == pytest.approx(PIECE_SIZE_M[0])


def test_surface_points_are_deterministic_and_on_the_surface():
    a, b = piece_surface_points(300, seed=3), piece_surface_points(300, seed=3)
    assert a.shape == (300, 3) and np.array_equal(a, b)
    assert not np.array_equal(a, piece_surface_points(300, seed=4))
    dist = ConvexHull(piece_vertices()).equations @ np.c_[a, np.ones(len(a))].T  # (faces, n)
    assert np.abs(dist.max(axis=0)).max() < 1e-9  # each on a face, none outside
