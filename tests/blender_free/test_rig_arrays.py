# SPDX-License-Identifier: GPL-3.0-or-later
"""The array helpers of the rig modules that replace slower numpy calls (no bpy): the
element-wise inverse of affine matrices and a bone's children. Each is checked
against what it stands for (``np.linalg.inv``, a scan of the parents),
floats within a tolerance (two code paths), decisions exactly."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.blender.rig.rest import _Rest, affine_inverse

seeds = st.integers(0, 2**32 - 1)


@given(seeds, st.integers(1, 40))
def test_affine_inverse_inverts_bone_and_object_matrices(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    m = np.tile(np.eye(4), (n, 1, 1))
    # scaled rotations (a bone's pose, an object's world), sheared ones, and any translation
    m[:, :3, :3] = rng.uniform(0.2, 3.0, (n, 1, 1)) * np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    m[:, :3, :3] += 0.2 * rng.normal(size=(n, 3, 3))
    m[:, :3, 3] = rng.normal(scale=10.0, size=(n, 3))
    inv = affine_inverse(m)
    assert inv.shape == m.shape
    np.testing.assert_allclose(inv @ m, np.broadcast_to(np.eye(4), m.shape), atol=1e-9)
    np.testing.assert_allclose(inv, np.linalg.inv(m), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(affine_inverse(m[0]), np.linalg.inv(m[0]), rtol=1e-9, atol=1e-9)


@given(seeds, st.integers(1, 60))
def test_children_are_the_bones_whose_parent_it_is(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    parent = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, n)], dtype=np.int64)
    names = tuple(f"b{i}" for i in range(n))
    head = rng.normal(size=(n, 3))
    rest = _Rest(names, {b: i for i, b in enumerate(names)}, parent, head, head + 0.1,
                 np.tile(np.eye(4), (n, 1, 1)), np.eye(4), 1.0)
    for i in range(n):
        kids = rest.children(i)
        assert kids == [int(c) for c in np.flatnonzero((parent == i) & ~rest.phantom)]
        kids.append(-5)  # a caller's list is its own
        assert -5 not in rest.children(i)
