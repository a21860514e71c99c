# SPDX-License-Identifier: GPL-3.0-or-later
"""Geometry of the gait-circle picture: where circles, sectors, needle and labels go.

Plain numpy, no ``bpy`` and no ``gpu``: ``draw.py`` turns these arrays into GPU
triangles, the overlay uses them for hit-testing, and tests use them to measure the
rendered image.

Conventions (thesis §3.3, figure 3.10): one circle per leg; phase 0 of the cycle is at
the top of the circle (12 o'clock) and phase grows **clockwise**, as the needle turns;
a leg's swing is the sector from ``swing_start`` to ``swing_start + swing_duration``
(fractions of the cycle, wrapping past 1). Pixel coordinates have their origin at the
bottom-left corner with y up, like GPU framebuffers and region drawing.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ChartLayout",
    "CircleLayout",
    "angle_to_phase",
    "annulus_sector_triangles",
    "canvas_size",
    "chart_layout",
    "drag_sector",
    "hit_test",
    "layout_circles",
    "leg_sides",
    "needle_quad",
    "phase_to_angle",
    "point_phase",
    "polyline_quads",
    "rect_triangles",
    "snap_phase",
    "swing_active",
    "wrap_phase",
]

# Ring proportions, as fractions of the circle radius.
RING_INNER = 0.58
NEEDLE_INNER = 0.52
NEEDLE_OUTER = 1.12
HANDLE_RADIUS = 0.16  # grab radius of a sector's start/end handle (fraction of the radius)

_LEFT = re.compile(r"(^L\d*$)|([._\-\s](l|left)$)|(^left)|(left$)", re.IGNORECASE)
_RIGHT = re.compile(r"(^R\d*$)|([._\-\s](r|right)$)|(^right)|(right$)", re.IGNORECASE)
_MID = re.compile(r"^M\d*$", re.IGNORECASE)


def wrap_phase(phase: np.ndarray | float) -> np.ndarray:
    """Phase(s) wrapped into [0, 1)."""
    wrapped = np.mod(np.asarray(phase, dtype=np.float64), 1.0)
    return np.where(wrapped >= 1.0, 0.0, wrapped)


def phase_to_angle(phase: np.ndarray | float) -> np.ndarray:
    """Mathematical angle (radians, counter-clockwise from +x) of a cycle phase.

    Phase 0 points up and phase grows clockwise: ``angle = π/2 − 2π·phase``.
    """
    return np.pi / 2.0 - 2.0 * np.pi * np.asarray(phase, dtype=np.float64)


def angle_to_phase(angle: np.ndarray | float) -> np.ndarray:
    """Inverse of :func:`phase_to_angle`, wrapped into [0, 1)."""
    return wrap_phase((np.pi / 2.0 - np.asarray(angle, dtype=np.float64)) / (2.0 * np.pi))


def swing_active(swing_start: np.ndarray, swing_duration: np.ndarray, phase: float) -> np.ndarray:
    """Which legs the needle at ``phase`` has in swing: ``(n_legs,)`` bool.

    A leg swings while ``(phase − swing_start) mod 1 < swing_duration``.
    """
    start = np.asarray(swing_start, dtype=np.float64)
    duration = np.asarray(swing_duration, dtype=np.float64)
    return np.asarray(wrap_phase(phase - start) < duration)


def leg_sides(labels: tuple[str, ...] | list[str]) -> np.ndarray:
    """Side of each leg from its label: −1 left, +1 right, 0 midline or unknown. ``(n_legs,)``.

    Understands the preset labels (``L1``, ``R2``, ``M3``) and common bone suffixes
    (``thigh.L``, ``leg_r``, ``LeftLeg``).
    """
    sides = np.zeros(len(labels), dtype=np.int64)
    for i, label in enumerate(labels):
        text = label.strip()
        if _MID.match(text):
            continue
        if _LEFT.search(text):
            sides[i] = -1
        elif _RIGHT.search(text):
            sides[i] = 1
    return sides


@dataclass(frozen=True)
class CircleLayout:
    """Where each leg's circle is drawn in a ``width × height`` pixel canvas.

    ``centers``: ``(n_legs, 2)`` pixel centres; ``radius``: outer radius in pixels (the
    same for every circle); ``label_pos``: ``(n_legs, 2)`` centre of each leg's label;
    ``font_size``: label height in pixels.
    """

    width: int
    height: int
    centers: np.ndarray
    radius: float
    label_pos: np.ndarray
    font_size: float

    @property
    def n_legs(self) -> int:
        return int(self.centers.shape[0])

    def contains(self, point: tuple[float, float]) -> bool:
        """True if ``point`` (pixels, canvas frame) is inside the canvas."""
        return 0.0 <= point[0] <= self.width and 0.0 <= point[1] <= self.height


def _rows_by_side(sides: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Grid cell (row, column) per leg, legs laid out like the body seen from above.

    Left legs go in column 0, right legs in column 2, midline legs in column 1 on a row
    of their own; legs are listed front to back, so each new pair starts a new row.
    Returns (rows, columns, n_rows); columns are in half-cells (0, 1, 2).
    """
    rows = np.zeros(len(sides), dtype=np.int64)
    cols = np.zeros(len(sides), dtype=np.int64)
    row = -1
    taken: set[int] = {0, 1, 2}
    for i, side in enumerate(sides):
        col = int(side) + 1
        if col == 1 or col in taken or 1 in taken:
            row += 1
            taken = set()
        rows[i], cols[i] = row, col
        taken.add(col)
    return rows, cols, row + 1


