# SPDX-License-Identifier: GPL-3.0-or-later
"""The footprint graph and A* search (biped thesis §3.2, after Choi, Lee and Shin 2003).

Nodes are right-foot footprints sampled over the walkable surface: one position per cell
of a ``cell``-sized lattice (jittered inside the cell by the seeded generator, kept where a
foot fits) times ``headings`` jittered headings; a node is used only where the foot's whole
sole at that heading is supported (:meth:`.WalkableSurface.supports`: not over a step's
edge, not into a riser). An edge leaves node ``a`` for every walk, run or jump clip: the
clip, started on ``a``, puts the right foot down again at a predicted pose, and the edge
goes to the supported node nearest that pose within the position and heading tolerances.

Walking clips also give *short strides*: the clip's root travel scaled by each of
``stride_scales`` (its turn kept), the feet placed about the root as in the clip. They are
offered only where a step blocks the clip's natural stride (a predicted footprint straddles
a step's edge or a half step rises too much) and near the goal (to stop in the right
place), so open ground is searched as before. On
stairs whose treads are shorter than a natural step they put a foot on every tread where
natural strides would land on an edge; the refinement, body trajectory and IK stages fit
the clip to the shorter footprints as they fit any other mismatch (the character then
climbs at the clip's cadence with shorter steps, as people do).

An edge exists only if

* the left footprint the clip makes in between is supported (shifted along its heading by
  up to ``left_search`` if need be: smoothing and refinement move it anyway);
* every half step (right to left, left to right) rises or drops by at most
  ``max_step_height``, so stairs are climbed one step at a time and never by a leap;
* for walks and runs, the ground under each half step is walkable, without a gap, a pit
  deeper than a step or anything higher than a step above the feet: walking never crosses
  a gap;
* for jumps, the run-up is walkable in the same way and the flight *does* cross a gap (or a
  pit deeper than a step): jumping is only for gaps, never onto a step one could walk up.

Edges are generated lazily while A* expands nodes, so only the part of the graph the
search visits is ever built. Edge cost is the clip's root path length times a per-role
weight (running and jumping cost more than walking, so a jump is chosen only where no
walkable route exists) plus a small cost per radian turned; a short stride costs its
shortened length plus ``short_stride_cost`` of what it left out, so the search takes short
strides only where natural ones do not fit. The heuristic is the walking distance to the
goal on a coarse grid of the surface (gaps narrower than a jump are crossable at the jump
weight), computed once per search by vectorised relaxation; it gives up at once when the
goal cannot be reached at all.

The search starts from the right footprint after the START clip and ends at the first
node from which the STOP clip brings the body within ``goal_radius`` of the goal.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import quat
from .database import ClipDatabase, ClipInfo
from .surface import WalkableSurface

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


class PlanningError(ValueError):
    """The planner cannot produce a motion; the message says why, for the animator."""


class NoClipsError(PlanningError):
    pass


class GoalOffSurfaceError(PlanningError):
    pass


class StartOffSurfaceError(PlanningError):
    pass


class GoalUnreachableError(PlanningError):
    pass


class PlanCancelled(Exception):  # noqa: N818 - not an error: the user pressed Esc
    """The progress callback asked to stop."""


@dataclass(frozen=True)
class GraphSettings:
    """Sampling, tolerances, costs and search limits of the footprint graph.

    Lengths in metres, angles in radians. ``position_tolerance``/``heading_tolerance``
    default to the lattice cell and one heading bin. ``role_cost`` weights the clips' root
    path length by role family; ``heuristic_weight > 1`` makes the search greedier (and
    faster) at the price of slightly longer paths. ``stride_scales`` are the walking strides
    offered (fractions of each walk clip's own travel; 1 is the clip itself),
    ``short_stride_cost`` the fraction of the left-out length a short stride still costs,
    ``left_search`` how far (default: half the position tolerance) the left footprint may
    shift along its heading to find support. ``support_samples`` ground samples check each
    half step (twice as many a jump's flight).
    """

    cell: float = 0.1
    headings: int = 24
    jitter: float = 0.8
    position_tolerance: float | None = None
    heading_tolerance: float | None = None
    max_step_height: float = 0.2
    role_cost: dict[str, float] = field(default_factory=lambda: {"walk": 1.0, "run": 2.0, "jump": 2.0})
    turn_cost: float = 0.5
    heuristic_weight: float = 1.2
    goal_radius: float = 0.25
    goal_heading_tolerance: float = 0.6
    max_expansions: int = 60_000
    batch: int = 16
    support_samples: int = 8
    field_cell: float = 0.2
    stride_scales: tuple[float, ...] = (1.0, 0.75, 0.55, 0.35)
    short_stride_cost: float = 0.2
    left_search: float | None = None


@dataclass(frozen=True)
class GraphPath:
    """A* result: ``right_pos (n, 3)``/``right_yaw (n,)`` the right footprints from the one
    after the START clip to the last before the STOP clip, ``clips (n - 1,)`` the clip of
    each edge between them, ``scales (n - 1,)`` the stride scale of each edge (1: the clip's
    own stride), ``expansions`` the number of nodes expanded."""

    right_pos: FloatArray
    right_yaw: FloatArray
    clips: IntArray
    expansions: int
    scales: FloatArray | None = None


@dataclass(frozen=True)
class _EdgeTable:
    """Per locomotion clip and stride scale, relative to its starting right footprint."""

    clip: IntArray
    end_pos: FloatArray  # (C, 3) next right footprint
    end_yaw: FloatArray
    left_pos: FloatArray  # (C, 3) the left footprint in between
    cost: FloatArray
    jump: BoolArray
    left_yaw: FloatArray
    scale: FloatArray
    natural: IntArray  # (C,) the column of the same clip at its natural stride


def _inverse(pos: FloatArray, yaw: float) -> tuple[FloatArray, float]:
    p, y = quat.relative2(np.asarray(pos, dtype=float), float(yaw), np.zeros(3), 0.0)
    return p, float(y)


def relative_to_right(info: ClipInfo, pos: FloatArray, yaw: float) -> tuple[FloatArray, float]:
    """A pose given relative to a clip's root at phase 0, re-expressed relative to the
    clip's starting right footprint."""
    rs = info.right_start
    inv_p, inv_y = _inverse(rs.pos, rs.yaw)
    p, y = quat.compose2(inv_p, inv_y, np.asarray(pos, dtype=float), float(yaw))
    return p, float(y)


def _scaled(
    db: ClipDatabase, info: ClipInfo, pos: FloatArray, yaw: float, phase: float, scale: float
) -> tuple[FloatArray, float]:
    """A footprint of a clip (relative to its root at phase 0, planted around ``phase``) on
    the clip's stride scaled by ``scale``: the root's travel up to ``phase`` is scaled, its
    turn kept, and the foot keeps its place relative to the root."""
    if scale == 1.0:
        return np.asarray(pos, dtype=float), float(yaw)
    rp, ry = db.sample_root(np.array(info.index), np.array(phase))
    rel_p, rel_y = quat.relative2(rp, float(ry), np.asarray(pos, dtype=float), float(yaw))
    moved = np.array([scale * rp[0], scale * rp[1], rp[2]])
    p, y = quat.compose2(moved, float(ry), rel_p, float(rel_y))
    return p, float(y)


def stride_geometry(
    db: ClipDatabase, info: ClipInfo, scale: float = 1.0
) -> tuple[FloatArray, float, FloatArray, float]:
    """Next right footprint and the left footprint in between, relative to the starting
    right footprint, of a walk/run/jump clip whose stride is scaled by ``scale``:
    ``(end_pos (3,), end_yaw, left_pos (3,), left_yaw)``."""
    rs = info.right_start
    ls = info.left_step
    start_p, start_y = _scaled(db, info, rs.pos, rs.yaw, 0.5 * (rs.td + rs.lo), scale)
    left_p, left_y = _scaled(db, info, ls.pos, ls.yaw, 0.5 * (ls.td + ls.lo), scale)
    if scale == 1.0 or not info.loops:
        end_p, end_y = np.asarray(info.end_right_pos, dtype=float), float(info.end_right_yaw)
    else:
        cycle = np.array([scale * info.cycle_pos[0], scale * info.cycle_pos[1], info.cycle_pos[2]])
        end_p, end_y_arr = quat.compose2(cycle, info.cycle_yaw, start_p, start_y)
        end_y = float(end_y_arr)
    e_p, e_y = quat.relative2(start_p, start_y, end_p, end_y)
    l_p, l_y = quat.relative2(start_p, start_y, left_p, left_y)
    return e_p, float(e_y), l_p, float(l_y)


def _edge_table(db: ClipDatabase, infos: list[ClipInfo], settings: GraphSettings) -> _EdgeTable:
    rows: list[tuple[ClipInfo, float]] = []
    for info in infos:
        scales = settings.stride_scales if info.role.family == "walk" else (1.0,)
        rows += [(info, float(f)) for f in dict.fromkeys((1.0, *scales)) if f > 0.0]
    n = len(rows)
    end_pos = np.zeros((n, 3))
    end_yaw = np.zeros(n)
    left_pos = np.zeros((n, 3))
    left_yaw = np.zeros(n)
    cost = np.zeros(n)
    jump = np.zeros(n, dtype=bool)
    scale = np.zeros(n)
    natural = {info.index: j for j, (info, f) in enumerate(rows) if f == 1.0}
    for i, (info, f) in enumerate(rows):
        end_pos[i], end_yaw[i], left_pos[i], left_yaw[i] = stride_geometry(db, info, f)
        weight = settings.role_cost.get(info.role.family, 1.0)
        length = info.path_length * (f + settings.short_stride_cost * max(0.0, 1.0 - f))
        cost[i] = length * weight + settings.turn_cost * abs(info.cycle_yaw)
        jump[i] = info.role.family == "jump"
        scale[i] = f
    return _EdgeTable(
        np.array([info.index for info, _ in rows], dtype=np.int64),
        end_pos,
        end_yaw,
        left_pos,
        cost,
        jump,
        left_yaw,
        scale,
        np.array([natural[info.index] for info, _ in rows], dtype=np.int64),
    )


class FootprintGraph:
    """The lazily built footprint graph over a walkable surface (see the module docstring)."""

    def __init__(
        self,
        db: ClipDatabase,
        surface: WalkableSurface,
        settings: GraphSettings,
        rng: np.random.Generator,
        families: tuple[str, ...] = ("walk", "run", "jump"),
    ) -> None:
        self.db = db
        self.surface = surface
        self.settings = settings
        locomotion = [info for info in db.infos if info.role.family in families]
        if not locomotion:
            raise NoClipsError("no walk, run or jump clip is tagged")
        self.edges = _edge_table(db, locomotion, settings)
        cell = settings.cell
        k = settings.headings
        lo = surface.origin
        size = np.array(surface.z.shape) * surface.cell
        self.origin = lo
        self.nx, self.ny = (np.ceil(size / cell).astype(int)).tolist()
        jit = settings.jitter
        offset = 0.5 + jit * (rng.random((self.nx, self.ny, 2)) - 0.5)
        gx, gy = np.meshgrid(np.arange(self.nx), np.arange(self.ny), indexing="ij")
        xy = lo + (np.stack((gx, gy), axis=-1) + offset) * cell
        self.cell_xy = xy
        self.cell_ok = surface.fits(xy)
        self.cell_z = np.where(self.cell_ok, surface.raster_height(xy), np.nan)
        self.bin = 2 * np.pi / k
        self.heading_offset = 0.5 + jit * (rng.random((self.nx, self.ny, k)) - 0.5)
        self.tol_p = settings.position_tolerance or cell
        self.tol_h = settings.heading_tolerance or self.bin
        self.left_search = 0.5 * self.tol_p if settings.left_search is None else settings.left_search
        # Whether each node's sole is supported: -1 not known yet, computed on first use.
        self._node_support = np.full((self.nx, self.ny, k), -1, dtype=np.int8)
        # Short strides are offered to any footprint this close to the goal (set by search).
        natural = self.edges.scale == 1.0
        self.near_goal = 1.5 * float(np.max(np.linalg.norm(self.edges.end_pos[natural, :2], axis=1)))
        self.goal_xy: FloatArray | None = None

    # -- nodes --------------------------------------------------------------------------------

    def node_pose(self, node: int) -> tuple[FloatArray, float]:
        k = self.settings.headings
        c, h = divmod(node, k)
        ix, iy = divmod(c, self.ny)
        xy = self.cell_xy[ix, iy]
        return np.array([xy[0], xy[1], self.cell_z[ix, iy]]), float(
            (h + self.heading_offset[ix, iy, h]) * self.bin
        )

    def node_supported(self, cx: IntArray, cy: IntArray, hk: IntArray) -> BoolArray:
        """Whether the foot of each node (cell indices and heading bin) is supported."""
        known = self._node_support[cx, cy, hk]
        todo = known < 0
        if np.any(todo):
            tx, ty, th = cx[todo], cy[todo], hk[todo]
            yaw = (th + self.heading_offset[tx, ty, th]) * self.bin
            ok = self.surface.supports(self.cell_xy[tx, ty], yaw)
            self._node_support[tx, ty, th] = ok.astype(np.int8)
            known = self._node_support[cx, cy, hk]
        return known > 0

    def match(self, xy: FloatArray, z: FloatArray, yaw: FloatArray) -> tuple[IntArray, BoolArray]:
        """Nearest supported graph node to each predicted pose ``(M, 2)``, within the tolerances."""
        k = self.settings.headings
        m = len(xy)
        f = (xy - self.origin) / self.settings.cell
        ix0 = np.floor(f[:, 0]).astype(np.int64)
        iy0 = np.floor(f[:, 1]).astype(np.int64)
        d = np.array([-1, 0, 1])
        cx = (ix0[:, None, None] + d[None, :, None]).repeat(3, axis=2).reshape(m, 9)
        cy = (iy0[:, None, None] + d[None, None, :]).repeat(3, axis=1).reshape(m, 9)
        inside = (cx >= 0) & (cx < self.nx) & (cy >= 0) & (cy < self.ny)
        cx = np.clip(cx, 0, self.nx - 1)
        cy = np.clip(cy, 0, self.ny - 1)
        kf = np.mod(yaw, 2 * np.pi) / self.bin - 0.5
        k0 = np.floor(kf).astype(np.int64)
        hk = np.stack((np.mod(k0, k), np.mod(k0 + 1, k)), axis=1)  # (M, 2)
        cxx = np.repeat(cx, 2, axis=1)
        cyy = np.repeat(cy, 2, axis=1)
        hkk = np.tile(hk, (1, 9))
        ok = np.repeat(inside, 2, axis=1) & self.cell_ok[cxx, cyy]
        pos = self.cell_xy[cxx, cyy]
        head = (hkk + self.heading_offset[cxx, cyy, hkk]) * self.bin
        dp = np.linalg.norm(pos - xy[:, None, :], axis=2)
        dh = np.abs(quat.wrap_angle(head - yaw[:, None]))
        dz = np.abs(self.cell_z[cxx, cyy] - z[:, None])
        # A stride is two half steps, each rising at most a step (checked by successors).
        ok &= (dp <= self.tol_p) & (dh <= self.tol_h) & (dz <= 2.0 * self.settings.max_step_height)
        if np.any(ok):
            ok[ok] = self.node_supported(cxx[ok], cyy[ok], hkk[ok])
        err = np.where(ok, dp / self.tol_p + dh / self.tol_h, np.inf)
        best = np.argmin(err, axis=1)
        rows = np.arange(m)
        node = (cxx[rows, best] * self.ny + cyy[rows, best]) * k + hkk[rows, best]
        return node, np.isfinite(err[rows, best])

    # -- edges --------------------------------------------------------------------------------

    def left_support(self, xy: FloatArray, yaw: FloatArray) -> tuple[BoolArray, FloatArray]:
        """Whether a left footprint predicted at ``xy (M, 2)``/``yaw (M,)`` can be supported
        by shifting it along its heading by at most ``left_search``, and where ``(M, 2)``."""
        found = self.surface.supports(xy, yaw)
        at = xy.copy()
        d = self.left_search
        miss = np.flatnonzero(~found)
        if d > 0.0 and len(miss):
            shifts = np.array([0.5 * d, -0.5 * d, d, -d])
            fwd = np.stack((np.cos(yaw[miss]), np.sin(yaw[miss])), axis=-1)
            cand = xy[miss, None, :] + shifts[None, :, None] * fwd[:, None, :]
            ok = self.surface.supports(cand, yaw[miss, None])
            first = np.argmax(ok, axis=1)
            found[miss] = ok.any(axis=1)
            at[miss] = cand[np.arange(len(miss)), first]
        return found, at

    def _half_step_ok(self, a: FloatArray, za: FloatArray, b: FloatArray, zb: FloatArray) -> BoolArray:
        """Whether the ground between footprints ``a`` and ``b`` (``(M, 2)``, heights ``(M,)``)
        can be walked: no gap, no pit deeper than a step, nothing higher than a step above
        the higher foot."""
        step = self.settings.max_step_height
        s = np.linspace(0.0, 1.0, self.settings.support_samples + 2)[1:-1]
        pts = a[:, None, :] + s[None, :, None] * (b - a)[:, None, :]
        h = self.surface.raster_height(pts)
        lo = np.minimum(za, zb)[:, None] - step
        hi = np.maximum(za, zb)[:, None] + step
        return np.all(np.isfinite(h) & (h >= lo) & (h <= hi), axis=1)

    def _flight_ok(self, a: FloatArray, za: FloatArray, b: FloatArray, zb: FloatArray) -> BoolArray:
        """Whether a jump from ``a`` to ``b`` crosses a gap (or a pit deeper than a step) and
        meets nothing higher than a step above the higher foot on its way."""
        step = self.settings.max_step_height
        s = np.linspace(0.0, 1.0, 2 * self.settings.support_samples + 2)[1:-1]
        pts = a[:, None, :] + s[None, :, None] * (b - a)[:, None, :]
        h = self.surface.raster_height(pts)
        lo = np.minimum(za, zb)[:, None] - step
        hi = np.maximum(za, zb)[:, None] + step
        gap = np.any(~np.isfinite(h) | (h < lo), axis=1)
        clear = np.all(~np.isfinite(h) | (h <= hi), axis=1)
        return gap & clear

    def successors(self, pos: FloatArray, yaw: FloatArray) -> tuple[IntArray, BoolArray]:
        """Edges out of ``B`` right footprints ``pos (B, 3)``, ``yaw (B,)``, one per clip and
        stride scale: the target nodes ``(B, C)`` and whether each edge exists ``(B, C)``.

        A clip's short strides are offered only from footprints where steps block its natural
        stride (a predicted footprint straddles a step's edge, or a half step rises too
        much), and to every footprint near the goal (within one and a half natural strides,
        where people shorten their steps to stop in the right place): elsewhere on open
        ground, and at the edges of platforms and gaps, the search sees the clips as they
        are."""
        e = self.edges
        b = len(yaw)
        c = len(e.clip)
        nodes = np.zeros((b, c), dtype=np.int64)
        ok = np.zeros((b, c), dtype=bool)
        natural = np.flatnonzero(e.scale == 1.0)
        rows = np.repeat(np.arange(b), len(natural))
        cols = np.tile(natural, b)
        blocked = np.zeros((b, c), dtype=bool)
        nodes[rows, cols], ok[rows, cols], blocked[rows, cols] = self._edges(pos, yaw, rows, cols)
        short = np.flatnonzero(e.scale != 1.0)
        if len(short):
            rows = np.repeat(np.arange(b), len(short))
            cols = np.tile(short, b)
            need = blocked[rows, e.natural[cols]]
            if self.goal_xy is not None:
                need |= np.linalg.norm(pos[rows, :2] - self.goal_xy, axis=1) <= self.near_goal
            rows, cols = rows[need], cols[need]
            if len(rows):
                nodes[rows, cols], ok[rows, cols], _ = self._edges(pos, yaw, rows, cols)
        return nodes, ok

    def _edges(
        self, pos: FloatArray, yaw: FloatArray, rows: IntArray, cols: IntArray
    ) -> tuple[IntArray, BoolArray, BoolArray]:
        """Target node and existence of the edges ``cols (M,)`` out of footprints ``rows
        (M,)``, and whether steps in the ground (not the lattice) stop each one."""
        e = self.edges
        surf = self.surface
        step = self.settings.max_step_height
        y0 = yaw[rows]
        start_xy = pos[rows, :2]
        z0 = pos[rows, 2]
        end_xy = start_xy + quat.rot2(y0, e.end_pos[cols, :2])
        end_yaw = y0 + e.end_yaw[cols]
        nodes, ok = self.match(end_xy, z0 + e.end_pos[cols, 2], end_yaw)
        blocked = np.zeros(len(rows), dtype=bool)
        miss = np.flatnonzero(~ok)
        if len(miss):
            blocked[miss] = surf.straddles_step(end_xy[miss], end_yaw[miss])
        idx = np.flatnonzero(ok)
        if len(idx) == 0:
            return nodes, ok, blocked
        # Only the edges that found a node: the left footprint, the half steps, the flight.
        cell = nodes[idx] // self.settings.headings
        ix, iy = cell // self.ny, cell % self.ny
        node_xy = self.cell_xy[ix, iy]
        node_z = self.cell_z[ix, iy]
        col = cols[idx]
        y0, start_xy, z0 = y0[idx], start_xy[idx], z0[idx]
        left_xy = start_xy + quat.rot2(y0, e.left_pos[col, :2])
        left_yaw = y0 + e.left_yaw[col]
        has_left, left_at = self.left_support(left_xy, left_yaw)
        left_z = surf.raster_height(left_at)
        rise = (np.abs(left_z - z0) <= step) & (np.abs(node_z - left_z) <= step)
        good = has_left & rise & self._half_step_ok(start_xy, z0, left_at, left_z)
        stepped = ~rise | (~has_left & surf.straddles_step(left_xy, left_yaw))
        left_xy = left_at
        jump = e.jump[col]
        if np.any(~jump):
            w = np.flatnonzero(~jump)
            good[w] &= self._half_step_ok(left_xy[w], left_z[w], node_xy[w], node_z[w])
        if np.any(jump):
            j = np.flatnonzero(jump)
            good[j] &= self._flight_ok(left_xy[j], left_z[j], node_xy[j], node_z[j])
        ok[idx] = good
        blocked[idx] = ~good & stepped
        return nodes, ok, blocked

    # -- heuristic ----------------------------------------------------------------------------

    def distance_field(self, goal_xy: FloatArray) -> tuple[FloatArray, FloatArray, float]:
        """Walking distance to the goal on a coarse grid: ``(field, origin, cell)``."""
        s = self.settings
        surf = self.surface
        cell = s.field_cell
        size = np.array(surf.z.shape) * surf.cell
        nx, ny = np.ceil(size / cell).astype(int).tolist()
        gx, gy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
        centres = surf.origin + (np.stack((gx, gy), axis=-1) + 0.5) * cell
        walkable = surf.supported(centres)
        cost = np.where(walkable, 1.0, np.inf)
        if np.any(self.edges.jump):
            # Gaps narrower than the longest jump are crossable, at the jump's price.
            reach = float(
                np.max(
                    np.linalg.norm(
                        self.edges.end_pos[self.edges.jump, :2] - self.edges.left_pos[self.edges.jump, :2],
                        axis=1,
                    )
                )
            )
            r = int(np.ceil(0.5 * reach / cell))
            near = walkable.copy()
            for _ in range(r):
                grown = near.copy()
                grown[1:] |= near[:-1]
                grown[:-1] |= near[1:]
                grown[:, 1:] |= near[:, :-1]
                grown[:, :-1] |= near[:, 1:]
                near = grown
            cost = np.where(~walkable & near, s.role_cost.get("jump", 1.0), cost)
        dist = np.full((nx, ny), np.inf)
        g = np.floor((goal_xy - surf.origin) / cell).astype(int)
        g = np.clip(g, 0, [nx - 1, ny - 1])
        dist[g[0], g[1]] = 0.0
        steps = [
            (1, 0, 1.0),
            (-1, 0, 1.0),
            (0, 1, 1.0),
            (0, -1, 1.0),
            (1, 1, np.sqrt(2)),
            (1, -1, np.sqrt(2)),
            (-1, 1, np.sqrt(2)),
            (-1, -1, np.sqrt(2)),
        ]
        for _ in range(4 * (nx + ny) + 10):
            new = dist.copy()
            for dx, dy, length in steps:
                src = dist[max(0, -dx) : nx - max(0, dx), max(0, -dy) : ny - max(0, dy)]
                dst = (slice(max(0, dx), nx - max(0, -dx)), slice(max(0, dy), ny - max(0, -dy)))
                new[dst] = np.minimum(new[dst], src + length * cell * cost[dst])
            if np.array_equal(new, dist):
                break
            dist = new
        return dist, surf.origin, cell

    # -- search -------------------------------------------------------------------------------

    def search(
        self,
        start_pos: FloatArray,
        start_yaw: float,
        goal_xy: FloatArray,
        goal_yaw: float | None,
        stop: ClipInfo,
        progress: Callable[[float], bool] | None = None,
    ) -> GraphPath:
        """A* from the right footprint ``start_pos/yaw`` to a node from which ``stop`` ends
        within ``goal_radius`` of ``goal_xy`` (and of ``goal_yaw``, when given).

        Nodes are expanded in small batches (the ``batch`` best of the open list at once),
        which lets numpy evaluate all their edges together; within a batch the order is
        that of A*.
        """
        s = self.settings
        field_, f_origin, f_cell = self.distance_field(goal_xy)
        self.goal_xy = np.asarray(goal_xy, dtype=float)[:2]
        fnx, fny = field_.shape

        def h(xy: FloatArray) -> FloatArray:
            i = np.clip(np.floor((xy - f_origin) / f_cell).astype(int), 0, [fnx - 1, fny - 1])
            return field_[i[..., 0], i[..., 1]]

        h_start = float(h(start_pos[:2]))
        if not np.isfinite(h_start):
            raise GoalUnreachableError(
                "the goal cannot be reached: no walkable route and no gap narrow enough to jump"
            )
        stop_end, stop_end_yaw = relative_to_right(stop, stop.cycle_pos, stop.cycle_yaw)
        stop_left, stop_left_yaw = relative_to_right(stop, stop.left_step.pos, stop.left_step.yaw)
        w = s.heuristic_weight
        counter = itertools.count()
        start_id = -1
        poses: dict[int, tuple[FloatArray, float]] = {
            start_id: (np.asarray(start_pos, dtype=float), float(start_yaw))
        }
        g_score: dict[int, float] = {start_id: 0.0}
        parent: dict[int, tuple[int, int]] = {}
        closed: set[int] = set()
        heap = [(w * h_start, next(counter), start_id)]
        expansions = 0
        edge_cost = self.edges.cost.tolist()
        while heap:
            batch: list[int] = []
            while heap and len(batch) < s.batch:
                _, _, node = heapq.heappop(heap)
                if node not in closed:
                    closed.add(node)
                    batch.append(node)
            if not batch:
                break
            pos = np.empty((len(batch), 3))
            yaw = np.empty(len(batch))
            for i, node in enumerate(batch):
                pos[i], yaw[i] = poses[node] if node in poses else self.node_pose(node)
            # Goal test: where the STOP clip would leave the body.
            end_xy = pos[:, :2] + quat.rot2(yaw, stop_end[None, :2])
            at_goal = np.linalg.norm(end_xy - goal_xy, axis=1) <= s.goal_radius
            if goal_yaw is not None:
                at_goal &= np.abs(quat.wrap_angle(yaw + stop_end_yaw - goal_yaw)) <= s.goal_heading_tolerance
            if np.any(at_goal):
                left_xy = pos[:, :2] + quat.rot2(yaw, stop_left[None, :2])
                at_goal &= self.surface.supports(left_xy, yaw + stop_left_yaw)
                hits = np.flatnonzero(at_goal)
                if len(hits):
                    best = int(hits[np.argmin([g_score[batch[i]] for i in hits])])
                    return self._path(batch[best], parent, poses, expansions)
            expansions += len(batch)
            if expansions > s.max_expansions:
                break
            if progress is not None and not progress(min(0.99, expansions / s.max_expansions)):
                raise PlanCancelled()
            nodes, ok = self.successors(pos, yaw)
            rows, cols = np.nonzero(ok)
            if len(rows) == 0:
                continue
            targets = nodes[rows, cols]
            npos = self.cell_xy.reshape(-1, 2)[targets // s.headings]
            h_new = (w * h(npos)).tolist()
            for r, c, nd, hn in zip(rows.tolist(), cols.tolist(), targets.tolist(), h_new, strict=True):
                if nd in closed:
                    continue
                g = g_score[batch[r]] + edge_cost[c]
                if g < g_score.get(nd, np.inf):
                    g_score[nd] = g
                    parent[nd] = (batch[r], c)
                    heapq.heappush(heap, (g + hn, next(counter), nd))
        raise GoalUnreachableError(
            f"no footprint path to the goal was found ({expansions} footprints explored)"
        )

    def _path(
        self,
        node: int,
        parent: dict[int, tuple[int, int]],
        poses: dict[int, tuple[FloatArray, float]],
        expansions: int,
    ) -> GraphPath:
        chain = [node]
        edges = []
        while chain[-1] in parent:
            prev, c = parent[chain[-1]]
            chain.append(prev)
            edges.append(c)
        chain.reverse()
        edges.reverse()
        cols = np.array(edges, dtype=np.int64)
        pos = []
        yaw = []
        for nd in chain:
            p, y = poses[nd] if nd in poses else self.node_pose(nd)
            pos.append(p)
            yaw.append(y)
        return GraphPath(
            np.array(pos),
            np.unwrap(np.array(yaw)),
            self.edges.clip[cols].astype(np.int64),
            expansions,
            self.edges.scale[cols].astype(float),
        )
