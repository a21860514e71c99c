# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait operators: apply, add and remove presets; show the circles in the viewport."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import bpy
from bpy.props import StringProperty

from ...core.locomotion import autogait
from ...core.locomotion import gait as core_gait
from ..modal import RemoveActiveItem
from . import geometry, handler, presets, rig_gait

__all__ = [
    "OverlayEditor",
    "PROCLOCO_MT_add_gait_change",
    "PROCLOCO_MT_auto_gait_presets",
    "PROCLOCO_MT_gait_presets",
    "PROCLOCO_OT_add_gait_change",
    "PROCLOCO_OT_add_gait_preset",
    "PROCLOCO_OT_apply_gait_preset",
    "PROCLOCO_OT_edit_gait_overlay",
    "PROCLOCO_OT_remove_gait_change",
    "PROCLOCO_OT_remove_gait_preset",
    "PROCLOCO_OT_set_auto_gait",
    "PROCLOCO_OT_toggle_gait_overlay",
]


def _rig_with_legs(cls: Any, context: Any) -> bool:
    """Poll shared by the operators that act on the active rig's gait."""
    obj = getattr(context, "active_object", None)
    if obj is None or obj.type != "ARMATURE":
        cls.poll_message_set("Select an armature (the rig whose gait to set)")
        return False
    if rig_gait.read_rig_gait(obj) is None:
        cls.poll_message_set(f"{obj.name} has no legs yet: detect its legs first")
        return False
    return True


class PROCLOCO_MT_gait_presets(bpy.types.Menu):
    """Shipped gait presets, then your own ones (with a button to remove each)."""

    bl_idname = "PROCLOCO_MT_gait_presets"
    bl_label = "Gait Presets"

    def draw(self, _context: Any) -> None:
        layout = self.layout
        entries = presets.list_presets()
        col = layout.column(align=True)
        shipped = [e for e in entries if not e.user]
        user = [e for e in entries if e.user]
        for group_index, group in enumerate((shipped, user)):
            if group_index == 1 and group:
                col.separator()
            for entry in group:
                row = col.row(align=True)
                props = row.operator(PROCLOCO_OT_apply_gait_preset.bl_idname, text=entry.name,
                                     icon="ERROR" if entry.error else "NONE")
                props.filepath = str(entry.path)
                if entry.user:
                    remove = row.operator(PROCLOCO_OT_remove_gait_preset.bl_idname, text="", icon="REMOVE")
                    remove.filepath = str(entry.path)
        if not entries:
            col.label(text="No gait presets found")
        layout.separator()
        layout.operator(PROCLOCO_OT_add_gait_preset.bl_idname, text="Save Current Gait as Preset…",
                        icon="ADD")


class PROCLOCO_OT_apply_gait_preset(bpy.types.Operator):
    """Set the active rig's gait circles and cycle time from a gait preset"""

    bl_idname = "procloco.apply_gait_preset"
    bl_label = "Apply Gait Preset"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="Preset File", subtype="FILE_PATH", options={"SKIP_SAVE", "HIDDEN"})

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _rig_with_legs(cls, context)

    def execute(self, context: Any) -> set[str]:
        if not self.filepath:
            self.report({"ERROR"}, "No gait preset file given")
            return {"CANCELLED"}
        try:
            preset = core_gait.load_gait_preset(self.filepath)
            warnings = rig_gait.apply_preset(context.active_object, preset)
        except core_gait.GaitPresetError as error:
            self.report({"ERROR"}, f"Bad {error}; nothing was changed")
            return {"CANCELLED"}
        except core_gait.GaitError as error:
            self.report({"ERROR"}, f"Cannot apply this preset: {error}; nothing was changed")
            return {"CANCELLED"}
        for warning in warnings:
            self.report({"WARNING"}, warning)
        handler.request_refresh()
        self.report({"INFO"}, f"Gait set to {preset.name}")
        return {"FINISHED"}


class PROCLOCO_OT_add_gait_preset(bpy.types.Operator):
    """Save the active rig's gait as a preset of your own (in your user scripts folder)"""

    bl_idname = "procloco.add_gait_preset"
    bl_label = "Save Gait Preset"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    name: StringProperty(name="Name", description="Name of the new preset", default="My Gait")
    source: StringProperty(
        name="Source", description="Where this gait comes from (who observed or designed it)",
        default="Made in Blender with ProcLoco",
    )

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _rig_with_legs(cls, context)

    def invoke(self, context: Any, _event: Any) -> set[str]:
        return context.window_manager.invoke_props_dialog(self)

    def execute(self, context: Any) -> set[str]:
        name = self.name.strip()
        if not name:
            self.report({"ERROR"}, "A gait preset needs a name")
            return {"CANCELLED"}
        try:
            preset = rig_gait.preset_from_rig(context.active_object, name, self.source.strip() or "ProcLoco")
            path = presets.save_user_preset(preset)
        except core_gait.GaitError as error:
            self.report({"ERROR"}, f"Cannot save this gait: {error}")
            return {"CANCELLED"}
        except OSError as error:
            self.report({"ERROR"}, f"Cannot write the preset file: {error}")
            return {"CANCELLED"}
        context.active_object.procloco.gait_preset = preset.name
        self.report({"INFO"}, f"Saved gait preset {preset.name!r} to {path}")
        return {"FINISHED"}