def _grid(labels: tuple[str, ...] | list[str]) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Per leg (row, column position) and the grid's (n_rows, n_cols)."""
    n = len(labels)
    sides = leg_sides(labels)
    if np.any(sides != 0) and n > 1:
        rows, half_cols, n_rows = _rows_by_side(sides)
        # half-column 0 → column 0, 2 → column 1, 1 (midline) → between them
        return rows, half_cols / 2.0, n_rows, 2
    n_cols = max(1, math.ceil(math.sqrt(n)))
    n_rows = max(1, math.ceil(n / n_cols))
    idx = np.arange(n)
    return idx // n_cols, (idx % n_cols).astype(np.float64), n_rows, n_cols


def canvas_size(labels: tuple[str, ...] | list[str], cell: int) -> tuple[int, int]:
    """(width, height) in pixels giving each circle a ``cell × cell`` square."""
    _rows, _cols, n_rows, n_cols = _grid(labels)
    return n_cols * cell, n_rows * cell


def layout_circles(labels: tuple[str, ...] | list[str], width: int, height: int,
                   *, margin: float = 0.04) -> CircleLayout:
    """Place one circle per leg in the canvas.

    When every leg has a side (left/right/midline) the circles form the body's plan
    (left column, right column, front at the top); otherwise a near-square grid in list
    order. Each cell keeps room around the ring for the needle's overhang.
    """
    n = len(labels)
    if n == 0:
        empty = np.zeros((0, 2))
        return CircleLayout(width, height, empty, 0.0, empty, 0.0)
    rows, col_pos, n_rows, n_cols = _grid(labels)
    pad = margin * min(width, height)
    cell_w = (width - 2 * pad) / n_cols
    cell_h = (height - 2 * pad) / n_rows
    radius = 0.5 * min(cell_w, cell_h) / NEEDLE_OUTER * 0.96
    cx = pad + (col_pos + 0.5) * cell_w
    cy = height - pad - (rows + 0.5) * cell_h
    centers = np.stack([cx, cy], axis=1).astype(np.float64)
    font_size = max(8.0, 0.34 * radius)
    return CircleLayout(width, height, centers, float(radius), centers.copy(), float(font_size))


def annulus_sector_triangles(center: np.ndarray, r_inner: float, r_outer: float,
                             start_phase: float, duration: float, *, step_deg: float = 1.0) -> np.ndarray:
    """Triangles ``(m, 3, 2)`` filling the ring between ``r_inner`` and ``r_outer`` from
    ``start_phase`` clockwise over ``duration`` of the cycle (a full ring when ≥ 1)."""
    duration = float(np.clip(duration, 0.0, 1.0))
    if duration <= 0.0:
        return np.zeros((0, 3, 2))
    n_seg = max(1, math.ceil(duration * 360.0 / step_deg))
    phases = start_phase + duration * np.linspace(0.0, 1.0, n_seg + 1)
    angles = phase_to_angle(phases)
    unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    inner = np.asarray(center, dtype=np.float64) + r_inner * unit
    outer = np.asarray(center, dtype=np.float64) + r_outer * unit
    a, b = inner[:-1], outer[:-1]
    c, d = outer[1:], inner[1:]
    first = np.stack([a, b, c], axis=1)
    second = np.stack([a, c, d], axis=1)
    return np.concatenate([first, second], axis=0)


