# SPDX-License-Identifier: GPL-3.0-or-later
"""Binomial smoothing of a footprint sequence (biped thesis §3.3).

One iteration replaces each position by the (1, 4, 6, 4, 1)/16 binomial average of itself
and its four neighbours, and each rotation by the same average taken on the logarithms of
the relative rotations ``ωᵢ = log(qᵢ⁻¹ qᵢ₊₁)``:

    q'ᵢ = qᵢ · exp((−ωᵢ₋₂ − 5ωᵢ₋₁ + 5ωᵢ + ωᵢ₊₁) / 16)

(For rotations about one axis this is exactly the binomial average of the angles; the
thesis prints the same weights shifted by one index, which is not.) After every iteration
the footprints are snapped back onto their own platform of the walkable surface — and, when
their terraces are given, onto their own terrace (the tread of a stair they were planned on)
with the whole sole supported at the smoothed heading.

Left and right footprints are smoothed as two separate sequences: averaging across feet
would pull both onto the centre line between them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import quat
from .surface import WalkableSurface

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

_KERNEL = np.array([1.0, 4.0, 6.0, 4.0, 1.0]) / 16.0


def smooth_positions(p: FloatArray, fixed: BoolArray | None = None) -> FloatArray:
    """One binomial pass over ``p (N, D)``; the sequence is padded by repeating its ends."""
    pad = np.concatenate((p[:1], p[:1], p, p[-1:], p[-1:]))
    out = sum(_KERNEL[k] * pad[k : k + len(p)] for k in range(5))
    assert isinstance(out, np.ndarray)
    if fixed is not None:
        out = np.where(fixed[:, None], p, out)
    return out


def smooth_rotations(q: FloatArray, fixed: BoolArray | None = None) -> FloatArray:
    """One binomial pass over unit quaternions ``q (N, 4)`` through their relative logarithms."""
    omega = quat.log(quat.mul(quat.conj(q[:-1]), q[1:]))  # (N-1, 3): ω_i for i = 0..N-2
    zero = np.zeros((2, 3))
    om = np.concatenate((zero, omega, zero))  # om[i + 2] = ω_i, zero beyond the ends
    n = len(q)
    i = np.arange(n)
    delta = (-om[i] - 5.0 * om[i + 1] + 5.0 * om[i + 2] + om[i + 3]) / 16.0
    out = quat.normalize(quat.mul(q, quat.exp(delta)))
    if fixed is not None:
        out = np.where(fixed[:, None], q, out)
    return out


def smooth_footprints(
    pos: FloatArray,
    yaw: FloatArray,
    side: IntArray,
    fixed: BoolArray,
    island: IntArray,
    surface: WalkableSurface | None,
    iterations: int = 4,
    terrace: IntArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Smooth footprints ``pos (N, 3)`` / ``yaw (N,)``, each foot's sequence on its own.

    ``fixed (N,)`` footprints do not move (the start and goal stances); ``island (N,)`` is
    the platform each footprint must stay on when snapped to ``surface``, ``terrace (N,)``
    (optional) the terrace, with the sole supported.
    """
    pos = pos.copy()
    q = quat.from_yaw(yaw)
    move = ~fixed
    for _ in range(iterations):
        for s in (0, 1):
            idx = np.flatnonzero(side == s)
            if len(idx) < 3:
                continue
            pos[idx] = smooth_positions(pos[idx], fixed[idx])
            q[idx] = smooth_rotations(q[idx], fixed[idx])
        if surface is not None:
            pos[move] = _snap(surface, pos, q, move, island, terrace, exact=False)
    if surface is not None and iterations > 0:
        pos[move, 2] = _snap(surface, pos, q, move, island, terrace, exact=True)[:, 2]
    new_yaw = yaw + quat.wrap_angle(quat.yaw_of(q) - yaw)
    return pos, new_yaw


def _snap(
    surface: WalkableSurface,
    pos: FloatArray,
    q: FloatArray,
    move: BoolArray,
    island: IntArray,
    terrace: IntArray | None,
    exact: bool,
) -> FloatArray:
    """The moving footprints snapped (with their soles when the terraces are known)."""
    if terrace is None:
        return surface.snap(pos[move], island[move], exact=exact)
    yaw = quat.yaw_of(q[move])
    return surface.snap(pos[move], island[move], exact=exact, yaw=yaw, terrace=terrace[move])
