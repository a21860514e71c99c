# SPDX-License-Identifier: GPL-3.0-or-later
"""The only writer of animation data in ProcLoco.

Everything that creates Actions, writes keyframes or assigns an Action to an object goes
through this module, so that one place knows both worlds:

* Blender 4.4+ and 5.x: *slotted* Actions. An Action holds ``slots``; F-curves live in
  ``action.layers[0].strips[0].channelbag(slot).fcurves`` and the object's
  ``animation_data.action_slot`` says which slot animates it. (5.0 removed the legacy
  ``Action.fcurves``.)
* Blender 4.2 LTS: legacy Actions with ``action.fcurves`` and ``fcurves.new(..., action_group=)``.

Keys are written in bulk: ``keyframe_points.add(n)`` then ``foreach_set("co", ...)`` and
``foreach_set("interpolation", ...)`` from numpy arrays, about a hundred times faster than a
per-frame ``keyframe_insert``.

Rules this module keeps for the animator:

* A generation makes a **new** Action named after the object (``"<object> ProcLoco"``;
  Blender appends ``.001`` ... when the name is taken). It never writes into, overwrites or
  deletes an Action it did not create.
* :func:`assign_generated_action` remembers what the object had before (Action and slot) in
  hidden ID properties on the object, which also keep that Action alive when the file is
  saved. :func:`restore_previous_action` puts it back. Generating again keeps the memory of
  the *user's* Action, not of the previous generation; a replaced generated Action gets a
  fake user so that it is never lost silently, unless the new one supersedes it (a re-bake)
  and nothing else uses it: then it is deleted and the new one takes its name.
* The pose (``matrix_basis`` channels) of every bone a generated Action keys is remembered
  as it was before ProcLoco first keyed it, so :func:`clear_generated_action` gives back a
  hand-posed, unkeyed bone too.
* Writing several rigs is all or nothing: :func:`remember_assignment` before assigning and
  :func:`undo_assignment` take an assignment back, and an Action superseded during the
  write can be collected (``superseded``) and deleted only once every rig is written
  (:func:`delete_superseded`).
* Rotations are keyed in each pose bone's (or object's) own rotation mode: quaternion, any
  Euler order, or axis-angle, with sign/branch continuity from frame to frame.

Shapes: ``frames`` is ``(n_frames,)``; per-channel values are ``(n_frames, n_channels)``;
quaternions are ``(..., 4)`` in Blender's ``(w, x, y, z)`` order.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import bpy
import numpy as np

__all__ = [
    "GENERATED_TAG",
    "ActionError",
    "Assignment",
    "Channel",
    "assign_action",
    "assign_generated_action",
    "channels_of",
    "clear_generated_action",
    "delete_superseded",
    "forget_previous",
    "generated_action",
    "is_generated",
    "is_slotted",
    "keyed_pose_bones",
    "make_cyclic",
    "new_action",
    "previous_action",
    "push_to_nla",
    "quaternion_to_euler",
    "read_channel",
    "read_channels",
    "remember_assignment",
    "remember_pose",
    "restore_previous_action",
    "rotation_channels",
    "sample_channels",
    "undo_assignment",
    "write_bezier_channels",
    "write_channels",
    "write_object_transforms",
    "write_pose_bone_transforms",
]

#: ID property set on every Action this module creates; its value is the object's name.
GENERATED_TAG = "_procloco_generated"
# Hidden ID properties on the object (a leading underscore hides them from the UI).
_PREV_ACTION = "_procloco_prev_action"
_PREV_SLOT = "_procloco_prev_slot"
_HAS_PREV = "_procloco_has_prev"
_PREV_POSE = "_procloco_prev_pose"
_HIDDEN_KEYS = (_HAS_PREV, _PREV_ACTION, _PREV_SLOT, _PREV_POSE)
# A pose bone's channels, in the order they are remembered.
_POSE_CHANNELS = (("location", 3), ("rotation_quaternion", 4), ("rotation_euler", 3),
                  ("rotation_axis_angle", 4), ("scale", 3))
# On a generated Action: the pose channels and custom properties it animates, as they were
# before the first generation (JSON), put back by Clear Generated Action.
_RESTORE = "_procloco_restore"

_OBJECT_GROUP = "Object Transforms"
_EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


class ActionError(RuntimeError):
    """Animation data cannot be written as asked (the message is meant for the user)."""


@dataclass(frozen=True)
class Channel:
    """One animated property: ``data_path`` and ``index`` as in an F-curve; ``group`` its channel group."""

    data_path: str
    index: int = 0
    group: str = ""


# ---------------------------------------------------------------------------------------
# Which world are we in


def is_slotted() -> bool:
    """True on Blender 4.4+ (slotted Actions), False on 4.2/4.3 (legacy ``action.fcurves``)."""
    global _SLOTTED
    if _SLOTTED is None:  # (asked per F-curve written: looked up once)
        _SLOTTED = bpy.app.version >= (4, 4, 0) and "slots" in bpy.types.Action.bl_rna.properties
    return _SLOTTED


_SLOTTED: bool | None = None


def _interpolation_code(name: str) -> int:
    return int(bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items[name].value)


# ---------------------------------------------------------------------------------------
# Creating and assigning Actions


def new_action(obj: bpy.types.Object, suffix: str = "ProcLoco") -> bpy.types.Action:
    """A new, empty Action for ``obj``, named ``"<obj.name> <suffix>"`` (made unique by Blender).

    The Action is tagged as generated (:data:`GENERATED_TAG`) and, on 4.4+, gets one slot for
    the object. It is not assigned; see :func:`assign_generated_action`.
    """
    action = bpy.data.actions.new(f"{obj.name} {suffix}".strip())
    action[GENERATED_TAG] = obj.name
    if is_slotted():
        action.slots.new(id_type="OBJECT", name=obj.name)
    else:
        action.id_root = "OBJECT"
    return action


def is_generated(action: bpy.types.Action | None) -> bool:
    """True if ``action`` was created by :func:`new_action`."""
    return action is not None and GENERATED_TAG in action


def _slot_for(action: bpy.types.Action, obj: bpy.types.Object) -> Any:
    """The slot of ``action`` that animates ``obj``: the assigned one, else one named after it,
    else the first object slot, else a new one."""
    adt = obj.animation_data
    if adt is not None and adt.action == action and adt.action_slot is not None:
        return adt.action_slot
    candidates = [s for s in action.slots if s.target_id_type in {"OBJECT", "UNSPECIFIED"}]
    for slot in candidates:
        if slot.name_display == obj.name:
            return slot
    if candidates:
        return candidates[0]
    return action.slots.new(id_type="OBJECT", name=obj.name)


def assign_action(obj: bpy.types.Object, action: bpy.types.Action | None, slot_identifier: str = "") -> None:
    """Make ``action`` the object's active Action (``None`` unassigns).

    On 4.4+ the slot is chosen by ``slot_identifier`` when given and present, otherwise as in
    :func:`_slot_for`. Raises :class:`ActionError` while the object's NLA is in tweak mode.
    """
    adt = obj.animation_data
    if adt is not None and adt.use_tweak_mode:
        raise ActionError(f"'{obj.name}' is in NLA tweak mode; leave tweak mode first")
    if action is None:
        if adt is not None:
            adt.action = None
        return
    adt = obj.animation_data_create()
    adt.action = action
    if is_slotted():
        slot = None
        if slot_identifier:
            slot = next((s for s in action.slots if s.identifier == slot_identifier), None)
        if slot is None:
            slot = _slot_for(action, obj)
        if adt.action_slot != slot:
            adt.action_slot = slot


def _current_slot_identifier(obj: bpy.types.Object) -> str:
    adt = obj.animation_data
    if not is_slotted() or adt is None or adt.action_slot is None:
        return ""
    return str(adt.action_slot.identifier)


def keyed_pose_bones(action: bpy.types.Action | None, obj: bpy.types.Object) -> set[str]:
    """Names of the pose bones ``action`` animates on ``obj``."""
    if action is None:
        return set()
    prefix = 'pose.bones["'
    out = set()
    for ch in channels_of(action, obj):
        if ch.data_path.startswith(prefix):
            end = ch.data_path.find('"]', len(prefix))
            if end > 0:
                out.add(ch.data_path[len(prefix):end].replace('\\"', '"').replace("\\\\", "\\"))
    return out


def _pose_values(pb: Any) -> list[float]:
    out: list[float] = []
    for name, _n in _POSE_CHANNELS:
        out.extend(float(v) for v in getattr(pb, name))
    return out


def _set_pose_values(pb: Any, values: Sequence[float]) -> None:
    k = 0
    for name, n in _POSE_CHANNELS:
        setattr(pb, name, tuple(values[k:k + n]))
        k += n


def _remember_pose(obj: bpy.types.Object, action: bpy.types.Action, fresh: bool) -> None:
    """Remember the current pose of the bones ``action`` keys that are not remembered yet
    (``fresh``: forget what was remembered before)."""
    if obj.pose is None:
        return
    stored = {} if fresh or _PREV_POSE not in obj else {k: list(v) for k, v in obj[_PREV_POSE].items()}
    for name in keyed_pose_bones(action, obj):
        pb = obj.pose.bones.get(name)
        if pb is not None and name not in stored:
            stored[name] = _pose_values(pb)
    obj[_PREV_POSE] = stored


def _restore_remembered_pose(obj: bpy.types.Object, keyed_by_restored: set[str]) -> None:
    """Put back the remembered pose of bones the restored Action does not key (those it keys
    are its own again at the next evaluation)."""
    if obj.pose is None or _PREV_POSE not in obj:
        return
    for name, values in obj[_PREV_POSE].items():
        pb = obj.pose.bones.get(name)
        if pb is not None and name not in keyed_by_restored:
            _set_pose_values(pb, list(values))


@dataclass
class Assignment:
    """What :func:`undo_assignment` needs to take an assignment back."""

    action: bpy.types.Action | None
    slot: str
    fake_user: bool
    hidden: dict[str, Any]


def _copy_idprop(value: Any) -> Any:
    return value.to_dict() if hasattr(value, "to_dict") else value


def remember_assignment(obj: bpy.types.Object) -> Assignment:
    """The object's Action, slot and ProcLoco's memory of the user's state, as they are now."""
    adt = obj.animation_data
    current = adt.action if adt is not None else None
    return Assignment(current, _current_slot_identifier(obj),
                      bool(current.use_fake_user) if current is not None else False,
                      {k: _copy_idprop(obj[k]) for k in _HIDDEN_KEYS if k in obj})


