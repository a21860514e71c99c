# SPDX-License-Identifier: GPL-3.0-or-later
"""The Make Cycle sub-panel of the ProcLoco tab: cycles, root motion, and the button."""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..ui.main import PANEL_ORDER, RigPanel, active_rig
from .ops import PROCLOCO_OT_make_cycle

__all__ = ["PROCLOCO_PT_make_cycle"]


class PROCLOCO_PT_make_cycle(RigPanel, bpy.types.Panel):
    """A seamless loop of whole gait cycles for game engines, on flat ground"""

    bl_label = "Make Cycle"
    bl_order = PANEL_ORDER["generate"] + 10  # after Generate: a loop is made from a tuned walk
    bl_options: ClassVar[set[str]] = {"DEFAULT_CLOSED"}

    def draw(self, context: Any) -> None:
        layout = self.layout
        obj = active_rig(context)
        settings = obj.procloco_cycle
        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.prop(settings, "cycles")
        col.prop(settings, "root_motion")
        if settings.root_motion == "ROOT_BONE":
            col.prop_search(settings, "root_bone", obj.data, "bones", text="Root Bone")
        layout.label(text="Flat ground, straight, one gait and speed", icon="INFO")
        layout.operator(PROCLOCO_OT_make_cycle.bl_idname, icon="FILE_REFRESH")
