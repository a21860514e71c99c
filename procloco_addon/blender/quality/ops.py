# SPDX-License-Identifier: GPL-3.0-or-later
"""Jump to Worst Frame: the quality panel's buttons.

Setting the scene's frame is navigation, like scrubbing the timeline: the operator pushes
no undo step (``bl_options`` without ``UNDO``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy
from bpy.props import EnumProperty

from . import measure
from .property_group import FIGURES

__all__ = ["PROCLOCO_MT_worst_frames", "PROCLOCO_OT_jump_to_worst_frame"]

_ITEMS = [(key, label, f"The frame where the {label.lower()} is worst") for key, label, _kind in FIGURES]


class PROCLOCO_OT_jump_to_worst_frame(bpy.types.Operator):
    """Go to the frame where this quality figure of the generated walk is worst"""

    bl_idname = "procloco.jump_to_worst_frame"
    bl_label = "Jump to Worst Frame"
    bl_options: ClassVar[set[str]] = {"REGISTER"}

    figure: EnumProperty(name="Figure", items=_ITEMS, description="Which figure's worst frame to show")

    @classmethod
    def poll(cls, context: Any) -> bool:
        obj = getattr(context, "active_object", None)
        if obj is None or obj.type != "ARMATURE":
            cls.poll_message_set("Select the rig whose walk was measured")
            return False
        if not obj.procloco.quality.measured:
            cls.poll_message_set("Generate Locomotion first: its result is measured after writing")
            return False
        if not measure.is_current(obj):
            cls.poll_message_set("The figures are stale (the rig's Action changed): generate again")
            return False
        return True

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        q = obj.procloco.quality
        key = self.figure
        label = {k: lb for k, lb, _kd in FIGURES}[key]
        leg = getattr(q, f"{key}_leg")
        if not leg:
            self.report({"ERROR"}, f"No frame has a {label.lower()} to show")
            return {"CANCELLED"}
        frame = int(getattr(q, f"{key}_frame"))
        context.scene.frame_set(frame)
        self.report({"INFO"}, f"Frame {frame}: {label.lower()} {measure.value_text(obj, key)} (leg {leg})")
        return {"FINISHED"}


class PROCLOCO_MT_worst_frames(bpy.types.Menu):
    """Go to the frame where a quality figure of the generated walk is worst"""

    bl_idname = "PROCLOCO_MT_worst_frames"
    bl_label = "Jump to Worst Frame"

    def draw(self, _context: Any) -> None:
        for key, label, _kind in FIGURES:
            self.layout.operator(PROCLOCO_OT_jump_to_worst_frame.bl_idname, text=label).figure = key
