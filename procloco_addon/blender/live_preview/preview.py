# SPDX-License-Identifier: GPL-3.0-or-later
"""What one Live Preview regeneration does, and which Actions it may touch.

A regeneration is Generate Locomotion's own pipeline (``locomotion.generate``: read, read
the terrain, simulate, write) run as progress steps (:func:`regenerate_steps`) that the
timer in :mod:`.handler` advances a slice at a time. Three things differ from the button:

* the simulation starts from the rig's last run (``simulation.Checkpoints``, kept in the
  :class:`TerrainCache`) at the last frame the edit leaves as it was: the same walk, only
  the frames from there on simulated again;
* the current frame's pose is written first: once the simulation has reached the current
  frame, a one-frame Action holding that pose is assigned (so the viewport shows the new
  pose long before the range is done); the whole walk then replaces it;
* the Actions are **preview Actions** (:data:`PREVIEW_TAG`, with the :func:`input_signature`
  they were made from), and what the rig had before the preview began, its *base*, is kept
  alive (a generated base gets a fake user for the time of the preview) so that
  :func:`discard` can give it back. Each regeneration supersedes the previous preview
  Action (deleted); one that fails or is cut short leaves the previous one in place.

:func:`keep` ends a preview keeping its last walk as the rig's generated Action (the base
is then superseded as by Generate Locomotion); :func:`discard` ends it giving the rig its
base back. Actions the user made are never written, and never deleted.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Generator, Sequence
from typing import Any

import bpy
import numpy as np

from .. import actions, rig, scene_terrain
from ..locomotion import generate, simulation
from ..modal import Steps, steps_with_result

__all__ = [
    "PARTIAL_TAG",
    "PREVIEW_TAG",
    "TerrainCache",
    "discard",
    "input_signature",
    "is_previewing",
    "keep",
    "preview_action",
    "regenerate_steps",
    "settings_signature",
    "sweep",
    "up_to_date",
]

#: On a preview Action: the name of its rig.
PREVIEW_TAG = "_procloco_preview"
#: On a preview Action: the :func:`input_signature` it was made from.
INPUTS_TAG = "_procloco_preview_inputs"
#: On the one-frame Action written before the whole walk.
PARTIAL_TAG = "_procloco_preview_partial"
# On the rig while a preview runs: what it had before (Action, slot, the Action's fake user).
_HAS_BASE = "_procloco_preview_has_base"
_BASE = "_procloco_preview_base"
_BASE_SLOT = "_procloco_preview_base_slot"
_BASE_FAKE = "_procloco_preview_base_fake"
_BASE_KEYS = (_HAS_BASE, _BASE, _BASE_SLOT, _BASE_FAKE)

# Settings that are not inputs of the walk: the toggle itself, list cursors and the Quality
# panel's figures measured on the result.
_NOT_INPUTS = frozenset({"rna_type", "live_preview", "active_leg_index", "active_gait_change_index",
                         "quality"})


# ---------------------------------------------------------------------------------------
# What a walk is made from


def _group_values(group: Any) -> tuple[Any, ...]:
    out: list[Any] = []
    for prop in group.bl_rna.properties:
        key = prop.identifier
        if key in _NOT_INPUTS:
            continue
        value = getattr(group, key)
        if prop.type == "COLLECTION":
            value = tuple(_group_values(item) for item in value)
        elif prop.type == "POINTER":
            value = None if value is None else (value.name if isinstance(value, bpy.types.ID)
                                                else _group_values(value))
        elif getattr(prop, "is_array", False):
            value = tuple(value)
        out.append((key, value))
    return tuple(out)


def settings_signature(obj: bpy.types.Object, scene: bpy.types.Scene) -> tuple[Any, ...]:
    """Every ProcLoco setting of ``obj`` that shapes its walk, with the scene's frame range
    and frame rate (cheap: read at each poll of the timer)."""
    render = scene.render
    return (_group_values(obj.procloco), int(scene.frame_start), int(scene.frame_end),
            int(render.fps), float(render.fps_base))


def _terrain_part(context: bpy.types.Context, obj: bpy.types.Object) -> tuple[Any, ...]:
    """Where the terrain objects are and what their meshes hold. Objects that move by
    themselves (keys, constraints, parents) are sampled over the range by Generate: their
    placement at the current frame is left out, or every frame change would look like an edit."""
    return tuple(_terrain_entry(ob) for ob in scene_terrain.terrain_objects(context, [obj],
                                                                             obj.procloco.terrain_collection))


def _terrain_entry(ob: bpy.types.Object) -> tuple[Any, ...]:
    animated = scene_terrain._maybe_animated(ob)
    entry: list[Any] = [ob.name, ob.type, str(getattr(ob, "procloco_role", "AUTO")), animated]
    if not animated:
        entry.append(np.array(ob.matrix_world, dtype=np.float64).round(9).tobytes())
    data = ob.data
    if ob.type == "MESH" and data is not None:
        co = np.empty(len(data.vertices) * 3, dtype=np.float32)
        data.vertices.foreach_get("co", co)
        entry += [data.name, hashlib.blake2b(co.tobytes(), digest_size=16).hexdigest(),
                  tuple(m.type for m in ob.modifiers)]
    return tuple(entry)


_Boxes = dict[str, tuple[Any, np.ndarray]]


def _terrain_boxes(context: bpy.types.Context, names: Sequence[str]) -> _Boxes:
    """Each terrain object's :func:`_terrain_entry` and world xy bounds ``(4,)`` (x0, y0, x1,
    y1) as evaluated now."""
    depsgraph = context.evaluated_depsgraph_get()
    out = {}
    for name in names:
        ob = bpy.data.objects.get(name)
        if ob is None:
            continue
        ev = ob.evaluated_get(depsgraph)
        corners = np.array([tuple(c) for c in ev.bound_box], dtype=np.float64).reshape(-1, 3)
        world = corners @ np.array(ev.matrix_world, dtype=np.float64)[:3, :3].T + np.array(
            ev.matrix_world, dtype=np.float64)[:3, 3]
        out[name] = (_terrain_entry(ob), np.concatenate([world[:, :2].min(axis=0), world[:, :2].max(axis=0)]))
    return out


def _changed_boxes(old: _Boxes, new: _Boxes) -> np.ndarray:
    """``(m, 4)`` the world xy bounds, before and after, of the terrain objects that changed
    (moved, edited, added or taken away) from ``old`` to ``new`` (:func:`_terrain_boxes`)."""
    boxes = []
    for name in old.keys() | new.keys():
        a, b = old.get(name), new.get(name)
        if a is not None and b is not None and a[0] == b[0]:
            continue
        boxes += [item[1] for item in (a, b) if item is not None]
    return np.array(boxes, dtype=np.float64).reshape(-1, 4)


def _path_part(context: bpy.types.Context, obj: bpy.types.Object) -> Any:
    path = obj.procloco.path
    if path is None:
        return None
    try:
        return generate.path_points(context, path).round(9).tobytes()
    except generate.GenerateError as err:
        return str(err)


def input_signature(context: bpy.types.Context, obj: bpy.types.Object,
                    settings: tuple[Any, ...] | None = None) -> tuple[str, str]:
    """``(whole, terrain)``: digests of everything the walk of ``obj`` is made from (its
    settings, its path curve as evaluated, the terrain objects' placement and meshes), and of
    the terrain part alone (the key of the terrain read kept between regenerations).
    ``settings``: the rig's :func:`settings_signature` if just taken (the timer's poll)."""
    terrain = repr(_terrain_part(context, obj)).encode()
    if settings is None:
        settings = settings_signature(obj, context.scene)
    whole = repr((settings, _path_part(context, obj))).encode() + terrain
    return (hashlib.blake2b(whole, digest_size=16).hexdigest(),
            hashlib.blake2b(terrain, digest_size=16).hexdigest())


# ---------------------------------------------------------------------------------------
# The Actions of a preview


def preview_action(obj: bpy.types.Object) -> bpy.types.Action | None:
    """The rig's current Action if Live Preview made it, else None."""
    action = actions.generated_action(obj)  # (its tag names the rig; a renamed rig's is still its own)
    return action if action is not None and action.get(PREVIEW_TAG) is not None else None


