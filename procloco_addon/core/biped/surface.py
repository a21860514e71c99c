# SPDX-License-Identifier: GPL-3.0-or-later
"""Walkable surfaces: where a biped may put its feet (biped thesis §3.2–3.3).

The planner needs more than a height field: it must know *which* platform a point is on
(so that snapping never carries a footprint across a gap onto another platform), whether a
foot fits (a footprint near an edge hangs off it), and the closest walkable point to a
footprint that smoothing pushed off an edge. The thesis keeps the traversable surface as
polygons and snaps to the closest point on them; we keep it as triangles (any polygon mesh
triangulates, and Blender gives triangles directly) plus a fine raster built once:

* ``z`` — height of the highest walkable triangle over each raster cell (NaN where none);
* ``island`` — connected platforms: neighbouring cells whose heights differ by at most
  ``max_step`` belong to the same island, so a gap (or a wall) separates islands;
* ``inner`` — cells at least ``margin`` (about half a foot) inside their island, the cells a
  footprint centre may use whatever the foot's heading;
* ``terrace`` — flat or gently sloping pieces: neighbouring cells whose heights differ by at
  most ``ledge`` (a step's riser, a kerb, a crate's edge separate terraces; a slope does not).

A planted foot must be *supported*: its whole sole — a rectangle of the foot's length and
width along its heading, grown by half a cell's diagonal so that raster look-ups cannot miss
an edge — lies on one terrace (:meth:`WalkableSurface.supports`). That keeps a foot from
hanging over a step's edge or standing half inside the riser of the next step up. Snapping
with a heading (:meth:`WalkableSurface.snap`) moves a footprint to the nearest supported pose
on its island and terrace.

Point queries are raster look-ups (constant time, vectorised); heights of final footprints
come from the triangles themselves, exactly. Surfaces stacked above each other (a bridge
over a path) keep only the highest one, the same model as the terrain elevation map.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class WalkableSurface:
    """Triangles a biped may stand on, with a raster for fast queries.

    Build with :meth:`from_triangles` or :meth:`from_polygons`. ``triangles`` is
    ``(T, 3, 3)``; raster arrays are ``(nx, ny)`` over cells of ``cell`` metres whose corner
    ``(0, 0)`` is at ``origin``.
    """

    triangles: FloatArray
    cell: float
    origin: FloatArray
    z: FloatArray
    island: IntArray
    inner: BoolArray
    tri_id: IntArray
    margin: float
    max_step: float
    terrace: IntArray
    ledge: float
    foot_half_length: float
    foot_half_width: float

    # -- construction -------------------------------------------------------------------------

    @classmethod
    def from_triangles(
        cls,
        triangles: FloatArray,
        cell: float = 0.05,
        margin: float = 0.12,
        max_step: float = 0.2,
        blocked: FloatArray | None = None,
        bounds: tuple[float, float, float, float] | None = None,
        ledge: float | None = None,
        foot: tuple[float, float] | None = None,
    ) -> WalkableSurface:
        """Surface from ``(T, 3, 3)`` triangles (any winding; vertical ones are ignored).

        ``cell`` is the raster resolution, ``margin`` how far inside an edge a footprint
        centre must stay (about half a foot length), ``max_step`` the height difference
        between neighbouring cells above which they are not connected (a ledge or a wall).
        ``blocked (B, 3, 3)``: triangles of obstacles to keep off; the ground under them
        (seen from above) is not walkable. ``bounds (x0, y0, x1, y1)`` limits the raster to
        a region (a large ground plane need not be rasterised far from the character).
        ``ledge`` (default: one ``cell``, a 45° slope) is the height difference between
        neighbouring cells that separates terraces. ``foot (half_length, half_width)`` is the
        sole :meth:`supports` checks (default: ``margin`` long and ``0.45 margin`` wide halves;
        see :meth:`with_foot`).
        """
        tris = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
        if len(tris) == 0:
            raise ValueError("a walkable surface needs at least one triangle")
        if cell <= 0.0 or margin < 0.0 or max_step <= 0.0:
            raise ValueError("cell and max_step must be positive and margin non-negative")
        lo = tris[:, :, :2].min(axis=(0, 1)) - (margin + 2 * cell)
        hi = tris[:, :, :2].max(axis=(0, 1)) + (margin + 2 * cell)
        if bounds is not None:
            lo = np.maximum(lo, np.array(bounds[:2], dtype=float))
            hi = np.minimum(hi, np.array(bounds[2:], dtype=float))
            if np.any(hi <= lo):
                raise ValueError("no walkable triangle lies inside the bounds")
        nx, ny = (np.ceil((hi - lo) / cell).astype(int) + 1).tolist()
        z, tri_id = _rasterise(tris, lo, cell, nx, ny)
        if blocked is not None and len(blocked):
            bz, _ = _rasterise(np.asarray(blocked, dtype=float).reshape(-1, 3, 3), lo, cell, nx, ny)
            gone = np.isfinite(bz)
            z = np.where(gone, np.nan, z)
            tri_id = np.where(gone, -1, tri_id)
        island = _label_islands(z, max_step)
        # One cell of slack: an edge may lie anywhere inside its boundary cell.
        inner = _erode(island, margin + cell, cell)
        ledge = float(cell if ledge is None else ledge)
        if ledge <= 0.0:
            raise ValueError("ledge must be positive")
        terrace = _label_islands(z, ledge)
        half_length, half_width = (margin, 0.45 * margin) if foot is None else foot
        return cls(
            tris,
            float(cell),
            lo,
            z,
            island,
            inner,
            tri_id,
            float(margin),
            float(max_step),
            terrace,
            ledge,
            float(half_length),
            float(half_width),
        )

    def with_foot(self, half_length: float, half_width: float) -> WalkableSurface:
        """The same surface checking a sole of the given half length and half width (metres)."""
        if half_length <= 0.0 or half_width <= 0.0:
            raise ValueError("a foot needs a positive length and width")
        return dataclasses.replace(
            self, foot_half_length=float(half_length), foot_half_width=float(half_width)
        )

    @classmethod
    def from_polygons(cls, polygons: Sequence[FloatArray], **kwargs: Any) -> WalkableSurface:
        """Surface from convex polygons, each ``(k, 3)`` vertices in order (fan-triangulated)."""
        tris: list[FloatArray] = []
        for poly in polygons:
            p = np.asarray(poly, dtype=float)
            if p.ndim != 2 or p.shape[1] != 3 or len(p) < 3:
                raise ValueError("each polygon must be (k >= 3, 3) vertices")
            tris.extend(np.stack((p[0], p[i], p[i + 1])) for i in range(1, len(p) - 1))
        return cls.from_triangles(np.array(tris), **kwargs)

    # -- raster look-ups ----------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int]:
        return self.z.shape  # type: ignore[return-value]

    def cell_of(self, xy: FloatArray) -> tuple[IntArray, IntArray, BoolArray]:
        """Raster indices of points ``(..., 2+)`` and whether they fall inside the raster."""
        f = (np.asarray(xy)[..., :2] - self.origin) / self.cell
        f = np.where(np.isfinite(f), f, -1.0)
        ix = np.floor(f[..., 0]).astype(np.int64)
        iy = np.floor(f[..., 1]).astype(np.int64)
        nx, ny = self.z.shape
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        return np.clip(ix, 0, nx - 1), np.clip(iy, 0, ny - 1), ok

    def island_at(self, xy: FloatArray) -> IntArray:
        """Island of each point (``-1`` off every surface)."""
        ix, iy, ok = self.cell_of(xy)
        return np.where(ok, self.island[ix, iy], -1)

    def raster_height(self, xy: FloatArray) -> FloatArray:
        """Raster height of each point (cell-centre height; NaN off the surfaces)."""
        ix, iy, ok = self.cell_of(xy)
        return np.where(ok, self.z[ix, iy], np.nan)

    def fits(self, xy: FloatArray) -> BoolArray:
        """Whether a footprint centred at each point stays ``margin`` inside its platform."""
        ix, iy, ok = self.cell_of(xy)
        return ok & self.inner[ix, iy]

    def supported(self, xy: FloatArray) -> BoolArray:
        """Whether each point is over some walkable surface."""
        return self.island_at(xy) >= 0

    def terrace_at(self, xy: FloatArray) -> IntArray:
        """Terrace of each point (``-1`` off every surface)."""
        ix, iy, ok = self.cell_of(xy)
        return np.where(ok, self.terrace[ix, iy], -1)

    @functools.cached_property
    def sole_offsets(self) -> FloatArray:
        """Sample points ``(P, 2)`` of the sole in the foot's frame (x along the heading): its
        centre, then a grid at most a cell apart over the sole grown by half a cell's
        diagonal, so that every raster cell the sole touches is looked at."""
        pad = 0.5 * np.sqrt(2.0) * self.cell
        hl = self.foot_half_length + pad
        hw = self.foot_half_width + pad
        na = max(2, int(np.ceil(2.0 * hl / self.cell)) + 1)
        nw = max(2, int(np.ceil(2.0 * hw / self.cell)) + 1)
        gx, gy = np.meshgrid(np.linspace(-hl, hl, na), np.linspace(-hw, hw, nw), indexing="ij")
        return np.vstack(([0.0, 0.0], np.column_stack((gx.ravel(), gy.ravel()))))

    @functools.cached_property
    def _terrace_border(self) -> IntArray:
        """``terrace`` framed by one cell of ``-1`` and flattened: look-ups need no bounds test."""
        nx, ny = self.terrace.shape
        out = np.full((nx + 2, ny + 2), -1, dtype=np.int64)
        out[1:-1, 1:-1] = self.terrace
        return out.ravel()

    def supports(self, xy: FloatArray, yaw: FloatArray, terrace: IntArray | None = None) -> BoolArray:
        """Whether a foot planted at each point ``(..., 2+)`` with heading ``yaw (...)`` stands
        wholly on one terrace (``terrace (...)``: on that one)."""
        labels = self.sole_terraces(xy, yaw)
        centre = labels[..., 0]
        ok = (centre >= 0) & np.all(labels == centre[..., None], axis=-1)
        if terrace is not None:
            ok &= centre == np.asarray(terrace)
        return np.asarray(ok)

    def straddles_step(self, xy: FloatArray, yaw: FloatArray) -> BoolArray:
        """Whether the sole of a foot at each pose covers two walkable terraces (it is planted
        across a step's edge), as opposed to hanging off a platform's edge or being whole."""
        labels = self.sole_terraces(xy, yaw)
        first = np.max(labels, axis=-1)
        return np.asarray(np.any((labels >= 0) & (labels != first[..., None]), axis=-1))

    def sole_terraces(self, xy: FloatArray, yaw: FloatArray) -> IntArray:
        """Terraces ``(..., P)`` under the sole samples (:attr:`sole_offsets`, the centre first)
        of a foot at each pose ``xy (..., 2+)``, ``yaw (...)``; ``-1`` off the surfaces."""
        xy = np.asarray(xy, dtype=float)[..., :2]
        yaw = np.broadcast_to(np.asarray(yaw, dtype=float), xy.shape[:-1])
        off = self.sole_offsets
        c, s = np.cos(yaw)[..., None], np.sin(yaw)[..., None]
        # Sample 0 is the centre; the others must be on its terrace.
        fx = (xy[..., 0, None] + c * off[:, 0] - s * off[:, 1] - self.origin[0]) / self.cell
        fy = (xy[..., 1, None] + s * off[:, 0] + c * off[:, 1] - self.origin[1]) / self.cell
        nx, ny = self.terrace.shape
        ix = np.clip(np.floor(fx).astype(np.int64) + 1, 0, nx + 1)
        iy = np.clip(np.floor(fy).astype(np.int64) + 1, 0, ny + 1)
        return np.asarray(self._terrace_border[ix * (ny + 2) + iy])

    @functools.cached_property
    def _inner_cells(self) -> dict[int, FloatArray]:
        """Centres of the cells a footprint fits in, per island (``-1``: all of them)."""
        idx = np.argwhere(self.inner)
        isl = self.island[idx[:, 0], idx[:, 1]]
        centres = self.origin + (idx + 0.5) * self.cell
        out = {int(k): centres[isl == k] for k in np.unique(isl)}
        out[-1] = centres
        return out

    # -- exact geometry -----------------------------------------------------------------------

    def height_at(self, xy: FloatArray) -> FloatArray:
        """Exact height of the walkable triangle under each point (NaN where none).

        The triangle is the one the raster found highest in the point's cell, or a
        neighbour of it when the point is right at a triangle edge.
        """
        xy = np.asarray(xy, dtype=float)[..., :2]
        shape = xy.shape[:-1]
        pts = xy.reshape(-1, 2)
        ix, iy, ok = self.cell_of(pts)
        out = np.full(len(pts), np.nan)
        nx, ny = self.z.shape
        best = np.full(len(pts), np.inf)
        todo = np.flatnonzero(ok)
        for dx, dy in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1), (1, -1), (-1, 1)):
            jx = np.clip(ix[todo] + dx, 0, nx - 1)
            jy = np.clip(iy[todo] + dy, 0, ny - 1)
            tid = self.tri_id[jx, jy]
            has = tid >= 0
            tri = self.triangles[np.maximum(tid, 0)]
            w = _barycentric(pts[todo], tri)
            # Distance outside the triangle in barycentric units; 0 inside.
            outside = np.maximum(-w.min(axis=-1), 0.0)
            zt = np.sum(w * tri[:, :, 2], axis=-1)
            better = has & (outside < best[todo] - 1e-12)
            out[todo[better]] = zt[better]
            best[todo[better]] = outside[better]
            # Points inside their triangle are done; the others look at the next neighbour.
            todo = todo[best[todo] > 0.0]
            if len(todo) == 0:
                break
        out = np.where(best <= 0.5, out, np.nan)
        return out.reshape(shape)

    def snap(
        self,
        points: FloatArray,
        island: IntArray | None = None,
        exact: bool = True,
        yaw: FloatArray | None = None,
        terrace: IntArray | None = None,
    ) -> FloatArray:
        """Closest footprint position to each point, on its island, ``margin`` inside edges.

        ``points`` is ``(N, 3)``; ``island`` ``(N,)`` says which platform each point must stay
        on (``None``: the one under it, or the nearest). A point that already fits keeps its
        ``x, y`` and gets the exact surface height; any other moves to the nearest fitting
        raster cell of its island (thesis §3.3: "snap to the closest point on the surface").
        ``exact=False`` takes heights from the raster (exact on flat ground, cheaper), for
        the inner iterations of smoothing and refinement.

        With the feet's headings ``yaw (N,)`` a footprint fits when its sole is supported
        (:meth:`supports`), on its ``terrace (N,)`` when given, and moves to the nearest
        supported position otherwise (within about a foot's length; farther, to the nearest
        fitting cell as above, then to a supported position near it).
        """
        pts = np.array(points, dtype=float).reshape(-1, 3)
        if island is None:
            island = self.island_at(pts)
        island = np.asarray(island, dtype=np.int64).reshape(-1)
        ix, iy, ok = self.cell_of(pts)
        if yaw is None:
            fits = ok & self.inner[ix, iy] & (self.island[ix, iy] == island)
        else:
            yaw = np.broadcast_to(np.asarray(yaw, dtype=float), island.shape)
            if terrace is not None:
                terrace = np.broadcast_to(np.asarray(terrace, dtype=np.int64), island.shape)
            fits = ok & (self.island[ix, iy] == island) & self.supports(pts[:, :2], yaw, terrace)
        need = np.flatnonzero(~fits)
        if len(need) and yaw is not None:
            found = self._nearest_support(pts[need, :2], yaw[need], island[need], terrace, need)
            moved = np.isfinite(found[:, 0])
            pts[need[moved], :2] = found[moved]
            need = need[~moved]
        if len(need):
            cells = self._inner_cells
            for i in need:
                centres = cells.get(int(island[i]))
                if centres is None:
                    centres = cells[-1]
                d2 = np.sum((centres - pts[i, :2]) ** 2, axis=1)
                pts[i, :2] = centres[int(np.argmin(d2))]
            if yaw is not None:
                found = self._nearest_support(pts[need, :2], yaw[need], island[need], terrace, need)
                moved = np.isfinite(found[:, 0])
                pts[need[moved], :2] = found[moved]
        raster = self.raster_height(pts[:, :2])
        z = self.height_at(pts[:, :2]) if exact else raster
        pts[:, 2] = np.where(np.isfinite(z), z, raster)
        return pts

    def _nearest_support(
        self,
        xy: FloatArray,
        yaw: FloatArray,
        island: IntArray,
        terrace: IntArray | None,
        rows: IntArray,
    ) -> FloatArray:
        """Nearest supported position ``(M, 2)`` to each point within about a foot's length
        (NaN where there is none): a coarse search one cell apart, then a fine one a quarter
        cell apart around the best coarse candidate."""
        cell = self.cell
        radius = 2.0 * self.foot_half_length + 2.0 * cell
        k = int(np.ceil(radius / cell))
        g = np.arange(-k, k + 1) * cell
        gx, gy = np.meshgrid(g, g, indexing="ij")
        coarse = np.column_stack((gx.ravel(), gy.ravel()))
        coarse = coarse[np.sum(coarse**2, axis=1) <= radius**2 + 1e-12]
        coarse = coarse[np.argsort(np.sum(coarse**2, axis=1), kind="stable")]
        f = np.arange(-4, 5) * (0.25 * cell)
        fx, fy = np.meshgrid(f, f, indexing="ij")
        fine = np.column_stack((fx.ravel(), fy.ravel()))
        ter = None if terrace is None else terrace[rows]
        out = np.full((len(xy), 2), np.nan)

        def good(cand: FloatArray) -> BoolArray:  # (M, K, 2) -> (M, K)
            ok = self.supports(cand, yaw[:, None], None if ter is None else ter[:, None])
            return ok & (self.island_at(cand) == island[:, None])

        cand = xy[:, None, :] + coarse[None]
        hit = good(cand)
        has = hit.any(axis=1)
        if not np.any(has):
            return out
        first = np.argmax(hit, axis=1)
        best = cand[np.arange(len(xy)), first]
        cand = best[:, None, :] + fine[None]
        hit = good(cand) & has[:, None]
        d2 = np.where(hit, np.sum((cand - xy[:, None, :]) ** 2, axis=2), np.inf)
        j = np.argmin(d2, axis=1)
        fine_best = cand[np.arange(len(xy)), j]
        pick = np.where(np.isfinite(d2[np.arange(len(xy)), j])[:, None], fine_best, best)
        out[has] = pick[has]
        return out


# ---------------------------------------------------------------------------------------------
# helpers


def rectangle(center: Sequence[float], size: Sequence[float], yaw: float = 0.0) -> FloatArray:
    """A horizontal rectangle polygon ``(4, 3)``: centre ``(x, y, z)``, size ``(length, width)``."""
    cx, cy, cz = center
    hx, hy = 0.5 * size[0], 0.5 * size[1]
    c, s = np.cos(yaw), np.sin(yaw)
    corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    xy = corners @ np.array([[c, s], [-s, c]])
    return np.column_stack((xy[:, 0] + cx, xy[:, 1] + cy, np.full(4, cz)))


def arc_band(
    center: Sequence[float], r_inner: float, r_outer: float, a0: float, a1: float, n: int = 24
) -> list[FloatArray]:
    """A curved walkway: the ring sector between two radii and angles, as ``n`` quads."""
    cx, cy, cz = center
    a = np.linspace(a0, a1, n + 1)
    quads = []
    for i in range(n):
        pts = [(r_inner, a[i]), (r_outer, a[i]), (r_outer, a[i + 1]), (r_inner, a[i + 1])]
        quads.append(np.array([[cx + r * np.cos(t), cy + r * np.sin(t), cz] for r, t in pts]))
    return quads


def _barycentric(p: FloatArray, tri: FloatArray) -> FloatArray:
    """Barycentric coordinates ``(N, 3)`` of points ``(N, 2)`` in triangles ``(N, 3, 3)`` (xy)."""
    a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
    v0, v1, v2 = b - a, c - a, p - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    den = np.where(np.abs(den) < 1e-18, np.nan, den)
    w1 = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
    w2 = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    w = np.stack((1.0 - w1 - w2, w1, w2), axis=-1)
    return np.where(np.isfinite(w), w, -np.inf)


def _rasterise(
    tris: FloatArray, origin: FloatArray, cell: float, nx: int, ny: int
) -> tuple[FloatArray, IntArray]:
    """Highest triangle over each cell centre: heights ``(nx, ny)`` and triangle ids."""
    z = np.full(nx * ny, -np.inf)
    lo = np.floor((tris[:, :, :2].min(axis=1) - origin) / cell - 0.5).astype(int)
    hi = np.ceil((tris[:, :, :2].max(axis=1) - origin) / cell - 0.5).astype(int)
    lo = np.clip(lo, 0, [nx - 1, ny - 1])
    hi = np.clip(hi, 0, [nx - 1, ny - 1])
    span = hi - lo + 1
    cells: list[IntArray] = []
    heights: list[FloatArray] = []
    tids: list[IntArray] = []

    def emit(t_idx: IntArray, cx: IntArray, cy: IntArray) -> None:
        centre = origin + (np.stack((cx, cy), axis=-1) + 0.5) * cell
        w = _barycentric(centre, tris[t_idx])
        inside = np.all(w >= -1e-9, axis=-1)
        # Triangles seen edge-on from above (a crate's side) have no barycentric coordinates
        # (-inf): they cover no cell centre, and must not enter the products as -inf * 0.
        zc = np.sum(np.where(inside[:, None], w, 0.0) * tris[t_idx, :, 2], axis=-1)
        cells.append((cx * ny + cy)[inside])
        heights.append(zc[inside])
        tids.append(t_idx[inside])

    small = np.all(span <= 16, axis=1)
    idx_small = np.flatnonzero(small)
    if len(idx_small):
        ox, oy = np.meshgrid(np.arange(16), np.arange(16), indexing="ij")
        ox, oy = ox.ravel(), oy.ravel()
        for chunk in np.array_split(idx_small, max(1, len(idx_small) // 4096)):
            cx = lo[chunk, 0, None] + ox
            cy = lo[chunk, 1, None] + oy
            keep = (cx <= hi[chunk, 0, None]) & (cy <= hi[chunk, 1, None])
            t_idx = np.broadcast_to(chunk[:, None], cx.shape)[keep]
            emit(t_idx, cx[keep], cy[keep])
    for t in np.flatnonzero(~small):
        gx, gy = np.meshgrid(
            np.arange(lo[t, 0], hi[t, 0] + 1), np.arange(lo[t, 1], hi[t, 1] + 1), indexing="ij"
        )
        emit(np.full(gx.size, t), gx.ravel(), gy.ravel())
    flat_cells = np.concatenate(cells) if cells else np.zeros(0, np.int64)
    flat_z = np.concatenate(heights) if heights else np.zeros(0)
    flat_t = np.concatenate(tids) if tids else np.zeros(0, np.int64)
    np.maximum.at(z, flat_cells, flat_z)
    tri_id = np.full(nx * ny, -1, dtype=np.int64)
    top = flat_z >= z[flat_cells]
    tri_id[flat_cells[top]] = flat_t[top]
    z = np.where(np.isfinite(z), z, np.nan)
    return z.reshape(nx, ny), tri_id.reshape(nx, ny)


def _label_islands(z: FloatArray, max_step: float) -> IntArray:
    """Connected components of supported cells (4-neighbours, height step ≤ ``max_step``)."""
    nx, ny = z.shape
    ok = np.isfinite(z).ravel()
    flat_z = z.ravel()
    idx = np.arange(nx * ny).reshape(nx, ny)
    edges = []
    for a, b in ((idx[:-1, :], idx[1:, :]), (idx[:, :-1], idx[:, 1:])):
        a, b = a.ravel(), b.ravel()
        keep = ok[a] & ok[b] & (np.abs(flat_z[a] - flat_z[b]) <= max_step)
        edges.append((a[keep], b[keep]))
    ea = np.concatenate([e[0] for e in edges])
    eb = np.concatenate([e[1] for e in edges])
    parent = np.arange(nx * ny)
    # Hooking + pointer jumping: converges in a few dozen vectorised rounds.
    while True:
        pa, pb = parent[ea], parent[eb]
        lo, hi = np.minimum(pa, pb), np.maximum(pa, pb)
        changed = lo != hi
        if not np.any(changed):
            break
        np.minimum.at(parent, hi[changed], lo[changed])
        while True:
            nxt = parent[parent]
            if np.array_equal(nxt, parent):
                break
            parent = nxt
    roots = np.where(ok, parent, -1)
    _, labels = np.unique(roots[ok], return_inverse=True)
    out = np.full(nx * ny, -1, dtype=np.int64)
    out[ok] = labels
    return out.reshape(nx, ny)


def _erode(island: IntArray, margin: float, cell: float) -> BoolArray:
    """Cells whose whole disc of radius ``margin`` lies on their own island."""
    r = int(np.ceil(margin / cell - 1e-9))
    inner = island >= 0
    if r == 0:
        return inner
    nx, ny = island.shape
    pad = np.full((nx + 2 * r, ny + 2 * r), -2, dtype=np.int64)
    pad[r : r + nx, r : r + ny] = island
    for dx in range(-r, r + 1):
        for dy in range(-r, r + 1):
            if dx * dx + dy * dy > (margin / cell) ** 2 + 1e-9:
                continue
            inner &= pad[r + dx : r + dx + nx, r + dy : r + dy + ny] == island
    return inner
