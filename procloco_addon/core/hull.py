# SPDX-License-Identifier: GPL-3.0-or-later
"""Upper convex hulls of height profiles (thesis §3.2.2, §3.4.2, §4.2.3).

The thesis uses the convex hull of elevated points in three places: the 3D foot trajectory
rests on the hull of the elevated path samples, the pelvis height and pitch come from the hull
of the ground under the body box and the feet, and spine nodes take their elevation the same
way. In every case only the *upper* hull of a height profile matters: points ``(x, z)``
where ``x`` is a position along a horizontal direction and ``z`` a height.

- :func:`upper_hull` — the hull's vertices of one profile (monotone chain, ``O(n log n)``).
- :func:`upper_hull_eval` — the hull's height and slope at query positions, for a batch of
  profiles at once (``(..., n)`` points, ``(..., m)`` queries; vectorised over the batch).
- :func:`project_along` and :func:`hull_height_and_pitch` — 3D points projected on a
  horizontal direction and the hull's height/pitch under given centres (pelvis, spine nodes).

Outside the profile's ``x`` range the hull is continued flat (the nearest end's height, slope
0): a pelvis slightly ahead of its last support keeps its height instead of extrapolating.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from .geometry import vector_norm

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]


def upper_hull(
    x: npt.ArrayLike, z: npt.ArrayLike, keep_collinear: bool = False, collinear: float = 0.0
) -> IntArray:
    """Indices of the upper hull's vertices of the points ``(x[i], z[i])``, by increasing x.

    ``x``, ``z``: ``(n,)``, ``n >= 1``, any order. Where several points share an ``x`` only
    the highest can be a vertex. Collinear points on a hull edge are dropped unless
    ``keep_collinear``. Every input point lies on or below the polyline through the result.

    ``collinear``: a relative tolerance under which a point counts as collinear with its
    neighbours (dropped; it may then stand above the hull by that share of the edge): the
    cross product against the sum of its two terms' magnitudes. Points collinear in exact
    arithmetic (flat runs, linear ramps) then give the same hull whatever rounding or tiny
    input noise does to them, at any scale.
    """
    xa = np.asarray(x, dtype=np.float64).ravel()
    za = np.asarray(z, dtype=np.float64).ravel()
    if xa.shape != za.shape or xa.size == 0:
        raise ValueError("x and z must be non-empty and the same length")
    # Sort by x, then by descending z so the highest of equal-x points comes first.
    order = np.lexsort((-za, xa))
    xs = xa[order].tolist()
    zs = za[order].tolist()
    idx = order.tolist()
    hull: list[int] = []  # positions into xs/zs
    for k in range(len(xs)):
        if hull and xs[hull[-1]] == xs[k]:
            continue  # lower duplicate x: never on the upper hull
        while len(hull) >= 2:
            i, j = hull[-2], hull[-1]
            # Cross product of (j - i) and (k - i); >= 0 means j is not strictly above ik.
            a = (xs[j] - xs[i]) * (zs[k] - zs[i])
            b = (zs[j] - zs[i]) * (xs[k] - xs[i])
            cross = a - b
            tol = collinear * (abs(a) + abs(b))
            if cross > tol or (cross >= -tol and not keep_collinear):
                hull.pop()
            else:
                break
        hull.append(k)
    return np.asarray([idx[k] for k in hull], dtype=np.intp)


def upper_hull_eval(
    x: npt.ArrayLike,
    z: npt.ArrayLike,
    xq: npt.ArrayLike,
    valid: npt.ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Height and slope of the upper hull at query positions, batched.

    ``x``, ``z``: ``(..., n)`` profiles; ``xq``: ``(..., m)`` queries (same batch shape);
    ``valid``: optional ``(..., n)`` mask of the points to use (each profile needs at least
    one). Returns ``(height, slope)``, each ``(..., m)``. At a hull vertex the slope is the
    mean of the two edges' slopes (a central difference).

    Uses the fact that in 1D the upper hull at ``q`` is the best interpolation over all pairs
    ``x_i <= q <= x_j`` (Carathéodory), which vectorises over the batch: ``O(n²)`` per query,
    fine for the tens of points a body or a spine samples.
    """
    xa = np.asarray(x, dtype=np.float64)
    za = np.asarray(z, dtype=np.float64)
    qa = np.asarray(xq, dtype=np.float64)
    mask = np.ones(xa.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    # Flat continuation outside the range: clamp queries into [min x, max x].
    xmin = np.where(mask, xa, np.inf).min(axis=-1, keepdims=True)
    xmax = np.where(mask, xa, -np.inf).max(axis=-1, keepdims=True)
    q = np.minimum(np.maximum(qa, xmin), xmax)  # (np.clip without its dispatch)
    eps = 1e-7 * np.maximum(1.0, xmax - xmin)
    q_lo = np.maximum(q - eps, xmin)
    q_hi = np.minimum(q + eps, xmax)
    m = qa.shape[-1]
    heights = _hull_heights(xa, za, np.concatenate([q, q_lo, q_hi], axis=-1), mask)
    height, h_lo, h_hi = heights[..., :m], heights[..., m : 2 * m], heights[..., 2 * m :]
    span = q_hi - q_lo
    slope = np.where(span > 0.0, (h_hi - h_lo) / np.where(span > 0.0, span, 1.0), 0.0)
    outside = (qa < xmin) | (qa > xmax)
    return height, np.where(outside, 0.0, slope)


@functools.lru_cache(maxsize=16)
def _pairs(n: int) -> IntArray:
    """``(2 P,)``: the first points of the ``P`` pairs ``i <= j`` of ``n`` points, then their
    second points (read only)."""
    i_of, j_of = np.triu_indices(n)
    out = np.concatenate([i_of, j_of]).astype(np.intp)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=16)
