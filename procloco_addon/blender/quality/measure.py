# SPDX-License-Identifier: GPL-3.0-or-later
"""The quality figures of a generated walk, measured on the written result.

After Generate Locomotion has keyed and assigned a rig's Action, :func:`measure_steps`
reads the posed rig at every frame: the world matrices of every leg bone and foot bone. A
plain rig (no constraints, drivers, NLA or moving object: :mod:`.posed`) is posed from its
Action's channels without the depsgraph; any other rig is evaluated frame by frame through
the depsgraph (the same pose evaluation the pose writer checks its controls with,
:func:`..pose_writer.evaluate_pose_steps`; for many rigs :func:`measure_all_steps`, every
such rig read at each frame of one pass), so Blender's constraints, drivers and the
object's own motion are all in. From those posed legs, the walk's plan (which feet the gait plants,
the targets it set) and the scene's ground under the posed feet, the core's
:func:`...core.metrics.posed_quality` computes the five figures the panel shows, against
the design's thresholds. :func:`store` saves them on the rig's settings (saved in the
.blend) and marks the Action they belong to.

Shapes: ``F`` frames, ``L`` legs, ``P`` probes per foot.
"""

from __future__ import annotations

import uuid
from collections.abc import Generator, Sequence
from typing import Any

import bpy
import numpy as np

from ...core import metrics
from .. import pose_writer
from . import posed
from .property_group import FIGURES

__all__ = [
    "ACTION_KEY",
    "clear",
    "figures_of",
    "is_current",
    "limit_text",
    "measure_all_steps",
    "measure_steps",
    "store",
    "summary_line",
    "value_text",
]

#: Custom property of a measured Action; its value is the rig settings' ``quality.token``.
ACTION_KEY = "_procloco_quality"

#: Each figure's threshold (``DESIGN.md``, "What done means for the motion").
LIMITS: dict[str, float] = {
    "slide": metrics.MAX_STANCE_SLIDE,
    "penetration": metrics.MAX_PENETRATION,
    "reach": metrics.MAX_REACH_ERROR,
    "few_feet_down": float(metrics.MAX_FEW_FEET_FRAMES),
    "over_stretched": float(metrics.MAX_STRETCHED_FRAMES),
}

_KIND = {key: kind for key, _label, kind in FIGURES}


def measure_steps(context: bpy.types.Context, job: Any) -> Generator[float, None, metrics.PosedQuality]:
    """Measure ``job``'s written result on its rig (a finished ``locomotion.generate.Job``
    whose Action is assigned), yielding the fraction done; returns the figures."""
    figures = (yield from measure_all_steps(context, [job]))[0]
    if isinstance(figures, Exception):
        raise figures
    return figures


def measure_all_steps(context: bpy.types.Context, jobs: Sequence[Any],
                      ) -> Generator[float, None, list[metrics.PosedQuality | Exception]]:
    """:func:`measure_steps` for every job at once: plain rigs posed from their Actions, the
    others read at each frame of one pass over the frames (a frame change evaluates all of
    them anyway). Yields the fraction done; returns per job its figures, or the error that
    kept it from being measured."""
    out: list[metrics.PosedQuality | Exception | None] = [None] * len(jobs)
    reads: list[tuple[int, bpy.types.Object, list[str]]] = []
    for k, job in enumerate(jobs):
        try:
            obj = bpy.data.objects[job.obj_name]
            reads.append((k, obj, _measured_bones(job)))
        except Exception as err:  # this rig only: the others are measured
            out[k] = err
    # Plain rigs are posed from their Actions; the others through the depsgraph, in one pass.
    mats: dict[int, np.ndarray] = {}
    for k, obj, names in reads:
        try:
            plain = posed.plain_poses(obj, jobs[k].frames, names)
        except Exception as err:
            out[k] = err
            continue
        if plain is not None:
            mats[k] = plain
    rest = [(k, obj, names) for k, obj, names in reads if k not in mats and out[k] is None]
    if rest:
        evaluated = yield from pose_writer.evaluate_poses_steps(
            [obj for _k, obj, _n in rest], [jobs[k].frames for k, _o, _n in rest],
            [names for _k, _o, names in rest], world=True)
        mats.update((k, m) for (k, _o, _n), m in zip(rest, evaluated, strict=True))
    for k, obj, names in reads:
        if k not in mats:
            continue
        try:
            out[k] = figures_of(jobs[k], obj, names, mats[k])
        except Exception as err:
            out[k] = err
    return [figures if figures is not None else RuntimeError("not measured") for figures in out]


def _measured_bones(job: Any) -> list[str]:
    """The bones whose posed world matrices the figures come from: every leg bone, then
    every foot bone."""
    legs = job.info.legs
    return list(dict.fromkeys([*(b for leg in legs for b in leg.bones),
                               *(b for leg in legs for b in leg.foot)]))