def is_previewing(obj: bpy.types.Object) -> bool:
    """A preview has begun on ``obj`` and was neither kept nor discarded."""
    return _HAS_BASE in obj


def up_to_date(obj: bpy.types.Object, signature: str) -> bool:
    """The rig shows the whole walk made from ``signature``."""
    action = preview_action(obj)
    return action is not None and action.get(INPUTS_TAG) == signature and PARTIAL_TAG not in action


def _base(obj: bpy.types.Object) -> bpy.types.Action | None:
    base = obj.get(_BASE)
    return base if isinstance(base, bpy.types.Action) else None


def _begin(obj: bpy.types.Object) -> None:
    """Remember what the rig has before its first preview Action; a generated Action (an
    earlier Generate) is kept alive with a fake user until the preview ends. When the
    animator assigned another Action during the preview, that one is the base from now on."""
    adt = obj.animation_data
    current = adt.action if adt is not None else None
    if is_previewing(obj):
        if current is None or current == _base(obj) or current.get(PREVIEW_TAG) is not None:
            return
        _release_base(obj, None)
    obj[_HAS_BASE] = 1
    obj[_BASE_SLOT] = str(adt.action_slot.identifier) if (
        actions.is_slotted() and adt is not None and adt.action_slot is not None) else ""
    if current is not None:
        obj[_BASE] = current
        obj[_BASE_FAKE] = int(current.use_fake_user)
        if actions.is_generated(current):
            current.use_fake_user = True  # the first preview Action would supersede it


