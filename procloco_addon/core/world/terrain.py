# SPDX-License-Identifier: GPL-3.0-or-later
"""The environment and the per-character window grids (thesis §3.4.1).

An :class:`Environment` holds what feet can stand on or must avoid:

- a :class:`Heightmap` (the terrain),
- :class:`Boxes` (crates: oriented boxes, static or moving, each with a role),
- :class:`TriangleSoup` meshes (how Blender meshes arrive), each with a role.

Roles: :data:`ROLE_GROUND` and :data:`ROLE_STEP_OVER` are surfaces feet may stand on or pass
over; :data:`ROLE_AVOID` obstacles are never stepped on nor over (their cells are forbidden).

For planning, the environment near a character is turned into two grids (thesis §3.4.1), the
:class:`WindowGrids` returned by :meth:`Environment.window` (default 70 × 70 cells of 7 cm):

- the *elevations map*: the highest surface in each cell (terrain and every obstacle, the
  whole cell area counts, so it is conservative for clearance);
- the *obstacles' map*: cells covered by avoided obstacles, enlarged by the foot's shape
  (thesis Figure 3.18). Cells forbidden only because of that enlargement ("dilation") are kept
  apart, since they are not valid footprints but are not inside an obstacle either.

Windows are cut from a fixed world lattice (cell ``(i, j)`` is centred at ``(j, i) * cell``),
so static content is rasterised once and cached in world tiles (each cell computed from its
tile's origin); a tile is filled block by block, only the blocks some window covers, and the
new blocks of a whole step (every window, every cell size) are rasterised in one batch, the
triangles of each static mesh found through a rectangle index; moving boxes and meshes are
rasterised on demand, only when a window overlaps them, and that raster is reused until they
move again (thesis: "we compute the map's representation of dynamic objects when they move near
the multi-legged character"). :meth:`Environment.windows` cuts the windows of a whole step at
once (one :class:`WindowParams` per window if their foot shapes differ): the moving boxes near
any of them are rasterised in one batch (thesis Table 3.1: the maps are prepared "for all
characters at the same time").

Point queries (:meth:`Environment.height_at`, :meth:`Environment.forbidden_at`) use bucket
indices of the boxes; asking both for the same points (as the controller does) finds the boxes
once.

Coordinates: world metres, Z up. Grid arrays are indexed ``[row, col]`` = ``[y, x]``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]

ROLE_GROUND = 0
ROLE_STEP_OVER = 1
ROLE_AVOID = 2

#: Elevation of cells with no surface at all (a gap, or outside every mesh). Trajectories may
#: pass over such cells but feet never land there.
NO_SURFACE = -1.0e4
_VOID_BELOW = NO_SURFACE * 0.5
#: Side of the point-query buckets of triangles, a share of a typical triangle's: a point's
#: candidates are about 2 (1 + share)^2 triangles of a triangulated grid (4.5 instead of 8 at
#: share 1; each triangle is in about (1 + 1 / share)^2 buckets). The 2 M points a 100-wolf
#: Generate asks of its ground: 0.87 -> 0.49 CPU s, the index built in the same time.
TRIANGLE_BUCKET = 0.5


# ---------------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Heightmap:
    """A regular grid of terrain heights.

    ``heights``: ``(ny, nx)``, row index is y and column index is x; ``origin``: ``(2,)``
    world xy of cell ``[0, 0]``'s centre; ``cell``: spacing in metres. Heights are bilinearly
    interpolated between samples; outside the sampled rectangle there is no terrain.
    """

    heights: FloatArray
    origin: FloatArray
    cell: float

    def __post_init__(self) -> None:
        h = np.asarray(self.heights, dtype=np.float64)
        if h.ndim != 2 or min(h.shape) < 2:
            raise ValueError(f"heights must be (ny >= 2, nx >= 2), got {h.shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError("heights must be finite")
        if not self.cell > 0.0:
            raise ValueError("cell must be positive")
        object.__setattr__(self, "heights", h)
        object.__setattr__(self, "origin", np.asarray(self.origin, dtype=np.float64).reshape(2))

    @property
    def extent(self) -> tuple[FloatArray, FloatArray]:
        """World xy of the sampled rectangle's min and max corners."""
        ny, nx = self.heights.shape
        return self.origin.copy(), self.origin + np.array([nx - 1, ny - 1]) * self.cell

    def sample(self, xy: npt.ArrayLike) -> FloatArray:
        """Bilinear heights at ``xy`` ``(..., 2)``; :data:`NO_SURFACE` outside: ``(...,)``."""
        p = np.asarray(xy, dtype=np.float64)
        ny, nx = self.heights.shape
        fx = (p[..., 0] - self.origin[0]) / self.cell
        fy = (p[..., 1] - self.origin[1]) / self.cell
        tol = 1e-9
        inside = (fx >= -tol) & (fx <= nx - 1 + tol) & (fy >= -tol) & (fy <= ny - 1 + tol)
        # np.clip as maximum/minimum (the same values, fewer calls); the four corners read
        # from the flat grid by one index (crowd queries run to thousands of points)
        fx = np.minimum(np.maximum(fx, 0.0), nx - 1.0)
        fy = np.minimum(np.maximum(fy, 0.0), ny - 1.0)
        x0 = np.minimum(fx.astype(np.intp), nx - 2)  # fx >= 0: truncation is the floor
        y0 = np.minimum(fy.astype(np.intp), ny - 2)
        tx = fx - x0
        ty = fy - y0
        flat = self.heights.reshape(-1)
        at = y0 * nx + x0
        sx = 1.0 - tx
        top = flat.take(at) * sx + flat.take(at + 1) * tx
        at += nx
        bottom = flat.take(at) * sx + flat.take(at + 1) * tx
        return np.where(inside, top * (1.0 - ty) + bottom * ty, NO_SURFACE)


@dataclass(frozen=True)
class Boxes:
    """Oriented boxes standing upright (crates).

    ``center``: ``(n, 3)`` world position of each box's bottom-face centre; ``size``:
    ``(n, 3)`` full extents (x, y in the box's own frame, then height); ``yaw``: ``(n,)``
    rotation about +Z in radians; ``role``: ``(n,)`` int (``ROLE_*``); ``dynamic``: ``(n,)``
    bool, True for boxes that may move (:meth:`Environment.move_boxes`).
    """

    center: FloatArray
    size: FloatArray
    yaw: FloatArray
    role: npt.NDArray[np.int_]
    dynamic: BoolArray

    def __post_init__(self) -> None:
        c = np.asarray(self.center, dtype=np.float64).reshape(-1, 3)
        n = c.shape[0]
        s = np.asarray(self.size, dtype=np.float64).reshape(n, 3)
        yaw = np.asarray(self.yaw, dtype=np.float64).reshape(n)
        role = np.asarray(self.role, dtype=np.int_).reshape(n)
        dyn = np.asarray(self.dynamic, dtype=bool).reshape(n)
        if np.any(s < 0.0) or not np.all(np.isfinite(c)) or not np.all(np.isfinite(s)):
            raise ValueError("box sizes must be finite and non-negative")
        if np.any((role < ROLE_GROUND) | (role > ROLE_AVOID)):
            raise ValueError("unknown box role")
        for name, value in (("center", c), ("size", s), ("yaw", yaw), ("role", role), ("dynamic", dyn)):
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return int(self.center.shape[0])


@dataclass(frozen=True)
class TriangleSoup:
    """A triangle mesh in world space: ``vertices`` ``(v, 3)``, ``faces`` ``(f, 3)`` int."""

    vertices: FloatArray
    faces: npt.NDArray[np.int_]
    role: int = ROLE_GROUND
    dynamic: bool = False

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(self.faces, dtype=np.int_).reshape(-1, 3)
        if f.size and (f.min() < 0 or f.max() >= v.shape[0]):
            raise ValueError("face indices out of range")
        if not np.all(np.isfinite(v)):
            raise ValueError("vertices must be finite")
        if self.role not in (ROLE_GROUND, ROLE_STEP_OVER, ROLE_AVOID):
            raise ValueError("unknown soup role")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)


@dataclass(frozen=True)
class WindowParams:
    """How to cut a character's window: ``n_cells`` per side, ``cell`` size in metres, and
    the foot's ground shape (``foot_half_extents`` along the foot's forward and left axes,
    ``foot_yaw``) used for the default obstacle dilation of :class:`WindowGrids`."""

    n_cells: int = 70
    cell: float = 0.07
    foot_half_extents: tuple[float, float] = (0.03, 0.03)
    foot_yaw: float = 0.0

    def __post_init__(self) -> None:
        if self.n_cells < 3 or not self.cell > 0.0:
            raise ValueError("a window needs n_cells >= 3 and a positive cell size")


# ---------------------------------------------------------------------------------------
# Kernels and grid helpers
# ---------------------------------------------------------------------------------------
def foot_kernel(
    cell: float, half_extents: npt.ArrayLike, yaw: float = 0.0, anywhere_in_cell: bool = True
) -> IntArray:
    """Cell offsets ``(k, 2)`` (rows, cols) covered by a foot box centred in cell ``(0, 0)``.

    With ``anywhere_in_cell`` the foot centre may be anywhere inside its cell (the box is grown
    by half a cell): dilating forbidden cells by this kernel makes every cell left free safe for
    a foot whose centre is anywhere in it (thesis Figure 3.18). Without it the foot sits at the
    cell centre (what a landing foot covers). Always contains ``(0, 0)``.
    """
    hx, hy = (float(v) for v in np.asarray(half_extents, dtype=np.float64).reshape(2))
    return _foot_kernel(float(cell), hx, hy, float(yaw), bool(anywhere_in_cell))


@functools.lru_cache(maxsize=512)
def _foot_kernel(cell: float, hx: float, hy: float, yaw: float, anywhere_in_cell: bool) -> IntArray:
    if anywhere_in_cell:
        grow = 0.5 * cell * (abs(math.cos(yaw)) + abs(math.sin(yaw)))
        hx, hy = hx + grow, hy + grow
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    ex = c * hx + s * hy
    ey = s * hx + c * hy
    rx = math.ceil(ex / cell + 0.5)
    ry = math.ceil(ey / cell + 0.5)
    jj, ii = np.meshgrid(np.arange(-rx, rx + 1), np.arange(-ry, ry + 1))
    centres = np.stack([jj.ravel() * cell, ii.ravel() * cell], axis=1)
    hit = _box_overlaps_cells(centres, cell, np.zeros(2), hx, hy, yaw)
    off = np.stack([ii.ravel()[hit], jj.ravel()[hit]], axis=1).astype(np.intp)
    if not np.any((off[:, 0] == 0) & (off[:, 1] == 0)):
        off = np.vstack([off, np.zeros((1, 2), dtype=np.intp)])
    off.setflags(write=False)  # shared by the cache
    return off


def foot_kernels(
    cell: FloatArray, half_x: FloatArray, half_y: FloatArray, yaw: FloatArray, anywhere_in_cell: bool = True
) -> tuple[IntArray, BoolArray]:
    """:func:`foot_kernel` of ``n`` feet at once (``(n,)`` cell sizes, half extents and yaws).

    Returns ``(offsets, member)``: ``offsets`` ``(m, 2)`` the cells of a rectangle holding every
    kernel, ``member`` ``(n, m)``; ``offsets[member[i]]`` are exactly the cells of foot ``i``'s
    kernel (the same tests with the same arithmetic, in another order)."""
    cos = np.cos(yaw)
    sin = np.sin(yaw)
    c = np.abs(cos)
    s = np.abs(sin)
    if anywhere_in_cell:
        grow = 0.5 * cell * (c + s)
        half_x = half_x + grow
        half_y = half_y + grow
    ex = c * half_x + s * half_y
    ey = s * half_x + c * half_y
    rx = int(np.maximum.reduce(np.ceil(ex / cell + 0.5), axis=None, initial=0))
    ry = int(np.maximum.reduce(np.ceil(ey / cell + 0.5), axis=None, initial=0))
    offsets = _rect_offsets(ry, rx)
    col = cell[:, None]
    # the cell centres from the foot's centre (0, 0), x and y apart
    member = _overlaps(offsets[None, :, 1] * col, offsets[None, :, 0] * col, col, half_x[:, None],
                       half_y[:, None], cos[:, None], sin[:, None])
    member[:, (2 * rx + 1) * ry + rx] = True  # (0, 0) always
    return offsets, member


@functools.lru_cache(maxsize=64)
def _rect_offsets(ry: int, rx: int) -> IntArray:
    """Cells ``(i, j)`` with ``|i| <= ry``, ``|j| <= rx``, row-major: ``((2ry+1)(2rx+1), 2)``."""
    ii, jj = np.meshgrid(np.arange(-ry, ry + 1), np.arange(-rx, rx + 1), indexing="ij")
    off = np.stack([ii.ravel(), jj.ravel()], axis=1).astype(np.intp)
    off.setflags(write=False)
    return off


