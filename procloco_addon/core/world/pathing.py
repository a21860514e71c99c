# SPDX-License-Identifier: GPL-3.0-or-later
"""3D foot trajectories through the window grids (thesis §3.4.2, Appendix F).

From a foot's position to a footprint target:

1. **Search rectangle** (:func:`search_region`): an oriented rectangle containing the start
   and the preferred footprint, as wide as the leg reach allows; nothing outside it is
   searched.
2. **Wavefront** (:func:`wavefront`): a distance field over the free cells of the rectangle,
   grown from one source cell by whole-array relaxation (numpy, no per-cell Python loop).
   Moves are the 8 neighbours with lengths 1 and √2 (an "octile" wavefront: the naive cells
   hug the straight line better than a hop-count BFS), and diagonal moves never cut the
   corner of a forbidden cell. The field is grown from the *foot*, so a single field gives
   the distance to every candidate footprint at once; the thesis grows one from each target.
3. **Descent** (:func:`descend`): from a cell, follow the steepest decrease of the field to
   the source — the naive cells.
4. **Line of sight** (:func:`segments_clear`, :func:`line_of_sight_reduce`): an all-cells
   (supercover) Bresenham test, vectorised over many segments, keeps only the naive cells
   that cannot be skipped — the final cells (waypoints).
5. **2D curve**: a cardinal (Hermite) spline through the final cells, sampled by arc length
   and checked against the obstacle map; if it cuts a forbidden cell the tension is lowered
   (down to 0, the straight segments that the line-of-sight test already proved free).
6. **Elevation** (:meth:`PathContext.lift`): every sample gets the elevation under the foot
   plus a clearance that ramps from 0 at lift-off and touch-down to the step height; the upper
   convex hull of these points gives the 3D waypoints; close waypoints are dropped when that
   keeps the curve clear; a Hermite height profile through the waypoints (never below the
   hull, see :func:`height_profile`) lifts the 2D curve into the final 3D trajectory. The
   thesis passes a 3D Hermite curve through the 3D waypoints; lifting the already checked 2D
   curve instead keeps the ground-plane path exactly where the obstacle map was checked, and
   the height profile provably above the clearance, so no sample can end up in a forbidden
   cell or under the elevation map.

When the target is in plain sight of the foot (supercover test of the straight segment) steps
2–4 are skipped: they would keep exactly the two end points (``PathParams.los_shortcut``).

The result is a :class:`FootTrajectory`: a dense 3D polyline of the curve with its length,
sampled at constant speed by fractions of its arc length. :func:`trajectory_valid` tells the
controller whether a running swing is still clear after obstacles moved (thesis §3.2.1).

For planning many feet at once (:func:`~.footprints.plan_footsteps`) the steps also come
batched, each making the same decisions as the one-at-a-time function (cells, masks, counts)
with the same element-wise arithmetic, so its floats equal the single function's to a few ulps
(numpy may group a reduction differently for arrays of another length): :func:`region_masks`
(search rectangles), :func:`wavefront_each` (distance fields of many grids, sweep for sweep),
:func:`segments_clear_each` (line of sight, each segment on its own grid),
:func:`turning_each` and :func:`lift_each` (3D trajectories of many 2D plans).

Grid coordinates: ``(row, col)`` in a window, cell ``(r, c)`` centred at continuous
coordinates ``(r, c)``; world xy ↔ grid through :class:`~.terrain.WindowGrids`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..geometry import clip, linspace_to, planar_length, vector_norm
from ..hermite import HERMITE_MATRIX, cardinal_samples, hermite_basis
from .terrain import NO_SURFACE, WindowGrids, dilate, foot_kernel

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]

SQRT2 = math.sqrt(2.0)
#: The 8 moves (d_row, d_col) of the wavefront, with their lengths in cells.
MOVES: tuple[tuple[int, int], ...] = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
MOVE_LENGTH: tuple[float, ...] = tuple(SQRT2 if dr and dc else 1.0 for dr, dc in MOVES)


# ---------------------------------------------------------------------------------------
# Trajectory
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FootTrajectory:
    """A foot's 3D swing trajectory.

    ``points``: ``(m, 3)`` dense polyline of the curve (world metres), from the foot's start
    to the footprint; ``length``: its 3D arc length in metres; ``waypoints``: ``(k, 3)`` the 3D
    waypoints (upper-hull vertices) the height profile passes through; ``waypoints_2d``:
    ``(w, 2)`` the final cells of the 2D plan; ``length_2d``: length of the 2D curve;
    ``arc``: ``(m,)`` 3D arc length at each point; ``arc_2d``: ``(m,)`` arc length of the 2D
    curve under each point (what the clearance profile is a function of).
    """

    points: FloatArray
    length: float
    waypoints: FloatArray
    waypoints_2d: FloatArray
    length_2d: float
    arc: FloatArray = field(repr=False)
    arc_2d: FloatArray = field(repr=False)

    @classmethod
    def from_points(
        cls, points: FloatArray, waypoints: FloatArray | None = None,
        waypoints_2d: FloatArray | None = None, length_2d: float | None = None,
        arc_2d: FloatArray | None = None,
    ) -> FootTrajectory:
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        if arc_2d is None:
            seg2 = np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1)
            arc_2d = np.concatenate([[0.0], np.cumsum(seg2)])
        if length_2d is None:
            length_2d = float(arc_2d[-1])
        return cls(
            points=pts,
            length=float(arc[-1]),
            waypoints=pts[[0, -1]] if waypoints is None else waypoints,
            waypoints_2d=pts[[0, -1], :2] if waypoints_2d is None else waypoints_2d,
            length_2d=length_2d,
            arc=arc,
            arc_2d=np.asarray(arc_2d, dtype=np.float64),
        )

    def point_at(self, u: npt.ArrayLike) -> FloatArray:
        """Points at fractions ``u`` ``(n,)`` of the arc length in [0, 1]: ``(n, 3)``.

        Equal steps of ``u`` are equal distances along the curve (constant speed).
        """
        uu = np.asarray(u, dtype=np.float64)
        return points_at_each([self], uu.reshape(-1))[0].reshape((*uu.shape, 3))

    def tangent_at(self, u: npt.ArrayLike) -> FloatArray:
        """Unit direction of travel at fractions ``u`` ``(n,)``: ``(n, 3)``."""
        uu = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
        if self.points.shape[0] < 2 or self.length <= 0.0:
            return np.zeros((*uu.shape, 3))
        last = self.points.shape[0] - 2
        seg = clip(self.arc.searchsorted(uu * self.length, side="right") - 1, 0, last)
        d = self.points[seg + 1] - self.points[seg]
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        return np.asarray(np.where(n > 1e-12, d / np.where(n > 1e-12, n, 1.0), 0.0))

    @property
    def start(self) -> FloatArray:
        return self.points[0]

    @property
    def end(self) -> FloatArray:
        return self.points[-1]


def points_at_each(trajectories: Sequence[FootTrajectory], u: FloatArray) -> FloatArray:
    """:meth:`FootTrajectory.point_at` of many trajectories at the same fractions ``u``
    ``(n,)``: ``(T, n, 3)``. The arithmetic of ``np.interp`` on each one's arc lengths and
    points (the knot at or before each sample; a sample on a knot or past either end gets
    that knot's point, the others the segment's slope times the way into it plus its first
    point), for all of them at once."""
    t = len(trajectories)
    if t == 0:
        return np.zeros((0, np.shape(u)[0], 3))
    uu = np.minimum(np.maximum(u, 0.0), 1.0)  # (np.clip without its dispatch)
    size_list = [tr.points.shape[0] for tr in trajectories]
    size = np.array(size_list)
    k = max(size_list)
    # every trajectory in a row of its own (past its end the arc is never at or before a
    # sample; its points there are never read), the points coordinate by coordinate
    at = (np.arange(t) * k - (size.cumsum() - size)).repeat(size) + np.arange(sum(size_list))
    arc = np.full(t * k, np.inf)
    arc[at] = np.concatenate([tr.arc for tr in trajectories])
    pts = np.empty((3, t * k))
    pts[:, at] = np.concatenate([tr.points for tr in trajectories]).T
    length = np.array([tr.length for tr in trajectories])
    s = uu[None, :] * length[:, None]  # (t, n)
    last = size[:, None] - 1
    j = np.minimum(np.add.reduce(arc.reshape(t, k)[:, None, :] <= s[:, :, None], axis=2) - 1, last)
    base = np.arange(t)[:, None] * k
    j0 = np.maximum(j, 0) + base
    j1 = np.minimum(j + 1, last) + base
    a0 = arc[j0]
    p0 = pts[:, j0]  # (3, t, n)
    p1 = pts[:, j1]
    inner = (j >= 0) & (j < last) & (a0 != s)  # (there the segment has a length)
    slope = (p1 - p0) / np.where(inner, arc[j1] - a0, 1.0)
    out = slope * (s - a0) + p0
    again = np.isnan(out) & inner
    if np.logical_or.reduce(again, axis=None):  # (np.interp: a NaN one way is tried the other way)
        out = np.where(again, slope * (s - arc[j1]) + p1, out)
        out = np.where(again & np.isnan(out) & (p0 == p1), p0, out)
    out = np.where(inner, out, p0)
    still = length <= 0.0  # no length: the first point everywhere
    if np.logical_or.reduce(still):
        out[:, still] = pts[:, base[still, 0], None]
    return np.ascontiguousarray(out.transpose(1, 2, 0))


# ---------------------------------------------------------------------------------------
# Search rectangle
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Region:
    """A sub-rectangle of a window: rows ``r0 .. r0 + h``, cols ``c0 .. c0 + w``; ``mask``
    ``(h, w)`` marks the cells inside the (oriented) search rectangle."""

    r0: int
    c0: int
    mask: BoolArray

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.mask.shape[0]), int(self.mask.shape[1]))

    def view(self, grid: npt.NDArray[np.generic]) -> npt.NDArray[np.generic]:
        h, w = self.shape
        return grid[self.r0 : self.r0 + h, self.c0 : self.c0 + w]


def search_region(
    window_shape: tuple[int, int], start_rc: npt.ArrayLike, end_rc: npt.ArrayLike,
    half_width: float, end_margin: float, start_margin: float = 2.0,
) -> Region:
    """The oriented search rectangle (thesis §3.4.2) in window cells.

    Its axis runs from ``start_rc`` to ``end_rc`` (continuous cell coordinates), extended by
    ``start_margin`` behind the start and ``end_margin`` beyond the end; ``half_width`` is
    its half width. All in cells. Clipped to the window.
    """
    a0, a1 = (float(v) for v in np.asarray(start_rc, dtype=np.float64).reshape(2))
    b0, b1 = (float(v) for v in np.asarray(end_rc, dtype=np.float64).reshape(2))
    frame = region_frame(window_shape, a0, a1, b0, b1, half_width, end_margin, start_margin)
    if frame is None:
        return Region(0, 0, np.zeros((0, 0), dtype=bool))
    r0, c0, h, w = frame[:4]
    mask = region_masks(np.array([frame]), h, w)[0]
    return Region(r0, c0, mask)


#: One search rectangle as plain numbers: ``(r0, c0, h, w, a0, a1, u0, u1, lo, hi, half)``
#: (bounding box; axis origin and unit direction; along-axis bounds; half width with margins).
RegionFrame = tuple[int, int, int, int, float, float, float, float, float, float, float]


def region_frame(
    window_shape: tuple[int, int], a0: float, a1: float, b0: float, b1: float,
    half_width: float, end_margin: float, start_margin: float,
) -> RegionFrame | None:
    """The numbers behind :func:`search_region` (plain Python floats), None if the rectangle
    misses the window."""
    dist = math.hypot(b0 - a0, b1 - a1)
    u0, u1 = ((b0 - a0) / dist, (b1 - a1) / dist) if dist > 1e-9 else (0.0, 1.0)
    p0, p1 = -u1, u0
    rows = []
    cols = []
    for t in (-start_margin, dist + end_margin):
        for q in (-half_width, half_width):
            rows.append(a0 + u0 * t + p0 * q)
            cols.append(a1 + u1 * t + p1 * q)
    ny, nx = window_shape
    r0 = max(math.floor(min(rows)), 0)
    r1 = min(math.ceil(max(rows)), ny - 1)
    c0 = max(math.floor(min(cols)), 0)
    c1 = min(math.ceil(max(cols)), nx - 1)
    if r1 < r0 or c1 < c0:
        return None
    eps = 1e-9
    return (r0, c0, r1 - r0 + 1, c1 - c0 + 1, a0, a1, u0, u1, -start_margin - eps, dist + end_margin + eps,
            half_width + eps)


def region_masks(frames: FloatArray, height: int, width: int) -> BoolArray:
    """Masks ``(n, height, width)`` of ``n`` search rectangles (rows of :data:`RegionFrame`),
    each in its bounding box at the top-left corner; cells past a box's own size are False."""
    f = frames
    r0, c0, h, w = (f[:, k].astype(np.intp) for k in range(4))
    a0, a1, u0, u1, lo, hi, half = (f[:, k, None, None] for k in range(4, 11))
    rows = np.arange(height)
    cols = np.arange(width)
    dr = (rows[None, :, None] + r0[:, None, None]) - a0
    dc = (cols[None, None, :] + c0[:, None, None]) - a1
    along = dr * u0 + dc * u1
    across = np.abs(dr * -u1 + dc * u0)
    mask = (along >= lo) & (along <= hi) & (across <= half)
    if f.shape[0] > 1 or h[0] != height or w[0] != width:
        mask &= (rows[None, :, None] < h[:, None, None]) & (cols[None, None, :] < w[:, None, None])
    return np.asarray(mask)


