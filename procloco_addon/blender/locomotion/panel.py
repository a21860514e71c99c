# SPDX-License-Identifier: GPL-3.0-or-later
"""Sub-panels of the ProcLoco tab for the locomotion feature: Rig & Legs, Locomotion, Terrain,
and the flexible spine's settings under Effects."""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..ui.main import PANEL_ORDER, PARENT, RigPanel, SidebarPanel, active_rig
from . import generate, handler
from .ops import PROCLOCO_OT_detect_legs
from .ui_list import PROCLOCO_UL_legs

__all__ = ["PROCLOCO_PT_locomotion", "PROCLOCO_PT_rig_legs", "PROCLOCO_PT_spine", "PROCLOCO_PT_terrain"]


class PROCLOCO_PT_rig_legs(RigPanel, bpy.types.Panel):
    """The rig's legs: detected automatically, each one editable"""

    bl_label = "Rig & Legs"
    bl_order = PANEL_ORDER["rig"]

    def draw(self, context: Any) -> None:
        layout = self.layout
        obj = active_rig(context)
        settings = obj.procloco
        row = layout.row(align=True)
        row.operator(PROCLOCO_OT_detect_legs.bl_idname, icon="VIEWZOOM")
        row.prop(settings, "forward_axis", text="")
        if not len(settings.legs):
            layout.label(text="Legs are detected when you generate; detect them to edit", icon="INFO")
            return
        handler.panel_drawn(obj)  # the chosen chains are drawn in the viewport while this is open
        layout.template_list(PROCLOCO_UL_legs.bl_idname, "", settings, "legs", settings, "active_leg_index",
                             rows=min(max(len(settings.legs), 3), 8))
        if any(leg.controls for leg in settings.legs):  # a control rig: which controls walk it
            row = layout.row()
            row.prop(settings, "drive_legs")
            if settings.controls_drive != settings.drive_legs:
                layout.label(text="Detect Legs again to list the controls this keys", icon="INFO")
        index = settings.active_leg_index
        if not 0 <= index < len(settings.legs):
            return
        leg = settings.legs[index]
        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.prop(leg, "label")
        col.prop_search(leg, "hip", obj.data, "bones", text="Hip")
        col.prop_search(leg, "end", obj.data, "bones", text="End-Effector")
        if leg.controls:
            col.label(text=f"Keys {leg.controls}", icon="CON_KINEMATIC")
        col.prop(leg, "offset")
        why = generate.leg_reason(leg)
        col.label(text=f"Why: {why}" if why else "Set by hand", icon="CHECKMARK" if why else "HAND")


class PROCLOCO_PT_locomotion(RigPanel, bpy.types.Panel):
    """How the rig walks: speed, direction or path, steps, frames and seed"""

    bl_label = "Locomotion"
    bl_order = PANEL_ORDER["locomotion"]

    def draw(self, context: Any) -> None:
        layout = self.layout
        settings = active_rig(context).procloco
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column()
        col.prop(settings, "speed")
        col.prop(settings, "path")
        sub = col.column()
        sub.active = settings.path is None
        sub.prop(settings, "heading")
        sub.prop(settings, "turn_rate")
        col.prop(settings, "step_height")
        col.prop(settings, "spacing")
        col = layout.column(heading="Frames")
        col.prop(settings, "use_scene_range")
        sub = col.column(align=True)
        sub.active = not settings.use_scene_range
        sub.prop(settings, "frame_start")
        sub.prop(settings, "frame_end")
        layout.prop(settings, "seed")


class PROCLOCO_PT_terrain(SidebarPanel, bpy.types.Panel):
    """What the creatures walk on: the terrain collection and each object's role"""

    bl_parent_id = PARENT
    bl_label = "Terrain"
    bl_order = PANEL_ORDER["terrain"]

    @classmethod
    def poll(cls, context: Any) -> bool:
        return getattr(context, "active_object", None) is not None

    def draw(self, context: Any) -> None:
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        obj = context.active_object
        rig = active_rig(context)
        if rig is not None:
            layout.prop(rig.procloco, "terrain_collection")
            if rig.procloco.terrain_collection is None:
                layout.label(text="Every visible mesh that is not part of a rig", icon="INFO")
        elif obj.type in {"MESH", "CURVE", "SURFACE", "FONT", "META"}:
            layout.prop(obj, "procloco_role")
        else:
            layout.label(text=f"{obj.name} is not a mesh or a rig", icon="INFO")


class PROCLOCO_PT_spine(SidebarPanel, bpy.types.Panel):
    """How the flexible spine bends: head turn rate, relaxing, joint limits, visual yaw"""

    bl_parent_id = "PROCLOCO_PT_effects"
    bl_label = "Spine"
    bl_options: ClassVar[set[str]] = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return active_rig(context) is not None

    def draw(self, context: Any) -> None:
        layout = self.layout
        settings = active_rig(context).procloco
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column()
        col.active = settings.use_spine
        col.prop(settings, "spine_turn_rate")
        col.prop(settings, "spine_relax_time")
        col.prop(settings, "spine_yaw_limit")
        col.prop(settings, "spine_pitch_limit")
        sub = col.column()
        sub.active = settings.use_visual_yaw
        sub.prop(settings, "visual_yaw_gain")
        if settings.use_spine:
            layout.label(text="Rigs whose legs hang from one bone turn rigidly", icon="INFO")
