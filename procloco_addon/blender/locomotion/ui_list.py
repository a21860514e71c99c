# SPDX-License-Identifier: GPL-3.0-or-later
"""The legs list of the Rig & Legs panel: one row per leg (label, hip > end-effector, why
it was chosen, on/off)."""

from __future__ import annotations

from typing import Any

import bpy

from .generate import leg_reason

__all__ = ["PROCLOCO_UL_legs"]


class PROCLOCO_UL_legs(bpy.types.UIList):
    """Legs of the rig: gait label, hip and end-effector bones, enabled"""

    bl_idname = "PROCLOCO_UL_legs"

    def draw_item(self, context: Any, layout: Any, data: Any, item: Any, icon: int, active_data: Any,
                  active_propname: str, index: int = 0, flt_flag: int = 0) -> None:
        if self.layout_type in {"DEFAULT", "COMPACT"}:
            row = layout.row(align=True)
            row.prop(item, "enabled", text="")
            sub = row.row(align=True)
            sub.active = item.enabled
            sub.label(text=item.label or item.name, icon="BONE_DATA")
            chain = f"{item.hip} > {item.end}" if item.hip or item.end else "choose bones"
            sub.label(text=chain)
            # why detection chose it: reaches the ground, mirrored pair, name
            sub.label(text=leg_reason(item) or "by hand")
            if item.controls:
                sub.label(text=item.controls, icon="CON_KINEMATIC")
        else:
            layout.alignment = "CENTER"
            layout.label(text=item.label or item.name)
