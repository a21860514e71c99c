# SPDX-License-Identifier: GPL-3.0-or-later
"""The pelvis of rigid bodies (thesis §3.2.2, §4.1): its pose (``Body``), the hull under it
that gives its height, pitch and roll (``hull_pose``, figure 3.8) and their low-pass filter
(``settle``), the feet-error feedback that moves it in the ground plane (``feedback_move``,
figure 3.9), and the pogo particles of pelvis pseudo-physics (``Pogo``, ``pogo_heights``).
Spine characters' nodes get their heights from the same particles; their poses come from
``spine_link``."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..geometry import clip, vector_norm
from ..hull import hull_height_and_pitch
from ..world.terrain import Environment
from .gait import GaitManager
from .pelvis_physics import PelvisPhysics
from .rig import Rig
from .types import RATE_JUMP, VOID, BoolArray, ControllerParams, FloatArray, IntArray

_XY = np.array([0, 1])


@dataclass
class Body:
    """Every character's pelvis ``(C, ...)``: ``pos (C, 3)``, ``yaw``, ``pitch``, ``roll``
    (radians), ``height_target`` (the filtered hull height, or the preferred height of the
    pogo particles), ``guard_drop`` (how far the reach guard lowered it last), and each
    leg's footprint error ``feedback (N, 2)`` (chosen minus preferred footprint) still to
    work off."""

    pos: FloatArray
    yaw: FloatArray
    pitch: FloatArray
    roll: FloatArray
    height_target: FloatArray
    guard_drop: FloatArray
    feedback: FloatArray


def start_body(start_xy: npt.ArrayLike, start_yaw: npt.ArrayLike, n_chars: int, n_legs: int) -> Body:
    """Pelvises on the ground plane at ``start_xy (C, 2)`` heading ``start_yaw (C,)``."""
    pos = np.zeros((n_chars, 3))
    pos[:, :2] = np.asarray(start_xy, dtype=np.float64).reshape(n_chars, 2)
    yaw = np.broadcast_to(np.asarray(start_yaw, dtype=np.float64), (n_chars,)).copy()
    return Body(pos, yaw, np.zeros(n_chars), np.zeros(n_chars), np.zeros(n_chars), np.zeros(n_chars),
                np.zeros((n_legs, 2)))


def hull_pose(
    env: Environment, rig: Rig, body_samples: tuple[int, int], body: Body, support: FloatArray,
    chars: IntArray | None = None, ground: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Hull height (+ body thickness), pitch and roll ``(C,)`` under each character (or
    only under ``chars``; the results are then ``(len(chars),)``), with the feet where the
    body rests on them, ``support (N, 3)``. ``ground``: the surface at
    ``hull_points(rig, body_samples, body, chars)`` when the caller asked already (in a
    query of its own; else it is asked here).

    Thesis figure 3.8 works on a vertical slice along the body: the terrain under the body
    box is sampled on a grid and reduced to its highest point across the body at each
    position along it (and along the body at each position across it, for roll), then the
    planted feet (and the targets of swinging ones) are added.
    """
    if chars is None:
        pos, yaw, box_center, box_half = body.pos, body.yaw, rig.box_center, rig.box_half
        thickness = rig.body_thickness
        leg_rows = np.arange(rig.n_legs)
        row_of = np.arange(rig.n_chars)
    else:
        pos, yaw = body.pos[chars], body.yaw[chars]
        box_center, box_half = rig.box_center[chars], rig.box_half[chars]
        thickness = rig.body_thickness[chars]
        leg_rows = np.flatnonzero(np.isin(rig.leg_char, chars))
        row_of = np.full(rig.n_chars, -1)
        row_of[chars] = np.arange(len(chars))
    c = pos.shape[0]
    along_pts, along_ok, across_pts, across_ok = terrain_slices(
        env, body_samples, pos, yaw, box_center, box_half, ground
    )
    # feet: planted feet where they are, swinging feet where they will land
    owner = rig.leg_char[leg_rows]
    feet = support[leg_rows]
    n_feet = int(np.bincount(row_of[owner], minlength=c).max())
    slot = leg_rows - rig.legs.leg_start[owner]
    feet_pts = np.zeros((c, n_feet, 3))
    feet_ok = np.zeros((c, n_feet), dtype=bool)
    feet_pts[row_of[owner], slot] = feet
    feet_ok[row_of[owner], slot] = True
    cos, sin = np.cos(yaw), np.sin(yaw)
    fwd = np.empty((c, 2))
    fwd[:, 0] = cos
    fwd[:, 1] = sin
    left = np.empty((c, 2))
    left[:, 0] = -sin
    left[:, 1] = cos
    # both slices (forward for height and pitch, left for roll) in one batched call
    both_h, both_a = hull_height_and_pitch(
        np.concatenate(
            [
                np.concatenate([along_pts, feet_pts], axis=1),
                np.concatenate([across_pts, feet_pts], axis=1),
            ]
        ),
        np.concatenate([pos[:, :2], pos[:, :2]]),
        np.concatenate([fwd, left]),
        np.concatenate(
            [np.concatenate([along_ok, feet_ok], axis=1), np.concatenate([across_ok, feet_ok], axis=1)]
        ),
    )
    height, pitch, roll = both_h[:c], both_a[:c], both_a[c:]
    return height + thickness, pitch, roll


