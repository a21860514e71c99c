# SPDX-License-Identifier: GPL-3.0-or-later
"""Body trajectory from footprint midpoints (biped thesis §3.6).

A good estimate of where the body is, is halfway between two consecutive footprints. The
midpoints ``mᵢ`` of the *original* footprints (those the clips leave when played without
correction) and of the *desired* ones are each interpolated in time by a centripetal
Catmull-Rom spline ``M(t)``, and their headings by spherical interpolation ``M_q(t)``.
The played body trajectory ``Rᴼ(t), Qᴼ(t)`` is expressed in the moving frame of the
original midpoint curve (the *displacement* ``D``) and re-applied in the frame of the
desired one:

    D_p = M_qᴼ⁻¹ (Rᴼ − Mᴼ),  D_q = M_qᴼ⁻¹ Qᴼ,   Rᴰ = M_qᴰ D_p + Mᴰ,  Qᴰ = M_qᴰ D_q

The character's root turns about the vertical only, so rotations here are headings and
slerp is a linear interpolation of the (unwrapped) angle, which is exact for them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import quat
from .splines import catmull_rom

FloatArray = NDArray[np.float64]


def midpoints(
    pos: FloatArray, yaw: FloatArray, time: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Midpoints of consecutive footprints: positions ``(N-1, 3)``, headings, times."""
    m = 0.5 * (pos[:-1] + pos[1:])
    my = yaw[:-1] + 0.5 * quat.wrap_angle(yaw[1:] - yaw[:-1])
    mt = 0.5 * (time[:-1] + time[1:])
    return m, np.unwrap(my), mt


def midpoint_curve(
    pos: FloatArray, yaw: FloatArray, time: FloatArray, t: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``M(t) (F, 3)`` and ``M_q(t) (F,)`` through the midpoints of the footprints."""
    m, my, mt = midpoints(pos, yaw, time)
    order = np.argsort(mt, kind="stable")
    m, my, mt = m[order], my[order], mt[order]
    curve = catmull_rom(m, mt, t)
    k = (
        np.clip(np.searchsorted(mt, t, side="right") - 1, 0, len(mt) - 2)
        if len(mt) > 1
        else np.zeros(len(t), int)
    )
    if len(mt) > 1:
        span = np.maximum(mt[k + 1] - mt[k], 1e-12)
        a = np.clip((t - mt[k]) / span, 0.0, 1.0)
        heading = my[k] + a * (my[k + 1] - my[k])
    else:
        heading = np.full(len(t), my[0])
    return curve, heading


def transfer(
    t: FloatArray,
    root_pos: FloatArray,
    root_yaw: FloatArray,
    fp_time: FloatArray,
    orig_pos: FloatArray,
    orig_yaw: FloatArray,
    want_pos: FloatArray,
    want_yaw: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Carry the played body trajectory from the original footprints to the desired ones.

    ``t (F,)``, ``root_pos (F, 3)``, ``root_yaw (F,)``: the played root; footprints ``(N, 3)``
    and ``(N,)`` with their stance times ``fp_time (N,)``. Returns ``(pos (F, 3), yaw (F,))``.
    """
    mo, qo = midpoint_curve(orig_pos, orig_yaw, fp_time, t)
    md, qd = midpoint_curve(want_pos, want_yaw, fp_time, t)
    d_p = quat.rot2(-qo, root_pos - mo)
    d_q = root_yaw - qo
    return md + quat.rot2(qd, d_p), qd + d_q
