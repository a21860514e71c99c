# SPDX-License-Identifier: GPL-3.0-or-later
"""How the gait circles are shown (``WindowManager.procloco_gait_view``).

Display choices only, shared by every rig: the gait itself is saved on the rig
(``Object.procloco``).
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty


def _redraw_viewports(_self: object, context: bpy.types.Context) -> None:
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


class PROCLOCO_PG_gait_view(bpy.types.PropertyGroup):
    """Display settings of the gait circles (panel picture and viewport overlay)."""

    show_overlay: BoolProperty(
        name="Show in Viewport",
        description="Draw the active rig's gait circles in a corner of the 3D viewport",
        default=False,
        update=_redraw_viewports,
    )
    overlay_corner: EnumProperty(
        name="Corner",
        description="Corner of the 3D viewport where the gait circles are drawn",
        items=(
            ("BOTTOM_LEFT", "Bottom Left", ""),
            ("BOTTOM_RIGHT", "Bottom Right", ""),
            ("TOP_LEFT", "Top Left", ""),
            ("TOP_RIGHT", "Top Right", ""),
        ),
        default="BOTTOM_LEFT",
        update=_redraw_viewports,
    )
    overlay_cell: IntProperty(
        name="Circle Size",
        description="Size of one leg's circle in the viewport, in pixels",
        default=90,
        min=40,
        max=400,
        subtype="PIXEL",
        update=_redraw_viewports,
    )
    picture_scale: FloatProperty(
        name="Picture Size",
        description="Size of the gait picture in the panel",
        default=9.0,
        min=4.0,
        max=20.0,
    )