def undo_assignment(obj: bpy.types.Object, memo: Assignment) -> None:
    """Give ``obj`` back what :func:`remember_assignment` saw (the Action, slot, memory)."""
    assign_action(obj, memo.action, slot_identifier=memo.slot)
    if memo.action is not None:
        memo.action.use_fake_user = memo.fake_user
    for key in _HIDDEN_KEYS:
        if key in obj:
            del obj[key]
    for key, value in memo.hidden.items():
        obj[key] = value


def delete_superseded(pairs: Sequence[tuple[bpy.types.Action, bpy.types.Action]]) -> None:
    """Delete each superseded Action of ``(superseded, new)`` that nothing uses any more; the
    new one takes its name (see :func:`assign_generated_action`)."""
    for superseded, action in pairs:
        if superseded.users == 0 and not superseded.use_fake_user:
            name = superseded.name
            bpy.data.actions.remove(superseded)
            if _unnumbered(action.name) == _unnumbered(name):
                action.name = name  # "Lizard Secondary" again rather than "Lizard Secondary.001"


def assign_generated_action(
    obj: bpy.types.Object, action: bpy.types.Action, *, replace: bool = False,
    superseded: list[tuple[bpy.types.Action, bpy.types.Action]] | None = None,
) -> None:
    """Assign a generated ``action`` to ``obj``, remembering what the user had before.

    If the object's current Action is itself generated, the remembered user Action is kept
    (so Clear goes back to the user's animation, however many times one generates), and the
    replaced generated Action gets a fake user so it stays reachable.

    ``replace``: the new Action supersedes the current one (the same operation run again,
    e.g. a re-bake). Then a current Action that ProcLoco generated and that nothing else
    uses (this object is its only user, no fake user) is deleted instead, and ``action``
    takes over its name. Anything else is kept as above; an Action the user made is never
    deleted. With ``superseded`` given, the Action to delete is appended there as
    ``(old, action)`` instead, for :func:`delete_superseded` once every rig is written.

    The current pose of every bone ``action`` keys and no earlier generation keyed is
    remembered for :func:`clear_generated_action`.
    """
    adt = obj.animation_data
    if adt is not None and adt.use_tweak_mode:
        raise ActionError(f"'{obj.name}' is in NLA tweak mode; leave tweak mode first")
    current = adt.action if adt is not None else None
    old = None
    fresh = False
    if current is not None and is_generated(current):
        if current != action:
            if replace and current.users == 1 and not current.use_fake_user:
                old = current
            else:
                current.use_fake_user = True
    else:
        fresh = True
        obj[_HAS_PREV] = 1
        obj[_PREV_SLOT] = _current_slot_identifier(obj)
        if current is not None:
            obj[_PREV_ACTION] = current
        elif _PREV_ACTION in obj:
            del obj[_PREV_ACTION]
    _remember_pose(obj, action, fresh)
    assign_action(obj, action)
    if old is not None:
        if superseded is not None:
            superseded.append((old, action))
        else:
            delete_superseded([(old, action)])


