# SPDX-License-Identifier: GPL-3.0-or-later
"""Characters that see each other: a crowd's bodies and feet as moving obstacles (thesis
§3.4.1's dynamic obstacles, the other characters being the obstacles) and local steering
around each other. Switched per character (``Simulation(avoid=...)``); off, nothing here runs.

For a character that avoids the others:

- **Bodies.** Every other character's body box (``Morphology.body_box_*`` at its pelvis pose;
  along a flexible spine, one box per spine bone) is an obstacle for its feet: the cells
  under it (and ``KEEP_OUT`` leg lengths around it) are avoided cells of the planning window,
  so no footprint is planned inside it; a swinging foot whose landing spot another body now
  covers re-plans, and a planted foot that another body comes within half ``KEEP_OUT`` of
  steps away (a forced step, as for a moving crate; once per approach). A character's own
  body never forbids its own feet (every box has an owner).
- **Feet.** Another character's planted feet and the landing spots of its swinging ones are
  avoided discs (its sole's half size) in the window: feet never land on each other.
- **Steering.** Before the controller plans, the commanded heading (and, if no heading
  helps, the speed) is chosen by reciprocal velocity obstacles sampled as in van den Berg,
  Lin and Manocha 2008, "Reciprocal Velocity Obstacles for real-time multi-agent
  navigation" (ICRA), §V: each character is a disc around its feet; candidate velocities
  around the preferred one are scored by ``w / tc + |v_pref - v|`` (``tc``: time to the
  first contact with any neighbour if it took the candidate and the neighbour kept half the
  avoiding effort, ``2 v - v_i - v_j``; a neighbour that does not avoid is a plain velocity
  obstacle, ``v - v_j``) and the best is taken, over the ``MAX_NEIGHBOURS`` nearest. A
  candidate that would pass close to a neighbour with the neighbour on its right costs more
  (keep right: the rule reads the same from both, so two characters agree on the side they
  pass; crossing paths, one of them gives way). Candidates are tried in a fixed order (the
  straight one first, then right before left), so the result is deterministic and two
  characters meeting head-on both keep right. The preferred heading and speed stay the
  user's (a path's follower aims from where the character is), so the original heading is
  resumed once nothing is in the way.

Cost: one ``(C, C)`` distance matrix per step, then only the pairs close enough to meet
within ``HORIZON`` seconds are scored (vectorised over pairs and candidates); the body and
feet checks run only for characters with a neighbour within a leg (``neighbours``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..world.terrain import WindowGrids
from .rig import Rig
from .types import BoolArray, FloatArray, IntArray

__all__ = ["HORIZON", "KEEP_OUT", "MAX_NEIGHBOURS", "BodyBoxes", "body_boxes", "feet_in_bodies",
           "footprint_discs", "inside_other", "mark_window", "neighbours", "steer"]

#: Seconds ahead within which a possible contact steers a character.
HORIZON = 3.0
#: Neighbours (the nearest) a character steers around at once.
MAX_NEIGHBOURS = 8
#: Margin around another body's box kept free of footprints, in leg lengths.
KEEP_OUT = 0.1
#: Heading offsets tried (radians), the straight one first, then right before left.
_OFFSETS = np.radians(np.concatenate([[0.0], *[[-d, d] for d in range(10, 100, 10)]]))
#: Speed factors tried with every offset.
_SPEEDS = np.array([1.0, 0.5, 0.15])
#: Weight of the time-to-contact term (× the preferred speed, seconds) and of a change from
#: the last choice (against flicker).
_W_CONTACT = 1.5
_W_CHANGE = 0.3
#: Weight (× the preferred speed) of passing a neighbour on the wrong side, and how close
#: (× the contact distance) counts as passing it.
_W_SIDE = 1.0
_SIDE_CLOSE = 1.5


@dataclass(frozen=True)
class BodyBoxes:
    """Upright boxes (their ground footprint) of every character's body: ``owner (B,)``
    character, ``center (B, 2)``, ``half (B, 2)`` along/across, ``yaw (B,)``."""

    owner: IntArray
    center: FloatArray
    half: FloatArray
    yaw: FloatArray

    @property
    def radius(self) -> FloatArray:
        """``(B,)`` half diagonal of each box."""
        return np.asarray(np.hypot(self.half[:, 0], self.half[:, 1]))


def body_boxes(box_center: FloatArray, box_half: FloatArray, pos: FloatArray, yaw: FloatArray,
               spine_joints: FloatArray | None = None, spine_n_joints: IntArray | None = None) -> BodyBoxes:
    """The body boxes of every character: its body box (``box_center``, ``box_half (C, 2)``
    in the body frame, ``Rig.box_*``) at its pelvis ``pos (C, 3)``, ``yaw (C,)``; a character
    with a spine of ``spine_n_joints (C,)`` > 1 joints ``spine_joints (C, J, 3)`` gets one box
    per spine bone instead (its body's width, as long as the bone plus half the width at each
    end)."""
    c = box_center.shape[0]
    spined = np.zeros(c, dtype=bool) if spine_n_joints is None else np.asarray(spine_n_joints) > 1
    rigid = np.flatnonzero(~spined)
    cos, sin = np.cos(yaw[rigid]), np.sin(yaw[rigid])
    bc = box_center[rigid]
    turned = np.stack([cos * bc[:, 0] - sin * bc[:, 1], sin * bc[:, 0] + cos * bc[:, 1]], axis=1)
    out = BodyBoxes(rigid.astype(np.int64), pos[rigid, :2] + turned, box_half[rigid], yaw[rigid])
    if spine_joints is None or spine_n_joints is None or not np.any(spined):
        return out
    # every spined character's bones at once, character after character, head first
    sp = np.flatnonzero(spined)
    bones = np.asarray(spine_n_joints)[sp] - 1
    j = spine_joints[sp, :, :2]
    real = np.arange(j.shape[1] - 1)[None, :] < bones[:, None]
    seg = (j[:, 1:] - j[:, :-1])[real]
    length = np.hypot(seg[:, 0], seg[:, 1])
    width = np.repeat(box_half[sp, 1], bones)
    return BodyBoxes(np.concatenate([out.owner, np.repeat(sp, bones)]).astype(np.int64),
                     np.concatenate([out.center, (0.5 * (j[:, 1:] + j[:, :-1]))[real]]),
                     np.concatenate([out.half, np.column_stack([0.5 * length + 0.5 * width, width])]),
                     np.concatenate([out.yaw, np.arctan2(seg[:, 1], seg[:, 0])]))


def _local(boxes: BodyBoxes, xy: FloatArray) -> FloatArray:
    """``(m, B, 2)`` points ``xy (m, 2)`` in every box's frame (``|local| <= half``: inside)."""
    d = xy[:, None, :] - boxes.center[None]
    cos, sin = np.cos(boxes.yaw), np.sin(boxes.yaw)
    return np.stack([cos * d[..., 0] + sin * d[..., 1], -sin * d[..., 0] + cos * d[..., 1]], axis=-1)


