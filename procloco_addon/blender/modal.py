# SPDX-License-Identifier: GPL-3.0-or-later
"""What the long-running operators share: the armature poll and the progress loop.

:class:`ProgressOperator` is a mixin for ``bpy.types.Operator``. An operator says how to
read its input (``_prepare``), how to do the work as a generator of ``(text, fraction)``
progress steps (``_run``), how to write the result (``_finish``) and how to drop a half-done
job (``_discard``). The mixin then gives it:

* ``execute``: straight through (scripts, ``EXEC_DEFAULT``, background mode and the batch
  command), printing ``ProcLoco: <text> <percent>%`` every tenth in background mode;
* ``invoke``: modal in the UI, a timer tick doing at most ``_tick_budget_s`` of work before
  handing control back, the percentage in the status bar and the area header, Esc cancelling
  with nothing written.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Generator
from typing import Any, ClassVar

import bpy

__all__ = ["ProgressOperator", "RemoveActiveItem", "Steps", "advance", "poll_armature", "steps_with_result"]

#: What ``_run`` returns: progress steps ``(text, fraction 0..1)``.
Steps = Generator[tuple[str, float], None, None]


def steps_with_result(steps: Generator[float, None, Any], text: str, start: float, share: float,
                      error: type[Exception], what: str) -> Generator[tuple[str, float], None, Any]:
    """Progress ``(text, start + share * fraction)`` for each fraction ``steps`` yields; returns
    what ``steps`` returns. Closed early (Esc), it closes ``steps`` (which takes back what it
    wrote); a failure in ``steps`` becomes ``error("Could not write <what> (nothing was
    changed): ...")``."""
    try:
        while True:
            try:
                fraction = next(steps)
            except StopIteration as done:
                return done.value
            yield text, start + share * fraction
    except GeneratorExit:
        steps.close()
        raise
    except Exception as err:
        raise error(f"Could not write {what} (nothing was changed): {err}") from err


def advance(steps: Steps, budget_s: float,
            on_step: Callable[[str, float], None] | None = None) -> bool:
    """Run ``steps`` for at most ``budget_s`` seconds (at least one step), calling
    ``on_step(text, fraction)`` after each; True once they are exhausted. The one slicing
    loop of the modal operators' timer ticks and of Live Preview's timer; errors raised by
    the steps propagate."""
    deadline = time.perf_counter() + budget_s
    for text, fraction in steps:
        if on_step is not None:
            on_step(text, fraction)
        if time.perf_counter() >= deadline:
            return False
    return True


def poll_armature(cls: Any, context: Any, message: str) -> bool:
    """Poll for an operator that works on the active armature in object or pose mode;
    ``message`` is shown when no armature is active."""
    obj = getattr(context, "active_object", None)
    if obj is None or obj.type != "ARMATURE":
        cls.poll_message_set(message)
        return False
    if getattr(context, "mode", "OBJECT") not in {"OBJECT", "POSE"}:
        cls.poll_message_set("Leave edit mode first")
        return False
    return True


class RemoveActiveItem:
    """Mixin for the Remove button of a list on the active armature: the armature's
    ``_settings`` group has a collection ``_items`` whose ``_index`` points at the item to
    remove; ``_no_rig`` and ``_no_item`` say why the button is off. The index stays on a
    neighbour."""

    _settings: ClassVar[str]
    _items: ClassVar[str]
    _index: ClassVar[str]
    _no_rig: ClassVar[str]
    _no_item: ClassVar[str]

    @classmethod
    def poll(cls, context: Any) -> bool:
        if not poll_armature(cls, context, cls._no_rig):
            return False
        group = getattr(context.active_object, cls._settings)
        if not 0 <= getattr(group, cls._index) < len(getattr(group, cls._items)):
            cls.poll_message_set(cls._no_item)  # type: ignore[attr-defined]
            return False
        return True

    def execute(self, context: Any) -> set[str]:
        group = getattr(context.active_object, self._settings)
        collection = getattr(group, self._items)
        collection.remove(getattr(group, self._index))
        setattr(group, self._index, max(0, min(getattr(group, self._index), len(collection) - 1)))
        return {"FINISHED"}