def _unnumbered(name: str) -> str:
    """A name without Blender's ``.001``-style suffix."""
    stem, dot, number = name.rpartition(".")
    return stem if dot and number.isdigit() else name


def generated_action(obj: bpy.types.Object) -> bpy.types.Action | None:
    """The object's active Action if ProcLoco generated it, else ``None``."""
    adt = obj.animation_data
    action = adt.action if adt is not None else None
    return action if is_generated(action) else None


def previous_action(obj: bpy.types.Object) -> tuple[bool, bpy.types.Action | None]:
    """``(remembered, action)``: whether a previous state is remembered, and its Action (or None)."""
    if _HAS_PREV not in obj:
        return False, None
    prev = obj.get(_PREV_ACTION)
    return True, prev if isinstance(prev, bpy.types.Action) else None


def forget_previous(obj: bpy.types.Object) -> None:
    """Forget what was remembered of the user's state before the first generation (the
    Action, slot and pose); nothing else changes."""
    for key in _HIDDEN_KEYS:
        if key in obj:
            del obj[key]


def restore_previous_action(obj: bpy.types.Object) -> bool:
    """Put back the Action (and slot) the object had before the first generation.

    Returns False when nothing was remembered. The remembered state is forgotten afterwards.
    """
    remembered, prev = previous_action(obj)
    if not remembered:
        return False
    assign_action(obj, prev, slot_identifier=str(obj.get(_PREV_SLOT, "")))
    _restore_remembered_pose(obj, keyed_pose_bones(prev, obj))
    forget_previous(obj)
    return True