def _box_overlaps_cells(
    cell_xy: FloatArray, cell: float | FloatArray, box_xy: FloatArray, hx: float | FloatArray,
    hy: float | FloatArray, yaw: float | FloatArray, cos_sin: tuple[FloatArray, FloatArray] | None = None,
) -> BoolArray:
    """Separating-axis test: does each axis-aligned cell square overlap its oriented box?
    ``cos_sin``: ``cos(yaw)``, ``sin(yaw)`` when the caller has them already."""
    cos, sin = (np.cos(yaw), np.sin(yaw)) if cos_sin is None else cos_sin
    d = cell_xy - box_xy
    return _overlaps(d[..., 0], d[..., 1], cell, hx, hy, cos, sin)


def _overlaps(
    dx: FloatArray, dy: FloatArray, cell: float | FloatArray, hx: float | FloatArray, hy: float | FloatArray,
    cos: float | FloatArray, sin: float | FloatArray,
) -> BoolArray:
    """:func:`_box_overlaps_cells` of cells at ``(dx, dy)`` from their boxes' centres (the
    coordinates apart, so that every operation runs along the cells)."""
    half = 0.5 * cell
    acos = np.abs(cos)
    asin = np.abs(sin)
    eps = 1e-9
    ok_x = np.abs(dx) < hx * acos + hy * asin + half - eps
    ok_y = np.abs(dy) < hx * asin + hy * acos + half - eps
    du = dx * cos + dy * sin
    dv = -dx * sin + dy * cos
    ok_u = np.abs(du) < hx + half * (acos + asin) - eps
    ok_v = np.abs(dv) < hy + half * (asin + acos) - eps
    return np.asarray(ok_x & ok_y & ok_u & ok_v)


def dilate(mask: BoolArray, offsets: IntArray) -> BoolArray:
    """Binary dilation of ``mask`` ``(..., h, w)`` by the cell ``offsets`` ``(k, 2)`` (every
    leading index is dilated on its own).

    The grids are laid out flat, each inside a border of False cells as wide as the kernel
    reaches, one after the other: a shift by ``(di, dj)`` is then one contiguous slice of
    the flat array (``di`` rows of the bordered width plus ``dj``), never reaching another
    grid. A kernel that fills its bounding rectangle is applied as a row pass then a column
    pass (``(a - 1) + (b - 1)`` shifted ORs instead of ``a * b - 1``)."""
    h, w = mask.shape[-2:]
    lead = mask.shape[:-2]
    r_lo, c_lo = (int(v) for v in np.minimum.reduce(offsets, axis=0))
    r_hi, c_hi = (int(v) for v in np.maximum.reduce(offsets, axis=0))
    rr = max(-r_lo, r_hi, 0)
    cc = max(-c_lo, c_hi, 0)
    w2 = w + 2 * cc
    pad = np.zeros((*lead, h + 2 * rr, w2), dtype=bool)
    pad[..., rr : rr + h, cc : cc + w] = mask
    src = pad.reshape(-1)
    if offsets.shape[0] == (r_hi - r_lo + 1) * (c_hi - c_lo + 1) and offsets.shape[0] > 4:
        rows = _shifted_or(src, [di * w2 for di in range(r_lo, r_hi + 1)])
        out = _shifted_or(rows, list(range(c_lo, c_hi + 1)))
    else:
        out = _shifted_or(src, [di * w2 + dj for di, dj in offsets.tolist()])
    return out.reshape(pad.shape)[..., rr : rr + h, cc : cc + w]


def _shifted_or(flat: BoolArray, shifts: Sequence[int]) -> BoolArray:
    """``flat`` OR-ed with itself moved forward by each of ``shifts`` (``out[i] |= flat[i -
    s]``; what would come from before the start or past the end is False)."""
    out = flat.copy()
    n = flat.size
    for s in shifts:
        if s > 0:
            out[s:] |= flat[: n - s]
        elif s < 0:
            out[: n + s] |= flat[-s:]
    return out


def dilate_each(mask: BoolArray, offsets: IntArray, member: BoolArray) -> BoolArray:
    """:func:`dilate` of every ``mask[i]`` ``(n, h, w)`` by its own kernel ``offsets[member[i]]``
    (``offsets`` ``(m, 2)``, ``member`` ``(n, m)``, as :func:`foot_kernels` gives them); masks
    that share a kernel are dilated together."""
    groups: dict[bytes, list[int]] = {}
    for i, row in enumerate(member):
        groups.setdefault(row.tobytes(), []).append(i)
    if len(groups) == 1:
        return dilate(mask, offsets[member[0]])
    out = np.empty_like(mask)
    for idx in groups.values():
        sel = np.asarray(idx, dtype=np.intp)
        out[sel] = dilate(mask[sel], offsets[member[idx[0]]])
    return out


def max_filter(values: FloatArray, offsets: IntArray) -> FloatArray:
    """Maximum of ``values`` ``(h, w)`` over the cell ``offsets`` ``(k, 2)`` around each cell."""
    out = values.copy()
    h, w = values.shape
    for di, dj in offsets.tolist():
        if (di == 0 and dj == 0) or abs(di) >= h or abs(dj) >= w:
            continue
        src = values[max(0, -di) : h - max(0, di), max(0, -dj) : w - max(0, dj)]
        dst = out[max(0, di) : h - max(0, -di), max(0, dj) : w - max(0, -dj)]
        np.maximum(dst, src, out=dst)
    return out


def _ranges_to_pairs(lo: IntArray, hi: IntArray) -> tuple[IntArray, IntArray]:
    """For items with inclusive integer ranges ``[lo, hi]`` return (item, value) pairs."""
    counts = np.maximum(hi - lo + 1, 0)
    total = int(np.add.reduce(counts))
    item = np.arange(lo.shape[0], dtype=np.intp).repeat(counts)
    # value = position in the run - run start + lo, with the two shifts repeated as one
    shift = counts.cumsum() - counts - lo
    value = np.arange(total, dtype=np.intp) - shift[item]
    return item, value


def raster_boxes(
    origin: FloatArray, cell: float | FloatArray, shape: tuple[int, int] | tuple[IntArray, IntArray],
    center_xy: FloatArray, half_x: FloatArray, half_y: FloatArray, yaw: FloatArray,
    first: tuple[int, int] | tuple[IntArray, IntArray] = (0, 0),
) -> tuple[IntArray, IntArray, IntArray]:
    """Cells of a grid overlapped by oriented rectangles.

    The grid has cell ``[0, 0]`` centred at ``origin`` ``(2,)``; rectangles have centres
    ``(n, 2)``, half extents ``(n,)`` and yaw ``(n,)``. Returns ``(box, row, col)`` index
    arrays of every overlapping (rectangle, cell) pair, rectangle by rectangle (``box`` does
    not decrease), vectorised over all rectangles. Only
    the grid's rows ``first[0]`` up to ``shape[0]`` and columns ``first[1]`` up to
    ``shape[1]`` are looked at.

    Each rectangle may have its own grid: ``origin`` ``(n, 2)``, ``cell`` ``(n,)`` and
    ``shape`` and ``first`` pairs of ``(n,)`` arrays (the same arithmetic per rectangle as
    with one grid).
    """
    n = center_xy.shape[0]
    if n == 0:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty, empty
    org = np.asarray(origin, dtype=np.float64)
    per_box = org.ndim == 2
    ny = np.asarray(shape[0])
    nx = np.asarray(shape[1])
    cos = np.cos(yaw)
    sin = np.sin(yaw)
    acos = np.abs(cos)
    asin = np.abs(sin)
    ex = half_x * acos + half_y * asin
    ey = half_x * asin + half_y * acos
    fx = (center_xy[:, 0] - org[..., 0]) / cell
    fy = (center_xy[:, 1] - org[..., 1]) / cell
    j0 = np.maximum(np.floor(fx - ex / cell - 0.5).astype(np.intp), first[1])
    j1 = np.minimum(np.ceil(fx + ex / cell + 0.5).astype(np.intp), nx - 1)
    i0 = np.maximum(np.floor(fy - ey / cell - 0.5).astype(np.intp), first[0])
    i1 = np.minimum(np.ceil(fy + ey / cell + 0.5).astype(np.intp), ny - 1)
    wcols = np.maximum(j1 - j0 + 1, 0)
    hrows = np.maximum(i1 - i0 + 1, 0)
    counts = wcols * hrows
    box = np.arange(n, dtype=np.intp).repeat(counts)
    if box.size == 0:
        return box, box.copy(), box.copy()
    start = counts.cumsum() - counts
    local = np.arange(box.size, dtype=np.intp) - start[box]
    down, across = np.divmod(local, np.maximum(wcols[box], 1))
    col = j0[box] + across
    row = i0[box] + down
    if per_box:
        cl_all = np.asarray(cell, dtype=np.float64)
        cl = cl_all[box] if cl_all.ndim else np.full(box.size, float(cl_all))
        # (a column taken, then gathered: one index array, not two)
        dx = (org[:, 0][box] + col * cl) - center_xy[:, 0][box]
        dy = (org[:, 1][box] + row * cl) - center_xy[:, 1][box]
        hit = _overlaps(dx, dy, cl, half_x[box], half_y[box], cos[box], sin[box])
    else:
        dx = (org[0] + col * cell) - center_xy[:, 0][box]
        dy = (org[1] + row * cell) - center_xy[:, 1][box]
        hit = _overlaps(dx, dy, cell, half_x[box], half_y[box], cos[box], sin[box])
    return box[hit], row[hit], col[hit]


#: Triangles rasterised together at most (larger batches are cut: arrays of about a hundred
#: thousand (triangle, cell) pairs stay in the processor's cache, twice as fast per pair).
_RASTER_CHUNK = 2048


def raster_triangles(
    origin: FloatArray, cell: float | FloatArray, shape: tuple[int, int] | tuple[IntArray, IntArray],
    tris: FloatArray, first: tuple[int, int] | tuple[IntArray, IntArray] = (0, 0),
) -> tuple[IntArray, IntArray, IntArray, FloatArray]:
    """Cells of a grid overlapped by triangles ``(k, 3, 3)`` and a height for each.

    A cell is overlapped when its square and the triangle's ground projection intersect
    (separating axes: the grid axes and the triangle's three edge normals), so vertical
    walls and triangles smaller than a cell count too. The height is the highest point of the
    triangle's plane over the cell, capped by the triangle's highest vertex: never below the
    highest point of the triangle inside the cell. Returns ``(tri, row, col, z)``; the caller
    takes the maximum per cell.

    The grid has cell ``[0, 0]`` centred at ``origin`` ``(2,)``; only its rows ``first[0]``
    up to ``shape[0]`` and columns ``first[1]`` up to ``shape[1]`` are looked at (a part of a
    grid gives exactly the cells and heights of the whole grid there). Each triangle may have
    its own grid: ``origin`` ``(k, 2)``, ``cell`` ``(k,)`` and ``shape`` and ``first`` pairs
    of ``(k,)`` arrays (the same arithmetic per triangle as with one grid).
    """
    parts = list(raster_triangle_pieces(origin, cell, shape, tris, first))
    if len(parts) == 1:
        return parts[0]
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] for p in parts]), np.concatenate([p[3] for p in parts]))


def raster_triangle_pieces(
    origin: FloatArray, cell: float | FloatArray, shape: tuple[int, int] | tuple[IntArray, IntArray],
    tris: FloatArray, first: tuple[int, int] | tuple[IntArray, IntArray] = (0, 0),
) -> Iterator[tuple[IntArray, IntArray, IntArray, FloatArray]]:
    """:func:`raster_triangles` in pieces of at most ``_RASTER_CHUNK`` triangles (what it
    returns, cut: each piece's ``tri`` counts from the first triangle of all), for a caller
    that uses each piece at once."""
    k = tris.shape[0]
    org = np.asarray(origin, dtype=np.float64)
    cl = np.asarray(cell, dtype=np.float64)
    if k <= _RASTER_CHUNK:
        yield _raster_triangles(org, cl, shape, tris, first)
        return
    per_tri = org.ndim == 2
    grid = [org, cl, np.asarray(shape[0]), np.asarray(shape[1]), np.asarray(first[0]), np.asarray(first[1])]
    for s0 in range(0, k, _RASTER_CHUNK):
        sl = slice(s0, s0 + _RASTER_CHUNK)
        o, c, ny, nx, f0, f1 = (a[sl] if per_tri and a.ndim else a for a in grid)
        tri, row, col, z = _raster_triangles(o, c, (ny, nx), tris[sl], (f0, f1))
        yield tri + s0, row, col, z


