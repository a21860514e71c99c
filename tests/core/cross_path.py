# SPDX-License-Identifier: GPL-3.0-or-later
"""Comparing two code paths that compute the same thing in another order.

A batched function and its one-at-a-time twin make the same decisions (cells, masks, counts,
the chosen footprint): those are compared exactly. Their floats may differ in the last bits
(numpy groups a reduction by the array's length and alignment; BLAS kernels are picked from
the CPU at run time), so floats are compared to :data:`RTOL` relative and :data:`ATOL`
absolute: a few hundred ulps of the metre-sized values the planner works with, far below
anything a foot could show (1e-12 m). Runs of the *same* code twice stay exact.
"""

from __future__ import annotations

from typing import Any

import numpy as np

RTOL = 1e-12
ATOL = 1e-12


def assert_close(got: Any, want: Any, name: str = "") -> None:
    """``got`` equals ``want`` to :data:`RTOL`/:data:`ATOL`, with the same shape and NaNs."""
    a = np.asarray(got, dtype=np.float64)
    b = np.asarray(want, dtype=np.float64)
    assert a.shape == b.shape, f"{name}: shape {a.shape} != {b.shape}"
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=ATOL, equal_nan=True, err_msg=name)
