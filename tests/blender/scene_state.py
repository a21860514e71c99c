# SPDX-License-Identifier: GPL-3.0-or-later
"""A snapshot of everything an operator could change, to prove a refused operator changed nothing."""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np


def _settings(obj: Any) -> Any:
    s = getattr(obj, "procloco", None)
    if s is None:
        return None
    plain = {}
    for prop in s.bl_rna.properties:
        name = prop.identifier
        if name in {"rna_type", "legs"}:
            continue
        value = getattr(s, name)
        plain[name] = value.name if hasattr(value, "name") else (tuple(value) if hasattr(value, "__len__")
                                                                  and not isinstance(value, str) else value)
    plain["legs"] = [(leg.name, leg.label, leg.hip, leg.end, leg.enabled, round(leg.swing_start, 6),
                      round(leg.swing_duration, 6), tuple(leg.offset)) for leg in s.legs]
    return plain


def snapshot() -> dict[str, Any]:
    """Actions, assignments, custom properties, settings, poses and frame of the open file."""
    scene = bpy.context.scene
    bpy.context.view_layer.update()  # evaluated matrices must be current on both sides
    state: dict[str, Any] = {
        "frame": (scene.frame_current, scene.frame_start, scene.frame_end),
        "actions": sorted((a.name, a.users, a.use_fake_user, len(a.keys())) for a in bpy.data.actions),
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
            "keys": sorted(set(obj.keys()) - {"procloco", "procloco_role"}),
            "matrix": np.round(np.array(obj.matrix_world), 9).tolist(),
            "settings": _settings(obj),
            "role": getattr(obj, "procloco_role", None),
        }
        if obj.pose is not None:
            entry["pose"] = [np.round(np.array(pb.matrix_basis), 9).tolist() for pb in obj.pose.bones]
        per_object[obj.name] = entry
    state["per_object"] = per_object
    return state