def _min3(v: FloatArray) -> FloatArray:
    """``(k,)`` the least of each row of ``v (k, 3)`` (the same as ``v.min(axis=1)``, faster)."""
    return np.minimum(np.minimum(v[:, 0], v[:, 1]), v[:, 2])


def _max3(v: FloatArray) -> FloatArray:
    """``(k,)`` the greatest of each row of ``v (k, 3)``."""
    return np.maximum(np.maximum(v[:, 0], v[:, 1]), v[:, 2])


def _raster_triangles(
    org: FloatArray, cl: FloatArray, shape: tuple[int, int] | tuple[IntArray, IntArray], tris: FloatArray,
    first: tuple[int, int] | tuple[IntArray, IntArray],
) -> tuple[IntArray, IntArray, IntArray, FloatArray]:
    """:func:`raster_triangles` of one batch (``org`` and ``cl`` arrays already)."""
    k = tris.shape[0]
    e = np.zeros(0, dtype=np.intp)
    if k == 0:
        return e, e.copy(), e.copy(), np.zeros(0)
    per_tri = org.ndim == 2
    ox, oy = org[..., 0], org[..., 1]
    if per_tri:  # (one grid per triangle: its numbers against the triangle's three corners)
        fx = (tris[..., 0] - ox[:, None]) / (cl[:, None] if cl.ndim else cl)  # (k, 3) in cells
        fy = (tris[..., 1] - oy[:, None]) / (cl[:, None] if cl.ndim else cl)
    else:
        fx = (tris[..., 0] - ox) / cl
        fy = (tris[..., 1] - oy) / cl
    j0 = np.maximum(np.ceil(_min3(fx) - 0.5).astype(np.intp), first[1])
    j1 = np.minimum(np.floor(_max3(fx) + 0.5).astype(np.intp), np.asarray(shape[1]) - 1)
    i0 = np.maximum(np.ceil(_min3(fy) - 0.5).astype(np.intp), first[0])
    i1 = np.minimum(np.floor(_max3(fy) + 0.5).astype(np.intp), np.asarray(shape[0]) - 1)
    wcols = np.maximum(j1 - j0 + 1, 0)
    counts = wcols * np.maximum(i1 - i0 + 1, 0)
    tri = np.arange(k, dtype=np.intp).repeat(counts)
    if tri.size == 0:
        return e, e.copy(), e.copy(), np.zeros(0)
    start = counts.cumsum() - counts
    local = np.arange(tri.size, dtype=np.intp) - start.take(tri)
    down, across = np.divmod(local, np.maximum(wcols, 1).take(tri))
    col = j0.take(tri) + across
    row = i0.take(tri) + down
    colf = col.astype(np.float64)
    rowf = row.astype(np.float64)
    hit = np.ones(tri.size, dtype=bool)
    for a in range(3):
        # Each edge normal and the triangle's extent along it are the triangle's own: found
        # per triangle, then looked up per (triangle, cell) pair; the cell's centre and
        # reach along the normal, (centre - reach) - 1e-12 and (centre + reach) + 1e-12
        b = (a + 1) % 3
        nxa = -(fy[:, b] - fy[:, a])  # (k,)
        nya = fx[:, b] - fx[:, a]
        proj = fx * nxa[:, None] + fy * nya[:, None]  # (k, 3)
        centre = colf * nxa.take(tri)
        centre += rowf * nya.take(tri)
        reach = (0.5 * (np.abs(nxa) + np.abs(nya))).take(tri)
        bound = centre - reach
        bound -= 1e-12
        hit &= _max3(proj).take(tri) >= bound
        centre += reach
        centre += 1e-12
        hit &= _min3(proj).take(tri) <= centre
    tri, row, col = tri[hit], row[hit], col[hit]
    colf, rowf = colf[hit], rowf[hit]
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    flat_ok = np.abs(normal[:, 2]) > 1e-12
    nz = np.where(flat_ok, normal[:, 2], 1.0)
    gx = -normal[:, 0] / nz
    gy = -normal[:, 1] / nz
    # the plane's highest point over the cell: z0 + gx px + gy py + half a cell (|gx| + |gy|),
    # (px, py) the cell's centre from the first corner (origin + col cell - x0)
    rise = 0.5 * cl * (np.abs(gx) + np.abs(gy))
    cl_t = cl.take(tri) if cl.ndim else cl
    px = colf * cl_t
    px += ox.take(tri) if per_tri else ox
    px -= tris[:, 0, 0].take(tri)
    py = rowf * cl_t
    py += oy.take(tri) if per_tri else oy
    py -= tris[:, 0, 1].take(tri)
    px *= gx.take(tri)
    px += tris[:, 0, 2].take(tri)
    py *= gy.take(tri)
    px += py
    px += rise.take(tri)
    top = _max3(tris[:, :, 2]).take(tri)
    z = np.minimum(px, top, out=px)
    if not np.all(flat_ok):
        z = np.where(flat_ok.take(tri), z, top)
    return tri, row, col, z


def triangle_table(tris: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """What :func:`triangle_hits` reads of each triangle ``(f, 3, 3)``: ``(f, 10)`` rows of the
    first corner's xy, the two edges' xy from it, the determinant of the edges (NaN for a
    triangle without ground area: no point is inside it), the first corner's z and the two
    edges' z; written into ``out`` when given."""
    if out is None:
        out = np.empty((tris.shape[0], 10))
    a = tris[:, 0]
    out[:, 0:2] = a[:, :2]
    out[:, 2:4] = tris[:, 1, :2] - a[:, :2]
    out[:, 4:6] = tris[:, 2, :2] - a[:, :2]
    den = out[:, 2] * out[:, 5] - out[:, 3] * out[:, 4]
    out[:, 6] = np.where(np.abs(den) > 1e-15, den, np.nan)
    out[:, 7] = a[:, 2]
    out[:, 8] = tris[:, 1, 2] - a[:, 2]
    out[:, 9] = tris[:, 2, 2] - a[:, 2]
    return out


def triangle_hits(
    table: FloatArray, xy: FloatArray, point: IntArray, tri: IntArray
) -> tuple[IntArray, IntArray, FloatArray]:
    """Which candidate (point, triangle) pairs hit: points ``xy`` ``(n, 2)`` inside the ground
    projection of triangles (their :func:`triangle_table` ``(f, 10)``), candidates
    ``point``/``tri`` ``(m,)``. Returns the pairs that hit and the triangle's height at the
    point, ``(k,)`` each."""
    t = table.take(tri, axis=0)  # (take: rows gathered about twice as fast as by indexing)
    q = xy.take(point, axis=0)
    px = q[:, 0] - t[:, 0]
    py = q[:, 1] - t[:, 1]
    e1x, e1y, e2x, e2y, den = t[:, 2], t[:, 3], t[:, 4], t[:, 5], t[:, 6]
    u = (px * e2y - py * e2x) / den
    v = (e1x * py - e1y * px) / den
    tol = -1e-9
    inside = np.flatnonzero((u >= tol) & (v >= tol) & (u + v <= 1.0 - tol))
    t = t.take(inside, axis=0)  # (the heights of the hits only)
    z = t[:, 7] + u.take(inside) * t[:, 8] + v.take(inside) * t[:, 9]
    return point.take(inside), tri.take(inside), z


# ---------------------------------------------------------------------------------------
# Spatial index for point queries
# ---------------------------------------------------------------------------------------
class _BucketIndex:
    """Items with 2D bounding boxes, bucketed on a regular grid (CSR layout). ``share``: the
    buckets' side as a share of a typical item's."""

    def __init__(self, lo: FloatArray, hi: FloatArray, share: float = 1.0) -> None:
        n = lo.shape[0]
        self.n = n
        if n == 0:
            self.bucket = 1.0
            self.origin = np.zeros(2)
            self.shape = (1, 1)
            self.offsets = np.zeros(3, dtype=np.intp)
            self.items = np.zeros(0, dtype=np.intp)
            self._dims = (1.0, 1.0)
            self._ox = self._oy = 0.0
            return
        # (coordinates one at a time: a reduction across the two columns of an (n, 2) array
        # is a strided loop, several times slower than two contiguous ones)
        lx, ly, hx, hy = lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]
        typical = float(np.median(np.maximum(hx - lx, hy - ly)))
        ox, oy = float(lx.min()), float(ly.min())
        self.origin = np.array([ox, oy])
        span = (float(hx.max()) - ox, float(hy.max()) - oy)
        # Buckets the size of a typical item (share 1): each item in about four buckets, a
        # point's candidates the few items over its bucket (twice that size gave about 18
        # candidates per point on a triangulated grid, where the exact test cost more than the
        # lookup). Triangles take half that size (TRIANGLE_BUCKET).
        bucket = max(typical * share, 1e-3)
        # Keep the bucket grid reasonably small for sparse, large worlds.
        while (span[0] / bucket + 1) * (span[1] / bucket + 1) > 4.0e6:
            bucket *= 2.0
        self.bucket = bucket
        nbx = math.floor(span[0] / bucket) + 1
        nby = math.floor(span[1] / bucket) + 1
        self.shape = (nby, nbx)
        # (32-bit indices while they fit: a million triangles make about four million entries)
        idx = np.int32 if n < 2**31 - 1 and nbx * nby + 2 < 2**31 - 1 else np.intp
        # An item's buckets: floor((bound - origin) / bucket), as pairs() finds a point's, so a
        # point within an item's bounds is within its buckets (both roundings are monotone).
        bx0 = np.floor((lx - ox) / bucket).astype(idx)
        bx1 = np.minimum(np.floor((hx - ox) / bucket).astype(idx), nbx - 1)
        by0 = np.floor((ly - oy) / bucket).astype(idx)
        by1 = np.minimum(np.floor((hy - oy) / bucket).astype(idx), nby - 1)
        wx = bx1 - bx0 + 1
        counts = wx * (by1 - by0 + 1)
        total = int(counts.sum(dtype=np.int64))
        if total >= 2**31 - 1:
            idx = np.intp
        item = np.arange(n, dtype=idx).repeat(counts)
        start = (counts.cumsum(dtype=np.int64) - counts).astype(idx)
        local = np.arange(total, dtype=idx)
        local -= start[item]  # each entry's place among its item's buckets
        width = wx[item]
        key = local // width
        key += by0[item]
        key *= nbx
        key += bx0[item]
        local %= width
        key += local
        del local, width
        buckets = nbx * nby
        if buckets < 2**16 - 1:
            key = key.astype(np.uint16)  # (a stable sort of 16-bit keys is a radix sort)
        order = np.argsort(key, kind="stable")
        self.items = item[order]
        del item
        # each bucket's first entry; one more bucket, empty, past the last: points outside
        # the grid read it. Bucket k's first entry is the number of sorted keys below k: entry
        # i is it for the buckets after key i - 1 up to key i (a repeat of the entries by the
        # gaps between the sorted keys; a running sum over every bucket, a serial loop of
        # about 3 ns a bucket, cost the moving crates' index of the crowd scene a third of
        # its build over its 31,000 buckets)
        sk = key[order].astype(np.intp)
        del order
        gaps = np.empty(total + 1, dtype=np.intp)
        gaps[0] = sk[0] + 1
        np.subtract(sk[1:], sk[:-1], out=gaps[1:-1])
        gaps[-1] = buckets + 1 - sk[-1]
        self.offsets = np.arange(total + 1, dtype=np.intp).repeat(gaps)
        self._dims = (float(nbx), float(nby))
        self._ox, self._oy = ox, oy

    def pairs(self, xy: FloatArray) -> tuple[IntArray, IntArray]:
        """(point, item) candidate pairs for points ``(n, 2)``."""
        if self.n == 0 or xy.shape[0] == 0:
            e = np.zeros(0, dtype=np.intp)
            return e, e.copy()
        nby, nbx = self.shape
        # each point's bucket column and row (the coordinates one at a time: operations
        # across the two columns of an (n, 2) array are strided loops, over twice as slow)
        cx = np.floor((xy[:, 0] - self._ox) / self.bucket)
        cy = np.floor((xy[:, 1] - self._oy) / self.bucket)
        ok = (cx >= 0.0) & (cx < self._dims[0]) & (cy >= 0.0) & (cy < self._dims[1])
        # a point outside the grid reads the empty bucket past the last one
        key = np.where(ok, cy * nbx + cx, nbx * nby).astype(np.intp)
        # _ranges_to_pairs of the buckets' item ranges, the offsets read once
        lo = self.offsets[key]
        count = self.offsets[key + 1] - lo
        point = np.arange(xy.shape[0], dtype=np.intp).repeat(count)
        shift = count.cumsum() - count - lo
        pos = np.arange(point.size, dtype=np.intp) - shift[point]
        return point, self.items[pos]


