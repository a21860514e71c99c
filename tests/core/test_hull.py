# SPDX-License-Identifier: GPL-3.0-or-later
"""Upper convex hulls of height profiles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from procloco_addon.core.hull import hull_height_and_pitch, project_along, upper_hull, upper_hull_eval

# Centimetre grid: no sub-normal gaps between x values (slopes stay finite in the checks).
values = st.integers(-300, 300).map(lambda v: v / 100.0)
profiles = st.integers(1, 25).flatmap(
    lambda n: st.tuples(arrays(np.float64, n, elements=values), arrays(np.float64, n, elements=values))
)


@given(profiles)
def test_upper_hull_covers_every_point_and_is_concave(xz: tuple[np.ndarray, np.ndarray]) -> None:
    x, z = xz
    idx = upper_hull(x, z)
    hx, hz = x[idx], z[idx]
    assert np.all(np.diff(hx) > 0.0)  # strictly increasing x
    assert hx[0] == x.min()
    assert hx[-1] == x.max()
    if idx.size >= 3:
        slopes = np.diff(hz) / np.diff(hx)
        assert np.all(np.diff(slopes) < 1e-9)  # concave: slopes decrease
    # Every point on or below the polyline through the vertices.
    line = np.interp(x, hx, hz)
    assert np.all(z <= line + 1e-9)


@given(profiles, arrays(np.float64, 6, elements=values))
def test_batched_evaluation_matches_the_vertices(xz: tuple[np.ndarray, np.ndarray], q: np.ndarray) -> None:
    x, z = xz
    idx = upper_hull(x, z)
    height, slope = upper_hull_eval(x, z, q)
    expected = np.interp(np.clip(q, x.min(), x.max()), x[idx], z[idx])
    assert np.allclose(height, expected, atol=1e-9)
    assert np.all(slope[(q < x.min()) | (q > x.max())] == 0.0)  # flat outside


def test_slopes_inside_edges_and_at_vertices() -> None:
    x = np.array([0.0, 1.0, 3.0, 2.0])
    z = np.array([0.0, 1.0, 0.0, 0.2])  # (2, 0.2) lies under the hull
    height, slope = upper_hull_eval(x, z, np.array([0.5, 1.0, 2.0]))
    assert np.allclose(height, [0.5, 1.0, 0.5])
    assert np.allclose(slope, [1.0, 0.25, -0.5])  # at the vertex: mean of 1 and -0.5


def test_batches_and_masks() -> None:
    rng = np.random.default_rng(4)
    x = rng.uniform(-1, 1, (3, 5, 12))
    z = rng.uniform(-1, 1, (3, 5, 12))
    valid = rng.random((3, 5, 12)) > 0.3
    valid[..., 0] = True
    q = rng.uniform(-1, 1, (3, 5, 4))
    height, slope = upper_hull_eval(x, z, q, valid)
    assert height.shape == slope.shape == (3, 5, 4)
    for i in range(3):
        for j in range(5):
            m = valid[i, j]
            h1, s1 = upper_hull_eval(x[i, j][m], z[i, j][m], q[i, j])
            assert np.allclose(height[i, j], h1)
            assert np.allclose(slope[i, j], s1)


def test_pelvis_height_and_pitch_on_a_slope_and_over_a_bump() -> None:
    xs = np.linspace(-0.5, 0.5, 11)
    forward = np.array([np.cos(0.7), np.sin(0.7)])
    ground = np.column_stack([xs * forward[0], xs * forward[1], 0.2 * xs])  # 0.2 slope along forward
    h, pitch = hull_height_and_pitch(ground, np.zeros(2), forward)
    assert h == pytest.approx(0.0, abs=1e-9)
    assert pitch == pytest.approx(np.arctan(0.2), abs=1e-6)
    # A crate under the back of the body lifts the hull under the centre.
    bump = np.array([[-0.3 * forward[0], -0.3 * forward[1], 0.4]])
    pts = np.vstack([ground, bump])
    h2, pitch2 = hull_height_and_pitch(pts, np.zeros(2), forward)
    assert h2 > 0.1
    assert pitch2 < 0.0
    x, z = project_along(pts, np.zeros(2), forward * 3.0)
    assert x[-1] == pytest.approx(-0.3)
    assert z[-1] == 0.4
    # Batched over characters.
    both = np.stack([ground, ground])
    hb, pb = hull_height_and_pitch(both, np.zeros((2, 2)), np.stack([forward, -forward]))
    assert np.allclose(hb, 0.0)
    assert np.allclose(pb, [np.arctan(0.2), -np.arctan(0.2)], atol=1e-6)


def test_rejects_empty_profiles() -> None:
    with pytest.raises(ValueError, match="non-empty"):
        upper_hull(np.zeros(0), np.zeros(0))