def _release_base(obj: bpy.types.Object, superseded_by: bpy.types.Action | None) -> None:
    """Give the base back its own fake-user flag and forget it; with ``superseded_by``, a
    generated base nothing else uses is deleted as Generate Locomotion would (that Action
    takes its name)."""
    base = _base(obj)
    fake = bool(obj.get(_BASE_FAKE, 0))
    for key in _BASE_KEYS:  # (the rig's pointer to the base is one of its users)
        if key in obj:
            del obj[key]
    if base is not None and actions.is_generated(base):
        base.use_fake_user = fake
        if superseded_by is not None:
            actions.delete_superseded([(base, superseded_by)])


def keep(obj: bpy.types.Object) -> bpy.types.Action | None:
    """End the preview keeping its walk as the rig's generated Action (Clear Generated
    Action then gives back what the rig had before it); returns that Action."""
    action = preview_action(obj)
    if action is not None:
        for key in (PREVIEW_TAG, INPUTS_TAG, PARTIAL_TAG):
            if key in action:
                del action[key]
    _release_base(obj, action)
    sweep(obj.name)
    return action


def discard(obj: bpy.types.Object) -> None:
    """End the preview giving the rig back the Action (and pose) it had before it began."""
    action = preview_action(obj)
    base = _base(obj)
    if action is not None:
        if base is not None and actions.is_generated(base):
            actions.restore_pose(obj, action)
            actions.assign_action(obj, base, slot_identifier=str(obj.get(_BASE_SLOT, "")))
            if action.users == 0 and not action.use_fake_user:
                bpy.data.actions.remove(action)
        else:
            actions.clear_generated_action(obj)
    _release_base(obj, None)
    sweep(obj.name)


def sweep(rig_name: str) -> None:
    """Delete the preview Actions of ``rig_name`` that nothing but a fake user keeps (left by
    an undo or a file saved in the middle of a regeneration, when the previous preview Action
    is kept by a fake user until the new one is written). A preview Action is ProcLoco's until
    it is kept."""
    for action in list(bpy.data.actions):
        if action.get(PREVIEW_TAG) == rig_name and action.users - int(action.use_fake_user) == 0:
            bpy.data.actions.remove(action)


