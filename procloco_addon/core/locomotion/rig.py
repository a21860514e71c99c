# SPDX-License-Identifier: GPL-3.0-or-later
"""What a rig allows, computed once per controller: every character's and every leg's fixed
geometry (``Rig``: mean leg length, body box, foot boxes, rest heights, the reaches the
guards use, the longest stance sweep), and the stride rule built on it: how much faster the
gait's needle must run so that the commanded speed never asks a stance sweep longer than the
legs allow (``rate_scale``, thesis §3.2; step 1 of ``Controller.step``).

Characters of different sizes in one controller each have their own ``ControllerParams``
(``character_params``): the fields creature-size scaling sets (``PER_CHARACTER``) become the
per-character and per-leg arrays of ``Rig``; every other field is shared."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np

from .gait import GaitManager
from .morphology import LegBatch
from .types import BoolArray, ControllerParams, FloatArray, IntArray

#: The ``ControllerParams`` fields that may differ between the characters of one controller
#: (those ``scaling.scaled_params`` sets; of ``physics`` only its gravity).
PER_CHARACTER = ("window_cells", "window_cell", "slice_size", "support_tolerance", "ik_tolerance",
                 "physics.gravity")


def character_params(params: ControllerParams | Sequence[ControllerParams] | None,
                     n_chars: int) -> list[ControllerParams]:
    """One ``ControllerParams`` per character from one for all (or None: the defaults) or a
    sequence of ``n_chars``. Fields other than ``PER_CHARACTER`` must be equal across the
    characters: a ``ValueError`` names the first that is not."""
    if params is None or isinstance(params, ControllerParams):
        return [params or ControllerParams()] * n_chars
    out = list(params)
    if len(out) != n_chars:
        raise ValueError(f"{len(out)} controller settings for {n_chars} characters")
    first = out[0] if out else ControllerParams()
    for q in out[1:]:
        for f in fields(ControllerParams):
            if f.name in PER_CHARACTER:
                continue
            a, b = getattr(first, f.name), getattr(q, f.name)
            if f.name == "physics":
                a, b = replace(a, gravity=0.0), replace(b, gravity=0.0)
            if a != b:
                name = "physics (other than gravity)" if f.name == "physics" else f.name
                raise ValueError(f"ControllerParams.{name} differs between characters; only "
                                 f"{', '.join(PER_CHARACTER)} may")
    return out


@dataclass(frozen=True)
class Rig:
    """Fixed geometry of every character ``(C, ...)`` and leg ``(N, ...)``.

    ``char_leg_length (C,)``: mean leg length; ``body_thickness (C,)``; ``box_center``,
    ``box_half (C, 2)``: the body box in the body frame; ``foot_half``, ``sole_half (C, 2)``:
    the foot box and the part of it other feet may not land on; ``foot_lift (N,)``: how far
    each end-effector stands above the ground its foot is planned on; ``window_cell (C,)``:
    planning cell size; ``rest_height``, ``rest_horizontal (N,)``: hip-to-foot drop and
    horizontal distance at rest; ``leg_arch (N,)`` (``leg_arch_shares``); ``comfort_reach``
    (a planted foot beyond it steps early), ``guard_reach (N,)`` (the pelvis sinks to keep
    its feet within it); ``stroke_limit (C,)``: longest stance sweep (``stroke_limits``).

    Each character's own ``PER_CHARACTER`` settings: ``window_cells (C,)``, ``slice_size``
    (one per character, None: no slices), ``support_tolerance``, ``ik_tolerance`` and the
    pelvis particles' ``gravity`` per leg ``(N,)``."""

    legs: LegBatch
    leg_char: IntArray
    n_chars: int
    n_legs: int
    char_leg_length: FloatArray
    body_thickness: FloatArray
    box_center: FloatArray
    box_half: FloatArray
    foot_half: FloatArray
    sole_half: FloatArray
    foot_lift: FloatArray
    window_cell: FloatArray
    rest_height: FloatArray
    rest_horizontal: FloatArray
    leg_arch: FloatArray
    comfort_reach: FloatArray
    guard_reach: FloatArray
    stroke_limit: FloatArray
    window_cells: IntArray
    slice_size: tuple[float | None, ...]
    support_tolerance: FloatArray
    ik_tolerance: FloatArray
    gravity: FloatArray


