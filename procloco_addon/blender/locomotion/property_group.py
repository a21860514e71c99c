# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-rig locomotion settings, saved in the .blend on the armature object."""

import bpy
from bpy.props import FloatProperty, IntProperty


class PROCLOCO_PG_rig_settings(bpy.types.PropertyGroup):
    """Locomotion controls of one rig (``Object.procloco``)."""

    speed: FloatProperty(
        name="Speed",
        description="Pelvis speed along the heading",
        default=0.3,
        min=0.0,
        soft_max=5.0,
        unit="VELOCITY",
    )
    step_height: FloatProperty(
        name="Step Height",
        description="Preferred clearance of a swinging foot above what it steps over",
        default=0.05,
        min=0.0,
        soft_max=1.0,
        unit="LENGTH",
    )
    seed: IntProperty(
        name="Seed",
        description="Seed of every random choice; the same seed gives the same Action",
        default=0,
        min=0,
    )
