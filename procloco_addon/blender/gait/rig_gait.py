# SPDX-License-Identifier: GPL-3.0-or-later
"""The gait stored on a rig (``Object.procloco``), as the picture and the presets see it.

The rig settings belong to the locomotion feature; this module is the one place where
the gait interface reads and writes them, so a change in their layout is a change here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from ...core.locomotion import autogait, scaling
from ...core.locomotion import gait as core_gait
from ..locomotion import property_group as locomotion_props

__all__ = [
    "AUTO",
    "AutoTrack",
    "RigGait",
    "apply_preset",
    "auto_overrides",
    "auto_params",
    "auto_track",
    "boundary_speeds",
    "choose_gait",
    "circles_at_frame",
    "is_auto",
    "mean_leg_length",
    "phase_at_frame",
    "preset_from_rig",
    "read_rig_gait",
    "set_auto_override",
    "set_leg_sector",
    "set_new_rig_default",
    "store_auto_track",
]

AUTO = "AUTO"
CIRCLES = "CIRCLES"
#: Custom property of a generated Action holding what Auto chose at each frame.
TRACK_PROPERTY = "procloco_auto_gait"


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
    settings.gait_mode = CIRCLES  # picking a preset is choosing the gait
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


# ---------------------------------------------------------------------------- auto gait
def is_auto(obj: Any) -> bool:
    """Whether the rig's gait follows its speed (Gait: Auto)."""
    settings = _settings(obj)
    return settings is not None and settings.gait_mode == AUTO


def set_new_rig_default(obj: Any) -> None:
    """A rig getting its legs for the first time has no gait chosen yet: Auto."""
    settings = _settings(obj)
    if settings is not None:
        settings.gait_mode = AUTO


def choose_gait(obj: Any, choice: str) -> str:
    """Set the rig's gait from a word: ``auto``, ``circles`` or a preset (file stem or name).
    Returns what was chosen; raises ``GaitError`` (nothing changed) for an unknown preset or
    one for other legs."""
    settings = _settings(obj)
    if settings is None:
        raise core_gait.GaitError(f"{getattr(obj, 'name', obj)!r} is not an armature")
    word = choice.strip()
    if word.lower() in ("auto", "circles"):
        settings.gait_mode = word.upper()
        return word.lower()
    preset = core_gait.find_gait_preset(word)
    apply_preset(obj, preset)
    return preset.name


def auto_overrides(obj: Any) -> dict[str, core_gait.GaitPreset]:
    """The rig's per-gait presets for Auto (gait name -> preset). Raises ``GaitError`` when
    the stored text is damaged."""
    settings = _settings(obj)
    text = getattr(settings, "auto_gait_overrides", "") if settings is not None else ""
    if not text:
        return {}
    try:
        data = json.loads(text)
        if not isinstance(data, dict):
            raise TypeError("not an object")
        return {str(k): core_gait.parse_gait_preset(v, f"{k}.json") for k, v in data.items()}
    except (ValueError, TypeError) as err:
        raise core_gait.GaitError(f"the Auto gait overrides of {obj.name} are damaged ({err}); "
                                  "reset them in the Gait section") from err


def set_auto_override(obj: Any, band: str, preset: core_gait.GaitPreset | None) -> None:
    """Use ``preset``'s footfall pattern for Auto's gait ``band`` (None: the shipped one).
    Raises ``GaitError`` (nothing changed) when the preset is not for the rig's legs."""
    settings = _settings(obj)
    gait = read_rig_gait(obj)
    if settings is None or gait is None:
        raise core_gait.GaitError("the active object is not a rig with legs")
    if preset is not None:
        preset.gait(gait.labels)  # the legs must match
    current = {k: v.to_json() for k, v in auto_overrides(obj).items()}
    if preset is None:
        current.pop(band, None)
    else:
        current[band] = preset.to_json()
    settings.auto_gait_overrides = json.dumps(current) if current else ""