def inside_other(boxes: BodyBoxes, xy: FloatArray, owner: IntArray,
                 margin: FloatArray | float = 0.0) -> BoolArray:
    """``(m,)`` whether each point ``xy (m, 2)`` of character ``owner (m,)`` is inside (within
    ``margin`` of) a body box of another character."""
    if xy.shape[0] == 0 or boxes.owner.size == 0:
        return np.zeros(xy.shape[0], dtype=bool)
    loc = np.abs(_local(boxes, xy))
    mg = np.broadcast_to(np.asarray(margin, dtype=np.float64), (xy.shape[0],))[:, None]
    hit = (loc[..., 0] <= boxes.half[None, :, 0] + mg) & (loc[..., 1] <= boxes.half[None, :, 1] + mg)
    hit &= boxes.owner[None, :] != owner[:, None]
    return np.asarray(hit.any(axis=1))


def feet_in_bodies(boxes: BodyBoxes, xy: FloatArray, owner: IntArray) -> FloatArray:
    """``(m,)`` how deep each point ``xy (m, 2)`` of character ``owner (m,)`` is inside another
    character's body box (metres to its nearest side; 0 outside)."""
    if xy.shape[0] == 0 or boxes.owner.size == 0:
        return np.zeros(xy.shape[0])
    loc = np.abs(_local(boxes, xy))
    depth = np.minimum(boxes.half[None, :, 0] - loc[..., 0], boxes.half[None, :, 1] - loc[..., 1])
    depth = np.where(boxes.owner[None, :] != owner[:, None], depth, 0.0)
    return np.asarray(np.maximum(depth.max(axis=1), 0.0))