def hull_points(
    rig: Rig, body_samples: tuple[int, int], body: Body, chars: IntArray | None = None
) -> FloatArray:
    """The points ``(k, 2)`` whose surface :func:`hull_pose` reads (its ``ground``), for the
    same ``chars``."""
    if chars is None:
        return _slice_grid(body_samples, body.pos, body.yaw, rig.box_center, rig.box_half)
    pos, yaw = body.pos[chars], body.yaw[chars]
    return _slice_grid(body_samples, pos, yaw, rig.box_center[chars], rig.box_half[chars])


def _to_world(
    out: FloatArray, pos: FloatArray, cy: FloatArray, sy: FloatArray, lx: FloatArray, ly: FloatArray
) -> None:
    """Points at ``lx``, ``ly`` (each ``(c, k)`` or ``(c, 1)``) in the frames of pelvises at
    ``pos (c, 3)`` whose headings' cosines and sines are ``cy``, ``sy (c, 1)``, written into
    ``out (c, k, >= 2)``'s first two columns."""
    out[..., 0] = pos[:, None, 0] + (cy * lx - sy * ly)
    out[..., 1] = pos[:, None, 1] + (sy * lx + cy * ly)


@functools.lru_cache(maxsize=8)
def _unit_grid(body_samples: tuple[int, int]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The sample positions along and across a body box of half size 1 (``na``, ``nc``) and
    their grid ``(na * nc, 2)``, row by row (read only)."""
    na, nc = body_samples
    sa = np.linspace(-1.0, 1.0, na)
    sc = np.linspace(-1.0, 1.0, nc)
    grid = np.stack(np.meshgrid(sa, sc, indexing="ij"), axis=-1).reshape(-1, 2)
    for a in (sa, sc, grid):
        a.setflags(write=False)
    return sa, sc, grid


def _slice_grid(
    body_samples: tuple[int, int], pos: FloatArray, yaw: FloatArray, box_center: FloatArray,
    box_half: FloatArray,
) -> FloatArray:
    """:func:`terrain_slices`' grid under the body boxes: ``(c * na * nc, 2)``."""
    grid = _unit_grid(body_samples)[2]
    lx = box_center[:, None, 0] + grid[None, :, 0] * box_half[:, None, 0]
    ly = box_center[:, None, 1] + grid[None, :, 1] * box_half[:, None, 1]
    out = np.empty((*lx.shape, 2))
    _to_world(out, pos, np.cos(yaw)[:, None], np.sin(yaw)[:, None], lx, ly)
    return out.reshape(-1, 2)


def terrain_slices(
    env: Environment, body_samples: tuple[int, int], pos: FloatArray, yaw: FloatArray, box_center: FloatArray,
    box_half: FloatArray, ground: FloatArray | None = None,
) -> tuple[FloatArray, BoolArray, FloatArray, BoolArray]:
    """The terrain under body boxes ``box_center``, ``box_half (c, 2)`` of pelvises at ``pos
    (c, 3)`` heading ``yaw (c,)``, sampled on a ``body_samples`` (along, across) grid and
    reduced to its highest point across the body at each position along it and along the
    body at each position across it: points ``(c, w, 3)`` and whether each is on a surface
    ``(c, w)`` of the slice along, then of the slice across (``w`` the larger sample count;
    padded rows are not valid). ``ground``: the surface on the grid (``_slice_grid``) when
    the caller asked already."""
    c = pos.shape[0]
    na, nc = body_samples
    sa, sc, _ = _unit_grid(body_samples)
    cy, sy = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    if ground is None:
        ground = env.height_at(_slice_grid(body_samples, pos, yaw, box_center, box_half))
    ground = ground.reshape(c, na, nc)
    ground = np.where(ground > VOID, ground, -np.inf)
    along_z = ground.max(axis=2)  # (c, na)
    across_z = ground.max(axis=1)  # (c, nc)
    # the slices' points in the body frame: along it (x varies, y the box centre's) and
    # across it
    along_x = box_center[:, None, 0] + sa[None, :] * box_half[:, None, 0]
    across_y = box_center[:, None, 1] + sc[None, :] * box_half[:, None, 1]
    width = max(na, nc)

    def padded(lx: FloatArray, ly: FloatArray, z: FloatArray) -> tuple[FloatArray, BoolArray]:
        pts = np.zeros((c, width, 3))
        ok = np.zeros((c, width), dtype=bool)
        k = z.shape[1]
        _to_world(pts[:, :k], pos, cy, sy, lx, ly)
        finite = np.isfinite(z)
        pts[:, :k, 2] = np.where(finite, z, 0.0)
        ok[:, :k] = finite
        return pts, ok

    along_pts, along_ok = padded(along_x, box_center[:, None, 1], along_z)
    across_pts, across_ok = padded(box_center[:, None, 0], across_y, across_z)
    return along_pts, along_ok, across_pts, across_ok


def settle(body: Body, pose: tuple[FloatArray, FloatArray, FloatArray], alpha: FloatArray,
           chars: IntArray | None) -> None:
    """Low-pass filter the pelvis height target, pitch and roll of ``chars`` (None: every
    character) toward the hull ``pose`` (each ``(len(chars),)``) by ``alpha (C,)``."""
    height, pitch, roll = pose
    sel = slice(None) if chars is None else chars
    a = alpha[sel]
    body.height_target[sel] += a * (height - body.height_target[sel])
    body.pitch[sel] += a * (pitch - body.pitch[sel])
    body.roll[sel] += a * (roll - body.roll[sel])


def feedback_move(
    leg_char: IntArray, p: ControllerParams, feedback: FloatArray, leg_length: FloatArray,
    cycle_time: FloatArray, dt: float,
) -> FloatArray | None:
    """Thesis figure 3.9: the ground-plane move ``(C, 2)`` of each pelvis by its feet's
    mean footprint error ``feedback (N, 2)`` when that exceeds ``feedback_threshold`` of its
    leg length ``leg_length (C,)``, worked off over a cycle ``cycle_time (C,)``; the part
    worked off is taken out of ``feedback`` (in place). None when no error matters."""
    c = leg_length.shape[0]
    # both components' sums in one bincount (bins 2 c and 2 c + 1)
    bins = (2 * leg_char[:, None] + _XY).reshape(-1)
    sums = np.bincount(bins, weights=feedback.reshape(-1), minlength=2 * c)
    mean = sums.reshape(c, 2) / np.bincount(leg_char, minlength=c)[:, None]
    significant = vector_norm(mean) > p.feedback_threshold * leg_length
    if not np.logical_or.reduce(significant):
        return None
    share = clip(p.feedback_gain * dt / cycle_time, 0.0, 1.0)
    move = np.where(significant[:, None], mean * share[:, None], 0.0)
    # the part worked off is consumed
    feedback -= np.where(significant[leg_char, None], feedback * share[leg_char, None], 0.0)
    return np.asarray(move)


@dataclass
class Pogo:
    """The pogo particles of pelvis pseudo-physics (``pelvis_physics``) and their switch:
    ``physics``, which characters had it on at the last step ``on (C,)``, and the needle
    rate their orbit was made for ``rate (N,)`` (re-made when it jumps)."""

    physics: PelvisPhysics
    on: BoolArray
    rate: FloatArray


def pogo_heights(
    pogo: Pogo, gait: GaitManager, leg_char: IntArray, node_char: IntArray, physics_on: BoolArray,
    needle_before: FloatArray, rate_leg: FloatArray, pref: FloatArray, dt: float,
) -> FloatArray:
    """Every pelvis node's height ``(n_nodes,)``: the pogo particles' for characters with
    ``physics_on (C,)``, the preferred height ``pref (n_nodes,)`` for the others. Particles
    switched on start on the current orbit (``needle_before``, ``rate_leg (N,)``)."""
    switched_on = physics_on & ~pogo.on
    # The particles' orbit belongs to a needle rate: one much faster or slower at once (a
    # turn on the spot speeding the gait up from the first frame) leaves them on an orbit
    # whose flights are sized for the old cycle, metres high on a slow gait's long stance.
    # Such a jump (over RATE_JUMP in one step) puts them on the new rate's orbit.
    ratio = rate_leg / np.maximum(pogo.rate, 1e-12)
    jumped = np.bincount(leg_char, weights=(ratio > RATE_JUMP) | (ratio < 1.0 / RATE_JUMP),
                         minlength=physics_on.shape[0]) > 0.0
    switched_on |= physics_on & jumped
    pogo.rate = rate_leg.copy()
    if np.logical_or.reduce(switched_on):
        pogo.physics.reset(
            pref, needle_before, rate_leg, gait.disk_start, gait.disk_duration, nodes=switched_on[node_char]
        )
    pogo.on = physics_on.copy()
    if not np.logical_or.reduce(physics_on):
        return pref.copy()
    node = pogo.physics.step(dt, needle_before, rate_leg, gait.disk_start, gait.disk_duration, pref)
    return np.asarray(np.where(physics_on[node_char], pogo.physics.centered_height(node), pref))
