# SPDX-License-Identifier: GPL-3.0-or-later
"""Key reduction fitting (core/keyfit.py): the kept keys and fitted handles, evaluated the
way Blender evaluates Bézier F-curves, stay within the tolerance of every sample."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core import keyfit


def _de_casteljau(p: np.ndarray, t: float) -> np.ndarray:
    """Point of the cubic Bézier with control points ``p`` ``(4, 2)`` at parameter ``t``."""
    pts = p.copy()
    for k in range(3, 0, -1):
        pts = pts[:k] + t * (pts[1:k + 1] - pts[:k])
    return pts[0]


def _walk_like(n: int, seed: int, channels: int = 3) -> np.ndarray:
    """Samples ``(n, channels)`` like a generated walk: smooth swings, kinks at contacts."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 24.0
    out = np.empty((n, channels))
    for c in range(channels):
        period = rng.uniform(0.5, 1.5)
        phase = (t / period + rng.uniform()) % 1.0
        swing = np.where(phase < 0.3, np.sin(np.pi * phase / 0.3), 0.0)  # kinks at 0 and 0.3
        out[:, c] = rng.uniform(0.05, 0.5) * swing + 0.02 * np.sin(2 * np.pi * t * rng.uniform(0.2, 2.0))
    return out


def test_a_straight_line_and_a_cubic_need_only_their_ends() -> None:
    x = np.arange(1.0, 41.0)
    u = (x - 1.0) / 39.0
    values = np.stack([3.0 * x - 2.0, 2.0 * u ** 3 - u ** 2 + 0.5 * u], axis=1)
    fit = keyfit.fit_keys(x, values, 1e-9)
    assert fit.keys.sum(axis=0).tolist() == [2, 2]
    assert fit.key_count == 4
    assert np.abs(keyfit.evaluate_fit(x, values, fit) - values).max() < 1e-9


def test_required_frames_are_keys_and_groups_share_them() -> None:
    x = np.arange(100.0)
    values = _walk_like(100, 3)
    required = np.zeros((100, 2), dtype=bool)
    required[[17, 50, 51], 0] = True
    required[63, 1] = True
    groups = np.array([0, 0, 1])
    fit = keyfit.fit_keys(x, values, 1e-3, groups, required)
    assert fit.keys[[0, 17, 50, 51, 99], 0].all()
    assert fit.keys[[0, 63, 99], 1].all()
    # the key count counts a group's keys once per channel in it
    assert fit.key_count == 2 * int(fit.keys[:, 0].sum()) + int(fit.keys[:, 1].sum())
    curve = keyfit.bezier_points(x, values, fit, 1)
    assert np.array_equal(curve.co[:, 0], x[fit.keys[:, 0]])


def test_a_walk_keeps_far_fewer_keys_within_its_tolerance() -> None:
    x = np.arange(1.0, 241.0)
    values = _walk_like(240, 7, channels=6)
    fit = keyfit.fit_keys(x, values, 1e-3)
    assert fit.key_count * 3 < values.size
    assert np.abs(keyfit.evaluate_fit(x, values, fit, float32=True) - values).max() <= 1e-3 + 1e-6


def test_bad_input_is_refused() -> None:
    x = np.arange(5.0)
    v = np.zeros((5, 1))
    with pytest.raises(ValueError, match="increasing"):
        keyfit.fit_keys(x[::-1], v, 1e-3)
    with pytest.raises(ValueError, match="positive"):
        keyfit.fit_keys(x, v, 0.0)
    with pytest.raises(ValueError, match="finite"):
        keyfit.fit_keys(x, np.full((5, 1), np.nan), 1e-3)
    with pytest.raises(ValueError, match="frames for"):
        keyfit.fit_keys(x[:4], v, 1e-3)


