"""Pose helpers: a rotation matrix back to its quaternion (the box fit's poses and the MCAP's
camera frame both come from it)."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.sim.geometry import matrix_to_quat, quat_from_axis_angle, quat_to_matrix


@pytest.mark.parametrize(
    ("axis", "angle_deg"),
    [
        ((0, 0, 1), 10),  # trace > 0
        ((1, 0, 0), 179),  # the largest diagonal entry in x, y, z in turn
        ((0, 1, 0), 179),
        ((0, 0, 1), 179),
        ((1, 2, 0.5), 200),  # trace < 0 and w < 0 as computed: flipped
    ],
)
def test_matrix_to_quat_inverts_quat_to_matrix_with_w_not_negative(axis, angle_deg):
    q = quat_from_axis_angle(np.array(axis, float), np.deg2rad(angle_deg))
    R = quat_to_matrix(q)
    back = matrix_to_quat(R)
    assert back[0] >= 0 and np.isclose(np.linalg.norm(back), 1.0)
    assert np.allclose(quat_to_matrix(back), R, atol=1e-12)
    assert np.allclose(back, q if q[0] >= 0 else -q, atol=1e-12)
