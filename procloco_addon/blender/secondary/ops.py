# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the secondary-motion feature: Suggest Chains, add/remove a chain, and
Bake Secondary Motion.

Every operator refuses bad input with a ``report({"ERROR"}, ...)`` and ``{"CANCELLED"}``
and then has changed nothing. Bake Secondary Motion runs modal in the UI (progress in the
status bar and the header, Esc cancels with nothing written) and straight through in
background mode and from scripts (``EXEC_DEFAULT``).
"""

from __future__ import annotations

import time
from collections.abc import Generator
from typing import Any, ClassVar

import bpy

from .. import actions
from . import bake

__all__ = [
    "PROCLOCO_OT_add_secondary_chain",
    "PROCLOCO_OT_bake_secondary_motion",
    "PROCLOCO_OT_remove_secondary_chain",
    "PROCLOCO_OT_suggest_secondary_chains",
    "suggest_chains",
]

# Longest time one modal timer tick may sample frames before handing control back to the UI.
_TICK_BUDGET_S = 0.05


def suggest_chains(obj: Any) -> int:
    """Fill the rig's chain list with the suggested chains; returns how many were found."""
    return len(bake.suggest_into_settings(obj))


def _poll_armature(cls: Any, context: Any, what: str) -> bool:
    obj = getattr(context, "active_object", None)
    if obj is None or obj.type != "ARMATURE":
        cls.poll_message_set(f"Select an armature (the rig {what})")
        return False
    if getattr(context, "mode", "OBJECT") not in {"OBJECT", "POSE"}:
        cls.poll_message_set("Leave edit mode first")
        return False
    return True


class PROCLOCO_OT_suggest_secondary_chains(bpy.types.Operator):
    """List the rig's tails, antennae, ears and other dangling chains for secondary motion"""

    bl_idname = "procloco.suggest_secondary_chains"
    bl_label = "Suggest Chains"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _poll_armature(cls, context, "whose tail, antennae or ears should swing")

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        found = bake.suggest_into_settings(obj)
        if not found:
            self.report({"WARNING"}, f"{obj.name}: no tail, antenna or ear chain found; add a chain and pick "
                        "its root and tip bones")
            return {"FINISHED"}
        self.report({"INFO"}, f"{obj.name}: {len(found)} chains ({', '.join(s.label for s in found)})")
        return {"FINISHED"}


class PROCLOCO_OT_add_secondary_chain(bpy.types.Operator):
    """Add a chain of swinging bones; in pose mode it runs from the selected bone nearest the
    body to the active bone"""

    bl_idname = "procloco.add_secondary_chain"
    bl_label = "Add Chain"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _poll_armature(cls, context, "to add a chain to")

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        settings = obj.procloco_secondary
        item = settings.chains.add()
        active = getattr(context, "active_pose_bone", None)
        if active is not None:
            tip = active.name
            selected = {pb.name for pb in (getattr(context, "selected_pose_bones", None) or [])}
            root = tip
            bone = obj.data.bones[tip].parent
            while bone is not None and bone.name in selected:
                root = bone.name
                bone = bone.parent
            item.root, item.tip = root, tip
            item.name = root if root == tip else f"{root} > {tip}"
        else:
            item.name = f"Chain {len(settings.chains)}"
        settings.active_chain_index = len(settings.chains) - 1
        return {"FINISHED"}


class PROCLOCO_OT_remove_secondary_chain(bpy.types.Operator):
    """Remove the active chain from the list (the bones are not touched)"""

    bl_idname = "procloco.remove_secondary_chain"
    bl_label = "Remove Chain"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        if not _poll_armature(cls, context, "whose chain to remove"):
            return False
        settings = context.active_object.procloco_secondary
        if not 0 <= settings.active_chain_index < len(settings.chains):
            cls.poll_message_set("The rig has no chain to remove")
            return False
        return True

    def execute(self, context: Any) -> set[str]:
        settings = context.active_object.procloco_secondary
        settings.chains.remove(settings.active_chain_index)
        settings.active_chain_index = max(0, min(settings.active_chain_index, len(settings.chains) - 1))
        return {"FINISHED"}


