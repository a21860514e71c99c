# SPDX-License-Identifier: GPL-3.0-or-later
"""Key Reduction settings of one rig (``Object.procloco_keys``), saved in the .blend, and
what the last reduction measured (shown in the panel)."""

import math

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty

__all__ = ["DEFAULT_ANGLE_TOLERANCE", "DEFAULT_FOOT_TOLERANCE", "PROCLOCO_PG_key_reduction"]

#: Defaults: feet within a millimetre, every other bone within half a degree of the full result.
DEFAULT_FOOT_TOLERANCE = 0.001
DEFAULT_ANGLE_TOLERANCE = math.radians(0.5)


class PROCLOCO_PG_key_reduction(bpy.types.PropertyGroup):
    """Whether Generate Locomotion, Bake Secondary Motion and Plan Biped Footsteps thin their
    keys, how close the posed rig must stay to the full result, and the last result."""

    use_key_reduction: BoolProperty(
        name="Key Reduction",
        description="Keep keys only where they are needed (foot contacts always keyed), with Bézier "
        "handles fitted so the posed rig stays within the tolerances of the key-per-frame result",
        default=False,
    )
    foot_tolerance: FloatProperty(
        name="Feet",
        description="How far a foot may move from where the key-per-frame result puts it",
        default=DEFAULT_FOOT_TOLERANCE,
        min=1e-6,
        soft_max=0.05,
        subtype="DISTANCE",
        unit="LENGTH",
        precision=4,
    )
    angle_tolerance: FloatProperty(
        name="Other Bones",
        description="How far any other bone may turn from the key-per-frame result",
        default=DEFAULT_ANGLE_TOLERANCE,
        min=1e-5,
        soft_max=math.radians(5.0),
        subtype="ANGLE",
        precision=2,
    )
    # What the last reduction on this rig did (read-only in the panel).
    keys_before: IntProperty(name="Keys Before", default=0, min=0)
    keys_after: IntProperty(name="Keys After", default=0, min=0)
    foot_error: FloatProperty(name="Worst Foot Error", default=0.0, subtype="DISTANCE", unit="LENGTH")
    angle_error: FloatProperty(name="Worst Bone Error", default=0.0, subtype="ANGLE")
    within: BoolProperty(name="Within the Tolerances", default=True)
