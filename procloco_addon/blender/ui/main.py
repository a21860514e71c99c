# SPDX-License-Identifier: GPL-3.0-or-later
"""The "ProcLoco" tab of the 3D viewport's sidebar: the parent panel, Effects and Generate.

Every feature hangs its own sub-panels under :data:`PARENT` (``bl_parent_id``) from its
``<feature>/panel.py``, derives them from :class:`SidebarPanel` and places them with
``bl_order = PANEL_ORDER["<section>"]`` so the tab reads in workflow order: pick the rig
and its legs, set the gait, the locomotion and the terrain, switch effects, generate.
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

__all__ = [
    "CATEGORY",
    "EFFECTS",
    "PANEL_ORDER",
    "PARENT",
    "PROCLOCO_PT_effects",
    "PROCLOCO_PT_generate",
    "PROCLOCO_PT_main",
    "SidebarPanel",
    "active_rig",
    "operator_available",
    "selected_rigs",
]

CATEGORY = "ProcLoco"
PARENT = "PROCLOCO_PT_main"

PANEL_ORDER: dict[str, int] = {
    "rig": 10,
    "gait": 20,
    "locomotion": 30,
    "terrain": 40,
    "effects": 50,
    "secondary": 60,
    "biped": 70,
    "generate": 100,
}

# Effect switches on the rig settings (``Object.procloco``), shown as they land:
# (property name, why an animator would switch it on).
EFFECTS: tuple[tuple[str, str], ...] = (
    ("use_pelvis_physics", "Pelvis bobs with the feet's push (pseudo-physics)"),
    ("use_spine", "The spine bends along the path instead of turning rigidly"),
    ("use_visual_yaw", "The spine sways with the feet"),
    ("use_progression", "Burst-like speed with stalls, like insects"),
    ("use_gait_randomizer", "A new random gait at each stall"),
)

# Operators offered in the Generate section once their feature is registered.
GENERATE_OPERATORS: tuple[tuple[str, str, str], ...] = (
    ("procloco.generate_locomotion", "Generate Locomotion", "ARMATURE_DATA"),
    ("procloco.bake_secondary_motion", "Bake Secondary Motion", "FORCE_HARMONIC"),
    ("procloco.plan_biped_footsteps", "Plan Biped Footsteps", "MOD_DYNAMICPAINT"),
    ("procloco.clear_generated_action", "Clear Generated Action", "X"),
)


def operator_available(idname: str) -> bool:
    """True if operator ``"module.name"`` is registered."""
    module, _, name = idname.partition(".")
    try:
        getattr(getattr(bpy.ops, module), name).get_rna_type()
    except (AttributeError, KeyError):
        return False
    return True


def active_rig(context: Any) -> Any:
    """The active object if it is an armature, else None."""
    obj = getattr(context, "active_object", None)
    return obj if obj is not None and obj.type == "ARMATURE" else None


def selected_rigs(context: Any) -> list[Any]:
    """Selected armatures (the active one first when it is selected)."""
    rigs = [o for o in (getattr(context, "selected_objects", None) or []) if o.type == "ARMATURE"]
    active = active_rig(context)
    if active is not None and active in rigs:
        rigs.remove(active)
        rigs.insert(0, active)
    return rigs


class SidebarPanel:
    """Mixin placing a panel in the ProcLoco tab of the 3D viewport's sidebar."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY


class RigPanel(SidebarPanel):
    """Mixin for sub-panels that only make sense with an armature active."""

    bl_parent_id = PARENT

    @classmethod
    def poll(cls, context: Any) -> bool:
        return active_rig(context) is not None


class PROCLOCO_PT_main(SidebarPanel, bpy.types.Panel):
    """ProcLoco: procedural, terrain-aware locomotion for the active rig."""

    bl_idname = PARENT
    bl_label = "ProcLoco"

    def draw(self, context: Any) -> None:
        layout = self.layout
        obj = getattr(context, "active_object", None)
        rig = active_rig(context)
        if obj is None:
            layout.label(text="Select an armature to animate", icon="INFO")
            return
        if rig is None:
            layout.label(text=f"{obj.name} is not an armature", icon="ERROR")
            layout.label(text="Select an armature to animate")
            return
        row = layout.row()
        row.label(text=rig.name, icon="ARMATURE_DATA")
        others = len(selected_rigs(context)) - 1
        if others > 0:
            row.label(text=f"+{others} selected rig{'s' if others > 1 else ''}")


class PROCLOCO_PT_effects(RigPanel, bpy.types.Panel):
    """Effects layered on the walk: pelvis physics, flexible spine, progression, gait randomizer."""

    bl_label = "Effects"
    bl_order = PANEL_ORDER["effects"]
    bl_options: ClassVar[set[str]] = {"DEFAULT_CLOSED"}

    def draw(self, context: Any) -> None:
        layout = self.layout
        settings = active_rig(context).procloco
        names = [name for name, _why in EFFECTS if settings.bl_rna.properties.get(name) is not None]
        if not names:
            layout.label(text="No effects in this version", icon="INFO")
            return
        col = layout.column(heading="Effects", align=True)
        for name in names:
            col.prop(settings, name)


class PROCLOCO_PT_generate(SidebarPanel, bpy.types.Panel):
    """Write the motion: Generate Locomotion and the bakes that build on it."""

    bl_parent_id = PARENT
    bl_label = "Generate"
    bl_order = PANEL_ORDER["generate"]

    def draw(self, context: Any) -> None:
        layout = self.layout
        shown = [op for op in GENERATE_OPERATORS if operator_available(op[0])]
        if not shown:
            layout.label(text="Generation is not available in this build", icon="ERROR")
            return
        col = layout.column(align=True)
        first, *rest = shown
        big = col.row(align=True)
        big.scale_y = 1.6
        rigs = len(selected_rigs(context))
        text = first[1]
        if rigs > 1 and first[0] == "procloco.generate_locomotion":
            text = f"{first[1]} ({rigs} rigs)"
        big.operator(first[0], text=text, icon=first[2])
        for idname, label, icon in rest:
            col.operator(idname, text=label, icon=icon)
        rig = active_rig(context)
        if rig is not None:
            # crowds: several rigs generated together (locomotion.crowd)
            crowd = layout.column(heading="Crowd")
            crowd.use_property_split = True
            crowd.use_property_decorate = False
            crowd.prop(rig.procloco, "use_avoid_others")
            crowd.prop(rig.procloco, "seed_offset")
            from ..live_preview.panel import draw_live_preview

            draw_live_preview(layout.box(), rig)


CLASSES: tuple[type, ...] = (PROCLOCO_PT_main, PROCLOCO_PT_effects, PROCLOCO_PT_generate)