def figures_of(job: Any, obj: bpy.types.Object, names: Sequence[str],
               mats: np.ndarray) -> metrics.PosedQuality:
    """The figures of ``job`` from the evaluated world matrices ``mats`` ``(F, n, 4, 4)`` of
    its rig ``obj``'s bones ``names`` (:func:`_measured_bones`) at its frames."""
    from ..locomotion import simulation

    info = job.info
    legs = info.legs
    foot_bones = [tuple(leg.foot) for leg in legs]
    col = {n: i for i, n in enumerate(names)}
    heads = mats[..., :3, 3]
    # A bone's tail lies along its +Y axis at its rest length (the matrix carries any scale).
    lengths = np.array([obj.data.bones[n].length for n in names])
    tails = heads + mats[..., :3, 1] * lengths[None, :, None]
    hips = np.stack([heads[:, col[leg.bones[0]]] for leg in legs], axis=1)  # (F, L, 3)
    ends = np.stack([tails[:, col[leg.bones[-1]]] for leg in legs], axis=1)
    # Probes: the end-effector (standing its foot height over the ground when down), then
    # each foot bone's head and tail (which may touch it); shorter feet repeat their end.
    n_probe = 1 + 2 * max((len(fb) for fb in foot_bones), default=0)
    probes = np.repeat(ends[:, :, None], n_probe, axis=2)  # (F, L, P, 3)
    lift = np.repeat(np.asarray(info.foot_height, dtype=np.float64)[:, None], n_probe, axis=1)
    for k, fb in enumerate(foot_bones):
        for j, b in enumerate(fb):
            probes[:, k, 1 + 2 * j] = heads[:, col[b]]
            probes[:, k, 2 + 2 * j] = tails[:, col[b]]
            lift[k, 1 + 2 * j: 3 + 2 * j] = 0.0
    ground = simulation.ground_function(job)
    n_frames = len(job.frames)
    frame_index = np.repeat(np.arange(n_frames), len(legs) * n_probe)
    surface = ground(frame_index, probes.reshape(-1, 3)[:, :2]).reshape(probes.shape[:3])
    res = job.result
    return metrics.posed_quality(ends, hips, res.feet, ~np.asarray(res.swing, dtype=bool),
                                 np.asarray(info.leg_length, dtype=np.float64), probes, surface, lift)


def store(obj: bpy.types.Object, action: bpy.types.Action, job: Any, quality: metrics.PosedQuality) -> None:
    """Save ``quality`` (measured on ``job``'s frames) on ``obj``'s settings and mark ``action``
    as the Action it belongs to."""
    q = obj.procloco.quality
    labels = [leg.label for leg in job.info.legs]
    frames = job.frames
    for key, figure in quality.figures():
        value = figure.value
        setattr(q, key, int(value) if isinstance(getattr(q, key), int) else float(value))
        setattr(q, f"{key}_frame", int(frames[figure.frame]) if figure.frame >= 0 else int(frames[0]))
        setattr(q, f"{key}_leg", labels[figure.leg] if figure.frame >= 0 else "")
    # over no ground the hover is infinite; -1 says so (the settings hold finite floats only)
    q.hover = float(quality.hover) if np.isfinite(quality.hover) else -1.0
    q.stretch = float(quality.stretch)
    q.frame_start, q.frame_end = int(frames[0]), int(frames[-1])
    token = uuid.uuid4().hex
    action[ACTION_KEY] = token
    q.token = token
    q.action = action.name
    q.measured = True


def clear(obj: bpy.types.Object) -> None:
    """Forget the figures of ``obj`` (its generated Action was cleared): every value back to
    its default, as before the first generation."""
    q = obj.procloco.quality
    for prop in q.bl_rna.properties:
        if prop.identifier != "rna_type" and not prop.is_readonly:
            q.property_unset(prop.identifier)


def is_current(obj: bpy.types.Object) -> bool:
    """Whether ``obj``'s figures were measured on the Action it has now."""
    q = obj.procloco.quality
    adt = obj.animation_data
    action = adt.action if adt is not None else None
    return bool(q.measured and action is not None and q.token and action.get(ACTION_KEY) == q.token)


def failed(obj: bpy.types.Object, key: str) -> bool:
    """Whether figure ``key`` of ``obj`` is above its threshold."""
    return float(getattr(obj.procloco.quality, key)) > LIMITS[key]


def value_text(obj: bpy.types.Object, key: str, short: bool = False) -> str:
    """Figure ``key`` of ``obj`` as the batch command shows it (``short``: as the panel
    does, without the worst hover or stretch of the frame counts)."""
    q = obj.procloco.quality
    value = getattr(q, key)
    if _KIND[key] == "frames":
        text = f"{int(value)} frame{'' if int(value) == 1 else 's'}"
        if short:
            return text
        if key == "few_feet_down" and value:
            text += " (over no ground)" if q.hover < 0.0 else f" (hangs {q.hover * 1000:.1f} mm)"
        if key == "over_stretched" and value:
            text += f" (to {q.stretch:.3f})"
        return text
    return f"{float(value) * 1000:.2f} mm"


def limit_text(key: str) -> str:
    """The threshold of figure ``key``."""
    limit = LIMITS[key]
    if _KIND[key] == "frames":
        return f"max {int(limit)}"
    return f"max {limit * 1000:g} mm"


def summary_line(obj: bpy.types.Object) -> str:
    """One line with every figure of ``obj`` (the batch command prints it per rig); a figure
    above its threshold says so in capitals."""
    q = obj.procloco.quality
    if not q.measured:
        return f"{obj.name}: quality not measured"
    parts = []
    for key, label, _kind in FIGURES:
        text = f"{label.lower()} {value_text(obj, key)}"
        if getattr(q, f"{key}_leg"):
            text += f" at frame {getattr(q, f'{key}_frame')} ({getattr(q, f'{key}_leg')})"
        if failed(obj, key):
            text += f" ABOVE {limit_text(key)[4:]}"
        parts.append(text)
    bad = sum(failed(obj, key) for key, _l, _k in FIGURES)
    verdict = "all within the thresholds" if not bad else f"{bad} above the thresholds"
    return (f"{obj.name}: quality on the posed rig, frames {q.frame_start}-{q.frame_end}: "
            + "; ".join(parts) + f" -- {verdict}")
