# SPDX-License-Identifier: GPL-3.0-or-later
"""Splines for the biped planner: centripetal Catmull-Rom and least-squares cubic B-splines.

* :func:`catmull_rom` interpolates the footprint midpoints in time (§3.6, appendix A.1).
  It is the *centripetal* Catmull-Rom of Barry and Goldman's recursive form with knot
  spacing ``|Pᵢ₊₁ - Pᵢ|^½``, which never forms cusps or loops inside a segment. (The
  appendix' basis matrix with τ = ½ is the uniform-knot spline; the name and the intent,
  no overshoot at sharp bends, are those of the centripetal one.)
* :func:`bspline_fit` is a least-squares uniform cubic B-spline with a small second-
  difference penalty: a low-pass filter whose cut-off is set by the knot spacing (§3.7.1)
  and which bridges frames without data (the IK offsets, §3.8.1).
  :func:`hierarchical_fit` stacks such fits at halving spacings on the residual, the
  hierarchical B-splines of Lee and Shin that the thesis uses for the IK offsets.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def catmull_rom(points: FloatArray, times: FloatArray, t: FloatArray, alpha: float = 0.5) -> FloatArray:
    """Centripetal Catmull-Rom through ``points (N, D)`` at increasing ``times (N,)``.

    Evaluated at ``t (M,)``; the ends are extended by reflection (``P₋₁ = 2P₀ − P₁``) as in
    §3.6, and times outside ``[times[0], times[-1]]`` extrapolate the first or last segment.
    """
    p = np.asarray(points, dtype=float)
    times = np.asarray(times, dtype=float)
    t = np.asarray(t, dtype=float)
    n = len(p)
    if n == 1:
        return np.broadcast_to(p[0], (len(t), p.shape[1])).copy()
    ext = np.concatenate((2 * p[:1] - p[1:2], p, 2 * p[-1:] - p[-2:-1]))
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, n - 2)
    span = np.maximum(times[k + 1] - times[k], 1e-12)
    u = (t - times[k]) / span
    p0, p1, p2, p3 = ext[k], ext[k + 1], ext[k + 2], ext[k + 3]

    def knot(a: FloatArray, b: FloatArray) -> FloatArray:
        return np.maximum(np.linalg.norm(b - a, axis=-1) ** alpha, 1e-6)[:, None]

    t0 = np.zeros((len(t), 1))
    t1 = t0 + knot(p0, p1)
    t2 = t1 + knot(p1, p2)
    t3 = t2 + knot(p2, p3)
    s = t1 + u[:, None] * (t2 - t1)
    a1 = ((t1 - s) * p0 + (s - t0) * p1) / (t1 - t0)
    a2 = ((t2 - s) * p1 + (s - t1) * p2) / (t2 - t1)
    a3 = ((t3 - s) * p2 + (s - t2) * p3) / (t3 - t2)
    b1 = ((t2 - s) * a1 + (s - t0) * a2) / (t2 - t0)
    b2 = ((t3 - s) * a2 + (s - t1) * a3) / (t3 - t1)
    return ((t2 - s) * b1 + (s - t1) * b2) / (t2 - t1)


def _basis(x: FloatArray, n_ctrl: int) -> tuple[NDArray[np.int64], FloatArray]:
    """First control index ``(M,)`` and the four cubic B-spline weights ``(M, 4)`` at knot units ``x``."""
    i = np.clip(np.floor(x).astype(np.int64), 0, n_ctrl - 4)
    u = x - i
    u2, u3 = u * u, u * u * u
    w = np.stack(((1 - u) ** 3, 3 * u3 - 6 * u2 + 4, -3 * u3 + 3 * u2 + 3 * u + 1, u3), axis=-1) / 6.0
    return i, w


class BSpline:
    """A uniform cubic B-spline: ``n_ctrl`` control values ``(n_ctrl, D)`` from ``t0`` every ``spacing``."""

    def __init__(self, t0: float, spacing: float, ctrl: FloatArray) -> None:
        self.t0 = t0
        self.spacing = spacing
        self.ctrl = ctrl

    def __call__(self, t: FloatArray) -> FloatArray:
        x = (np.asarray(t, dtype=float) - self.t0) / self.spacing
        i, w = _basis(x, len(self.ctrl))
        idx = i[:, None] + np.arange(4)
        return np.einsum("mk,mkd->md", w, self.ctrl[idx])


def bspline_fit(
    t: FloatArray, y: FloatArray, spacing: float, weights: FloatArray | None = None, smoothness: float = 1e-3
) -> BSpline:
    """Least-squares cubic B-spline through samples ``y (N, D)`` at times ``t (N,)``.

    ``spacing`` (seconds between knots) sets the cut-off: wiggles shorter than about two
    spacings are filtered out. ``weights (N,)`` (0 = ignore a sample) let the fit bridge
    gaps; ``smoothness`` scales a second-difference penalty that also keeps control values
    without data on a straight line between their neighbours.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    t0 = float(t.min())
    span = float(t.max()) - t0
    n_ctrl = int(np.floor(span / spacing)) + 4
    x = (t - t0) / spacing
    i, w = _basis(x, n_ctrl)
    basis = np.zeros((len(t), n_ctrl))
    rows = np.arange(len(t))[:, None]
    basis[rows, i[:, None] + np.arange(4)] = w
    wts = np.ones(len(t)) if weights is None else np.asarray(weights, dtype=float)
    bw = basis * wts[:, None]
    lhs = basis.T @ bw
    rhs = bw.T @ y
    d2 = np.diff(np.eye(n_ctrl), 2, axis=0)
    scale = max(float(np.trace(lhs)) / n_ctrl, 1e-9)
    lhs = lhs + smoothness * scale * (d2.T @ d2) + 1e-12 * scale * np.eye(n_ctrl)
    return BSpline(t0, spacing, np.linalg.solve(lhs, rhs))


def hierarchical_fit(
    t: FloatArray,
    y: FloatArray,
    spacings: tuple[float, ...],
    t_eval: FloatArray,
    weights: FloatArray | None = None,
) -> FloatArray:
    """Sum of B-spline fits at the given (coarse to fine) spacings, each fitted to the
    residual of the previous ones; evaluated at ``t_eval``. Returns ``(M, D)``."""
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    residual = y.copy()
    out = np.zeros((len(t_eval), y.shape[1]))
    for h in spacings:
        spline = bspline_fit(t, residual, h, weights)
        out += spline(t_eval)
        residual = residual - spline(t)
    return out
