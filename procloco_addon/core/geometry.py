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
