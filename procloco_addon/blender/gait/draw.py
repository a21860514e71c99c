# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait circles drawn with Blender's ``gpu`` module.

One drawing routine, :func:`draw_gait`, issues the GPU calls in pixel coordinates. It
is used three ways: into an off-screen buffer read back as an RGBA array
(:func:`render_gait_image`, shown in the panel through a preview icon and exported as
PNG for the documentation), and directly in the 3D viewport's corner as an overlay.
The geometry itself (angles, rings, needle, label places) lives in ``geometry.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import blf
import bpy
import gpu
import numpy as np
from gpu_extras.batch import batch_for_shader
from mathutils import Matrix

from . import geometry
from .geometry import CircleLayout

__all__ = [
    "BAND_COLORS",
    "DEFAULT_PALETTE",
    "LINE_COLORS",
    "Palette",
    "draw_auto_chart",
    "draw_gait",
    "ensure_gpu_context",
    "gpu_available",
    "render_auto_chart",
    "render_gait_image",
    "render_offscreen",
]

Color = tuple[float, float, float, float]


@dataclass(frozen=True)
class Palette:
    """Colours of the picture (RGBA, display space)."""

    background: Color = (0.114, 0.114, 0.114, 1.0)
    ring: Color = (0.33, 0.33, 0.33, 1.0)
    swing: Color = (0.85, 0.45, 0.10, 1.0)
    swing_active: Color = (1.0, 0.78, 0.25, 1.0)
    needle: Color = (0.30, 0.70, 1.0, 1.0)
    label: Color = (0.88, 0.88, 0.88, 1.0)
    handle: Color = (1.0, 1.0, 1.0, 1.0)


DEFAULT_PALETTE = Palette()
_FONT_ID = 0


_gpu_ready = False


def gpu_available() -> bool:
    """True when GPU drawing works in this process (always in the UI; in background
    mode only after something created a GPU context)."""
    global _gpu_ready
    if not _gpu_ready:
        try:
            gpu.types.GPUOffScreen(1, 1).free()
        except (SystemError, RuntimeError):
            return False
        _gpu_ready = True
    return True


def ensure_gpu_context() -> None:
    """Make GPU drawing available in background mode by rendering a tiny Workbench frame.

    Blender only creates its GPU context on first use by a renderer; the temporary scene,
    camera and render result made for that are removed again.
    """
    if gpu_available():
        return
    had_result = "Render Result" in bpy.data.images
    scene = bpy.data.scenes.new("procloco-gpu-init")
    camera_data = bpy.data.cameras.new("procloco-gpu-init")
    camera = bpy.data.objects.new("procloco-gpu-init", camera_data)
    try:
        scene.collection.objects.link(camera)
        scene.camera = camera
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x = scene.render.resolution_y = 4
        with bpy.context.temp_override(scene=scene):
            bpy.ops.render.render(write_still=False, scene=scene.name)
    finally:
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(camera_data)
        bpy.data.scenes.remove(scene)
        if not had_result and "Render Result" in bpy.data.images:
            bpy.data.images.remove(bpy.data.images["Render Result"])
    if not gpu_available():
        raise RuntimeError("could not create a GPU context for drawing")


def _colored_triangles(parts: list[tuple[np.ndarray, Color]]) -> tuple[np.ndarray, np.ndarray]:
    """Flatten (triangles (m, 3, 2), colour) pairs into vertex positions and colours."""
    positions = [tris.reshape(-1, 2) for tris, _ in parts if len(tris)]
    colors = [np.tile(np.asarray(color, dtype=np.float32), (tris.shape[0] * 3, 1))
              for tris, color in parts if len(tris)]
    if not positions:
        return np.zeros((0, 2), np.float32), np.zeros((0, 4), np.float32)
    return (np.ascontiguousarray(np.concatenate(positions), dtype=np.float32),
            np.ascontiguousarray(np.concatenate(colors), dtype=np.float32))


def _disc_triangles(center: np.ndarray, radius: float, segments: int = 24) -> np.ndarray:
    return geometry.annulus_sector_triangles(center, 0.0, radius, 0.0, 1.0, step_deg=360.0 / segments)