# ---------------------------------------------------------------------------------------
# Wavefront
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DistanceField:
    """Wavefront result over a region: ``dist`` ``(h, w)`` in cells (``inf`` where
    unreachable), ``parent`` ``(h, w)`` index into :data:`MOVES` of the move that reached each
    cell (-1 at the source and where unreachable), ``source`` the source cell, ``iterations``
    the number of whole-array relaxation sweeps."""

    dist: FloatArray
    parent: npt.NDArray[np.int8]
    source: tuple[int, int]
    iterations: int

    def reachable(self, rc: IntArray) -> BoolArray:
        return np.asarray(np.isfinite(self.dist[rc[..., 0], rc[..., 1]]))


def wavefront_each(
    free: BoolArray, sources: list[tuple[int, int]], shapes: list[tuple[int, int]],
    max_iterations: int | None = None,
) -> list[DistanceField]:
    """Octile distance fields of many grids at once: grid ``i`` is ``free[i, :h, :w]``
    (``free`` ``(m, H, W)``, False past each grid's own ``shapes[i] = (h, w)``) with source
    ``sources[i]`` (always treated as free).

    Whole-array relaxation (every move, every cell, per sweep) until nothing changes; each
    sweep costs a few numpy operations on the stack, and the number of sweeps is about the
    longest path's length in cells. The sweeps of each grid are exactly its own (grids never
    interact): its sweep count is the sweep after which it stopped changing.

    The grids are laid out flat, each with a border of blocked cells, one after the other:
    a move is then a shift of the one flat array by a constant (a contiguous slice, where a
    2D shift is a strided one), and the border cells, whose every move costs ``inf``, keep
    one grid from reaching into the next. The moves are relaxed in the same order with the
    same sums as on the 2D grids, so every distance, parent and sweep count is the same."""
    m, hh, ww = free.shape
    src = np.asarray(sources, dtype=np.intp).reshape(m, 2)
    at = np.arange(m)
    w2 = ww + 2
    plane = (hh + 2) * w2
    pad = np.zeros((m, hh + 2, w2), dtype=bool)
    pad[:, 1:-1, 1:-1] = free
    pad[at, src[:, 0] + 1, src[:, 1] + 1] = True
    flat_free = pad.reshape(-1)
    lo = w2 + 1  # the first inner cell of the first grid
    hi = m * plane - w2 - 1  # one past the last inner cell of the last grid
    n = hi - lo
    here = flat_free[lo:hi]
    offsets = [dr * w2 + dc for dr, dc in MOVES]  # a move's source is the cell `offset` before
    costs = []
    for (dr, dc), length in zip(MOVES, MOVE_LENGTH, strict=True):
        ok = here
        if dr and dc:  # no corner cutting: both side cells must be free
            ok = ok & flat_free[lo - dr * w2 : hi - dr * w2] & flat_free[lo - dc : hi - dc]
        costs.append(np.where(ok, length, np.inf))
    dist = np.full(m * plane, np.inf)
    dist[at * plane + (src[:, 0] + 1) * w2 + (src[:, 1] + 1)] = 0.0
    inner = dist[lo:hi]
    shifted = [dist[lo - off : hi - off] for off in offsets]
    limit = max_iterations if max_iterations is not None else max(h * w for h, w in shapes) + 1
    iterations = np.zeros(m, dtype=np.intp)
    starts = at * plane  # grid i's cells are inner[starts[i] - lo + ...]: the reduceat cuts
    starts[0] = lo
    cuts = starts - lo
    sweeps = 0
    cand = np.empty(n)
    before = np.empty(n)
    changed = np.empty(n, dtype=bool)
    # the last sweep that changed each cell (0: none). A sweep that changes nothing in a grid
    # leaves it as it is for good (its next sweeps compute the same), so a grid stops at the
    # sweep after its last change, and every grid stops in the first sweep that changes
    # nothing anywhere (its per-grid bookkeeping once, after the sweeps)
    last = np.zeros(n, dtype=np.intp) if m > 1 else None
    any_of = np.logical_or.reduce
    while sweeps < limit:
        np.copyto(before, inner)
        for view, cost in zip(shifted, costs, strict=True):
            np.add(view, cost, out=cand)
            np.minimum(inner, cand, out=inner)
        sweeps += 1
        np.not_equal(before, inner, out=changed)
        if not any_of(changed):
            break
        if last is not None:
            np.copyto(last, sweeps, where=changed)
    if last is None:
        iterations[0] = sweeps
    else:
        # a grid still changing when the sweeps ran out: every sweep (its last change + 1 would
        # be one more)
        iterations[:] = np.minimum(np.maximum.reduceat(last, cuts) + 1, sweeps)
    # Parent move of every reached cell: the move that realises its distance.
    stacked = np.empty((len(costs), n))
    for row, view, cost in zip(stacked, shifted, costs, strict=True):
        np.add(view, cost, out=row)
    flat_parent = np.full(m * plane, -1, dtype=np.int8)
    flat_parent[lo:hi] = np.where(np.isfinite(inner), stacked.argmin(axis=0), -1)
    parent = flat_parent.reshape(m, hh + 2, w2)[:, 1:-1, 1:-1]
    parent[at, src[:, 0], src[:, 1]] = -1
    grid = dist.reshape(m, hh + 2, w2)[:, 1:-1, 1:-1]
    out = []
    for i, (h, w) in enumerate(shapes):
        source = (int(src[i, 0]), int(src[i, 1]))
        out.append(DistanceField(grid[i, :h, :w].copy(), parent[i, :h, :w], source, int(iterations[i])))
    return out