def needle_quad(center: np.ndarray, radius: float, phase: float, *, thickness: float = 2.0) -> np.ndarray:
    """Two triangles ``(2, 3, 2)`` drawing the needle at ``phase`` as a radial bar that
    crosses the ring and sticks out past it."""
    angle = float(phase_to_angle(phase))
    direction = np.array([math.cos(angle), math.sin(angle)])
    normal = np.array([-direction[1], direction[0]]) * (thickness / 2.0)
    c = np.asarray(center, dtype=np.float64)
    p0 = c + NEEDLE_INNER * radius * direction
    p1 = c + NEEDLE_OUTER * radius * direction
    a, b, cc, d = p0 - normal, p1 - normal, p1 + normal, p0 + normal
    return np.array([[a, b, cc], [a, cc, d]])


def hit_test(layout: CircleLayout, swing_start: np.ndarray, swing_duration: np.ndarray,
             point: tuple[float, float]) -> tuple[int, str] | None:
    """What a pointer at ``point`` (pixels, canvas frame) would grab.

    Returns ``(leg, "START")`` or ``(leg, "END")`` when the point is near the start or end
    edge of a leg's swing sector on its ring, ``(leg, "MOVE")`` inside the sector,
    ``(leg, "RING")`` on the stance part of the ring, or None off the rings. Handles win
    over the ring; the nearer handle wins when both are close (very short sectors).
    """
    if layout.n_legs == 0:
        return None
    p = np.asarray(point, dtype=np.float64)
    offsets = p[None, :] - layout.centers
    dist = np.linalg.norm(offsets, axis=1)
    leg = int(np.argmin(dist))
    r = layout.radius
    if not (RING_INNER * r - HANDLE_RADIUS * r <= dist[leg] <= r + HANDLE_RADIUS * r):
        return None
    ring_mid = 0.5 * (RING_INNER + 1.0) * r
    best: tuple[float, str] | None = None
    for name, phase in (("START", swing_start[leg]), ("END", swing_start[leg] + swing_duration[leg])):
        angle = float(phase_to_angle(phase))
        handle = layout.centers[leg] + ring_mid * np.array([math.cos(angle), math.sin(angle)])
        d = float(np.linalg.norm(p - handle))
        if d <= HANDLE_RADIUS * r * 1.6 and (best is None or d < best[0]):
            best = (d, name)
    if best is not None:
        return leg, best[1]
    phase = float(angle_to_phase(math.atan2(offsets[leg, 1], offsets[leg, 0])))
    inside = bool(swing_active(np.array([swing_start[leg]]), np.array([swing_duration[leg]]), phase)[0])
    return leg, "MOVE" if inside else "RING"


def point_phase(layout: CircleLayout, leg: int, point: tuple[float, float]) -> float:
    """Cycle phase under ``point`` on leg ``leg``'s circle, in [0, 1)."""
    offset = np.asarray(point, dtype=np.float64) - layout.centers[leg]
    return float(angle_to_phase(math.atan2(offset[1], offset[0])))


MIN_DURATION = 0.02  # the shortest swing the editor allows (a zero swing is not a gait)


def snap_phase(phase: float, step: float) -> float:
    """``phase`` rounded to a multiple of ``step`` (no rounding when ``step`` is 0)."""
    if step <= 0.0:
        return float(phase)
    return float(wrap_phase(round(phase / step) * step))


def drag_sector(handle: str, start: float, duration: float, grab_phase: float, phase: float, *,
                previous_duration: float | None = None,
                min_duration: float = MIN_DURATION) -> tuple[float, float]:
    """New (swing_start, swing_duration) when a sector's handle is dragged to ``phase``.

    ``handle`` is "START" (the end stays), "END" (the start stays) or "MOVE" (the whole
    sector turns by ``phase − grab_phase``); ``start``/``duration`` are the values when the
    drag began. The duration stays within [min_duration, 1 − min_duration]; when the
    pointer crosses the fixed edge, it sticks to the nearer limit instead of jumping from
    a full cycle to nothing (``previous_duration`` is the last value shown).
    """
    lo, hi = min_duration, 1.0 - min_duration
    if handle == "MOVE":
        return float(wrap_phase(start + (phase - grab_phase))), float(duration)
    if handle == "START":
        end = start + duration
        new_duration = float(wrap_phase(end - phase))
    elif handle == "END":
        new_duration = float(wrap_phase(phase - start))
    else:
        raise ValueError(f"unknown handle {handle!r}")
    last = duration if previous_duration is None else previous_duration
    if abs(new_duration - last) > 0.5:  # wrapped past the fixed edge
        new_duration = hi if last > 0.5 else lo
    new_duration = min(max(new_duration, lo), hi)
    if handle == "START":
        return float(wrap_phase(start + duration - new_duration)), new_duration
    return float(wrap_phase(start)), new_duration


