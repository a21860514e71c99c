# SPDX-License-Identifier: GPL-3.0-or-later
"""The footprint graph and A* search (biped thesis §3.2, after Choi, Lee and Shin 2003).

Nodes are right-foot footprints sampled over the walkable surface: one position per cell
of a ``cell``-sized lattice (jittered inside the cell by the seeded generator, kept where a
foot fits) times ``headings`` jittered headings. An edge leaves node ``a`` for every
walk, run or jump clip: the clip, started on ``a``, puts the right foot down again at a
predicted pose, and the edge goes to the node that matches that pose within the position
and heading tolerances. The edge exists only if the left footprint the clip makes in
between fits on the surface, the heights match, and — except for jumps — the ground under
the whole step is walkable, so walking never crosses a gap: only a jump edge can.

Edges are generated lazily while A* expands nodes, so only the part of the graph the
search visits is ever built. Edge cost is the clip's root path length times a per-role
weight (running and jumping cost more than walking, so a jump is chosen only where no
walkable route exists) plus a small cost per radian turned. The heuristic is the walking
distance to the goal on a coarse grid of the surface (gaps narrower than a jump are
crossable at the jump weight), computed once per search by vectorised relaxation; it
gives up at once when the goal cannot be reached at all.

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
    faster) at the price of slightly longer paths.
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


@dataclass(frozen=True)
class GraphPath:
    """A* result: ``right_pos (n, 3)``/``right_yaw (n,)`` the right footprints from the one
    after the START clip to the last before the STOP clip, ``clips (n - 1,)`` the clip of
    each edge between them, ``expansions`` the number of nodes expanded."""

    right_pos: FloatArray
    right_yaw: FloatArray
    clips: IntArray
    expansions: int


@dataclass(frozen=True)
class _EdgeTable:
    """Per locomotion clip, relative to its starting right footprint."""

    clip: IntArray
    end_pos: FloatArray  # (C, 3) next right footprint
    end_yaw: FloatArray
    left_pos: FloatArray  # (C, 3) the left footprint in between
    cost: FloatArray
    jump: BoolArray
    support: FloatArray  # (C, P, 3) ground points under the step (NaN for jumps)


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


def _edge_table(db: ClipDatabase, infos: list[ClipInfo], settings: GraphSettings) -> _EdgeTable:
    n = len(infos)
    end_pos = np.zeros((n, 3))
    end_yaw = np.zeros(n)
    left_pos = np.zeros((n, 3))
    cost = np.zeros(n)
    jump = np.zeros(n, dtype=bool)
    p = settings.support_samples
    support = np.full((n, 2 * p, 3), np.nan)
    for i, info in enumerate(infos):
        end_pos[i], end_yaw[i] = relative_to_right(info, info.end_right_pos, info.end_right_yaw)
        ls = info.left_step
        left_pos[i], _ = relative_to_right(info, ls.pos, ls.yaw)
        weight = settings.role_cost.get(info.role.family, 1.0)
        cost[i] = info.path_length * weight + settings.turn_cost * abs(info.cycle_yaw)
        jump[i] = info.role.family == "jump"
        if not jump[i]:
            s = np.linspace(0.0, 1.0, p)[:, None]
            support[i, :p] = s * left_pos[i]
            support[i, p:] = left_pos[i] + s * (end_pos[i] - left_pos[i])
    return _EdgeTable(
        np.array([info.index for info in infos], dtype=np.int64),
        end_pos,
        end_yaw,
        left_pos,
        cost,
        jump,
        support,
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

    # -- nodes --------------------------------------------------------------------------------

    def node_pose(self, node: int) -> tuple[FloatArray, float]:
        k = self.settings.headings
        c, h = divmod(node, k)
        ix, iy = divmod(c, self.ny)
        xy = self.cell_xy[ix, iy]
        return np.array([xy[0], xy[1], self.cell_z[ix, iy]]), float(
            (h + self.heading_offset[ix, iy, h]) * self.bin
        )

    def match(self, xy: FloatArray, z: FloatArray, yaw: FloatArray) -> tuple[IntArray, BoolArray]:
        """Nearest graph node to each predicted pose ``(M, 2)``, within the tolerances."""
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
        ok &= (dp <= self.tol_p) & (dh <= self.tol_h) & (dz <= self.settings.max_step_height)
        err = np.where(ok, dp / self.tol_p + dh / self.tol_h, np.inf)
        best = np.argmin(err, axis=1)
        rows = np.arange(m)
        node = (cxx[rows, best] * self.ny + cyy[rows, best]) * k + hkk[rows, best]
        return node, np.isfinite(err[rows, best])

    # -- edges --------------------------------------------------------------------------------

    def successors(self, pos: FloatArray, yaw: FloatArray) -> tuple[IntArray, BoolArray]:
        """Edges out of ``B`` right footprints ``pos (B, 3)``, ``yaw (B,)``, one per clip:
        the target nodes ``(B, C)`` and whether each edge exists ``(B, C)``."""
        e = self.edges
        surf = self.surface
        b = len(yaw)
        c = len(e.clip)
        yaw_b = yaw[:, None]
        end_xy = pos[:, None, :2] + quat.rot2(yaw_b, e.end_pos[None, :, :2])
        end_z = pos[:, None, 2] + e.end_pos[None, :, 2]
        nodes, ok = self.match(end_xy.reshape(-1, 2), end_z.reshape(-1), (yaw_b + e.end_yaw).reshape(-1))
        nodes, ok = nodes.reshape(b, c), ok.reshape(b, c)
        left_xy = pos[:, None, :2] + quat.rot2(yaw_b, e.left_pos[None, :, :2])
        left_z = surf.raster_height(left_xy)
        ok &= surf.fits(left_xy) & (
            np.abs(left_z - (pos[:, None, 2] + e.left_pos[:, 2])) <= self.settings.max_step_height
        )
        walk = ~e.jump
        if np.any(walk):
            sup = e.support[walk]  # (W, P, 3)
            sxy = pos[:, None, None, :2] + quat.rot2(yaw[:, None, None], sup[None, ..., :2])
            sz = surf.raster_height(sxy)
            expect = pos[:, None, None, 2] + sup[None, ..., 2]
            good = np.all(np.isfinite(sz) & (np.abs(sz - expect) <= self.settings.max_step_height), axis=2)
            ok[:, walk] &= good
        return nodes, ok

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
        stop_left, _ = relative_to_right(stop, stop.left_step.pos, stop.left_step.yaw)
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
        edge_clip = self.edges.clip.tolist()
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
                at_goal &= self.surface.fits(left_xy)
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
                    parent[nd] = (batch[r], edge_clip[c])
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
        clips = []
        while chain[-1] in parent:
            prev, c = parent[chain[-1]]
            chain.append(prev)
            clips.append(c)
        chain.reverse()
        clips.reverse()
        pos = []
        yaw = []
        for nd in chain:
            p, y = poses[nd] if nd in poses else self.node_pose(nd)
            pos.append(p)
            yaw.append(y)
        return GraphPath(np.array(pos), np.unwrap(np.array(yaw)), np.array(clips, dtype=np.int64), expansions)