class _RectIndex:
    """Items with 2D bounding boxes for rectangle queries: each item in the one bucket of its
    lower corner (CSR layout), items wider than a bucket apart; a rectangle's candidates are
    the buckets from a bucket before its lower corner to its upper corner (each item once)."""

    def __init__(self, lo: FloatArray, hi: FloatArray) -> None:
        self.lo_x, self.lo_y = lo[:, 0].copy(), lo[:, 1].copy()
        self.hi_x, self.hi_y = hi[:, 0].copy(), hi[:, 1].copy()
        n = lo.shape[0]
        ext = np.max(hi - lo, axis=1) if n else np.zeros(0)
        # Buckets of two typical items a side (a rectangle's candidates: the items starting
        # up to a bucket before it)
        bucket = max(2.0 * float(np.median(ext)) if n else 1.0, 1e-3)
        self.origin = lo.min(axis=0) if n else np.zeros(2)
        span = (lo.max(axis=0) - self.origin) if n else np.zeros(2)
        while (span[0] / bucket + 1) * (span[1] / bucket + 1) > 4.0e6:
            bucket *= 2.0
        self.bucket = bucket
        small = ext <= bucket
        self.wide = np.nonzero(~small)[0]
        items = np.nonzero(small)[0]
        nbx = int(span[0] // bucket) + 1
        nby = int(span[1] // bucket) + 1
        self.shape = (nby, nbx)
        b = np.minimum(np.floor((lo[items] - self.origin) / bucket).astype(np.intp), [nbx - 1, nby - 1])
        key = b[:, 1] * nbx + b[:, 0]
        self.items = items[np.argsort(key, kind="stable")]
        self.offsets = np.zeros(nbx * nby + 1, dtype=np.intp)
        np.cumsum(np.bincount(key, minlength=nbx * nby), out=self.offsets[1:])

    def pairs(self, qlo: FloatArray, qhi: FloatArray) -> tuple[IntArray, IntArray]:
        """(query, item) pairs of the items whose bounds overlap rectangles ``[qlo, qhi]``
        (``(q, 2)`` each; bounds touching count)."""
        nby, nbx = self.shape
        # An item reaching the rectangle starts at most a bucket before it (its bucket found
        # with the same arithmetic as the items', from a point a little further back: rounding
        # only moves the bounds outwards)
        a = np.floor((qlo - 1.001 * self.bucket - self.origin) / self.bucket)
        b = np.floor((qhi - self.origin) / self.bucket)
        bx0 = np.maximum(a[:, 0], 0).astype(np.intp)
        by0 = np.maximum(a[:, 1], 0).astype(np.intp)
        bx1 = np.minimum(b[:, 0], nbx - 1).astype(np.intp)
        by1 = np.minimum(b[:, 1], nby - 1).astype(np.intp)
        by1 = np.where(bx1 >= bx0, by1, -1)  # (no columns: no rows)
        query, row = _ranges_to_pairs(by0, by1)
        start = self.offsets[row * nbx + bx0[query]]
        stop = self.offsets[row * nbx + bx1[query] + 1]
        run, pos = _ranges_to_pairs(start, stop - 1)
        query = query[run]
        item = self.items[pos]
        if self.wide.size:
            q_w, w_w = np.nonzero(np.ones((qlo.shape[0], self.wide.size), dtype=bool))
            query = np.concatenate([query, q_w])
            item = np.concatenate([item, self.wide[w_w]])
        ok = self.hi_x.take(item) >= qlo[:, 0].take(query)
        ok &= self.hi_y.take(item) >= qlo[:, 1].take(query)
        ok &= self.lo_x.take(item) <= qhi[:, 0].take(query)
        ok &= self.lo_y.take(item) <= qhi[:, 1].take(query)
        return query[ok], item[ok]


# ---------------------------------------------------------------------------------------
# Window grids
# ---------------------------------------------------------------------------------------
@dataclass
class WindowGrids:
    """The two grids of a character's window (thesis §3.4.1) and helpers to read them.

    ``origin``: ``(2,)`` world xy of cell ``[0, 0]``'s centre; ``cell``: metres;
    ``elevation``: ``(ny, nx)`` highest surface per cell (:data:`NO_SURFACE` where none);
    ``avoid``: ``(ny, nx)`` cells overlapped by avoided obstacles (the obstacle map's core);
    ``foot_half_extents``/``foot_yaw``: the foot shape of the default dilation.

    Derived, computed on first use: ``forbidden`` (= ``avoid``), ``dilated`` (cells forbidden
    only by the foot-shape enlargement), ``void`` (no surface) — the obstacle map without
    slices and without other feet. The planner builds its own per-slice maps with
    :meth:`obstacle_map`.

    ``stack``: the windows made together (:meth:`Environment.windows`) keep their elevations
    in one ``(m, ny, nx)`` array; this window's is ``stack[0][stack[1]]`` (None: its own
    array). The planner reads many windows at once through it without copying them.
    """

    origin: FloatArray
    cell: float
    elevation: FloatArray
    avoid: BoolArray
    foot_half_extents: tuple[float, float] = (0.03, 0.03)
    foot_yaw: float = 0.0
    _cache: dict[str, npt.NDArray[np.generic]] = field(default_factory=dict, repr=False, compare=False)
    stack: tuple[FloatArray, int] | None = field(default=None, repr=False, compare=False)

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.elevation.shape[0]), int(self.elevation.shape[1]))

    @property
    def forbidden(self) -> BoolArray:
        """Cells inside avoided obstacles: ``(ny, nx)``."""
        return self.avoid

    @property
    def dilated(self) -> BoolArray:
        """Cells forbidden only because of the foot-shape enlargement: ``(ny, nx)``."""
        if "dilated" not in self._cache:
            self._cache["dilated"] = self.obstacle_map()[1]
        return self._cache["dilated"]  # type: ignore[return-value]

    @property
    def void(self) -> BoolArray:
        """Cells without any surface (gaps): ``(ny, nx)``."""
        return np.asarray(self.elevation < _VOID_BELOW)

    def obstacle_map(
        self,
        level: float | None = None,
        extra: BoolArray | None = None,
        foot_half_extents: npt.ArrayLike | None = None,
        foot_yaw: float | None = None,
    ) -> tuple[BoolArray, BoolArray]:
        """The obstacles' map for one height slice (thesis §3.5.2).

        Forbidden cells are the avoided obstacles, the ``extra`` cells (other feet) and, when
        ``level`` is given, every cell whose elevation is above ``level`` (walked around
        instead of over). Returns ``(core, dilated)``: ``core`` the forbidden cells, ``dilated``
        the cells added by the foot-shape enlargement only (thesis Figure 3.18).
        """
        core = self.avoid.copy()
        if extra is not None:
            core |= extra
        if level is not None:
            core |= self.elevation > level
        half = self.foot_half_extents if foot_half_extents is None else foot_half_extents
        yaw = self.foot_yaw if foot_yaw is None else foot_yaw
        grown = dilate(core, foot_kernel(self.cell, half, yaw))
        return core, grown & ~core

    def rowcol(self, xy: npt.ArrayLike) -> FloatArray:
        """Continuous (row, col) coordinates of world points ``(..., 2)``: ``(..., 2)``."""
        p = np.asarray(xy, dtype=np.float64)
        # (a coordinate at a time: an operation across the two columns is a strided loop)
        out = np.empty(p.shape)
        out[..., 0] = (p[..., 1] - self.origin[1]) / self.cell
        out[..., 1] = (p[..., 0] - self.origin[0]) / self.cell
        return out

    def cell_of(self, xy: npt.ArrayLike) -> IntArray:
        """Integer (row, col) of the cell containing each point ``(..., 2)``."""
        return np.rint(self.rowcol(xy)).astype(np.intp)

    def xy_of(self, rows: npt.ArrayLike, cols: npt.ArrayLike) -> FloatArray:
        """World xy of cell centres ``(..., 2)``."""
        r = np.asarray(rows, dtype=np.float64)
        c = np.asarray(cols, dtype=np.float64)
        out = np.empty((*(r.shape if r.shape == c.shape else np.broadcast_shapes(r.shape, c.shape)), 2))
        out[..., 0] = self.origin[0] + c * self.cell
        out[..., 1] = self.origin[1] + r * self.cell
        return out

    def inside(self, rc: IntArray) -> BoolArray:
        """Whether integer cells ``(..., 2)`` lie in the window."""
        ny, nx = self.shape
        return np.asarray((rc[..., 0] >= 0) & (rc[..., 0] < ny) & (rc[..., 1] >= 0) & (rc[..., 1] < nx))

    def elevation_at(self, xy: npt.ArrayLike) -> FloatArray:
        """Elevation-map value of the cell under each point; :data:`NO_SURFACE` outside."""
        rc = self.cell_of(xy)
        ok = self.inside(rc)
        r = np.where(ok, rc[..., 0], 0)
        c = np.where(ok, rc[..., 1], 0)
        return np.where(ok, self.elevation[r, c], NO_SURFACE)


# ---------------------------------------------------------------------------------------
# Environment
# ---------------------------------------------------------------------------------------
_TileKey = tuple[float, int, int]

#: Blocks filled around a window beyond it when it needs new ones (:meth:`Environment._fill_static`),
#: in a call of at most :data:`_FILL_AHEAD_WINDOWS` windows: a few characters' windows then
#: rasterise new blocks at every other block they cross, not at each (a call's fixed cost is
#: most of a small raster); a crowd's call pays that cost once for all its windows, and the
#: ring would only grow each character's raster (100 wolves: a fifth more cells).
_FILL_AHEAD = 1
_FILL_AHEAD_WINDOWS = 8
_KEY_HALF = 1 << 20  # block rows and columns from -2**20 to 2**20 - 1 in a key


def _block_key(cid: IntArray, bi: IntArray, bj: IntArray) -> npt.NDArray[np.int64]:
    """One int64 per (cell size id, block row, block column) (or per tile), ordered as the
    triples are."""
    if bi.size and (min(int(bi.min()), int(bj.min())) < -_KEY_HALF
                    or max(int(bi.max()), int(bj.max())) >= _KEY_HALF):
        raise ValueError("a window lies too far from the world origin for its cell size")
    return np.asarray(((cid.astype(np.int64) * (2 * _KEY_HALF) + (bi + _KEY_HALF)) * (2 * _KEY_HALF)
                       + (bj + _KEY_HALF)), dtype=np.int64)


def _block_of_key(key: npt.NDArray[np.int64]) -> tuple[IntArray, IntArray, IntArray]:
    """The (cell size id, block row, block column) of keys (:func:`_block_key`)."""
    rest, bj = np.divmod(key, 2 * _KEY_HALF)
    cid, bi = np.divmod(rest, 2 * _KEY_HALF)
    return cid.astype(np.intp), (bi - _KEY_HALF).astype(np.intp), (bj - _KEY_HALF).astype(np.intp)


class _BoxRasters:
    """The lattice rasters of the moving boxes at one cell size, kept until a box moves: box
    ``b``'s cells are rows ``start[b]:stop[b]`` of the arrays ``(row, col, top)`` of batch
    ``batch[b]`` (-1: none kept), one batch per call that rasterised boxes (so a window's
    boxes are read with one gather per batch, not one slice per box)."""

    def __init__(self, n_boxes: int) -> None:
        self.batch = np.full(n_boxes, -1, dtype=np.intp)
        self.start = np.zeros(n_boxes, dtype=np.intp)
        self.stop = np.zeros(n_boxes, dtype=np.intp)
        self.batches: dict[int, tuple[IntArray, IntArray, FloatArray]] = {}
        self._next = 0

    def add(self, boxes: IntArray, bounds: IntArray, cells: tuple[IntArray, IntArray, FloatArray]) -> None:
        """Keep the rasters of ``boxes (k,)``: rows ``bounds[i]:bounds[i + 1]`` of ``cells``."""
        if len(self.batches) >= 4:  # forget the batches no box reads any more
            live = set(np.unique(self.batch[self.batch >= 0]).tolist())
            self.batches = {k: v for k, v in self.batches.items() if k in live}
        self.batches[self._next] = cells
        self.batch[boxes] = self._next
        self.start[boxes] = bounds[:-1]
        self.stop[boxes] = bounds[1:]
        self._next += 1

    def cells(self, boxes: IntArray) -> tuple[IntArray, IntArray, IntArray, FloatArray]:
        """The cells of ``boxes (p,)`` (all kept): for each cell its position in ``boxes``,
        its row, column and top."""
        parts = []
        batch = self.batch[boxes]
        for k in np.unique(batch).tolist():
            at = np.flatnonzero(batch == k) if len(self.batches) > 1 else np.arange(boxes.size)
            piece, pos = _ranges_to_pairs(self.start[boxes[at]], self.stop[boxes[at]] - 1)
            row, col, top = self.batches[k]
            parts.append((at[piece], row[pos], col[pos], top[pos]))
        if len(parts) == 1:
            return parts[0]
        if not parts:
            e = np.zeros(0, dtype=np.intp)
            return e, e, e, np.zeros(0)
        return (np.concatenate([q[0] for q in parts]), np.concatenate([q[1] for q in parts]),
                np.concatenate([q[2] for q in parts]), np.concatenate([q[3] for q in parts]))