def _rows(b: int) -> IntArray:
    """``(b, 1)``: the row index of each of ``b`` rows (read only)."""
    out = np.arange(b, dtype=np.intp)[:, None]
    out.flags.writeable = False
    return out


def _hull_heights(xa: FloatArray, za: FloatArray, q: FloatArray, mask: BoolArray) -> FloatArray:
    # The points of each profile sorted by x: a pair (i, j) with x_i > x_j can only count
    # where x_i == x_j == q, as the pair (j, i) does with the same height, so the pairs
    # i <= j hold every height that counts. What does not depend on the queries is found
    # once per pair; the interpolation, the test x_i <= q <= x_j and the maximum run over
    # (profile, query, pair), the pairs last: an operation on a profile's pairs runs along
    # them whatever the number of profiles (a spine's few profiles, a crowd's hundreds).
    n = xa.shape[-1]
    m = q.shape[-1]
    ij = _pairs(n)
    n_pairs = ij.shape[0] // 2
    xz = np.empty((2, *xa.shape))  # x and z of every profile, sorted together
    xz[0] = xa
    xz[1] = za
    xz = xz.reshape(2, -1, n)
    order = np.argsort(xz[0], axis=1, kind="stable")  # (B, n)
    at = (_rows(order.shape[0]), order)
    ok = mask.reshape(-1, n)[at]
    xz = np.where(ok, xz[:, at[0], at[1]], 0.0)
    ends = xz.take(ij, axis=2)  # (2, B, 2 P): x, z of every pair's first points, then second points
    xi, xj = ends[0, :, :n_pairs], ends[0, :, n_pairs:]  # (B, P)
    zi, zj = ends[1, :, :n_pairs], ends[1, :, n_pairs:]
    ok_ends = ok.take(ij, axis=1)  # (take: a gather along a last axis twice as fast as indexing)
    pair = ok_ends[:, :n_pairs] & ok_ends[:, n_pairs:]
    dx = xj - xi
    wide = (dx > 1e-12) & pair
    # a pair without width (a point exactly at q, or equal x) gives its higher point's height
    # (its slope -0.0: adding -0.0 * run, run >= 0, leaves any height as it is)
    slope = np.where(wide, (zj - zi) / np.where(wide, dx, 1.0), -0.0)
    base = np.where(wide, zi, np.where(pair, np.maximum(zi, zj), -np.inf))
    qs = q.reshape(-1, m, 1)  # (B, m, 1)
    run = qs - xi[:, None, :]  # (B, m, P): q - x_i
    inside = run >= 0.0
    inside &= qs <= xj[:, None, :]
    val = slope[:, None, :] * run
    val += base[:, None, :]
    np.copyto(val, -np.inf, where=~inside)
    return np.asarray(np.maximum.reduce(val, axis=2).reshape(q.shape))


def project_along(
    points: npt.ArrayLike, origin_xy: npt.ArrayLike, direction_xy: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Signed horizontal positions along ``direction_xy`` and heights of 3D points.

    ``points``: ``(..., n, 3)``; ``origin_xy``, ``direction_xy``: ``(..., 2)`` (the direction
    need not be unit). Returns ``(x, z)``, each ``(..., n)``.
    """
    pts = np.asarray(points, dtype=np.float64)
    origin = np.asarray(origin_xy, dtype=np.float64)
    direction = np.asarray(direction_xy, dtype=np.float64)
    norm = vector_norm(direction, keepdims=True)
    unit = direction / np.where(norm > 1e-12, norm, 1.0)
    # (the two products summed written out, x and y apart: a sum of two does not depend on
    # its order, and the operations run along the points instead of over pairs)
    x = (pts[..., 0] - origin[..., 0, None]) * unit[..., 0, None]
    x += (pts[..., 1] - origin[..., 1, None]) * unit[..., 1, None]
    return x, pts[..., 2]


def hull_height_and_pitch(
    points: npt.ArrayLike,
    centre_xy: npt.ArrayLike,
    forward_xy: npt.ArrayLike,
    valid: npt.ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Height of the upper hull right under ``centre_xy`` and the pitch of the hull there.

    Thesis §3.2.2: the ground under the body box and the feet form a vertical slice along the
    body's forward axis; the pelvis sits on the upper hull of that slice and pitches with the
    hull's segment under its centre. ``points``: ``(..., n, 3)`` (ground samples under the
    body box and the feet), ``centre_xy``, ``forward_xy``: ``(..., 2)``, ``valid``: ``(..., n)``.
    Returns ``(height, pitch)``, each ``(...,)``; pitch in radians, positive nose up.
    """
    x, z = project_along(points, centre_xy, forward_xy)
    q = np.zeros((*x.shape[:-1], 1))
    height, slope = upper_hull_eval(x, z, q, valid)
    return height[..., 0], np.arctan(slope[..., 0])
