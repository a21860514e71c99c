# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Preview's watcher: notices edits, waits for them to settle, re-generates in slices.

One ``bpy.app.timers`` function, :func:`tick`, does everything, so a test drives it by
calling it until it returns None (background mode runs no timers):

* it polls the ProcLoco settings of every rig whose Live Preview is on (or that still shows
  a preview), cheaply (:func:`.preview.settings_signature`), every :data:`POLL_S`: edits
  from the panel, from operators (presets, the viewport gait editor) and from undo are all
  seen the same way. An edit while the rig is re-generating cuts that regeneration short;
* a ``depsgraph_update_post`` handler notices moved or edited objects (the path curve, the
  terrain); the message bus wakes the timer when a ProcLoco setting is edited in the UI
  (property ``update`` callbacks are not used: on Blender 4.2 a property group with Python
  callbacks crashes Blender at exit once the extension was uninstalled);
* an edit (or an object moved) after a quiet time starts a regeneration at once; edits
  that follow each other within :data:`DEBOUNCE_S` wait until that long after the last one;
* before re-generating, the inputs' digest (:func:`.preview.input_signature`) is compared
  with the one the shown preview was made from: a change that changes nothing (or
  ProcLoco's own writes seen by the depsgraph) costs no regeneration;
* a regeneration (:func:`.preview.regenerate_steps`) is advanced :data:`BUDGET_S` at a
  time through the same slicing loop as the modal operators (``modal.advance``). It pushes
  no undo step (only operators do). Its error is shown in the panel and stops the preview
  of that rig until its inputs change, with nothing changed;
* a rig whose Live Preview was switched off keeps its walk once it is up to date
  (:func:`.preview.keep`); the Discard Preview button gives back what it had before.

Loading a file or undoing first stops a regeneration in flight (its Actions taken back),
then the watch starts afresh from what the file holds.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import bpy
from bpy.app.handlers import persistent

from .. import rig
from ..locomotion import generate
from ..modal import Steps, advance
from . import preview

__all__ = [
    "BUDGET_S",
    "DEBOUNCE_S",
    "POLL_S",
    "Status",
    "discard",
    "register",
    "status",
    "tick",
    "unregister",
    "wake",
]

#: Seconds without edits before a burst of edits is re-generated.
DEBOUNCE_S = 0.2
#: Seconds between two polls of the settings while nothing runs.
POLL_S = 0.05
#: Longest time one timer call works before handing control back to the UI.
BUDGET_S = 0.05
#: Seconds between timer calls while a regeneration runs: none, the next call comes at the
#: next turn of Blender's event loop, once it has handled the interface's events and redraws
#: (a wait here would only delay the walk: ten of them made a tenth of a second).
STEP_S = 0.0
#: Seconds to wait when the timer is called while ProcLoco itself is changing the scene.
BUSY_S = 0.01


@dataclass
class _Watch:
    seen: Any = None  # (settings signature, toggle) at the last poll
    due: float | None = None  # when to look at the inputs again
    last_edit: float = float("-inf")
    error: tuple[str, str] | None = None  # (input digest, message): stopped until the inputs change
    warnings: list[str] = field(default_factory=list)
    hinted: bool = False  # an object changed while this rig was re-generating


@dataclass
class _Run:
    rig: str
    steps: Steps
    signature: tuple[str, str]
    done: list[generate.Job]
    text: str = ""
    fraction: float = 0.0


class _State:
    watches: dict[str, _Watch]
    run: _Run | None = None
    busy: bool = False  # ProcLoco itself is changing the scene: the depsgraph hints are its own
    last_move: float = float("-inf")  # when the depsgraph last reported an object moved or edited
    clock: Callable[[], float] = time.monotonic
    registered: bool = False

    def __init__(self) -> None:
        self.watches = {}
        self.cache = preview.TerrainCache()
        self.reads = rig.ReadCache()  # the rigs as read for their last regeneration


_state = _State()


@dataclass(frozen=True)
class Status:
    """What the panel shows for a rig: ``state`` is ``"off"``, ``"waiting"``, ``"running"``,
    ``"ready"``, ``"idle"`` (on, but the rig's Action is not a preview) or ``"error"``."""

    state: str
    text: str = ""
    fraction: float = 0.0
    warnings: tuple[str, ...] = ()


def status(obj: bpy.types.Object) -> Status:
    """Live Preview's state for ``obj``."""
    watch = _state.watches.get(obj.name)
    run = _state.run
    if run is not None and run.rig == obj.name:
        return Status("running", run.text, run.fraction)
    if watch is not None and watch.error is not None:
        return Status("error", watch.error[1])
    if not obj.procloco.live_preview:
        return Status("off")
    if watch is None or watch.due is not None:
        return Status("waiting")
    if preview.preview_action(obj) is None:  # e.g. Generate Locomotion clicked meanwhile
        return Status("idle")
    return Status("ready", warnings=tuple(watch.warnings))


# ---------------------------------------------------------------------------------------
# The timer


def _watched(scene: bpy.types.Scene) -> list[bpy.types.Object]:
    return [o for o in scene.objects if o.type == "ARMATURE"
            and (o.procloco.live_preview or preview.is_previewing(o))]


def _edited(name: str, now: float) -> None:
    """An edit of ``name``'s settings: re-generate at once after a quiet time, else once the
    edits have settled; a regeneration in flight is cut short."""
    watch = _state.watches.setdefault(name, _Watch())
    quiet = now - watch.last_edit >= DEBOUNCE_S
    if _state.run is not None and _state.run.rig == name:
        _stop_run()
        quiet = False
    watch.due = now if quiet else now + DEBOUNCE_S
    watch.last_edit = now


def _stop_run() -> None:
    """Cut the regeneration in flight short: it takes back what it wrote."""
    run, _state.run = _state.run, None
    if run is None:
        return
    _state.busy = True
    try:
        run.steps.close()
    finally:
        _state.busy = False


def _poll(scene: bpy.types.Scene, now: float) -> None:
    names = set()
    for obj in _watched(scene):
        names.add(obj.name)
        seen = (preview.settings_signature(obj, scene), bool(obj.procloco.live_preview))
        watch = _state.watches.setdefault(obj.name, _Watch())
        if seen != watch.seen:
            watch.seen = seen
            _edited(obj.name, now)
    for name in list(_state.watches):
        if name not in names:
            del _state.watches[name]
    if _state.run is not None and _state.run.rig not in names:
        _stop_run()


def _fail(name: str, digest: str, err: BaseException) -> None:
    message = str(err) if isinstance(err, generate.GenerateError) else f"{type(err).__name__}: {err}"
    watch = _state.watches.setdefault(name, _Watch())
    watch.error = (digest, message)
    print(f"ProcLoco Live Preview of '{name}' stopped: {message}")


def _start_due(context: Any, now: float) -> None:
    """Start the regeneration of the first rig whose edits have settled and whose inputs
    differ from what it shows; finish the previews switched off."""
    due = sorted((w.due, name) for name, w in _state.watches.items() if w.due is not None and w.due <= now)
    for _when, name in due:
        watch = _state.watches[name]
        watch.due = None
        obj = bpy.data.objects.get(name)
        if obj is None or obj.type != "ARMATURE":
            continue
        _state.busy = True
        try:
            # (this tick's poll has just read the rig's settings)
            seen = watch.seen[0] if watch.seen is not None else None
            signature = preview.input_signature(context, obj, seen)
        finally:
            _state.busy = False
        on = bool(obj.procloco.live_preview)
        if watch.error is not None and watch.error[0] != signature[0]:
            watch.error = None  # the inputs changed: try again
        current = preview.up_to_date(obj, signature[0])
        if not on and (current or watch.error is not None or preview.preview_action(obj) is None):
            _state.busy = True
            try:
                preview.keep(obj)
            finally:
                _state.busy = False
            watch.error = None
            continue
        if current or watch.error is not None:
            continue
        done: list[generate.Job] = []
        _state.run = _Run(name, preview.regenerate_steps(context, name, signature, _state.cache, done,
                                                         _state.reads), signature, done)
        return


def _advance(now: float) -> None:
    run = _state.run
    assert run is not None

    def show(text: str, fraction: float) -> None:
        run.text, run.fraction = text, fraction

    _state.busy = True
    try:
        finished = advance(run.steps, BUDGET_S, show)
    except Exception as err:
        _state.run = None
        _fail(run.rig, run.signature[0], err)
        return
    finally:
        _state.busy = False
    if not finished:
        return
    _state.run = None
    watch = _state.watches.setdefault(run.rig, _Watch())
    watch.warnings = list(run.done[0].warnings) if run.done else []
    # Look again at once: a rig switched off keeps its walk, an object moved meanwhile is seen.
    watch.due = now + (DEBOUNCE_S if watch.hinted else 0.0)
    watch.hinted = False
    _tag_redraw()


def tick() -> float | None:
    """The timer: poll, start or advance a regeneration. Returns the seconds until it wants
    to run again, or None when no rig is watched (the timer then ends; :func:`wake` starts it)."""
    if _state.busy:
        return BUSY_S
    context = bpy.context
    scene = getattr(context, "scene", None)
    if scene is None:
        return POLL_S
    now = _state.clock()
    try:
        _poll(scene, now)
        if _state.run is None:
            _start_due(context, now)
        if _state.run is not None:
            _advance(now)
    except Exception as err:  # a failure must never break the event loop
        print(f"ProcLoco Live Preview: {type(err).__name__}: {err}")
    if _state.run is not None:
        return STEP_S
    if not _state.watches:
        return None
    waits = [w.due - now for w in _state.watches.values() if w.due is not None]
    return max(0.0, min([POLL_S, *waits]))


def wake() -> None:
    """Make sure the timer runs (a setting was edited, a file loaded, the panel drew)."""
    if not _state.registered or bpy.app.timers.is_registered(tick):
        return
    bpy.app.timers.register(tick, first_interval=0.0, persistent=True)  # (kept across file loads)


def discard(obj: bpy.types.Object) -> None:
    """Stop the preview of ``obj`` and give it back what it had before (Discard Preview)."""
    if _state.run is not None and _state.run.rig == obj.name:
        _stop_run()
    _state.busy = True
    try:
        obj.procloco.live_preview = False
        preview.discard(obj)
    finally:
        _state.busy = False
    watch = _state.watches.pop(obj.name, None)
    del watch


def _tag_redraw() -> None:
    window_manager = getattr(bpy.context, "window_manager", None)
    for window in getattr(window_manager, "windows", ()):
        for area in window.screen.areas:
            if area.type in {"VIEW_3D", "PROPERTIES"}:
                area.tag_redraw()


# ---------------------------------------------------------------------------------------
# Hints: objects moved or edited, settings edited in the UI, files loaded, undo


def _owned_by_a_rig(obj: bpy.types.Object) -> bool:
    if obj.type == "ARMATURE" or (obj.parent is not None and obj.parent.type == "ARMATURE"):
        return True
    return any(m.type == "ARMATURE" for m in getattr(obj, "modifiers", ()))


@persistent
def _on_depsgraph_update(_scene: Any, depsgraph: Any = None) -> None:
    if depsgraph is None:
        return
    # An edited mesh (a weight painted, a vertex moved; a rig's pose updates its skin object,
    # never the mesh) may be a skin: the rigs are read again.
    if (_state.reads.infos or _state.reads.rest) and any(
            isinstance(update.id, bpy.types.Mesh) for update in depsgraph.updates):
        _state.reads.forget_meshes()
    if _state.busy or not _state.watches:
        return
    moved = False
    for update in depsgraph.updates:
        ob = getattr(update.id, "original", update.id)
        if (isinstance(ob, bpy.types.Object) and (update.is_updated_transform or update.is_updated_geometry)
                and not _owned_by_a_rig(ob)):
            moved = True
            break
    if not moved:
        return
    now = _state.clock()
    # A move after a quiet time is looked at at once (a single move: G, a value, Enter); a drag
    # sends many: the ones that follow wait until it stops.
    quiet = now - _state.last_move >= DEBOUNCE_S
    _state.last_move = now
    for name, watch in _state.watches.items():
        if _state.run is not None and _state.run.rig == name:
            watch.hinted = True  # looked at when it is done
        else:
            watch.due = now if quiet else now + DEBOUNCE_S
    wake()


def _forget(*_args: Any) -> None:
    _stop_run()
    _state.last_move = float("-inf")
    _state.watches.clear()
    _state.cache.clear()
    _state.reads.clear()


@persistent
def _on_load_pre(*_args: Any) -> None:
    _forget()


@persistent
def _on_undo_pre(*_args: Any) -> None:
    _forget()


@persistent
def _on_load_post(*_args: Any) -> None:
    _forget()
    for obj in bpy.data.objects:
        if obj.type == "ARMATURE":
            preview.sweep(obj.name)
    _subscribe()
    wake()


@persistent
def _on_undo_post(*_args: Any) -> None:
    wake()


_HANDLERS = (
    (bpy.app.handlers.depsgraph_update_post, _on_depsgraph_update),
    (bpy.app.handlers.load_pre, _on_load_pre),
    (bpy.app.handlers.load_post, _on_load_post),
    (bpy.app.handlers.undo_pre, _on_undo_pre),
    (bpy.app.handlers.redo_pre, _on_undo_pre),
    (bpy.app.handlers.undo_post, _on_undo_post),
    (bpy.app.handlers.redo_post, _on_undo_post),
)

_MSGBUS_OWNER = object()


def _subscribe() -> None:
    """Wake the timer when a ProcLoco setting is edited in the UI (message bus; loading a
    file drops every subscription, so ``load_post`` subscribes again)."""
    from ..locomotion import property_group

    bpy.msgbus.clear_by_owner(_MSGBUS_OWNER)
    for group in (property_group.PROCLOCO_PG_rig_settings, property_group.PROCLOCO_PG_leg,
                  property_group.PROCLOCO_PG_gait_change):
        bpy.msgbus.subscribe_rna(key=group, owner=_MSGBUS_OWNER, args=(), notify=wake)


def register() -> None:
    for handlers, callback in _HANDLERS:
        if callback not in handlers:
            handlers.append(callback)
    _subscribe()
    _state.registered = True
    wake()


def unregister() -> None:
    _stop_run()
    _state.registered = False
    bpy.msgbus.clear_by_owner(_MSGBUS_OWNER)
    for handlers, callback in _HANDLERS:
        while callback in handlers:
            handlers.remove(callback)
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)
    _state.watches.clear()
    _state.cache.clear()
    _state.reads.clear()
