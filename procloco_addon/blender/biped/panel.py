# SPDX-License-Identifier: GPL-3.0-or-later
"""The Biped sub-panel of the ProcLoco tab: clip list, goal, options, Plan Biped Footsteps."""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..ui.main import PANEL_ORDER, RigPanel, active_rig
from .ops import (
    PROCLOCO_OT_add_biped_clip,
    PROCLOCO_OT_make_biped_clips,
    PROCLOCO_OT_plan_biped_footsteps,
    PROCLOCO_OT_remove_biped_clip,
)
from .ui_list import PROCLOCO_UL_biped_clips

__all__ = ["PROCLOCO_PT_biped"]


class PROCLOCO_PT_biped(RigPanel, bpy.types.Panel):
    """Biped footprint planner: clips tagged by role, a goal, and Plan Biped Footsteps"""

    bl_label = "Biped"
    bl_order = PANEL_ORDER["biped"]
    bl_options: ClassVar[set[str]] = {"DEFAULT_CLOSED"}

    def draw(self, context: Any) -> None:
        layout = self.layout
        obj = active_rig(context)
        settings = obj.procloco_biped
        layout.label(text="Clips")
        row = layout.row()
        row.template_list(
            PROCLOCO_UL_biped_clips.bl_idname,
            "",
            settings,
            "clips",
            settings,
            "active_clip_index",
            rows=min(max(len(settings.clips), 3), 10),
        )
        col = row.column(align=True)
        col.operator(PROCLOCO_OT_add_biped_clip.bl_idname, text="", icon="ADD")
        col.operator(PROCLOCO_OT_remove_biped_clip.bl_idname, text="", icon="REMOVE")
        if 0 <= settings.active_clip_index < len(settings.clips):
            item = settings.clips[settings.active_clip_index]
            sub = layout.column()
            sub.use_property_split = True
            sub.use_property_decorate = False
            sub.prop(item, "action")
            sub.prop(item, "role")
        if not len(settings.clips):
            layout.label(text="Tag the rig's Actions by role, or make examples", icon="INFO")
        layout.operator(PROCLOCO_OT_make_biped_clips.bl_idname, icon="ACTION")

        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.prop(settings, "goal")
        col.prop(settings, "use_goal_heading")
        col.prop(settings, "allow_run")
        col.prop(settings, "use_blend_groups")
        col.prop(settings, "speed_change")
        col.prop(settings, "crossfade")
        col.prop(settings, "max_slope")
        col.prop(settings, "seed")
        row = col.row(heading="Start")
        row.prop(settings, "use_scene_start", text="Scene Start")
        sub = row.row()
        sub.active = not settings.use_scene_start
        sub.prop(settings, "start_frame", text="")
        big = layout.row()
        big.scale_y = 1.4
        big.operator(PROCLOCO_OT_plan_biped_footsteps.bl_idname, icon="MOD_DYNAMICPAINT")