def _mark(action: bpy.types.Action, signature: str, partial: bool) -> None:
    action[PREVIEW_TAG] = action[actions.GENERATED_TAG]
    action[INPUTS_TAG] = signature
    if partial:
        action[PARTIAL_TAG] = 1


# ---------------------------------------------------------------------------------------
# One regeneration


class TerrainCache:
    """The terrain last read for each rig, reused while its objects do not change (an edit
    of the gait or the speed re-simulates without reading the scene's meshes again), and
    each rig's last simulation (``simulation.Checkpoints``: a run on the same terrain
    starts from the last frame whose inputs are unchanged)."""

    def __init__(self) -> None:
        self._items: dict[str, tuple[tuple[Any, ...], scene_terrain.SceneTerrain]] = {}
        self._runs: dict[str, simulation.Checkpoints] = {}
        # the last two terrains read for each rig, with their objects' _terrain_boxes
        self._boxes: dict[str, list[tuple[scene_terrain.SceneTerrain, _Boxes]]] = {}

    def runs(self, rig: str) -> simulation.Checkpoints:
        """The last simulation of ``rig`` (empty at first)."""
        return self._runs.setdefault(rig, simulation.Checkpoints())

    def get(self, rig: str, key: tuple[Any, ...]) -> scene_terrain.SceneTerrain | None:
        item = self._items.get(rig)
        return item[1] if item is not None and item[0] == key else None

    def put(self, rig: str, key: tuple[Any, ...], terrain: scene_terrain.SceneTerrain) -> None:
        self._items[rig] = (key, terrain)

    def read(self, rig: str, terrain: scene_terrain.SceneTerrain, boxes: _Boxes) -> None:
        """``terrain`` was read for ``rig``, its objects as :func:`_terrain_boxes` says."""
        self._boxes[rig] = [*self._boxes.get(rig, [])[-1:], (terrain, boxes)]

    def changed(self, rig: str, old: Any, new: Any) -> np.ndarray | None:
        """The world xy bounds ``(m, 4)`` of what changed from terrain ``old`` to ``new`` of
        ``rig`` (:func:`_changed_boxes`), None when either is not one of its last two reads."""
        found = {id(terrain): boxes for terrain, boxes in self._boxes.get(rig, [])
                 if terrain is old or terrain is new}
        if old is None or id(old) not in found or id(new) not in found:
            return None
        return _changed_boxes(found[id(old)], found[id(new)])

    def clear(self) -> None:
        self._items.clear()
        self._runs.clear()
        self._boxes.clear()


class _FromFrame:
    """A job's terrain seen from frame index ``first`` on (for the one-frame job)."""

    def __init__(self, terrain: scene_terrain.SceneTerrain, first: int) -> None:
        self._terrain = terrain
        self._first = first

    def __getattr__(self, name: str) -> Any:
        return getattr(self._terrain, name)

    def apply_frame(self, f: int) -> None:
        self._terrain.apply_frame(self._first + f)


def _frame_job(job: generate.Job, k: int) -> generate.Job:
    """The job of frame index ``k`` alone, from the simulation's results so far."""
    assert job.partial is not None
    assert job.terrain is not None
    so_far = job.partial(k + 1)
    one = dataclasses.replace(so_far, **{  # type: ignore[arg-type]
        f.name: None if getattr(so_far, f.name) is None else getattr(so_far, f.name)[k:k + 1]
        for f in dataclasses.fields(so_far)})
    terrain: Any = _FromFrame(job.terrain, k)
    return dataclasses.replace(job, frames=job.frames[k:k + 1], result=one, partial=None, terrain=terrain,
                               warnings=[], timings={}, keyed_bones=())


