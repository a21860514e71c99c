# SPDX-License-Identifier: GPL-3.0-or-later
"""Make Cycle: a game-ready loop of whole gait cycles for the active rig and every selected rig.

Refuses with a message and changes nothing when the walk cannot loop (see :mod:`.make`);
modal with progress and Esc in the UI, straight through in background mode, like Generate
Locomotion; one undo step.
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..locomotion import generate
from ..locomotion.ops import rigs_to_generate
from ..modal import ProgressOperator, Steps, poll_armature, steps_with_result
from . import make

__all__ = ["PROCLOCO_OT_make_cycle"]


class PROCLOCO_OT_make_cycle(ProgressOperator, bpy.types.Operator):
    """Make a seamless loop of whole gait cycles on flat ground, in place or on a root bone, for export"""

    bl_idname = "procloco.make_cycle"
    bl_label = "Make Cycle"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    _cancelled_message: ClassVar[str] = "Make Cycle cancelled: nothing was changed"
    _run_errors: ClassVar[tuple[type[Exception], ...]] = (generate.GenerateError,)
    _jobs: list[make.CycleJob]
    _made: list[Any]

    @classmethod
    def poll(cls, context: Any) -> bool:
        return poll_armature(cls, context, "Select an armature (the rig to loop)")

    def _prepare(self, context: Any) -> bool:
        try:
            self._jobs = [make.read(context, obj) for obj in rigs_to_generate(context)]
        except generate.GenerateError as err:
            self.report({"ERROR"}, str(err))
            return False
        return True

    def _run(self, context: Any, modal: bool) -> Steps:
        n = len(self._jobs)
        for k, cj in enumerate(self._jobs):
            for text, fraction in make.simulate_steps(context, cj):
                yield text, 0.9 * (k + fraction) / n
        self._made = yield from steps_with_result(make.write_steps(context, self._jobs), "writing the loops",
                                                  0.9, 0.1, generate.GenerateError, "the loops")

    def _finish(self, context: Any) -> set[str]:
        for cj in self._jobs:
            for warning in cj.job.warnings:
                self.report({"WARNING"}, f"{cj.obj_name}: {warning}")
            self.report({"INFO"}, f"{cj.obj_name}: '{cj.action.name}', {cj.summary()}")
        return {"FINISHED"}