def remember_pose(action: bpy.types.Action, obj: bpy.types.Object, bones: Sequence[str],
                  props: Sequence[tuple[str, str]] = ()) -> None:
    """Store on ``action`` the current transform channels of pose ``bones`` and the custom
    properties ``props`` (``(bone, name)``, or a pose bone's own float such as ``ik_stretch``)
    of ``obj``, for :func:`clear_generated_action`.

    When the object's current Action is a generated one that remembers the pose before it,
    that older memory wins for the channels it holds (Clear goes back to the user's pose).
    """
    current = generated_action(obj)
    data: dict[str, Any] = {"bones": {}, "props": {}}
    if current is not None and _RESTORE in current:
        data = json.loads(str(current[_RESTORE]))
    pbones = obj.pose.bones
    for name in bones:
        pb = pbones.get(name)
        if pb is None or name in data["bones"]:
            continue
        data["bones"][name] = {prop: list(getattr(pb, prop)) for prop in (
            "location", "rotation_quaternion", "rotation_euler", "rotation_axis_angle", "scale")}
    for bone, prop in props:
        key = json.dumps([bone, prop])
        pb = pbones.get(bone)
        if pb is None or key in data["props"]:
            continue
        if prop in pb:
            value = pb[prop]
            if isinstance(value, (bool, int, float)):
                data["props"][key] = [type(value).__name__, float(value)]
        elif isinstance(getattr(pb, prop, None), float):  # a pose bone's own (ik_stretch)
            data["props"][key] = ["rna", float(getattr(pb, prop))]
    action[_RESTORE] = json.dumps(data)


def restore_pose(obj: bpy.types.Object, action: bpy.types.Action) -> None:
    """Put back the channels and switch properties :func:`remember_pose` stored on ``action``
    (a write given up half way leaves the rig's pose as it found it)."""
    _restore_from_action(obj, action)


def _restore_from_action(obj: bpy.types.Object, action: bpy.types.Action) -> None:
    """Put back the channels and switch properties :func:`remember_pose` stored on ``action``."""
    if _RESTORE not in action:
        return
    data = json.loads(str(action[_RESTORE]))
    pbones = obj.pose.bones
    for name, channels in data.get("bones", {}).items():
        pb = pbones.get(name)
        if pb is not None:
            for prop, value in channels.items():
                setattr(pb, prop, value)
    kinds = {"bool": bool, "int": int, "float": float}
    for key, (kind, value) in data.get("props", {}).items():
        bone, prop = json.loads(key)
        pb = pbones.get(bone)
        if pb is not None and kind == "rna":
            setattr(pb, prop, float(value))
        elif pb is not None and prop in pb:
            pb[prop] = kinds.get(kind, float)(value)


def clear_generated_action(obj: bpy.types.Object) -> bool:
    """Unassign the object's generated Action, restore the previous one and delete the generated
    Action when nothing else uses it; channels the generated Action animated get back the values
    they had before it (:func:`remember_pose`). Returns False (and changes nothing) when the
    object's active Action is not a generated one."""
    action = generated_action(obj)
    if action is None:
        return False
    _restore_from_action(obj, action)
    if not restore_previous_action(obj):
        assign_action(obj, None)
    if action.users == 0 and not action.use_fake_user:
        bpy.data.actions.remove(action)
    return True


# ---------------------------------------------------------------------------------------
# F-curves


def _fcurve_collection(action: bpy.types.Action, obj: bpy.types.Object, create: bool) -> Any:
    """The F-curve collection of ``action`` for ``obj`` (a channelbag's on 4.4+)."""
    if not is_slotted():
        return action.fcurves
    slot = _slot_for(action, obj) if create else _find_slot(action, obj)
    if slot is None:
        return None
    if not action.layers:
        if not create:
            return None
        action.layers.new("Layer")
    layer = action.layers[0]
    if not layer.strips:
        if not create:
            return None
        layer.strips.new(type="KEYFRAME")
    bag = layer.strips[0].channelbag(slot, ensure=create)
    return bag.fcurves if bag is not None else None


def _find_slot(action: bpy.types.Action, obj: bpy.types.Object) -> Any:
    adt = obj.animation_data
    if adt is not None and adt.action == action and adt.action_slot is not None:
        return adt.action_slot
    slots = [s for s in action.slots if s.target_id_type in {"OBJECT", "UNSPECIFIED"}]
    named = [s for s in slots if s.name_display == obj.name]
    if named:
        return named[0]
    return slots[0] if slots else None


def _new_fcurve(fcurves: Any, channel: Channel) -> Any:
    if is_slotted():
        return fcurves.new(channel.data_path, index=channel.index, group_name=channel.group)
    return fcurves.new(channel.data_path, index=channel.index, action_group=channel.group)


def write_channels(
    action: bpy.types.Action,
    obj: bpy.types.Object,
    channels: Sequence[Channel],
    frames: np.ndarray,
    values: np.ndarray,
    interpolation: str = "LINEAR",
) -> None:
    """Write one F-curve per channel in bulk: ``values[:, c]`` keyed at ``frames``.

    frames: ``(n_frames,)`` strictly increasing; values: ``(n_frames, n_channels)``.
    An existing F-curve with the same path and index in this Action is replaced wholesale.
    Refuses (:class:`ActionError`) to write into an Action ProcLoco did not create.
    """
    if not is_generated(action):
        raise ActionError(f"Action '{action.name}' was not made by ProcLoco; it is never written to")
    frames = np.asarray(frames, dtype=np.float64).reshape(-1)
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 1:
        values = values[:, None]
    n_frames = frames.shape[0]
    if values.shape != (n_frames, len(channels)):
        raise ValueError(f"values shape {values.shape} != ({n_frames}, {len(channels)})")
    if n_frames == 0 or not channels:
        return
    if not np.all(np.isfinite(values)):
        raise ActionError("refusing to key non-finite values")
    if n_frames > 1 and not np.all(np.diff(frames) > 0):
        raise ValueError("frames must be strictly increasing")
    fcurves = _fcurve_collection(action, obj, create=True)
    ipo = np.full(n_frames, _interpolation_code(interpolation), dtype=np.int32)
    co = np.empty((len(channels), n_frames, 2), dtype=np.float32)  # every curve's keys, a row each
    co[:, :, 0] = frames
    co[:, :, 1] = values.T
    existing = {(fc.data_path, fc.array_index): fc for fc in fcurves} if len(fcurves) else {}
    new = fcurves.new
    slotted = is_slotted()
    for c, channel in enumerate(channels):
        old = existing.pop((channel.data_path, channel.index), None) if existing else None
        if old is not None:
            fcurves.remove(old)
        if slotted:
            fcurve = new(channel.data_path, index=channel.index, group_name=channel.group)
        else:
            fcurve = new(channel.data_path, index=channel.index, action_group=channel.group)
        points = fcurve.keyframe_points
        points.add(n_frames)
        points.foreach_set("co", co[c].ravel())
        points.foreach_set("interpolation", ipo)
        fcurve.update()


