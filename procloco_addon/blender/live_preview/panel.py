# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Preview's rows in the Generate section: the toggle, its state or error, Discard."""

from __future__ import annotations

from typing import Any

from . import handler, preview
from .ops import PROCLOCO_OT_discard_live_preview

__all__ = ["draw_live_preview"]


def draw_live_preview(layout: Any, obj: Any) -> None:
    """Draw the Live Preview toggle of rig ``obj`` and what it is doing into ``layout``."""
    settings = obj.procloco
    row = layout.row(align=True)
    row.prop(settings, "live_preview", toggle=1, icon="PLAY" if not settings.live_preview else "PAUSE")
    row.operator(PROCLOCO_OT_discard_live_preview.bl_idname, text="", icon="TRASH")
    if settings.live_preview or preview.is_previewing(obj):
        handler.wake()  # (the timer stops when no rig is watched; a file loaded without the add-on)
    shown = handler.status(obj)
    col = layout.column(align=True)
    if shown.state == "error":
        col.alert = True
        col.label(text=f"Stopped: {shown.text}", icon="ERROR")
        col.label(text="Change the setting to try again")
    elif shown.state == "running":
        col.label(text=f"Updating: {shown.text} {int(100 * shown.fraction)}%", icon="SORTTIME")
    elif shown.state == "waiting":
        col.label(text="Waiting for the edits to settle", icon="TIME")
    elif shown.state == "idle":
        col.label(text="The rig's Action is not a preview: edit a setting to preview again", icon="INFO")
    elif shown.state == "ready":
        col.label(text="Up to date. Off keeps this walk", icon="CHECKMARK")
        for warning in shown.warnings[:2]:
            col.label(text=warning, icon="INFO")
