# SPDX-License-Identifier: GPL-3.0-or-later
"""Checks every operator and the batch command make before anything is written.

Blender's float properties accept NaN (a script, a driver, a typo in the batch command) and
clamp infinity to the largest float; neither means anything to the simulation, which would
fail deep inside with "SVD did not converge" after the whole run. These checks name the
setting instead, up front. Each returns a message for the user, or None when all is well;
the operators turn a message into their own error.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["MAX_FRAMES", "frame_range_problem", "non_finite_setting", "placement_problem",
           "tweak_mode_problem"]

#: Longest frame range a job accepts (per-frame arrays of a few hundred bytes per bone).
MAX_FRAMES = 200_000
# Magnitudes beyond this are not a setting but infinity clamped to the largest float.
_HUGE = 1e15


def _bad_float(value: float) -> str | None:
    if math.isnan(value):
        return "is not a number"
    if math.isinf(value) or abs(value) >= _HUGE:
        return f"is {value:g}, out of any usable range"
    return None


def _item_name(item: Any) -> str:
    return str(getattr(item, "label", "") or getattr(item, "name", "") or "?")


def non_finite_setting(group: Any, where: str, depth: int = 0) -> str | None:
    """The first float setting of the property group ``group`` (its collections' items and
    nested groups included) that is NaN or infinite, as a message naming it; None if none.

    ``where`` names the owner in the message, e.g. ``"'Wolf'"``.
    """
    if group is None or depth > 3:
        return None
    for prop in group.bl_rna.properties:
        name = prop.identifier
        if name == "rna_type":
            continue
        if prop.type == "FLOAT":
            value = getattr(group, name)
            values = list(value) if getattr(prop, "array_length", 0) else [value]
            for v in values:
                why = _bad_float(float(v))
                if why is not None:
                    return f"{prop.name} of {where} {why}: set a finite value"
        elif prop.type == "COLLECTION":
            kind = prop.name.rstrip("s").lower() or "item"
            for item in getattr(group, name):
                found = non_finite_setting(item, f"{kind} {_item_name(item)} of {where}", depth + 1)
                if found is not None:
                    return found
        elif prop.type == "POINTER":
            value = getattr(group, name)
            if value is not None and not hasattr(value, "users"):  # a nested group, not an ID
                found = non_finite_setting(value, where, depth + 1)
                if found is not None:
                    return found
    return None


def placement_problem(obj: Any) -> str | None:
    """A message when the object's world placement (or a pose bone's) is not finite."""
    if not np.all(np.isfinite(np.array(obj.matrix_world, dtype=np.float64))):
        return (f"The placement of '{obj.name}' is not finite (location, rotation or scale is NaN or "
                "infinite, on it or a parent): fix its transform")
    return None


def frame_range_problem(obj_name: str, start: int, end: int, what: str = "generating") -> str | None:
    """A message when ``start..end`` cannot be used: reversed, a single frame, or too long."""
    if end < start:
        return (f"The frame range of '{obj_name}' is reversed ({start} to {end}): the end must come "
                "after the start")
    if end == start:
        return (f"The frame range of '{obj_name}' is one frame ({start}): {what} needs at least two "
                "frames")
    if end - start + 1 > MAX_FRAMES:
        return (f"The frame range of '{obj_name}' has {end - start + 1} frames: at most {MAX_FRAMES} "
                "are generated at once; split it")
    return None


def tweak_mode_problem(obj: Any) -> str | None:
    """A message when the object's NLA is in tweak mode (no Action can be assigned then)."""
    adt = getattr(obj, "animation_data", None)
    if adt is not None and adt.use_tweak_mode:
        return f"'{obj.name}' is in NLA tweak mode; leave tweak mode first"
    return None