def write_bezier_channels(
    action: bpy.types.Action,
    obj: bpy.types.Object,
    channels: Sequence[Channel],
    curves: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    handle_type: str = "FREE",
) -> int:
    """Write one Bézier F-curve per channel in bulk, handles as given.

    curves: per channel ``(co, handle_left, handle_right)``, each ``(n_keys, 2)`` as
    ``(frame, value)``, frames strictly increasing. Every key gets Bézier interpolation and
    ``handle_type`` on both sides (``"FREE"`` or ``"ALIGNED"`` keep the positions given;
    automatic types would recompute them). An existing F-curve with the same path and index
    is replaced wholesale. Refuses (:class:`ActionError`) to write into an Action ProcLoco did
    not create. Returns the number of keys written.
    """
    if not is_generated(action):
        raise ActionError(f"Action '{action.name}' was not made by ProcLoco; it is never written to")
    if len(curves) != len(channels):
        raise ValueError(f"{len(curves)} curves for {len(channels)} channels")
    for co, hl, hr in curves:
        arrays = [np.asarray(a, dtype=np.float64) for a in (co, hl, hr)]
        if any(a.ndim != 2 or a.shape != arrays[0].shape or a.shape[1] != 2 for a in arrays):
            raise ValueError("each curve needs (n, 2) points and handles of one shape")
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise ActionError("refusing to key non-finite values")
        if arrays[0].shape[0] > 1 and not np.all(np.diff(arrays[0][:, 0]) > 0):
            raise ValueError("frames must be strictly increasing")
    fcurves = _fcurve_collection(action, obj, create=True)
    bezier = _interpolation_code("BEZIER")
    side = bpy.types.Keyframe.bl_rna.properties["handle_left_type"].enum_items[handle_type].value
    existing = {(fc.data_path, fc.array_index): fc for fc in fcurves}
    total = 0
    for channel, (co, hl, hr) in zip(channels, curves, strict=True):
        n = int(np.asarray(co).shape[0])
        if n == 0:
            continue
        old = existing.pop((channel.data_path, channel.index), None)
        if old is not None:
            fcurves.remove(old)
        fcurve = _new_fcurve(fcurves, channel)
        points = fcurve.keyframe_points
        points.add(n)
        # Types first: with automatic types, setting positions would be undone by update().
        points.foreach_set("interpolation", np.full(n, bezier, dtype=np.int32))
        points.foreach_set("handle_left_type", np.full(n, side, dtype=np.int32))
        points.foreach_set("handle_right_type", np.full(n, side, dtype=np.int32))
        points.foreach_set("co", np.asarray(co, dtype=np.float32).ravel())
        points.foreach_set("handle_left", np.asarray(hl, dtype=np.float32).ravel())
        points.foreach_set("handle_right", np.asarray(hr, dtype=np.float32).ravel())
        fcurve.update()
        total += n
    return total


def read_channels(
    action: bpy.types.Action, obj: bpy.types.Object
) -> list[tuple[Channel, np.ndarray, np.ndarray]]:
    """Every F-curve of ``action`` for ``obj`` with its keys: ``(channel, frames, values)``,
    both ``(n_keys,)``, read in bulk (any Action; nothing is changed)."""
    fcurves = _fcurve_collection(action, obj, create=False)
    if fcurves is None:
        return []
    out = []
    for fc in fcurves:
        points = fc.keyframe_points
        co = np.empty(2 * len(points), dtype=np.float32)
        points.foreach_get("co", co)
        co2 = co.reshape(-1, 2).astype(np.float64)
        out.append((Channel(fc.data_path, fc.array_index, fc.group.name if fc.group else ""),
                    co2[:, 0], co2[:, 1]))
    return out


