# SPDX-License-Identifier: GPL-3.0-or-later
"""Small shared geometry, written once so that every code path computes it alike.

Lengths of 2-vectors are written out as ``sqrt(dx * dx + dy * dy)``, never as
``np.linalg.norm`` of a 1-D array: numpy computes that as a BLAS ``ddot``, and OpenBLAS picks
its kernel from the CPU at run time (its AVX-512 kernels fuse the multiply-add), so the same
length would differ in the last bit between a one-at-a-time and a batched planner on some
machines and not on others. Element-wise products and sums round the same everywhere.
"""

from __future__ import annotations

from typing import overload

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@overload
def planar_length(dx: float, dy: float) -> float: ...
@overload
def planar_length(dx: FloatArray, dy: FloatArray) -> FloatArray: ...
def planar_length(dx: float | FloatArray, dy: float | FloatArray) -> float | FloatArray:
    """Length of the 2-vectors ``(dx, dy)``: scalars, or arrays of any (same) shape."""
    if isinstance(dx, np.ndarray) or isinstance(dy, np.ndarray):
        return np.sqrt(dx * dx + dy * dy)
    return float(np.sqrt(float(dx) * float(dx) + float(dy) * float(dy)))


def vector_norm(v: FloatArray, keepdims: bool = False) -> FloatArray:
    """Lengths of the vectors along the last axis of ``v`` ``(..., d)``: ``(...)`` (or
    ``(..., 1)`` with ``keepdims``). The same sum of squares as ``np.linalg.norm(v,
    axis=-1)``, without its dispatch: a character's step takes a few thousand lengths of
    small arrays, where the call cost more than the arithmetic."""
    return np.sqrt(np.add.reduce(v * v, axis=-1, keepdims=keepdims))


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross products ``(..., 3)`` of 3-vectors ``a`` and ``b`` ``(..., 3)`` (broadcast
    together), written out: ``np.cross`` spends most of its time moving axes of small
    arrays around."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


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


def wrap_angle(a: npt.ArrayLike) -> FloatArray:
    """Angles wrapped into ``[-π, π)``."""
    return np.asarray((np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi)
