# SPDX-License-Identifier: GPL-3.0-or-later
"""Game-ready loops: whole gait cycles cut from a steady walk, closed exactly.

A walk on flat ground at a constant speed and gait settles, after a few cycles, into a
motion that repeats every gait cycle moved on by one stride. Make Cycle (the Blender
shell's ``cycle`` feature) simulates such a walk with a warm-up, finds the first whole
cycle from which it repeats (:func:`steady_start`), cuts ``N`` cycles from there and
closes the loop exactly: what is left of the difference between the last frame and the
first one stride later is spread evenly over the frames (:func:`close_points`,
:func:`close_rotations`), so the last frame is the first one moved by ``N`` strides. The
root motion is then taken off (:func:`remove_drift`) for an in-place cycle, or kept on a
root bone.

A loop can only close on a whole number of frames: :func:`whole_period` rounds the gait's
cycle to whole frames and gives the factor by which the cycle time is stretched (and the
speed divided, so the stride stays what it was).

Shapes: ``F`` frames, ``M`` points; points ``(F, M, 3)``, rotations ``(F, M, 3, 3)``;
``drift`` ``(3,)`` is the motion of the whole loop (``N`` strides).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = [
    "close_points",
    "close_rotations",
    "loop_error",
    "remove_drift",
    "rotation_exp",
    "rotation_log",
    "steady_start",
    "stride_of",
    "whole_period",
]

FloatArray = npt.NDArray[np.float64]

#: Shortest loop cycle accepted, in frames: fewer cannot show a foot lifting and landing.
MIN_PERIOD_FRAMES = 4


def whole_period(cycle_time: float, fps: float) -> tuple[int, float]:
    """Frames per cycle ``P`` (the nearest whole number to ``cycle_time * fps``) and the
    factor ``k = P / (cycle_time * fps)`` by which the cycle time is stretched to fill them.

    Raises ``ValueError`` when the cycle is shorter than :data:`MIN_PERIOD_FRAMES` frames.
    """
    frames = cycle_time * fps
    if not (math.isfinite(frames) and frames > 0.0):
        raise ValueError(f"a gait cycle of {cycle_time!r} s at {fps!r} fps has no length")
    period = round(frames)
    if period < MIN_PERIOD_FRAMES:
        raise ValueError(f"one gait cycle lasts {frames:.2f} frames at {fps:g} fps; a loop needs at least "
                         f"{MIN_PERIOD_FRAMES}: slow the gait down (longer cycle time, lower speed)")
    return period, period / frames


def stride_of(points: FloatArray, period: int, start: int, cycles: int) -> FloatArray:
    """The mean motion ``(3,)`` of ``points`` ``(F, M, 3)`` over one cycle of ``period``
    frames, measured over ``cycles`` cycles from frame ``start``."""
    p = np.asarray(points, dtype=np.float64)
    end = start + cycles * period
    return np.asarray((p[end] - p[start]).mean(axis=0) / cycles)


def loop_error(points: FloatArray, period: int, start: int, cycles: int) -> float:
    """How far ``points`` ``(F, M, 3)`` are from repeating, moved on by one stride, from each
    cycle of ``period`` frames to the next, over ``cycles`` cycles from ``start``: the
    largest distance (m) between a point and the same point one cycle later less the
    stride. Needs one cycle beyond the loop: ``start + (cycles + 1) * period < F``."""
    p = np.asarray(points, dtype=np.float64)
    end = start + cycles * period
    if end + period > p.shape[0] - 1:
        raise ValueError("the walk is shorter than the loop and one more cycle")
    stride = stride_of(p, period, start, cycles)
    later = p[start + period:end + period + 1] - p[start:end + 1] - stride
    return float(np.sqrt(np.einsum("...i,...i->...", later, later)).max())


def steady_start(points: FloatArray, period: int, cycles: int, tolerance: float,
                 earliest: int = 1) -> tuple[int, float]:
    """The first frame ``s = j * period`` (``j >= earliest``) from which ``points``
    ``(F, M, 3)`` repeat within ``tolerance`` (m, :func:`loop_error`) for ``cycles`` cycles,
    and that error; ``(-1, smallest error seen)`` when no start in the walk does."""
    p = np.asarray(points, dtype=np.float64)
    best = math.inf
    j = earliest
    while (j + cycles + 1) * period <= p.shape[0] - 1:
        err = loop_error(p, period, j * period, cycles)
        if err <= tolerance:
            return j * period, err
        best = min(best, err)
        j += 1
    return -1, best


def close_points(points: FloatArray, drift: npt.ArrayLike) -> FloatArray:
    """``points`` ``(F, M, 3)`` with the loop's closing error (``points[-1] - points[0] -
    drift``) spread evenly over the frames, none at the first: the last frame is exactly the
    first moved by ``drift`` ``(3,)``."""
    p = np.asarray(points, dtype=np.float64)
    d = np.asarray(drift, dtype=np.float64)
    error = p[-1] - p[0] - d
    weight = np.linspace(0.0, 1.0, p.shape[0]).reshape((-1,) + (1,) * (p.ndim - 1))
    out: FloatArray = p - weight * error
    out[-1] = out[0] + d
    return out


def remove_drift(points: FloatArray, drift: npt.ArrayLike,
                 origin_shift: npt.ArrayLike | None = None) -> FloatArray:
    """``points`` ``(F, M, 3)`` with the root motion taken off: frame ``f`` moved back by
    ``f / (F - 1)`` of ``drift`` ``(3,)`` (then by ``origin_shift`` ``(3,)`` on every frame).
    A loop closed by :func:`close_points` then ends exactly where it began."""
    p = np.asarray(points, dtype=np.float64)
    d = np.asarray(drift, dtype=np.float64)
    weight = np.linspace(0.0, 1.0, p.shape[0]).reshape((-1,) + (1,) * (p.ndim - 1))
    out: FloatArray = p - weight * d
    if origin_shift is not None:
        out = out - np.asarray(origin_shift, dtype=np.float64)
    out[-1] = out[0]
    return out


def rotation_log(r: FloatArray) -> FloatArray:
    """Rotation vectors ``(..., 3)`` (axis times angle, radians) of rotation matrices ``(..., 3, 3)``."""
    m = np.asarray(r, dtype=np.float64)
    cos = np.clip(0.5 * (np.trace(m, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
    angle = np.arccos(cos)
    axis = np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
                    axis=-1)
    sin = np.sin(angle)
    # angle / (2 sin angle) -> 1/2 as the angle vanishes; near pi the loop error is not small
    # and the loop is refused before this is asked.
    scale = np.where(sin > 1e-12, angle / np.maximum(2.0 * sin, 1e-300), 0.5)
    out: FloatArray = axis * scale[..., None]
    return out


def rotation_exp(w: FloatArray) -> FloatArray:
    """Rotation matrices ``(..., 3, 3)`` of rotation vectors ``w`` ``(..., 3)`` (Rodrigues)."""
    v = np.asarray(w, dtype=np.float64)
    angle = np.sqrt(np.einsum("...i,...i->...", v, v))
    axis = v / np.maximum(angle, 1e-300)[..., None]
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    zero = np.zeros_like(x)
    k = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)], -2)
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    out: FloatArray = np.eye(3) + s * k + (1.0 - c) * (k @ k)
    return out


def close_rotations(rotations: FloatArray) -> FloatArray:
    """``rotations`` ``(F, M, 3, 3)`` turned, a growing part of the way each frame, so the
    last frame is exactly the first: frame ``f`` is turned by ``f / (F - 1)`` of the
    rotation from the last frame to the first (on flat ground and a straight line a steady
    walk's rotations repeat without drift)."""
    r = np.asarray(rotations, dtype=np.float64)
    back = np.einsum("mij,mkj->mik", r[0], r[-1])  # R_0 R_last^T: the last frame onto the first
    w = rotation_log(back)
    weight = np.linspace(0.0, 1.0, r.shape[0])
    turn = rotation_exp(weight[:, None, None] * w[None])
    out: FloatArray = np.einsum("fmij,fmjk->fmik", turn, r)
    out[-1] = out[0]
    return out
