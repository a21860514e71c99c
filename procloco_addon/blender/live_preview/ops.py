# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Preview's operator: Discard Preview (switching the toggle off keeps the walk)."""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..modal import poll_armature
from . import handler, preview

__all__ = ["PROCLOCO_OT_discard_live_preview"]


class PROCLOCO_OT_discard_live_preview(bpy.types.Operator):
    """Switch Live Preview off and give the rig back the Action it had before the preview
    (switching Live Preview off instead keeps the previewed walk as the generated Action)"""

    bl_idname = "procloco.discard_live_preview"
    bl_label = "Discard Preview"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        if not poll_armature(cls, context, "Select an armature (the rig whose preview to discard)"):
            return False
        obj = context.active_object
        if not preview.is_previewing(obj) and not obj.procloco.live_preview:
            cls.poll_message_set(f"{obj.name} has no Live Preview to discard")
            return False
        return True

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        try:
            handler.discard(obj)
        except Exception as err:  # an Action the preview could not give back: said, not raised
            self.report({"ERROR"}, f"Could not discard the preview of '{obj.name}': "
                        f"{type(err).__name__}: {err}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Discarded the Live Preview of '{obj.name}'")
        return {"FINISHED"}
