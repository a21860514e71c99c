# SPDX-License-Identifier: GPL-3.0-or-later
"""Small shared geometry, written once so that every code path computes it alike.

Lengths of 2-vectors are written out as ``sqrt(dx * dx + dy * dy)``, never as
``np.linalg.norm`` of a 1-D array: numpy computes that as a BLAS ``ddot``, and OpenBLAS picks
its kernel from the CPU at run time (its AVX-512 kernels fuse the multiply-add), so the same
length would differ in the last bit between a one-at-a-time and a batched planner on some
machines and not on others. Element-wise products and sums round the same everywhere.
"""

from __future__ import annotations

from typing import TypeVar, overload

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
_T = TypeVar("_T", bound=np.generic)


@overload
def planar_length(dx: float, dy: float) -> float: ...
@overload
def planar_length(dx: FloatArray, dy: FloatArray) -> FloatArray: ...
def planar_length(dx: float | FloatArray, dy: float | FloatArray) -> float | FloatArray:
    """Length of the 2-vectors ``(dx, dy)``: scalars, or arrays of any (same) shape."""
    if isinstance(dx, np.ndarray) or isinstance(dy, np.ndarray):
        return np.sqrt(dx * dx + dy * dy)
    return float(np.sqrt(float(dx) * float(dx) + float(dy) * float(dy)))


def column_pair(a: npt.NDArray[_T], b: npt.NDArray[_T]) -> npt.NDArray[_T]:
    """``np.column_stack([a, b])`` of two 1-D arrays ``(n,)``: ``(n, 2)``, in one C-level call
    (column_stack's Python-level set-up costs several times the copy on the planner's arrays
    of a few dozen rows)."""
    return np.concatenate((a[:, None], b[:, None]), axis=1)


def sum_last(v: FloatArray, keepdims: bool = False) -> FloatArray:
    """``np.add.reduce(v, axis=-1)``: two or three components summed written out, in the
    reduction's order (a reduction along a last axis of two or three is a loop per row, four
    to five times slower than the written-out sums)."""
    d = v.shape[-1]
    if d == 2 or d == 3:
        out = v[..., 0] + v[..., 1]
        if d == 3:
            out += v[..., 2]
        return out[..., None] if keepdims else out
    return np.add.reduce(v, axis=-1, keepdims=keepdims)


def vector_norm(v: FloatArray, keepdims: bool = False) -> FloatArray:
    """Lengths of the vectors along the last axis of ``v`` ``(..., d)``: ``(...)`` (or
    ``(..., 1)`` with ``keepdims``). The same sum of squares as ``np.linalg.norm(v,
    axis=-1)``, without its dispatch: a character's step takes a few thousand lengths of
    small arrays, where the call cost more than the arithmetic."""
    return np.sqrt(sum_last(v * v, keepdims))


#: The components of a 3-vector turned once and twice: (y, z, x) and (z, x, y).
_YZX = np.array([1, 2, 0])
_ZXY = np.array([2, 0, 1])


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross products ``(..., 3)`` of 3-vectors ``a`` and ``b`` ``(..., 3)`` (broadcast
    together), written out as ``a.yzx * b.zxy - a.zxy * b.yzx``: ``np.cross`` spends most of
    its time moving axes of small arrays around."""
    return np.asarray(a.take(_YZX, axis=-1) * b.take(_ZXY, axis=-1)
                      - a.take(_ZXY, axis=-1) * b.take(_YZX, axis=-1))


def z_rotations(angle: FloatArray) -> FloatArray:
    """Rotations ``(..., 3, 3)`` about Z by ``angle`` ``(...)`` radians, written element by
    element into one array (stacking rows was a tenth of a spine character's step)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((*np.shape(angle), 3, 3))
    out[..., 0, 0] = c
    out[..., 0, 1] = -s
    out[..., 1, 0] = s
    out[..., 1, 1] = c
    out[..., 2, 2] = 1.0
    return out


def clip(a: npt.ArrayLike, lo: npt.ArrayLike, hi: npt.ArrayLike) -> FloatArray:
    """``np.clip(a, lo, hi)`` (the same numbers, NaN included) without its dispatch: a step
    clips a few dozen arrays of a few elements, where the call cost more than the work."""
    return np.asarray(np.minimum(np.maximum(a, lo), hi))


def wrap_angle(a: npt.ArrayLike) -> FloatArray:
    """Angles wrapped to ``[-π, π)``."""
    return np.asarray(np.mod(np.asarray(a, dtype=np.float64) + np.pi, 2.0 * np.pi) - np.pi)


def rotate_xy(v: FloatArray, yaw: FloatArray) -> FloatArray:
    """2-vectors ``v (n, 2)`` turned by ``yaw (n,)`` radians about Z: ``(n, 2)``."""
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.empty((v.shape[0], 2))
    out[:, 0] = c * v[:, 0] - s * v[:, 1]
    out[:, 1] = s * v[:, 0] + c * v[:, 1]
    return out


def rotation_matrices(yaw: FloatArray, pitch: FloatArray, roll: FloatArray) -> FloatArray:
    """Body-to-world rotations ``(n, 3, 3)``: yaw about world z, then pitch (nose up
    positive), then roll (left side up positive) about the body's own axes."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    # Rz(yaw) @ Ry'(pitch, nose up = about -y) @ Rx(roll) multiplied out (the step asks for
    # these a few times; two stacked 3x3 products cost more than the nine entries)
    out = np.empty((yaw.shape[0], 3, 3))
    out[:, 0, 0] = cy * cp
    out[:, 0, 1] = -sy * cr - cy * sp * sr
    out[:, 0, 2] = sy * sr - cy * sp * cr
    out[:, 1, 0] = sy * cp
    out[:, 1, 1] = cy * cr - sy * sp * sr
    out[:, 1, 2] = -cy * sr - sy * sp * cr
    out[:, 2, 0] = sp
    out[:, 2, 1] = cp * sr
    out[:, 2, 2] = cp * cr
    return out