def auto_params(obj: Any, info: Any, morphology: Any = None) -> autogait.AutoGaitParams | None:
    """Core auto-gait parameters of armature ``obj`` read as ``info`` (``rig.RigInfo``):
    its legs' family, hip height (hips above the ground contacts at rest), leg length,
    the longest stance sweep its legs allow (``scaling.stroke_limit`` of ``morphology``, the
    rig's core morphology, made from ``info`` when not given), gait speed scale and
    overrides. None when no family fits the legs (their count, or the labels of the
    family's shipped presets)."""
    from .. import rig

    settings = _settings(obj)
    try:
        stroke: float | None = scaling.stroke_limit(morphology if morphology is not None
                                                    else rig.morphology_of(info))
    except rig.RigError:
        stroke = None  # (Generate says what is wrong with the rig)
    labels = [leg.label for leg in info.legs]
    hips = np.array([j[0, 2] for j in info.joints])
    hip_height = float(np.mean(hips - info.contact[:, 2]))
    leg_length = float(np.mean(info.leg_length))
    overrides = auto_overrides(obj)
    try:
        return autogait.auto_gait_params(
            labels, max(hip_height, 1e-3 * leg_length), leg_length,
            speed_scale=float(settings.gait_speed_scale) if settings is not None else 1.0,
            overrides=overrides, stroke=stroke)
    except core_gait.GaitError:
        if overrides:
            raise  # the animator's own preset does not fit: say so
        # The family's presets are for other legs (five legs with the odd one behind, not
        # the pentapod's M1 ahead): no Auto gait, the gait circles.
        return None


@dataclass(frozen=True, eq=False)
class AutoTrack:
    """What Auto does over a rig's frames (``F`` frames, ``n`` legs, ``B`` gaits).

    ``frames (F,)``; ``speed (F,)`` m/s; ``band (F,)`` gait index; ``names (B,)``;
    ``boundaries (B - 1,)`` the speeds (m/s) at which the gaits begin (with the speed scale);
    ``disk_start``, ``disk_duration`` ``(F, n)``; ``needle (F,)`` the cycle phase;
    ``recorded``: read from the generated Action (else predicted from the settings)."""

    frames: np.ndarray
    speed: np.ndarray
    band: np.ndarray
    names: tuple[str, ...]
    boundaries: np.ndarray
    disk_start: np.ndarray
    disk_duration: np.ndarray
    needle: np.ndarray
    recorded: bool

    def index(self, frame: float) -> int:
        return int(np.clip(round(float(frame)) - int(self.frames[0]), 0, self.frames.size - 1))


def store_auto_track(action: Any, track: AutoTrack) -> None:
    """Keep what Auto chose on the generated ``action`` (saved with the .blend), so the panel
    shows the gait of each frame as it was generated."""
    action[TRACK_PROPERTY] = {
        "frames": [int(f) for f in track.frames],
        "speed": [float(v) for v in track.speed],
        "band": [int(b) for b in track.band],
        "names": json.dumps(list(track.names)),
        "boundaries": [float(v) for v in track.boundaries],
        "disk_start": [float(v) for v in track.disk_start.ravel()],
        "disk_duration": [float(v) for v in track.disk_duration.ravel()],
        "needle": [float(v) for v in track.needle],
    }


def _recorded_track(obj: Any, n_legs: int) -> AutoTrack | None:
    from .. import actions

    action = actions.generated_action(obj)
    data = action.get(TRACK_PROPERTY) if action is not None else None
    if data is None:
        return None
    try:
        frames = np.array(data["frames"], dtype=np.int64)
        f = frames.size
        return AutoTrack(
            frames, np.array(data["speed"], dtype=np.float64), np.array(data["band"], dtype=np.int64),
            tuple(json.loads(data["names"])), np.array(data["boundaries"], dtype=np.float64),
            np.array(data["disk_start"], dtype=np.float64).reshape(f, n_legs),
            np.array(data["disk_duration"], dtype=np.float64).reshape(f, n_legs),
            np.array(data["needle"], dtype=np.float64), True)
    except (KeyError, ValueError, TypeError):
        return None  # an older or damaged record: predict instead


_prediction_cache: dict[str, tuple[Any, AutoTrack | None]] = {}


