# SPDX-License-Identifier: GPL-3.0-or-later
"""The Gait section of the ProcLoco tab: presets, the circles, per-leg sectors, overlay."""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..ui.main import PANEL_ORDER, RigPanel, active_rig
from . import handler, ops, rig_gait, ui_list

__all__ = ["PROCLOCO_PT_gait", "PROCLOCO_PT_gait_changes"]


class PROCLOCO_PT_gait(RigPanel, bpy.types.Panel):
    """Gait circles of the active rig: which part of the cycle each leg swings."""

    bl_label = "Gait"
    bl_order = PANEL_ORDER["gait"]

    def draw(self, context: Any) -> None:
        layout = self.layout
        obj = active_rig(context)
        view = context.window_manager.procloco_gait_view

        layout.row().prop(obj.procloco, "gait_mode", expand=True)
        row = layout.row(align=True)
        # Like Blender's preset menus, the button names the preset applied last.
        current = obj.procloco.gait_preset or ops.PROCLOCO_MT_gait_presets.bl_label
        row.menu(ops.PROCLOCO_MT_gait_presets.bl_idname, text=current, icon="PRESET")
        row.operator(ops.PROCLOCO_OT_add_gait_preset.bl_idname, text="", icon="ADD")

        gait = rig_gait.read_rig_gait(obj)
        if gait is None:
            layout.label(text="No legs yet: detect the rig's legs first", icon="INFO")
            return

        handler.ensure_current(context)  # a stale picture is redrawn on the next event-loop turn
        if rig_gait.is_auto(obj) and _draw_auto(layout, context, obj, view):
            _draw_overlay_box(layout, view, auto=True)
            return
        layout.template_icon(icon_value=handler.icon_id(), scale=view.picture_scale)
        phase = rig_gait.phase_at_frame(gait, context.scene)
        swinging = [label for label, on in zip(gait.labels, gait_swinging(gait, phase), strict=True) if on]
        info = layout.row()
        info.alignment = "CENTER"
        info.label(text=f"Frame {context.scene.frame_current}: phase {phase:.2f}, "
                        f"swinging {', '.join(swinging) if swinging else 'none'}")
        changed = [c for c in obj.procloco.gait_changes if c.frame <= context.scene.frame_current]
        if changed:
            # the circles are the starting gait: say which change rules this frame instead
            last = max(changed, key=lambda c: c.frame)
            note = layout.row()
            note.alignment = "CENTER"
            note.label(text=f"From frame {last.frame}: {last.name} (Gait Changes)", icon="INFO")

        settings = obj.procloco
        layout.use_property_split = True
        layout.use_property_decorate = False
        layout.prop(settings, "cycle_time")

        col = layout.column(align=True)
        col.use_property_split = False
        for leg, label in zip(settings.legs, gait.labels, strict=True):
            split = col.split(factor=0.2, align=True)
            split.active = leg.enabled  # a leg switched off keeps its circle but is greyed
            split.label(text=label)
            row = split.row(align=True)
            row.prop(leg, "swing_start", text="Start")
            row.prop(leg, "swing_duration", text="Swing")
        _draw_overlay_box(layout, view, auto=False)


def _draw_overlay_box(layout: Any, view: Any, auto: bool) -> None:
    box = layout.box()
    header = box.row()
    header.use_property_split = False
    header.prop(view, "show_overlay")
    if view.show_overlay:
        col = box.column(align=True)
        col.prop(view, "overlay_corner")
        col.prop(view, "overlay_cell")
        if not auto:  # Auto's circles follow the speed: nothing to drag
            box.operator(ops.PROCLOCO_OT_edit_gait_overlay.bl_idname, icon="MOUSE_LMB_DRAG")
    box.prop(view, "picture_scale")


def _draw_auto(layout: Any, context: Any, obj: Any, view: Any) -> bool:
    """Gait: Auto — the chart of the gait bands with the speed over the shot, the circles of
    the current frame, the bias and the per-gait presets. False (nothing drawn but a note)
    when Auto knows no gaits for the rig's legs: the circles are used."""
    settings = obj.procloco
    track = rig_gait.auto_track(obj, context.scene)
    if track is None:
        layout.label(text=f"Auto knows no gaits for {len(settings.legs)} legs: the circles below are used",
                     icon="INFO")
        return False
    layout.template_icon(icon_value=handler.chart_icon_id(), scale=view.picture_scale)
    layout.template_icon(icon_value=handler.icon_id(), scale=view.picture_scale)
    k = track.index(context.scene.frame_current)
    shown = rig_gait.circles_at_frame(obj, context.scene)
    assert shown is not None
    labels, start, duration, phase = shown
    swinging = [lb for lb, on in zip(labels, gait_swinging_arrays(start, duration, phase), strict=True) if on]
    info = layout.column(align=True)
    info.alignment = "CENTER"
    info.label(text=f"Frame {context.scene.frame_current}: {track.names[int(track.band[k])]} at "
                    f"{track.speed[k]:.2f} m/s, swinging {', '.join(swinging) if swinging else 'none'}")
    if not track.recorded:
        info.label(text="Predicted from the speeds (Generate to see bursts and the path's end)")
    layout.use_property_split = True
    layout.use_property_decorate = False
    layout.prop(settings, "gait_speed_scale")
    col = layout.column(align=True)
    col.use_property_split = False
    starts = [0.0, *track.boundaries]
    for name, v in zip(track.names, starts, strict=True):
        split = col.split(factor=0.5, align=True)
        split.label(text=name.capitalize())
        split.label(text=f"from {v:.2f} m/s")
    layout.menu(ops.PROCLOCO_MT_auto_gait_presets.bl_idname, text="Gaits from Presets", icon="PRESET")
    return True


class PROCLOCO_PT_gait_changes(RigPanel, bpy.types.Panel):
    """Changes of gait and speed over the generated frames"""

    bl_parent_id = "PROCLOCO_PT_gait"
    bl_label = "Gait Changes"
    bl_options: ClassVar[set[str]] = {"DEFAULT_CLOSED"}

    def draw(self, context: Any) -> None:
        layout = self.layout
        obj = active_rig(context)
        settings = obj.procloco
        if rig_gait.is_auto(obj):
            layout.label(text="Gait is Auto: only the changes' speeds are used")
        else:
            layout.label(text="The circles above are the gait the walk starts with")
        row = layout.row()
        row.template_list(ui_list.PROCLOCO_UL_gait_changes.bl_idname, "", settings, "gait_changes",
                          settings, "active_gait_change_index", rows=3)
        col = row.column(align=True)
        col.menu(ops.PROCLOCO_MT_add_gait_change.bl_idname, text="", icon="ADD")
        col.operator(ops.PROCLOCO_OT_remove_gait_change.bl_idname, text="", icon="REMOVE")
        index = settings.active_gait_change_index
        if not 0 <= index < len(settings.gait_changes):
            return
        item = settings.gait_changes[index]
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column()
        col.prop(item, "frame")
        col.prop(item, "transition_time")
        col.prop(item, "use_speed")
        sub = col.column()
        sub.active = item.use_speed
        sub.prop(item, "speed")


def gait_swinging(gait: rig_gait.RigGait, phase: float) -> list[bool]:
    """Per leg, whether it swings at ``phase``."""
    return gait_swinging_arrays(gait.swing_start, gait.swing_duration, phase)


def gait_swinging_arrays(swing_start: Any, swing_duration: Any, phase: float) -> list[bool]:
    """Per leg of sectors ``(n_legs,)``, whether it swings at ``phase``."""
    from ...core.locomotion.gait import in_swing

    return [bool(v) for v in in_swing(phase, swing_start, swing_duration)]
