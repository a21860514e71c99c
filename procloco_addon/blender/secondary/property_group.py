# SPDX-License-Identifier: GPL-3.0-or-later
"""Secondary-motion settings, saved in the .blend on the armature object.

``Object.procloco_secondary`` (:class:`PROCLOCO_PG_secondary_settings`) lists the rig's
pendulum chains (:class:`PROCLOCO_PG_secondary_chain`): a chain runs from its root bone down
to its tip bone, every bone of it a pendulum (thesis chapter 5). Per chain the animator sets
the settling time Ts and damping ratio ζ of the springs, the rest direction (the animation,
or straight down) and how much of the swing reaches the baked Action.
"""

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    StringProperty,
)

REST_ITEMS = (
    ("ANIMATION", "Animation", "The bones swing around their animated direction and come back to it"),
    ("GRAVITY", "Gravity", "The bones hang straight down (world -Z) and swing around that"),
)

class PROCLOCO_PG_secondary_chain(bpy.types.PropertyGroup):
    """One chain of pendulums: the bones from ``root`` down to ``tip`` (``name`` is its label)."""

    enabled: BoolProperty(name="Enabled", description="Bake secondary motion on this chain", default=True)
    root: StringProperty(name="Root", description="First bone of the chain, hanging from the body")
    tip: StringProperty(
        name="Tip", description="Last bone of the chain (a descendant of the root, or the root)"
    )
    settling_time: FloatProperty(
        name="Settling Time",
        description="Seconds a disturbed bone takes to come back within 5 % of its rest direction "
        "and stay there (Ts)",
        default=0.6,
        min=0.02,
        soft_max=3.0,
        unit="TIME_ABSOLUTE",
    )
    damping: FloatProperty(
        name="Damping",
        description="Damping ratio ζ: 1 comes back without overshooting, lower values swing past "
        "and oscillate, higher values creep back",
        default=0.4,
        min=0.05,
        max=3.0,
    )
    rest_direction: EnumProperty(
        name="Rest Direction",
        description="What the bones are pulled back to",
        items=REST_ITEMS,
        default="ANIMATION",
    )
    influence: FloatProperty(
        name="Influence",
        description="How much of the swing is baked: 0 keeps the animation, 1 the full swing",
        default=1.0,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
    )


class PROCLOCO_PG_secondary_settings(bpy.types.PropertyGroup):
    """Secondary motion of one rig (``Object.procloco_secondary``).

    A chain whose root hangs from a bone of another chain continues that chain's tree: the
    bone it hangs from is its father pendulum.
    """

    chains: CollectionProperty(type=PROCLOCO_PG_secondary_chain)
    active_chain_index: IntProperty(name="Active Chain", default=0, min=0)
    use_reaction: BoolProperty(
        name="Whole-Chain Swing",
        description="Bones push back on the bones they hang from, so the chain swings as one "
        "(stable for long chains). Off: each bone only follows its parent (the thesis's scheme; "
        "long, lightly damped chains can whip round)",
        default=True,
    )
