# SPDX-License-Identifier: GPL-3.0-or-later
"""Quaternion and yaw helpers of the biped planner."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core.biped import quat

angles = st.floats(-3.0, 3.0)


def _random_quats(n: int, seed: int = 0) -> np.ndarray:
    return quat.normalize(np.random.default_rng(seed).normal(size=(n, 4)))


def test_log_exp_round_trip() -> None:
    q = quat.hemisphere(_random_quats(200))
    back = quat.exp(quat.log(q))
    assert np.allclose(quat.hemisphere(back), q, atol=1e-12)


def test_log_is_angle_times_axis() -> None:
    # Appendix A.2.1: log of a rotation by θ about an axis is θ·axis (θ, not θ/2).
    q = quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), 1.2)
    assert np.allclose(quat.log(q), [0.0, 0.0, 1.2])


def test_rotate_matches_matrix() -> None:
    q = _random_quats(50, 1)
    v = np.random.default_rng(2).normal(size=(50, 3))
    assert np.allclose(quat.rotate(q, v), np.einsum("nij,nj->ni", quat.to_matrix(q), v))


def test_matrix_round_trip() -> None:
    q = quat.hemisphere(_random_quats(300, 3))
    assert np.allclose(quat.from_matrix(quat.to_matrix(q)), q, atol=1e-10)


@given(angles, angles, st.floats(0.0, 1.0))
def test_slerp_of_yaws_is_linear_in_angle(a: float, b: float, t: float) -> None:
    q = quat.slerp(quat.from_yaw(a), quat.from_yaw(b), t)
    expected = a + t * quat.wrap_angle(b - a)
    assert abs(quat.wrap_angle(quat.yaw_of(q) - expected)) < 1e-9


def test_from_two_frames_maps_both_directions() -> None:
    rng = np.random.default_rng(4)
    a1, a2 = rng.normal(size=(2, 40, 3))
    r = _random_quats(40, 5)
    b1, b2 = quat.rotate(r, a1), quat.rotate(r, a2)
    found = quat.from_two_frames(a1, a2, b1, b2)
    assert np.allclose(quat.angle_between(found, r), 0.0, atol=1e-6)


@given(angles, angles)
def test_ground_pose_compose_and_relative_are_inverse(ya: float, yb: float) -> None:
    pa, pb = np.array([1.0, -2.0, 0.3]), np.array([0.5, 0.25, 0.1])
    p, y = quat.compose2(pa, ya, pb, yb)
    back_p, back_y = quat.relative2(pa, ya, p, y)
    assert np.allclose(back_p, pb)
    assert abs(quat.wrap_angle(back_y - yb)) < 1e-12
