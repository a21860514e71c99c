# SPDX-License-Identifier: GPL-3.0-or-later
"""The gait changes list of the Gait panel: one row per change (frame, gait, speed)."""

from __future__ import annotations

from typing import Any

import bpy

__all__ = ["PROCLOCO_UL_gait_changes"]


class PROCLOCO_UL_gait_changes(bpy.types.UIList):
    """Changes of gait over the generated frames: frame, gait and speed"""

    bl_idname = "PROCLOCO_UL_gait_changes"

    def draw_item(self, context: Any, layout: Any, data: Any, item: Any, icon: int, active_data: Any,
                  active_propname: str, index: int = 0, flt_flag: int = 0) -> None:
        if self.layout_type in {"DEFAULT", "COMPACT"}:
            row = layout.row(align=True)
            row.label(text=f"{item.frame}", icon="TIME")
            row.label(text=item.name or "Gait")
            if item.use_speed:
                row.label(text=f"{item.speed:.2f} m/s")
        else:
            layout.alignment = "CENTER"
            layout.label(text=f"{item.frame}")
