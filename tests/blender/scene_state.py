# SPDX-License-Identifier: GPL-3.0-or-later
"""A snapshot of everything an operator could change, to prove a refused operator changed nothing."""

from __future__ import annotations

import math
from typing import Any

import bpy
import numpy as np

#: The property groups ProcLoco attaches to objects.
_GROUPS = ("procloco", "procloco_secondary", "procloco_biped", "procloco_cycle", "procloco_keys")


def _plain(value: Any) -> Any:
    """A comparable copy of one RNA property value (NaN compares equal to NaN)."""
    if isinstance(value, float):
        return "nan" if math.isnan(value) else round(value, 6)
    if isinstance(value, bpy.types.ID):
        return ("ID", value.name)
    if isinstance(value, str | int | bool) or value is None:
        return value
    if hasattr(value, "__len__"):
        return tuple(_plain(v) for v in value)
    return repr(value)


def group_state(group: Any) -> Any:
    """Every property of a property group, collections and nested groups included."""
    if group is None:
        return None
    out: dict[str, Any] = {}
    for prop in group.bl_rna.properties:
        name = prop.identifier
        if name == "rna_type":
            continue
        value = getattr(group, name)
        if prop.type == "COLLECTION":
            out[name] = [group_state(item) for item in value]
        elif prop.type == "POINTER" and isinstance(value, bpy.types.PropertyGroup):
            out[name] = group_state(value)
        else:
            out[name] = _plain(value)
    return out


def _matrix(m: Any) -> Any:
    """A matrix as nested lists, rounded; NaN as a string so that it compares equal."""
    a = np.round(np.array(m, dtype=np.float64), 9)
    return [["nan" if math.isnan(v) else v for v in row] for row in a.tolist()]


def _action_keys(action: Any) -> Any:
    """Every F-curve's path and keys of an Action (4.2 and slotted Actions alike)."""
    bags: list[Any] = []
    if hasattr(action, "layers"):
        for layer in action.layers:
            for strip in layer.strips:
                for slot in action.slots:
                    bag = strip.channelbag(slot)
                    if bag is not None:
                        bags.append((slot.identifier, bag.fcurves))
    else:
        bags.append(("", action.fcurves))
    out = []
    for slot, fcurves in bags:
        for fc in fcurves:
            co = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
            fc.keyframe_points.foreach_get("co", co)
            out.append((slot, fc.data_path, fc.array_index, np.round(co, 5).tolist()))
    return sorted(out)


def snapshot() -> dict[str, Any]:
    """Actions (with their keys), assignments, custom properties, every ProcLoco property
    group, poses and frame of the open file."""
    scene = bpy.context.scene
    bpy.context.view_layer.update()  # evaluated matrices must be current on both sides
    state: dict[str, Any] = {
        "frame": (scene.frame_current, scene.frame_start, scene.frame_end),
        "actions": sorted((a.name, a.users, a.use_fake_user, len(a.keys())) for a in bpy.data.actions),
        "action_keys": {a.name: _action_keys(a) for a in bpy.data.actions},
        "objects": sorted(o.name for o in bpy.data.objects),
        "cameras": sorted(c.name for c in bpy.data.cameras),
        "render": (scene.render.engine, scene.render.filepath, scene.camera.name if scene.camera else None),
    }
    per_object = {}
    for obj in bpy.data.objects:
        adt = obj.animation_data
        entry: dict[str, Any] = {
            "action": adt.action.name if adt is not None and adt.action is not None else None,
            # (registered property groups show up in keys() once read on 4.2: not a change)
            "keys": sorted(set(obj.keys()) - {"procloco", "procloco_role", *_GROUPS}),
            "matrix": _matrix(obj.matrix_world),
            "role": getattr(obj, "procloco_role", None),
        }
        for name in _GROUPS:
            entry[name] = group_state(getattr(obj, name, None))
        if obj.pose is not None:
            entry["pose"] = [_matrix(pb.matrix_basis) for pb in obj.pose.bones]
        per_object[obj.name] = entry
    state["per_object"] = per_object
    return state
