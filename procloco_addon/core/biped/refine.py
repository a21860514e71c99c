# SPDX-License-Identifier: GPL-3.0-or-later
"""Refinement of desired footprints towards the clips' own footprints (biped thesis §3.5).

Playing the chosen clips without any correction leaves *original* footprints
``(pᴼᵢ, qᴼᵢ)``; the plan wants *desired* ones ``(pᴰᵢ, qᴰᵢ)``. For every footprint but the
fixed ones, the similarity transform of the ground plane that carries the original
neighbours ``pᴼᵢ₋₁, pᴼᵢ₊₁`` onto the desired neighbours ``pᴰᵢ₋₁, pᴰᵢ₊₁`` (a translation,
a rotation about the vertical, a uniform scale) is applied to the original footprint
``i``; the result replaces the desired footprint ``i``. Neighbours alternate feet, so
each footprint gets back the stance width and step shape of its clip while following the
desired path. Iterated (all footprints at once), with every footprint snapped back onto
its platform (and, when given, its terrace with the sole supported) after each iteration.

Each iteration moves a footprint only halfway to its mapped position (a damped Jacobi
step). Without damping, footprints of the two feet push each other back and forth: with
both neighbours displaced sideways, every footprint overshoots by the same amount in the
opposite direction, and the stance width alternates between twice and zero from one
iteration to the next.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import quat
from .surface import WalkableSurface

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def refine_step(
    orig_pos: FloatArray,
    orig_yaw: FloatArray,
    pos: FloatArray,
    yaw: FloatArray,
    fixed: BoolArray,
    damping: float = 0.5,
) -> tuple[FloatArray, FloatArray]:
    """One refinement pass: ``(N, 3)`` positions and ``(N,)`` yaws in, the same out.

    ``damping`` is the fraction of the way each footprint moves towards its mapped pose.
    """
    n = len(pos)
    new_pos = pos.copy()
    new_yaw = yaw.copy()
    if n < 3:
        return new_pos, new_yaw
    i = np.arange(1, n - 1)
    o_prev, o_next, o_cur = orig_pos[i - 1], orig_pos[i + 1], orig_pos[i]
    d_prev, d_next = pos[i - 1], pos[i + 1]
    vo = o_next[:, :2] - o_prev[:, :2]
    vd = d_next[:, :2] - d_prev[:, :2]
    lo = np.linalg.norm(vo, axis=1)
    ld = np.linalg.norm(vd, axis=1)
    ok = (lo > 1e-6) & (ld > 1e-6)
    theta = np.where(ok, np.arctan2(vd[:, 1], vd[:, 0]) - np.arctan2(vo[:, 1], vo[:, 0]), 0.0)
    scale = np.where(ok, ld / np.maximum(lo, 1e-6), 1.0)
    rel = o_cur - o_prev
    moved = d_prev[:, :2] + scale[:, None] * quat.rot2(theta, rel[:, :2])
    z = d_prev[:, 2] + rel[:, 2]
    cand = np.column_stack((moved, z))
    cand_yaw = orig_yaw[i] + quat.wrap_angle(theta)
    move = ~fixed[i]
    j = i[move]
    new_pos[j] = pos[j] + damping * (cand[move] - pos[j])
    new_yaw[j] = yaw[j] + damping * quat.wrap_angle(cand_yaw[move] - yaw[j])
    return new_pos, new_yaw


def refine(
    orig_pos: FloatArray,
    orig_yaw: FloatArray,
    pos: FloatArray,
    yaw: FloatArray,
    fixed: BoolArray,
    island: IntArray,
    surface: WalkableSurface | None,
    iterations: int = 10,
    terrace: IntArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``iterations`` refinement passes with snapping (thesis: about 10 suffice);
    ``terrace (N,)``: see :func:`.smoothing.smooth_footprints`."""
    pos = pos.copy()
    yaw = yaw.copy()
    move = ~fixed
    ter = None if terrace is None else terrace[move]
    for _ in range(iterations):
        pos, yaw = refine_step(orig_pos, orig_yaw, pos, yaw, fixed)
        if surface is not None:
            sole = None if ter is None else yaw[move]
            pos[move] = surface.snap(pos[move], island[move], exact=False, yaw=sole, terrace=ter)
    if surface is not None and iterations > 0:
        sole = None if ter is None else yaw[move]
        pos[move, 2] = surface.snap(pos[move], island[move], yaw=sole, terrace=ter)[:, 2]  # exact heights
    return pos, yaw
