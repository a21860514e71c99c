# SPDX-License-Identifier: GPL-3.0-or-later
"""Keeps the gait picture current and draws the optional viewport overlay.

The panel shows the active rig's gait circles as a preview icon whose pixels are drawn
off screen by ``draw.render_gait_image``. Any change that could alter the picture
(a depsgraph update, a frame change, a file load, or the panel noticing that what it
shows is stale) calls :func:`request_refresh`; the redraw itself runs from a timer on
the next event-loop turn, so a burst of changes (dragging a slider) costs one redraw,
and it is skipped when nothing visible changed. In background mode nothing is drawn
automatically; :func:`flush` redraws on demand (tests, the PNG export tool).

The overlay is a ``SpaceView3D`` ``POST_PIXEL`` draw callback that draws the same
circles straight into the viewport's corner when switched on.

With Gait: Auto the circles are the gait Auto uses at the current frame
(``rig_gait.circles_at_frame``), and a second preview holds the Auto chart (the gait
bands and the rig's speed over the shot), kept current the same way.
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import draw, geometry, rig_gait

__all__ = [
    "CHART_SIZE",
    "OVERLAY_PALETTE",
    "PREVIEW_SIZE",
    "chart_icon_id",
    "chart_pixels",
    "chart_signature",
    "draw_overlay",
    "ensure_current",
    "flush",
    "icon_id",
    "overlay_layout",
    "overlay_rect",
    "preview",
    "preview_pixels",
    "refresh",
    "register",
    "request_refresh",
    "set_editing",
    "shown_signature",
    "unregister",
]

PREVIEW_SIZE = 256
_PREVIEW_NAME = "procloco_gait"
CHART_SIZE = (320, 160)
_CHART_NAME = "procloco_auto_chart"


class _State:
    previews: Any = None
    dirty: bool = True
    signature: tuple[Any, ...] | None = None
    chart_signature: tuple[Any, ...] | None = None
    draw_handle: Any = None
    editing: bool = False  # the overlay editor is running: draw the sector handles


_state = _State()


# -------------------------------------------------------------------- the preview image
def preview(name: str = _PREVIEW_NAME) -> Any:
    """The ImagePreview holding the panel's picture (None before ``register``)."""
    if _state.previews is None:
        return None
    previews = _state.previews
    return previews[name] if name in previews else previews.new(name)


def chart_icon_id() -> int:
    """Icon id of the Auto chart for ``layout.template_icon``; 0 when unavailable."""
    image = preview(_CHART_NAME)
    return int(image.icon_id) if image is not None else 0


def chart_pixels() -> np.ndarray:
    """The Auto chart currently shown, ``(h, w, 4)`` float32, rows bottom to top."""
    return _pixels_of(preview(_CHART_NAME))


def icon_id() -> int:
    """Icon id to show the picture with ``layout.template_icon``; 0 when unavailable."""
    image = preview()
    return int(image.icon_id) if image is not None else 0


def preview_pixels() -> np.ndarray:
    """The picture currently shown, ``(h, w, 4)`` float32, rows bottom to top."""
    return _pixels_of(preview())


def _pixels_of(image: Any) -> np.ndarray:
    if image is None:
        return np.zeros((0, 0, 4), np.float32)
    width, height = image.image_size
    pixels = np.empty(width * height * 4, dtype=np.float32)
    if pixels.size:
        image.image_pixels_float.foreach_get(pixels)
    return pixels.reshape(height, width, 4)


def shown_signature(context: Any = None) -> tuple[Any, ...] | None:
    """What the picture depends on for the active rig: labels, sectors, needle phase.

    None when there is no rig with a gait to show. Phases are rounded to 1/1000 of a
    cycle (a third of a degree), below what the picture can show.
    """
    ctx = bpy.context if context is None else context
    obj = getattr(ctx, "active_object", None)
    shown = rig_gait.circles_at_frame(obj, ctx.scene) if obj is not None else None
    if obj is None or shown is None:
        return None
    labels, start, duration, phase = shown
    return (
        obj.name,
        labels,
        tuple(np.round(start, 4)),
        tuple(np.round(duration, 4)),
        round(phase, 3) % 1.0,
    )