def sample_channels(action: bpy.types.Action, obj: bpy.types.Object, frames: np.ndarray,
                    select: Callable[[str], bool] | None = None) -> dict[tuple[str, int], np.ndarray]:
    """What each F-curve of ``action`` for ``obj`` (whose data path ``select`` accepts, all
    by default) gives at the integer ``frames`` ``(F,)``, ``{(data_path, index): values (F,)}``,
    as the animation system evaluates it: muted curves (or curves of a muted group) are left
    out; on a frame that holds a key the curve's value is that key's (the keys read in bulk),
    elsewhere, and on a curve with modifiers, the curve is evaluated (``FCurve.evaluate``).
    Nothing is changed."""
    fcurves = _fcurve_collection(action, obj, create=False)
    if fcurves is None:
        return {}
    wanted = np.asarray(frames, dtype=np.float64).reshape(-1)
    n_curves = len(fcurves)
    muted = np.empty(n_curves, dtype=bool)  # (the flags and indices of every curve read in bulk)
    fcurves.foreach_get("mute", muted)
    indices = np.empty(n_curves, dtype=np.int32)
    fcurves.foreach_get("array_index", indices)
    curves = []
    for fc, mute, index in zip(fcurves, muted.tolist(), indices.tolist(), strict=True):
        if mute:
            continue
        path = fc.data_path
        if select is not None and not select(path):
            continue
        group = fc.group
        if group is not None and group.mute:
            continue
        points = fc.keyframe_points
        curves.append((fc, path, index, points, len(points)))
    if not curves:
        return {}
    counts = np.array([c[4] for c in curves], dtype=np.int64)
    start = np.concatenate([[0], np.cumsum(counts)])
    co = np.empty(2 * int(start[-1]), dtype=np.float32)
    for (_fc, _path, _index, points, n), s in zip(curves, start, strict=False):
        points.foreach_get("co", co[2 * s: 2 * (s + n)])
    keys = co.reshape(-1, 2).astype(np.float64)
    # Every curve's keys in one sorted run of (curve, frame): one search finds each wanted frame.
    span = float(max(np.abs(keys[:, 0]).max(initial=0.0), np.abs(wanted).max(initial=0.0))) * 2.0 + 2.0
    owner = np.repeat(np.arange(len(curves)), counts)
    ranked = owner * span + keys[:, 0]
    asked = (np.arange(len(curves))[:, None] * span + wanted[None]).reshape(-1)
    found = np.zeros(asked.shape, dtype=bool)
    values = np.full(asked.shape, np.nan)
    if ranked.size:
        at = np.minimum(np.searchsorted(ranked, asked), ranked.size - 1)
        found = ranked[at] == asked
        values[found] = keys[at[found], 1]
    found = found.reshape(len(curves), -1)
    values = values.reshape(len(curves), -1)
    complete = found.all(axis=1)
    out: dict[tuple[str, int], np.ndarray] = {}
    for c, (fc, path, index, _points, _n) in enumerate(curves):
        row = values[c]
        modified = len(fc.modifiers)
        if modified or not complete[c]:
            for f in range(wanted.shape[0]) if modified else np.flatnonzero(~found[c]):
                row[f] = fc.evaluate(float(wanted[f]))
        out[(path, index)] = row
    return out


def channels_of(action: bpy.types.Action, obj: bpy.types.Object) -> list[Channel]:
    """Every F-curve ``action`` holds for ``obj`` (read-only view, any Action)."""
    fcurves = _fcurve_collection(action, obj, create=False)
    if fcurves is None:
        return []
    return [Channel(fc.data_path, fc.array_index, fc.group.name if fc.group else "") for fc in fcurves]


