# SPDX-License-Identifier: GPL-3.0-or-later
"""Vectorised quaternion and yaw helpers for the biped planner.

Quaternions are ``(..., 4)`` arrays in ``(w, x, y, z)`` order (Blender's order), unit
length, acting on column vectors: ``rotate(q, v) = q v q⁻¹``. Every function broadcasts
over leading axes, so one call handles all frames (and all joints) at once.

The logarithm follows the biped thesis' appendix A.2.1: ``log(q)`` is the rotation vector
``θ·axis`` (θ the rotation angle, not θ/2), and ``exp`` is its inverse.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..geometry import wrap_angle

FloatArray = NDArray[np.float64]

_EPS = 1e-12


def identity(shape: tuple[int, ...] = ()) -> FloatArray:
    """Identity quaternions of the given leading shape: ``(*shape, 4)``."""
    q = np.zeros((*shape, 4))
    q[..., 0] = 1.0
    return q


def normalize(q: FloatArray) -> FloatArray:
    """Unit quaternions; a zero quaternion becomes the identity."""
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.where(n > _EPS, q / np.maximum(n, _EPS), 0.0)
    out[..., 0] = np.where(n[..., 0] > _EPS, out[..., 0], 1.0)
    return out


def conj(q: FloatArray) -> FloatArray:
    """Conjugate, the inverse of a unit quaternion."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def mul(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product ``a b`` (apply ``b`` first, then ``a``)."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        axis=-1,
    )


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    # np.cross spends most of its time moving axes around for small arrays.
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-1)