def chart_signature(context: Any = None) -> tuple[Any, ...] | None:
    """What the Auto chart depends on: the track's gaits, boundaries and speeds, the frame.
    None when the active rig is not in Auto."""
    ctx = bpy.context if context is None else context
    obj = getattr(ctx, "active_object", None)
    track = rig_gait.auto_track(obj, ctx.scene) if obj is not None else None
    if obj is None or track is None:
        return None
    return (obj.name, track.names, tuple(np.round(track.boundaries, 4)), track.recorded,
            hash(np.round(track.speed, 4).tobytes()), hash(track.band.tobytes()),
            track.index(ctx.scene.frame_current))


def ensure_current(context: Any = None) -> None:
    """Ask for a redraw if the picture no longer shows the active rig's gait (cheap)."""
    if shown_signature(context) != _state.signature or chart_signature(context) != _state.chart_signature:
        request_refresh()


def refresh(context: Any = None, *, force: bool = False) -> bool:
    """Redraw the preview for the active rig if what it shows changed. True if redrawn."""
    image = preview()
    if image is None or not draw.gpu_available():
        return False
    ctx = bpy.context if context is None else context
    drawn = _refresh_chart(ctx, force)
    signature = shown_signature(ctx)
    if signature == _state.signature and not force:
        if drawn:
            _tag_redraw()
        return drawn
    if signature is None:
        pixels = np.zeros((1, 1, 4), np.float32)
    else:
        shown = rig_gait.circles_at_frame(ctx.active_object, ctx.scene)
        assert shown is not None
        labels, start, duration, phase = shown
        pixels = draw.render_gait_image(start, duration, labels, phase,
                                        width=PREVIEW_SIZE, height=PREVIEW_SIZE)
    _set_pixels(image, pixels)
    _state.signature = signature
    _tag_redraw()
    return True


def _set_pixels(image: Any, pixels: np.ndarray) -> None:
    image.image_size = (pixels.shape[1], pixels.shape[0])
    image.image_pixels_float.foreach_set(pixels.ravel())


def _refresh_chart(ctx: Any, force: bool) -> bool:
    """Redraw the Auto chart if what it shows changed. True if redrawn."""
    image = preview(_CHART_NAME)
    signature = chart_signature(ctx)
    if image is None or (signature == _state.chart_signature and not force):
        return False
    if signature is None:
        pixels = np.zeros((1, 1, 4), np.float32)
    else:
        track = rig_gait.auto_track(ctx.active_object, ctx.scene)
        assert track is not None
        width, height = CHART_SIZE
        pixels = draw.render_auto_chart(track.names, track.boundaries, track.speed,
                                        track.index(ctx.scene.frame_current), width=width, height=height,
                                        band=track.band)
    _set_pixels(image, pixels)
    _state.chart_signature = signature
    return True


def flush(context: Any = None) -> bool:
    """Run a pending refresh now. True if the picture was redrawn."""
    if not _state.dirty:
        return False
    _state.dirty = False
    return refresh(context)


def request_refresh() -> None:
    """Mark the picture stale; outside background mode a timer redraws it soon."""
    _state.dirty = True
    if bpy.app.background or _state.previews is None:
        return
    if not bpy.app.timers.is_registered(_refresh_timer):
        bpy.app.timers.register(_refresh_timer, first_interval=0.0)


def _refresh_timer() -> None:
    try:
        flush()
    except Exception as error:  # a drawing failure must never break the event loop
        print(f"ProcLoco: could not redraw the gait circles: {error}")


_MSGBUS_OWNER = object()


def _tag_redraw() -> None:
    window_manager = getattr(bpy.context, "window_manager", None)
    for window in getattr(window_manager, "windows", ()):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


@persistent
def _on_depsgraph_update(_scene: Any, _depsgraph: Any = None) -> None:
    request_refresh()


@persistent
def _on_frame_change(_scene: Any, _depsgraph: Any = None) -> None:
    request_refresh()


def _subscribe_overlay_settings() -> None:
    """Redraw the viewports when an overlay setting changes (message bus; loading a file
    drops every subscription, so ``load_post`` subscribes again)."""
    from .property_group import OVERLAY_PROPERTIES, PROCLOCO_PG_gait_view

    bpy.msgbus.clear_by_owner(_MSGBUS_OWNER)
    for name in OVERLAY_PROPERTIES:
        bpy.msgbus.subscribe_rna(key=(PROCLOCO_PG_gait_view, name), owner=_MSGBUS_OWNER, args=(),
                                 notify=_tag_redraw)


