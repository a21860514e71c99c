# SPDX-License-Identifier: GPL-3.0-or-later
"""The gait stored on a rig (``Object.procloco``), as the picture and the presets see it.

The rig settings belong to the locomotion feature; this module is the one place where
the gait interface reads and writes them, so a change in their layout is a change here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...core import gait as core_gait
from ..locomotion import property_group as locomotion_props

__all__ = [
    "RigGait",
    "apply_preset",
    "mean_leg_length",
    "phase_at_frame",
    "preset_from_rig",
    "read_rig_gait",
    "set_leg_sector",
]


@dataclass(frozen=True, eq=False)
class RigGait:
    """A rig's gait circles: per leg ``labels``, ``swing_start`` and ``swing_duration``
    (``(n_legs,)`` cycle fractions), the ``cycle_time`` in seconds and the frame where
    the generated walk starts (the needle's phase 0)."""

    labels: tuple[str, ...]
    swing_start: np.ndarray
    swing_duration: np.ndarray
    cycle_time: float
    frame_start: int


def _settings(obj: Any) -> Any:
    if obj is None or getattr(obj, "type", None) != "ARMATURE":
        return None
    return getattr(obj, "procloco", None)


def read_rig_gait(obj: Any, scene: Any = None) -> RigGait | None:
    """The gait of armature ``obj``, or None if it is not a rig with legs.

    ``scene`` (default the context's) decides the first generated frame when the rig
    uses the scene's frame range.
    """
    settings = _settings(obj)
    if settings is None:
        return None
    legs = list(getattr(settings, "legs", ()))
    if not legs:
        return None
    labels = tuple(leg.label or leg.name or f"Leg {i + 1}" for i, leg in enumerate(legs))
    start = np.array([leg.swing_start for leg in legs], dtype=np.float64)
    duration = np.array([leg.swing_duration for leg in legs], dtype=np.float64)
    if scene is None:
        import bpy

        scene = bpy.context.scene
    if scene is not None:
        frame_start = locomotion_props.frame_range(settings, scene)[0]
    else:
        frame_start = int(settings.frame_start)
    return RigGait(labels, start, duration, float(settings.cycle_time), frame_start)


def mean_leg_length(obj: Any) -> float | None:
    """Mean length of the rig's enabled legs in metres (world space), or None if the legs
    cannot be read (missing bones, no legs...)."""
    from .. import rig

    settings = _settings(obj)
    if settings is None:
        return None
    try:
        legs = [rig.leg_from_bones(obj, leg.hip, leg.end, leg.label) for leg in settings.legs if leg.enabled]
        info = rig.read_rig(obj, legs, settings.forward_axis)
    except (rig.RigError, ValueError):
        return None
    lengths = info.leg_length
    return float(lengths.mean()) if lengths.size and np.all(lengths > 0) else None


def phase_at_frame(gait: RigGait, scene: Any, frame: float | None = None) -> float:
    """The needle's cycle phase at ``frame`` (default the scene's current frame).

    The needle starts at phase 0 on the rig's first generated frame and turns once per
    ``cycle_time`` seconds at the scene's frame rate.
    """
    if frame is None:
        frame = scene.frame_current + scene.frame_current_final % 1.0
    fps = scene.render.fps / scene.render.fps_base
    seconds = (float(frame) - gait.frame_start) / fps
    return float(np.mod(seconds / max(gait.cycle_time, 1e-6), 1.0))


def set_leg_sector(obj: Any, leg: int, swing_start: float, swing_duration: float) -> None:
    """Set one leg's swing sector (cycle fractions) on the rig."""
    item = _settings(obj).legs[leg]
    item.swing_start = float(swing_start)
    item.swing_duration = float(swing_duration)


def apply_preset(obj: Any, preset: core_gait.GaitPreset) -> list[str]:
    """Set the rig's gait from ``preset``: legs matched by label (L1, R1, ...), cycle time,
    and speed and step height scaled by the rig's mean leg length.

    Raises ``GaitError`` (and changes nothing) when the preset's legs are not the rig's.
    Returns warnings (the speed and step height are kept when the legs cannot be measured).
    """
    settings = _settings(obj)
    if settings is None:
        raise core_gait.GaitError(f"{getattr(obj, 'name', obj)!r} is not an armature with ProcLoco settings")
    gait = read_rig_gait(obj)
    if gait is None:
        raise core_gait.GaitError(f"{obj.name} has no legs yet: detect its legs first")
    mapped = preset.gait(gait.labels)  # raises before anything is written
    leg_length = mean_leg_length(obj)
    for leg, start, duration in zip(settings.legs, mapped.swing_start, mapped.swing_duration, strict=True):
        leg.swing_start = float(start)
        leg.swing_duration = float(duration)
    settings.cycle_time = float(preset.cycle_time)
    settings.gait_preset = preset.name
    if leg_length is None:
        return [f"could not measure {obj.name}'s legs: speed and step height were kept"]
    settings.speed = preset.speed * leg_length
    settings.step_height = preset.step_height * leg_length
    return []


def preset_from_rig(obj: Any, name: str, source: str = "Saved from a rig in Blender") -> core_gait.GaitPreset:
    """The rig's current gait as a preset called ``name`` (speed and step height in leg
    lengths, as preset files hold them).

    Raises ``GaitError`` when the rig has no legs, its legs cannot be measured, or its
    gait is not valid (a zero or full-cycle swing).
    """
    gait = read_rig_gait(obj)
    settings = _settings(obj)
    if gait is None or settings is None:
        raise core_gait.GaitError("the active object is not a rig with legs")
    leg_length = mean_leg_length(obj)
    if leg_length is None:
        raise core_gait.GaitError(f"could not measure {obj.name}'s legs "
                                  "(check their hip and end-effector bones)")
    data = {
        "format": core_gait.PRESET_FORMAT,
        "name": name.strip(),
        "legs": list(gait.labels),
        "swing_start": [float(v) % 1.0 for v in gait.swing_start],
        "swing_duration": [float(v) for v in gait.swing_duration],
        "cycle_time": gait.cycle_time,
        "speed": float(settings.speed) / leg_length,
        "step_height": float(settings.step_height) / leg_length,
        "source": source,
    }
    return core_gait.parse_gait_preset(data, f"{name}.json")
