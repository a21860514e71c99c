# SPDX-License-Identifier: GPL-3.0-or-later
"""The Secondary Motion sub-panel of the ProcLoco tab: chains, their springs, and Bake."""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..ui.main import PANEL_ORDER, RigPanel, active_rig
from .ops import (
    PROCLOCO_OT_add_secondary_chain,
    PROCLOCO_OT_bake_secondary_motion,
    PROCLOCO_OT_remove_secondary_chain,
    PROCLOCO_OT_suggest_secondary_chains,
)
from .ui_list import PROCLOCO_UL_secondary_chains

__all__ = ["PROCLOCO_PT_secondary"]


class PROCLOCO_PT_secondary(RigPanel, bpy.types.Panel):
    """Tails, antennae and ears that swing with the body (3D pendulums), baked into a new Action"""

    bl_label = "Secondary Motion"
    bl_order = PANEL_ORDER["secondary"]
    bl_options: ClassVar[set[str]] = {"DEFAULT_CLOSED"}

    def draw(self, context: Any) -> None:
        layout = self.layout
        obj = active_rig(context)
        settings = obj.procloco_secondary
        layout.operator(PROCLOCO_OT_suggest_secondary_chains.bl_idname, icon="VIEWZOOM")
        row = layout.row()
        row.template_list(PROCLOCO_UL_secondary_chains.bl_idname, "", settings, "chains", settings,
                          "active_chain_index", rows=min(max(len(settings.chains), 3), 8))
        col = row.column(align=True)
        col.operator(PROCLOCO_OT_add_secondary_chain.bl_idname, text="", icon="ADD")
        col.operator(PROCLOCO_OT_remove_secondary_chain.bl_idname, text="", icon="REMOVE")
        if not len(settings.chains):
            layout.label(text="No chains yet: suggest them, or add one", icon="INFO")
            return
        index = settings.active_chain_index
        if 0 <= index < len(settings.chains):
            chain = settings.chains[index]
            col = layout.column()
            col.use_property_split = True
            col.use_property_decorate = False
            col.prop(chain, "name", text="Label")
            col.prop_search(chain, "root", obj.data, "bones", text="Root")
            col.prop_search(chain, "tip", obj.data, "bones", text="Tip")
            col.separator()
            col.prop(chain, "settling_time")
            col.prop(chain, "damping")
            col.prop(chain, "rest_direction")
            col.prop(chain, "influence", slider=True)
        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.prop(settings, "use_reaction")
        layout.operator(PROCLOCO_OT_bake_secondary_motion.bl_idname, icon="FORCE_HARMONIC")
