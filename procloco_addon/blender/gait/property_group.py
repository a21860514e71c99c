# SPDX-License-Identifier: GPL-3.0-or-later
"""How the gait circles are shown (``WindowManager.procloco_gait_view``).

Display choices only, shared by every rig: the gait itself is saved on the rig
(``Object.procloco``).
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty

#: Properties whose change redraws the 3D viewports. They are watched through the message
#: bus (gait/handler.py) rather than ``update=`` callbacks: on Blender 4.2, a property group
#: with an update callback crashes Blender at exit once the extension has been uninstalled.
OVERLAY_PROPERTIES = ("show_overlay", "overlay_corner", "overlay_cell")


class PROCLOCO_PG_gait_view(bpy.types.PropertyGroup):
    """Display settings of the gait circles (panel picture and viewport overlay)."""

    show_overlay: BoolProperty(
        name="Show in Viewport",
        description="Draw the active rig's gait circles in a corner of the 3D viewport",
        default=False,
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
    )
    overlay_cell: IntProperty(
        name="Circle Size",
        description="Size of one leg's circle in the viewport, in pixels",
        default=90,
        min=40,
        max=400,
        subtype="PIXEL",
    )
    picture_scale: FloatProperty(
        name="Picture Size",
        description="Size of the gait picture in the panel",
        default=9.0,
        min=4.0,
        max=20.0,
    )