@persistent
def _on_load_post(*_args: Any) -> None:
    _state.signature = None
    _state.chart_signature = None
    _subscribe_overlay_settings()
    request_refresh()


_HANDLERS = (
    (bpy.app.handlers.depsgraph_update_post, _on_depsgraph_update),
    (bpy.app.handlers.frame_change_post, _on_frame_change),
    (bpy.app.handlers.load_post, _on_load_post),
)


# -------------------------------------------------------------------- the viewport overlay
def overlay_rect(context: Any, region: Any, labels: tuple[str, ...]) -> tuple[float, float, int, int]:
    """(x, y, width, height) of the overlay in the 3D view's main ``region``, in region pixels."""
    view = context.window_manager.procloco_gait_view
    width, height = geometry.canvas_size(labels, view.overlay_cell)
    margin = 12
    corner = view.overlay_corner
    x = margin if corner.endswith("LEFT") else region.width - width - margin
    y = margin if corner.startswith("BOTTOM") else region.height - height - margin
    area = getattr(context, "area", None)
    if not corner.endswith("LEFT") and area is not None and context.preferences.system.use_region_overlap:
        # Keep clear of the sidebar, which covers the viewport's right side.
        x -= sum(r.width for r in area.regions if r.type == "UI" and r.width > 1)
    return float(x), float(y), width, height


def overlay_layout(context: Any, region: Any,
                   labels: tuple[str, ...]) -> tuple[geometry.CircleLayout, tuple[float, float]]:
    """The overlay's circle layout (in its own frame) and its offset in the region."""
    x, y, width, height = overlay_rect(context, region, labels)
    return geometry.layout_circles(labels, width, height), (x, y)


OVERLAY_PALETTE = draw.Palette(background=(0.0, 0.0, 0.0, 0.45))


def draw_overlay(context: Any, region: Any) -> bool:
    """Draw the active rig's gait circles in the corner of ``region`` (pixel projection
    already set, as in a ``POST_PIXEL`` callback). True if something was drawn."""
    view = getattr(context.window_manager, "procloco_gait_view", None)
    if view is None or not view.show_overlay or region is None:
        return False
    obj = getattr(context, "active_object", None)
    shown = rig_gait.circles_at_frame(obj, context.scene) if obj is not None else None
    if shown is None:
        return False
    labels, start, duration, phase = shown
    layout, offset = overlay_layout(context, region, labels)
    import gpu

    gpu.state.blend_set("ALPHA")
    draw.draw_gait(layout, start, duration, labels, phase, OVERLAY_PALETTE,
                   offset=offset, show_handles=_state.editing, background=True)
    gpu.state.blend_set("NONE")
    return True


def _draw_overlay() -> None:
    draw_overlay(bpy.context, bpy.context.region)


def set_editing(editing: bool) -> None:
    """Show or hide the sector handles in the overlay (the overlay editor runs)."""
    _state.editing = editing


# -------------------------------------------------------------------- (un)registration
def register() -> None:
    import bpy.utils.previews

    _state.previews = bpy.utils.previews.new()
    _state.signature = None
    _state.chart_signature = None
    _state.dirty = True
    for handlers, callback in _HANDLERS:
        if callback not in handlers:
            handlers.append(callback)
    _state.draw_handle = bpy.types.SpaceView3D.draw_handler_add(_draw_overlay, (), "WINDOW", "POST_PIXEL")
    _subscribe_overlay_settings()


def unregister() -> None:
    import bpy.utils.previews

    bpy.msgbus.clear_by_owner(_MSGBUS_OWNER)
    if _state.draw_handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_state.draw_handle, "WINDOW")
        _state.draw_handle = None
    for handlers, callback in _HANDLERS:
        while callback in handlers:
            handlers.remove(callback)
    if bpy.app.timers.is_registered(_refresh_timer):
        bpy.app.timers.unregister(_refresh_timer)
    if _state.previews is not None:
        bpy.utils.previews.remove(_state.previews)
        _state.previews = None
    _state.signature = None
    _state.chart_signature = None
    _state.editing = False