def build_rig(legs: LegBatch, p: ControllerParams, chars: Sequence[ControllerParams] | None = None) -> Rig:
    """The ``Rig`` of ``legs`` under the knobs ``p`` (the shared ones) and each character's
    own ``chars`` (``character_params``; default ``p`` for all)."""
    c = legs.n_chars
    own = list(chars) if chars is not None else [p] * c
    lc = legs.leg_char
    mean_leg = np.bincount(legs.leg_char, weights=legs.leg_length, minlength=c) / np.bincount(
        legs.leg_char, minlength=c
    )
    body_thickness = np.array([m.body_thickness for m in legs.morphologies])
    foot_half = np.array([m.foot_half_extents for m in legs.morphologies])
    # the part of each foot the others may not land on (a foot box unless the
    # morphology gives a smaller sole)
    sole_half = np.array([m.foot_half_extents if m.sole_half_extents is None else m.sole_half_extents
                          for m in legs.morphologies])
    window_cell = np.array([
        float(np.clip(0.065 * mean_leg[i], 0.005, 0.25)) if q.window_cell is None else float(q.window_cell)
        for i, q in enumerate(own)
    ], dtype=np.float64).reshape(c)
    rest_vec = legs.rest_foot - legs.hip_offset
    rest_height = -rest_vec[:, 2]
    rest_dist = np.linalg.norm(rest_vec, axis=1)
    # comfortable reach: never tighter than the rest pose itself
    comfort_reach = np.minimum(
        np.maximum(p.step_early_reach * legs.leg_length, 1.02 * rest_dist), 0.995 * legs.leg_length
    )
    guard_reach = np.minimum(
        np.maximum(p.reach_margin * legs.leg_length, 1.01 * rest_dist), 0.999 * legs.leg_length
    )
    # the longest stance sweep the legs allow (the needle runs faster beyond it), never
    # less than a quarter of max_stroke: a leg's reach with the pelvis half its allowed
    # drop lower, and neighbouring feet kept two foot boxes and half a planning cell apart
    # (their toes do not meet as they sweep; a foot may land nearer, its box off the
    # other's sole, but a longer sweep then crowds the next footfalls)
    cap = p.max_stroke * mean_leg
    low = rest_height - 0.5 * p.max_drop * body_thickness[legs.leg_char]
    clearance = 2.0 * foot_half.max(axis=1) + 0.5 * window_cell
    stroke_limit = np.maximum(stroke_limits(legs, comfort_reach, low, clearance, cap), 0.25 * cap)
    return Rig(
        legs=legs, leg_char=legs.leg_char, n_chars=c, n_legs=legs.n_legs, char_leg_length=mean_leg,
        body_thickness=body_thickness,
        box_center=np.array([m.body_box_center for m in legs.morphologies]),
        box_half=np.array([m.body_box_half for m in legs.morphologies]),
        foot_half=foot_half, sole_half=sole_half, foot_lift=legs.foot_lift, window_cell=window_cell,
        rest_height=rest_height, rest_horizontal=np.linalg.norm(rest_vec[:, :2], axis=1),
        leg_arch=leg_arch_shares(legs), comfort_reach=comfort_reach, guard_reach=guard_reach,
        stroke_limit=stroke_limit,
        window_cells=np.array([q.window_cells for q in own], dtype=np.int64).reshape(c),
        slice_size=tuple(q.slice_size for q in own),
        support_tolerance=np.array([q.support_tolerance for q in own], dtype=np.float64).reshape(c)[lc],
        ik_tolerance=np.array([q.ik_tolerance for q in own], dtype=np.float64).reshape(c)[lc],
        gravity=np.array([q.physics.gravity for q in own], dtype=np.float64).reshape(c)[lc],
    )


def rate_scale(
    rig: Rig, gait: GaitManager, has_spine: BoolArray, speed: FloatArray, yaw_rate: FloatArray | None = None
) -> FloatArray:
    """``(C,)`` needle speed-up for the commanded ``speed (C,)`` and the body's
    ``yaw_rate (C,)`` (rad/s): the stance sweep at the gait's own cycle, over the longest
    the legs allow (``stroke_limit``), at least 1. A rigid body turning sweeps its planted
    feet sideways too (the farther from the pelvis, the more); a spine's nodes (characters
    with ``has_spine (C,)``) follow the head's path, so only their speed counts."""
    lc = rig.leg_char
    stance = (1.0 - gait.disk_duration) * gait.cycle_time[lc]
    foot_speed = np.asarray(speed, dtype=np.float64)[lc]
    if yaw_rate is not None:
        w = np.where(has_spine, 0.0, np.asarray(yaw_rate, dtype=np.float64))[lc]
        r = rig.legs.rest_foot[:, :2]
        foot_speed = np.hypot(foot_speed - w * r[:, 1], w * r[:, 0])
    stroke = np.zeros(rig.n_chars)
    np.maximum.at(stroke, lc, foot_speed * stance)
    # in steps of 1/1024 (rounded up): characters that differ only by rounding (a rig
    # read at 100 times its size) keep exactly the same cycle
    steps = np.ceil(stroke / rig.stroke_limit * 1024.0 - 1e-6) / 1024.0
    return np.asarray(np.maximum(1.0, steps))


