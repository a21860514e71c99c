# SPDX-License-Identifier: GPL-3.0-or-later
"""The Quality sub-panel of Generate: what was measured on the rig's generated walk.

One row per figure (:data:`.property_group.FIGURES`): its name, its value, the design's
threshold and a button showing the worst frame, which jumps there. A row above its
threshold is drawn red (``layout.alert``). Figures measured on another Action than the
rig's current one are shown greyed, marked stale.
"""

from __future__ import annotations

from typing import Any

import bpy

from ..ui.main import SidebarPanel, active_rig
from . import measure
from .ops import PROCLOCO_OT_jump_to_worst_frame
from .property_group import FIGURES

__all__ = ["PROCLOCO_PT_quality", "draw_quality"]


def draw_quality(layout: Any, obj: Any) -> None:
    """The quality figures of ``obj`` drawn into ``layout`` (also used for the README's picture)."""
    q = obj.procloco.quality
    if not q.measured:
        layout.label(text="Generate Locomotion to measure the walk", icon="INFO")
        return
    current = measure.is_current(obj)
    if current:
        layout.label(text=f"Posed rig, frames {q.frame_start}-{q.frame_end}", icon="CHECKMARK")
    else:
        layout.label(text=f"Stale: measured on '{q.action}'", icon="ERROR")
        layout.label(text="The rig's Action changed: generate again")
    col = layout.column(align=True)
    col.active = current
    for key, label, _kind in FIGURES:
        row = col.row(align=True)
        row.alert = measure.failed(obj, key)
        split = row.split(factor=0.42, align=True)
        split.label(text=label)
        split = split.split(factor=0.55, align=True)
        split.label(text=measure.value_text(obj, key, short=True))
        leg = getattr(q, f"{key}_leg")
        sub = split.row(align=True)
        sub.enabled = bool(leg) and current
        text = f"{getattr(q, f'{key}_frame')}" if leg else "-"
        op = sub.operator(PROCLOCO_OT_jump_to_worst_frame.bl_idname, text=text, icon="TIME")
        op.figure = key
    # The thresholds (DESIGN.md, "What done means for the motion"), short enough for the sidebar.
    limits = [measure.limit_text(key)[4:] for key, _label, kind in FIGURES if kind == "length"]
    layout.label(text=f"Red above {', '.join(limits)}, or 0 frames")


class PROCLOCO_PT_quality(SidebarPanel, bpy.types.Panel):
    """What was measured on the generated walk, each figure with its worst frame"""

    bl_parent_id = "PROCLOCO_PT_generate"
    bl_label = "Quality"

    @classmethod
    def poll(cls, context: Any) -> bool:
        return active_rig(context) is not None

    def draw(self, context: Any) -> None:
        draw_quality(self.layout, active_rig(context))
