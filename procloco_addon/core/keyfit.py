# SPDX-License-Identifier: GPL-3.0-or-later
"""Key reduction: keys only where they are needed, with Bézier handles fitted so that the
curves stay within a tolerance of densely sampled values.

A generated Action holds a key on every frame of every channel; an animator cannot retime
or edit that by hand. :func:`fit_keys` keeps a subset of the sampled frames as keys (every
frame a caller *requires*, such as a foot's touch-down and lift-off, and the first and last
frame) and gives each kept key a left and a right slope, so that Blender's Bézier
interpolation between the keys reproduces every sample within its tolerance.

How: channels are fitted in *groups* that share their key frames (all the channels of one
bone, so a bone's keys line up for editing). A group starts with its required keys; each
segment between two keys gets, per channel, the two end slopes that fit the samples inside it
best (linear least squares on the cubic Hermite basis, with the key values fixed to the
samples); a segment whose worst sample is off by more than its tolerance is split at that
sample (a Douglas-Peucker subdivision with cubic segments), until every segment fits.

The handles are placed a third of the way to the neighbouring key in time
(:func:`bezier_points`), so Blender's Bézier segment is exactly the cubic Hermite curve with
those slopes (its time coordinate runs linearly in the curve parameter) and no handle is ever
corrected away. :func:`evaluate_bezier` evaluates keys and handles the way Blender's F-curves
do (handle correction, the time cubic solved for the parameter), so the tests check the fit
against what Blender will play, not against the fitting's own formula.

Units: frames for time (the samples' own numbers), the channel's own units for values.
Shapes: ``frames`` ``(F,)``; ``values`` ``(F, C)``; ``groups`` ``(C,)`` group index per
channel, ``0 .. G - 1``; ``required`` ``(F, G)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "BezierCurve",
    "KeyFit",
    "bezier_points",
    "evaluate_bezier",
    "evaluate_fit",
    "fit_keys",
]

#: Pulls a segment's two slopes towards its chord when the samples inside it cannot decide
#: them (one sample for two slopes), relative to the basis' own scale.
_RIDGE = 1e-12


@dataclass(frozen=True)
class KeyFit:
    """Which frames are keys per group, and each key's slopes per channel.

    keys: ``(F, G)`` bool, frame ``f`` is a key of group ``g``; left, right: ``(F, C)`` the
    slope (value per frame) of the curve arriving at and leaving each key (NaN where the
    frame is not a key of the channel's group; ``left`` of the first and ``right`` of the
    last key extend their neighbour's).
    """

    keys: np.ndarray
    left: np.ndarray
    right: np.ndarray
    groups: np.ndarray

    @property
    def key_count(self) -> int:
        """Keyframes over all channels (a group's keys count once per channel)."""
        per_group = self.keys.sum(axis=0)
        return int(per_group[self.groups].sum())


@dataclass(frozen=True)
class BezierCurve:
    """One F-curve's keys as Blender stores them: points and handles ``(K, 2)`` each, as
    ``(frame, value)``."""

    co: np.ndarray
    handle_left: np.ndarray
    handle_right: np.ndarray


def _fit_segment(x: np.ndarray, y: np.ndarray, tol: np.ndarray,
                 step: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Best end slopes of one segment and how badly it still fits.

    x: ``(n,)`` frames from one key to the next (both included); y, tol: ``(n, c)``; step:
    ``(n, c)`` or None, ``step[i]`` bounds how much the error may change from sample ``i``
    to ``i + 1``. Returns ``(m0, m1, worst_index, worst_ratio)``: slopes ``(c,)`` leaving the
    first and arriving at the last key, the interior sample that fits worst (index into
    ``x``) and its error over its tolerance (0 when there is no interior sample).
    """
    h = x[-1] - x[0]
    chord = (y[-1] - y[0]) / h
    if x.size <= 2:
        return chord, chord, 0, 0.0
    u = (x[1:-1] - x[0]) / h
    u2 = u * u
    u3 = u2 * u
    a0 = h * (u3 - 2.0 * u2 + u)  # h * h10
    a1 = h * (u3 - u2)  # h * h11
    h01 = 3.0 * u2 - 2.0 * u3
    # y(u) = h00 y0 + h01 y1 + h (h10 m0 + h11 m1) with h00 = 1 - h01: with m = chord + d the
    # unknowns d enter linearly, the rest is known. The 2 x 2 normal equations are solved in
    # closed form (the subdivision calls this thousands of times: few numpy calls, no LAPACK).
    s00 = float(a0 @ a0)
    s01 = float(a0 @ a1)
    s11 = float(a1 @ a1)
    ridge = _RIDGE * max(s00 + s11, 1e-300)
    s00 += ridge
    s11 += ridge
    det = s00 * s11 - s01 * s01
    if y.shape[1] == 1:  # one channel: 1-D arithmetic
        y0, y1, c = float(y[0, 0]), float(y[-1, 0]), float(chord[0])
        r1 = y[1:-1, 0] - (y0 + h01 * (y1 - y0) + (a0 + a1) * c)
        b0, b1 = float(a0 @ r1), float(a1 @ r1)
        e0 = (s11 * b0 - s01 * b1) / det
        e1 = (s00 * b1 - s01 * b0) / det
        err = a0 * e0 + a1 * e1 - r1
        ratio = np.abs(err) / tol[1:-1, 0]
        if step is not None:
            ratio = np.maximum(ratio, _step_ratio(err[:, None], step)[:, 0])
        worst = int(np.argmax(ratio))
        return np.array([c + e0]), np.array([c + e1]), worst + 1, float(ratio[worst])
    r = y[1:-1] - (y[0] + h01[:, None] * (y[-1] - y[0]) + (a0 + a1)[:, None] * chord)
    b0 = a0 @ r
    b1 = a1 @ r
    d0 = (s11 * b0 - s01 * b1) / det
    d1 = (s00 * b1 - s01 * b0) / det
    err2 = a0[:, None] * d0 + a1[:, None] * d1 - r
    ratio2 = np.abs(err2) / tol[1:-1]
    if step is not None:
        ratio2 = np.maximum(ratio2, _step_ratio(err2, step))
    ratio = np.max(ratio2, axis=1)
    worst = int(np.argmax(ratio))
    return chord + d0, chord + d1, worst + 1, float(ratio[worst])


def _step_ratio(err: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Per interior sample ``(n - 2, c)``, the larger change of the error ``err`` ``(n - 2, c)``
    (zero at both keys) to or from it, over the step tolerance ``step`` ``(n, c)`` of that pair."""
    full = np.zeros((err.shape[0] + 2, err.shape[1]))
    full[1:-1] = err
    change = np.abs(np.diff(full, axis=0)) / step[:-1]  # (n - 1, c): pair i -> i + 1
    return np.maximum(change[:-1], change[1:])


def fit_keys(
    frames: np.ndarray,
    values: np.ndarray,
    tolerance: np.ndarray | float,
    groups: np.ndarray | None = None,
    required: np.ndarray | None = None,
    step_tolerance: np.ndarray | float | None = None,
) -> KeyFit:
    """Keys and slopes that keep every sample within its tolerance (see the module doc).

    frames: ``(F,)`` strictly increasing; values: ``(F, C)``; tolerance: broadcastable to
    ``(F, C)``, > 0 (per frame and channel: a caller can tighten it where a check on the
    posed rig asks for it); groups: ``(C,)`` ints ``0 .. G - 1`` (default: one group per
    channel); required: ``(F, G)`` bool, frames that must be keys; step_tolerance:
    broadcastable to ``(F, C)``, > 0 (``inf`` where free), how much a channel's error may
    change from frame ``f`` to ``f + 1`` (a planted foot that must not jitter). The first and
    last frame are always keys. Returns a :class:`KeyFit`.
    """
    x = np.asarray(frames, dtype=np.float64).reshape(-1)
    y = np.asarray(values, dtype=np.float64)
    if y.ndim == 1:
        y = y[:, None]
    n_frames, n_channels = y.shape
    if x.shape[0] != n_frames:
        raise ValueError(f"{x.shape[0]} frames for {n_frames} samples")
    if n_frames > 1 and not np.all(np.diff(x) > 0):
        raise ValueError("frames must be strictly increasing")
    if not np.all(np.isfinite(y)):
        raise ValueError("values must be finite")
    tol = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (n_frames, n_channels))
    if not np.all(tol > 0):
        raise ValueError("tolerances must be positive")
    step = None
    if step_tolerance is not None:
        step = np.broadcast_to(np.asarray(step_tolerance, dtype=np.float64), (n_frames, n_channels))
        if not np.all(step > 0):
            raise ValueError("step tolerances must be positive")
    g = np.arange(n_channels) if groups is None else np.asarray(groups, dtype=np.int64).reshape(-1)
    if g.shape[0] != n_channels:
        raise ValueError(f"{g.shape[0]} group numbers for {n_channels} channels")
    n_groups = int(g.max()) + 1 if n_channels else 0
    keys = np.zeros((n_frames, n_groups), dtype=bool)
    required_mask = np.zeros((n_frames, n_groups), dtype=bool)
    if required is not None:
        required_mask = np.asarray(required, dtype=bool).reshape(n_frames, n_groups)
        keys |= required_mask
    if n_frames:
        keys[[0, -1]] = True
    left = np.full((n_frames, n_channels), np.nan)
    right = np.full((n_frames, n_channels), np.nan)
    for grp in range(n_groups):
        cols = np.flatnonzero(g == grp)
        if cols.size == 0:
            continue
        yg, tg = y[:, cols], tol[:, cols]
        sg = None if step is None else step[:, cols]
        todo = list(zip(np.flatnonzero(keys[:, grp])[:-1], np.flatnonzero(keys[:, grp])[1:], strict=True))
        while todo:
            a, b = todo.pop()
            m0, m1, worst, ratio = _fit_segment(x[a:b + 1], yg[a:b + 1], tg[a:b + 1],
                                                None if sg is None else sg[a:b + 1])
            if ratio > 1.0:
                mid = a + worst
                keys[mid, grp] = True
                todo += [(a, mid), (mid, b)]
                continue
            right[a, cols] = m0
            left[b, cols] = m1
        _merge(x, yg, tg, sg, keys[:, grp], required_mask[:, grp], left, right, cols)
        if n_frames == 1:
            left[0, cols] = right[0, cols] = 0.0
        else:
            first, last = np.flatnonzero(keys[:, grp])[[0, -1]]
            left[first, cols] = right[first, cols]
            right[last, cols] = left[last, cols]
    return KeyFit(keys, left, right, g)


def _merge(x: np.ndarray, y: np.ndarray, tol: np.ndarray, step: np.ndarray | None, keys: np.ndarray,
           required: np.ndarray, left: np.ndarray, right: np.ndarray, cols: np.ndarray) -> None:
    """Drop the keys the subdivision made that its neighbours can do without: each key in
    turn (not a required one, not the ends) is removed when the segment joining its two
    neighbours still fits; ``keys`` ``(F,)`` and the slopes are updated in place."""
    kept = list(np.flatnonzero(keys))
    i = 1
    while i < len(kept) - 1:
        a, k, b = kept[i - 1], kept[i], kept[i + 1]
        if required[k]:
            i += 1
            continue
        m0, m1, _worst, ratio = _fit_segment(x[a:b + 1], y[a:b + 1], tol[a:b + 1],
                                             None if step is None else step[a:b + 1])
        if ratio > 1.0:
            i += 1
            continue
        keys[k] = False
        left[k, cols] = right[k, cols] = np.nan
        right[a, cols] = m0
        left[b, cols] = m1
        del kept[i]


def bezier_points(frames: np.ndarray, values: np.ndarray, fit: KeyFit, channel: int) -> BezierCurve:
    """Channel ``channel`` of ``fit`` as Blender keys and handles.

    Each handle lies a third of the way to the neighbouring key in time (at the first and
    last key, a third of the way to the one beside), so the Bézier segment is the Hermite
    curve with the fitted slopes.
    """
    x = np.asarray(frames, dtype=np.float64).reshape(-1)
    y = np.asarray(values, dtype=np.float64)
    if y.ndim == 1:
        y = y[:, None]
    k = np.flatnonzero(fit.keys[:, fit.groups[channel]])
    kx, ky = x[k], y[k, channel]
    if k.size == 1:
        gap_before = gap_after = np.ones(1)
    else:
        gaps = np.diff(kx)
        gap_before = np.concatenate([gaps[:1], gaps])
        gap_after = np.concatenate([gaps, gaps[-1:]])
    co = np.stack([kx, ky], axis=1)
    left_dx = gap_before / 3.0
    right_dx = gap_after / 3.0
    hl = np.stack([kx - left_dx, ky - fit.left[k, channel] * left_dx], axis=1)
    hr = np.stack([kx + right_dx, ky + fit.right[k, channel] * right_dx], axis=1)
    return BezierCurve(co, hl, hr)


def _correct_handles(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray,
                     p3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Blender's ``BKE_fcurve_correct_bezpart``: a handle ``p1`` or ``p2`` ``(n, 2)`` reaching
    further in time than the segment is long is shortened (keeping its direction) to the
    segment's length, so it does not pass the other key."""
    span = (p3[:, 0] - p0[:, 0])[:, None]
    h1 = p0 - p1
    h2 = p3 - p2
    len1 = np.abs(h1[:, :1])
    len2 = np.abs(h2[:, :1])
    fac1 = np.where(len1 > span, span / np.where(len1 > span, len1, 1.0), 1.0)
    fac2 = np.where(len2 > span, span / np.where(len2 > span, len2, 1.0), 1.0)
    return p0 - fac1 * h1, p3 - fac2 * h2


def _bezier(c0: np.ndarray, c1: np.ndarray, c2: np.ndarray, c3: np.ndarray, t: np.ndarray) -> np.ndarray:
    s = 1.0 - t
    return s * s * s * c0 + 3.0 * s * s * t * c1 + 3.0 * s * t * t * c2 + t * t * t * c3


def evaluate_bezier(curve: BezierCurve, x: np.ndarray) -> np.ndarray:
    """Values ``(n,)`` of the F-curve ``curve`` (all keys Bézier) at frames ``x`` ``(n,)``,
    as Blender evaluates it: constant before the first and after the last key; within a
    segment, the handles corrected so neither passes the other key, the parameter found where
    the segment's time cubic equals the frame, and the value cubic taken there. The time
    cubic must rise through the segment (it does for every curve :func:`bezier_points`
    makes; Blender too takes one root where it does not)."""
    xq = np.asarray(x, dtype=np.float64).reshape(-1)
    co = np.asarray(curve.co, dtype=np.float64)
    hl = np.asarray(curve.handle_left, dtype=np.float64)
    hr = np.asarray(curve.handle_right, dtype=np.float64)
    out = np.empty(xq.shape)
    before = xq <= co[0, 0]
    after = xq >= co[-1, 0]
    out[before] = co[0, 1]
    out[after & ~before] = co[-1, 1]
    inside = ~(before | after)
    if not np.any(inside):
        return out
    xi = xq[inside]
    seg = np.clip(np.searchsorted(co[:, 0], xi, side="right") - 1, 0, len(co) - 2)
    p0, p3 = co[seg], co[seg + 1]
    p1, p2 = _correct_handles(p0, hr[seg], hl[seg + 1], p3)
    # The time cubic rises through the segment: bisection brackets the root and
    # Newton steps polish it (Blender solves the cubic in closed form; both find the one root
    # in [0, 1] to well below a millionth of a frame).
    lo = np.zeros(xi.shape)
    hi = np.ones(xi.shape)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        below = _bezier(p0[:, 0], p1[:, 0], p2[:, 0], p3[:, 0], mid) < xi
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    t = 0.5 * (lo + hi)
    for _ in range(3):
        s = 1.0 - t
        fx = _bezier(p0[:, 0], p1[:, 0], p2[:, 0], p3[:, 0], t) - xi
        dx = 3.0 * (s * s * (p1[:, 0] - p0[:, 0]) + 2.0 * s * t * (p2[:, 0] - p1[:, 0])
                    + t * t * (p3[:, 0] - p2[:, 0]))
        step = np.where(np.abs(dx) > 1e-12, fx / np.where(np.abs(dx) > 1e-12, dx, 1.0), 0.0)
        t = np.clip(t - step, 0.0, 1.0)
    out[inside] = _bezier(p0[:, 1], p1[:, 1], p2[:, 1], p3[:, 1], t)
    return out


def evaluate_fit(frames: np.ndarray, values: np.ndarray, fit: KeyFit,
                 at: np.ndarray | None = None, float32: bool = False) -> np.ndarray:
    """Every channel of ``fit`` evaluated as Blender would at frames ``at`` (default: the
    sampled frames): ``(n, C)``. ``float32``: round keys and handles as Blender stores them."""
    x = np.asarray(frames, dtype=np.float64).reshape(-1)
    xq = x if at is None else np.asarray(at, dtype=np.float64).reshape(-1)
    y = np.asarray(values, dtype=np.float64)
    if y.ndim == 1:
        y = y[:, None]
    out = np.empty((xq.size, y.shape[1]))
    for c in range(y.shape[1]):
        curve = bezier_points(x, y, fit, c)
        if float32:
            curve = BezierCurve(*(a.astype(np.float32).astype(np.float64)
                                  for a in (curve.co, curve.handle_left, curve.handle_right)))
        out[:, c] = evaluate_bezier(curve, xq)
    return out
