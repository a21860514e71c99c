# SPDX-License-Identifier: GPL-3.0-or-later
"""The list of the biped's clips in the Biped panel."""

from __future__ import annotations

from typing import Any

import bpy

__all__ = ["PROCLOCO_UL_biped_clips"]


class PROCLOCO_UL_biped_clips(bpy.types.UIList):
    """One row per clip: on/off, its Action and its role"""

    bl_idname = "PROCLOCO_UL_biped_clips"

    def draw_item(
        self,
        context: Any,
        layout: Any,
        data: Any,
        item: Any,
        icon: Any,
        active_data: Any,
        active_propname: str,
        index: int = 0,
        flt_flag: int = 0,
    ) -> None:
        row = layout.row(align=True)
        row.prop(item, "use", text="")
        sub = row.row(align=True)
        sub.active = bool(item.use)
        if item.action is None:
            sub.label(text="(no Action)", icon="ERROR")
        else:
            sub.label(text=item.action.name, icon="ACTION")
        sub.prop(item, "role", text="")