# ---------------------------------------------------------------------------- Auto gait chart
@dataclass(frozen=True, eq=False)
class ChartLayout:
    """The Auto gait chart in pixels: the rig's speed over the shot across the gait bands.

    Frames run left to right over the plot, speeds bottom to top from 0 to ``v_max`` m/s.
    ``plot``: ``(x0, y0, x1, y1)``; ``bands``: ``(B, 4)`` rectangles ``x0, y0, x1, y1`` of
    the gaits' speed ranges (first gait at the bottom); ``curve``: ``(F, 2)`` the speed at
    each frame; ``marker_x``: the current frame's x (None outside the shot)."""

    width: int
    height: int
    plot: tuple[float, float, float, float]
    v_max: float
    bands: np.ndarray
    curve: np.ndarray
    marker_x: float | None

    def speed_y(self, speed: np.ndarray | float) -> np.ndarray:
        y0, y1 = self.plot[1], self.plot[3]
        share = np.clip(np.asarray(speed, dtype=np.float64) / self.v_max, 0.0, 1.0)
        return np.asarray(y0 + (y1 - y0) * share)


def chart_layout(boundaries: np.ndarray, speed: np.ndarray, frame_index: int | None,
                 width: int, height: int, margin: float = 6.0, axis: float = 14.0) -> ChartLayout:
    """Place the chart for gait boundaries ``(B - 1,)`` m/s and speeds ``(F,)`` m/s in a
    ``width × height`` picture; ``frame_index`` marks the current frame (None: no marker).
    The speed axis reaches a bit past the highest of the speeds and the last boundary."""
    edges = np.asarray(boundaries, dtype=np.float64).reshape(-1)
    v = np.asarray(speed, dtype=np.float64).reshape(-1)
    top = max(float(v.max(initial=0.0)) * 1.15, float(edges.max(initial=0.0)) * 1.3, 1e-6)
    x0, y0, x1, y1 = margin + axis * 2.2, margin + axis, width - margin, height - margin
    plot = (x0, y0, x1, y1)
    layout = ChartLayout(width, height, plot, top, np.zeros((0, 4)), np.zeros((0, 2)), None)
    lows = np.concatenate([[0.0], edges])
    highs = np.concatenate([edges, [top]])
    bands = np.column_stack([np.full(lows.size, x0), layout.speed_y(lows), np.full(lows.size, x1),
                             layout.speed_y(highs)])
    n = max(v.size - 1, 1)
    xs = x0 + (x1 - x0) * np.arange(v.size) / n
    curve = np.column_stack([xs, layout.speed_y(v)])
    marker = None
    if frame_index is not None and 0 <= frame_index < v.size:
        marker = float(xs[frame_index])
    return ChartLayout(width, height, plot, top, bands, curve, marker)


def polyline_quads(points: np.ndarray, thickness: float) -> np.ndarray:
    """Triangles ``(2 (n - 1), 3, 2)`` of a polyline ``(n, 2)`` drawn ``thickness`` pixels wide."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] < 2:
        return np.zeros((0, 3, 2))
    a, b = p[:-1], p[1:]
    d = b - a
    length = np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    normal = np.column_stack([-d[:, 1], d[:, 0]]) / length * (0.5 * thickness)
    q0, q1, q2, q3 = a - normal, b - normal, b + normal, a + normal
    return np.concatenate([np.stack([q0, q1, q2], axis=1), np.stack([q0, q2, q3], axis=1)])


def rect_triangles(rects: np.ndarray) -> np.ndarray:
    """Triangles ``(2 m, 3, 2)`` of axis-aligned rectangles ``(m, 4)`` (x0, y0, x1, y1)."""
    r = np.asarray(rects, dtype=np.float64).reshape(-1, 4)
    a = r[:, [0, 1]]
    b = r[:, [2, 1]]
    c = r[:, [2, 3]]
    d = r[:, [0, 3]]
    return np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])