class PROCLOCO_OT_bake_secondary_motion(bpy.types.Operator):
    """Make the rig's tails, antennae and ears swing with its motion (3D pendulums), baked over the
    frame range into a new Action; the current Action is kept untouched"""

    bl_idname = "procloco.bake_secondary_motion"
    bl_label = "Bake Secondary Motion"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    _timer: Any = None
    _steps: Generator[float, None, None] | None = None
    _job: bake.Job | None = None

    @classmethod
    def poll(cls, context: Any) -> bool:
        return _poll_armature(cls, context, "to bake")

    # -- shared -------------------------------------------------------------------------
    def _prepare(self, context: Any) -> bool:
        obj = context.active_object
        if obj is not None and obj.type == "ARMATURE" and not len(obj.procloco_secondary.chains):
            # A rig nobody set up (a script, the batch command, a first click): the
            # suggested chains are listed and baked.
            bake.suggest_into_settings(obj)
        try:
            self._job = bake.prepare(context, obj)
        except bake.BakeError as err:
            self.report({"ERROR"}, str(err))
            return False
        return True

    def _finish(self, context: Any) -> set[str]:
        job = self._job
        assert job is not None
        try:
            action = bake.write(context, job)
        except (bake.BakeError, actions.ActionError, ValueError) as err:
            self.report({"ERROR"}, f"Could not write the Action: {err}")
            return {"CANCELLED"}
        for warning in job.warnings:
            self.report({"WARNING"}, f"{job.obj_name}: {warning}")
        source = f"'{job.source.name}'" if job.source is not None else "the rig's pose (no Action)"
        self.report({"INFO"}, f"Baked {len(job.bones)} bones over frames {job.frames[0]}-{job.frames[-1]} "
                    f"into '{action.name}' (on {source}, which is kept)")
        return {"FINISHED"}

    # -- straight through ---------------------------------------------------------------
    def execute(self, context: Any) -> set[str]:
        if not self._prepare(context):
            return {"CANCELLED"}
        job = self._job
        assert job is not None
        try:
            for _fraction in bake.sample(context, job):
                pass
        except bake.BakeError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        return self._finish(context)

    # -- modal --------------------------------------------------------------------------
    def invoke(self, context: Any, event: Any) -> set[str]:
        if bpy.app.background or context.window is None:
            return self.execute(context)
        if not self._prepare(context):
            return {"CANCELLED"}
        assert self._job is not None
        self._steps = bake.sample(context, self._job)
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _stop(self, context: Any) -> None:
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.area is not None:
            context.area.header_text_set(None)
        self._steps = None

    def modal(self, context: Any, event: Any) -> set[str]:
        if event.type == "ESC":
            self._abort(context)
            self.report({"WARNING"}, "Bake cancelled: nothing was changed")
            return {"CANCELLED"}
        if event.type != "TIMER" or self._steps is None:
            return {"PASS_THROUGH"}
        deadline = time.perf_counter() + _TICK_BUDGET_S
        try:
            for fraction in self._steps:
                percent = int(90 * fraction)  # the last tenth is simulating and writing
                context.window_manager.progress_update(percent)
                if context.area is not None:
                    context.area.header_text_set(
                        f"ProcLoco: baking secondary motion {percent}% (Esc to cancel)"
                    )
                if time.perf_counter() > deadline:
                    return {"RUNNING_MODAL"}
        except bake.BakeError as err:
            self._stop(context)
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        self._stop(context)
        return self._finish(context)

    def _abort(self, context: Any) -> None:
        steps = self._steps
        self._stop(context)
        if steps is not None:
            steps.close()  # runs the sampler's clean-up: frame and Action put back
        if self._job is not None:
            bake.cancel(context, self._job)

    def cancel(self, context: Any) -> None:
        self._abort(context)