def stroke_limits(
    legs: LegBatch,
    reach: FloatArray,
    low: FloatArray,
    clearance: FloatArray,
    cap: FloatArray,
    samples: int = 97,
) -> FloatArray:
    """Longest stance sweep ``(C,)`` (metres) each character's legs allow when walking
    straight ahead: a foot lands half a sweep ahead of its rest position and lifts half a
    sweep behind it (thesis figures 3.6, 3.7), so

    - every foot must stay within ``reach (N,)`` of its hip at both ends, with the hip
      ``low (N,)`` above the ground (horizontally: ``sqrt(reach² - low²)``);
    - a foot landing must stay behind a neighbour's planted foot that is about to lift (at
      its far end) and ``clearance (C,)`` away from it, without the two legs crossing (the
      planner forbids both: the neighbour's foot box and legs crossing, thesis §3.5.1).
      Pairs already crossing or crowded at rest are left out (the stroke cannot help them).

    Neither is ever more than ``cap (C,)``. Rest geometry only (body frame, x forward)."""
    c = legs.n_chars
    hip = legs.hip_offset[:, :2]
    rest = legs.rest_foot[:, :2] - hip
    out = np.asarray(cap, dtype=np.float64).copy()
    # reach: |rest ± s/2 x| <= H  <=>  s <= 2 (sqrt(H² - y²) - |x|)
    horizontal = np.sqrt(np.maximum(reach * reach - low * low, 0.0))
    room = np.sqrt(np.maximum(horizontal * horizontal - rest[:, 1] ** 2, 0.0)) - np.abs(rest[:, 0])
    np.minimum.at(out, legs.leg_char, np.maximum(2.0 * room, 0.0))
    # neighbours: ordered pairs (i lands, j lifts) of the same character
    i, j = np.nonzero((legs.leg_char[:, None] == legs.leg_char[None, :]) & ~np.eye(legs.n_legs, dtype=bool))
    if i.size == 0:
        return out
    owner = legs.leg_char[i]
    s = np.linspace(0.0, 1.0, samples)[None, :] * out[owner][:, None]  # (p, k)
    shift = np.stack([0.5 * s, np.zeros_like(s)], axis=-1)
    foot_i = legs.rest_foot[i, None, :2] + shift
    foot_j = legs.rest_foot[j, None, :2] - shift
    hip_i = np.broadcast_to(hip[i, None], foot_i.shape)
    hip_j = np.broadcast_to(hip[j, None], foot_j.shape)

    def side(a: FloatArray, b: FloatArray, q: FloatArray) -> FloatArray:
        d = b - a
        e = q - a
        return np.asarray(d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0])

    cross = (side(hip_i, foot_i, hip_j) * side(hip_i, foot_i, foot_j) < 0.0) & (
        side(hip_j, foot_j, hip_i) * side(hip_j, foot_j, foot_i) < 0.0
    )
    bad = cross | (np.linalg.norm(foot_i - foot_j, axis=-1) < clearance[owner][:, None])
    keep = ~bad[:, 0]
    first = np.where(bad.any(axis=1), np.argmax(bad, axis=1), samples)
    limit = np.where(first < samples, s[np.arange(i.size), np.maximum(first - 1, 0)], out[owner])
    np.minimum.at(out, owner[keep], limit[keep])
    return out[:c]


def leg_arch_shares(legs: LegBatch) -> FloatArray:
    """``(N,)`` how high each leg's inner joints rise above its hip-foot line at rest, as a
    share of the half-height a two-segment leg of the same length bends over that distance
    (``sqrt(L² - C²) / 2``): near 1 for a spider's or an insect's legs (knees above the
    hip), 0 for legs whose knees bend forward or back under the hip."""
    joints = legs.rest_joints
    rows = np.arange(legs.n_legs)
    hip = joints[:, 0]
    foot = joints[rows, legs.n_segments]
    d = foot - hip
    chord2 = np.einsum("ij,ij->i", d, d)
    inner = joints[:, 1:]
    along = np.einsum("nkj,nj->nk", inner - hip[:, None], d)
    t = np.clip(along / np.maximum(chord2, 1e-18)[:, None], 0.0, 1.0)
    above = inner[..., 2] - (hip[:, None, 2] + t * d[:, None, 2])
    valid = np.arange(inner.shape[1])[None, :] < (legs.n_segments - 1)[:, None]
    rise = np.where(valid, above, 0.0).max(axis=1, initial=0.0)
    half = 0.5 * np.sqrt(np.maximum(legs.leg_length**2 - chord2, 0.0))
    return np.asarray(np.clip(np.where(half > 1e-9, rise / np.maximum(half, 1e-12), 0.0), 0.0, 1.0))
