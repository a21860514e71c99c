# SPDX-License-Identifier: GPL-3.0-or-later
"""What the legs reach: the pelvis reach guard (the pelvis stays above its feet, step 4 of
``Controller.step``), planted feet left behind that step early (``overstretched``) and the
ones that wait for support first (``wait_for_support``), how long a foot left behind takes to
catch up (``catch_up_time``), whether a swing stays within its leg's reach
(``within_reach_all``, ``hip_distance``, ``reach_bound``), and the legs' IK with the swinging
feet bent to what their legs reach (``solve_ik``, ``ik_targets``; step 5)."""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np

from ..geometry import vector_norm
from ..world.terrain import Environment
from .ik import IKResult, solve_legs
from .rig import Rig
from .types import BoolArray, ControllerParams, FloatArray, IntArray


def guard_drop(
    rig: Rig, p: ControllerParams, hips: FloatArray, foot: FloatArray, spine_legs: IntArray
) -> FloatArray:
    """``(C,)`` how far to lower each pelvis so that no leg (hips ``hips (N, 3)``, feet
    ``foot (N, 3)``) stretches past ``guard_reach``: bounded by ``guard_max_drop`` of its
    thickness (a foot beyond any help steps early instead), and continuous in the feet.
    Legs on a spine (``spine_legs``) are left out: spines keep their legs within reach in
    step 4 (``spine.repeat_for_reach``)."""
    reach = rig.guard_reach
    d_h = vector_norm(hips[:, :2] - foot[:, :2])
    allowed = foot[:, 2] + rig.foot_lift + np.sqrt(np.maximum(reach * reach - d_h * d_h, 0.0))
    excess = np.maximum(hips[:, 2] - allowed, 0.0)
    excess[spine_legs] = 0.0
    drop = np.zeros(rig.n_chars)
    np.maximum.at(drop, rig.leg_char, excess)
    return np.asarray(np.minimum(drop, p.guard_max_drop * rig.body_thickness))


def overstretched(
    rig: Rig, p: ControllerParams, hips: FloatArray, foot: FloatArray, planted: BoolArray
) -> tuple[BoolArray, FloatArray]:
    """Planted feet (``planted (N,)``) left so far behind (or aside) that keeping them would
    need the pelvis to drop more than ``max_drop`` of its body thickness: they step early.
    ``hips (N, 3)``: the hips at the height the pelvis wants (not where the reach guard has
    already lowered it, else a foot dragging the pelvis down never counts as left behind;
    a spine's where the spine would put them before step 4 pulls them toward the feet: a
    foot left behind must step, not drag the body back). Also returns how far the pelvis
    would have to drop for each foot ``(N,)`` (inf: beyond reach)."""
    reach = rig.comfort_reach
    d_h = vector_norm(hips[:, :2] - foot[:, :2])
    top = foot[:, 2] + rig.foot_lift + np.sqrt(np.maximum(reach * reach - d_h * d_h, 0.0))
    need = np.where(d_h < reach, hips[:, 2] - top, np.inf)
    over = planted & (need > p.max_drop * rig.body_thickness[rig.leg_char])
    return np.asarray(over), np.asarray(need, dtype=np.float64)


def wait_for_support(
    rig: Rig, p: ControllerParams, candidates: BoolArray, stretch: FloatArray, airborne: BoolArray,
    ik_error: FloatArray | None,
) -> BoolArray:
    """Which feet left behind (``candidates (N,)``) wait a little before their forced step:
    those that would leave their character with fewer than ``min_planted`` feet on the
    ground (feet ``airborne (N,)`` are not; a walking wolf or human does not fling every
    foot up at once), as long as the pelvis would have to drop less than ``urgent_drop``
    (× body thickness) to keep them (``stretch (N,)``, metres; the reach guard lowers it
    meanwhile) and its leg still reaches it (the last IK's ``ik_error (N,)``). The most
    stretched feet of a character go first."""
    wait = np.zeros(rig.n_legs, dtype=bool)
    if not np.any(candidates):
        return wait
    down = np.bincount(rig.leg_char, weights=(~airborne).astype(np.float64), minlength=rig.n_chars)
    n_legs = np.bincount(rig.leg_char, minlength=rig.n_chars)
    need = np.minimum(p.min_planted, n_legs - 1)
    urgent = stretch > p.urgent_drop * rig.body_thickness[rig.leg_char]
    if ik_error is not None:  # a planted foot its leg no longer reaches: now
        urgent |= ik_error > 1e-3 * rig.legs.leg_length
    for leg in np.flatnonzero(candidates)[np.argsort(-stretch[candidates], kind="stable")].tolist():
        c = int(rig.leg_char[leg])
        if urgent[leg] or down[c] - 1 >= need[c]:
            down[c] -= 1  # this one steps
        else:
            wait[leg] = True
    return wait


def catch_up_time(
    rig: Rig, disk_duration: FloatArray, speed: FloatArray, swing_time: FloatArray, hips: FloatArray,
    leg_rot: FloatArray, foot: FloatArray,
) -> FloatArray:
    """Seconds ``(N,)`` a foot left behind takes to come back under its rest place (from
    its hip ``hips (N, 3)`` in its frame ``leg_rot (N, 3, 3)``) at twice the mean ground
    speed of a gait swing (its stride over its swing time ``swing_time (N,)``, the
    character's ``speed (C,)``), at most a cycle: a foot held back for cycles (its plans
    failed) covers more than a stride, and in a forced step's fixed share of a swing its leg
    would whip over."""
    share = np.maximum(disk_duration, 1e-9)
    cycle = swing_time / share  # the needle's cycle now (sped up for long strides)
    stride_speed = speed[rig.leg_char] / share
    rest = hips + np.einsum("nij,nj->ni", leg_rot, rig.legs.rest_foot - rig.legs.hip_offset)
    gap = vector_norm(rest[:, :2] - foot[:, :2])
    return np.asarray(np.minimum(gap / np.maximum(2.0 * stride_speed, 1e-9), cycle))