def gait_triangles(layout: CircleLayout, swing_start: np.ndarray, swing_duration: np.ndarray,
                   phase: float | None, palette: Palette = DEFAULT_PALETTE, *,
                   show_handles: bool = False, offset: tuple[float, float] = (0.0, 0.0),
                   needle_thickness: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertex positions ``(k, 2)`` and colours ``(k, 4)`` of every filled shape, in drawing order."""
    start = np.asarray(swing_start, dtype=np.float64)
    duration = np.asarray(swing_duration, dtype=np.float64)
    active = (geometry.swing_active(start, duration, phase) if phase is not None
              else np.zeros(len(start), dtype=bool))
    r = layout.radius
    r_in = geometry.RING_INNER * r
    thickness = needle_thickness if needle_thickness is not None else max(1.5, r * 0.045)
    parts: list[tuple[np.ndarray, Color]] = []
    shift = np.asarray(offset, dtype=np.float64)
    for leg in range(layout.n_legs):
        c = layout.centers[leg] + shift
        parts.append((geometry.annulus_sector_triangles(c, r_in, r, 0.0, 1.0), palette.ring))
        color = palette.swing_active if active[leg] else palette.swing
        parts.append((geometry.annulus_sector_triangles(c, r_in, r, start[leg], duration[leg]), color))
        # A small notch outside the ring marks phase 0 (the top).
        parts.append((geometry.annulus_sector_triangles(c, r * 1.02, r * 1.07, -0.004, 0.008), palette.ring))
        if show_handles:
            ring_mid = 0.5 * (geometry.RING_INNER + 1.0) * r
            for ph in (start[leg], start[leg] + duration[leg]):
                angle = float(geometry.phase_to_angle(ph))
                at = c + ring_mid * np.array([np.cos(angle), np.sin(angle)])
                parts.append((_disc_triangles(at, geometry.HANDLE_RADIUS * r * 0.55), palette.handle))
        if phase is not None:
            parts.append((geometry.needle_quad(c, r, phase, thickness=thickness), palette.needle))
    return _colored_triangles(parts)


def draw_gait(layout: CircleLayout, swing_start: np.ndarray, swing_duration: np.ndarray,
              labels: tuple[str, ...] | list[str], phase: float | None,
              palette: Palette = DEFAULT_PALETTE, *, offset: tuple[float, float] = (0.0, 0.0),
              show_handles: bool = False, background: bool = False) -> None:
    """Draw the gait circles into the bound framebuffer, in pixel coordinates.

    The caller sets a pixel projection (the viewport's POST_PIXEL callbacks already have
    one). ``offset`` moves the picture (the overlay's corner); ``background`` fills the
    layout's rectangle first.
    """
    shader = gpu.shader.from_builtin("FLAT_COLOR")
    if background:
        x0, y0 = offset
        x1, y1 = x0 + layout.width, y0 + layout.height
        rect = np.array([[[x0, y0], [x1, y0], [x1, y1]], [[x0, y0], [x1, y1], [x0, y1]]])
        pos, col = _colored_triangles([(rect, palette.background)])
        batch_for_shader(shader, "TRIS", {"pos": pos, "color": col}).draw(shader)
    pos, col = gait_triangles(layout, swing_start, swing_duration, phase, palette,
                              show_handles=show_handles, offset=offset)
    if len(pos):
        batch_for_shader(shader, "TRIS", {"pos": pos, "color": col}).draw(shader)
    _draw_labels(layout, labels, swing_start, swing_duration, phase, palette, offset)


def _draw_labels(layout: CircleLayout, labels: tuple[str, ...] | list[str], swing_start: np.ndarray,
                 swing_duration: np.ndarray, phase: float | None, palette: Palette,
                 offset: tuple[float, float]) -> None:
    active = (geometry.swing_active(swing_start, swing_duration, phase) if phase is not None
              else np.zeros(layout.n_legs, dtype=bool))
    max_width = 2.0 * geometry.RING_INNER * layout.radius * 0.82
    for leg, text in enumerate(labels[: layout.n_legs]):
        size = layout.font_size
        blf.size(_FONT_ID, size)
        width, height = blf.dimensions(_FONT_ID, text)
        if width > max_width > 0:
            size = max(6.0, size * max_width / width)
            blf.size(_FONT_ID, size)
            width, height = blf.dimensions(_FONT_ID, text)
        x = layout.label_pos[leg, 0] + offset[0] - width / 2.0
        y = layout.label_pos[leg, 1] + offset[1] - height / 2.0
        color = palette.swing_active if active[leg] else palette.label
        blf.color(_FONT_ID, *color)
        blf.position(_FONT_ID, float(x), float(y), 0.0)
        blf.draw(_FONT_ID, text)


def _pixel_projection(width: int, height: int) -> Any:
    """Orthographic projection mapping pixel (0..width, 0..height) to clip space."""
    return Matrix((
        (2.0 / width, 0.0, 0.0, -1.0),
        (0.0, 2.0 / height, 0.0, -1.0),
        (0.0, 0.0, 1.0, 0.0),
        (0.0, 0.0, 0.0, 1.0),
    ))


def render_offscreen(width: int, height: int, draw_fn: Callable[[], None],
                     clear: Color = DEFAULT_PALETTE.background) -> np.ndarray:
    """Run ``draw_fn`` in a ``width × height`` off-screen buffer with a pixel projection
    and return the result, ``(height, width, 4)`` float32 RGBA, rows bottom to top."""
    offscreen = gpu.types.GPUOffScreen(width, height)
    flat = gpu.types.Buffer("FLOAT", width * height * 4)
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            framebuffer.clear(color=clear, depth=1.0)
            gpu.state.depth_test_set("NONE")  # 2D drawing; Blender 4.2 keeps a depth test on
            gpu.state.blend_set("ALPHA")
            with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
                gpu.matrix.load_matrix(Matrix.Identity(4))
                gpu.matrix.load_projection_matrix(_pixel_projection(width, height))
                draw_fn()
            gpu.state.blend_set("NONE")
            # A 1-D buffer: the (h, w, 4) buffer's memoryview reports wrong strides.
            framebuffer.read_color(0, 0, width, height, 4, 0, "FLOAT", data=flat)
    finally:
        offscreen.free()
    return np.frombuffer(flat, dtype=np.float32).reshape(height, width, 4).copy()


def render_gait_image(swing_start: np.ndarray, swing_duration: np.ndarray,
                      labels: tuple[str, ...] | list[str], phase: float | None, *,
                      width: int = 256, height: int = 256, palette: Palette = DEFAULT_PALETTE,
                      show_handles: bool = False) -> np.ndarray:
    """Draw the gait circles off screen and read them back.

    ``swing_start``, ``swing_duration``: ``(n_legs,)`` cycle fractions; ``labels``: one
    per leg; ``phase``: the needle's cycle phase, or None for no needle.
    Returns ``(height, width, 4)`` float32 RGBA in [0, 1], rows bottom to top (Blender's
    image order). Needs a GPU context (see :func:`ensure_gpu_context`).
    """
    layout = geometry.layout_circles(labels, width, height)

    def draw_fn() -> None:
        draw_gait(layout, swing_start, swing_duration, labels, phase, palette, show_handles=show_handles)

    return render_offscreen(width, height, draw_fn, palette.background)


# ---------------------------------------------------------------------------- Auto gait chart
#: Fill of each gait band of the Auto chart, slowest first (muted, so the curve stands out).
BAND_COLORS: tuple[Color, ...] = (
    (0.16, 0.30, 0.20, 1.0),  # walk, wave: green
    (0.18, 0.24, 0.38, 1.0),  # trot, tetrapod, run: blue
    (0.38, 0.20, 0.16, 1.0),  # gallop, tripod: red
    (0.33, 0.28, 0.14, 1.0),
)


#: The speed line where each gait is chosen (bright, in the hue of its band).
LINE_COLORS: tuple[Color, ...] = (
    (0.45, 1.0, 0.55, 1.0),
    (0.5, 0.75, 1.0, 1.0),
    (1.0, 0.55, 0.4, 1.0),
    (1.0, 0.9, 0.4, 1.0),
)


def draw_auto_chart(layout: geometry.ChartLayout, names: tuple[str, ...] | list[str],
                    boundaries: np.ndarray, palette: Palette = DEFAULT_PALETTE,
                    band: np.ndarray | None = None) -> None:
    """Draw the Auto gait chart (bands, the speed over the shot, the current frame) into the
    bound framebuffer, in pixel coordinates. ``band (F,)``: the gait chosen at each frame;
    the speed line takes that gait's colour, so the hysteresis shows where it changes."""
    shader = gpu.shader.from_builtin("FLAT_COLOR")
    parts: list[tuple[np.ndarray, Color]] = []
    for k, rect in enumerate(layout.bands):
        parts.append((geometry.rect_triangles(rect), BAND_COLORS[k % len(BAND_COLORS)]))
    curve = layout.curve
    if band is None or len(band) != curve.shape[0]:
        parts.append((geometry.polyline_quads(curve, 2.0), palette.label))
    else:
        chosen = np.asarray(band, dtype=np.int64)
        cuts = np.flatnonzero(np.diff(chosen)) + 1
        for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, chosen.size], strict=True):
            color = LINE_COLORS[int(chosen[lo]) % len(LINE_COLORS)]
            parts.append((geometry.polyline_quads(curve[max(lo - 1, 0):hi], 3.0), color))
    if layout.marker_x is not None:
        x = layout.marker_x
        _, y0, _, y1 = layout.plot
        parts.append((geometry.rect_triangles(np.array([x - 1.0, y0, x + 1.0, y1])), palette.needle))
    pos, col = _colored_triangles(parts)
    if len(pos):
        batch_for_shader(shader, "TRIS", {"pos": pos, "color": col}).draw(shader)
    size = max(8.0, min(13.0, layout.height / 12.0))
    blf.size(_FONT_ID, size)
    blf.color(_FONT_ID, *palette.label)
    x0, y0, x1, _ = layout.plot
    for k, rect in enumerate(layout.bands):
        name = names[k] if k < len(names) else ""
        _, h = blf.dimensions(_FONT_ID, name or "x")
        if rect[3] - rect[1] >= h + 2:
            blf.position(_FONT_ID, float(x0 + 4), float(rect[1] + 3), 0.0)
            blf.draw(_FONT_ID, name)
    # the speed axis: each boundary's speed at its edge, frames along the bottom
    for v, rect in zip(boundaries, layout.bands[1:], strict=False):
        text = f"{v:.2g}"
        w, h = blf.dimensions(_FONT_ID, text)
        blf.position(_FONT_ID, float(x0 - w - 3), float(rect[1] - 0.5 * h), 0.0)
        blf.draw(_FONT_ID, text)
    blf.position(_FONT_ID, float(x0 - blf.dimensions(_FONT_ID, "m/s")[0] - 3), float(y0), 0.0)
    blf.draw(_FONT_ID, "m/s")
    label = "speed over the shot"
    w, _ = blf.dimensions(_FONT_ID, label)
    blf.position(_FONT_ID, float(0.5 * (x0 + x1) - 0.5 * w), 3.0, 0.0)
    blf.draw(_FONT_ID, label)


def render_auto_chart(names: tuple[str, ...] | list[str], boundaries: np.ndarray, speed: np.ndarray,
                      frame_index: int | None, *, width: int = 320, height: int = 160,
                      palette: Palette = DEFAULT_PALETTE, band: np.ndarray | None = None) -> np.ndarray:
    """Draw the Auto gait chart off screen and read it back: ``names (B,)`` of the gaits,
    ``boundaries (B - 1,)`` m/s where each gait after the first begins, ``speed (F,)`` m/s
    over the shot, ``frame_index`` the current frame's index (or None), ``band (F,)`` the gait
    chosen at each frame (colours the speed line; None: plain). Returns
    ``(height, width, 4)`` float32 RGBA, rows bottom to top. Needs a GPU context."""
    layout = geometry.chart_layout(boundaries, speed, frame_index, width, height)

    def draw_fn() -> None:
        draw_auto_chart(layout, names, boundaries, palette, band)

    return render_offscreen(width, height, draw_fn, palette.background)