def read_channel(
    action: bpy.types.Action, obj: bpy.types.Object, data_path: str, index: int = 0
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(frames, values)`` of one F-curve's keyframes, both ``(n_keys,)``; None if absent."""
    fcurves = _fcurve_collection(action, obj, create=False)
    if fcurves is None:
        return None
    fcurve = fcurves.find(data_path, index=index)
    if fcurve is None:
        return None
    points = fcurve.keyframe_points
    co = np.empty(2 * len(points), dtype=np.float32)
    points.foreach_get("co", co)
    co2 = co.reshape(-1, 2).astype(np.float64)
    return co2[:, 0], co2[:, 1]


def make_cyclic(action: bpy.types.Action, obj: bpy.types.Object,
                offset_channels: set[tuple[str, int]] | frozenset[tuple[str, int]] = frozenset()) -> float:
    """Make ``action`` a loop for ``obj`` (Make Cycle): on each of its F-curves the last key
    takes the first key's value, except the ``(data_path, index)`` channels of
    ``offset_channels``, which repeat moved on by their change over the loop (root motion);
    a Cycles modifier repeats every curve before and after its keys (with offset for those),
    so the loop plays on in Blender and in the NLA; the Action's manual frame range is the
    loop's and it is flagged cyclic, which exporters and the NLA read.

    Returns the largest change made to a key value (how far the loop was from closing).
    Refuses (:class:`ActionError`) an Action ProcLoco did not create.
    """
    if not is_generated(action):
        raise ActionError(f"Action '{action.name}' was not made by ProcLoco; it is never written to")
    fcurves = _fcurve_collection(action, obj, create=False)
    worst = 0.0
    first, last = np.inf, -np.inf
    for fcurve in fcurves if fcurves is not None else ():
        points = fcurve.keyframe_points
        n = len(points)
        if n < 2:
            continue
        co = np.empty(2 * n, dtype=np.float32)
        points.foreach_get("co", co)
        co2 = co.reshape(n, 2)
        first, last = min(first, float(co2[0, 0])), max(last, float(co2[-1, 0]))
        offset = (fcurve.data_path, fcurve.array_index) in offset_channels
        if not offset:
            worst = max(worst, abs(float(co2[-1, 1]) - float(co2[0, 1])))
            co2[-1, 1] = co2[0, 1]
            points.foreach_set("co", co)
        for old in [m for m in fcurve.modifiers if m.type == "CYCLES"]:
            fcurve.modifiers.remove(old)
        cycles = fcurve.modifiers.new("CYCLES")
        cycles.mode_before = cycles.mode_after = "REPEAT_OFFSET" if offset else "REPEAT"
        fcurve.update()
    if first < last:
        action.use_frame_range = True
        action.frame_start, action.frame_end = first, last
        action.use_cyclic = True
    return worst


def push_to_nla(obj: bpy.types.Object, action: bpy.types.Action, track_name: str = "ProcLoco") -> Any:
    """Add ``action`` as a strip on a new NLA track of ``obj`` (starting at its first key)."""
    adt = obj.animation_data_create()
    track = adt.nla_tracks.new()
    track.name = track_name
    start = int(np.floor(action.frame_range[0]))
    strip = track.strips.new(action.name, start, action)
    if is_slotted() and hasattr(strip, "action_slot"):
        slot = _find_slot(action, obj)
        if slot is not None and strip.action_slot != slot:
            strip.action_slot = slot
    return strip


# ---------------------------------------------------------------------------------------
# Rotations in any rotation mode


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) -> (..., 3, 3) rotation matrices."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    m = np.empty((*q.shape[:-1], 3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - w * z)
    m[..., 0, 2] = 2 * (x * z + w * y)
    m[..., 1, 0] = 2 * (x * y + w * z)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - w * x)
    m[..., 2, 0] = 2 * (x * z - w * y)
    m[..., 2, 1] = 2 * (y * z + w * x)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def quaternion_to_euler(q: np.ndarray, order: str = "XYZ") -> np.ndarray:
    """(..., 4) quaternions -> (..., 3) Euler angles ``(x, y, z)`` in Blender's convention for
    ``order`` (``"XYZ"`` applies X first, then Y, then Z: ``R = Rz @ Ry @ Rx``)."""
    if order not in _EULER_ORDERS:
        raise ValueError(f"unknown Euler order {order!r}")
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    m = _quat_to_matrix(q)
    i, j, k = ("XYZ".index(a) for a in order)
    # sign +1 for the cyclic orders XYZ, YZX, ZXY; -1 for the others.
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    s_mid = np.clip(-sign * m[..., k, i], -1.0, 1.0)
    mid = np.arcsin(s_mid)
    first = np.arctan2(sign * m[..., k, j], m[..., k, k])
    last = np.arctan2(sign * m[..., j, i], m[..., i, i])
    # Gimbal lock: put everything into the first angle, keep the last at 0.
    locked = np.abs(s_mid) > 1.0 - 1e-9
    if np.any(locked):
        alt_first = np.arctan2(-sign * m[..., j, k], m[..., j, j])
        first = np.where(locked, alt_first, first)
        last = np.where(locked, 0.0, last)
    out = np.empty((*q.shape[:-1], 3))
    out[..., i] = first
    out[..., j] = mid
    out[..., k] = last
    return out


def _euler_continuous(euler: np.ndarray, order: str) -> np.ndarray:
    """Along axis 0 (frames), pick per frame the Euler triple (of the two equivalent ones and
    their 2π shifts) closest to the previous frame's, so curves do not jump."""
    i, j, k = ("XYZ".index(a) for a in order)
    out = euler.copy()
    alt = euler.copy()
    alt[..., i] = euler[..., i] + np.pi
    alt[..., j] = np.pi - euler[..., j]
    alt[..., k] = euler[..., k] + np.pi
    two_pi = 2.0 * np.pi
    for f in range(1, euler.shape[0]):
        prev = out[f - 1]
        a = euler[f] + two_pi * np.round((prev - euler[f]) / two_pi)
        b = alt[f] + two_pi * np.round((prev - alt[f]) / two_pi)
        use_b = np.sum((b - prev) ** 2, axis=-1) < np.sum((a - prev) ** 2, axis=-1)
        out[f] = np.where(use_b[..., None], b, a)
    return out


def _quat_continuous(q: np.ndarray) -> np.ndarray:
    """Flip signs along axis 0 (frames) so consecutive quaternions are in the same hemisphere."""
    # Frame f is flipped when it faces away from frame f - 1 as written, so its sign is the
    # previous sign times the sign of the two input frames' dot product, and +1 where that
    # product is exactly 0: a running parity of the negative products since the last zero (in
    # one pass: a frame-by-frame loop takes seconds over 10,000 frames).
    dots = np.sum(q[1:] * q[:-1], axis=-1)  # (F - 1, ...)
    negative = np.cumsum(dots < 0.0, axis=0)
    since = np.maximum.accumulate(np.where(dots == 0.0, negative, 0), axis=0)
    sign = np.ones(q.shape[:-1])
    sign[1:] = np.where((negative - since) % 2 == 1, -1.0, 1.0)
    return np.asarray(q * sign[..., None])