def mark_window(grid: WindowGrids, boxes: BodyBoxes, owner: int, margin: float, feet_xy: FloatArray,
                feet_owner: IntArray, feet_radius: FloatArray) -> WindowGrids:
    """``grid`` with the cells touching other characters' body boxes (grown by ``margin``)
    or the discs of ``feet_radius (k,)`` around their feet ``feet_xy (k, 2)`` (owners
    ``feet_owner (k,)``) added to its avoided cells (the planner grows them by the foot's
    own box); ``grid`` itself when none of them reaches the window."""
    ny, nx = grid.shape
    cell = grid.cell
    lo = grid.origin - 0.5 * cell
    hi = lo + cell * np.array([nx, ny])
    grow = margin + 0.5 * cell  # a cell counts when any of it is covered (to half a cell)
    reach_b = boxes.radius + grow
    bsel = np.flatnonzero((boxes.owner != owner) & np.all(boxes.center + reach_b[:, None] >= lo, axis=1)
                          & np.all(boxes.center - reach_b[:, None] <= hi, axis=1))
    reach_f = feet_radius + 0.5 * cell
    fsel = np.flatnonzero((feet_owner != owner) & np.all(feet_xy + reach_f[:, None] >= lo, axis=1)
                          & np.all(feet_xy - reach_f[:, None] <= hi, axis=1))
    if bsel.size == 0 and fsel.size == 0:
        return grid
    extra = np.zeros((ny, nx), dtype=bool)
    for b in bsel:  # (a few boxes reach a window)
        r = float(reach_b[b])
        i0, j0 = np.floor((boxes.center[b] - r - lo) / cell).astype(int)
        i1, j1 = np.ceil((boxes.center[b] + r - lo) / cell).astype(int)
        i0, i1, j0, j1 = max(i0, 0), min(i1, nx), max(j0, 0), min(j1, ny)
        if i0 >= i1 or j0 >= j1:
            continue
        gx, gy = np.meshgrid(grid.origin[0] + cell * np.arange(i0, i1),
                             grid.origin[1] + cell * np.arange(j0, j1))
        dx, dy = gx - boxes.center[b, 0], gy - boxes.center[b, 1]
        cos, sin = np.cos(boxes.yaw[b]), np.sin(boxes.yaw[b])
        along, across = np.abs(cos * dx + sin * dy), np.abs(-sin * dx + cos * dy)
        extra[j0:j1, i0:i1] |= (along <= boxes.half[b, 0] + grow) & (across <= boxes.half[b, 1] + grow)
    if fsel.size:
        # every foot's disc on a stencil of the cells around its own
        k = int(np.ceil(float(reach_f[fsel].max()) / cell)) + 1
        off = np.arange(-k, k + 1)
        oi, oj = (a.ravel() for a in np.meshgrid(off, off))
        fi = np.floor((feet_xy[fsel] - lo) / cell).astype(int)
        ci, cj = fi[:, 0:1] + oi[None], fi[:, 1:2] + oj[None]
        dx = grid.origin[0] + cell * ci - feet_xy[fsel, 0:1]
        dy = grid.origin[1] + cell * cj - feet_xy[fsel, 1:2]
        hit = (dx * dx + dy * dy <= (reach_f[fsel] ** 2)[:, None]) & (ci >= 0) & (ci < nx)
        hit &= (cj >= 0) & (cj < ny)
        extra[cj[hit], ci[hit]] = True
    if not extra.any():
        return grid
    return WindowGrids(grid.origin, grid.cell, grid.elevation, grid.avoid | extra,
                       grid.foot_half_extents, grid.foot_yaw, stack=grid.stack)