def _read_terrain(context: bpy.types.Context, job: generate.Job, cache: TerrainCache,
                  terrain_signature: str) -> Generator[float, None, None]:
    # (objects that move by themselves are read over the range: without any, the same terrain
    # serves any range, and a run over a longer or shorter range starts from the last one's)
    animated = any(scene_terrain._maybe_animated(bpy.data.objects[name]) for name in job.terrain_objects)
    key = (terrain_signature, (int(job.frames[0]), int(job.frames[-1])) if animated else None,
           round(job.lift, 9))
    terrain = cache.get(job.obj_name, key)
    if terrain is None:
        yield from generate.read_terrain(context, job)
        assert job.terrain is not None
        cache.put(job.obj_name, key, job.terrain)
        # (where its objects are: a run that never looked where they changed starts from the last one)
        cache.read(job.obj_name, job.terrain, _terrain_boxes(context, job.terrain_objects))
        return
    # (the terrain's own caches, its planning windows' rasterised tiles among them, are kept:
    # they never change a result, and the next walk crosses much the same ground)
    try:
        scene_terrain.check_ground_under(terrain, job.info.contact, job.obj_name,
                                         reach=float(np.mean(job.info.leg_length)))
    except scene_terrain.TerrainError as err:
        raise generate.GenerateError(str(err)) from err
    job.terrain = terrain
    job.warnings.extend(terrain.warnings)


def regenerate_steps(context: bpy.types.Context, obj_name: str, signature: tuple[str, str],
                     cache: TerrainCache, done: list[generate.Job],
                     reads: rig.ReadCache | None = None) -> Steps:
    """Re-generate the walk of ``obj_name`` into a new preview Action, as progress steps
    ``(text, fraction)``; the finished job is appended to ``done``. ``cache`` and ``reads``:
    the terrain and the rig as read for the last regeneration, reused while unchanged.

    Raises :class:`.generate.GenerateError` on bad input. When it fails or is closed early,
    the rig has what it had before (the previous preview Action, assigned, its pose), and
    no Action it wrote is left.
    """
    obj = bpy.data.objects[obj_name]
    job = generate.read(context, obj, reads)
    yield "reading the terrain", 0.0
    for fraction in _read_terrain(context, job, cache, signature[1]):
        yield "reading the terrain", 0.1 * fraction
    began = not is_previewing(obj)
    _begin(obj)
    memo = actions.remember_assignment(obj)
    before = memo.action
    if before is not None and actions.is_generated(before):
        before.use_fake_user = True  # the one-frame Action must not supersede it: kept until the end
    early: bpy.types.Action | None = None
    n = int(job.frames.size)
    k = int(np.clip(context.scene.frame_current - job.frames[0], 0, n - 1))
    try:
        kept = cache.runs(obj_name)
        kept.current = k  # (a state before it kept: a Gait Change added there starts from it)
        kept.changed = cache.changed(obj_name, kept.terrain, job.terrain)
        for i, fraction in enumerate(generate.simulate(job, kept)):
            yield obj_name, 0.1 + 0.8 * fraction
            # The current frame first, the rest of the range follows (on the last frame too:
            # one frame is keyed in a fraction of the time the whole range takes).
            if i == k and n > 1:
                made = yield from steps_with_result(
                    generate.write_all_steps(context, [_frame_job(job, k)]), "showing the current frame",
                    0.1 + 0.8 * fraction, 0.0, generate.GenerateError, "the preview")
                early = made[0]
                _mark(early, signature[0], partial=True)
        made = yield from steps_with_result(generate.write_all_steps(context, [job]), "writing the preview",
                                            0.9, 0.1, generate.GenerateError, "the preview")
    except BaseException:
        if early is not None and early.name in bpy.data.actions:
            actions.restore_pose(obj, early)
            actions.undo_assignment(obj, memo)  # the previous Action again, with its own fake user
            bpy.data.actions.remove(early)
        elif before is not None:
            before.use_fake_user = memo.fake_user
        if began:  # the first regeneration of this preview: the rig as it was, bookkeeping included
            _release_base(obj, None)
        raise
    _mark(made[0], signature[0], partial=False)
    if before is not None and before != _base(obj):
        before.use_fake_user = memo.fake_user
        if before.get(PREVIEW_TAG) is not None:
            actions.delete_superseded([(before, made[0])])
    done.append(job)
