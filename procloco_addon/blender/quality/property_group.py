# SPDX-License-Identifier: GPL-3.0-or-later
"""What was measured on a rig's generated walk, saved in the .blend with the rig's settings
(``Object.procloco.quality``).

Each figure ``<key>`` (see :data:`FIGURES`) has its value, ``<key>_frame`` (the scene frame
where it is worst) and ``<key>_leg`` (the leg's label there, "" when there is no worst
frame). ``token`` matches the ``_procloco_quality`` key of the Action measured: when the
rig's Action no longer carries it (cleared, regenerated without measuring, another Action
assigned), the figures are stale.

No ``update`` callbacks: Blender 4.2 crashes at exit once an extension whose property groups
carry Python functions was uninstalled in the session (see the locomotion settings).
"""

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, StringProperty


class PROCLOCO_PG_quality(bpy.types.PropertyGroup):
    """Figures of the last generated walk, measured on the posed rig after writing."""

    measured: BoolProperty(name="Measured", description="The figures hold a measurement", default=False)
    token: StringProperty(name="Token", description="Matches the measured Action's _procloco_quality key")
    action: StringProperty(name="Action", description="Name of the Action the figures were measured on")
    frame_start: IntProperty(name="First Frame", description="First frame measured")
    frame_end: IntProperty(name="Last Frame", description="Last frame measured")

    slide: FloatProperty(name="Stance Slide", description="Worst distance a planted foot moved from where it "
                         "touched down", subtype="DISTANCE", unit="LENGTH")
    slide_frame: IntProperty(name="Worst Frame", description="Frame of the worst stance slide")
    slide_leg: StringProperty(name="Leg", description="Leg with the worst stance slide")

    penetration: FloatProperty(name="Penetration", description="Deepest a foot went below the ground",
                               subtype="DISTANCE", unit="LENGTH")
    penetration_frame: IntProperty(name="Worst Frame", description="Frame of the deepest penetration")
    penetration_leg: StringProperty(name="Leg", description="Leg with the deepest penetration")

    reach: FloatProperty(name="Reach Error", description="Worst distance between a foot and a target its leg "
                         "could reach", subtype="DISTANCE", unit="LENGTH")
    reach_frame: IntProperty(name="Worst Frame", description="Frame of the worst reach error")
    reach_leg: StringProperty(name="Leg", description="Leg with the worst reach error")

    few_feet_down: IntProperty(name="Too Few Feet Down", description="Frames where a foot the gait plants is "
                               "not on the ground")
    few_feet_down_frame: IntProperty(name="Worst Frame", description="Frame whose planted foot hangs highest")
    few_feet_down_leg: StringProperty(name="Leg", description="Leg whose planted foot hangs highest")
    hover: FloatProperty(name="Hover", description="Highest a planted foot hangs above the ground "
                         "(-1 over no ground)", subtype="DISTANCE", unit="LENGTH")

    over_stretched: IntProperty(name="Over-Stretched", description="Frames where a leg is, or is asked to "
                                "be, longer than it is")
    over_stretched_frame: IntProperty(name="Worst Frame", description="Frame of the longest leg")
    over_stretched_leg: StringProperty(name="Leg", description="Leg stretched the most")
    stretch: FloatProperty(name="Stretch", description="Largest hip-to-foot distance over the leg's length, "
                           "asked or posed")


#: The figures in the panel's order: (key, label, kind); kind "length" for a distance in
#: metres, "frames" for a number of frames.
FIGURES: tuple[tuple[str, str, str], ...] = (
    ("slide", "Stance slide", "length"),
    ("penetration", "Penetration", "length"),
    ("reach", "Reach error", "length"),
    ("few_feet_down", "Too few feet down", "frames"),
    ("over_stretched", "Over-stretched", "frames"),
)
