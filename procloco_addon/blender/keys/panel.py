# SPDX-License-Identifier: GPL-3.0-or-later
"""The Key Reduction sub-panel of the Generate section: the switch in its header, the two
tolerances, and the key counts of the last reduction."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import bpy

from ..ui.main import SidebarPanel, active_rig

__all__ = ["PROCLOCO_PT_key_reduction"]


class PROCLOCO_PT_key_reduction(SidebarPanel, bpy.types.Panel):
    """Fewer keys, Bézier handles fitted: the posed rig stays within the tolerances"""

    bl_parent_id = "PROCLOCO_PT_generate"
    bl_label = "Key Reduction"
    bl_options: ClassVar[set[str]] = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return active_rig(context) is not None

    def draw_header(self, context: Any) -> None:
        self.layout.prop(active_rig(context).procloco_keys, "use_key_reduction", text="")

    def draw(self, context: Any) -> None:
        layout = self.layout
        settings = active_rig(context).procloco_keys
        col = layout.column(align=True)
        col.use_property_split = True
        col.use_property_decorate = False
        col.active = bool(settings.use_key_reduction)
        col.prop(settings, "foot_tolerance")
        col.prop(settings, "angle_tolerance")
        if settings.keys_before:
            ratio = settings.keys_before / max(settings.keys_after, 1)
            box = layout.box()
            box.label(text=f"Keys: {settings.keys_before:,} → {settings.keys_after:,} ({ratio:.1f}× fewer)",
                      icon="KEYFRAME")
            box.label(text=f"Feet within {1000.0 * settings.foot_error:.2f} mm, "
                      f"bones within {math.degrees(settings.angle_error):.2f}°")
