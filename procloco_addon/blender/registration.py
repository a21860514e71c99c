# SPDX-License-Identifier: GPL-3.0-or-later
"""The one place where ProcLoco's Blender classes and properties are registered.

``CLASSES`` lists every class in registration order (property groups before the groups
and panels that use them). ``POINTERS`` lists the ``PointerProperty`` attachments made
on Blender ID types. ``unregister`` undoes both in reverse order, so enabling and
disabling the extension any number of times leaves nothing behind.
"""

from __future__ import annotations

from typing import Any

import bpy

from . import cli
from .biped import ops as biped_ops
from .biped import panel as biped_panel
from .biped import property_group as biped_props
from .biped import ui_list as biped_ui_list
from .cycle import ops as cycle_ops
from .cycle import panel as cycle_panel
from .cycle import property_group as cycle_props
from .gait import handler as gait_handler
from .gait import ops as gait_ops
from .gait import panel as gait_panel
from .gait import property_group as gait_props
from .gait import ui_list as gait_ui_list
from .keys import panel as keys_panel
from .keys import property_group as keys_props
from .live_preview import handler as live_preview_handler
from .live_preview import ops as live_preview_ops
from .locomotion import handler as legs_handler
from .locomotion import ops as locomotion_ops
from .locomotion import panel as locomotion_panel
from .locomotion import property_group as locomotion_props
from .locomotion import ui_list as locomotion_ui_list
from .quality import ops as quality_ops
from .quality import panel as quality_panel
from .quality import property_group as quality_props
from .secondary import ops as secondary_ops
from .secondary import panel as secondary_panel
from .secondary import property_group as secondary_props
from .secondary import ui_list as secondary_ui_list
from .ui import main as ui_main
from .ui import menu as ui_menu

CLASSES: tuple[type, ...] = (
    locomotion_props.PROCLOCO_PG_leg,
    locomotion_props.PROCLOCO_PG_gait_change,
    quality_props.PROCLOCO_PG_quality,
    locomotion_props.PROCLOCO_PG_rig_settings,
    keys_props.PROCLOCO_PG_key_reduction,
    locomotion_ops.PROCLOCO_OT_detect_legs,
    locomotion_ops.PROCLOCO_OT_generate_locomotion,
    locomotion_ops.PROCLOCO_OT_clear_generated_action,
    live_preview_ops.PROCLOCO_OT_discard_live_preview,
    quality_ops.PROCLOCO_OT_jump_to_worst_frame,
    locomotion_ui_list.PROCLOCO_UL_legs,
    gait_props.PROCLOCO_PG_gait_view,
    biped_props.PROCLOCO_PG_biped_clip,
    biped_props.PROCLOCO_PG_biped_settings,
    biped_ops.PROCLOCO_OT_plan_biped_footsteps,
    biped_ops.PROCLOCO_OT_add_biped_clip,
    biped_ops.PROCLOCO_OT_remove_biped_clip,
    biped_ops.PROCLOCO_OT_make_biped_clips,
    biped_ui_list.PROCLOCO_UL_biped_clips,
    secondary_props.PROCLOCO_PG_secondary_chain,
    secondary_props.PROCLOCO_PG_secondary_settings,
    secondary_ops.PROCLOCO_OT_suggest_secondary_chains,
    secondary_ops.PROCLOCO_OT_add_secondary_chain,
    secondary_ops.PROCLOCO_OT_remove_secondary_chain,
    secondary_ops.PROCLOCO_OT_bake_secondary_motion,
    secondary_ui_list.PROCLOCO_UL_secondary_chains,
    # The sidebar tab's parent panel before every feature's sub-panels.
    ui_main.PROCLOCO_PT_main,
    gait_ops.PROCLOCO_MT_gait_presets,
    gait_ops.PROCLOCO_MT_add_gait_change,
    gait_ops.PROCLOCO_OT_add_gait_change,
    gait_ops.PROCLOCO_OT_remove_gait_change,
    gait_ui_list.PROCLOCO_UL_gait_changes,
    gait_ops.PROCLOCO_OT_apply_gait_preset,
    gait_ops.PROCLOCO_OT_add_gait_preset,
    gait_ops.PROCLOCO_OT_remove_gait_preset,
    gait_ops.PROCLOCO_OT_toggle_gait_overlay,
    gait_ops.PROCLOCO_MT_auto_gait_presets,
    gait_ops.PROCLOCO_OT_set_auto_gait,
    gait_ops.PROCLOCO_OT_edit_gait_overlay,
    locomotion_panel.PROCLOCO_PT_rig_legs,
    gait_panel.PROCLOCO_PT_gait,
    gait_panel.PROCLOCO_PT_gait_changes,
    locomotion_panel.PROCLOCO_PT_locomotion,
    locomotion_panel.PROCLOCO_PT_terrain,
    secondary_panel.PROCLOCO_PT_secondary,
    biped_panel.PROCLOCO_PT_biped,
    ui_main.PROCLOCO_PT_effects,
    locomotion_panel.PROCLOCO_PT_spine,
    ui_main.PROCLOCO_PT_generate,
    keys_panel.PROCLOCO_PT_key_reduction,
    quality_panel.PROCLOCO_PT_quality,
    quality_ops.PROCLOCO_MT_worst_frames,
    cycle_props.PROCLOCO_PG_cycle_settings,
    cycle_ops.PROCLOCO_OT_make_cycle,
    cycle_panel.PROCLOCO_PT_make_cycle,
    ui_menu.PROCLOCO_MT_lists,
    ui_menu.PROCLOCO_MT_animation,
)

# (owner ID type, attribute name, property) for plain properties (not groups)
PROPERTIES: tuple[tuple[type, str, Any], ...] = (
    (bpy.types.Object, "procloco_role", locomotion_props.ROLE_PROPERTY),
)

# (owner ID type, attribute name, property group class)
POINTERS: tuple[tuple[type, str, type], ...] = (
    (bpy.types.Object, "procloco", locomotion_props.PROCLOCO_PG_rig_settings),
    (bpy.types.Object, "procloco_biped", biped_props.PROCLOCO_PG_biped_settings),
    (bpy.types.Object, "procloco_secondary", secondary_props.PROCLOCO_PG_secondary_settings),
    (bpy.types.Object, "procloco_keys", keys_props.PROCLOCO_PG_key_reduction),
    (bpy.types.Object, "procloco_cycle", cycle_props.PROCLOCO_PG_cycle_settings),
    (bpy.types.WindowManager, "procloco_gait_view", gait_props.PROCLOCO_PG_gait_view),
)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for owner, attr, group in POINTERS:
        setattr(owner, attr, bpy.props.PointerProperty(type=group))
    for owner, attr, prop in PROPERTIES:
        setattr(owner, attr, prop)
    cli.register()
    gait_handler.register()
    legs_handler.register()
    live_preview_handler.register()
    ui_menu.register()


def unregister() -> None:
    ui_menu.unregister()
    cli.unregister()
    for owner, attr, _prop in reversed(PROPERTIES):
        if hasattr(owner, attr):
            delattr(owner, attr)
    live_preview_handler.unregister()
    legs_handler.unregister()
    gait_handler.unregister()
    for owner, attr, _group in reversed(POINTERS):
        if hasattr(owner, attr):
            delattr(owner, attr)
    for cls in reversed(CLASSES):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