def neighbours(center: FloatArray, radius: FloatArray, reach: FloatArray, avoid: BoolArray) -> BoolArray:
    """``(C, C)`` pairs ``[i, j]`` of characters ``i`` with ``avoid (C,)`` whose discs
    (``center (C, 2)``, ``radius (C,)``, see ``footprint_discs``) are within ``reach[i]`` of
    another's: the only ones whose bodies and feet ``i``'s feet check."""
    d = center[:, None, :] - center[None, :, :]
    dist2 = np.einsum("ijd,ijd->ij", d, d)
    lim = radius[:, None] + reach[:, None] + radius[None, :]
    near = (dist2 < lim * lim) & avoid[:, None]
    np.fill_diagonal(near, False)
    return np.asarray(near)


def footprint_discs(rig: Rig) -> tuple[FloatArray, FloatArray]:
    """Each character's steering disc: its centre in the body frame ``(C, 2)`` (the middle of
    its rest feet and body box) and radius ``(C,)`` (reaching every rest foot's box and the
    body box's corners)."""
    c = rig.n_chars
    feet = rig.legs.rest_foot[:, :2]
    corner = np.linalg.norm(rig.foot_half, axis=1)[rig.leg_char]
    lo = np.full((c, 2), np.inf)
    hi = np.full((c, 2), -np.inf)
    np.minimum.at(lo, rig.leg_char, feet - corner[:, None])
    np.maximum.at(hi, rig.leg_char, feet + corner[:, None])
    lo = np.minimum(lo, rig.box_center - rig.box_half)
    hi = np.maximum(hi, rig.box_center + rig.box_half)
    center = 0.5 * (lo + hi)
    dist = np.linalg.norm(feet - center[rig.leg_char], axis=1) + corner
    radius = np.zeros(c)
    np.maximum.at(radius, rig.leg_char, dist)
    box = np.linalg.norm(np.abs(rig.box_center - center) + rig.box_half, axis=1)
    return center, np.maximum(radius, box)


