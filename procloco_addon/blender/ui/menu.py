# SPDX-License-Identifier: GPL-3.0-or-later
"""The ProcLoco menu: every ProcLoco operator under Object > Animation and Pose > Animation.

Blender's operator search (F3) finds operators through the menus they are in, so each of
ProcLoco's operators has an entry here as well as its button in the sidebar. The submenu is
appended to ``VIEW3D_MT_object_animation``, which is the Animation menu of both Object and
Pose mode; :func:`register` and :func:`unregister` add and remove that entry.
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..biped import ops as biped_ops
from ..cycle import ops as cycle_ops
from ..gait import ops as gait_ops
from ..live_preview import ops as live_preview_ops
from ..locomotion import ops as locomotion_ops
from ..quality import ops as quality_ops
from ..secondary import ops as secondary_ops

__all__ = ["HOST_MENU", "PROCLOCO_MT_animation", "PROCLOCO_MT_lists", "register", "unregister"]

#: The Animation menu of the 3D viewport's Object and Pose modes.
HOST_MENU = "VIEW3D_MT_object_animation"


class PROCLOCO_MT_lists(bpy.types.Menu):
    """Add and remove entries of the active rig's ProcLoco lists"""

    bl_idname = "PROCLOCO_MT_lists"
    bl_label = "Lists"

    def draw(self, _context: Any) -> None:
        layout = self.layout
        layout.menu(gait_ops.PROCLOCO_MT_add_gait_change.bl_idname, text="Add Gait Change", icon="ADD")
        layout.operator(gait_ops.PROCLOCO_OT_remove_gait_change.bl_idname, icon="REMOVE")
        layout.separator()
        layout.operator(secondary_ops.PROCLOCO_OT_add_secondary_chain.bl_idname, icon="ADD")
        layout.operator(secondary_ops.PROCLOCO_OT_remove_secondary_chain.bl_idname, icon="REMOVE")
        layout.separator()
        layout.operator(biped_ops.PROCLOCO_OT_add_biped_clip.bl_idname, icon="ADD")
        layout.operator(biped_ops.PROCLOCO_OT_remove_biped_clip.bl_idname, icon="REMOVE")


class PROCLOCO_MT_animation(bpy.types.Menu):
    """ProcLoco: procedural locomotion for the selected rigs"""

    bl_idname = "PROCLOCO_MT_animation"
    bl_label = "ProcLoco"

    #: Operators that are reached through a menu drawn here rather than by an entry of their own
    #: (a preset's Apply and Remove are the presets menu's rows).
    VIA_SUBMENUS: ClassVar[dict[str, str]] = {
        gait_ops.PROCLOCO_OT_apply_gait_preset.bl_idname: gait_ops.PROCLOCO_MT_gait_presets.bl_idname,
        gait_ops.PROCLOCO_OT_remove_gait_preset.bl_idname: gait_ops.PROCLOCO_MT_gait_presets.bl_idname,
        gait_ops.PROCLOCO_OT_add_gait_preset.bl_idname: gait_ops.PROCLOCO_MT_gait_presets.bl_idname,
        gait_ops.PROCLOCO_OT_set_auto_gait.bl_idname: gait_ops.PROCLOCO_MT_auto_gait_presets.bl_idname,
        gait_ops.PROCLOCO_OT_add_gait_change.bl_idname: gait_ops.PROCLOCO_MT_add_gait_change.bl_idname,
    }

    def draw(self, _context: Any) -> None:
        layout = self.layout
        layout.operator(locomotion_ops.PROCLOCO_OT_detect_legs.bl_idname, icon="BONE_DATA")
        layout.operator(locomotion_ops.PROCLOCO_OT_generate_locomotion.bl_idname, icon="ANIM")
        layout.operator(cycle_ops.PROCLOCO_OT_make_cycle.bl_idname, icon="FILE_REFRESH")
        layout.operator(locomotion_ops.PROCLOCO_OT_clear_generated_action.bl_idname, icon="X")
        layout.operator(live_preview_ops.PROCLOCO_OT_discard_live_preview.bl_idname, icon="TRASH")
        layout.menu(quality_ops.PROCLOCO_MT_worst_frames.bl_idname, text="Jump to Worst Frame")
        layout.separator()
        layout.menu(gait_ops.PROCLOCO_MT_gait_presets.bl_idname, text="Gait Presets")
        layout.menu(gait_ops.PROCLOCO_MT_auto_gait_presets.bl_idname, text="Auto Gait Presets")
        layout.operator(gait_ops.PROCLOCO_OT_toggle_gait_overlay.bl_idname, icon="MESH_CIRCLE")
        layout.operator(gait_ops.PROCLOCO_OT_edit_gait_overlay.bl_idname, icon="MOUSE_LMB_DRAG")
        layout.separator()
        layout.operator(secondary_ops.PROCLOCO_OT_suggest_secondary_chains.bl_idname)
        layout.operator(secondary_ops.PROCLOCO_OT_bake_secondary_motion.bl_idname, icon="PHYSICS")
        layout.separator()
        layout.operator(biped_ops.PROCLOCO_OT_make_biped_clips.bl_idname)
        layout.operator(biped_ops.PROCLOCO_OT_plan_biped_footsteps.bl_idname)
        layout.separator()
        layout.menu(PROCLOCO_MT_lists.bl_idname)


def _draw_entry(self: Any, _context: Any) -> None:
    self.layout.separator()
    self.layout.menu(PROCLOCO_MT_animation.bl_idname)


def register() -> None:
    """Add the ProcLoco submenu to the Animation menu (after the classes are registered)."""
    host = getattr(bpy.types, HOST_MENU, None)
    if host is not None:
        host.append(_draw_entry)


def unregister() -> None:
    host = getattr(bpy.types, HOST_MENU, None)
    if host is not None:
        host.remove(_draw_entry)