def wavefront(free: BoolArray, source: tuple[int, int], max_iterations: int | None = None) -> DistanceField:
    """Octile distance field from ``source`` over the ``free`` cells ``(h, w)`` (always free
    itself): :func:`wavefront_each` of one grid."""
    return wavefront_each(free[None], [source], [(free.shape[0], free.shape[1])], max_iterations)[0]


def octile_field(shape: tuple[int, int], source: tuple[int, int]) -> DistanceField:
    """The wavefront of an obstacle-free region in closed form (same result, no sweeps)."""
    h, w = shape
    rr, cc = np.meshgrid(np.arange(h) - source[0], np.arange(w) - source[1], indexing="ij")
    ar, ac = np.abs(rr), np.abs(cc)
    dist = np.maximum(ar, ac) + (SQRT2 - 1.0) * np.minimum(ar, ac)
    # Arrive diagonally while both offsets are non-zero, then straight.
    sr, sc = np.sign(rr), np.sign(cc)
    move_index = {m: k for k, m in enumerate(MOVES)}
    parent = np.full(shape, -1, dtype=np.int8)
    for (dr, dc), k in move_index.items():
        parent[(sr == dr) & (sc == dc)] = k
    parent[source] = -1
    return DistanceField(dist.astype(np.float64), parent, (int(source[0]), int(source[1])), 0)


def descend(field_: DistanceField, cell: tuple[int, int]) -> IntArray:
    """Naive cells from ``cell`` down the field to its source: ``(k, 2)`` (row, col).

    Empty if ``cell`` is unreachable.
    """
    parent = field_.parent
    if not np.isfinite(field_.dist[cell]):
        return np.zeros((0, 2), dtype=np.intp)
    r, c = int(cell[0]), int(cell[1])
    out = [(r, c)]
    limit = parent.size
    while (r, c) != field_.source and len(out) <= limit:
        k = int(parent[r, c])
        if k < 0:
            break
        dr, dc = MOVES[k]
        r, c = r - dr, c - dc
        out.append((r, c))
    return np.asarray(out, dtype=np.intp)


# ---------------------------------------------------------------------------------------
# Supercover line of sight
# ---------------------------------------------------------------------------------------
def supercover_cells(a: npt.ArrayLike, b: npt.ArrayLike) -> IntArray:
    """Every cell a segment touches (all-cells Bresenham, thesis Figure 3.21b): ``(k, 2)``.

    ``a``, ``b``: continuous (row, col). A segment passing exactly through a cell corner
    touches the four cells around it. Unique cells, unordered.
    """
    aa = np.asarray(a, dtype=np.float64).reshape(2)
    rows, cols, mask = _crossing_samples(aa, np.asarray(b, dtype=np.float64).reshape(1, 2))
    cells = np.column_stack([rows[:, 0][mask[:, 0]], cols[:, 0][mask[:, 0]]])
    return np.unique(cells, axis=0)


def _crossing_samples(a: FloatArray, b: FloatArray) -> tuple[IntArray, IntArray, BoolArray]:
    """Cells around every grid-line crossing and both ends of segments ``a -> b[i]``.

    ``a``: ``(2,)`` shared by every segment, or ``(m, 2)`` one per segment; ``b``: ``(m, 2)``.
    Returns ``(rows, cols, valid)``, each ``(K*4, m)``: sample by sample (the crossings'
    parameters, then the four cells around each point), each sample's arithmetic running
    along the segments.
    """
    m = b.shape[0]
    aa = np.broadcast_to(a, b.shape)
    d = b - aa  # (m, 2)
    lo = np.minimum(aa, b)
    hi = np.maximum(aa, b)
    first = np.ceil(lo - 0.5)  # first grid line index k with k + 0.5 >= lo
    last = np.floor(hi - 0.5)
    moving = np.abs(d) > 1e-12
    count = np.where(moving, np.maximum(last - first + 1, 0), 0).astype(np.intp)  # (m, 2)
    kmax = int(np.maximum.reduce(count, axis=None, initial=0))
    steps = np.arange(kmax)[:, None]
    dd = np.where(moving, d, 1.0)
    k = 2 + 2 * kmax
    t = np.empty((k, m))  # the ends, then the crossings of row lines, then of column lines
    t[0] = 0.0
    t[1] = 1.0
    ok = np.ones((k, m), dtype=bool)
    for axis in (0, 1):
        rows = slice(2 + axis * kmax, 2 + (axis + 1) * kmax)
        line = first[:, axis] + steps + 0.5  # (kmax, m)
        t[rows] = clip((line - aa[:, axis]) / dd[:, axis], 0.0, 1.0)
        ok[rows] = steps < count[:, axis]
    p0 = aa[:, 0] + t * d[:, 0]
    p1 = aa[:, 1] + t * d[:, 1]
    eps = _CORNER_EPS
    r_lo, r_hi = np.rint(p0 - eps).astype(np.intp), np.rint(p0 + eps).astype(np.intp)
    c_lo, c_hi = np.rint(p1 - eps).astype(np.intp), np.rint(p1 + eps).astype(np.intp)
    rows_out = np.concatenate([r_lo, r_lo, r_hi, r_hi])
    cols_out = np.concatenate([c_lo, c_hi, c_lo, c_hi])
    return rows_out, cols_out, np.concatenate([ok, ok, ok, ok])


