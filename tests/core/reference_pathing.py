# SPDX-License-Identifier: GPL-3.0-or-later
"""One-at-a-time versions of the batched path steps, kept as readable references for the tests.

The product (:mod:`procloco_addon.core.world.pathing`) computes each step for many grids, segments
or plans at once (:func:`~procloco_addon.core.world.pathing.wavefront_each`,
:func:`~procloco_addon.core.world.pathing.segments_clear_each`,
:func:`~procloco_addon.core.world.pathing.turning_each`,
:func:`~procloco_addon.core.world.pathing._hull_knots_increasing`); its one-grid functions are
one-line calls of those. Here each step is written out for one grid, one segment or one
polyline, and the tests compare the two (decisions exactly, floats to
:mod:`tests.core.cross_path`'s tolerance).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from procloco_addon.core.geometry import planar_length
from procloco_addon.core.hull import upper_hull
from procloco_addon.core.world.pathing import (
    _COLLINEAR,
    MOVE_LENGTH,
    MOVES,
    DistanceField,
    _chord_tolerance,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]


def _move_costs(free: BoolArray) -> list[FloatArray]:
    """Per move, the cost of entering each cell (``inf`` if the move is not allowed);
    ``free`` ``(h, w)``."""
    h, w = free.shape
    pad = np.zeros((h + 2, w + 2), dtype=bool)
    pad[1:-1, 1:-1] = free
    costs = []
    for (dr, dc), length in zip(MOVES, MOVE_LENGTH, strict=True):
        ok = free.copy()
        if dr and dc:  # no corner cutting: both side cells must be free
            ok &= pad[1 - dr : h + 1 - dr, 1 : w + 1] & pad[1 : h + 1, 1 - dc : w + 1 - dc]
        costs.append(np.where(ok, length, np.inf))
    return costs


def wavefront(free: BoolArray, source: tuple[int, int], max_iterations: int | None = None) -> DistanceField:
    """Octile distance field from ``source`` over the ``free`` cells ``(h, w)``.

    Whole-array relaxation (every move, every cell, per sweep) until nothing changes; each
    sweep costs a few numpy operations on the region, and the number of sweeps is about the
    longest path's length in cells. The source is always treated as free.
    """
    h, w = free.shape
    fr = free.copy()
    fr[source] = True
    costs = _move_costs(fr)
    dist = np.full((h + 2, w + 2), np.inf)
    dist[source[0] + 1, source[1] + 1] = 0.0
    inner = dist[1:-1, 1:-1]
    limit = max_iterations if max_iterations is not None else h * w + 1
    iterations = 0
    cand = np.empty((h, w))
    before = np.empty((h, w))
    shifted = [dist[1 - dr : h + 1 - dr, 1 - dc : w + 1 - dc] for dr, dc in MOVES]
    while iterations < limit:
        np.copyto(before, inner)
        for view, cost in zip(shifted, costs, strict=True):
            np.add(view, cost, out=cand)
            np.minimum(inner, cand, out=inner)
        iterations += 1
        if np.array_equal(before, inner):
            break
    # Parent move of every reached cell: the move that realises its distance.
    stacked = np.stack([view + cost for view, cost in zip(shifted, costs, strict=True)])
    parent = np.argmin(stacked, axis=0).astype(np.int8)
    parent[~np.isfinite(inner)] = -1
    parent[source] = -1
    return DistanceField(inner.copy(), parent, (int(source[0]), int(source[1])), iterations)


def hull_waypoints(s: FloatArray, required: FloatArray, min_gap: float) -> IntArray:
    """Upper-hull vertices of ``(s, required)``, without vertices closer than ``min_gap`` to
    the previous one when the chord that replaces them still clears every sample."""
    hull = upper_hull(s, required, collinear=_COLLINEAR).tolist()
    if len(hull) <= 2 or min_gap <= 0.0:
        return np.asarray(hull, dtype=np.intp)
    keep = [hull[0]]
    for pos in range(1, len(hull) - 1):
        v = hull[pos]
        if s[v] - s[keep[-1]] >= min_gap:
            keep.append(v)
            continue
        a, c = keep[-1], hull[pos + 1]
        seg = slice(a, c + 1)
        chord = required[a] + (required[c] - required[a]) * (s[seg] - s[a]) / max(s[c] - s[a], 1e-12)
        if np.all(chord >= required[seg] - _chord_tolerance(min_gap)):
            continue  # removable: the straight chord still clears
        keep.append(v)
    keep.append(hull[-1])
    return np.asarray(keep, dtype=np.intp)


def turning(samples: FloatArray) -> float:
    """Total absolute heading change along a 2D polyline, in radians."""
    d = np.diff(samples, axis=0)
    d = d[planar_length(d[:, 0], d[:, 1]) > 1e-9]
    if d.shape[0] < 2:
        return 0.0
    ang = np.arctan2(d[:, 1], d[:, 0])
    turn = np.diff(ang)
    turn = (turn + np.pi) % (2.0 * np.pi) - np.pi
    return float(np.sum(np.abs(turn)))
