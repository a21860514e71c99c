# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the secondary-motion feature: Suggest Chains, add/remove a chain, and
Bake Secondary Motion.

Every operator refuses bad input with a ``report({"ERROR"}, ...)`` and ``{"CANCELLED"}``
and then has changed nothing. Bake Secondary Motion runs modal in the UI (progress in the
status bar and the header, Esc cancels with nothing written) and straight through in
background mode and from scripts (``EXEC_DEFAULT``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..keys.reduce import last_reduction
from ..modal import ProgressOperator, RemoveActiveItem, Steps, poll_armature, steps_with_result
from . import bake

__all__ = [
    "PROCLOCO_OT_add_secondary_chain",
    "PROCLOCO_OT_bake_secondary_motion",
    "PROCLOCO_OT_remove_secondary_chain",
    "PROCLOCO_OT_suggest_secondary_chains",
    "suggest_chains",
]

def suggest_chains(obj: Any) -> int:
    """Fill the rig's chain list with the suggested chains; returns how many were found."""
    return len(bake.suggest_into_settings(obj))


class PROCLOCO_OT_suggest_secondary_chains(bpy.types.Operator):
    """List the rig's tails, antennae, ears and other dangling chains for secondary motion"""

    bl_idname = "procloco.suggest_secondary_chains"
    bl_label = "Suggest Chains"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return poll_armature(
            cls, context, "Select an armature (the rig whose tail, antennae or ears should swing)"
        )

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
        return poll_armature(cls, context, "Select an armature (the rig to add a chain to)")

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


class PROCLOCO_OT_remove_secondary_chain(RemoveActiveItem, bpy.types.Operator):
    """Remove the active chain from the list (the bones are not touched)"""

    bl_idname = "procloco.remove_secondary_chain"
    bl_label = "Remove Chain"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}
    _settings, _items, _index = "procloco_secondary", "chains", "active_chain_index"
    _no_rig = "Select an armature (the rig whose chain to remove)"
    _no_item = "The rig has no chain to remove"


def _take_back_suggestions(op: Any, context: Any) -> None:
    """Empty the chain list again when the operator ``op`` filled it with suggestions and
    then did not bake (refused, cancelled)."""
    obj = context.active_object
    if getattr(op, "_suggested", False) and obj is not None:
        obj.procloco_secondary.chains.clear()
        obj.procloco_secondary.active_chain_index = 0
    op._suggested = False


class PROCLOCO_OT_bake_secondary_motion(ProgressOperator, bpy.types.Operator):
    """Make the rig's tails, antennae and ears swing with its motion (3D pendulums), baked over the
    frame range into a new Action; the current Action is kept untouched"""

    bl_idname = "procloco.bake_secondary_motion"
    bl_label = "Bake Secondary Motion"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    _cancelled_message: ClassVar[str] = "Bake cancelled: nothing was changed"
    _run_errors: ClassVar[tuple[type[Exception], ...]] = (bake.BakeError,)
    _job: bake.Job | None = None
    _made: Any = None
    _suggested: bool = False

    @classmethod
    def poll(cls, context: Any) -> bool:
        return poll_armature(cls, context, "Select an armature (the rig to bake)")

    def _prepare(self, context: Any) -> bool:
        obj = context.active_object
        self._suggested = False
        if obj is not None and obj.type == "ARMATURE" and not len(obj.procloco_secondary.chains):
            # A rig nobody set up (a script, the batch command, a first click): the
            # suggested chains are listed and baked (and taken back if the bake is not).
            bake.suggest_into_settings(obj)
            self._suggested = True
        try:
            self._job = bake.prepare(context, obj)
        except bake.BakeError as err:
            _take_back_suggestions(self, context)
            self.report({"ERROR"}, str(err))
            return False
        return True



    def _finish(self, context: Any) -> set[str]:
        job = self._job
        assert job is not None
        action = self._made
        for warning in job.warnings:
            self.report({"WARNING"}, f"{job.obj_name}: {warning}")
        source = f"'{job.source.name}'" if job.source is not None else "the rig's pose (no Action)"
        self.report({"INFO"}, f"Baked {len(job.bones)} bones over frames {job.frames[0]}-{job.frames[-1]} "
                    f"into '{action.name}' (on {source}, which is kept)")
        reduced = last_reduction(bpy.data.objects[job.obj_name])
        if reduced is not None:
            self.report({"INFO"}, f"{job.obj_name}: {reduced.describe()}")
        return {"FINISHED"}

    def _run(self, context: Any, modal: bool) -> Steps:
        job = self._job
        assert job is not None
        samples = bake.sample(context, job)
        try:
            for fraction in samples:
                yield "playing the animation", 0.5 * fraction
        finally:
            samples.close()  # closed early (Esc): frame and Action put back
        # The pendulums in slices: progress, and Esc stops them with nothing written.
        for fraction in bake.simulate_steps(job):
            yield "swinging the chains", 0.5 + 0.45 * fraction
        # Writing: Esc there deletes the new Action and gives the rig back what it had.
        self._made = yield from steps_with_result(bake.write_steps(context, job), "writing the Action", 0.95,
                                                  0.05, bake.BakeError, "the Action")

    def _discard(self, context: Any) -> None:
        if self._job is not None:
            bake.cancel(context, self._job)
        _take_back_suggestions(self, context)
