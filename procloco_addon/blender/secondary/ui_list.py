# SPDX-License-Identifier: GPL-3.0-or-later
"""The chains list of the Secondary Motion panel: one row per chain (on/off, label, root > tip)."""

from __future__ import annotations

from typing import Any

import bpy

__all__ = ["PROCLOCO_UL_secondary_chains"]


class PROCLOCO_UL_secondary_chains(bpy.types.UIList):
    """Chains of swinging bones: enabled, label, root and tip bones"""

    bl_idname = "PROCLOCO_UL_secondary_chains"

    def draw_item(self, context: Any, layout: Any, data: Any, item: Any, icon: int, active_data: Any,
                  active_propname: str, index: int = 0, flt_flag: int = 0) -> None:
        if self.layout_type in {"DEFAULT", "COMPACT"}:
            row = layout.row(align=True)
            row.prop(item, "enabled", text="")
            sub = row.row(align=True)
            sub.active = item.enabled
            sub.label(text=item.name or "Chain", icon="FORCE_HARMONIC")
            if item.root and item.tip:
                sub.label(text=item.root if item.root == item.tip else f"{item.root} > {item.tip}")
            else:
                sub.label(text="choose bones")
        else:
            layout.alignment = "CENTER"
            layout.label(text=item.name or "Chain")