def hip_distance(
    rig: Rig, p: ControllerParams, leg: int | IntArray, samples: FloatArray, hip_start: FloatArray,
    hip_end_xy: FloatArray,
) -> FloatArray:
    """``(..., k + 1)`` distances of swing samples ``(..., k + 1, 3)`` to the hip of ``leg``
    moving from ``hip_start`` to ``hip_end_xy (..., 2)`` (rising or sinking with the feet),
    the pelvis lowered as far as the reach guard ever lowers it. One leg: ``leg`` an index,
    ``hip_start (3,)``; many swings of their own legs: ``leg (m,)``, ``hip_start (m, 3)``,
    ``samples (m, k + 1, 3)``."""
    legs = np.asarray(leg)
    start = np.asarray(hip_start)[..., None, :]
    u = _unit_samples(samples.shape[-2])
    end_xy = np.broadcast_to(hip_end_xy, (*samples.shape[:-2], 2))
    end = np.concatenate(
        [end_xy, (start[..., 0, 2] + samples[..., -1, 2] - samples[..., 0, 2])[..., None]], axis=-1
    )
    hip = start + u[:, None] * (end[..., None, :] - start)
    horizontal = vector_norm(samples[..., :2] - hip[..., :2])
    drop = (p.guard_max_drop * rig.body_thickness[rig.leg_char[legs]])[..., None]
    below = hip[..., 2] - (samples[..., 2] + rig.foot_lift[legs][..., None])
    vertical = np.where(below > 0.0, np.maximum(below - drop, 0.0), -below)
    return np.asarray(np.hypot(horizontal, vertical))


@functools.lru_cache(maxsize=8)
def _unit_samples(n: int) -> FloatArray:
    """``np.linspace(0, 1, n)``: the swing parameters of ``n`` samples (made once per ``n``;
    read only)."""
    u = np.linspace(0.0, 1.0, n)
    u.setflags(write=False)
    return u


def reach_bound(rig: Rig, leg: int | IntArray, start: float | FloatArray, u: FloatArray) -> FloatArray:
    """How far a swing's samples at ``u`` may be from the hip: the leg's length, or for a
    foot that starts beyond it (``start``: its distance at ``u = 0``; left behind), a bound
    shrinking from there to it. ``leg`` and ``start`` an index and a distance, or ``(m,)``
    each for ``(m, len(u))`` bounds."""
    length = rig.legs.leg_length[np.asarray(leg)]
    return np.asarray(length[..., None] + np.maximum(np.asarray(start) - length, 0.0)[..., None] * (1.0 - u))


def within_reach_all(
    rig: Rig, p: ControllerParams, legs: IntArray, samples: FloatArray, hip_start: FloatArray,
    hip_end_xy: FloatArray,
) -> BoolArray:
    """Whether each swing ``samples (m, k + 1, 3)`` of legs ``legs (m,)`` stays within its
    leg's length of its hip moving from ``hip_start (m, 3)`` to ``hip_end_xy (m, 2)`` at
    touch-down (``hip_distance``, ``reach_bound``): ``(m,)``. The planner's paths may detour
    around obstacles farther than a leg reaches; such a couple is not taken."""
    dist = hip_distance(rig, p, legs, samples, hip_start, hip_end_xy)
    u = _unit_samples(samples.shape[-2])
    return np.asarray(np.all(dist <= reach_bound(rig, legs, dist[:, 0], u), axis=1))


def ik_targets(rig: Rig, foot: FloatArray) -> FloatArray:
    """``(N, 3)`` where each leg's end-effector goes: its foot ``foot (N, 3)``, raised by its
    ``Morphology.foot_lift``."""
    out = foot.copy()
    out[:, 2] += rig.foot_lift
    return out


def solve_ik(
    env: Environment, rig: Rig, p: ControllerParams, hips: FloatArray, leg_rot: FloatArray, foot: FloatArray,
    swinging: BoolArray, angles: FloatArray, prev_normal: FloatArray | None, mask: BoolArray,
) -> tuple[IKResult, int]:
    """Pose every leg from ``hips (N, 3)`` in frames ``leg_rot (N, 3, 3)`` to its foot
    ``foot (N, 3)`` (legs with ``mask (N,)`` False keep ``angles``); returns the result and
    how many swinging feet (``swinging (N,)``) were moved (in ``foot``, in place) to what
    their legs reach."""
    res = solve_legs(
        rig.legs, hips, leg_rot, ik_targets(rig, foot), angles, mask=None if mask.all() else mask,
        tolerance=rig.ik_tolerance, prev_normal=prev_normal,
    )
    # A swinging foot goes where its leg reaches: a point of its trajectory beyond the leg
    # (the hip rose or moved on more than foreseen) or nearer the hip than its joints fold
    # (a robot knee stopping at 160°) is replaced by the closest point the leg reaches,
    # unless that point is under the ground. Planted feet never move.
    missed = np.flatnonzero(swinging & mask & (res.error > 1e-3 * rig.legs.leg_length))
    if missed.size == 0:
        return res, 0
    end = res.joints[missed, rig.legs.n_segments[missed]]
    end[:, 2] -= rig.foot_lift[missed]  # the foot, on the ground it is planned on
    ground = env.height_at(end[:, :2])
    above = end[:, 2] >= ground - 1e-9
    moved = missed[above]
    if moved.size:
        foot[moved] = end[above]
        error = res.error.copy()
        error[moved] = 0.0
        res = replace(res, error=error)
    return res, int(moved.size)