class Environment:
    """Terrain and obstacles, with point queries and cached per-character window grids.

    ``heightmap``: optional :class:`Heightmap`; ``boxes``: optional :class:`Boxes`;
    ``soups``: :class:`TriangleSoup` meshes. ``tile_cells``: side of the cached static tiles
    in cells. Inputs are copied; move things only through :meth:`move_boxes`,
    :meth:`set_soup_vertices` and :meth:`move_soup`.
    """

    def __init__(
        self,
        heightmap: Heightmap | None = None,
        boxes: Boxes | None = None,
        soups: Sequence[TriangleSoup] = (),
        tile_cells: int = 128,
    ) -> None:
        self.heightmap = heightmap
        if boxes is None:
            boxes = Boxes(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int_),
                          np.zeros(0, dtype=bool))
        self._box_center = boxes.center.copy()
        self._box_size = boxes.size.copy()
        self._box_yaw = boxes.yaw.copy()
        self._box_role = boxes.role.copy()
        self._box_dynamic = boxes.dynamic.copy()
        self._static_boxes = np.nonzero(~self._box_dynamic)[0]
        self._dynamic_boxes = np.nonzero(self._box_dynamic)[0]
        self._soups: list[TriangleSoup] = list(soups)
        self.tile_cells = int(tile_cells)
        # Static tiles are filled block by block (a block: block_cells a side), only the blocks
        # a window covers, when static meshes make a cell dear to rasterise (else a tile at
        # once: a heightmap's and boxes' cells cost little, and a whole tile is then made in
        # one go instead of a few blocks at most steps); the keys of the filled blocks
        # (_block_key), sorted.
        meshes = any(not soup.dynamic and soup.faces.shape[0] for soup in soups)
        self.block_cells = 8 if meshes and self.tile_cells % 8 == 0 else self.tile_cells
        self._tiles: dict[_TileKey, tuple[FloatArray, BoolArray]] = {}
        self._filled = np.zeros(0, dtype=np.int64)
        self._filled_set: set[int] = set()  # the same keys, for the few-window check
        self._cell_ids: dict[float, int] = {}
        self._cells: list[float] = []
        self._rect_index: dict[int, _RectIndex] = {}
        self._static_rects: tuple[_RectIndex, IntArray, dict[int, int]] | None = None
        # Lattice rasters of moving soups, reused until they move: key (cell, "soup", id); of
        # the moving boxes, per cell size (a box's raster is stale once it moved).
        self._moving_raster: dict[tuple[float, str, int], tuple[IntArray, IntArray, FloatArray]] = {}
        self._box_rasters: dict[float, _BoxRasters] = {}
        self._box_index_static: _BucketIndex | None = None
        self._box_index_dynamic: _BucketIndex | None = None
        self._soup_index: dict[int, _BucketIndex] = {}
        self._soup_tris: dict[int, tuple[FloatArray, FloatArray, FloatArray]] = {}
        self._soup_role = np.array([soup.role for soup in self._soups], dtype=np.int_)
        self._static_soup_index: tuple[_BucketIndex, FloatArray, IntArray, IntArray] | None = None
        self._dynamic_soups = [i for i, soup in enumerate(self._soups) if soup.dynamic]
        # static meshes only: a one-point height query reads them in plain Python floats
        self._meshes_only = (self.heightmap is None and not self._box_center.shape[0]
                             and not self._dynamic_soups)
        # Translation of each dynamic soup from its stored vertices (move_soup): the triangles,
        # their index and their raster are kept and only the queries are shifted.
        self._soup_offset: dict[int, FloatArray] = {}
        # The offset each moving soup's cached lattice raster was made at.
        self._raster_offset: dict[tuple[float, str, int], FloatArray] = {}
        # The widest moving box's x extent (found again after a move); the last point query's
        # (point, box) pairs (height_at and forbidden_at often ask for the same points one
        # after the other).
        self._dynamic_widest: float | None = None
        self._last_pairs: tuple[tuple[int, ...], bytes, IntArray, IntArray] | None = None
        self._update_box_bounds()
        self.stats = {"tiles_rasterised": 0, "moving_rasterised": 0, "windows": 0}

    # -- read-only views -----------------------------------------------------------------
    @property
    def boxes(self) -> Boxes:
        """A copy of the current boxes."""
        return Boxes(self._box_center.copy(), self._box_size.copy(), self._box_yaw.copy(),
                     self._box_role.copy(), self._box_dynamic.copy())

    @property
    def soups(self) -> tuple[TriangleSoup, ...]:
        """The soups where they are now (a translated soup's vertices are materialised)."""
        return tuple(self._soups[i] if i not in self._soup_offset else
                     TriangleSoup(self._soups[i].vertices + self._soup_offset[i], self._soups[i].faces,
                                  self._soups[i].role, True)
                     for i in range(len(self._soups)))

    @property
    def dynamic(self) -> bool:
        """Whether anything here can move (boxes or soups made dynamic): what a point query
        answers then depends on when it is asked."""
        return bool(self._dynamic_boxes.size) or bool(self._dynamic_soups)

    def _offset(self, i: int) -> FloatArray:
        off = self._soup_offset.get(i)
        return off if off is not None else np.zeros(3)

    # -- moving things -------------------------------------------------------------------
    def move_boxes(self, index: npt.ArrayLike, center: npt.ArrayLike, yaw: npt.ArrayLike) -> None:
        """Move dynamic boxes ``index`` ``(k,)`` to ``center`` ``(k, 3)`` and ``yaw`` ``(k,)``."""
        idx = np.asarray(index, dtype=np.intp).reshape(-1)
        if idx.size == 0:
            return
        if np.any(~self._box_dynamic[idx]):
            raise ValueError("only boxes created with dynamic=True can move")
        self._box_center[idx] = np.asarray(center, dtype=np.float64).reshape(idx.size, 3)
        self._box_yaw[idx] = np.asarray(yaw, dtype=np.float64).reshape(idx.size)
        self._update_box_bounds(idx)
        self._box_index_dynamic = None
        self._dynamic_widest = None
        self._last_pairs = None
        for store in self._box_rasters.values():
            store.batch[idx] = -1

    def set_soup_vertices(self, i: int, vertices: npt.ArrayLike) -> None:
        """Replace the vertices ``(v, 3)`` of dynamic soup ``i`` (same topology)."""
        soup = self._soups[i]
        if not soup.dynamic:
            raise ValueError("only soups created with dynamic=True can move")
        v = np.asarray(vertices, dtype=np.float64).reshape(soup.vertices.shape)
        self._soups[i] = TriangleSoup(v, soup.faces, soup.role, True)
        self._soup_index.pop(i, None)
        self._soup_tris.pop(i, None)
        self._soup_offset.pop(i, None)
        self._last_pairs = None
        for key in [k for k in self._moving_raster if k[1] == "soup" and k[2] == i]:
            del self._moving_raster[key]
            self._raster_offset.pop(key, None)

    def move_soup(self, i: int, offset: npt.ArrayLike) -> None:
        """Translate dynamic soup ``i`` to its stored vertices plus ``offset`` ``(3,)``.

        The same as :meth:`set_soup_vertices` with the shifted vertices, but its triangles
        and their index are kept (a rigidly sliding or lifting platform of a million
        triangles costs a shift per frame, not a rebuild); its lattice raster is rebuilt
        only when the horizontal offset changes.
        """
        soup = self._soups[i]
        if not soup.dynamic:
            raise ValueError("only soups created with dynamic=True can move")
        off = np.asarray(offset, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(off)):
            raise ValueError("offset must be finite")
        self._soup_offset[i] = off.copy()
        self._last_pairs = None

    def clear_cache(self) -> None:
        """Forget every cached tile and raster (memory only; results do not change)."""
        self._tiles.clear()
        self._filled = np.zeros(0, dtype=np.int64)
        self._filled_set.clear()
        self._moving_raster.clear()
        self._raster_offset.clear()
        self._box_rasters.clear()

    def _update_box_bounds(self, idx: IntArray | None = None) -> None:
        if idx is None:
            idx = np.arange(self._box_center.shape[0])
            self._box_lo = np.zeros((idx.size, 2))
            self._box_hi = np.zeros((idx.size, 2))
            self._box_cos = np.zeros(idx.size)
            self._box_sin = np.zeros(idx.size)
            self._box_half = 0.5 * self._box_size[:, :2]
            self._box_top = np.zeros(idx.size)
        hx = 0.5 * self._box_size[idx, 0]
        hy = 0.5 * self._box_size[idx, 1]
        cos = np.cos(self._box_yaw[idx])
        sin = np.sin(self._box_yaw[idx])
        acos = np.abs(cos)
        asin = np.abs(sin)
        ext = np.stack([hx * acos + hy * asin, hx * asin + hy * acos], axis=1)
        self._box_lo[idx] = self._box_center[idx, :2] - ext
        self._box_hi[idx] = self._box_center[idx, :2] + ext
        self._box_cos[idx] = cos
        self._box_sin[idx] = sin
        self._box_top[idx] = self._box_center[idx, 2] + self._box_size[idx, 2]

    # -- point queries -------------------------------------------------------------------
    def _box_pairs(self, xy: FloatArray) -> tuple[IntArray, IntArray]:
        """(point, box) pairs of points ``(n, 2)`` inside boxes' ground footprints. The last
        query's answer is kept: asking again for the same points (until something moves) costs
        a comparison."""
        if self._box_center.shape[0] == 0:  # (a scene of meshes only: the shell's)
            e = np.zeros(0, dtype=np.intp)
            return e, e
        key = xy.tobytes()
        last = self._last_pairs
        if last is not None and last[0] == xy.shape and last[1] == key:
            return last[2], last[3]
        if self._box_index_static is None:
            s = self._static_boxes
            self._box_index_static = _BucketIndex(self._box_lo[s], self._box_hi[s])
        p1, b1 = self._box_index_static.pairs(xy)
        p2, b2 = self._dynamic_index().pairs(xy)
        point = np.concatenate([p1, p2])
        box = np.concatenate([self._static_boxes[b1], self._dynamic_boxes[b2]])
        # The point in its box's frame, column by column (1-D gathers: the queries run to
        # thousands of points)
        rx = xy[:, 0].take(point) - self._box_center[:, 0].take(box)
        ry = xy[:, 1].take(point) - self._box_center[:, 1].take(box)
        cos = self._box_cos.take(box)
        sin = self._box_sin.take(box)
        u = rx * cos + ry * sin
        v = -rx * sin + ry * cos
        inside = (np.abs(u) <= self._box_half[:, 0].take(box)) & (np.abs(v) <= self._box_half[:, 1].take(box))
        point, box = point[inside], box[inside]
        self._last_pairs = (xy.shape, key, point, box)
        return point, box

    def _soup_triangles(self, i: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Triangles ``(f, 3, 3)`` of soup ``i`` and their xy bounds, cached until it moves."""
        hit = self._soup_tris.get(i)
        if hit is None:
            soup = self._soups[i]
            tris = soup.vertices[soup.faces]
            a, b, c = tris[:, 0, :2], tris[:, 1, :2], tris[:, 2, :2]
            # (corner by corner: a reduction across the corners of (f, 3, 2) is a strided loop)
            hit = (tris, np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c))
            self._soup_tris[i] = hit
        return hit

    def _soup_hits(self, i: int, xy: FloatArray) -> tuple[IntArray, FloatArray]:
        tris, tlo, thi = self._soup_triangles(i)
        if i not in self._soup_index:
            self._soup_index[i] = _BucketIndex(tlo, thi, TRIANGLE_BUCKET)
        off = self._soup_offset.get(i)
        if off is not None:
            xy = xy - off[:2]
        point, tri = self._soup_index[i].pairs(xy)
        # (a moving soup's table only for the candidates: it may be large and change)
        point, _, z = triangle_hits(triangle_table(tris[tri]), xy, point, np.arange(tri.size))
        if off is not None:
            z = z + off[2]
        return point, z

    def _static_soups(self) -> tuple[_BucketIndex, FloatArray, IntArray, IntArray]:
        """Every static soup's triangles in one bucket index, built once (static soups never
        change): the index, the triangles' :func:`triangle_table` ``(f, 10)``, the soup of each
        triangle ``(f,)`` and the static soups' ids. One query then answers for all of them (a
        scene of a ground and ten crates asked eleven indices per point query before)."""
        if self._static_soup_index is None:
            ids = np.array([i for i, soup in enumerate(self._soups) if not soup.dynamic], dtype=np.intp)
            parts = [self._soup_triangles(int(i)) for i in ids]
            sizes = [p[0].shape[0] for p in parts]
            tlo = np.concatenate([p[1] for p in parts]) if parts else np.zeros((0, 2))
            thi = np.concatenate([p[2] for p in parts]) if parts else np.zeros((0, 2))
            owner = np.repeat(ids, sizes).astype(np.intp)
            table = np.empty((sum(sizes), 10))
            first = 0
            for p, size in zip(parts, sizes, strict=True):  # (soup by soup: no copy of all triangles)
                triangle_table(p[0], table[first : first + size])
                first += size
            self._static_soup_index = (_BucketIndex(tlo, thi, TRIANGLE_BUCKET), table, owner, ids)
        return self._static_soup_index

    def _static_rect_index(self) -> tuple[_RectIndex, IntArray, dict[int, int]]:
        """Every static soup's triangles in one rectangle index (for the static tiles' rasters),
        built once: the index, the soup of each triangle ``(f,)`` and where each soup's
        triangles start in it (by soup id). One query then finds a rectangle's triangles in
        every static soup (a ground and ten crates were eleven queries per raster)."""
        if self._static_rects is None:
            ids = [i for i, soup in enumerate(self._soups) if not soup.dynamic and soup.faces.shape[0]]
            parts = [self._soup_triangles(i) for i in ids]
            sizes = [p[0].shape[0] for p in parts]
            tlo = np.concatenate([p[1] for p in parts]) if parts else np.zeros((0, 2))
            thi = np.concatenate([p[2] for p in parts]) if parts else np.zeros((0, 2))
            owner = np.repeat(np.array(ids, dtype=np.intp), sizes).astype(np.intp)
            starts = np.cumsum([0, *sizes[:-1]]).tolist() if sizes else []
            self._static_rects = (_RectIndex(tlo, thi), owner, dict(zip(ids, starts, strict=True)))
        return self._static_rects

    def _static_soup_hits(self, xy: FloatArray) -> tuple[IntArray, FloatArray, IntArray]:
        """(point, height, triangle) of every static soup triangle under points ``(n, 2)``
        (the triangle's soup: ``_static_soups()[2]``)."""
        index, table, _, _ = self._static_soups()
        point, tri = index.pairs(xy)
        point, tri, z = triangle_hits(table, xy, point, tri)
        return point, z, tri

    def _static_soup_height(self, x: float, y: float) -> float:
        """The highest static soup triangle under one point (finite ``x``, ``y``), or
        :data:`NO_SURFACE`: what :meth:`height_at` finds for it, in plain Python floats (a
        point query of one point is most of a step's queries; the arithmetic of
        :meth:`_BucketIndex.pairs` and :func:`triangle_hits`, operation by operation, and
        the maximum taken as ``np.maximum.at`` takes it)."""
        index, table, _, _ = self._static_soups()
        if index.n == 0:
            return NO_SURFACE
        nby, nbx = index.shape
        cx = math.floor((x - index._ox) / index.bucket)
        cy = math.floor((y - index._oy) / index.bucket)
        key = cy * nbx + cx if 0 <= cx < index._dims[0] and 0 <= cy < index._dims[1] else nbx * nby
        lo, hi = index.offsets[key : key + 2].tolist()
        best = NO_SURFACE
        if hi == lo:
            return best
        tol = -1e-9
        for x0, y0, e1x, e1y, e2x, e2y, den, z0, dz1, dz2 in table.take(index.items[lo:hi], axis=0).tolist():
            px = x - x0
            py = y - y0
            u = (px * e2y - py * e2x) / den
            v = (e1x * py - e1y * px) / den
            if u >= tol and v >= tol and u + v <= 1.0 - tol:
                z = z0 + u * dz1 + v * dz2
                if z > best or z != z:  # (np.maximum: a NaN stays)
                    best = z
        return best

    def height_at(self, xy: npt.ArrayLike) -> FloatArray:
        """Highest surface (terrain and every obstacle) under each point ``(n, 2)``: ``(n,)``.

        :data:`NO_SURFACE` where there is nothing at all.
        """
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if p.shape[0] == 1 and self._meshes_only:  # (a scene of static meshes: the shell's)
            x, y = p[0].tolist()
            if math.isfinite(x) and math.isfinite(y):
                return np.array([self._static_soup_height(x, y)])
        out = np.full(p.shape[0], NO_SURFACE)
        if self.heightmap is not None:
            out = np.maximum(out, self.heightmap.sample(p))
        point, box = self._box_pairs(p)
        if point.size:
            np.maximum.at(out, point, self._box_top[box])
        if self._static_soups()[0].n:  # (a scene of boxes and a heightmap has no static soup)
            pt, z, _ = self._static_soup_hits(p)
            np.maximum.at(out, pt, z)
        for i in self._dynamic_soups:
            pt, z = self._soup_hits(i, p)
            np.maximum.at(out, pt, z)
        return out

    def forbidden_at(self, xy: npt.ArrayLike) -> BoolArray:
        """Whether each point ``(n, 2)`` lies inside an avoided obstacle's footprint: ``(n,)``."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(p.shape[0], dtype=bool)
        point, box = self._box_pairs(p)
        out[point[self._box_role[box] == ROLE_AVOID]] = True
        if any(soup.role == ROLE_AVOID and not soup.dynamic for soup in self._soups):
            pt, _, tri = self._static_soup_hits(p)
            out[pt[self._soup_role[self._static_soups()[2][tri]] == ROLE_AVOID]] = True
        for i, soup in enumerate(self._soups):
            if soup.role == ROLE_AVOID and soup.dynamic:
                pt, _ = self._soup_hits(i, p)
                out[pt] = True
        return out

    # -- rasterisation -----------------------------------------------------------------------
    def _raster_into(
        self, origin: FloatArray, cell: float, elev: FloatArray, avoid: BoolArray,
        box_ids: IntArray, soup_ids: Sequence[int],
    ) -> None:
        shape = (elev.shape[0], elev.shape[1])
        if box_ids.size:
            b, r, c = raster_boxes(origin, cell, shape, self._box_center[box_ids, :2],
                                   0.5 * self._box_size[box_ids, 0], 0.5 * self._box_size[box_ids, 1],
                                   self._box_yaw[box_ids])
            ids = box_ids[b]
            np.maximum.at(elev, (r, c), self._box_center[ids, 2] + self._box_size[ids, 2])
            a = self._box_role[ids] == ROLE_AVOID
            avoid[r[a], c[a]] = True
        for i in soup_ids:
            soup = self._soups[i]
            tris = (soup.vertices + self._offset(i))[soup.faces]
            _, r, c, z = raster_triangles(origin, cell, shape, tris)
            np.maximum.at(elev, (r, c), z)
            if soup.role == ROLE_AVOID:
                avoid[r, c] = True

    def _heightmap_cells(
        self, origin: FloatArray, cell: float, shape: tuple[int, int], first: tuple[int, int] = (0, 0)
    ) -> FloatArray:
        """Highest terrain height over each cell's area (exact for the bilinear surface):
        ``shape`` cells from cell ``first`` (row, col) of the grid whose cell ``[0, 0]`` is
        centred at ``origin`` (a part of a grid holds exactly what the whole grid holds there).

        A bilinear patch is linear along grid-parallel lines, so over a rectangle its maximum
        is at a corner of the rectangle cut by the heightmap's grid lines: sample the lattice
        of cell borders and heightmap lines, then take the maximum over each cell's lattice
        points. A cell partly over the terrain's edge counts as terrain.
        """
        ny, nx = shape
        hm = self.heightmap
        if hm is None:
            return np.full(shape, NO_SURFACE)
        hny, hnx = hm.heights.shape

        def axis(o: float, k: int, n: int, h_o: float, h_n: int) -> tuple[FloatArray, IntArray]:
            borders = o + (np.arange(k, k + n + 1) - 0.5) * cell
            lines = h_o + np.arange(h_n) * hm.cell
            lines = lines[(lines > borders[0]) & (lines < borders[-1])]
            coords = np.union1d(borders, lines)
            return coords, np.searchsorted(coords, borders)

        xs, bx = axis(float(origin[0]), first[1], nx, float(hm.origin[0]), hnx)
        ys, by = axis(float(origin[1]), first[0], ny, float(hm.origin[1]), hny)
        gx, gy = np.meshgrid(xs, ys)
        lattice = hm.sample(np.stack([gx, gy], axis=-1))
        lattice = np.where(lattice < _VOID_BELOW, -np.inf, lattice)
        # Max over [b_i, b_{i+1}] (both borders included) along each axis.
        rows = np.maximum(np.maximum.reduceat(lattice, by[:-1], axis=0), lattice[by[1:]])
        cells = np.maximum(np.maximum.reduceat(rows, bx[:-1], axis=1), rows[:, bx[1:]])
        return np.where(np.isfinite(cells), cells, NO_SURFACE)

    def _cell_id(self, cell: float) -> int:
        cid = self._cell_ids.get(cell)
        if cid is None:
            cid = self._cell_ids[cell] = len(self._cells)
            self._cells.append(cell)
        return cid

    def _fill_static(self, cells: FloatArray, n: IntArray, i0: IntArray, j0: IntArray) -> None:
        """Make the static grids of windows ready: windows of cell sizes ``cells``, ``n`` cells
        a side, whose cell ``[0, 0]`` is lattice cell ``(i0, j0)`` (``(m,)`` each). The blocks
        of the static tiles they cover that no window covered before are rasterised, every
        block of a tile's new ones' bounding rectangle at once and every rectangle of the
        call in one batch (:meth:`_raster_static`)."""
        b = self.block_cells
        if self._blocks_filled(cells.tolist(), n.tolist(), i0.tolist(), j0.tolist()):
            return
        if b < self.tile_cells and cells.size <= _FILL_AHEAD_WINDOWS:
            # a window that needs new blocks takes a ring of blocks around it too: a window
            # moving with its character then needs new blocks at every other block it
            # crosses, not at each (a rectangle's raster is mostly the call's fixed cost)
            i0, j0, n = i0 - _FILL_AHEAD * b, j0 - _FILL_AHEAD * b, n + 2 * _FILL_AHEAD * b
        ids = np.array([self._cell_id(c) for c in cells.tolist()], dtype=np.int64)
        w, bi = _ranges_to_pairs(i0 // b, (i0 + n - 1) // b)
        v, bj = _ranges_to_pairs(j0[w] // b, (j0[w] + n[w] - 1) // b)
        key = np.unique(_block_key(ids[w[v]], bi[v], bj))
        filled = self._filled
        at = np.minimum(np.searchsorted(filled, key), max(filled.size - 1, 0))
        todo = key[filled[at] != key] if filled.size else key
        if todo.size == 0:
            return
        cid, bi, bj = _block_of_key(todo)
        kb = self.tile_cells // b
        ti, tj = bi // kb, bj // kb
        # one rectangle per tile: the bounds of its new blocks (in blocks, from the tile's first)
        tiles, which = np.unique(_block_key(cid, ti, tj), return_inverse=True)
        g = tiles.size
        lo_i = np.full(g, kb, dtype=np.int64)
        lo_j = np.full(g, kb, dtype=np.int64)
        hi_i = np.full(g, -1, dtype=np.int64)
        hi_j = np.full(g, -1, dtype=np.int64)
        np.minimum.at(lo_i, which, bi - ti * kb)
        np.minimum.at(lo_j, which, bj - tj * kb)
        np.maximum.at(hi_i, which, bi - ti * kb)
        np.maximum.at(hi_j, which, bj - tj * kb)
        t_cid, t_i, t_j = _block_of_key(tiles)
        self._raster_static(t_cid, t_i, t_j, lo_i * b, (hi_i + 1) * b, lo_j * b, (hi_j + 1) * b)
        # every block of the rectangles is filled now
        r, bi = _ranges_to_pairs(lo_i, hi_i)
        q, bj = _ranges_to_pairs(lo_j[r], hi_j[r])
        r = r[q]
        done = _block_key(t_cid[r], t_i[r] * kb + bi[q], t_j[r] * kb + bj)
        self._filled = np.union1d(filled, done)
        self._filled_set.update(done.tolist())

    def _blocks_filled(self, cells: list[float], n: list[int], i0: list[int], j0: list[int]) -> bool:
        """Whether every block the windows of :meth:`_fill_static` cover is filled already,
        looked up key by key in plain Python (most steps move a window within filled blocks:
        a few dozen set look-ups instead of :meth:`_fill_static`'s array passes); False when
        the windows cover too many blocks for that to pay."""
        b = self.block_cells
        spans = [((i + k - 1) // b - i // b + 1) * ((j + k - 1) // b - j // b + 1)
                 for k, i, j in zip(n, i0, j0, strict=True)]
        if sum(spans) > 1024:
            return False
        filled = self._filled_set
        side = 2 * _KEY_HALF
        for c, k, i, j in zip(cells, n, i0, j0, strict=True):
            cid = self._cell_ids.get(c)
            if cid is None or min(i // b, j // b) < -_KEY_HALF or max(i + k - 1, j + k - 1) // b >= _KEY_HALF:
                return False  # (keys out of range: the array path raises)
            cols = range(j // b + _KEY_HALF, (j + k - 1) // b + 1 + _KEY_HALF)
            for bi in range(i // b, (i + k - 1) // b + 1):
                row = (cid * side + bi + _KEY_HALF) * side
                for bj in cols:
                    if row + bj not in filled:
                        return False
        return True

    def _raster_static(
        self, cid: IntArray, ti: IntArray, tj: IntArray, r0: IntArray, r1: IntArray, c0: IntArray,
        c1: IntArray,
    ) -> None:
        """Rasterise the static scene into rectangles of static tiles, all in one batch: tile
        ``(ti, tj)`` of cell size ``self._cells[cid]``, its rows ``r0`` to ``r1`` and columns
        ``c0`` to ``c1`` (ends excluded; ``(g,)`` each). Every cell gets the numbers of its
        whole tile's rasterisation (the same grid, origin and arithmetic: the tile is a cache
        of the lattice, not a grid of its own)."""
        t = self.tile_cells
        g = cid.size
        cell = np.array(self._cells)[cid]
        origin = np.column_stack([tj * t * cell, ti * t * cell])  # (each cell of a tile from its origin)
        h = r1 - r0
        w = c1 - c0
        size = h * w
        off = np.cumsum(size) - size
        elev = np.full(int(size.sum()), NO_SURFACE)
        avoid = np.zeros(elev.size, dtype=bool)
        h_l, w_l, r0_l, c0_l, off_l = h.tolist(), w.tolist(), r0.tolist(), c0.tolist(), off.tolist()
        if self.heightmap is not None:
            cell_l = cell.tolist()
            for k in range(g):
                elev[off_l[k] : off_l[k] + h_l[k] * w_l[k]] = self._heightmap_cells(
                    origin[k], cell_l[k], (h_l[k], w_l[k]), (r0_l[k], c0_l[k])).ravel()
        # the rectangles' world bounds, with a cell of margin
        lo = origin + np.column_stack([c0 - 1, r0 - 1]) * cell[:, None]
        hi = origin + np.column_stack([c1, r1]) * cell[:, None]

        # where a cell (row, col) of a rectangle is in the rectangles' flat arrays: its
        # rectangle's base + row * width + col
        base = off - r0 * w - c0

        def paste(rect: IntArray, row: IntArray, col: IntArray, z: FloatArray,
                  avoided: BoolArray | bool) -> None:
            at = base.take(rect) + row * w.take(rect) + col
            np.maximum.at(elev, at, z)
            if avoided is True:
                avoid[at] = True
            elif avoided is not False:
                avoid[at[avoided]] = True

        s = self._static_boxes
        if s.size:
            index = self._rect_index.get(-1)
            if index is None:
                index = self._rect_index[-1] = _RectIndex(self._box_lo[s], self._box_hi[s])
            rect, box = index.pairs(lo, hi)
            box = s[box]
            pair, row, col = raster_boxes(origin[rect], cell[rect], (r1[rect], c1[rect]),
                                          self._box_center[box, :2], 0.5 * self._box_size[:, 0][box],
                                          0.5 * self._box_size[:, 1][box], self._box_yaw[box],
                                          first=(r0[rect], c0[rect]))
            rect, box = rect[pair], box[pair]
            paste(rect, row, col, self._box_center[:, 2][box] + self._box_size[:, 2][box],
                  self._box_role[box] == ROLE_AVOID)
        index, owner, first = self._static_rect_index()
        rect_all, tri_all = index.pairs(lo, hi)
        # (the triangles of every soup some rectangle reaches in one batch, soup after soup:
        # every triangle's cells and heights are its own, and the paste takes maxima in the
        # order the soups came one by one)
        soups_hit = np.unique(owner[tri_all]).tolist() if tri_all.size > 0 else []
        if soups_hit:
            tri_owner = owner[tri_all]
            order = tri_owner.argsort(kind="stable") if len(soups_hit) > 1 else slice(None)
            rect, gtri, tri_owner = rect_all[order], tri_all[order], tri_owner[order]
            cuts = tri_owner.searchsorted(np.asarray([*soups_hit, len(self._soups)])).tolist()
            tris = np.concatenate([self._soup_triangles(i)[0][gtri[cuts[k] : cuts[k + 1]] - first[i]]
                                   for k, i in enumerate(soups_hit)])
            soup_avoided = np.asarray([soup.role == ROLE_AVOID for soup in self._soups])
            avoided = soup_avoided[tri_owner]
            for pair, row, col, z in raster_triangle_pieces(origin[rect], cell[rect], (r1[rect], c1[rect]),
                                                            tris, first=(r0[rect], c0[rect])):
                paste(rect.take(pair), row, col, z, avoided.take(pair))
        for k, (c, i, j) in enumerate(zip(cid.tolist(), ti.tolist(), tj.tolist(), strict=True)):
            key = (self._cells[c], i, j)
            tile = self._tiles.get(key)
            if tile is None:
                tile = self._tiles[key] = (np.full((t, t), NO_SURFACE), np.zeros((t, t), dtype=bool))
            cut = (slice(r0_l[k], r0_l[k] + h_l[k]), slice(c0_l[k], c0_l[k] + w_l[k]))
            tile[0][cut] = elev[off_l[k] : off_l[k] + h_l[k] * w_l[k]].reshape(h_l[k], w_l[k])
            tile[1][cut] = avoid[off_l[k] : off_l[k] + h_l[k] * w_l[k]].reshape(h_l[k], w_l[k])
        self.stats["tiles_rasterised"] += g

    def _cache_moving_boxes(self, cell: float, ids: IntArray) -> None:
        """Rasterise the moving boxes ``ids`` not cached yet, all in one vectorised call."""
        store = self._box_rasters.get(cell)
        if store is None:
            store = self._box_rasters[cell] = _BoxRasters(self._box_center.shape[0])
        todo = ids[store.batch[ids] < 0]
        if todo.size == 0:
            return
        lo = self._box_lo[todo].min(axis=0)
        hi = self._box_hi[todo].max(axis=0)
        i0 = math.floor(lo[1] / cell) - 1
        j0 = math.floor(lo[0] / cell) - 1
        shape = (math.ceil(hi[1] / cell) + 2 - i0, math.ceil(hi[0] / cell) + 2 - j0)
        origin = np.array([j0 * cell, i0 * cell])
        half = 0.5 * self._box_size[todo]
        which, r, c = raster_boxes(origin, cell, shape, self._box_center[todo, :2], half[:, 0], half[:, 1],
                                   self._box_yaw[todo])
        # (raster_boxes gives the cells box by box: no sort needed)
        r, c = r + i0, c + j0
        bounds = np.searchsorted(which, np.arange(todo.size + 1))
        top = (self._box_center[:, 2][todo] + self._box_size[:, 2][todo])[which]
        store.add(todo, bounds, (r, c, top))
        self.stats["moving_rasterised"] += int(todo.size)

    def _moving_soup_cells(self, cell: float, ident: int) -> tuple[IntArray, IntArray, FloatArray]:
        """Lattice cells (I, J) and heights covered by one moving soup, cached until it moves."""
        key = (cell, "soup", ident)
        hit = self._moving_raster.get(key)
        off = self._offset(ident)
        if hit is not None:
            made_at = self._raster_offset.get(key, np.zeros(3))
            if np.array_equal(made_at[:2], off[:2]):
                if made_at[2] == off[2]:
                    return hit
                # Only lifted or lowered: the same cells, every height shifted.
                hit = (hit[0], hit[1], hit[2] + (off[2] - made_at[2]))
                self._moving_raster[key] = hit
                self._raster_offset[key] = off.copy()
                return hit
        soup = self._soups[ident]
        v = soup.vertices + off
        lo = v[:, :2].min(axis=0)
        hi = v[:, :2].max(axis=0)
        i0 = math.floor(lo[1] / cell) - 1
        j0 = math.floor(lo[0] / cell) - 1
        shape = (math.ceil(hi[1] / cell) + 2 - i0, math.ceil(hi[0] / cell) + 2 - j0)
        origin = np.array([j0 * cell, i0 * cell])
        _, r, c, z = raster_triangles(origin, cell, shape, v[soup.faces])
        order = np.argsort(r, kind="stable")  # by row, for windows to take theirs
        out = (r[order] + i0, c[order] + j0, z[order])
        self._moving_raster[key] = out
        self._raster_offset[key] = off.copy()
        self.stats["moving_rasterised"] += 1
        return out

    def window(self, center_xy: npt.ArrayLike, params: WindowParams | None = None) -> WindowGrids:
        """The grids of the ``n_cells`` × ``n_cells`` window nearest to ``center_xy`` ``(2,)``.

        The window is snapped to the world lattice (its centre is within half a cell of
        ``center_xy``). Static content comes from cached tiles; moving boxes and meshes that
        overlap the window are pasted from their cached rasters (re-rasterised only after
        they moved). For many characters prefer :meth:`windows` (one batch for all).
        """
        return self.windows(np.asarray(center_xy, dtype=np.float64).reshape(1, 2), params)[0]

    def windows(
        self, centers_xy: npt.ArrayLike, params: WindowParams | Sequence[WindowParams] | None = None
    ) -> list[WindowGrids]:
        """:meth:`window` for many characters at once (``(n, 2)`` centres): the moving boxes
        near any of them are rasterised in a single vectorised batch, once per move.
        ``params``: one :class:`WindowParams` for every window, or one per centre (the foot
        shape and cell may differ; windows of one size share one elevation stack)."""
        ctr = np.asarray(centers_xy, dtype=np.float64).reshape(-1, 2)
        m = ctr.shape[0]
        if params is None or isinstance(params, WindowParams):
            plist = [params if params is not None else WindowParams()] * m
        else:
            plist = list(params)
            if len(plist) != m:
                raise ValueError("give one WindowParams per centre, or one for all")
        if m == 0:
            return []
        cells = np.array([float(prm.cell) for prm in plist])
        sides = np.array([int(prm.n_cells) for prm in plist], dtype=np.intp)
        # each window's cell [0, 0] on the world lattice, and its bounds with a cell of margin
        i0s = np.rint(ctr[:, 1] / cells).astype(np.intp) - sides // 2
        j0s = np.rint(ctr[:, 0] / cells).astype(np.intp) - sides // 2
        lo_w = np.column_stack([j0s, i0s]) * cells[:, None] - cells[:, None]
        hi_w = lo_w + (sides + 1)[:, None] * cells[:, None]
        self._fill_static(cells, sides, i0s, j0s)
        near_boxes = self._near_moving_boxes(lo_w, hi_w, cells, sides)
        # windows of one size share one stack (whatever their cells)
        groups: dict[int, list[int]] = {}
        for w, n in enumerate(sides.tolist()):
            groups.setdefault(n, []).append(w)
        out: list[WindowGrids | None] = [None] * m
        for n, ws in groups.items():
            made = self._windows_of(n, cells[ws], i0s[ws], j0s[ws], lo_w[ws], hi_w[ws],
                                    [near_boxes[w] for w in ws], [plist[w] for w in ws])
            for w, grids in zip(ws, made, strict=True):
                out[w] = grids
        return [g for g in out if g is not None]

    def _near_moving_boxes(
        self, lo_w: FloatArray, hi_w: FloatArray, cells: FloatArray, sides: IntArray
    ) -> list[IntArray]:
        """The moving boxes near each window (bounds ``lo_w``, ``hi_w`` ``(m, 2)``: whose xy
        bounds reach them, their lower x at most the widest box's width before the window),
        their rasters made for the windows' cell sizes: one batch per window size and cell
        size (a moving box's raster is cut from its batch's lattice). The candidates come
        from the moving boxes' point-query index (every box in every bucket its bounds
        reach: a box reaching a window is in one of its buckets), for every window at once;
        each window's boxes in increasing order."""
        m = lo_w.shape[0]
        if not self._dynamic_boxes.size:
            return [np.zeros(0, dtype=np.intp)] * m
        rect, box, _ = self._moving_box_candidates(lo_w, hi_w, None)
        # (window, box) once each, by window then box
        n_all = self._box_center.shape[0]
        key = np.unique(rect * n_all + box)
        rect, box = np.divmod(key, n_all)
        blo, bhi = self._box_lo, self._box_hi
        lx = blo[:, 0][box]
        ok = ((lx >= (lo_w[:, 0] - self._widest_moving())[rect]) & (lx <= hi_w[:, 0][rect])
              & (bhi[:, 0][box] >= lo_w[:, 0][rect]) & (bhi[:, 1][box] >= lo_w[:, 1][rect])
              & (blo[:, 1][box] <= hi_w[:, 1][rect]))
        rect, box = rect[ok], box[ok]
        cuts = np.searchsorted(rect, np.arange(m + 1)).tolist()
        near_arrays = [box[cuts[w] : cuts[w + 1]] for w in range(m)]
        batches: dict[tuple[int, float], list[int]] = {}
        for w, (n, cell) in enumerate(zip(sides.tolist(), cells.tolist(), strict=True)):
            batches.setdefault((n, cell), []).append(w)
        for (_, cell), ws in batches.items():
            todo = box if len(ws) == m else np.concatenate([near_arrays[w] for w in ws])
            self._cache_moving_boxes(cell, np.unique(todo))
        return near_arrays

    def _widest_moving(self) -> float:
        """The widest moving box's x extent (kept until a box moves)."""
        if self._dynamic_widest is None:
            d = self._dynamic_boxes
            self._dynamic_widest = float(np.max(self._box_hi[:, 0][d] - self._box_lo[:, 0][d]))
        return self._dynamic_widest

    def moving_near(self, lo: FloatArray, hi: FloatArray) -> BoolArray:
        """``(m,)`` whether a moving box's or moving mesh's ground footprint (its xy bounds)
        may reach each rectangle ``[lo, hi]`` (``(m, 2)`` each, world xy) now: True for every
        rectangle one reaches (and for some it only comes within a nanometre of, or that is
        more than a few metres across). Where it is False, every point query inside the
        rectangle answers what the static scene alone does (and did at any earlier time when
        it was False too).

        The moving boxes: each rectangle is tested against the bounds of the boxes in its
        buckets of the moving boxes' point-query index."""
        m = lo.shape[0]
        out = np.zeros(m, dtype=bool)
        if m == 0:
            return out
        if self._dynamic_boxes.size:
            out = self._moving_boxes_reach(lo, hi)
        for i, soup in enumerate(self._soups):
            if soup.dynamic and soup.faces.shape[0]:
                _, t_lo, t_hi = self._soup_triangles(i)
                off = self._offset(i)[:2]
                s_lo = t_lo.min(axis=0) + off
                s_hi = t_hi.max(axis=0) + off
                out |= np.all((s_hi >= lo) & (s_lo <= hi), axis=1)
        return out

    def _moving_boxes_reach(self, lo: FloatArray, hi: FloatArray) -> BoolArray:
        """``(m,)`` whether a moving box's xy bounds, a nanometre larger each way (the point
        queries' own rounding is far below it), reach each rectangle ``[lo, hi]`` (``(m, 2)``
        each); rectangles over more than 36 buckets of the index count as reached. The boxes
        looked at: those in the rectangle's buckets of the moving boxes' point-query index
        (every box is in every bucket its bounds reach)."""
        m = lo.shape[0]
        if self._dynamic_index().n == 0:
            return np.zeros(m, dtype=bool)
        eps = 1e-9
        rect, box, wide = self._moving_box_candidates(lo - eps, hi + eps, 36)
        blo, bhi = self._box_lo, self._box_hi
        hit = ((blo[:, 0][box] - eps <= hi[:, 0][rect]) & (bhi[:, 0][box] + eps >= lo[:, 0][rect])
               & (blo[:, 1][box] - eps <= hi[:, 1][rect]) & (bhi[:, 1][box] + eps >= lo[:, 1][rect]))
        out = wide.copy()
        out[rect[hit]] = True
        return out

    def _moving_box_candidates(
        self, lo: FloatArray, hi: FloatArray, most: int | None
    ) -> tuple[IntArray, IntArray, BoolArray]:
        """(rectangle, moving box) pairs of the boxes in the buckets of the moving boxes'
        point-query index each rectangle ``[lo, hi]`` (``(m, 2)`` each) covers (a box once
        per bucket), and which rectangles cover more than ``most`` buckets (None: no limit;
        those are left out)."""
        index = self._dynamic_index()
        m = lo.shape[0]
        nby, nbx = index.shape
        ox, oy = float(index.origin[0]), float(index.origin[1])
        bucket = index.bucket
        x0 = np.maximum(np.floor((lo[:, 0] - ox) / bucket), 0.0).astype(np.intp)
        x1 = np.minimum(np.floor((hi[:, 0] - ox) / bucket), nbx - 1.0).astype(np.intp)
        y0 = np.maximum(np.floor((lo[:, 1] - oy) / bucket), 0.0).astype(np.intp)
        y1 = np.minimum(np.floor((hi[:, 1] - oy) / bucket), nby - 1.0).astype(np.intp)
        wx = np.maximum(x1 - x0 + 1, 0)
        count = wx * np.maximum(y1 - y0 + 1, 0)
        wide = count > most if most is not None else np.zeros(m, dtype=bool)
        count[wide] = 0
        # (rectangle, bucket) pairs, then (rectangle, box) pairs: the buckets' item ranges
        rect, local = _ranges_to_pairs(np.zeros(m, dtype=np.intp), count - 1)
        key = (y0[rect] + local // wx[rect]) * nbx + x0[rect] + local % wx[rect]
        first = index.offsets[key]
        pair, at = _ranges_to_pairs(first, index.offsets[key + 1] - 1)
        return rect[pair], self._dynamic_boxes[index.items[at]], wide

    def _dynamic_index(self) -> _BucketIndex:
        """The moving boxes' point-query index (built at the first query after they moved)."""
        if self._box_index_dynamic is None:
            d = self._dynamic_boxes
            self._box_index_dynamic = _BucketIndex(self._box_lo[d], self._box_hi[d])
        return self._box_index_dynamic

    def _windows_of(
        self, n: int, cells: FloatArray, i0s: IntArray, j0s: IntArray, lo_w: FloatArray, hi_w: FloatArray,
        near_boxes: list[IntArray], plist: list[WindowParams],
    ) -> list[WindowGrids]:
        """The windows of one size ``n`` (cell sizes ``cells (m,)``, cell [0, 0] at lattice
        cell ``(i0s, j0s)``, bounds ``lo_w``, ``hi_w``, the moving boxes ``near_boxes`` near
        each): their static grids copied from the tiles into one stack ``(m, n, n)``, then
        every moving box's and moving mesh's cached raster near each of them pasted into that
        stack at once (one ``maximum.at`` for all windows; each window's grids are its slice
        of the stack)."""
        m = cells.size
        i0_list, j0_list, cell_list = i0s.tolist(), j0s.tolist(), cells.tolist()
        elev_all = np.empty((m, n, n))
        avoid_all = np.empty((m, n, n), dtype=bool)
        for w in range(m):
            self._static_window(cell_list[w], n, i0_list[w], j0_list[w], elev_all[w], avoid_all[w])
        # The moving pieces near each window: every (window, box) pair's cells, read from the
        # boxes' rasters at once per cell size, then each moving mesh's raster.
        parts: list[tuple[IntArray, IntArray, IntArray, FloatArray, BoolArray]] = []
        if self._dynamic_boxes.size:
            sizes = [near.size for near in near_boxes]
            pair_window = np.repeat(np.arange(m), sizes)
            pair_box = np.concatenate(near_boxes) if m else np.zeros(0, dtype=np.intp)
            for cell in set(cell_list):
                sel = np.flatnonzero(cells[pair_window] == cell) if len(set(cell_list)) > 1 else None
                boxes = pair_box if sel is None else pair_box[sel]
                at, r_b, c_b, z_b = self._box_rasters[cell].cells(boxes)
                pair = at if sel is None else sel[at]
                parts.append((pair_window[pair], r_b, c_b, z_b, self._box_role[pair_box[pair]] == ROLE_AVOID))
        pieces: list[tuple[IntArray, IntArray, FloatArray]] = []
        piece_window: list[int] = []
        piece_avoid: list[bool] = []
        for i, soup in enumerate(self._soups):
            if not (soup.dynamic and soup.faces.shape[0]):
                continue
            _, t_lo, t_hi = self._soup_triangles(i)
            s_lo = t_lo.min(axis=0) + self._offset(i)[:2]
            s_hi = t_hi.max(axis=0) + self._offset(i)[:2]
            for w in range(m):
                if np.all(s_hi >= lo_w[w]) and np.all(s_lo <= hi_w[w]):
                    r, c, z = self._moving_soup_cells(cell_list[w], i)
                    # The raster is sorted by row: only the window's rows are taken (a moving
                    # ground of a million triangles covers far more than one window).
                    a, b = np.searchsorted(r, [i0_list[w], i0_list[w] + n])
                    pieces.append((r[a:b], c[a:b], z[a:b]))
                    piece_window.append(w)
                    piece_avoid.append(soup.role == ROLE_AVOID)
        if pieces:
            sizes = [p[0].size for p in pieces]
            parts.append((np.repeat(np.asarray(piece_window, dtype=np.intp), sizes),
                          np.concatenate([p[0] for p in pieces]), np.concatenate([p[1] for p in pieces]),
                          np.concatenate([p[2] for p in pieces]),
                          np.repeat(np.asarray(piece_avoid, dtype=bool), sizes)))
        if parts:  # (pasting takes maxima and sets flags: the order of the cells does not matter)
            win = np.concatenate([q[0] for q in parts])
            r = np.concatenate([q[1] for q in parts]) - i0s[win]
            c = np.concatenate([q[2] for q in parts]) - j0s[win]
            z = np.concatenate([q[3] for q in parts])
            av = np.concatenate([q[4] for q in parts])
            ok = (r >= 0) & (r < n) & (c >= 0) & (c < n)
            at = (win * n + r) * n + c
            np.maximum.at(elev_all.reshape(-1), at[ok], z[ok])
            avoid_all.reshape(-1)[at[ok & av]] = True
        self.stats["windows"] += m
        out: list[WindowGrids] = []
        for w in range(m):
            prm = plist[w]
            half = (float(prm.foot_half_extents[0]), float(prm.foot_half_extents[1]))
            cell = cell_list[w]
            origin = np.array([j0_list[w] * cell, i0_list[w] * cell])
            out.append(WindowGrids(origin, cell, elev_all[w], avoid_all[w], half, float(prm.foot_yaw),
                                   stack=(elev_all, w)))
        return out

    def _static_window(
        self, cell: float, n: int, i0: int, j0: int, elev: FloatArray, avoid: BoolArray
    ) -> None:
        """The static grids of the window whose cell [0, 0] is lattice cell (i0, j0), copied
        from the tiles (filled there by :meth:`_fill_static`) into ``elev`` and ``avoid``
        ``(n, n)``."""
        t = self.tile_cells
        for ti in range(i0 // t, (i0 + n - 1) // t + 1):
            r_lo = max(i0, ti * t)
            r_hi = min(i0 + n, (ti + 1) * t)
            for tj in range(j0 // t, (j0 + n - 1) // t + 1):
                c_lo = max(j0, tj * t)
                c_hi = min(j0 + n, (tj + 1) * t)
                te, ta = self._tiles[(cell, ti, tj)]
                dst = (slice(r_lo - i0, r_hi - i0), slice(c_lo - j0, c_hi - j0))
                src = (slice(r_lo - ti * t, r_hi - ti * t), slice(c_lo - tj * t, c_hi - tj * t))
                elev[dst] = te[src]
                avoid[dst] = ta[src]

    def rasterise(
        self, origin: npt.ArrayLike, cell: float, shape: tuple[int, int]
    ) -> tuple[FloatArray, BoolArray]:
        """Elevation and avoid grids of any rectangle, without caches (reference/debugging)."""
        o = np.asarray(origin, dtype=np.float64).reshape(2)
        elev = self._heightmap_cells(o, cell, shape)
        avoid = np.zeros(shape, dtype=bool)
        self._raster_into(o, cell, elev, avoid, np.arange(self._box_center.shape[0]), range(len(self._soups)))
        return elev, avoid