def steer(
    center: FloatArray, radius: FloatArray, velocity: FloatArray, heading: FloatArray, speed: FloatArray,
    avoid: BoolArray, last: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Headings and speeds ``(C,)`` for characters with discs ``center (C, 2)``, ``radius
    (C,)`` moving at ``velocity (C, 2)``, asked for ``heading``, ``speed (C,)``; those with
    ``avoid (C,)`` steer around the others (reciprocal velocity obstacles, see the module
    docstring). ``last (C, 2)``: the velocities chosen at the last step (a change from them
    costs a little)."""
    out_h, out_v = heading.astype(np.float64).copy(), speed.astype(np.float64).copy()
    c = center.shape[0]
    if c < 2 or not np.any(avoid):
        return out_h, out_v
    v_now = np.hypot(velocity[:, 0], velocity[:, 1])
    reach = radius[:, None] + radius[None, :] + HORIZON * (np.maximum(speed, v_now)[:, None]
                                                          + np.maximum(speed, v_now)[None, :])
    d = center[None, :, :] - center[:, None, :]
    dist = np.hypot(d[..., 0], d[..., 1])
    near = (dist < reach) & avoid[:, None] & (speed > 0.0)[:, None]
    np.fill_diagonal(near, False)
    if c > MAX_NEIGHBOURS + 1:
        # the nearest few only (van den Berg et al. also bound the neighbours considered)
        gap = np.where(near, dist - radius[None, :], np.inf)
        keep = np.argpartition(gap, MAX_NEIGHBOURS, axis=1)[:, :MAX_NEIGHBOURS]
        nearest = np.zeros_like(near)
        np.put_along_axis(nearest, keep, True, axis=1)
        near &= nearest
    ii, jj = np.nonzero(near)
    if ii.size == 0:
        return out_h, out_v
    # candidates (C, K) around each preferred velocity, x and y apart (every (pair,
    # candidate) array below runs along the candidates; they are worked in place: a
    # temporary of a hundred characters' pairs is larger than the allocator keeps at hand)
    ang = heading[:, None] + np.repeat(_OFFSETS, _SPEEDS.size)[None, :]
    mag = speed[:, None] * np.tile(_SPEEDS, _OFFSETS.size)[None, :]
    cand_x, cand_y = np.cos(ang) * mag, np.sin(ang) * mag
    # reciprocal toward a neighbour that also avoids (2 v - v_i - v_j), a plain velocity
    # obstacle otherwise (v - v_j)
    vjx, vjy = velocity[jj, 0][:, None], velocity[jj, 1][:, None]
    recip = avoid[jj]
    if np.all(recip):
        ux = (2.0 * cand_x)[ii]
        ux -= velocity[ii, 0][:, None]
        ux -= vjx
        uy = (2.0 * cand_y)[ii]
        uy -= velocity[ii, 1][:, None]
        uy -= vjy
    else:
        cx, cy = cand_x[ii], cand_y[ii]
        r = recip[:, None]
        ux = np.where(r, 2.0 * cx - velocity[ii, 0][:, None] - vjx, cx - vjx)
        uy = np.where(r, 2.0 * cy - velocity[ii, 1][:, None] - vjy, cy - vjy)
    px, py = d[ii, jj, 0][:, None], d[ii, jj, 1][:, None]
    big_r = (radius[ii] + radius[jj])[:, None]
    a = ux * ux
    a += uy * uy
    b = px * ux
    b += py * uy
    cc = px * px + py * py - big_r ** 2  # (pairs, 1)
    disc = b * b
    disc -= a * cc
    np.maximum(a, 1e-18, out=a)  # (a is only ever divided by from here on)
    root = np.maximum(disc, 0.0)
    np.sqrt(root, out=root)
    np.subtract(b, root, out=root)
    root /= a
    ahead = b > 0.0
    # the first contact: the smaller root where the paths meet
    tc = np.where(ahead & (disc >= 0.0), root, np.inf)
    # already touching: any candidate still closing in is a contact now
    touching = np.flatnonzero(cc[:, 0] < 0.0)
    if touching.size:
        tc[touching] = np.where(ahead[touching], 0.0, np.inf)
    # per character (np.nonzero gives the pairs sorted by ii): the first contact over its pairs
    rows, starts = np.unique(ii, return_index=True)
    first = np.minimum.reduceat(tc, starts, axis=0)
    # keep right: a candidate passing close to a neighbour (within _SIDE_CLOSE of the
    # contact distance, before HORIZON) with the neighbour on its right costs more; the rule
    # is the same seen from both, so two characters agree on how they pass
    t_close = np.divide(b, a, out=root)
    d2_close = b * t_close
    np.subtract(cc + big_r ** 2, d2_close, out=d2_close)
    close = ahead  # (ahead is not read again: it becomes the close-pass mask in place)
    close &= t_close < HORIZON
    close &= d2_close < (_SIDE_CLOSE * big_r) ** 2
    np.multiply(ux, py, out=ux)
    np.multiply(uy, px, out=uy)
    close &= ux - uy < 0.0
    side = np.logical_or.reduceat(close, starts, axis=0)
    w = _W_CONTACT * speed[rows, None]
    contact = w * np.maximum(1.0 / np.maximum(first, 1e-3) - 1.0 / HORIZON, 0.0)
    contact = contact + _W_SIDE * speed[rows, None] * side
    ex = cand_x[rows] - (np.cos(heading[rows]) * speed[rows])[:, None]
    ey = cand_y[rows] - (np.sin(heading[rows]) * speed[rows])[:, None]
    cost = contact + np.sqrt(ex * ex + ey * ey)
    if last is not None:
        ex = cand_x[rows] - last[rows, 0][:, None]
        ey = cand_y[rows] - last[rows, 1][:, None]
        cost = cost + _W_CHANGE * np.sqrt(ex * ex + ey * ey)
    best = np.argmin(cost, axis=1)
    k_off, k_speed = np.divmod(best, _SPEEDS.size)
    out_h[rows] = heading[rows] + _OFFSETS[k_off]
    out_v[rows] = speed[rows] * _SPEEDS[k_speed]
    return out_h, out_v
