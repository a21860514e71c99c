# SPDX-License-Identifier: GPL-3.0-or-later
"""Biped planner settings, saved in the .blend on the armature object (``Object.procloco_biped``).

The rig's *clip database* is a list of Actions, each tagged with a role (walk forward, walk
left, run right, jump, start, stop, idle...). The planner walks the rig to a *goal* object
over the terrain of the Terrain panel (``Object.procloco.terrain_collection``, or every
visible mesh).
"""

import math

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
)

ROLE_ITEMS = [
    ("WALK_FORWARD", "Walk Forward", "One stride walking straight"),
    ("WALK_LEFT", "Walk Left", "One stride walking on a tight left arc"),
    ("WALK_LEFT_WIDE", "Walk Left Wide", "One stride walking on a wide left arc"),
    ("WALK_RIGHT", "Walk Right", "One stride walking on a tight right arc"),
    ("WALK_RIGHT_WIDE", "Walk Right Wide", "One stride walking on a wide right arc"),
    ("RUN_FORWARD", "Run Forward", "One stride running straight"),
    ("RUN_LEFT", "Run Left", "One stride running on a left arc"),
    ("RUN_RIGHT", "Run Right", "One stride running on a right arc"),
    ("JUMP", "Jump", "A running jump: from a right touchdown over a gap to the next right touchdown"),
    ("START", "Start", "From standing to walking (ends at a right touchdown)"),
    ("STOP", "Stop", "From walking (a right touchdown) to standing"),
    ("IDLE", "Idle", "Standing"),
]


class PROCLOCO_PG_biped_clip(bpy.types.PropertyGroup):
    """One Action of the biped's clip database and the role it plays."""

    action: PointerProperty(
        name="Action",
        type=bpy.types.Action,
        description="An Action of this rig: one stride of a walk, run or jump, a start, a stop or idle",
    )
    role: EnumProperty(
        name="Role",
        items=ROLE_ITEMS,
        default="WALK_FORWARD",
        description="What the clip does; the planner picks and blends clips by role",
    )
    use: BoolProperty(name="Use", default=True, description="Use this clip when planning")


class PROCLOCO_PG_biped_settings(bpy.types.PropertyGroup):
    """Clips, goal and options of Plan Biped Footsteps for one rig."""

    clips: CollectionProperty(type=PROCLOCO_PG_biped_clip)
    active_clip_index: IntProperty(name="Active Clip", default=0, min=0)
    goal: PointerProperty(
        name="Goal",
        type=bpy.types.Object,
        description="Where the character walks to and stops (any object; an Empty is handy)",
    )
    use_goal_heading: BoolProperty(
        name="Face Goal Direction",
        default=False,
        description="Stop facing the goal object's front (its -Y axis, like Blender's front view)",
    )
    allow_run: BoolProperty(
        name="Allow Running",
        default=True,
        description="Blend into running where the path needs it (before and after jumps)",
    )
    use_blend_groups: BoolProperty(
        name="Blend Groups",
        default=True,
        description="Blend the walks by the path's curvature and walk/run by speed, instead of "
        "playing one clip per stride",
    )
    speed_change: FloatProperty(
        name="Speed Change",
        default=2.0,
        min=0.25,
        soft_max=6.0,
        description="Strides the character takes to speed up to a run or slow down to a walk",
    )
    crossfade: FloatProperty(
        name="Cross-fade",
        default=0.3,
        min=0.0,
        soft_max=1.0,
        unit="TIME_ABSOLUTE",
        description="Time over which one stride's clip fades into the next",
    )
    max_slope: FloatProperty(
        name="Max Slope",
        default=math.radians(35.0),
        min=0.0,
        max=math.radians(80.0),
        subtype="ANGLE",
        description="Steepest ground the character may stand on",
    )
    seed: IntProperty(
        name="Seed",
        default=0,
        min=0,
        description="Seed of the footprint graph's samples; the same seed gives the same Action",
    )
    start_frame: IntProperty(name="Start Frame", default=1, description="Frame of the first key")
    use_scene_start: BoolProperty(
        name="Scene Start",
        default=True,
        description="Start at the scene's first frame instead of Start Frame",
    )
