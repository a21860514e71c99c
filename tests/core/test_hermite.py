# SPDX-License-Identifier: GPL-3.0-or-later
"""Hermite and cardinal curves (thesis Appendix F)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from procloco_addon.core.hermite import (
    HermiteCurve,
    cardinal_samples,
    cardinal_tangents,
    hermite_basis,
    hermite_segment,
    hermite_segment_derivative,
)
from tests.core.cross_path import assert_close

coords = st.floats(-5.0, 5.0, allow_nan=False, allow_infinity=False)


def _spread_points(dim: int) -> st.SearchStrategy[np.ndarray]:
    """3..7 points, consecutive ones at least 5 cm apart."""
    return arrays(np.float64, st.tuples(st.integers(3, 7), st.just(dim)), elements=coords).filter(
        lambda p: bool(np.all(np.linalg.norm(np.diff(p, axis=0), axis=1) > 0.05))
    )


@given(arrays(np.float64, (4, 3), elements=coords), st.floats(0.0, 1.0))
def test_segment_matches_eq_f1_and_its_ends(ctrl: np.ndarray, s: float) -> None:
    p1, p2, t1, t2 = ctrl
    # Eq. F.1 written out with the cubic Hermite polynomials.
    expected = ((2 * s**3 - 3 * s**2 + 1) * p1 + (-2 * s**3 + 3 * s**2) * p2
                + (s**3 - 2 * s**2 + s) * t1 + (s**3 - s**2) * t2)
    assert np.allclose(hermite_segment(p1, p2, t1, t2, s), expected, atol=1e-9)
    ends = hermite_segment(p1, p2, t1, t2, np.array([0.0, 1.0]))
    assert np.allclose(ends, [p1, p2])
    d = hermite_segment_derivative(p1, p2, t1, t2, np.array([0.0, 1.0]))
    assert np.allclose(d, [t1, t2])


def test_basis_weights_partition_unity_for_points() -> None:
    w = hermite_basis(np.linspace(0.0, 1.0, 11))
    assert w.shape == (11, 4)
    assert np.allclose(w[:, 0] + w[:, 1], 1.0)  # a constant curve stays constant


def test_segments_broadcast_over_batches() -> None:
    rng = np.random.default_rng(1)
    p1, p2, t1, t2 = rng.normal(size=(4, 5, 3))
    s = np.linspace(0.0, 1.0, 7)
    batch = hermite_segment(p1, p2, t1, t2, s)
    assert batch.shape == (5, 7, 3)
    for i in range(5):
        assert np.allclose(batch[i], hermite_segment(p1[i], p2[i], t1[i], t2[i], s))


def test_cardinal_tangents_are_eq_f5_for_even_spacing() -> None:
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    bent = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # unit chords
    for p in (pts, bent):
        t_start, t_end = cardinal_tangents(p, tension=0.3)
        for i in range(1, p.shape[0] - 1):
            expected = 0.3 * (p[i + 1] - p[i - 1])
            assert np.allclose(t_start[i], expected)
            assert np.allclose(t_end[i - 1], expected)


@given(_spread_points(2) | _spread_points(3), st.floats(0.0, 1.0))
def test_cardinal_curve_passes_through_its_points_with_one_direction_at_each(
    pts: np.ndarray, tension: float
) -> None:
    curve = HermiteCurve.cardinal(pts, tension=tension)
    n = pts.shape[0]
    assert np.allclose(curve.evaluate(np.arange(n, dtype=float)), pts, atol=1e-9)
    if tension > 0.05:
        # Geometric continuity: both sides of an interior point leave in the same direction.
        a = curve.t_end[:-1] / np.linalg.norm(curve.t_end[:-1], axis=1, keepdims=True).clip(1e-12)
        b = curve.t_start[1:] / np.linalg.norm(curve.t_start[1:], axis=1, keepdims=True).clip(1e-12)
        nonzero = np.linalg.norm(curve.t_end[:-1], axis=1) > 1e-9
        assert np.allclose(a[nonzero], b[nonzero], atol=1e-9)


@given(_spread_points(3))
def test_arc_length_sampling_is_constant_speed(pts: np.ndarray) -> None:
    curve = HermiteCurve.cardinal(pts)
    dense = curve.polyline(400)
    dense_len = float(np.sum(np.linalg.norm(np.diff(dense, axis=0), axis=1)))
    assert curve.length == pytest.approx(dense_len, rel=2e-3)
    u = np.linspace(0.0, 1.0, 41)
    p = curve.at_fraction(u)
    assert np.allclose(p[0], pts[0])
    assert np.allclose(p[-1], pts[-1])
    # Arc length between consecutive samples: measure it on a fine polyline of each piece.
    arcs = []
    for a, b in itertools.pairwise(u):
        piece = curve.at_fraction(np.linspace(a, b, 400))
        arcs.append(np.sum(np.linalg.norm(np.diff(piece, axis=0), axis=1)))
    arcs_a = np.array(arcs)
    assert np.allclose(arcs_a, curve.length / 40, rtol=0.02, atol=1e-4)


def test_zero_tension_gives_straight_segments() -> None:
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [1.0, 2.0, 0.5]])
    curve = HermiteCurve.cardinal(pts, tension=0.0)
    t = np.linspace(0.0, 1.0, 9)
    on_first = curve.evaluate(t)
    # Every point of segment 0 lies on the chord from P0 to P1.
    chord = pts[1] - pts[0]
    rel = on_first - pts[0]
    assert np.allclose(np.cross(rel, chord), 0.0, atol=1e-12)
    assert curve.length == pytest.approx(np.linalg.norm(chord) + 2.0, rel=1e-6)


def test_sample_spacing_and_chord_walk() -> None:
    curve = HermiteCurve.cardinal(np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 0.0], [3.0, 1.0]]))
    samples = curve.sample(0.1)
    gaps = np.linalg.norm(np.diff(samples, axis=0), axis=1)
    assert np.all(gaps[:-1] == pytest.approx(0.1, abs=2e-3))  # chords of 10 cm arcs
    bones = np.array([0.3, 0.5, 0.2, 0.4])
    walked = curve.chord_walk(bones)
    assert walked.shape == (5, 2)
    assert np.allclose(np.linalg.norm(np.diff(walked, axis=0), axis=1), bones, atol=1e-9)
    # Each joint lies on the curve: close to a dense sample.
    dense = curve.polyline(500)
    for p in walked:
        assert np.min(np.linalg.norm(dense - p, axis=1)) < 5e-3
    # Longer than the curve: continues straight along the end tangent.
    far = curve.chord_walk(np.array([10.0]))
    assert np.linalg.norm(far[1] - far[0]) == pytest.approx(10.0)


def test_from_directions_leaves_each_point_along_its_direction() -> None:
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.2], [2.0, 0.5, 0.2]])
    dirs = np.array([[1.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.0, 1.0, 0.0]])
    curve = HermiteCurve.from_directions(pts, dirs)
    d = curve.derivative(np.array([0.0, 1.0, 2.0]))
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    expected = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    assert np.allclose(unit, expected, atol=1e-9)
    assert np.allclose(curve.tangent_at_fraction(np.array([1.0]))[0], [0.0, 1.0, 0.0], atol=1e-6)


def test_degenerate_inputs_do_not_produce_nan() -> None:
    pts = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    curve = HermiteCurve.cardinal(pts)
    assert np.all(np.isfinite(curve.at_fraction(np.linspace(0.0, 1.0, 5))))
    with pytest.raises(ValueError, match="at least two"):
        cardinal_tangents(np.zeros((1, 2)))


@given(st.integers(0, 100_000), st.sampled_from([0.5, 0.25, 0.0]))
def test_cardinal_samples_equal_the_curve_object_sampled_by_arc_length(seed: int, tension: float) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 7))
    pts = np.cumsum(rng.normal(size=(n, 2)) * rng.uniform(0.01, 1.0), axis=0)
    if n > 2 and seed % 5 == 0:
        pts[1] = pts[0]  # coincident waypoints: zero tangents, never NaN
    spacing = float(rng.uniform(0.005, 0.05))
    curve = HermiteCurve.cardinal(pts, tension=tension, samples_per_segment=16)
    arc = np.linspace(0.0, curve.length, max(2, math.ceil(curve.length / spacing) + 1))
    samples, got_arc, length = cardinal_samples(pts, tension, spacing, samples_per_segment=16)
    # The same arithmetic as the curve object, in fewer calls: equal to a few ulps.
    assert_close(length, curve.length, "length")
    assert_close(got_arc, arc, "arc")
    assert_close(samples, curve.at_length(arc), "samples")