def rotation_channels(mode: str, quaternions: np.ndarray) -> tuple[str, np.ndarray]:
    """Convert ``(n_frames, 4)`` quaternions into the property and values that ``mode`` keys.

    Returns ``(property_name, values)`` with values ``(n_frames, 4)`` for ``"QUATERNION"``
    (``rotation_quaternion``) and ``"AXIS_ANGLE"`` (``rotation_axis_angle``: angle, x, y, z),
    ``(n_frames, 3)`` for the Euler orders (``rotation_euler``). Consecutive frames are made
    continuous (no sign flips, no 2π jumps).
    """
    q = np.asarray(quaternions, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    q = _quat_continuous(q)
    if mode == "QUATERNION":
        return "rotation_quaternion", q
    if mode == "AXIS_ANGLE":
        # Keep w >= 0 per frame would flip axes; instead keep the continuous sign and let the
        # angle run past π, which is the same rotation.
        w = np.clip(q[:, 0], -1.0, 1.0)
        angle = 2.0 * np.arccos(w)
        s = np.sqrt(np.maximum(1.0 - w * w, 0.0))
        axis = np.empty((q.shape[0], 3))
        small = s < 1e-9
        axis[~small] = q[~small, 1:] / s[~small, None]
        # No rotation: any axis; reuse the neighbouring frame's so curves stay smooth.
        axis[small] = np.array([0.0, 1.0, 0.0])
        if np.any(small) and not np.all(small):
            idx = np.where(~small, np.arange(q.shape[0]), -1)
            idx = np.maximum.accumulate(idx)
            first_valid = int(np.argmax(~small))
            idx[idx < 0] = first_valid
            axis = axis[idx]
        return "rotation_axis_angle", np.column_stack([angle, axis])
    if mode in _EULER_ORDERS:
        euler = quaternion_to_euler(q, mode)
        return "rotation_euler", _euler_continuous(euler, mode)
    raise ValueError(f"unknown rotation mode {mode!r}")


def write_pose_bone_transforms(
    action: bpy.types.Action,
    obj: bpy.types.Object,
    frames: np.ndarray,
    bone_names: Sequence[str],
    rotations: np.ndarray | None = None,
    locations: np.ndarray | None = None,
    scales: np.ndarray | None = None,
    interpolation: str = "LINEAR",
) -> int:
    """Key pose-bone channels (``matrix_basis`` components) of armature ``obj`` in bulk.

    frames: ``(n_frames,)``; rotations: ``(n_frames, n_bones, 4)`` quaternions written in each
    bone's rotation mode; locations, scales: ``(n_frames, n_bones, 3)``. Channels are grouped by
    bone name. Returns the number of F-curves written.
    """
    pose = obj.pose
    if pose is None:
        raise ActionError(f"'{obj.name}' is not an armature")
    channels: list[Channel] = []
    columns: list[np.ndarray] = []
    bones = pose.bones
    modes = []
    for name in bone_names:
        pbone = bones.get(name)
        if pbone is None:
            raise ActionError(f"'{obj.name}' has no bone '{name}'")
        modes.append(pbone.rotation_mode)
    # The bones of one rotation mode converted together (the conversion is per frame and bone)
    turned: dict[int, tuple[str, np.ndarray]] = {}
    if rotations is not None:
        q = np.asarray(rotations)
        for mode in dict.fromkeys(modes):
            cols = [b for b, m in enumerate(modes) if m == mode]
            if mode == "AXIS_ANGLE":  # (its conversion takes one bone at a time)
                turned.update((b, rotation_channels(mode, q[:, b, :])) for b in cols)
                continue
            prop, vals = rotation_channels(mode, q[:, cols, :])
            turned.update((b, (prop, vals[:, k])) for k, b in enumerate(cols))
    for b, name in enumerate(bone_names):
        base = f'pose.bones["{bpy.utils.escape_identifier(name)}"]'
        if locations is not None:
            channels.extend(Channel(f"{base}.location", a, name) for a in range(3))
            columns.append(np.asarray(locations, dtype=np.float64)[:, b, :])
        if rotations is not None:
            prop, vals = turned[b]
            channels.extend(Channel(f"{base}.{prop}", a, name) for a in range(vals.shape[1]))
            columns.append(vals)
        if scales is not None:
            channels.extend(Channel(f"{base}.scale", a, name) for a in range(3))
            columns.append(np.asarray(scales, dtype=np.float64)[:, b, :])
    if not channels:
        return 0
    write_channels(action, obj, channels, frames, np.concatenate(columns, axis=1), interpolation)
    return len(channels)


def write_object_transforms(
    action: bpy.types.Action,
    obj: bpy.types.Object,
    frames: np.ndarray,
    locations: np.ndarray | None = None,
    rotations: np.ndarray | None = None,
    interpolation: str = "LINEAR",
) -> int:
    """Key the object's own ``location`` ``(n_frames, 3)`` and rotation ``(n_frames, 4)``
    quaternions (written in ``obj.rotation_mode``). Returns the number of F-curves written."""
    channels: list[Channel] = []
    columns: list[np.ndarray] = []
    if locations is not None:
        channels += [Channel("location", a, _OBJECT_GROUP) for a in range(3)]
        columns.append(np.asarray(locations, dtype=np.float64).reshape(-1, 3))
    if rotations is not None:
        prop, vals = rotation_channels(obj.rotation_mode, np.asarray(rotations).reshape(-1, 4))
        channels += [Channel(prop, a, _OBJECT_GROUP) for a in range(vals.shape[1])]
        columns.append(vals)
    if not channels:
        return 0
    write_channels(action, obj, channels, frames, np.concatenate(columns, axis=1), interpolation)
    return len(channels)
