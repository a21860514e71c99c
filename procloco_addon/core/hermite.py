# SPDX-License-Identifier: GPL-3.0-or-later
"""Cubic Hermite and cardinal curves in any dimension (thesis Appendix F).

A Hermite segment joins two points ``P1``, ``P2`` with end tangents ``T1``, ``T2``::

    P(s) = [s³ s² s 1] · H · [P1 P2 T1 T2]ᵀ,   s in [0, 1]          (eq. F.1–F.4)

with the constant matrix ``H`` below. Cardinal splines choose the tangents automatically
from the neighbouring points, ``T_i = a (P_{i+1} - P_{i-1})`` (eq. F.5); ``a = 0.5`` is the
Catmull-Rom spline.

Waypoints along a foot path or a spine are rarely evenly spaced, and the plain eq. F.5 makes a
short segment next to a long one overshoot. :func:`cardinal_tangents` therefore uses the
chord-weighted form of F.5: the direction at a point is the central difference divided by the
two adjacent chord lengths, and each segment scales it by its own chord. With even spacing
this is exactly ``a (P_{i+1} - P_{i-1})``.

Two levels of API:

- functions that broadcast over any leading batch shape, for callers that vectorise over
  legs or characters (:func:`hermite_basis`, :func:`hermite_segment`,
  :func:`hermite_segment_derivative`, :func:`cardinal_tangents`);
- :class:`HermiteCurve`, one piecewise curve with arc-length queries: its length, points at
  arc lengths or at fractions of the length (constant speed), uniform resampling and
  "chord walking" (points at given straight-line distances from each other, e.g. bones).

Shapes: ``d`` is the dimension (2 or 3, any works), ``n`` the number of points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .geometry import linspace_to, sum_last

FloatArray = npt.NDArray[np.float64]

#: Hermite matrix of eq. F.4; rows multiply [s³, s², s, 1], columns are P1, P2, T1, T2.
HERMITE_MATRIX: FloatArray = np.array(
    [
        [2.0, -2.0, 1.0, 1.0],
        [-3.0, 3.0, -2.0, -1.0],
        [0.0, 0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0, 0.0],
    ]
)

# Derivative of the basis: d/ds [s³ s² s 1] = [3s² 2s 1 0].
_HERMITE_DERIV_MATRIX: FloatArray = np.array(
    [
        [6.0, -6.0, 3.0, 3.0],
        [-6.0, 6.0, -4.0, -2.0],
        [0.0, 0.0, 1.0, 0.0],
    ]
)


def hermite_basis(s: npt.ArrayLike) -> FloatArray:
    """Weights of ``(P1, P2, T1, T2)`` at parameters ``s``: shape ``s.shape + (4,)``."""
    s_arr = np.asarray(s, dtype=np.float64)
    powers = np.empty((*s_arr.shape, 4))
    powers[..., 0] = s_arr**3
    powers[..., 1] = s_arr**2
    powers[..., 2] = s_arr
    powers[..., 3] = 1.0
    return powers @ HERMITE_MATRIX


def hermite_basis_derivative(s: npt.ArrayLike) -> FloatArray:
    """Derivative of :func:`hermite_basis` with respect to ``s``: ``s.shape + (4,)``."""
    s_arr = np.asarray(s, dtype=np.float64)
    powers = np.stack([s_arr**2, s_arr, np.ones_like(s_arr)], axis=-1)
    return powers @ _HERMITE_DERIV_MATRIX


def hermite_segment(
    p1: npt.ArrayLike, p2: npt.ArrayLike, t1: npt.ArrayLike, t2: npt.ArrayLike, s: npt.ArrayLike
) -> FloatArray:
    """Points of Hermite segments at parameters ``s`` (eq. F.1).

    ``p1, p2, t1, t2``: ``(..., d)`` (broadcast together); ``s``: ``(m,)`` or scalar.
    Returns ``(..., m, d)`` (or ``(..., d)`` for a scalar ``s``).
    """
    return _combine(hermite_basis(s), p1, p2, t1, t2)


def hermite_segment_derivative(
    p1: npt.ArrayLike, p2: npt.ArrayLike, t1: npt.ArrayLike, t2: npt.ArrayLike, s: npt.ArrayLike
) -> FloatArray:
    """Derivative ``dP/ds`` of Hermite segments; same shapes as :func:`hermite_segment`."""
    return _combine(hermite_basis_derivative(s), p1, p2, t1, t2)


def _combine(
    w: FloatArray, p1: npt.ArrayLike, p2: npt.ArrayLike, t1: npt.ArrayLike, t2: npt.ArrayLike
) -> FloatArray:
    p1a, p2a, t1a, t2a = (np.asarray(v, dtype=np.float64) for v in (p1, p2, t1, t2))
    if w.ndim == 1:  # scalar s
        return w[0] * p1a + w[1] * p2a + w[2] * t1a + w[3] * t2a
    ctrl = np.stack(np.broadcast_arrays(p1a, p2a, t1a, t2a), axis=-2)  # (..., 4, d)
    return np.asarray(w @ ctrl)  # (m, 4) @ (..., 4, d) -> (..., m, d)


def cardinal_tangents(
    points: npt.ArrayLike,
    tension: float = 0.5,
    start_direction: npt.ArrayLike | None = None,
    end_direction: npt.ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Per-segment end tangents of a cardinal spline through ``points`` (eq. F.5).

    ``points``: ``(..., n, d)`` with ``n >= 2``; ``tension`` is the thesis's ``a`` in [0, 1]
    (0 gives straight segments, 0.5 Catmull-Rom). ``start_direction``/``end_direction``
    (``(..., d)``, any length) impose the direction of the curve at its two ends; by default
    the end tangents follow the first and last chords.

    Returns ``(t_start, t_end)``, each ``(..., n - 1, d)``: the tangents ``T1`` and ``T2`` of
    every segment. Coincident neighbouring points give zero tangents, never NaN.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[-2] < 2:
        raise ValueError("a curve needs at least two points")
    chords = np.diff(pts, axis=-2)  # (..., n-1, d)
    h = np.linalg.norm(chords, axis=-1)  # (..., n-1)
    # Unit-speed-ish direction at every point: chord-weighted central difference.
    direction = np.empty_like(pts)
    span = h[..., :-1] + h[..., 1:]
    inner = pts[..., 2:, :] - pts[..., :-2, :]
    direction[..., 1:-1, :] = _safe_divide(inner, span[..., None])
    direction[..., 0, :] = _safe_divide(chords[..., 0, :], h[..., 0, None])
    direction[..., -1, :] = _safe_divide(chords[..., -1, :], h[..., -1, None])
    if start_direction is not None:
        direction[..., 0, :] = _unit(np.asarray(start_direction, dtype=np.float64))
    if end_direction is not None:
        direction[..., -1, :] = _unit(np.asarray(end_direction, dtype=np.float64))
    scale = 2.0 * tension * h[..., None]  # a * (two chords) for even spacing
    return direction[..., :-1, :] * scale, direction[..., 1:, :] * scale


def _safe_divide(num: FloatArray, den: FloatArray) -> FloatArray:
    den_safe = np.where(den > 1e-12, den, 1.0)
    return np.where(den > 1e-12, num / den_safe, 0.0)


def _unit(v: FloatArray) -> FloatArray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return _safe_divide(v, n)


@dataclass(frozen=True)
class HermiteCurve:
    """A piecewise cubic Hermite curve through ``points`` with per-segment tangents.

    ``points``: ``(n, d)``; ``t_start``/``t_end``: ``(n - 1, d)``, the tangents at the start
    and the end of each segment (for a C¹ curve ``t_end[i] == t_start[i + 1]``).
    The global parameter ``t`` runs from 0 to ``n - 1``; segment ``i`` covers ``[i, i + 1]``.

    Build one with :meth:`cardinal` (automatic tangents), :meth:`from_directions` (given
    directions at every point, e.g. spine orientations) or :meth:`from_point_tangents`
    (the thesis's form with one tangent per point).
    """

    points: FloatArray
    t_start: FloatArray
    t_end: FloatArray
    samples_per_segment: int = 32
    _table_t: FloatArray = field(init=False, repr=False, compare=False)
    _table_len: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[0] < 2:
            raise ValueError(f"points must be (n >= 2, d), got {pts.shape}")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "t_start", np.asarray(self.t_start, dtype=np.float64))
        object.__setattr__(self, "t_end", np.asarray(self.t_end, dtype=np.float64))
        seg_shape = (pts.shape[0] - 1, pts.shape[1])
        if self.t_start.shape != seg_shape or self.t_end.shape != seg_shape:
            raise ValueError(f"segment tangents must be {seg_shape}")
        # Arc-length table: dense chords, refined later by one Newton step per query.
        k = max(4, int(self.samples_per_segment))
        t = np.linspace(0.0, pts.shape[0] - 1.0, (pts.shape[0] - 1) * k + 1)
        dense = self.evaluate(t)
        seg = np.linalg.norm(np.diff(dense, axis=0), axis=1)
        object.__setattr__(self, "_table_t", t)
        object.__setattr__(self, "_table_len", np.concatenate([[0.0], np.cumsum(seg)]))

    # -- construction -----------------------------------------------------------------
    @classmethod
    def cardinal(
        cls,
        points: npt.ArrayLike,
        tension: float = 0.5,
        start_direction: npt.ArrayLike | None = None,
        end_direction: npt.ArrayLike | None = None,
        samples_per_segment: int = 32,
    ) -> HermiteCurve:
        """Cardinal spline through ``points`` ``(n, d)`` with tangents from eq. F.5."""
        pts = np.asarray(points, dtype=np.float64)
        t0, t1 = cardinal_tangents(pts, tension, start_direction, end_direction)
        return cls(pts, t0, t1, samples_per_segment)

    @classmethod
    def from_directions(
        cls, points: npt.ArrayLike, directions: npt.ArrayLike, scale: float = 1.0,
        samples_per_segment: int = 32,
    ) -> HermiteCurve:
        """Curve through ``points`` ``(n, d)`` leaving each point along ``directions`` ``(n, d)``.

        Directions are normalised; each segment's tangents are the unit direction times the
        segment's chord length times ``scale`` (1.0 gives a well-rounded curve).
        """
        pts = np.asarray(points, dtype=np.float64)
        dirs = _unit(np.asarray(directions, dtype=np.float64))
        h = np.linalg.norm(np.diff(pts, axis=0), axis=1)[:, None] * scale
        return cls(pts, dirs[:-1] * h, dirs[1:] * h, samples_per_segment)

    @classmethod
    def from_point_tangents(
        cls, points: npt.ArrayLike, tangents: npt.ArrayLike, samples_per_segment: int = 32
    ) -> HermiteCurve:
        """Curve with one tangent per point ``(n, d)``, used as is (thesis eq. F.1)."""
        tan = np.asarray(tangents, dtype=np.float64)
        return cls(np.asarray(points, dtype=np.float64), tan[:-1], tan[1:], samples_per_segment)

    # -- evaluation ----------------------------------------------------------------------
    @property
    def n_segments(self) -> int:
        return int(self.points.shape[0] - 1)

    @property
    def length(self) -> float:
        """Arc length in the points' units (metres)."""
        return float(self._table_len[-1])

    def _split(self, t: npt.ArrayLike) -> tuple[npt.NDArray[np.intp], FloatArray]:
        t_arr = np.clip(np.asarray(t, dtype=np.float64), 0.0, float(self.n_segments))
        seg = np.minimum(np.floor(t_arr).astype(np.intp), self.n_segments - 1)
        return seg, t_arr - seg

    def evaluate(self, t: npt.ArrayLike) -> FloatArray:
        """Points at global parameters ``t`` ``(m,)`` in ``[0, n - 1]``: ``(m, d)``."""
        seg, s = self._split(t)
        w = hermite_basis(s)  # (m, 4)
        return (
            w[..., 0:1] * self.points[seg]
            + w[..., 1:2] * self.points[seg + 1]
            + w[..., 2:3] * self.t_start[seg]
            + w[..., 3:4] * self.t_end[seg]
        )

    def derivative(self, t: npt.ArrayLike) -> FloatArray:
        """``dP/dt`` at global parameters ``t``: ``(m, d)``."""
        seg, s = self._split(t)
        w = hermite_basis_derivative(s)
        return (
            w[..., 0:1] * self.points[seg]
            + w[..., 1:2] * self.points[seg + 1]
            + w[..., 2:3] * self.t_start[seg]
            + w[..., 3:4] * self.t_end[seg]
        )

    def param_at_length(self, arc: npt.ArrayLike) -> FloatArray:
        """Global parameters at arc lengths ``arc`` ``(m,)`` (clamped to ``[0, length]``)."""
        a = np.clip(np.asarray(arc, dtype=np.float64), 0.0, self.length)
        t = np.interp(a, self._table_len, self._table_t)
        # One Newton step on the exact curve: the table is piecewise linear in t.
        approx = np.interp(t, self._table_t, self._table_len)
        speed = np.linalg.norm(self.derivative(t), axis=-1)
        t = t + np.where(speed > 1e-12, (a - approx) / np.where(speed > 1e-12, speed, 1.0), 0.0)
        return np.clip(t, 0.0, float(self.n_segments))

    def at_length(self, arc: npt.ArrayLike) -> FloatArray:
        """Points at arc lengths ``arc`` ``(m,)`` from the start: ``(m, d)``."""
        return self.evaluate(self.param_at_length(arc))

    def at_fraction(self, u: npt.ArrayLike) -> FloatArray:
        """Points at fractions ``u`` ``(m,)`` of the arc length: constant speed in ``u``."""
        return self.at_length(np.asarray(u, dtype=np.float64) * self.length)

    def tangent_at_fraction(self, u: npt.ArrayLike) -> FloatArray:
        """Unit tangents at fractions ``u`` of the arc length: ``(m, d)``."""
        t = self.param_at_length(np.asarray(u, dtype=np.float64) * self.length)
        return _unit(self.derivative(t))

    def sample(self, spacing: float, include_end: bool = True) -> FloatArray:
        """Points every ``spacing`` of arc length from the start (and the end point)."""
        if spacing <= 0.0:
            raise ValueError("spacing must be positive")
        arcs = np.arange(0.0, self.length, spacing)
        if include_end and (arcs.size == 0 or self.length - arcs[-1] > 1e-9):
            arcs = np.append(arcs, self.length)
        return self.at_length(arcs)

    def polyline(self, samples_per_segment: int = 16) -> FloatArray:
        """Dense points, evenly spaced in the parameter: ``(n_seg * k + 1, d)``."""
        k = max(1, int(samples_per_segment))
        return self.evaluate(np.linspace(0.0, float(self.n_segments), self.n_segments * k + 1))

    def chord_walk(self, lengths: npt.ArrayLike, start_length: float = 0.0) -> FloatArray:
        """Points whose straight-line distances from one to the next are ``lengths``.

        Starts at arc length ``start_length`` and walks forward; each next point is the first
        point further along the curve at the given Euclidean distance from the previous one
        (what rigid bones laid along the curve need). If the curve ends first, the remaining
        points continue straight along the last tangent. ``lengths``: ``(k,)``; returns
        ``(k + 1, d)`` starting with the start point.
        """
        lens = np.asarray(lengths, dtype=np.float64)
        dense_t = self._table_t
        dense = self.evaluate(dense_t)
        start_t = float(self.param_at_length(start_length))
        prev = self.evaluate(np.array([start_t]))[0]
        out = [prev]
        idx = int(np.searchsorted(dense_t, start_t, side="right"))
        end_dir = _unit(self.derivative(np.array([float(self.n_segments)]))[0])
        for length in lens:
            dist = np.linalg.norm(dense[idx:] - prev, axis=1)
            beyond = np.nonzero(dist >= length)[0]
            if beyond.size == 0:
                nxt = prev + end_dir * length
                idx = dense.shape[0]
            else:
                j = idx + int(beyond[0])
                a = dense[j - 1] if j > 0 else prev
                b = dense[j]
                nxt = _segment_sphere_exit(a, b, prev, float(length))
                idx = j
            out.append(nxt)
            prev = nxt
        return np.asarray(out)


def _segment_sphere_exit(a: FloatArray, b: FloatArray, centre: FloatArray, radius: float) -> FloatArray:
    """Point on segment ``ab`` at distance ``radius`` from ``centre`` (the far solution)."""
    d = b - a
    f = a - centre
    qa = float(d @ d)
    if qa < 1e-18:
        return b.copy()
    qb = 2.0 * float(f @ d)
    qc = float(f @ f) - radius * radius
    disc = max(qb * qb - 4.0 * qa * qc, 0.0)
    s = (-qb + np.sqrt(disc)) / (2.0 * qa)
    return np.asarray(a + np.clip(s, 0.0, 1.0) * d)


def cardinal_samples(
    points: FloatArray, tension: float, spacing: float, samples_per_segment: int = 16
) -> tuple[FloatArray, FloatArray, float]:
    """Points at even arc-length steps of about ``spacing`` (both ends included) along the
    cardinal curve through ``points`` ``(n, d)``, ``n >= 2``.

    Returns ``(samples (m, d), arc (m,), length)``: exactly what
    ``HermiteCurve.cardinal(points, tension, samples_per_segment=...)`` gives with
    ``at_length(np.linspace(0, length, max(2, ceil(length / spacing) + 1)))``, with the same
    arithmetic but without building the object (a path planner samples many curves).
    """
    pts = np.asarray(points, dtype=np.float64)
    n_seg = pts.shape[0] - 1
    chords: FloatArray = pts[1:] - pts[:-1]
    h = np.sqrt(sum_last(chords * chords))
    d = pts.shape[1]
    # the control points of every segment (its two points and two tangents), one row each
    ctrl = np.empty((n_seg, 4, d))
    ctrl[:, 0] = pts[:-1]
    ctrl[:, 1] = pts[1:]
    # no coincident points: cardinal_tangents' guarded divisions are plain ones
    if np.minimum.reduce(h) > 1e-12:
        direction = np.empty_like(pts)
        direction[1:-1] = (pts[2:] - pts[:-2]) / (h[:-1] + h[1:])[:, None]
        direction[0] = chords[0] / h[0]
        direction[-1] = chords[-1] / h[-1]
        scale = 2.0 * tension * h[:, None]
        np.multiply(direction[:-1], scale, out=ctrl[:, 2])
        np.multiply(direction[1:], scale, out=ctrl[:, 3])
    else:
        ctrl[:, 2], ctrl[:, 3] = cardinal_tangents(pts, tension)
    top = float(n_seg)
    k = max(4, int(samples_per_segment))
    last = n_seg - 1

    def evaluate(t: FloatArray, deriv: bool = False) -> FloatArray:
        # the curve (or its derivative) at parameters t within [0, n_seg] (HermiteCurve's
        # clip changes nothing there): the powers of each t by the basis matrix, then the
        # segment's control points weighted by them (the same products as HermiteCurve's)
        seg = np.floor(t).astype(np.intp)
        np.minimum(seg, last, out=seg)
        s = t - seg
        if deriv:
            powers = np.empty((s.size, 3))
            powers[:, 0] = s**2
            powers[:, 1] = s
            powers[:, 2] = 1.0
            w = powers @ _HERMITE_DERIV_MATRIX
        else:
            powers = np.empty((s.size, 4))
            powers[:, 0] = s**3
            powers[:, 1] = s**2
            powers[:, 2] = s
            powers[:, 3] = 1.0
            w = powers @ HERMITE_MATRIX
        c = ctrl[seg]
        return np.asarray(w[:, 0:1] * c[:, 0] + w[:, 1:2] * c[:, 1] + w[:, 2:3] * c[:, 2]
                          + w[:, 3:4] * c[:, 3])

    table_t = linspace_to(top, n_seg * k + 1)
    dense = evaluate(table_t)
    dd: FloatArray = dense[1:] - dense[:-1]
    table_len = np.empty(table_t.size)
    table_len[0] = 0.0
    np.sqrt(sum_last(dd * dd)).cumsum(out=table_len[1:])
    length = float(table_len[-1])
    arc = linspace_to(length, max(2, math.ceil(length / spacing) + 1))
    # HermiteCurve.param_at_length: the table, then one Newton step on the exact curve.
    t = np.interp(arc, table_len, table_t)  # arc is within [0, length]: its clip changes nothing
    approx = np.interp(t, table_t, table_len)
    v = evaluate(t, True)
    speed = np.sqrt(sum_last(v * v))
    fast = speed > 1e-12
    t = t + np.where(fast, (arc - approx) / np.where(fast, speed, 1.0), 0.0)
    t = np.minimum(np.maximum(t, 0.0), top)
    return evaluate(t), arc, length
