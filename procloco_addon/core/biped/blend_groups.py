# SPDX-License-Identifier: GPL-3.0-or-later
"""Blend groups: turning by curvature and walk/run by speed (biped thesis §3.7).

*Turning* (§3.7.1). Walks (and runs) in a database turn by a few fixed curvatures
``τᵢ = 1/rᵢ``. Chaining them approximates an arc clumsily (forward, forward, right, ...);
instead every walk segment is replaced by the whole walk group, blended at the path's own
curvature. The curvature at each frame is that of the circle through the body trajectory
a fraction of a second before, now, and after; a least-squares B-spline low-passes it (the
sway of a walk would otherwise make the character weave). The two clips whose ``τᵢ``
bracket ``τ(t)`` share the weight linearly; outside the group's range the nearest clip
takes it all.

*Speed* (§3.7.2). Walks and runs blend freely through ``s`` (0 walk, 1 run). Special clips
fix ``s`` where they start and end (a running jump: 1; start and stop: 0), as do the ends
of the animation; in between, ``s`` relaxes to walking over ``σ`` strides, unless two
fixed values are too close for that, where it goes linearly from one to the other.
Distances are in *normalised time*, here segment coordinates (strides).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .splines import bspline_fit

FloatArray = NDArray[np.float64]


def circle_curvature(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    """Signed curvature ``1/R`` of the circle through three ground points ``(..., 2+)``.

    Positive when ``a → b → c`` turns left (counter-clockwise); zero for collinear points.
    """
    ab = b[..., :2] - a[..., :2]
    bc = c[..., :2] - b[..., :2]
    ca = a[..., :2] - c[..., :2]
    cross = ab[..., 0] * bc[..., 1] - ab[..., 1] * bc[..., 0]
    den = np.linalg.norm(ab, axis=-1) * np.linalg.norm(bc, axis=-1) * np.linalg.norm(ca, axis=-1)
    return np.where(den > 1e-12, 2.0 * cross / np.maximum(den, 1e-300), 0.0)


def path_curvature(t: FloatArray, pos: FloatArray, window: float = 0.4) -> FloatArray:
    """Curvature ``τ(t) (F,)`` of a trajectory ``pos (F, 3)`` from the circle through
    ``R(t − window)``, ``R(t)``, ``R(t + window)``. Near the ends the three times slide
    inwards so that they stay ``window`` apart inside the trajectory."""
    span = min(2.0 * window, float(t[-1] - t[0]))
    ta = np.clip(t - 0.5 * span, t[0], t[-1] - span)
    tb = ta + span
    tm = 0.5 * (ta + tb)

    def at(x: FloatArray) -> FloatArray:
        return np.column_stack([np.interp(x, t, pos[:, i]) for i in range(2)])

    return circle_curvature(at(ta), at(tm), at(tb))


def lowpass(t: FloatArray, values: FloatArray, spacing: float) -> FloatArray:
    """B-spline low-pass filter of ``values (F,)``; ``spacing`` is the knot spacing (s)."""
    return bspline_fit(t, values, spacing)(t)[:, 0]


def turning_weights(tau: FloatArray, clip_tau: FloatArray) -> FloatArray:
    """Weights ``(M, G)`` of a group's clips (curvatures ``clip_tau (G,)``) at ``tau (M,)``."""
    order = np.argsort(clip_tau)
    ct = clip_tau[order]
    m = len(tau)
    w = np.zeros((m, len(ct)))
    if len(ct) == 1:
        w[:, 0] = 1.0
    else:
        x = np.clip(tau, ct[0], ct[-1])
        j = np.clip(np.searchsorted(ct, x, side="right") - 1, 0, len(ct) - 2)
        span = np.maximum(ct[j + 1] - ct[j], 1e-12)
        a = np.clip((x - ct[j]) / span, 0.0, 1.0)
        rows = np.arange(m)
        w[rows, j] = 1.0 - a
        w[rows, j + 1] += a
    out = np.zeros_like(w)
    out[:, order] = w
    return out


def speed_parameter(
    u: FloatArray, fixed_u: FloatArray, fixed_s: FloatArray, sigma: float = 2.0
) -> FloatArray:
    """Walk/run parameter ``s(u)`` between fixed values (thesis §3.7.2, σ in strides).

    Between fixed points ``(u₁, s₁)`` and ``(u₂, s₂)``, with ``d₁ = u − u₁`` and
    ``d₂ = u₂ − u``: linear interpolation if ``d₁ + d₂ < 2σ(s₁ + s₂)``, otherwise
    ``max(0, s₁(σ − d₁)/σ, s₂(σ − d₂)/σ)``. Outside the fixed points ``s`` holds.
    """
    order = np.argsort(fixed_u, kind="stable")
    fu = np.asarray(fixed_u, dtype=float)[order]
    fs = np.asarray(fixed_s, dtype=float)[order]
    s = np.interp(u, fu, fs)
    if len(fu) < 2:
        return s
    j = np.clip(np.searchsorted(fu, u, side="right") - 1, 0, len(fu) - 2)
    u1, u2, s1, s2 = fu[j], fu[j + 1], fs[j], fs[j + 1]
    d1 = u - u1
    d2 = u2 - u
    total = np.maximum(d1 + d2, 1e-12)
    linear = (s1 * d2 + s2 * d1) / total
    relax = np.maximum.reduce([np.zeros_like(u), s1 * (sigma - d1) / sigma, s2 * (sigma - d2) / sigma])
    inside = (u >= fu[0]) & (u <= fu[-1])
    return np.where(inside, np.where(d1 + d2 < 2 * sigma * (s1 + s2), linear, relax), s)