def test_handles_longer_than_their_segment_are_shortened_as_blender_does() -> None:
    # A handle reaching past the other key in time is shortened, keeping its direction, to
    # the segment's length (BKE_fcurve_correct_bezpart): the curve stays a function of time.
    co = np.array([[0.0, 0.0], [10.0, 1.0]])
    hl = np.array([[-1.0, 0.0], [8.0, 1.0]])
    hr = np.array([[16.0, 0.8], [11.0, 1.0]])
    curve = keyfit.BezierCurve(co, hl, hr)
    fac = 10.0 / 16.0
    p = np.array([co[0], co[0] + fac * (hr[0] - co[0]), hl[1], co[1]])
    for t in (0.1, 0.35, 0.5, 0.8):
        x, y = _de_casteljau(p, t)
        assert keyfit.evaluate_bezier(curve, np.array([x]))[0] == pytest.approx(y, abs=1e-9)
    # constant outside the keys
    assert keyfit.evaluate_bezier(curve, np.array([-5.0, 20.0])).tolist() == [0.0, 1.0]


@given(
    st.lists(st.tuples(st.floats(0.05, 0.95), st.floats(0.05, 0.95)), min_size=1, max_size=5),
    st.lists(st.floats(-3.0, 3.0), min_size=12, max_size=12),
    st.floats(0.0, 1.0),
)
def test_evaluation_is_the_bezier_curve_at_the_parameter_of_the_frame(
    handle_spans: list[tuple[float, float]], ys: list[float], t: float
) -> None:
    # Handles within their segment: evaluating at x(t) gives y(t), as de Casteljau does.
    n = len(handle_spans) + 1
    kx = np.cumsum(np.concatenate([[0.0], 1.0 + np.abs(ys[:n - 1])]))
    ky = np.array(ys[:n])
    hl = np.zeros((n, 2))
    hr = np.zeros((n, 2))
    for k in range(n - 1):
        gap = kx[k + 1] - kx[k]
        a, b = handle_spans[k]
        hr[k] = (kx[k] + a * 0.5 * gap, ky[k] + ys[n + k % (12 - n)])
        hl[k + 1] = (kx[k + 1] - b * 0.5 * gap, ky[k + 1] - ys[(2 * k + 1) % 12])
    hl[0] = (kx[0] - 1.0, ky[0])
    hr[-1] = (kx[-1] + 1.0, ky[-1])
    curve = keyfit.BezierCurve(np.stack([kx, ky], axis=1), hl, hr)
    seg = (n - 2) // 2 if n > 1 else 0
    p = np.array([curve.co[seg], hr[seg], hl[seg + 1], curve.co[seg + 1]])
    x, y = _de_casteljau(p, t)
    assert keyfit.evaluate_bezier(curve, np.array([x]))[0] == pytest.approx(y, abs=1e-8)


@given(
    st.integers(3, 160),
    st.integers(0, 2**31 - 1),
    st.integers(1, 4),
    st.floats(1e-5, 1e-1),
    st.booleans(),
    st.booleans(),
    st.booleans(),
)
def test_the_fitted_curves_stay_within_tolerance_of_the_samples(
    n: int, seed: int, channels: int, tol: float, shared: bool, noisy: bool, steady: bool
) -> None:
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.integers(1, 3, size=n)).astype(np.float64) + float(rng.integers(-50, 50))
    values = _walk_like(n, seed, channels) * rng.uniform(0.1, 20.0)
    if noisy:
        values += rng.normal(scale=tol, size=values.shape)
    tolerance = tol * rng.uniform(0.2, 1.0, size=(n, channels))  # per frame and channel
    groups = np.zeros(channels, dtype=np.int64) if shared else np.arange(channels)
    n_groups = int(groups.max()) + 1
    required = rng.uniform(size=(n, n_groups)) < 0.05
    # where steady, the error may change from one frame to the next by half its tolerance only
    step = np.where(rng.uniform(size=(n, channels)) < 0.5, 0.5 * tolerance, np.inf) if steady else None
    fit = keyfit.fit_keys(x, values, tolerance, groups, required, step)
    assert fit.keys[required].all()
    assert fit.keys[[0, -1]].all()
    # As Blender plays it, keys and handles stored in single precision.
    played = keyfit.evaluate_fit(x, values, fit, float32=True)
    slack = 1e-6 * max(1.0, float(np.abs(values).max()))
    assert np.all(np.abs(played - values) <= tolerance + slack)
    if step is not None:
        change = np.abs(np.diff(played - values, axis=0))
        assert np.all(change <= step[:-1] + 2 * slack)
    # keys sit on the samples
    for c in range(channels):
        curve = keyfit.bezier_points(x, values, fit, c)
        assert np.allclose(curve.co[:, 1], values[fit.keys[:, groups[c]], c])