_CORNER_EPS = 1e-7


def segments_clear_each(
    blocked: BoolArray, which: IntArray, shape: IntArray, a: FloatArray, b: FloatArray
) -> BoolArray:
    """Line of sight of many segments, each on its own grid: segment ``i`` from ``a[i]`` to
    ``b[i]`` (``(m, 2)`` continuous row, col) on ``blocked[which[i]]`` (``blocked``:
    ``(n, H, W)``), whose own size is ``shape[i]`` (``(m, 2)``: rows, cols; cells past it
    count as outside). Same samples and result as :func:`segments_clear` per segment."""
    if b.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    r, c, mask = _crossing_samples(a, b)
    inside = (r >= 0) & (r < shape[:, 0]) & (c >= 0) & (c < shape[:, 1])
    hit = blocked[which, np.where(inside, r, 0), np.where(inside, c, 0)]
    bad = mask & (~inside | hit)
    return np.asarray(~np.logical_or.reduce(bad, axis=0))


def segments_clear(blocked: BoolArray, a: npt.ArrayLike, b: npt.ArrayLike) -> BoolArray:
    """Line of sight from ``a`` ``(2,)`` to each ``b`` ``(m, 2)`` (continuous row, col) on
    ``blocked`` ``(h, w)`` (cells outside count as blocked): :func:`segments_clear_each` on
    one grid; one segment alone is walked by :func:`_segment_clear` (the same samples,
    without numpy's per-call cost)."""
    bb = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    if bb.shape[0] == 1:
        a0, a1 = np.asarray(a, dtype=np.float64).reshape(2).tolist()
        b0, b1 = bb[0].tolist()
        h, w = blocked.shape
        return np.array([_segment_clear(blocked, h, w, a0, a1, b0, b1)])
    aa = np.broadcast_to(np.asarray(a, dtype=np.float64).reshape(2), bb.shape)
    m = bb.shape[0]
    shape = np.tile(np.asarray(blocked.shape, dtype=np.intp), (m, 1))
    return segments_clear_each(blocked[None], np.zeros(m, dtype=np.intp), shape, aa, bb)


