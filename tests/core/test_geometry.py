# SPDX-License-Identifier: GPL-3.0-or-later
"""The small shared geometry of ``core/geometry.py`` against numpy's own functions."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from procloco_addon.core.geometry import column_pair, cross, planar_length, vector_norm
from tests.core.cross_path import assert_close


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([(5, 3), (2, 4, 3), (7, 2), (3,)]))
def test_vector_norm_is_numpys_norm_along_the_last_axis(seed: int, shape: tuple[int, ...]) -> None:
    v = np.random.default_rng(seed).normal(size=shape) * 10.0
    assert_close(vector_norm(v), np.linalg.norm(v, axis=-1), "norm")
    kept = vector_norm(v, keepdims=True)
    assert kept.shape == (*shape[:-1], 1)
    assert_close(kept, np.linalg.norm(v, axis=-1, keepdims=True), "keepdims")


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_cross_is_numpys_cross_and_broadcasts(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(6, 3))
    b = rng.normal(size=(6, 3))
    assert_close(cross(a, b), np.cross(a, b), "rows")
    x = np.array([1.0, 0.0, 0.0])
    assert_close(cross(a, x), np.cross(a, x), "one vector")
    c = rng.normal(size=(2, 1, 3))
    assert cross(c, a).shape == (2, 6, 3)
    assert_close(cross(c, a), np.cross(c, a), "broadcast")
    # perpendicular to both, with the right hand
    assert_close(np.einsum("ij,ij->i", cross(a, b), a), np.zeros(6), "perpendicular")
    assert_close(cross(np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])), [0.0, 0.0, 1.0], "x cross y")


def test_planar_length_of_scalars_and_arrays() -> None:
    assert planar_length(3.0, 4.0) == 5.0
    assert_close(planar_length(np.array([3.0, 5.0]), np.array([4.0, 12.0])), [5.0, 13.0], "arrays")


@given(st.integers(0, 40), st.sampled_from([np.float64, np.intp, np.bool_]))
def test_column_pair_is_column_stack_of_two_columns(n: int, dtype: type) -> None:
    rng = np.random.default_rng(n)
    a = (rng.normal(size=n) * 10).astype(dtype)
    b = (rng.normal(size=n) * 10).astype(dtype)
    got = column_pair(a, b)
    want = np.column_stack([a, b])
    assert got.dtype == want.dtype
    assert got.shape == want.shape
    assert (got == want).all()
