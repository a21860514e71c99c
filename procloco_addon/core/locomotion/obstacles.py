# SPDX-License-Identifier: GPL-3.0-or-later
"""Moving obstacles and the ground under the feet (thesis §3.6, sequence 4).

Owns the watch rings around each planted foot and landing spot (``Watch``: what was there at
the last look), and the checks built on them: a swing whose remaining trajectory or landing
spot an obstacle now cuts and a planted foot whose support moved or is closing in (the looks
of every foot of a step in one query, ``look_around``; ``check_supports``), a landing spot
taken since it was planned (``spot_taken``), a foot an obstacle ran into pushed out of it
(``push_out``), and a footprint over a hole moved onto the ground its foot box reaches
(``onto_support``). A look asks the ground only
where a moving obstacle is or was near (``look_points``, ``Environment.moving_near``): the
rest of the scene holds what the watch remembers.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..geometry import vector_norm
from ..world.terrain import Environment
from .rig import Rig
from .state import FootState, swing_parameter
from .types import VOID, BoolArray, ControllerParams, FloatArray, IntArray


@dataclass
class Watch:
    """Two rings of points around every foot's watched spot: ``offsets (N, 16, 2)`` (at the
    foot box's corner distance plus ``watch_distance`` and half of it, the inner ring turned
    half a step), and what was there at the last look, ``ground (N, 16)`` and ``forbidden
    (N, 16)``. ``dynamic``: the environment has moving parts (else nothing is watched).

    What lets a look skip the rings no moving thing comes near (most of a crowd's feet): the
    spot looked at last, ``spot (N, 2)``, and whether a moving obstacle reached its ring
    then, ``stirred (N,)`` (a ring reaches ``reach (N, 2)`` from its spot along x and y);
    whether one reached a swing when it was planned, ``swing_stirred (N,)``, and the bounds
    of its samples, ``swing_box (N, 4)`` (min x, min y, max x, max y). A ring whose spot
    stayed put, that nothing moving reached then or reaches now, holds what the static scene
    holds: what was remembered (the same for a swing's samples and what was recorded when it
    was planned). The spot itself, inside its ring, likewise: what was there at the last
    look, ``spot_ground (N,)`` and ``spot_forbidden (N,)``, where ``spot_known (N,)``."""

    offsets: FloatArray
    ground: FloatArray
    forbidden: BoolArray
    dynamic: bool
    spot: FloatArray
    stirred: BoolArray
    swing_stirred: BoolArray
    swing_box: FloatArray
    reach: FloatArray
    spot_ground: FloatArray
    spot_forbidden: BoolArray
    spot_known: BoolArray


def make_watch(env: Environment, rig: Rig, p: ControllerParams, foot: FloatArray) -> Watch:
    """The watch rings of every foot, remembering what is around ``foot (N, 3)`` now."""
    legs = rig.legs
    n = rig.n_legs
    ring = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    dirs = np.stack([np.cos(ring), np.sin(ring)], axis=1)
    corner = np.linalg.norm(rig.foot_half, axis=1)[legs.leg_char]
    outer = corner + p.watch_distance * legs.leg_length
    inner = corner + 0.5 * p.watch_distance * legs.leg_length
    offsets = np.concatenate(
        [outer[:, None, None] * dirs[None], inner[:, None, None] * np.roll(dirs, 1, axis=0)[None]], axis=1
    )  # (N, 16, 2), the inner ring turned half a step
    dynamic = bool(env.boxes.dynamic.any()) or any(soup.dynamic for soup in env.soups)
    watch = Watch(offsets, np.zeros((n, 16)), np.zeros((n, 16), dtype=bool), dynamic, np.zeros((n, 2)),
                  np.ones(n, dtype=bool), np.ones(n, dtype=bool), np.zeros((n, 4)),
                  np.abs(offsets).max(axis=1), np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))
    watch_reset(env, watch, np.arange(n), foot)
    return watch


def ring_points(watch: Watch, legs: IntArray, spot: FloatArray) -> FloatArray:
    """The watch rings' points ``(m * 16, 2)`` around the spots ``spot (m, 3)`` of ``legs``."""
    off = watch.offsets[legs]
    out = np.empty(off.shape)  # (x and y apart: the sums run along the rings, not over pairs)
    out[..., 0] = spot[:, 0, None] + off[..., 0]
    out[..., 1] = spot[:, 1, None] + off[..., 1]
    return out.reshape(-1, 2)


def _ring_near(env: Environment, watch: Watch, legs: IntArray, spot: FloatArray) -> BoolArray:
    """``(m,)`` whether a moving obstacle reaches the rings around ``spot (m, 3)`` of ``legs``
    now (their bounding boxes)."""
    reach = watch.reach[legs]
    return env.moving_near(spot[:, :2] - reach, spot[:, :2] + reach)


def swing_planned(
    env: Environment, watch: Watch, legs: IntArray, samples: FloatArray, spot: FloatArray | None = None
) -> BoolArray | None:
    """Remember the bounds of the swings ``samples (m, k, 3)`` just planned for ``legs`` and
    whether a moving obstacle reaches them now. ``spot (m, 3)``: their landing spots, whose
    rings are asked in the same rectangle query (``_ring_near``: returned, for
    ``watch_reset``)."""
    box = np.concatenate([samples[..., :2].min(axis=1), samples[..., :2].max(axis=1)], axis=1)
    watch.swing_box[legs] = box
    if spot is None:
        watch.swing_stirred[legs] = env.moving_near(box[:, :2], box[:, 2:])
        return None
    reach = watch.reach[legs]
    near = env.moving_near(np.concatenate([box[:, :2], spot[:, :2] - reach]),
                           np.concatenate([box[:, 2:], spot[:, :2] + reach]))
    watch.swing_stirred[legs] = near[: legs.size]
    return near[legs.size :]


def watch_reset(
    env: Environment, watch: Watch, legs: IntArray, spot: FloatArray,
    queried: tuple[FloatArray, BoolArray, FloatArray, BoolArray] | None = None, near: BoolArray | None = None,
) -> None:
    """Remember what is at and around the watched spots ``spot (m, 3)`` of ``legs (m,)`` now
    (a foot landed, or a swing was planned). ``queried``: the heights and forbidden flags at
    their ``ring_points``, then at the spots, when the caller asked for them already (in one
    query with others); ``near``: whether a moving obstacle reaches their rings now
    (``_ring_near``), when the caller asked already."""
    if not watch.dynamic or legs.size == 0:
        return
    if queried is None:
        pts = np.concatenate([ring_points(watch, legs, spot), spot[:, :2]])
        heights, flags = env.height_at(pts), env.forbidden_at(pts)
        k = heights.size - legs.size
        queried = (heights[:k], flags[:k], heights[k:], flags[k:])
    watch.ground[legs] = queried[0].reshape(legs.size, -1)
    watch.forbidden[legs] = queried[1].reshape(legs.size, -1)
    watch.spot_ground[legs] = queried[2]
    watch.spot_forbidden[legs] = queried[3]
    watch.spot_known[legs] = True
    watch.spot[legs] = spot[:, :2]
    watch.stirred[legs] = _ring_near(env, watch, legs, spot) if near is None else near


#: A look's point query: the heights and forbidden flags at the spots of the rows
#: ``asked[0]``, then at the rings of the rows ``asked[1]``, and which rings a moving
#: obstacle reaches now (``look_points``).
LookQuery = tuple[FloatArray, BoolArray, tuple[IntArray, IntArray], BoolArray]


def look_points(
    env: Environment, watch: Watch, legs: IntArray, spot: FloatArray, near: BoolArray | None = None
) -> tuple[FloatArray, tuple[IntArray, IntArray], BoolArray]:
    """What a look at the spots ``spot (m, 3)`` of ``legs`` asks: the points ``(p, 2)`` (the
    spots of the rows ``asked[0]``, then the rings of the rows ``asked[1]``), ``asked`` and
    which rings a moving obstacle reaches now ``(m,)`` (``near``: when the caller asked
    already). A ring is asked when its spot moved, or a moving obstacle reached it at the
    last look or reaches it now; a spot too, and when the watch does not know what is there;
    the others hold what the watch remembers."""
    if near is None:
        near = _ring_near(env, watch, legs, spot)
    moved = np.logical_or.reduce(spot[:, :2] != watch.spot[legs], axis=1)
    stirred = near | moved | watch.stirred[legs]
    rings = stirred.nonzero()[0]
    spots = (stirred | ~watch.spot_known[legs]).nonzero()[0]
    xy = np.concatenate([spot[spots, :2], ring_points(watch, legs[rings], spot[rings])])
    return xy, (spots, rings), near


def look(
    env: Environment, watch: Watch, legs: IntArray, spot: FloatArray, tol: FloatArray,
    queried: LookQuery | None = None,
) -> tuple[FloatArray, BoolArray, BoolArray]:
    """Query the watched spots ``spot (m, 3)`` of ``legs`` and the rings around them (one
    query of ``look_points``; ``queried``: its answer when the caller asked for those
    points already, in one query with others).

    Returns the surface ``(m,)`` and forbidden flags ``(m,)`` at the spots, and whether a
    moving obstacle closes in on each spot ``(m,)`` (since the last look, a ring point rose
    more than its leg's ``tol (N,)`` above the spot or became forbidden). The rings' memory
    moves on to now."""
    k = watch.offsets.shape[1]
    if queried is None:
        xy, asked, near = look_points(env, watch, legs, spot)
        queried = (env.height_at(xy), env.forbidden_at(xy), asked, near)
    heights, forbidden, (spots, rings), near = queried
    m = spots.size
    here_h = watch.spot_ground[legs]
    here_f = watch.spot_forbidden[legs]
    here_h[spots] = heights[:m]
    here_f[spots] = forbidden[:m]
    ring_h = watch.ground[legs]
    ring_f = watch.forbidden[legs]
    ring_h[rings] = heights[m:].reshape(rings.size, k)
    ring_f[rings] = forbidden[m:].reshape(rings.size, k)
    t = tol[legs][:, None]
    rose = (ring_h > watch.ground[legs] + t) & (ring_h > spot[:, 2, None] + t)
    coming = (rose | (ring_f & ~watch.forbidden[legs])).any(axis=1)
    watch.ground[legs] = ring_h
    watch.forbidden[legs] = ring_f
    watch.spot_ground[legs] = here_h
    watch.spot_forbidden[legs] = here_f
    watch.spot_known[legs] = True
    watch.spot[legs] = spot[:, :2]
    watch.stirred[legs] = near
    return here_h, here_f, coming


#: The look at the planted feet of a step (``look_around``): their legs ``(m,)``, and the
#: surface, forbidden flags and whether a moving obstacle closes in at their spots ``(m,)``.
PlantedLook = tuple[IntArray, FloatArray, BoolArray, BoolArray]


def look_around(
    env: Environment, watch: Watch, feet: FootState, landed: IntArray, swing: BoolArray, planted: BoolArray,
    progress: FloatArray, tol: FloatArray,
) -> tuple[BoolArray, PlantedLook]:
    """The looks of a step's foot-state rules, for every foot at once, in one rectangle query
    (``Environment.moving_near``) and one point query:

    - the feet ``landed (m,)`` (on ``feet.foot``) remember what is around their new spots
      (``watch_reset``);
    - the swinging feet ``swing (N,)``: whether a moving obstacle now cuts the rest of
      their trajectory (past ``progress (N,)``) or their target (by more than the leg's
      ``tol (N,)``), or closes in on it (once per swing: ``feet.dodged`` is updated);
    - the planted feet ``planted (N,)`` (the landed ones among them): their looks
      (``look``), for ``check_supports``.

    Returns the blocked swings ``(N,)`` and the planted feet's ``PlantedLook``. The swings'
    and planted feet's legs are apart from the landed ones, and a landed foot's look sees
    what its reset remembered (its spot did not move since)."""
    out = np.zeros(swing.shape[0], dtype=bool)
    legs = swing.nonzero()[0]
    p_legs = planted.nonzero()[0]
    plan = feet.plan
    spot_l = feet.foot[landed]
    targets = plan.target[legs]
    spot_p = feet.foot[p_legs]
    box = watch.swing_box[legs]
    nl, ns, n_p = landed.size, legs.size, p_legs.size
    # the rings around the landed spots, the swings' landing spots and the planted feet
    # (their bounding boxes, ``_ring_near``), and the swings' boxes: one rectangle query
    centre = np.concatenate([spot_l[:, :2], targets[:, :2], spot_p[:, :2]])
    reach = watch.reach[np.concatenate([landed, legs, p_legs])]
    near = env.moving_near(np.concatenate([centre - reach, box[:, :2]]),
                           np.concatenate([centre + reach, box[:, 2:]]))
    near_l, near_s = near[:nl], near[nl : nl + ns]
    near_p, near_box = near[nl + ns : nl + ns + n_p], near[nl + ns + n_p :]
    # a landed foot's watch moves to its spot before the planted feet's looks are made
    watch.spot_known[landed] = True
    watch.spot[landed] = spot_l[:, :2]
    watch.stirred[landed] = near_l
    # the swings: every other sample (and the landing one), a few centimetres apart on a
    # stride; those of the swings a moving obstacle reached when they were planned or
    # reaches now (the others hold what was recorded then)
    k_all = plan.traj.shape[1]
    cols, u_cols = _look_columns(k_all)
    k = cols.size
    pts = plan.traj[legs][:, cols]
    asked = (watch.swing_stirred[legs] | near_box).nonzero()[0]
    xy_s, rings_s, _ = look_points(env, watch, legs, targets, near_s)
    xy_p, rings_p, _ = look_points(env, watch, p_legs, spot_p, near_p)
    # one point query: the landed feet's rings and spots, the swings' samples, the swings'
    # landing spots and their rings, the planted feet's spots and rings
    xy = np.concatenate([ring_points(watch, landed, spot_l), spot_l[:, :2], pts[asked, :, :2].reshape(-1, 2),
                         xy_s, xy_p])
    heights = env.height_at(xy) if xy.shape[0] else np.zeros(0)
    flags = env.forbidden_at(xy) if xy.shape[0] else np.zeros(0, dtype=bool)
    a = nl * watch.offsets.shape[1]
    b = a + nl
    watch_reset(env, watch, landed, spot_l, (heights[:a], flags[:a], heights[a:b], flags[a:b]), near_l)
    c = b + asked.size * k
    d = c + xy_s.shape[0]
    if ns:
        planned = plan.ground[legs][:, cols]
        planned_forbidden = plan.forbidden[legs][:, cols]
        surface = planned.copy()
        forbidden = planned_forbidden.copy()
        surface[asked] = heights[b:c].reshape(asked.size, k)
        forbidden[asked] = flags[b:c].reshape(asked.size, k)
        # only what changed since the plan counts: something rose into the path, or became
        # forbidden
        t = tol[legs]
        u = swing_parameter(feet, progress)[legs]
        ahead = u_cols[None, :] >= u[:, None]
        risen = (surface > planned + t[:, None]) & (surface > pts[..., 2] + t[:, None])
        cut = ahead & (risen | (forbidden & ~planned_forbidden))
        # the landing spot itself must still be there, and nothing moving may be closing in
        # on it (once per swing: a foot that already moved its landing spot away lands;
        # spot_taken still stops it landing on the obstacle)
        queried = (heights[c:d], flags[c:d], rings_s, near_s)
        land_surface, _, coming = look(env, watch, legs, targets, tol, queried)
        moved = np.abs(land_surface - plan.support[legs]) > t
        coming &= ~feet.dodged[legs]
        feet.dodged[legs] |= coming
        out[legs] = cut.any(axis=1) | moved | coming
    looked: PlantedLook = (p_legs, np.zeros(0), np.zeros(0, dtype=bool), np.zeros(0, dtype=bool))
    if n_p:
        looked = (p_legs, *look(env, watch, p_legs, spot_p, tol, (heights[d:], flags[d:], rings_p, near_p)))
    return out, looked


@functools.lru_cache(maxsize=8)
def _look_columns(k_all: int) -> tuple[IntArray, FloatArray]:
    """The samples of a plan of ``k_all`` that :func:`look_around` reads (every other one and
    the landing one) and their swing parameters (read only)."""
    cols = np.unique(np.concatenate([np.arange(0, k_all, 2), [k_all - 1]]))
    u = np.linspace(0.0, 1.0, k_all)[cols]
    cols.setflags(write=False)
    u.setflags(write=False)
    return cols, u


def check_supports(
    env: Environment, feet: FootState, looked: PlantedLook | None, tol: FloatArray,
    push: Callable[[IntArray, FloatArray], None],
) -> BoolArray:
    """``(N,)`` planted feet whose support moved, rose into them or became forbidden (thesis
    sequence 4; by more than the leg's ``tol (N,)``), or that a moving obstacle closes in on,
    from the look at them (``looked``, ``look_around``; None where nothing moves). A foot an
    obstacle slid under anyway is pushed out by ``push(legs, surface)`` first."""
    out = np.zeros(feet.foot.shape[0], dtype=bool)
    if looked is None or looked[0].size == 0:
        return out
    legs, surface, forbidden, coming = looked
    # the foot's own spot, and something moving closing in around it (it steps away
    # before the obstacle reaches it)
    t = tol[legs]
    buried = surface > feet.foot[legs, 2] + t
    bad = (np.abs(surface - feet.support_z[legs]) > t) | buried
    out[legs] = bad | forbidden | coming
    if np.logical_or.reduce(buried):
        # an obstacle slid under a planted foot anyway: it pushes the foot out (the foot
        # steps off from there)
        at = legs[buried]
        push(at, surface[buried])
        h = env.height_at(feet.foot[at, :2])
        feet.support_z[at] = np.where(h > VOID, h, 0.0)
    return out


def push_out(
    env: Environment, watch: Watch, foot: FloatArray, legs: IntArray, surface: FloatArray,
    hips: FloatArray, reach: FloatArray, tol: FloatArray,
) -> None:
    """Feet ``foot[legs]`` (``foot (N, 3)``, moved in place) that a moving obstacle ran into
    (its top ``surface (m,)`` is above them) are pushed out of it the shorter way: up onto
    its top (never onto an avoided obstacle while there is room beside it), or aside to the
    nearest point around them (the watch rings, one to three times as far) that is free at
    their height (within the leg's ``tol (N,)``) and within ``reach (m,)`` of their hips
    ``hips (m, 3)``."""
    m = legs.size
    offsets = np.concatenate([f * watch.offsets[legs] for f in (1.0, 2.0, 3.0)], axis=1)
    k = offsets.shape[1]
    here = foot[legs, :2]
    pts = np.concatenate([here, (here[:, None, :] + offsets).reshape(-1, 2)])
    heights = env.height_at(pts)
    forbidden = env.forbidden_at(pts)
    ring_h = heights[m:].reshape(m, k)
    ring_f = forbidden[m:].reshape(m, k)
    z = foot[legs, 2]
    free = (ring_h <= z[:, None] + tol[legs][:, None]) & ~ring_f & (ring_h > VOID)
    # within the leg's reach
    top = np.maximum(ring_h, z[:, None])
    spots = np.concatenate([here[:, None, :] + offsets, top[..., None]], axis=2)
    free &= vector_norm(spots - hips[:, None, :]) <= reach[:, None]
    # the nearest ring with room, and on it the point facing away from the obstacle
    # (the mean direction of the points it covers), so the foot is not pushed ahead of it
    radius = np.linalg.norm(offsets, axis=2)
    unit = offsets / np.maximum(radius, 1e-12)[..., None]
    covered = np.where(~free[..., None], unit, 0.0).sum(axis=1)
    norm = np.maximum(np.linalg.norm(covered, axis=1), 1e-12)
    away = -np.einsum("mkd,md->mk", unit, covered) / norm[:, None]
    ring_no = np.repeat(np.arange(3), k // 3)[None, :]
    first = np.min(np.where(free, ring_no, 3), axis=1)
    rank = np.where(free & (ring_no == first[:, None]), away, -np.inf)
    pick = np.argmax(rank, axis=1)
    best = np.where(free.any(axis=1), radius[np.arange(m), pick], np.inf)
    aside = (best < surface - z) | (forbidden[:m] & np.isfinite(best))
    side, up = legs[aside], legs[~aside]
    foot[side, :2] += offsets[aside, pick[aside]]
    foot[side, 2] = np.maximum(foot[side, 2], ring_h[aside, pick[aside]])
    foot[up, 2] = surface[~aside]


def spot_taken(
    env: Environment, watch: Watch, feet: FootState, points: FloatArray, which: BoolArray, tol: FloatArray
) -> tuple[BoolArray, FloatArray | None]:
    """``(N,)`` whether a moving obstacle now covers the footprints ``points (N, 3)`` of legs
    ``which (N,)`` (rose above them by more than the leg's ``tol (N,)`` or made them
    forbidden since they were planned), and the surface under them ``(N,)`` (valid at
    ``which``; None where nothing moves: nothing was asked)."""
    out = np.zeros(which.shape[0], dtype=bool)
    legs = which.nonzero()[0]
    if not watch.dynamic or legs.size == 0:
        return out, None
    xy = points[legs, :2]
    surface = env.height_at(xy)
    newly_forbidden = env.forbidden_at(xy) & ~feet.plan.forbidden[legs, -1]
    out[legs] = (surface > points[legs, 2] + tol[legs]) | newly_forbidden
    under = np.zeros(which.shape[0])
    under[legs] = surface
    return out, under


def onto_support(env: Environment, rig: Rig, xy: FloatArray, char: int) -> FloatArray | None:
    """The shortest shift ``(2,)``, within the foot box's size or a planning cell,
    whichever is more (the planner sees the ground per cell), that puts a footprint's
    point ``xy (2,)`` of character ``char`` over ground (not over a hole, not into an
    avoided obstacle), with a quarter of the box's half size to spare; None if there is
    none."""
    half = float(np.max(rig.foot_half[char]))
    if half <= 0.0:
        return None
    radius = max(2.0 * half, float(rig.window_cell[char]))
    grid = np.linspace(-radius, radius, 17)
    off = np.stack(np.meshgrid(grid, grid, indexing="ij"), axis=-1).reshape(-1, 2)
    off = off[np.argsort(np.hypot(off[:, 0], off[:, 1]), kind="stable")][1:]
    norm = np.hypot(off[:, 0], off[:, 1])[:, None]
    spare = off + 0.25 * half * off / np.maximum(norm, 1e-12)
    pts = np.concatenate([xy[None, :] + off, xy[None, :] + spare])
    ok = (env.height_at(pts) > VOID) & ~env.forbidden_at(pts)
    good = ok[: off.shape[0]] & ok[off.shape[0]:]
    if not np.any(good):
        return None
    return np.asarray(spare[int(np.flatnonzero(good)[0])], dtype=np.float64)