def _predicted_track(obj: Any, scene: Any) -> AutoTrack | None:
    """Auto over the frames at the commanded speeds (the rig's speed and its Gait Changes'),
    as Generate Locomotion would choose it without burst progression or a path's end."""
    from .. import rig
    from ..locomotion import simulation

    settings = _settings(obj)
    start, end = locomotion_props.frame_range(settings, scene)
    fps = scene.render.fps / scene.render.fps_base
    changes = tuple((c.frame, c.transition_time, c.use_speed, c.speed) for c in settings.gait_changes)
    key = (tuple((leg.hip, leg.end, leg.label, leg.enabled) for leg in settings.legs),
           tuple(np.round(np.array(obj.matrix_world), 6).ravel()), float(settings.speed),
           float(settings.gait_speed_scale), settings.auto_gait_overrides, start, end, fps, changes,
           settings.forward_axis)
    cached = _prediction_cache.get(obj.name)
    if cached is not None and cached[0] == key:
        return cached[1]
    track = None
    try:
        legs = [rig.leg_from_bones(obj, leg.hip, leg.end, leg.label) for leg in settings.legs if leg.enabled]
        info = rig.read_rig(obj, legs, settings.forward_axis)
        params = auto_params(obj, info)
    except (rig.RigError, core_gait.GaitError, ValueError):
        params = None
    if params is not None and end > start:
        frames = np.arange(start, end + 1)
        job = SimpleNamespace(speed=float(settings.speed), dt=1.0 / fps, gait_changes=[
            SimpleNamespace(frame_index=max(int(c[0] - start), 0), transition_time=float(c[1]),
                            speed=float(c[3]))
            for c in changes if c[2] and c[0] <= end])
        job.gait_changes.sort(key=lambda c: c.frame_index)
        speed_at = simulation.speed_at(job)  # type: ignore[arg-type]
        speed = np.array([speed_at(k / fps) for k in range(frames.size)])
        band, duty, cycle = params.schedule(speed)
        needle = np.mod(np.concatenate([[0.0], np.cumsum(1.0 / (fps * cycle[:-1]))]), 1.0)
        track = AutoTrack(frames, speed, band, params.names, boundary_speeds(params),
                          params.patterns[band], np.repeat((1.0 - duty)[:, None], params.n_legs, axis=1),
                          needle, False)
    _prediction_cache[obj.name] = (key, track)
    return track


def boundary_speeds(params: autogait.AutoGaitParams) -> np.ndarray:
    """``(B - 1,)`` speeds in m/s at which each gait after the first begins (speed scale and
    the legs' stroke in: ``AutoGaitParams.band_scale``)."""
    edges = params.family.boundaries() * params.band_scale ** 2
    return np.asarray(np.sqrt(edges * params.g * params.size))


def auto_track(obj: Any, scene: Any = None) -> AutoTrack | None:
    """What Auto does over the rig's frames: as last generated (when the rig's Action is
    the generated one and was made with Auto), else predicted from the settings. None when
    the rig is not in Auto or its legs fit no auto-gait family."""
    if not is_auto(obj):
        return None
    gait = read_rig_gait(obj, scene)
    if gait is None:
        return None
    if scene is None:
        import bpy

        scene = bpy.context.scene
    recorded = _recorded_track(obj, len(gait.labels))
    return recorded if recorded is not None else _predicted_track(obj, scene)


def circles_at_frame(obj: Any, scene: Any, frame: float | None = None
                     ) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, float] | None:
    """What the gait circles show at ``frame`` (default the current one): labels, swing
    starts and durations ``(n_legs,)`` and the needle's phase. In Auto, the gait Auto uses
    at that frame; else the rig's circles. None for a rig without legs."""
    gait = read_rig_gait(obj, scene)
    if gait is None:
        return None
    if frame is None:
        frame = scene.frame_current + scene.frame_current_final % 1.0
    track = auto_track(obj, scene)
    if track is not None and track.disk_start.shape[1] == len(gait.labels):
        k = track.index(frame)
        return gait.labels, track.disk_start[k], track.disk_duration[k], float(track.needle[k])
    return gait.labels, gait.swing_start, gait.swing_duration, phase_at_frame(gait, scene, frame)