def rotate(q: FloatArray, v: FloatArray) -> FloatArray:
    """Rotate vectors ``v`` (``(..., 3)``) by unit quaternions ``q``."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def from_axis_angle(axis: FloatArray, angle: FloatArray | float) -> FloatArray:
    """Rotation of ``angle`` radians about ``axis`` (normalised here)."""
    axis = np.asarray(axis, dtype=float)
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    unit = axis / np.maximum(n, _EPS)
    half = 0.5 * np.asarray(angle, dtype=float)[..., None]
    return np.concatenate((np.cos(half), np.sin(half) * unit), axis=-1)


def from_yaw(yaw: FloatArray | float) -> FloatArray:
    """Rotation about +Z by ``yaw`` radians (counter-clockwise seen from above)."""
    half = 0.5 * np.asarray(yaw, dtype=float)
    zeros = np.zeros_like(half)
    return np.stack((np.cos(half), zeros, zeros, np.sin(half)), axis=-1)


def yaw_of(q: FloatArray) -> FloatArray:
    """Heading of the rotated +X axis in the ground plane, in ``(-π, π]``."""
    fwd = rotate(q, np.broadcast_to(np.array([1.0, 0.0, 0.0]), (*q.shape[:-1], 3)))
    return np.arctan2(fwd[..., 1], fwd[..., 0])


def log(q: FloatArray) -> FloatArray:
    """Rotation vector ``θ·axis`` of unit quaternions (shortest rotation, θ in [0, π])."""
    q = np.where(q[..., :1] < 0.0, -q, q)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    # θ/sin(θ/2) → 2 when the rotation vanishes.
    scale = np.where(s > 1e-9, angle / np.maximum(s, 1e-300), 2.0)
    return v * scale


def exp(r: FloatArray) -> FloatArray:
    """Unit quaternion of the rotation vector ``r = θ·axis``."""
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(θ/2)/θ → 1/2 when the rotation vanishes.
    scale = np.where(angle > 1e-9, np.sin(half) / np.maximum(angle, 1e-300), 0.5)
    return np.concatenate((np.cos(half), r * scale), axis=-1)


def angle_between(a: FloatArray, b: FloatArray) -> FloatArray:
    """Angle in radians of the rotation that takes ``a`` to ``b``."""
    d = np.abs(np.sum(a * b, axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


def slerp(a: FloatArray, b: FloatArray, t: FloatArray | float) -> FloatArray:
    """Spherical linear interpolation along the shorter arc, ``t`` broadcast to ``(...)``."""
    t = np.asarray(t, dtype=float)[..., None]
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0.0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-6
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(small, 1.0, s))
    wb = np.where(small, t, np.sin(t * theta) / np.where(small, 1.0, s))
    return normalize(wa * a + wb * b)


def hemisphere(q: FloatArray) -> FloatArray:
    """The same rotations with ``w >= 0``, so weighted sums of nearby rotations behave."""
    return np.where(q[..., :1] < 0.0, -q, q)


def to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), axis=-1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), axis=-1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), axis=-1),
        ),
        axis=-2,
    )


def from_matrix(m: FloatArray) -> FloatArray:
    """Unit quaternions (``w >= 0``) of rotation matrices ``(..., 3, 3)``.

    Uses the largest of the four diagonal combinations for each matrix, which is stable for
    every rotation (Shepperd's method).
    """
    m = np.asarray(m, dtype=float)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack((tr, m00, m11, m22), axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((*m.shape[:-2], 4))
    # w largest
    s = np.sqrt(np.maximum(1.0 + tr, _EPS)) * 2.0
    qw = np.stack(
        (
            0.25 * s,
            (m[..., 2, 1] - m[..., 1, 2]) / s,
            (m[..., 0, 2] - m[..., 2, 0]) / s,
            (m[..., 1, 0] - m[..., 0, 1]) / s,
        ),
        axis=-1,
    )
    s = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, _EPS)) * 2.0
    qx = np.stack(
        (
            (m[..., 2, 1] - m[..., 1, 2]) / s,
            0.25 * s,
            (m[..., 0, 1] + m[..., 1, 0]) / s,
            (m[..., 0, 2] + m[..., 2, 0]) / s,
        ),
        axis=-1,
    )
    s = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, _EPS)) * 2.0
    qy = np.stack(
        (
            (m[..., 0, 2] - m[..., 2, 0]) / s,
            (m[..., 0, 1] + m[..., 1, 0]) / s,
            0.25 * s,
            (m[..., 1, 2] + m[..., 2, 1]) / s,
        ),
        axis=-1,
    )
    s = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, _EPS)) * 2.0
    qz = np.stack(
        (
            (m[..., 1, 0] - m[..., 0, 1]) / s,
            (m[..., 0, 2] + m[..., 2, 0]) / s,
            (m[..., 1, 2] + m[..., 2, 1]) / s,
            0.25 * s,
        ),
        axis=-1,
    )
    q = np.where(
        (k == 0)[..., None], qw, np.where((k == 1)[..., None], qx, np.where((k == 2)[..., None], qy, qz))
    )
    return hemisphere(normalize(q))


def from_two_frames(a1: FloatArray, a2: FloatArray, b1: FloatArray, b2: FloatArray) -> FloatArray:
    """Rotation taking direction ``a1`` to ``b1`` and, as well as possible, ``a2`` to ``b2``.

    ``a1``/``b1`` are matched exactly; ``a2``/``b2`` only fix the roll about them (their
    components along ``a1``/``b1`` are ignored). All arrays ``(..., 3)``.
    """
    fa = _frame(a1, a2)
    fb = _frame(b1, b2)
    return from_matrix(fb @ np.swapaxes(fa, -1, -2))


def _frame(d1: FloatArray, d2: FloatArray) -> FloatArray:
    e1 = d1 / np.maximum(np.linalg.norm(d1, axis=-1, keepdims=True), _EPS)
    e3 = np.cross(e1, d2)
    e3 = e3 / np.maximum(np.linalg.norm(e3, axis=-1, keepdims=True), _EPS)
    e2 = np.cross(e3, e1)
    return np.stack((e1, e2, e3), axis=-1)


def rotation_between(a: FloatArray, b: FloatArray) -> FloatArray:
    """Shortest rotation taking direction ``a`` to direction ``b`` (``(..., 3)`` each)."""
    a = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), _EPS)
    b = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), _EPS)
    w = 1.0 + np.sum(a * b, axis=-1, keepdims=True)
    axis = np.cross(a, b)
    # Opposite directions: any perpendicular axis works.
    perp = np.cross(a, np.array([1.0, 0.0, 0.0]))
    perp = np.where(
        np.linalg.norm(perp, axis=-1, keepdims=True) < 1e-6, np.cross(a, np.array([0.0, 1.0, 0.0])), perp
    )
    opposite = w < 1e-9
    axis = np.where(opposite, perp, axis)
    w = np.where(opposite, 0.0, w)
    return normalize(np.concatenate((w, axis), axis=-1))


# ---------------------------------------------------------------------------------------------
# Yaw-only (ground plane) helpers: headings are angles about +Z.




def rot2(yaw: FloatArray | float, v: FloatArray) -> FloatArray:
    """Rotate vectors ``(..., 2 or 3)`` about +Z by ``yaw`` (z unchanged)."""
    yaw = np.asarray(yaw, dtype=float)
    c, s = np.cos(yaw), np.sin(yaw)
    x = c * v[..., 0] - s * v[..., 1]
    y = s * v[..., 0] + c * v[..., 1]
    if v.shape[-1] == 2:
        return np.stack((x, y), axis=-1)
    return np.stack((x, y, np.broadcast_to(v[..., 2], x.shape)), axis=-1)


def compose2(
    pos_a: FloatArray, yaw_a: FloatArray | float, pos_b: FloatArray, yaw_b: FloatArray | float
) -> tuple[FloatArray, FloatArray]:
    """Ground pose ``a ∘ b``: pose ``b`` expressed in frame ``a``, returned in the world."""
    return pos_a + rot2(yaw_a, pos_b), np.asarray(yaw_a, dtype=float) + yaw_b


def relative2(
    pos_a: FloatArray, yaw_a: FloatArray | float, pos_b: FloatArray, yaw_b: FloatArray | float
) -> tuple[FloatArray, FloatArray]:
    """Ground pose ``a⁻¹ ∘ b``: pose ``b`` seen from frame ``a``."""
    return rot2(-np.asarray(yaw_a), pos_b - pos_a), wrap_angle(np.asarray(yaw_b) - yaw_a)
