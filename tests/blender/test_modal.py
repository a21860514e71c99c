# SPDX-License-Identifier: GPL-3.0-or-later
"""The progress loop the long operators share (``blender/modal.py``): straight through,
modal ticks, Esc and errors; and Esc through the real Bake Secondary Motion and Plan Biped
Footsteps operators' loops."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, ClassVar

import bpy
import pytest

from procloco_addon.blender.modal import ProgressOperator, Steps
from tests.blender.scene_state import snapshot

pytestmark = pytest.mark.blender


class Counting(ProgressOperator):
    """Ten steps; records what the loop did with it."""

    _tick_budget_s: ClassVar[float] = 0.0
    _run_errors: ClassVar[tuple[type[Exception], ...]] = (ValueError,)
    _cancelled_message: ClassVar[str] = "Counting cancelled"

    def __init__(self, fail_at: int | None = None) -> None:
        self.fail_at = fail_at
        self.reports: list[tuple[str, str]] = []
        self.done: list[int] = []
        self.events: list[str] = []

    def report(self, kind: set[str], text: str) -> None:
        self.reports.append((next(iter(kind)), text))

    def _prepare(self, context: Any) -> bool:
        self.events.append("prepare")
        return True

    def _run(self, context: Any, modal: bool) -> Steps:
        try:
            for k in range(10):
                if k == self.fail_at:
                    raise ValueError(f"step {k} failed")
                self.done.append(k)
                yield "counting", (k + 1) / 10
        finally:
            self.events.append("closed")

    def _finish(self, context: Any) -> set[str]:
        self.events.append("finish")
        return {"FINISHED"}

    def _discard(self, context: Any) -> None:
        self.events.append("discard")


def _fake_context() -> SimpleNamespace:
    headers: list[str | None] = []
    progress: list[int] = []
    wm = SimpleNamespace(progress_update=progress.append, progress_end=lambda: None,
                         event_timer_remove=lambda _t: None)
    area = SimpleNamespace(header_text_set=headers.append)
    return SimpleNamespace(window_manager=wm, area=area, headers=headers, progress=progress)


TIMER = SimpleNamespace(type="TIMER")


def test_straight_through_runs_every_step_then_finishes(capsys: pytest.CaptureFixture[str]) -> None:
    op = Counting()
    assert op.execute(None) == {"FINISHED"}
    assert op.done == list(range(10))
    assert op.events == ["prepare", "closed", "finish"]
    if bpy.app.background:  # the bpy module runs in background mode: progress is printed
        assert "ProcLoco: counting 100%" in capsys.readouterr().out


def test_modal_ticks_show_progress_and_finish_once() -> None:
    op, ctx = Counting(), _fake_context()
    op._prepare(ctx)
    op._steps = op._run(ctx, True)
    results = [op.modal(ctx, TIMER) for _ in range(12)]
    assert results[:10] == [{"RUNNING_MODAL"}] * 10  # one step per tick (budget 0)
    assert results[10] == {"FINISHED"}
    assert results[11] == {"PASS_THROUGH"}  # nothing left to run
    assert ctx.progress[:3] == [10, 20, 30]
    assert ctx.headers[0] == "ProcLoco: counting 10% (Esc to cancel)"
    assert ctx.headers[-1] is None  # the header is given back
    assert op.modal(ctx, SimpleNamespace(type="MOUSEMOVE")) == {"PASS_THROUGH"}


def test_escape_closes_the_work_and_discards_it() -> None:
    op, ctx = Counting(), _fake_context()
    op._prepare(ctx)
    op._steps = op._run(ctx, True)
    for _ in range(3):
        op.modal(ctx, TIMER)
    assert op.modal(ctx, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert op.done == [0, 1, 2]
    assert op.events == ["prepare", "closed", "discard"]  # never finished
    assert op.reports == [("WARNING", "Counting cancelled")]
    assert op._steps is None


@pytest.mark.parametrize("modal", [False, True])
def test_an_error_in_the_work_is_reported_and_nothing_is_finished(modal: bool) -> None:
    op, ctx = Counting(fail_at=4), _fake_context()
    if modal:
        op._prepare(ctx)
        op._steps = op._run(ctx, True)
        results = [op.modal(ctx, TIMER) for _ in range(6)]
        assert results[4] == {"CANCELLED"}
    else:
        assert op.execute(ctx) == {"CANCELLED"}
    assert "finish" not in op.events
    assert op.reports == [("ERROR", "step 4 failed")]


def _drive_modal(op_class: Any, context: Any, ticks: int, **attrs: Any) -> SimpleNamespace:
    """An instance-like namespace running ``op_class``'s own loop methods, ``ticks`` timer
    ticks after a successful prepare."""
    me = SimpleNamespace(report=lambda *_a: None, _timer=None, _steps=None, _tick_budget_s=0.0,
                         _cancelled_message="cancelled", _run_errors=op_class._run_errors, **attrs)
    for name in ("_prepare", "_run", "_stop", "_abort", "_discard", "_finish"):
        setattr(me, name, getattr(op_class, name).__get__(me))
    assert me._prepare(context)
    me._steps = me._run(context, True)
    for _ in range(ticks):
        assert op_class.modal(me, context, TIMER) == {"RUNNING_MODAL"}
    return me


def _context_for(scene: Any) -> SimpleNamespace:
    wm = SimpleNamespace(progress_update=lambda _v: None, progress_end=lambda: None,
                         event_timer_remove=lambda _t: None)
    return SimpleNamespace(**{k: getattr(bpy.context, k) for k in
                              ("scene", "view_layer", "active_object", "selected_objects")},
                           window_manager=wm, area=None,
                           evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)


def test_escape_midway_through_a_secondary_bake_leaves_the_scene_unchanged(empty_scene: Any) -> None:
    from procloco_addon.blender.secondary.ops import PROCLOCO_OT_bake_secondary_motion as Op
    from tests.blender.test_secondary import _frames, _key_object_path, _lizard, _select_only

    lizard = _lizard(empty_scene)
    _frames(empty_scene, 1, 30)
    _key_object_path(lizard, 24, 1.2)
    _select_only(lizard)
    empty_scene.frame_set(7)
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}  # Esc during a re-bake
    before = snapshot()
    context = _context_for(empty_scene)
    me = _drive_modal(Op, context, 10, _job=None)
    assert empty_scene.frame_current != 7  # the bake is playing the animation
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert snapshot() == before


@pytest.mark.parametrize(("op", "settings", "items", "index", "empty_message"), [
    ("remove_gait_change", "procloco", "gait_changes", "active_gait_change_index", "Select a gait change"),
    ("remove_secondary_chain", "procloco_secondary", "chains", "active_chain_index", "no chain to remove"),
    ("remove_biped_clip", "procloco_biped", "clips", "active_clip_index", "Select a clip"),
])
def test_remove_buttons_remove_the_active_item_and_keep_the_index_on_a_neighbour(
    empty_scene: Any, op: str, settings: str, items: str, index: str, empty_message: str
) -> None:
    from tests.blender.test_gait_presets import make_rig

    obj = make_rig(empty_scene)
    operator = getattr(bpy.ops.procloco, op)
    assert not operator.poll()
    with pytest.raises(RuntimeError, match=empty_message):
        operator()
    group = getattr(obj, settings)
    collection = getattr(group, items)
    for name in ("a", "b", "c"):
        collection.add().name = name
    setattr(group, index, 2)
    assert operator() == {"FINISHED"}
    assert [item.name for item in collection] == ["a", "b"]
    assert getattr(group, index) == 1  # the last one went: its neighbour is active
    setattr(group, index, 0)
    assert operator() == {"FINISHED"}
    assert [item.name for item in collection] == ["b"]
    assert getattr(group, index) == 0