def line_of_sight_reduce(blocked: BoolArray, points: npt.ArrayLike) -> IntArray:
    """Indices of the points to keep so that consecutive kept points see each other.

    ``points``: ``(n, 2)`` continuous (row, col), from start to end. Greedy: from each kept
    point jump to the farthest later point in sight (thesis §3.4.2, the final cells); the
    next point is kept when no later one is in sight. The later points are tried from the
    farthest down, one segment at a time with :func:`_segment_clear` on the map as lists:
    the first clear one ends the tries, so a path of a few dozen cells costs a few segment
    walks (2.5x less than testing all later points at once with numpy, measured on the
    crowd benchmark's plans).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2).tolist()
    n = len(pts)
    h, w = blocked.shape
    rows = blocked.tolist()
    keep = [0]
    i = 0
    while i < n - 1:
        a0, a1 = pts[i]
        j = n - 1
        while j > i + 1 and not _segment_clear(rows, h, w, a0, a1, pts[j][0], pts[j][1]):
            j -= 1
        keep.append(j)  # the next point is always kept, in sight or not
        i = j
    return np.asarray(keep, dtype=np.intp)


def _segment_clear(rows: Any, h: int, w: int, a0: float, a1: float, b0: float, b1: float) -> bool:
    """Line of sight of one segment ``(a0, a1) -> (b0, b1)`` for :func:`line_of_sight_reduce`:
    the samples of :func:`_crossing_samples` (the same arithmetic, in plain Python floats),
    nudged by -1e-7 and +1e-7 in both axes, looked up in ``rows`` (a boolean map indexable
    as ``rows[r][c]``; outside ``h`` × ``w`` is blocked). The tests check it against
    :func:`segments_clear_each` on random maps, on and off the cell lattice. Each sample is
    looked up as soon as it is made: the first one blocked ends the walk (most segments that
    :func:`line_of_sight_reduce` tries are blocked)."""
    d0 = b0 - a0
    d1 = b1 - a1
    # the ends first (t = 0 and 1, computed as the other samples are)
    if not _point_clear(rows, h, w, a0 + 0.0 * d0, a1 + 0.0 * d1):
        return False
    if not _point_clear(rows, h, w, a0 + d0, a1 + d1):
        return False
    for a, b, d in ((a0, b0, d0), (a1, b1, d1)):
        if abs(d) <= 1e-12:
            continue
        lo, hi = (a, b) if a <= b else (b, a)
        for k in range(math.ceil(lo - 0.5), math.floor(hi - 0.5) + 1):
            t = (float(k) + 0.5 - a) / d
            if t < 0.0:
                t = 0.0
            elif t > 1.0:
                t = 1.0
            if not _point_clear(rows, h, w, a0 + t * d0, a1 + t * d1):
                return False
    return True


def _point_clear(rows: Any, h: int, w: int, p0: float, p1: float) -> bool:
    """:func:`_segment_clear`'s look-up of one sample: its cell and the cells the sample
    nudged by :data:`_CORNER_EPS` falls in."""
    eps = _CORNER_EPS
    r_lo = round(p0 - eps)
    r_hi = round(p0 + eps)  # rounding is monotone: r_lo <= r_hi, c_lo <= c_hi
    c_lo = round(p1 - eps)
    c_hi = round(p1 + eps)
    if r_lo < 0 or r_hi >= h or c_lo < 0 or c_hi >= w:
        return False
    lo_row = rows[r_lo]
    hi_row = rows[r_hi]
    return not (lo_row[c_lo] or lo_row[c_hi] or hi_row[c_lo] or hi_row[c_hi])


# ---------------------------------------------------------------------------------------
# Height profile
# ---------------------------------------------------------------------------------------
def clearance_profile(s: npt.ArrayLike, length: float, step_height: float, ramp: float) -> FloatArray:
    """Required clearance above the ground at arc lengths ``s``: 0 at both ends, rising
    linearly over ``ramp`` metres to ``step_height``."""
    ss = np.asarray(s, dtype=np.float64)
    if ramp <= 0.0:
        return np.full(ss.shape, float(step_height))
    return np.asarray(step_height * np.clip(np.minimum(ss, length - ss) / ramp, 0.0, 1.0))


def height_profile(knots_s: FloatArray, knots_z: FloatArray, s: FloatArray) -> FloatArray:
    """Hermite height profile through concave waypoints, evaluated at ``s``.

    Interior slopes are the non-uniform Catmull-Rom ones (the chord-weighted mean of the two
    neighbouring secants), end slopes the end secants. For concave waypoints (an upper hull)
    each segment's end slopes bracket its secant, which keeps the cubic on or above the chord,
    so the profile never dips below the hull.
    """
    k = knots_s.shape[0]
    if k == 1:
        return np.full(s.shape, float(knots_z[0]))
    h = np.diff(knots_s)
    h_safe = np.where(h > 1e-12, h, 1e-12)
    delta = np.diff(knots_z) / h_safe
    slope = np.empty(k)
    slope[0] = delta[0]
    slope[-1] = delta[-1]
    if k > 2:
        slope[1:-1] = (knots_z[2:] - knots_z[:-2]) / np.maximum(knots_s[2:] - knots_s[:-2], 1e-12)
    seg = clip(knots_s.searchsorted(s, side="right") - 1, 0, k - 2)
    t = np.clip((s - knots_s[seg]) / h_safe[seg], 0.0, 1.0)
    w = hermite_basis(t)
    return np.asarray(
        w[:, 0] * knots_z[seg] + w[:, 1] * knots_z[seg + 1]
        + w[:, 2] * h[seg] * slope[seg] + w[:, 3] * h[seg] * slope[seg + 1]
    )


#: Relative tolerance of the trajectory hull's collinearity test: the clearance profile has
#: long collinear runs (flat ground, linear ramps) whose points must be dropped or kept the
#: same way for a rig and its ×100 copy, whose inputs differ by float noise (~1e-8).
_COLLINEAR = 1e-6


def _chord_tolerance(min_gap: float) -> float:
    """How far below a sample a chord may pass and still count as clearing it (metres): a
    millionth of the waypoint gap, so the same at every scale."""
    return 1e-6 * min_gap if min_gap > 0.0 else 1e-9


def _hull_knots_increasing(
    s: list[float], required: list[float], min_gap: float, start: int = 0, stop: int | None = None
) -> list[int]:
    """Upper-hull vertices of ``(s, required)`` for strictly increasing ``s`` (a monotone
    chain, collinear points dropped to :data:`_COLLINEAR`), without vertices closer than
    ``min_gap`` to the previous one when the chord that replaces them still clears every
    sample; in plain Python floats (a few dozen points: cheaper than numpy calls). Of the
    points ``start:stop`` only (indices into the whole lists: many plans' samples one after
    the other are not copied plan by plan)."""
    if stop is None:
        stop = len(s)
    ncol = -_COLLINEAR
    hull: list[int] = []
    push = hull.append
    # the hull's second last and last vertices (si, zi), (sj, zj) kept in locals: a point
    # costs no list lookups unless it pops a vertex
    si = zi = sj = zj = 0.0
    n = 0
    k = start
    for sk, zk in zip(s[start:stop], required[start:stop], strict=True):
        while n >= 2:
            ax = (sj - si) * (zk - zi)
            bx = (zj - zi) * (sk - si)
            if ax - bx >= ncol * (abs(ax) + abs(bx)):
                hull.pop()
                n -= 1
                sj = si
                zj = zi
                if n >= 2:
                    i = hull[-2]
                    si = s[i]
                    zi = required[i]
            else:
                break
        push(k)
        n += 1
        si = sj
        zi = zj
        sj = sk
        zj = zk
        k += 1
    if n <= 2 or min_gap <= 0.0:
        return hull
    tol = _chord_tolerance(min_gap)
    keep = [hull[0]]
    a = hull[0]
    sa = s[a]
    for pos in range(1, n - 1):
        v = hull[pos]
        if s[v] - sa >= min_gap:
            keep.append(v)
            a = v
            sa = s[v]
            continue
        c = hull[pos + 1]
        ra = required[a]
        rise = required[c] - ra
        den = max(s[c] - sa, 1e-12)
        for s_i, r_i in zip(s[a : c + 1], required[a : c + 1], strict=True):
            if not ra + rise * (s_i - sa) / den >= r_i - tol:
                keep.append(v)  # the chord that would replace it dips under a sample
                a = v
                sa = s[v]
                break
    keep.append(hull[-1])
    return keep


def turning_each(samples: FloatArray, bounds: list[int]) -> list[float]:
    """Total absolute heading change (radians) of many polylines stored one after the other
    in ``samples`` ``(M, 2)``, polyline ``i`` being rows ``bounds[i]:bounds[i + 1]``."""
    n = len(bounds) - 1
    # (differences as a[1:] - a[:-1]: np.diff's arithmetic without its Python-level set-up)
    d = samples[1:] - samples[:-1]
    length = planar_length(d[:, 0], d[:, 1])
    owner = np.arange(n).repeat([b - a for a, b in itertools.pairwise(bounds)])
    keep = (length > 1e-9) & (owner[:-1] == owner[1:])
    idx = keep.nonzero()[0]
    ang = np.arctan2(d[idx, 1], d[idx, 0])
    turn = np.abs((ang[1:] - ang[:-1] + np.pi) % (2.0 * np.pi) - np.pi)
    who = owner[idx]
    cuts = who.searchsorted(np.arange(n + 1)).tolist()
    add = np.add.reduce  # (np.sum's reduction, without its Python-level dispatch)
    out = []
    for i in range(n):
        a, b = cuts[i], cuts[i + 1]
        out.append(float(add(turn[a : b - 1])) if b - a >= 2 else 0.0)
    return out


def lift_each(
    samples: FloatArray, arc: FloatArray, bounds: list[int], ground: FloatArray, length: list[float],
    start_z: list[float], target_z: list[float], step_height: list[float], ramp: list[float],
    min_gap: list[float], waypoints_2d: list[FloatArray],
) -> list[FootTrajectory]:
    """:meth:`PathContext.lift` of many 2D plans at once (same arithmetic, so the same
    trajectories to a few ulps): plan ``i`` has the samples ``samples[bounds[i]:bounds[i + 1]]`` ``(m, 2)``
    at strictly increasing arc lengths ``arc``, ``ground`` under them (what the swinging foot
    must clear), its 2D ``length`` (> 0) and ``waypoints_2d``; ``ramp`` is already capped at
    half the length."""
    n = len(bounds) - 1
    # (differences as a[1:] - a[:-1]: np.diff's arithmetic without its Python-level set-up)
    counts = np.array([b - a for a, b in itertools.pairwise(bounds)])
    if n == 1:  # scalars broadcast: the same numbers, fewer calls
        L: FloatArray | float = length[0]
        rp: FloatArray | float = ramp[0]
        sh: FloatArray | float = step_height[0]
        owner = None
    else:
        owner = np.arange(n).repeat(counts)
        L = np.asarray(length)[owner]
        rp = np.asarray(ramp)[owner]
        sh = np.asarray(step_height)[owner]
    # clearance_profile (np.clip as minimum/maximum: the same values)
    clear = sh * np.minimum(np.maximum(np.minimum(arc, L - arc) / rp, 0.0), 1.0)
    required = ground + clear
    first = bounds[:-1]
    last = [b - 1 for b in bounds[1:]]
    required[first] = start_z
    required[last] = target_z
    s_list = arc.tolist()
    r_list = required.tolist()
    knots: list[int] = []
    knot_bounds = [0]
    for i in range(n):
        a, b = bounds[i], bounds[i + 1]
        knots.extend(_hull_knots_increasing(s_list, r_list, min_gap[i], a, b))
        knot_bounds.append(len(knots))
    kidx = np.asarray(knots)
    ks = arc[kidx]
    kz = required[kidx]
    # Height profile (height_profile per plan): knot j's segment to knot j + 1.
    h = ks[1:] - ks[:-1]
    h_safe = np.where(h > 1e-12, h, 1e-12)
    delta = (kz[1:] - kz[:-1]) / h_safe
    nk = kidx.size
    slope = np.empty(nk)
    slope[1:-1] = (kz[2:] - kz[:-2]) / np.maximum(ks[2:] - ks[:-2], 1e-12)
    heads = knot_bounds[:-1]
    tails = [k - 1 for k in knot_bounds[1:]]
    slope[heads] = delta[heads]
    slope[tails] = delta[[k - 1 for k in tails]]
    is_knot = np.zeros(arc.size, dtype=np.intp)
    is_knot[kidx] = 1
    # The knot at or before each sample (each plan's first sample is a knot), at most its
    # plan's second last: searchsorted(knots, s, "right") - 1 clipped, for increasing s.
    seg = is_knot.cumsum() - 1
    seg = np.minimum(seg, nk - 2) if owner is None else np.minimum(seg, (np.asarray(tails) - 1)[owner])
    t = np.minimum(np.maximum((arc - ks[seg]) / h_safe[seg], 0.0), 1.0)
    powers = np.empty((t.size, 4))
    powers[:, 0] = t**3
    powers[:, 1] = t**2
    powers[:, 2] = t
    powers[:, 3] = 1.0
    if n == 1:
        w = powers @ HERMITE_MATRIX
    else:
        w = np.empty_like(powers)
        for i in range(n):  # one product per plan: the same BLAS call as for that plan alone
            a, b = bounds[i], bounds[i + 1]
            w[a:b] = powers[a:b] @ HERMITE_MATRIX
    hs = h[seg]
    z = (w[:, 0] * kz[seg] + w[:, 1] * kz[seg + 1] + w[:, 2] * hs * slope[seg]
         + w[:, 3] * hs * slope[seg + 1])
    points = np.empty((arc.size, 3))
    points[:, :2] = samples
    np.maximum(z, required, out=points[:, 2])
    d3 = points[1:] - points[:-1]
    seg3 = vector_norm(d3)
    way3 = np.empty((nk, 3))
    way3[:, :2] = samples[kidx]
    way3[:, 2] = kz
    # Each plan's 3D arc length: its segments in a row of their own after a 0, one running
    # sum along the rows (the same sums, in the same order, as a cumsum per plan).
    if owner is None:
        arcs = np.empty((1, arc.size))
        arcs[0, 0] = 0.0
        seg3.cumsum(out=arcs[0, 1:])
    else:
        table = np.zeros((n, int(np.maximum.reduce(counts))))
        pos = np.arange(arc.size) - np.asarray(first).repeat(counts)
        inner = pos > 0  # a sample after its plan's first: its segment from the one before
        table[owner[inner], pos[inner]] = seg3[inner[1:]]
        arcs = table.cumsum(axis=1)
    ends = arcs[np.arange(n), counts - 1].tolist()
    out = []
    for i in range(n):
        a, b = bounds[i], bounds[i + 1]
        out.append(FootTrajectory(points[a:b], ends[i], way3[knot_bounds[i] : knot_bounds[i + 1]],
                                  waypoints_2d[i], length[i], arcs[i, : b - a], arc[a:b]))
    return out


# ---------------------------------------------------------------------------------------
# Paths inside one plan: shared context
# ---------------------------------------------------------------------------------------
@dataclass
class Path2D:
    """A 2D plan: ``waypoints`` ``(k, 2)`` world xy (final cells, exact ends), dense
    ``samples`` ``(m, 2)`` of the curve at arc lengths ``arc`` ``(m,)``, its ``length``,
    total absolute ``turning`` (radians) and the cardinal ``tension`` that cleared;
    ``in_sight``: the target was in plain sight of the foot (the plan is the straight line,
    and stays so at every higher slice)."""

    waypoints: FloatArray
    samples: FloatArray
    arc: FloatArray
    length: float
    turning: float
    tension: float
    n_naive: int
    in_sight: bool = False


@dataclass(frozen=True)
class PathParams:
    """Path construction knobs: ``step_height`` (clearance, metres), ``tension`` of the 2D
    cardinal curve, ``sample_spacing`` along curves in cells, ``min_waypoint_gap`` in cells
    (closer 3D waypoints are merged when safe), ``ramp`` of the clearance at lift-off and
    touch-down in metres (None: the step height, at least two cells); ``los_shortcut``: skip
    the wavefront when the target is in sight from the foot (same result, faster)."""

    step_height: float = 0.1
    tension: float = 0.5
    sample_spacing: float = 0.25
    min_waypoint_gap: float = 1.5
    ramp: float | None = None
    los_shortcut: bool = True


class PathContext:
    """What all paths of one foot share: the search region, the foot kernels, the clearance
    elevations, the lift-off zone and one cached wavefront per height slice.

    ``grids``: the window; ``start``: ``(3,)`` the foot; ``region``: the search rectangle;
    ``extra``: ``(ny, nx)`` extra forbidden cells (other feet) or None; ``foot_half_extents``
    and ``foot_yaw``: the foot's shape; ``per_target``: grow one wavefront per target (the
    thesis's way) instead of one per slice from the foot.

    The *lift-off zone* is never blocked for paths: the cells the foot covers where it stands,
    and, when it stands on an avoided obstacle (one that moved under it), that obstacle's cells
    and their enlargement, so that the foot can leave it.
    """

    def __init__(
        self, grids: WindowGrids, start: npt.ArrayLike, region: Region, extra: BoolArray | None,
        foot_half_extents: npt.ArrayLike, foot_yaw: float, params: PathParams, per_target: bool = False,
    ) -> None:
        self.grids = grids
        self.params = params
        self.start = np.asarray(start, dtype=np.float64).reshape(3)
        self.region = region
        self.per_target = per_target
        cell = grids.cell
        self.sweep_kernel = foot_kernel(cell, foot_half_extents, foot_yaw, anywhere_in_cell=True)
        self._foot_shape = (foot_half_extents, float(foot_yaw))
        self._land_kernel: IntArray | None = None
        self.elevation = np.asarray(region.view(grids.elevation), dtype=np.float64)
        base = np.asarray(region.view(grids.avoid), dtype=bool).copy()
        if extra is not None:
            base |= np.asarray(region.view(extra), dtype=bool)
        self.base_core = base
        self.outside = ~region.mask
        start_rc = grids.rowcol(self.start[:2]) - np.array([region.r0, region.c0])
        self.start_rc = start_rc
        self.start_cell = (int(np.rint(start_rc[0])), int(np.rint(start_rc[1])))
        h, w = region.shape
        inside = 0 <= self.start_cell[0] < h and 0 <= self.start_cell[1] < w
        self.start_inside = bool(inside)
        liftoff = np.zeros((h, w), dtype=bool)
        if inside:
            rr = self.start_cell[0] + self.sweep_kernel[:, 0]
            cc = self.start_cell[1] + self.sweep_kernel[:, 1]
            ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
            liftoff[rr[ok], cc[ok]] = True
            avoid = np.asarray(region.view(grids.avoid), dtype=bool)
            if avoid[self.start_cell]:
                # The foot stands on an avoided obstacle (it moved under the foot): let it leave
                # across that obstacle's cells rather than be stuck there.
                avoid_grown = dilate(avoid, self.sweep_kernel)
                escape = wavefront(avoid_grown & region.mask, self.start_cell)
                liftoff |= np.isfinite(escape.dist)
        self.liftoff = liftoff
        self._clear_grid: FloatArray | None = None
        self._blocked: dict[float, tuple[BoolArray, BoolArray, BoolArray]] = {}
        self._fields: dict[tuple[float, int, int], DistanceField] = {}
        self.n_wavefronts = 0
        self.wavefront_iterations = 0
        self.ramp = params.ramp if params.ramp is not None else max(params.step_height, 2.0 * cell)

    @classmethod
    def from_parts(
        cls, grids: WindowGrids, start: FloatArray, region: Region, params: PathParams, per_target: bool,
        sweep_kernel: IntArray, foot_shape: tuple[npt.ArrayLike, float], elevation: FloatArray,
        base_core: BoolArray, start_rc: FloatArray, liftoff: BoolArray,
        maps: dict[float, tuple[BoolArray, BoolArray, BoolArray]],
        fields: dict[tuple[float, int, int], DistanceField] | None = None,
    ) -> PathContext:
        """A context from parts computed elsewhere (the batched planner computes them for many
        feet at once): exactly what ``__init__`` would compute. ``foot_shape``: the foot's half
        extents and yaw; ``maps`` (slice level -> its maps) and ``fields`` are the caches
        themselves, shared with the caller."""
        self = cls.__new__(cls)
        self.grids = grids
        self.params = params
        self.start = start
        self.region = region
        self.per_target = per_target
        self.sweep_kernel = sweep_kernel
        self._foot_shape = (foot_shape[0], float(foot_shape[1]))
        self._land_kernel = None
        self.elevation = elevation
        self.base_core = base_core
        self.outside = ~region.mask
        self.start_rc = start_rc
        self.start_cell = (round(float(start_rc[0])), round(float(start_rc[1])))
        h, w = region.shape
        self.start_inside = 0 <= self.start_cell[0] < h and 0 <= self.start_cell[1] < w
        self.liftoff = liftoff
        self._clear_grid = None
        self._blocked = maps
        self._fields = fields if fields is not None else {}
        self.n_wavefronts = 0
        self.wavefront_iterations = 0
        cell = grids.cell
        self.ramp = params.ramp if params.ramp is not None else max(params.step_height, 2.0 * cell)
        return self

    @property
    def land_kernel(self) -> IntArray:
        """The cells a landing foot covers at a cell centre (made on first use)."""
        if self._land_kernel is None:
            half, yaw = self._foot_shape
            self._land_kernel = foot_kernel(self.grids.cell, half, yaw, anywhere_in_cell=False)
        return self._land_kernel

    # -- obstacle maps per slice ------------------------------------------------------------
    def maps(self, level: float) -> tuple[BoolArray, BoolArray, BoolArray]:
        """``(core, dilated, blocked)`` for a slice ``level`` (``inf`` = no slice).

        ``core``: forbidden cells; ``dilated``: cells forbidden by the foot enlargement only;
        ``blocked``: what paths may not cross (both, plus outside the rectangle, minus the
        lift-off zone around the foot).
        """
        hit = self._blocked.get(level)
        if hit is None:
            core = self.base_core | (self.elevation > level) if math.isfinite(level) else self.base_core
            grown = dilate(core, self.sweep_kernel)
            blocked = (grown | self.outside) & ~self.liftoff
            hit = (core, grown & ~core, blocked)
            self._blocked[level] = hit
        return hit

    def field(self, level: float, source: tuple[int, int] | None = None) -> DistanceField:
        """Wavefront for a slice, from the foot (default) or from ``source``; cached."""
        src = self.start_cell if source is None else source
        key = (level, src[0], src[1])
        hit = self._fields.get(key)
        if hit is None:
            blocked = self.maps(level)[2]
            hit = octile_field(self.region.shape, src) if not blocked.any() else wavefront(~blocked, src)
            self.n_wavefronts += 1
            self.wavefront_iterations += hit.iterations
            self._fields[key] = hit
        return hit

    def reachable(self, level: float, cells: IntArray) -> BoolArray:
        """Which region cells ``(k, 2)`` the foot can reach at this slice (shared wavefront)."""
        return self.field(level).reachable(cells)

    # -- one 2D plan -----------------------------------------------------------------------
    def to_world(self, rc: FloatArray) -> FloatArray:
        g = self.grids
        return g.xy_of(rc[..., 0] + self.region.r0, rc[..., 1] + self.region.c0)

    def path_2d(
        self, level: float, target_cell: tuple[int, int], target_xy: FloatArray | None = None
    ) -> Path2D | None:
        """The 2D plan from the foot to a region cell at a slice, or None if unreachable.

        ``target_xy`` (world, inside the target cell) ends the plan exactly there instead of at
        the cell centre."""
        if not self.start_inside:
            return None
        blocked = self.maps(level)[2]
        if blocked[target_cell]:
            return None
        offset = np.array([self.region.r0, self.region.c0])
        if target_xy is not None:
            end_rc = self.grids.rowcol(np.asarray(target_xy, dtype=np.float64)) - offset
        else:
            end_rc = np.asarray(target_cell, dtype=np.float64)
        if not self.per_target:
            cached = self._fields.get((level, self.start_cell[0], self.start_cell[1]))
            if cached is not None and not np.isfinite(cached.dist[target_cell]):
                return None  # known unreachable at this slice
        in_sight = bool(segments_clear(blocked, self.start_rc, end_rc[None, :])[0])
        return self.plan_2d(level, target_cell, end_rc, in_sight, target_xy is not None)

    def plan_2d(
        self, level: float, target_cell: tuple[int, int], end_rc: FloatArray, in_sight: bool,
        exact_end: bool = True,
    ) -> Path2D | None:
        """The rest of :meth:`path_2d` once its checks passed (the target cell is free and not
        known to be unreachable; ``in_sight``: the straight line to ``end_rc`` is clear)."""
        blocked = self.maps(level)[2]
        offset = np.array([self.region.r0, self.region.c0])
        if self.params.los_shortcut and in_sight:
            # The target is in sight: the wavefront, its descent and the line-of-sight reduction
            # would keep exactly these two points (the greedy reduction jumps to the farthest
            # visible point), so skip them.
            way_rc = np.array((self.start_rc, end_rc))
            n_naive = 0
        else:
            if self.per_target:
                fld = self.field(level, target_cell)
                naive = descend(fld, self.start_cell)  # start -> target
            else:
                fld = self.field(level)
                naive = descend(fld, target_cell)[::-1]  # target -> start, reversed
            if naive.shape[0] == 0:
                return None
            n_naive = int(naive.shape[0])
            pts = np.vstack([self.start_rc[None, :], naive.astype(np.float64)])
            if exact_end:
                # End exactly at the target; it replaces its cell's centre when the cell before
                # sees it (no detour to the centre and back), else the centre stays a waypoint.
                if segments_clear(blocked, pts[-2], end_rc[None, :])[0]:
                    pts[-1] = end_rc
                else:
                    pts = np.vstack([pts, end_rc[None, :]])
            way_rc = pts[line_of_sight_reduce(blocked, pts)]
        waypoints = self.to_world(way_rc)
        spacing = self.params.sample_spacing * self.grids.cell
        # Drop coincident consecutive waypoints (the start on its own cell centre).
        chords = waypoints[1:] - waypoints[:-1]
        step = vector_norm(chords)  # np.linalg.norm's arithmetic
        waypoints = waypoints[np.concatenate([[True], step > 1e-9])]
        if waypoints.shape[0] < 2:
            p = waypoints[:1]
            return Path2D(p, p.copy(), np.zeros(1), 0.0, 0.0, self.params.tension, n_naive, in_sight)
        h, w = blocked.shape
        tension = self.params.tension
        for attempt in range(3):
            if waypoints.shape[0] == 2:  # a straight segment, whatever the tension
                chord = waypoints[1] - waypoints[0]
                length = planar_length(float(chord[0]), float(chord[1]))
                arc = linspace_to(length, max(2, math.ceil(length / spacing) + 1))
                samples = waypoints[0] + (waypoints[1] - waypoints[0]) * (arc / length)[:, None]
            else:
                samples, arc, length = cardinal_samples(waypoints, tension, spacing, samples_per_segment=16)
            cells = np.rint(self.grids.rowcol(samples) - offset).astype(np.intp)
            inside = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
            if np.logical_and.reduce(inside) and not np.logical_or.reduce(blocked[cells[:, 0], cells[:, 1]]):
                break
            tension = 0.0 if attempt == 1 else tension * 0.5
        else:
            return None
        return Path2D(waypoints, samples, arc, float(length), _turning(samples), tension, n_naive, in_sight)

    # -- lifting to 3D -------------------------------------------------------------------------
    def kernel_max(self, cells: IntArray, kernel: IntArray, grid: FloatArray | None = None) -> FloatArray:
        """Highest elevation over ``kernel`` offsets around region cells ``(k, 2)``: ``(k,)``.

        Reads the whole window (or ``grid``, a map of the window's shape), so cells near the
        region's border see past it."""
        g = self.grids.elevation if grid is None else grid
        ny, nx = g.shape
        rr = cells[:, 0, None] + (self.region.r0 + kernel[None, :, 0])
        cc = cells[:, 1, None] + (self.region.c0 + kernel[None, :, 1])
        ok = (rr >= 0) & (rr < ny) & (cc >= 0) & (cc < nx)
        # (np.clip as a maximum and a minimum: the same cells without its dispatch)
        r_in = np.minimum(np.maximum(rr, 0), ny - 1)
        c_in = np.minimum(np.maximum(cc, 0), nx - 1)
        vals = np.where(ok, g[r_in, c_in], -np.inf)
        return np.maximum.reduce(vals, axis=1)

    def land_height(self, cells: IntArray, kernel: IntArray | None = None) -> FloatArray:
        """Height a foot lands at in region cells ``(k, 2)``: the highest surface under it.

        ``kernel``: the cells the foot covers around its cell (default: a foot at the cell
        centre)."""
        return self.kernel_max(cells, self.land_kernel if kernel is None else kernel)

    def lift(self, path: Path2D, target_z: float) -> FootTrajectory:
        """The 3D trajectory over a 2D plan (thesis Figure 3.23)."""
        prm = self.params
        z0 = float(self.start[2])
        if path.length <= 1e-9:
            return _in_place(self.start, target_z, self._clear_at(path.samples[:1])[0], prm.step_height)
        # The samples are at increasing arc lengths (a linspace over a positive length):
        # lift_each holds the same arithmetic as the steps below, with fewer numpy calls.
        #   required = ground + clearance_profile(s, length, step_height, ramp), pinned to the
        #   start and target heights; knots = _hull_waypoints(s, required, min gap);
        #   z = max(height_profile(s[knots], required[knots], s), required).
        ground = self._clear_at(path.samples)
        ramp = min(self.ramp, 0.5 * path.length)
        return lift_each(path.samples, path.arc, [0, path.samples.shape[0]], ground, [path.length], [z0],
                         [target_z], [prm.step_height], [ramp], [prm.min_waypoint_gap * self.grids.cell],
                         [path.waypoints])[0]

    def clearance_grid(self) -> FloatArray:
        """The window's elevation as a swing must clear it (:func:`clearance_elevation`)."""
        if self._clear_grid is None:
            self._clear_grid = clearance_elevation(self.grids, float(self.start[2]) + self.params.step_height)
        return self._clear_grid

    def _clear_at(self, xy: FloatArray) -> FloatArray:
        """What a foot swinging over each point must clear: the highest surface under the foot
        anywhere in that point's cell (avoided obstacles aside, see :meth:`clearance_grid`)."""
        rc = np.rint(self.grids.rowcol(xy) - np.array([self.region.r0, self.region.c0])).astype(np.intp)
        return self.kernel_max(rc, self.sweep_kernel, self.clearance_grid())


def clearance_elevation(grids: WindowGrids, above: float) -> FloatArray:
    """The elevation a swing must clear: ``grids.elevation`` with the avoided cells higher
    than ``above`` (the foot's height plus its step height) at :data:`~.terrain.NO_SURFACE`.

    Paths never cross avoided cells; a foot's swept box only grazes them beside its path, or
    where it stands when a moving obstacle has come at it, and such a foot leaves sideways,
    not over the obstacle's top. A foot standing on an avoided obstacle's top (it was pushed
    up there) still clears it on its way off."""
    if not grids.avoid.any():
        return grids.elevation
    return np.where(grids.avoid & (grids.elevation > above), NO_SURFACE, grids.elevation)


def _turning(samples: FloatArray) -> float:
    """Total absolute heading change along a 2D polyline ``(m, 2)``, in radians:
    :func:`turning_each` of one polyline (the same arithmetic without its bookkeeping)."""
    d = samples[1:] - samples[:-1]
    idx = (planar_length(d[:, 0], d[:, 1]) > 1e-9).nonzero()[0]
    if idx.size < 2:
        return 0.0
    ang = np.arctan2(d[idx, 1], d[idx, 0])
    return float(np.add.reduce(np.abs((ang[1:] - ang[:-1] + np.pi) % (2.0 * np.pi) - np.pi)))


def _in_place(start: FloatArray, target_z: float, ground: float, step_height: float) -> FootTrajectory:
    """Lift and put down on the spot: up to the step height above the ground, then down. A
    foot already in the air (a re-plan) is not lifted a step height above where it is: plan
    after plan it would ratchet upward."""
    top = max(float(start[2]), max(target_z, ground) + step_height)
    knots_s = np.array([0.0, 0.5, 1.0])
    knots_z = np.array([float(start[2]), top, target_z])
    s = np.linspace(0.0, 1.0, 17)
    z = height_profile(knots_s, knots_z, s)
    pts = np.column_stack([np.broadcast_to(start[:2], (s.size, 2)), z])
    return FootTrajectory.from_points(pts, np.column_stack([np.broadcast_to(start[:2], (3, 2)), knots_z]),
                                      start[None, :2].copy(), 0.0, np.zeros(s.size))


# ---------------------------------------------------------------------------------------
# Scores (thesis §3.5.1: straight, low-curvature trajectories are preferred)
# ---------------------------------------------------------------------------------------
def path_score_2d(path: Path2D) -> float:
    """Score in (0, 1] of a 2D plan: straightness (direct distance / curve length) times
    ``1 / (1 + turning / 2π)``. 1 for a straight line."""
    if path.length <= 1e-9:
        return 1.0
    chord = path.samples[-1] - path.samples[0]
    return straightness_score(planar_length(float(chord[0]), float(chord[1])), path.length, path.turning)


def straightness_score(direct: float, length: float, turning: float) -> float:
    """:func:`path_score_2d` from a plan's ``direct`` distance, curve ``length`` (> 0) and total
    ``turning`` (radians); the batched planner scores its straight plans with the same
    operations, element-wise."""
    return min(1.0, direct / length) / (1.0 + turning / (2.0 * math.pi))


def vertical_factor(traj: FootTrajectory, step_height: float) -> float:
    """Factor in (0, 1] for the climb of a 3D trajectory: 1 while its length stays within a
    clean arc's bound on flat ground (2D length + twice the step height), then the square of
    that bound over the length: lifting a foot onto or over a tall obstacle costs more than a
    short detour around it. Never above 1, so a 3D score never beats its 2D bound
    (Appendix E)."""
    if traj.length <= 1e-9:
        return 1.0
    return min(1.0, (traj.length_2d + 2.0 * step_height) / traj.length) ** 2


# ---------------------------------------------------------------------------------------
# Re-validation (thesis §3.2.1: the controller checks running swings every step)
# ---------------------------------------------------------------------------------------
def trajectory_valid(
    grids: WindowGrids, traj: FootTrajectory, u_from: float = 0.0, tolerance: float = 0.005
) -> bool:
    """Whether the rest of a swing, from fraction ``u_from`` of its length on, is still clear
    in ``grids`` (rebuilt after obstacles moved).

    Invalid when a remaining point lies in a cell covered by an avoided obstacle, or more than
    ``tolerance`` metres below the elevation map (something moved into the way or onto the
    footprint). Points in the foot's starting cell are not checked (the foot lifts off from
    there); points outside the window are not judged.
    """
    pts = traj.points
    sel = traj.arc >= u_from * traj.length - 1e-12
    sel[-1] = True
    p = pts[sel]
    rc = grids.cell_of(p[:, :2])
    ok = grids.inside(rc) & ~np.all(rc == grids.cell_of(pts[0, :2]), axis=1)
    r, c = rc[ok, 0], rc[ok, 1]
    if np.any(grids.avoid[r, c]):
        return False
    return bool(np.all(p[ok, 2] >= grids.elevation[r, c] - tolerance))


# ---------------------------------------------------------------------------------------
# One-shot convenience
# ---------------------------------------------------------------------------------------
def build_path(
    grids: WindowGrids,
    start: npt.ArrayLike,
    target_xy: npt.ArrayLike,
    params: PathParams | None = None,
    level: float | None = None,
    extra: BoolArray | None = None,
    half_width: float = 0.4,
    foot_half_extents: npt.ArrayLike | None = None,
    foot_yaw: float = 0.0,
) -> FootTrajectory | None:
    """The 3D trajectory from ``start`` ``(3,)`` to the cell under ``target_xy`` ``(2,)``.

    ``level``: height slice (walk around everything higher), None for no slice;
    ``half_width``: half width of the search rectangle in metres. Returns None when the target
    cannot be reached (or is forbidden). The target height is the highest surface under the
    foot there.
    """
    prm = params if params is not None else PathParams()
    half = grids.foot_half_extents if foot_half_extents is None else foot_half_extents
    st = np.asarray(start, dtype=np.float64).reshape(3)
    s_rc = grids.rowcol(st[:2])
    t_rc = np.rint(grids.rowcol(np.asarray(target_xy, dtype=np.float64).reshape(2)))
    region = search_region(grids.shape, s_rc, t_rc, half_width / grids.cell, 3.0)
    if region.mask.size == 0:
        return None
    ctx = PathContext(grids, st, region, extra, half, foot_yaw, prm)
    cell = (int(t_rc[0]) - region.r0, int(t_rc[1]) - region.c0)
    h, w = region.shape
    if not (0 <= cell[0] < h and 0 <= cell[1] < w):
        return None
    lvl = math.inf if level is None else float(level)
    path = ctx.path_2d(lvl, cell)
    if path is None:
        return None
    return ctx.lift(path, float(ctx.land_height(np.array([cell]))[0]))
