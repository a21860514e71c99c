# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-rig locomotion settings, saved in the .blend on the armature object.

``Object.procloco`` (:class:`PROCLOCO_PG_rig_settings`) holds what the thesis's Appendix D
lists as the user's controls — speed, heading or a path to follow, step height, each
foot's relative position and its gait circle — plus the frame range, the seed and the
effect switches. ``Object.procloco_role`` is the terrain role of any object.

Lengths are in the scene's units (metres), speeds in metres per second, angles in radians.
"""

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from ..quality.property_group import PROCLOCO_PG_quality
from ..scene_terrain import ROLE_ITEMS


def _is_curve(_self: object, obj: bpy.types.Object) -> bool:
    return obj.type == "CURVE"


# Blender 4.2 crashes at exit once an extension whose property groups carry Python functions
# (``poll`` and ``update`` callbacks, methods) was uninstalled in the session; 4.5 does not.
# There the picker lists every object and Generate Locomotion refuses a path that is not a
# curve.
_PATH_POLL = {"poll": _is_curve} if bpy.app.version >= (4, 5, 0) else {}


class PROCLOCO_PG_leg(bpy.types.PropertyGroup):
    """One leg of a rig: its bones, its gait circle and its relative foot position.

    ``name`` (inherited) is shown in the legs list; ``label`` is the gait label (L1, R1, ...).
    """

    label: StringProperty(
        name="Label",
        description="Gait label of the leg: L1, R1, L2, ... front to back, left before right; M for midline",
    )
    hip: StringProperty(name="Hip", description="First bone of the leg (the hip joint)")
    end: StringProperty(
        name="End-Effector",
        description="Last bone solved by the IK; its tail is placed on the ground "
        "(often the bone before the foot)",
    )
    reason: StringProperty(
        name="Why",
        description="Why Detect Legs chose this chain (reaches the ground, mirrored pair, name)",
    )
    detected: StringProperty(
        name="Detected Chain",
        description="The hip and end-effector Detect Legs chose (\"hip>end\"): the reason holds while "
        "they are unchanged",
    )
    enabled: BoolProperty(name="Enabled", description="Animate this leg", default=True)
    controls: StringProperty(
        name="Keyed Controls",
        description="On a control rig, the controls Generate Locomotion keys for this leg "
        "(found by Detect Legs)",
    )
    swing_start: FloatProperty(
        name="Swing Start",
        description="Where in the cycle the foot lifts off (fraction of the cycle)",
        default=0.0,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
    )
    swing_duration: FloatProperty(
        name="Swing Duration",
        description="How long the foot is in the air (fraction of the cycle)",
        default=0.3,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
    )
    offset: FloatVectorProperty(
        name="Foot Offset",
        description="Shift of the foot's preferred position relative to its rest place, "
        "in the body's frame (forward, left)",
        size=2,
        default=(0.0, 0.0),
        subtype="XYZ",
        unit="LENGTH",
    )


class PROCLOCO_PG_gait_change(bpy.types.PropertyGroup):
    """A change of gait (and optionally of speed) at a frame of the generated walk.

    ``name`` (inherited) is the gait's name; ``gait`` holds it as a preset file's JSON text
    (legs by label, sectors, cycle time), written by Add Gait Change.
    """

    frame: IntProperty(name="Frame", description="Frame at which the change begins", default=1)
    transition_time: FloatProperty(
        name="Transition",
        description="Time over which the gait circles move from the gait before to this one "
        "(a leg takes its new sector only while its foot is down; 0: at each leg's next stance)",
        default=0.5,
        min=0.0,
        soft_max=5.0,
        unit="TIME_ABSOLUTE",
    )
    use_speed: BoolProperty(
        name="Change Speed",
        description="Also change the speed, evenly over the transition time",
        default=True,
    )
    speed: FloatProperty(
        name="Speed",
        description="Pelvis speed from this change on",
        default=0.3,
        min=0.0,
        soft_max=5.0,
        unit="VELOCITY",
    )
    gait: StringProperty(
        name="Gait",
        description="The gait as a preset file's JSON text (set by Add Gait Change)",
        options={"HIDDEN"},
    )


class PROCLOCO_PG_rig_settings(bpy.types.PropertyGroup):
    """Locomotion controls of one rig (``Object.procloco``)."""

    legs: CollectionProperty(type=PROCLOCO_PG_leg, name="Legs")
    active_leg_index: IntProperty(name="Active Leg", default=0, min=0)
    forward_axis: EnumProperty(
        name="Forward",
        description="Which way the rig faces in its rest pose",
        items=(
            ("AUTO", "Auto", "From the legs' sides (left/right names), else the rig's -Y axis"),
            ("-Y", "-Y", "The rig faces its -Y axis (Blender and Rigify convention)"),
            ("+Y", "+Y", "The rig faces its +Y axis"),
            ("+X", "+X", "The rig faces its +X axis"),
            ("-X", "-X", "The rig faces its -X axis"),
        ),
        default="AUTO",
    )
    drive_legs: EnumProperty(
        name="Drive Legs",
        description="Which controls Generate Locomotion keys for legs that have both IK and FK controls "
                    "(an IK/FK switch, as on generated Rigify rigs)",
        items=(
            ("AUTO", "Auto", "IK controls, except for legs whose IK chain cannot place every leg bone at its "
             "length (Rigify's three-bone paws): FK controls there"),
            ("IK", "IK Controls", "The IK foot controls and knee poles"),
            ("FK", "FK Controls",
             "The FK controls of every leg bone: the deform bones land exactly as solved"),
        ),
        default="AUTO",
    )
    # the Drive Legs the legs' controls were listed for (Detect Legs)
    controls_drive: StringProperty(default="AUTO", options={"HIDDEN"})

    # --- locomotion -----------------------------------------------------------------
    speed: FloatProperty(
        name="Speed",
        description="Pelvis speed along the heading",
        default=0.3,
        min=0.0,
        soft_max=5.0,
        unit="VELOCITY",
    )
    heading: FloatProperty(
        name="Heading",
        description="Walking direction relative to where the rig faces (0: straight ahead)",
        default=0.0,
        subtype="ANGLE",
        unit="ROTATION",
    )
    turn_rate: FloatProperty(
        name="Turn Rate",
        description="Constant turning speed while walking (0: a straight line)",
        default=0.0,
        soft_min=-3.0,
        soft_max=3.0,
        subtype="ANGLE",
        unit="ROTATION",
    )
    path: PointerProperty(
        type=bpy.types.Object,
        name="Path",
        description="A curve to follow instead of the heading (walked from its start at the given speed)",
        **_PATH_POLL,
    )
    step_height: FloatProperty(
        name="Step Height",
        description="Preferred clearance of a swinging foot above what it steps over",
        default=0.05,
        min=0.0,
        soft_max=1.0,
        unit="LENGTH",
    )
    spacing: FloatProperty(
        name="Feet Spacing",
        description="Scales how far the feet stand from the body's centre line (1: as in the rest pose)",
        default=1.0,
        min=0.3,
        max=2.0,
    )
    cycle_time: FloatProperty(
        name="Cycle Time",
        description="Duration of one gait cycle (every foot lifts once)",
        default=1.0,
        min=0.05,
        soft_max=5.0,
        unit="TIME_ABSOLUTE",
    )
    gait_preset: StringProperty(
        name="Gait Preset",
        description="Name of the gait preset last applied to this rig",
    )
    # Auto gait (gait/rig_gait.py reads and sets these). CIRCLES is the stored default so
    # rigs saved before Auto existed keep their gait; Detect Legs on a new rig picks AUTO.
    gait_mode: EnumProperty(
        name="Gait",
        description="How the gait is chosen",
        items=(
            ("AUTO", "Auto", "The gait, stride and cycle follow the speed at every frame, as animals do "
             "(walk, trot, gallop...; chosen by the Froude number, Alexander & Jayes 1983)"),
            ("CIRCLES", "Circles", "The gait circles below (a preset or your own), with the Gait Changes"),
        ),
        default="CIRCLES",
    )
    gait_speed_scale: FloatProperty(
        name="Gait Speed Scale",
        description="Multiplies the speeds at which Auto changes gait (above 1: keeps walking to higher "
        "speeds; below 1: trots and gallops sooner)",
        default=1.0,
        min=0.25,
        max=4.0,
    )
    auto_gait_overrides: StringProperty(
        name="Auto Gait Overrides",
        description="Per-gait presets used by Auto instead of the shipped ones (JSON: gait name to preset)",
        options={"HIDDEN"},
    )
    gait_changes: CollectionProperty(
        type=PROCLOCO_PG_gait_change,
        name="Gait Changes",
        description="Changes of gait and speed over the generated frames, in frame order; "
        "the gait circles above are the gait the walk starts with",
    )
    active_gait_change_index: IntProperty(name="Active Gait Change", default=0, min=0)

    # --- time and randomness ------------------------------------------------------------
    use_scene_range: BoolProperty(
        name="Scene Frame Range",
        description="Generate over the scene's frame range",
        default=True,
    )
    frame_start: IntProperty(name="Start", description="First generated frame", default=1)
    frame_end: IntProperty(name="End", description="Last generated frame", default=250)
    live_preview: BoolProperty(
        name="Live Preview",
        description="Re-generate the walk whenever a setting, the gait circles, the path curve or a terrain "
        "object changes, without blocking the interface (switching it off keeps the previewed walk "
        "as the generated Action)",
        default=False,
    )
    seed: IntProperty(
        name="Seed",
        description="Seed of every random choice; the same seed gives the same Action",
        default=0,
        min=0,
    )

    # --- crowds ---------------------------------------------------------------------
    use_avoid_others: BoolProperty(
        name="Avoid Other Rigs",
        description="Generated together with other rigs, this rig's feet keep off their bodies and planted "
        "feet and it steers around them",
        default=True,
    )
    seed_offset: IntProperty(
        name="Seed Offset",
        description="A different start phase and a slightly different stride (cycle time within 4 %) for "
        "each value, so copies of one creature do not walk in step (0: as set)",
        default=0,
    )

    # --- terrain --------------------------------------------------------------------
    terrain_collection: PointerProperty(
        type=bpy.types.Collection,
        name="Terrain",
        description="Collection whose meshes are the terrain (empty: every visible mesh not part of a rig)",
    )

    # --- effects --------------------------------------------------------------------
    use_pelvis_physics: BoolProperty(
        name="Pelvis Physics",
        description="The pelvis bobs with the feet's push and landing (thesis §4.1)",
        default=True,
    )
    use_progression: BoolProperty(
        name="Burst Progression",
        description="Burst-like speed with stalls, like insects (thesis §4.3)",
        default=False,
    )
    use_gait_randomizer: BoolProperty(
        name="Gait Randomizer",
        description="A new random gait at each stall (thesis §4.3)",
        default=False,
    )
    use_spine: BoolProperty(
        name="Flexible Spine",
        description="The spine bends through turns and over the terrain, each girdle with its own height and "
        "pitch (thesis §4.2). Used when the legs hang from two or more bones of the spine chain "
        "(quadrupeds, lizards); other rigs turn as one rigid body",
        default=True,
    )
    use_visual_yaw: BoolProperty(
        name="Visual Yaw",
        description="The spine sways toward the feet as they reach and push, like a lizard (thesis §4.4)",
        default=False,
    )
    spine_turn_rate: FloatProperty(
        name="Head Turn Rate",
        description="Fastest turn of the head; the rest of the spine follows its path",
        default=2.0943951023931953,  # 120 degrees per second
        min=0.01,
        soft_max=10.0,
        subtype="ANGLE",
        unit="ROTATION",
    )
    spine_relax_time: FloatProperty(
        name="Relax Time",
        description="How long the back of the spine takes to straighten after a turn",
        default=0.6,
        min=0.01,
        soft_max=5.0,
        unit="TIME_ABSOLUTE",
    )
    spine_yaw_limit: FloatProperty(
        name="Joint Side Limit",
        description="How far each spine joint may bend sideways",
        default=0.4363323129985824,  # 25 degrees
        min=0.0,
        max=1.5707963267948966,
        subtype="ANGLE",
        unit="ROTATION",
    )
    spine_pitch_limit: FloatProperty(
        name="Joint Up/Down Limit",
        description="How far each spine joint may bend up or down",
        default=0.3490658503988659,  # 20 degrees
        min=0.0,
        max=1.5707963267948966,
        subtype="ANGLE",
        unit="ROTATION",
    )
    visual_yaw_gain: FloatProperty(
        name="Sway",
        description="Strength of the visual yaw: 1 turns each girdle by the mean angle of its feet "
        "away from their rest places",
        default=1.0,
        min=0.0,
        soft_max=2.0,
        subtype="FACTOR",
    )

    # --- what was measured on the generated walk (quality panel) --------------------
    quality: PointerProperty(type=PROCLOCO_PG_quality, name="Quality")


def frame_range(settings: PROCLOCO_PG_rig_settings, scene: bpy.types.Scene) -> tuple[int, int]:
    """``(first, last)`` frames a rig's settings generate in ``scene``.

    A module function rather than a method: Blender 4.2 crashes at exit once an extension
    was uninstalled whose property groups carry Python functions.
    """
    if settings.use_scene_range:
        return int(scene.frame_start), int(scene.frame_end)
    return int(settings.frame_start), int(settings.frame_end)


#: ``Object.procloco_role``: the object's part in the terrain (see ``scene_terrain``).
ROLE_PROPERTY = EnumProperty(
    name="Terrain Role",
    description="How ProcLoco's creatures treat this object",
    items=ROLE_ITEMS,
    default="AUTO",
)
