# SPDX-License-Identifier: GPL-3.0-or-later
"""Test worlds for the biped planner, after the biped thesis' evaluation (§4.1).

* ``corridor`` — a straight 2 m wide walkway;
* ``curve`` — a curved walkway (a ring sector);
* ``turns`` — a walkway with a sequence of bends ending on a curved platform, walking
  only (the thesis' "Turns");
* ``jumps`` — walk, bend, run, jump a gap, sharp bend, jump a second gap, stop (the
  thesis' "Jumps"): three platforms, so the only route jumps twice;
* ``stairs`` — a walkway with a flight of steps up to a landing and down again (0.15 m
  rises, 0.35 m treads, as in the example scene), filling its width: the only route climbs.

Used by the tests and the benchmark; all flat (z = 0) unless stated.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .surface import WalkableSurface, arc_band, rectangle

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Scenario:
    """A walkable world with a start pose and a goal."""

    name: str
    polygons: tuple[FloatArray, ...]
    start_pos: FloatArray
    start_yaw: float
    goal: FloatArray
    allow_run: bool = True
    gaps: tuple[FloatArray, ...] = ()
    cell: float = 0.05

    def surface(self, cell: float | None = None) -> WalkableSurface:
        return WalkableSurface.from_polygons(list(self.polygons), cell=self.cell if cell is None else cell)


def _box(x0: float, x1: float, y0: float, y1: float, z: float = 0.0) -> FloatArray:
    return rectangle((0.5 * (x0 + x1), 0.5 * (y0 + y1), z), (x1 - x0, y1 - y0))


def _strip(points: Sequence[tuple[float, float]], width: float, z: float = 0.0) -> list[FloatArray]:
    """A walkway of the given width along a polyline: a rectangle per segment and an
    octagon at each inner corner to fill the joint."""
    polys = []
    pts = np.asarray(points, dtype=float)
    for a, b in itertools.pairwise(pts):
        d = b - a
        length = float(np.linalg.norm(d))
        c = 0.5 * (a + b)
        polys.append(rectangle((c[0], c[1], z), (length, width), float(np.arctan2(d[1], d[0]))))
    for p in pts[1:-1]:
        ang = np.linspace(0.0, 2 * np.pi, 9)[:-1] + np.pi / 8
        r = 0.5 * width / np.cos(np.pi / 8)
        polys.append(np.column_stack((p[0] + r * np.cos(ang), p[1] + r * np.sin(ang), np.full(8, z))))
    return polys


def corridor() -> Scenario:
    return Scenario(
        "corridor", (_box(-1.0, 13.0, -1.0, 1.0),), np.array([0.0, 0.0, 0.0]), 0.0, np.array([11.0, 0.3])
    )


def curve() -> Scenario:
    band = arc_band((0.0, 5.0, 0.0), 4.2, 5.8, -np.pi / 2 - 0.15, 0.35 * np.pi, n=32)
    return Scenario(
        "curve",
        tuple(band),
        np.array([0.0, 0.0, 0.0]),
        0.0,
        np.array([5.0 * np.cos(0.3 * np.pi), 5.0 + 5.0 * np.sin(0.3 * np.pi)]),
    )


def turns() -> Scenario:
    path = [(-1.0, 0.0), (4.0, 0.0), (7.0, 2.5), (10.0, 2.5), (12.5, 0.0), (15.0, 0.0)]
    polys = _strip(path, 1.6)
    polys += arc_band((15.0, 4.0, 0.0), 3.2, 4.8, -np.pi / 2 - 0.05, 0.25 * np.pi, n=24)
    goal_angle = 0.2 * np.pi
    goal = np.array([15.0 + 4.0 * np.cos(goal_angle), 4.0 + 4.0 * np.sin(goal_angle)])
    return Scenario("turns", tuple(polys), np.array([0.0, 0.0, 0.0]), 0.0, goal, allow_run=False)


def jumps(length: float = 1.0) -> Scenario:
    """Three platforms: an L, a second L across a 1.3 m gap, a last one across another 1.3 m
    gap. ``length`` stretches the walkways (not the gaps)."""
    a, y0 = 9.0 * length, 7.0 * length
    first = [_box(-1.0, a, -1.0, 1.0), _box(a - 2.0, a, -1.0, y0)]
    second = [_box(a - 2.0, a, y0 + 1.3, y0 + 4.0), _box(2.0, a, y0 + 2.0, y0 + 4.0)]
    third = [_box(-5.0 * length, 0.7, y0 + 2.0, y0 + 4.0)]
    gaps = (_box(a - 2.0, a, y0, y0 + 1.3), _box(0.7, 2.0, y0 + 2.0, y0 + 4.0))
    goal = np.array([-3.5 * length, y0 + 3.0])
    return Scenario("jumps", tuple(first + second + third), np.array([0.0, 0.0, 0.0]), 0.0, goal, gaps=gaps)


STAIR_RISE = 0.15
STAIR_TREAD = 0.35
STAIR_START = 3.0
STAIR_LANDING = 1.5


def stair_treads(steps: int = 3) -> list[tuple[float, float, float]]:
    """``(x0, x1, height)`` of every tread of :func:`stairs`, the landing included."""
    out = []
    x = STAIR_START
    for k in range(1, steps + 1):
        out.append((x, x + STAIR_TREAD, k * STAIR_RISE))
        x += STAIR_TREAD
    top = (steps + 1) * STAIR_RISE
    out.append((x, x + STAIR_LANDING, top))
    x += STAIR_LANDING
    for k in range(steps, 0, -1):
        out.append((x, x + STAIR_TREAD, k * STAIR_RISE))
        x += STAIR_TREAD
    return out


def stairs(goal: tuple[float, float] = (9.0, 0.0), steps: int = 3) -> Scenario:
    """Ground, ``steps`` steps up to a landing one rise higher, as many steps down, ground
    again, all 1.6 m wide. Rasterised at 2.5 cm: a 35 cm tread leaves a foot only a few
    centimetres of play, which a coarser raster would not resolve."""
    treads = stair_treads(steps)
    polys = [_box(-1.0, STAIR_START, -0.8, 0.8)]
    polys += [_box(x0, x1, -0.8, 0.8, z) for x0, x1, z in treads]
    polys.append(_box(treads[-1][1], treads[-1][1] + 4.0, -0.8, 0.8))
    return Scenario(
        "stairs", tuple(polys), np.array([0.0, 0.0, 0.0]), 0.0, np.array(goal, dtype=float), cell=0.025
    )


SCENARIOS = {"corridor": corridor, "curve": curve, "turns": turns, "jumps": jumps, "stairs": stairs}