class PROCLOCO_OT_remove_gait_preset(bpy.types.Operator):
    """Delete one of your own gait presets (shipped presets cannot be removed)"""

    bl_idname = "procloco.remove_gait_preset"
    bl_label = "Remove Gait Preset"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="Preset File", subtype="FILE_PATH", options={"SKIP_SAVE", "HIDDEN"})

    @classmethod
    def poll(cls, context: Any) -> bool:
        folder = presets.user_dir()
        if folder is None or not any(folder.glob("*.json")):
            cls.poll_message_set("You have no gait presets of your own to remove")
            return False
        return True

    def execute(self, _context: Any) -> set[str]:
        path = Path(self.filepath)
        if not self.filepath or not path.is_file():
            self.report({"ERROR"}, f"No gait preset file at {self.filepath!r}")
            return {"CANCELLED"}
        try:
            presets.remove_user_preset(path)
        except (PermissionError, OSError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Removed gait preset {path.name}")
        return {"FINISHED"}


class PROCLOCO_MT_auto_gait_presets(bpy.types.Menu):
    """For each gait Auto uses, the presets for the rig's legs that can replace its pattern."""

    bl_idname = "PROCLOCO_MT_auto_gait_presets"
    bl_label = "Auto Gaits from Presets"

    def draw(self, context: Any) -> None:
        layout = self.layout
        gait = rig_gait.read_rig_gait(getattr(context, "active_object", None))
        family = autogait.family_for(gait.labels) if gait is not None else None
        if gait is None or family is None:
            layout.label(text="Auto knows no gaits for these legs")
            return
        fitting = []
        for entry in presets.list_presets():
            if entry.error is None:
                try:
                    preset = core_gait.load_gait_preset(entry.path)
                except core_gait.GaitError:
                    continue
                if sorted(preset.legs) == sorted(gait.labels):
                    fitting.append(entry)
        col = layout.column(align=True)
        for k, band in enumerate(family.bands):
            if k:
                col.separator()
            col.label(text=band.name.capitalize())
            reset = col.operator(PROCLOCO_OT_set_auto_gait.bl_idname, text="Shipped", icon="LOOP_BACK")
            reset.band = band.name
            for entry in fitting:
                props = col.operator(PROCLOCO_OT_set_auto_gait.bl_idname, text=entry.name)
                props.band = band.name
                props.filepath = str(entry.path)


class PROCLOCO_OT_set_auto_gait(bpy.types.Operator):
    """Use a preset's footfall pattern for one of the gaits Auto chooses (no preset: the shipped one)"""

    bl_idname = "procloco.set_auto_gait"
    bl_label = "Set Auto Gait"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    band: StringProperty(name="Gait", description="The Auto gait to change (walk, trot...)",
                         options={"SKIP_SAVE", "HIDDEN"})
    filepath: StringProperty(name="Preset File", subtype="FILE_PATH", options={"SKIP_SAVE", "HIDDEN"})

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _rig_with_legs(cls, context)

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        gait = rig_gait.read_rig_gait(obj)
        family = autogait.family_for(gait.labels) if gait is not None else None
        if family is None or self.band not in [b.name for b in family.bands]:
            self.report({"ERROR"}, f"Auto has no gait {self.band!r} for the legs of {obj.name}")
            return {"CANCELLED"}
        try:
            preset = core_gait.load_gait_preset(self.filepath) if self.filepath else None
            rig_gait.set_auto_override(obj, self.band, preset)
        except core_gait.GaitPresetError as error:
            self.report({"ERROR"}, f"Bad {error}; nothing was changed")
            return {"CANCELLED"}
        except core_gait.GaitError as error:
            self.report({"ERROR"}, f"Cannot use this preset: {error}; nothing was changed")
            return {"CANCELLED"}
        handler.request_refresh()
        self.report({"INFO"}, f"Auto {self.band}: {preset.name if preset else 'shipped pattern'}")
        return {"FINISHED"}


def sort_gait_changes(settings: Any) -> None:
    """Keep the rig's gait changes in frame order (the active one stays active)."""
    changes = settings.gait_changes
    for i in range(1, len(changes)):
        j = i
        while j > 0 and changes[j - 1].frame > changes[j].frame:
            changes.move(j, j - 1)
            if settings.active_gait_change_index == j:
                settings.active_gait_change_index = j - 1
            elif settings.active_gait_change_index == j - 1:
                settings.active_gait_change_index = j
            j -= 1


class PROCLOCO_MT_add_gait_change(bpy.types.Menu):
    """Add a change of gait at the current frame: to a preset, or to the circles as they are."""

    bl_idname = "PROCLOCO_MT_add_gait_change"
    bl_label = "Add Gait Change"

    def draw(self, _context: Any) -> None:
        layout = self.layout
        col = layout.column(align=True)
        col.operator(PROCLOCO_OT_add_gait_change.bl_idname, text="Current Gait Circles", icon="MESH_CIRCLE")
        col.separator()
        for entry in presets.list_presets():
            if entry.error is None:
                props = col.operator(PROCLOCO_OT_add_gait_change.bl_idname, text=entry.name)
                props.filepath = str(entry.path)


class PROCLOCO_OT_add_gait_change(bpy.types.Operator):
    """Change the gait (and speed) at the current frame: to a gait preset, or to the gait circles as
    they are now. The circles themselves are not changed"""

    bl_idname = "procloco.add_gait_change"
    bl_label = "Add Gait Change"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="Preset File", subtype="FILE_PATH", options={"SKIP_SAVE", "HIDDEN"})

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _rig_with_legs(cls, context)

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        settings = obj.procloco
        try:
            if self.filepath:
                preset = core_gait.load_gait_preset(self.filepath)
                gait = rig_gait.read_rig_gait(obj)
                assert gait is not None  # poll
                preset.gait(gait.labels)  # the legs must match: raises before anything is added
                leg_length = rig_gait.mean_leg_length(obj)
                speed = preset.speed * leg_length if leg_length is not None else float(settings.speed)
            else:
                preset = rig_gait.preset_from_rig(obj, settings.gait_preset or "Gait circles")
                speed = float(settings.speed)
        except core_gait.GaitPresetError as error:
            self.report({"ERROR"}, f"Bad {error}; nothing was changed")
            return {"CANCELLED"}
        except core_gait.GaitError as error:
            self.report({"ERROR"}, f"Cannot change to this gait: {error}; nothing was changed")
            return {"CANCELLED"}
        item = settings.gait_changes.add()
        item.name = preset.name
        item.frame = int(context.scene.frame_current)
        item.gait = json.dumps(preset.to_json())
        item.speed = speed
        item.transition_time = 0.5 * float(preset.cycle_time)
        settings.active_gait_change_index = len(settings.gait_changes) - 1
        sort_gait_changes(settings)
        self.report({"INFO"}, f"Gait changes to {preset.name} at frame {item.frame}")
        return {"FINISHED"}