class ProgressOperator:
    """Mixin: the straight-through and the modal runs of a long operator (module docstring)."""

    #: Longest time one timer tick may work before handing control back to the UI.
    _tick_budget_s: ClassVar[float] = 0.05
    #: Seconds between timer ticks.
    _timer_step_s: ClassVar[float] = 0.01
    #: Reported when Esc cancels.
    _cancelled_message: ClassVar[str] = "Cancelled: nothing was changed"
    #: Errors ``_run`` may raise with a message for the user.
    _run_errors: ClassVar[tuple[type[Exception], ...]] = ()

    _timer: Any = None
    _steps: Steps | None = None

    # -- what an operator provides --------------------------------------------------------
    def _prepare(self, context: Any) -> bool:
        """Read the input; report and return False when it cannot be used."""
        raise NotImplementedError

    def _run(self, context: Any, modal: bool) -> Steps:
        """The work, as progress steps (``modal``: run from a timer in the UI)."""
        raise NotImplementedError

    def _finish(self, context: Any) -> set[str]:
        """Write the result; the operator's return value."""
        raise NotImplementedError

    def _discard(self, context: Any) -> None:
        """Drop a half-done job after Esc or a cancelled operator (nothing by default)."""

    def _fault(self, context: Any, err: Exception) -> set[str]:
        """An error nobody foresaw: reported as a message (never a traceback in the user's
        face), the half-done job dropped."""
        try:
            self._discard(context)
        finally:
            self.report({"ERROR"}, f"ProcLoco failed, nothing was changed: "  # type: ignore[attr-defined]
                        f"{type(err).__name__}: {err}")
        return {"CANCELLED"}

    def _prepared(self, context: Any) -> bool:
        try:
            return self._prepare(context)
        except Exception as err:
            self._fault(context, err)
            return False

    # -- straight through ---------------------------------------------------------------
    def execute(self, context: Any) -> set[str]:
        if not self._prepared(context):
            return {"CANCELLED"}
        background = bpy.app.background
        last = -1
        steps = self._run(context, False)
        try:
            for text, fraction in steps:
                percent = int(100 * fraction)
                if background and percent // 10 != last // 10:
                    print(f"ProcLoco: {text} {percent:3d}%", flush=True)
                last = percent
        except self._run_errors as err:
            self._discard(context)
            self.report({"ERROR"}, str(err))  # type: ignore[attr-defined]
            return {"CANCELLED"}
        except Exception as err:
            steps.close()
            return self._fault(context, err)
        try:
            return self._finish(context)
        except Exception as err:
            return self._fault(context, err)

    # -- modal --------------------------------------------------------------------------
    def invoke(self, context: Any, event: Any) -> set[str]:
        if bpy.app.background or context.window is None:
            return self.execute(context)
        if not self._prepared(context):
            return {"CANCELLED"}
        self._steps = self._run(context, True)
        wm = context.window_manager
        self._timer = wm.event_timer_add(self._timer_step_s, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _stop(self, context: Any) -> None:
        """End the modal run: timer, progress and header gone (the work is left as it is)."""
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.area is not None:
            context.area.header_text_set(None)
        self._steps = None

    def _abort(self, context: Any) -> None:
        steps = self._steps
        self._stop(context)
        if steps is not None:
            steps.close()  # the work's own clean-up runs (its finally blocks)
        self._discard(context)

    def modal(self, context: Any, event: Any) -> set[str]:
        if event.type == "ESC":
            self._abort(context)
            self.report({"WARNING"}, self._cancelled_message)  # type: ignore[attr-defined]
            return {"CANCELLED"}
        if event.type != "TIMER" or self._steps is None:
            return {"PASS_THROUGH"}
        def show(text: str, fraction: float) -> None:
            percent = int(100 * fraction)
            context.window_manager.progress_update(percent)
            if context.area is not None:
                context.area.header_text_set(f"ProcLoco: {text} {percent}% (Esc to cancel)")

        try:
            if not advance(self._steps, self._tick_budget_s, show):
                return {"RUNNING_MODAL"}
        except self._run_errors as err:
            self._abort(context)
            self.report({"ERROR"}, str(err))  # type: ignore[attr-defined]
            return {"CANCELLED"}
        except Exception as err:
            self._abort(context)
            return self._fault(context, err)
        self._stop(context)
        try:
            return self._finish(context)
        except Exception as err:
            return self._fault(context, err)

    def cancel(self, context: Any) -> None:
        self._abort(context)
