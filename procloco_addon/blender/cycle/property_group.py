# SPDX-License-Identifier: GPL-3.0-or-later
"""Make Cycle settings, saved in the .blend on the armature object (``Object.procloco_cycle``).

The walk itself (gait, speed, step height, effects, the first frame) comes from the rig's
locomotion settings (``Object.procloco``); these say how many cycles the loop holds and where
its root motion goes.
"""

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

ROOT_MOTION_ITEMS = (
    ("IN_PLACE", "In Place", "The rig walks on the spot, as on a treadmill: the game moves it"),
    ("ROOT_BONE", "Root Bone", "The root bone carries the walk forward, one stride per cycle; the rest "
     "of the rig walks in place on it"),
)


class PROCLOCO_PG_cycle_settings(bpy.types.PropertyGroup):
    """How Make Cycle cuts a loop from the rig's walk."""

    cycles: IntProperty(
        name="Cycles",
        description="Whole gait cycles in the loop (every foot lifts once per cycle)",
        default=1,
        min=1,
        soft_max=8,
        max=64,
    )
    root_motion: EnumProperty(
        name="Root Motion",
        description="Where the walk's forward motion goes",
        items=ROOT_MOTION_ITEMS,
        default="IN_PLACE",
    )
    root_bone: StringProperty(
        name="Root Bone",
        description="Bone with no parent above every animated bone: it carries the root motion",
        default="root",
    )