class PROCLOCO_OT_remove_gait_change(RemoveActiveItem, bpy.types.Operator):
    """Remove the selected gait change (the gait circles are not touched)"""

    bl_idname = "procloco.remove_gait_change"
    bl_label = "Remove Gait Change"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}
    _settings, _items, _index = "procloco", "gait_changes", "active_gait_change_index"
    _no_rig = "Select an armature (the rig whose gait change to remove)"
    _no_item = "Select a gait change in the list"


class PROCLOCO_OT_toggle_gait_overlay(bpy.types.Operator):
    """Show or hide the active rig's gait circles in a corner of the 3D viewport"""

    bl_idname = "procloco.toggle_gait_overlay"
    bl_label = "Toggle Gait Circles in Viewport"
    # A display setting of the window, not of the scene: no undo step.
    bl_options: ClassVar[set[str]] = {"REGISTER"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        if getattr(context.window_manager, "procloco_gait_view", None) is None:
            cls.poll_message_set("ProcLoco is not registered")
            return False
        return True

    def execute(self, context: Any) -> set[str]:
        view = context.window_manager.procloco_gait_view
        view.show_overlay = not view.show_overlay
        return {"FINISHED"}


@dataclass
class _Drag:
    leg: int
    handle: str
    start: float
    duration: float
    grab_phase: float
    last_duration: float


class OverlayEditor:
    """What dragging in the overlay does, apart from Blender's events (so it can be tested).

    Positions are pixels in the overlay's own frame (``layout``). A press on a sector's
    start or end handle grabs that edge, a press inside a sector grabs the whole sector;
    moves then rewrite that leg's swing start and duration on the rig; a release keeps
    them, :meth:`cancel` puts back the values from before the press.
    """

    def __init__(self, obj: Any) -> None:
        self.obj = obj
        self.drag: _Drag | None = None

    def press(self, layout: geometry.CircleLayout, pos: tuple[float, float]) -> bool:
        gait = rig_gait.read_rig_gait(self.obj)
        if gait is None:
            return False
        hit = geometry.hit_test(layout, gait.swing_start, gait.swing_duration, pos)
        if hit is None or hit[1] == "RING":
            return False
        leg, handle = hit
        start, duration = float(gait.swing_start[leg]), float(gait.swing_duration[leg])
        self.drag = _Drag(leg, handle, start, duration, geometry.point_phase(layout, leg, pos), duration)
        return True

    def move(self, layout: geometry.CircleLayout, pos: tuple[float, float], *, snap: float = 0.0) -> bool:
        drag = self.drag
        if drag is None:
            return False
        phase = geometry.snap_phase(geometry.point_phase(layout, drag.leg, pos), snap)
        grab = geometry.snap_phase(drag.grab_phase, snap)
        start, duration = geometry.drag_sector(drag.handle, drag.start, drag.duration, grab, phase,
                                               previous_duration=drag.last_duration)
        drag.last_duration = duration
        rig_gait.set_leg_sector(self.obj, drag.leg, start, duration)
        return True

    def release(self) -> bool:
        grabbed = self.drag is not None
        self.drag = None
        return grabbed

    def cancel(self) -> bool:
        drag = self.drag
        if drag is None:
            return False
        rig_gait.set_leg_sector(self.obj, drag.leg, drag.start, drag.duration)
        self.drag = None
        return True


def _window_region(area: Any) -> Any:
    return next((r for r in area.regions if r.type == "WINDOW"), None)


class PROCLOCO_OT_edit_gait_overlay(bpy.types.Operator):
    """Edit the gait in the viewport: drag a sector's start or end, or the whole sector
    (Ctrl snaps to 1/20 of the cycle); Esc or right-click ends editing"""

    bl_idname = "procloco.edit_gait_overlay"
    bl_label = "Edit Gait in Viewport"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    _editor: OverlayEditor | None = None

    @classmethod
    def poll(cls, context: Any) -> bool:
        area = getattr(context, "area", None)
        if area is None or area.type != "VIEW_3D":
            cls.poll_message_set("Run this from a 3D viewport (the ProcLoco sidebar tab)")
            return False
        if rig_gait.is_auto(getattr(context, "active_object", None)):
            cls.poll_message_set("The gait is Auto: switch the Gait to Circles to edit the circles")
            return False
        return _rig_with_legs(cls, context)

    def invoke(self, context: Any, _event: Any) -> set[str]:
        self._editor = OverlayEditor(context.active_object)
        context.window_manager.procloco_gait_view.show_overlay = True
        handler.set_editing(True)
        context.window_manager.modal_handler_add(self)
        context.area.header_text_set("Gait: drag a sector's start or end, or the whole sector (Ctrl snaps) · "
                                     "Esc / right-click: done")
        context.area.tag_redraw()
        return {"RUNNING_MODAL"}

    def _finish(self, context: Any) -> None:
        handler.set_editing(False)
        context.area.header_text_set(None)
        context.area.tag_redraw()

    def _overlay(self, context: Any, event: Any) -> tuple[geometry.CircleLayout, tuple[float, float]] | None:
        region = _window_region(context.area)
        gait = rig_gait.read_rig_gait(self._editor.obj if self._editor else None)
        if region is None or gait is None:
            return None
        layout, (x, y) = handler.overlay_layout(context, region, gait.labels)
        return layout, (event.mouse_x - region.x - x, event.mouse_y - region.y - y)

    def modal(self, context: Any, event: Any) -> set[str]:
        editor = self._editor
        if editor is None or context.area is None:
            handler.set_editing(False)
            return {"CANCELLED"}
        if context.active_object != editor.obj:  # the overlay now shows another rig
            editor.cancel()
            self._finish(context)
            return {"FINISHED"}
        dragging = editor.drag is not None
        if event.type in {"ESC", "RIGHTMOUSE"} and event.value == "PRESS":
            if dragging:
                editor.cancel()
                context.area.tag_redraw()
                return {"RUNNING_MODAL"}
            self._finish(context)
            return {"FINISHED"}
        if event.type == "LEFTMOUSE":
            overlay = self._overlay(context, event)
            if event.value == "PRESS" and overlay is not None and editor.press(*overlay):
                context.area.tag_redraw()
                return {"RUNNING_MODAL"}
            if event.value == "RELEASE" and editor.release():
                handler.request_refresh()
                return {"RUNNING_MODAL"}
            if overlay is not None and overlay[0].contains(overlay[1]):
                return {"RUNNING_MODAL"}  # a click on the overlay must not select behind it
            return {"PASS_THROUGH"}
        if event.type in {"MOUSEMOVE", "INBETWEEN_MOUSEMOVE"} and dragging:
            overlay = self._overlay(context, event)
            if overlay is not None and editor.move(*overlay, snap=0.05 if event.ctrl else 0.0):
                context.area.tag_redraw()
            return {"RUNNING_MODAL"}
        return {"PASS_THROUGH"}
