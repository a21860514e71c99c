# SPDX-License-Identifier: GPL-3.0-or-later
"""Key Reduction of a generated Action, checked on the posed rig.

Generate Locomotion, Bake Secondary Motion and Plan Biped Footsteps first key every frame
(:mod:`..pose_writer`); with Key Reduction on, :func:`reduce_action` then thins those
keys:

1. the posed rig is evaluated with the full keys (the reference): the world head and tail of
   every foot bone, the world rotation of every deform and keyed bone;
2. each channel gets a tolerance derived from the chain (:func:`channel_tolerances`): a
   bone's turn moves every foot below it by the turn times its distance, and the errors of a
   chain of keyed bones add up, so the posed tolerances are shared out along the chain;
3. :func:`..core.keyfit.fit_keys` keeps the keys needed (all the channels of one bone share
   their key frames; the frames the caller requires, such as the feet's contacts, are keys)
   and fits the Bézier handles; the curves are written in bulk through :mod:`..actions`;
4. the posed rig is evaluated again and compared with the reference. Where a frame is off
   (a foot by more than its tolerance, a bone turned by more than its), the channels that
   are not exact there get a tighter tolerance over the segment around it and are fitted
   again; the last pass keys such frames outright. Control rigs (IK targets, poles) are
   covered by this check: their chains are Blender's own.

Shapes: ``frames`` ``(F,)`` scene frames; ``required`` maps a bone name, or a channel's
``(data_path, index)``, to ``(F,)`` bools.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import bpy
import numpy as np

from ...core import keyfit
from ...core.steps import run_steps
from .. import actions, pose_writer
from ..rig.controls import ConstraintGraph, ControlPlan

__all__ = [
    "Reduction",
    "channel_tolerances",
    "contact_frames",
    "is_enabled",
    "last_reduction",
    "leg_keyed_bones",
    "posed_errors",
    "reduce_action",
    "reduce_action_steps",
    "reduce_if_enabled",
    "reduce_if_enabled_steps",
]

_PREFIX = 'pose.bones["'
#: The errors of ``n`` keyed bones down a chain add up as about ``n ** _DEPTH_POWER`` times
#: one bone's (they are rarely all at their worst on the same frame; measured on the example
#: wolf: a quarter power needs the fewest keys, the check pass catches the rest).
_DEPTH_POWER = 0.25
#: Share of each posed tolerance the channels start with (measured on the example wolf: 0.7
#: to 0.8 needs the fewest keys; looser starts need more tightening passes, and each pass
#: tightens whole segments).
_SHARE = 0.8
#: A turn is about twice the change of its quaternion; the change is shared by its components.
_QUAT_SHARE = 2.0
#: Passes of fit, write and check (the last one keys what is still off).
_MAX_PASSES = 5
#: A channel counts as contributing to a frame's error when its own error there is above this
#: share of its tolerance.
_CONTRIBUTES = 0.02
#: A planted foot may move from one frame to the next by this share of the foot tolerance
#: more than in the full result (so the gait still reads from when feet stop and start:
#: measured on the example wolf, 1.0 breaks the gait-phase check, 0.7 keeps it).
_STEP_SHARE = 0.7


@dataclass(frozen=True)
class Reduction:
    """What :func:`reduce_action` did: key counts over every F-curve of the Action, the worst
    posed-rig errors against the full keys (feet in metres, world; bones in radians), the
    passes, the seconds it took, and whether everything is within the tolerances."""

    keys_before: int
    keys_after: int
    foot_error: float
    angle_error: float
    passes: int
    seconds: float
    within: bool

    @property
    def ratio(self) -> float:
        return self.keys_before / max(self.keys_after, 1)

    def describe(self) -> str:
        """One line for the operator's report and the batch command."""
        text = (f"Key Reduction: {self.keys_before:,} -> {self.keys_after:,} keys ({self.ratio:.1f}x fewer); "
                f"feet within {1000.0 * self.foot_error:.2f} mm, bones within "
                f"{math.degrees(self.angle_error):.2f} deg")
        if self.within:
            return text
        return (f"Key Reduction kept all {self.keys_before:,} keys: fewer would move the feet by "
                f"{1000.0 * self.foot_error:.2f} mm and bones by {math.degrees(self.angle_error):.2f} deg")


def _bone_of(data_path: str) -> str | None:
    if not data_path.startswith(_PREFIX):
        return None
    end = data_path.find('"]', len(_PREFIX))
    if end < 0:
        return None
    return data_path[len(_PREFIX):end].replace('\\"', '"').replace("\\\\", "\\")


def contact_frames(planted: np.ndarray) -> np.ndarray:
    """Frames that must be keys so each foot's touch-down and lift-off can be retimed:
    ``planted`` ``(F, n_feet)`` -> ``(F, n_feet)`` bool, the first planted frame of every
    stance (touch-down) and its last (lift-off), so a whole stance lies between two keys."""
    p = np.asarray(planted, dtype=bool)
    out = np.zeros(p.shape, dtype=bool)
    if p.shape[0] < 2:
        return out
    out[1:] |= p[1:] & ~p[:-1]  # touch-down
    out[:-1] |= p[:-1] & ~p[1:]  # lift-off
    return out


def leg_keyed_bones(plan: ControlPlan | None, legs: Sequence[Sequence[str]]) -> list[list[str]]:
    """Per leg, the bones whose keys time its steps: the leg's own bones and, on a control
    rig, its IK target, pole, FK controls and the controls that place it."""
    out = []
    for k, bones in enumerate(legs):
        names = list(bones)
        if plan is not None:
            if k < len(plan.legs):
                lc = plan.legs[k]
                names += [b for b in (lc.ik, lc.pole, *lc.fk) if b]
            names += [c.bone for c in plan.controls if c.leg == k]
        out.append(list(dict.fromkeys(names)))
    return out


def _tails(m: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """World tails ``(F, n, 3)`` of bones posed ``m`` ``(F, n, 4, 4)``, ``lengths`` ``(n,)`` long."""
    return m[..., :3, 3] + m[..., :3, 1] * lengths[None, :, None]


def posed_errors(ref: np.ndarray, got: np.ndarray, lengths: np.ndarray,
                 is_foot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame and bone, how far ``got`` is from ``ref`` (both ``(F, n, 4, 4)`` world):
    ``(distance, angle)``, each ``(F, n)``; the distance (of head and tail, bones ``lengths``
    ``(n,)`` long) only for feet (``is_foot`` ``(n,)``), else 0."""
    dist = np.maximum(np.linalg.norm(got[..., :3, 3] - ref[..., :3, 3], axis=-1),
                      np.linalg.norm(_tails(got, lengths) - _tails(ref, lengths), axis=-1))
    dist = np.where(is_foot[None], dist, 0.0)
    r0 = ref[..., :3, :3] / np.maximum(np.linalg.norm(ref[..., :3, :3], axis=-2, keepdims=True), 1e-12)
    r1 = got[..., :3, :3] / np.maximum(np.linalg.norm(got[..., :3, :3], axis=-2, keepdims=True), 1e-12)
    cos = (np.einsum("...ij,...ij->...", r0, r1) - 1.0) / 2.0
    return dist, np.arccos(np.clip(cos, -1.0, 1.0))


def channel_tolerances(obj: bpy.types.Object, channels: Sequence[actions.Channel], feet: Sequence[str],
                       foot_tolerance: float, angle_tolerance: float,
                       moved_by: Callable[[str], set[str]] | None = None) -> np.ndarray:
    """A first tolerance per channel ``(C,)`` (in the channel's units) from the chain.

    A bone's own turn is given ``angle_tolerance`` shared with the keyed bones from the root
    down to it (:data:`_DEPTH_POWER`), and at most ``foot_tolerance`` over its distance to
    each foot below it (shared the same way along that foot's keyed bones); a location takes
    ``foot_tolerance`` the same way. A quaternion component carries half the angle (a turn is
    about twice the quaternion's change), an Euler angle a third. These are a first guess:
    :func:`reduce_action` checks the posed rig and tightens them where it is off.
    ``moved_by``: the rig's :func:`_moved_by`, when the caller has it already.
    """
    bones = obj.data.bones
    keyed = {b for ch in channels if (b := _bone_of(ch.data_path)) is not None and b in bones}
    world = np.array(obj.matrix_world, dtype=np.float64)
    scale = float(np.mean(np.linalg.norm(world[:3, :3], axis=0))) or 1.0
    chain = moved_by if moved_by is not None else _moved_by(obj)
    chains = {f: chain(f) for f in feet if f in bones}
    depth = {b: max(1, sum(1 for a in chain(b) if a in keyed)) for b in keyed}
    angle: dict[str, float] = {}
    location: dict[str, float] = {}
    for b in keyed:
        theta = angle_tolerance / depth[b] ** _DEPTH_POWER
        loc = foot_tolerance / scale
        head = np.array(bones[b].head_local, dtype=np.float64)
        for foot, above in chains.items():
            if b not in above:
                continue
            n_keyed = max(1, sum(1 for a in above if a in keyed))
            fb = bones[foot]
            reach = scale * max(float(np.linalg.norm(np.array(fb.head_local) - head)),
                                float(np.linalg.norm(np.array(fb.tail_local) - head)), 1e-9)
            theta = min(theta, foot_tolerance / (reach * n_keyed ** _DEPTH_POWER))
            loc = min(loc, foot_tolerance / (scale * n_keyed ** _DEPTH_POWER))
        angle[b] = theta
        location[b] = loc
    out = np.empty(len(channels))
    for c, ch in enumerate(channels):
        b = _bone_of(ch.data_path)
        prop = ch.data_path.rsplit(".", 1)[-1]
        theta = angle.get(b, angle_tolerance) if b is not None else angle_tolerance
        loc = location.get(b, foot_tolerance / scale) if b is not None else foot_tolerance
        if prop == "location":
            out[c] = loc
        elif prop == "rotation_quaternion":
            out[c] = theta / _QUAT_SHARE
        elif prop == "rotation_euler":
            out[c] = theta / 3.0
        elif prop == "rotation_axis_angle":
            out[c] = theta / 4.0
        elif prop == "scale":
            out[c] = 1e-4
        else:  # anything else keyed densely: kept all but exact
            out[c] = 1e-6
    return out


def _moved_by(obj: bpy.types.Object) -> Callable[[str], set[str]]:
    """A function: bone name -> the set of bones whose pose moves it, itself included: its
    parents and, on a control rig, the bones its constraints follow, upstream to the controls
    (:class:`..rig.controls.ConstraintGraph`: Rigify's ``ORG-foot.L`` is moved by
    ``foot_fk.L``, ``shin_fk.L``, ``thigh_fk.L`` and ``torso`` when its leg is in FK)."""
    graph = ConstraintGraph(obj)
    nodes = graph.nodes

    def moved_by(name: str) -> set[str]:
        return set(graph.upstream([name])) if name in nodes else {name}

    return moved_by


#: A quaternion component's tolerance grows at most this much where it hardly turns the bone.
_MAX_QUATERNION_GAIN = 5.0


def _quaternion_shares(chans: Sequence[actions.Channel], values: np.ndarray, tol: np.ndarray) -> None:
    """Loosen, frame by frame, the quaternion components that hardly turn the bone.

    Blender normalises a bone's interpolated quaternion, so an error along the quaternion
    itself turns nothing: an error ``e`` in component ``i`` turns the bone by about
    ``2 e sqrt(1 - q_i**2)``. Each component's tolerance ``tol`` ``(F, C)`` is divided by that
    factor (at most :data:`_MAX_QUATERNION_GAIN` times looser), so ``w`` of a bone near its
    rest pose is allowed far more than ``x``, ``y`` and ``z``. Changed in place."""
    by_path: dict[str, dict[int, int]] = {}
    for c, ch in enumerate(chans):
        if ch.data_path.endswith(".rotation_quaternion"):
            by_path.setdefault(ch.data_path, {})[ch.index] = c
    for cols in by_path.values():
        if sorted(cols) != [0, 1, 2, 3]:
            continue
        idx = [cols[i] for i in range(4)]
        q = values[:, idx]
        q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
        turns = np.sqrt(np.maximum(1.0 - q * q, 0.0))
        tol[:, idx] /= np.maximum(turns, 1.0 / _MAX_QUATERNION_GAIN)


def _dense(action: bpy.types.Action, obj: bpy.types.Object,
           frames: np.ndarray) -> tuple[list[actions.Channel], np.ndarray, int]:
    """The channels keyed on every one of ``frames`` (what the writers keyed densely), their
    values ``(F, C)`` and the total keys of the Action."""
    chans, cols = [], []
    total = 0
    for ch, fx, vals in actions.read_channels(action, obj):
        total += fx.size
        if fx.shape == frames.shape and np.allclose(fx, frames):
            chans.append(ch)
            cols.append(vals)
    values = np.stack(cols, axis=1) if cols else np.zeros((frames.size, 0))
    return chans, values, total


def reduce_action(
    obj: bpy.types.Object, action: bpy.types.Action, frames: np.ndarray, feet: Sequence[str],
    required: Mapping[Any, np.ndarray] | None = None, *, foot_tolerance: float = 0.001,
    angle_tolerance: float = math.radians(0.5), planted: Mapping[str, np.ndarray] | None = None,
    step_tolerance: float | None = None, max_passes: int = _MAX_PASSES,
) -> Reduction:
    """:func:`reduce_action_steps` run through."""
    return run_steps(reduce_action_steps(obj, action, frames, feet, required, foot_tolerance=foot_tolerance,
                                         angle_tolerance=angle_tolerance, planted=planted,
                                         step_tolerance=step_tolerance, max_passes=max_passes))


def reduce_action_steps(
    obj: bpy.types.Object, action: bpy.types.Action, frames: np.ndarray, feet: Sequence[str],
    required: Mapping[Any, np.ndarray] | None = None, *, foot_tolerance: float = 0.001,
    angle_tolerance: float = math.radians(0.5), planted: Mapping[str, np.ndarray] | None = None,
    step_tolerance: float | None = None, max_passes: int = _MAX_PASSES,
) -> Generator[float, None, Reduction]:
    """Thin the keys ``action`` (assigned to ``obj``, generated) holds on every one of
    ``frames``, keeping the posed rig within ``foot_tolerance`` (world distance of the head
    and tail of each of ``feet``) and ``angle_tolerance`` (radians, world rotation of every
    deform and keyed bone) of the full keys. ``required``: frames that stay keys, per bone
    name (all its channels) or per ``(data_path, index)`` of one channel. ``planted``: per
    foot, ``(F,)`` frames it stands on; between two such frames it may move by at most
    ``step_tolerance`` (default 0.7 of ``foot_tolerance``) more than in the full result
    (other bones listed there, such as IK controls, are held as steady on those frames).
    Channels with fewer keys (switches, held bones) are left as they are. When the passes
    cannot get within the tolerances, the full keys are written back (``within`` False).

    Yields the fraction done after each refit pass (and once the rig's full pose has been
    evaluated); closed early (Esc), the Action keeps whatever keys it last had written: the
    caller deletes it."""
    t0 = time.perf_counter()
    frames = np.asarray(frames, dtype=np.float64).reshape(-1)
    chans, values, before = _dense(action, obj, frames)
    if not chans or frames.size < 3:
        return Reduction(before, before, 0.0, 0.0, 0, time.perf_counter() - t0, True)
    # Each F-curve keeps its own keys (as Blender's Decimate and other curve simplifiers do):
    # on the example wolf that needs a tenth fewer keys than sharing them per bone.
    groups = np.arange(len(chans))
    bone_of = [_bone_of(ch.data_path) for ch in chans]
    req = np.zeros((frames.size, len(chans)), dtype=bool)
    for c, (bone, ch) in enumerate(zip(bone_of, chans, strict=True)):
        for key in (bone, (ch.data_path, ch.index)):
            if required is not None and key is not None and key in required:
                req[:, c] |= np.asarray(required[key]).astype(bool).reshape(-1)
    pbones = obj.pose.bones
    feet = [f for f in dict.fromkeys(feet) if f in pbones]
    keyed = [n for n in dict.fromkeys(bone_of) if n is not None and n in pbones]
    check = list(dict.fromkeys([*feet, *(pb.name for pb in pbones if pb.bone.use_deform), *keyed]))
    is_foot = np.array([n in feet for n in check])
    planted_mask = np.zeros((frames.size, len(check)), dtype=bool)
    for b, name in enumerate(check):
        if planted is not None and name in planted and name in feet:
            planted_mask[:, b] = np.asarray(planted[name]).astype(bool).reshape(-1)
    if step_tolerance is None:
        step_tolerance = _STEP_SHARE * foot_tolerance
    lengths = np.array([obj.data.bones[n].length for n in check])
    # ancestry[b, c]: channel c belongs to checked bone b or a bone that moves it
    ancestry = np.zeros((len(check), len(chans)), dtype=bool)
    moved_by = _moved_by(obj)
    for b, name in enumerate(check):
        line = moved_by(name)
        ancestry[b] = [o in line for o in bone_of]
    # steady[f, c]: channel c moves a foot planted from frame f to f + 1 (it is in the foot's
    # parent chain, or listed with it): there its error may change only by a share of its
    # tolerance from one frame to the next.
    steady = np.zeros((frames.size, len(chans)), dtype=bool)
    for b in range(len(check)):
        both = np.zeros(frames.size, dtype=bool)
        both[:-1] = planted_mask[1:, b] & planted_mask[:-1, b]
        steady |= both[:, None] & ancestry[b][None, :]
    for c, bone in enumerate(bone_of):
        if planted is not None and bone is not None and bone in planted and bone not in feet:
            mask = np.asarray(planted[bone]).astype(bool).reshape(-1)
            steady[:-1, c] |= mask[1:] & mask[:-1]
    worlds = pose_writer.object_worlds(obj, frames)  # the reduction keys bones, not the object
    ref = worlds[:, None] @ pose_writer.evaluate_pose(obj, frames, check)
    # (evaluating the full pose costs about what one pass does)
    yield 1.0 / (max_passes + 1)
    base_tol = _SHARE * channel_tolerances(obj, chans, feet, foot_tolerance, angle_tolerance, moved_by)
    tol = np.tile(base_tol, (frames.size, 1))
    _quaternion_shares(chans, values, tol)
    after = before
    dist_max = angle_max = 0.0
    passes = 0
    within = False
    # Per channel: keys (F, C), slopes (F, C); refitted only where a pass changed something.
    keys = np.zeros(values.shape, dtype=bool)
    left = np.full(values.shape, np.nan)
    right = np.full(values.shape, np.nan)
    changed = np.ones(len(chans), dtype=bool)
    for p in range(max_passes):
        passes = p + 1
        cols = np.flatnonzero(changed)
        step_tol = np.where(steady[:, cols], step_tolerance / foot_tolerance * tol[:, cols], np.inf)
        part = keyfit.fit_keys(frames, values[:, cols], tol[:, cols], None, req[:, cols], step_tol)
        keys[:, cols], left[:, cols], right[:, cols] = part.keys, part.left, part.right
        fit = keyfit.KeyFit(keys, left, right, groups)
        _write(action, obj, [chans[c] for c in cols], frames, values[:, cols], part)
        after = before - values.size + fit.key_count
        got = worlds[:, None] @ pose_writer.evaluate_pose(obj, frames, check)
        dist, angle = posed_errors(ref, got, lengths, is_foot)
        dist_max, angle_max = float(dist.max(initial=0.0)), float(angle.max(initial=0.0))
        per_bone = np.maximum(dist / foot_tolerance, angle / angle_tolerance)  # (F, n)
        if planted_mask.any():
            # A planted foot stays put from frame to frame, not only near the full result
            # (the gait is read from when feet stop and start moving).
            step = np.zeros_like(per_bone)
            moved = np.maximum(np.linalg.norm(np.diff(got[..., :3, 3] - ref[..., :3, 3], axis=0), axis=-1),
                               np.linalg.norm(np.diff(_tails(got, lengths) - _tails(ref, lengths), axis=0),
                                              axis=-1))  # (F - 1, n)
            both = planted_mask[1:] & planted_mask[:-1]
            jump = np.where(both, moved / step_tolerance, 0.0)
            step[1:] = np.maximum(step[1:], jump)
            step[:-1] = np.maximum(step[:-1], jump)
            per_bone = np.maximum(per_bone, step)
        yield (p + 2) / (max_passes + 1)
        ratio = per_bone.max(axis=1, initial=0.0)  # (F,)
        off = np.flatnonzero(ratio > 1.0)
        if off.size == 0:
            within = True
            break
        # Which channels are not exact on the frames that are off: those that contribute most
        # (all of them on the next to last pass) get a key there.
        resid = np.abs(keyfit.evaluate_fit(frames, values, fit, float32=True) - values) / tol
        last = p == max_passes - 2
        changed[:] = False
        for f in off:
            # the channels of the bones above the ones that are off (their parent chains)
            above = np.zeros(len(chans), dtype=bool)
            for b in np.flatnonzero(per_bone[f] > 1.0):
                above |= ancestry[b]
            guilty = np.flatnonzero((resid[f] > _CONTRIBUTES) & above)
            chained = guilty.size > 0
            if not chained:  # driven through constraints: any channel not exact there
                guilty = np.flatnonzero(resid[f] > _CONTRIBUTES)
            if guilty.size == 0:
                guilty = np.flatnonzero(~keys[f])
            if guilty.size == 0:  # every channel is keyed there: keys cannot do better
                continue
            if chained and not last:  # in the parent chains, those that contribute most
                guilty = guilty[resid[f, guilty] >= 0.5 * resid[f, guilty].max()]
            req[f, guilty] = True
            changed[guilty] = True
        if not changed.any():  # nothing left to key: more passes would change nothing
            break
    if not within:
        # Never leave a result off by more than asked: the full keys go back.
        actions.write_channels(action, obj, chans, frames, values)
        after = before
    return Reduction(int(before), int(after), dist_max, angle_max, passes, time.perf_counter() - t0, within)


def _write(action: bpy.types.Action, obj: bpy.types.Object, chans: Sequence[actions.Channel],
           frames: np.ndarray, values: np.ndarray, fit: keyfit.KeyFit) -> None:
    curves = []
    for c in range(len(chans)):
        curve = keyfit.bezier_points(frames, values, fit, c)
        curves.append((curve.co, curve.handle_left, curve.handle_right))
    actions.write_bezier_channels(action, obj, chans, curves)


def is_enabled(obj: bpy.types.Object) -> bool:
    """Whether the rig has Key Reduction on (``obj.procloco_keys``)."""
    settings = getattr(obj, "procloco_keys", None)
    return settings is not None and bool(settings.use_key_reduction)


def reduce_if_enabled(
    obj: bpy.types.Object, action: bpy.types.Action, frames: np.ndarray, feet: Sequence[str],
    required: Mapping[Any, np.ndarray] | None = None, planted: Mapping[str, np.ndarray] | None = None,
) -> Reduction | None:
    """:func:`reduce_if_enabled_steps` run through."""
    return run_steps(reduce_if_enabled_steps(obj, action, frames, feet, required, planted))


def reduce_if_enabled_steps(
    obj: bpy.types.Object, action: bpy.types.Action, frames: np.ndarray, feet: Sequence[str],
    required: Mapping[Any, np.ndarray] | None = None, planted: Mapping[str, np.ndarray] | None = None,
) -> Generator[float, None, Reduction | None]:
    """:func:`reduce_action_steps` with the rig's Key Reduction settings
    (``obj.procloco_keys``) when they are on, the result stored there for the panel; None
    (at once) when off. Yields the fraction done."""
    if not is_enabled(obj):
        return None
    settings = obj.procloco_keys
    result = yield from reduce_action_steps(obj, action, frames, feet, required,
                                            foot_tolerance=float(settings.foot_tolerance),
                                            angle_tolerance=float(settings.angle_tolerance), planted=planted)
    settings.keys_before = min(result.keys_before, 2**31 - 1)
    settings.keys_after = min(result.keys_after, 2**31 - 1)
    settings.foot_error = result.foot_error
    settings.angle_error = result.angle_error
    settings.within = result.within
    return result


def last_reduction(obj: bpy.types.Object) -> Reduction | None:
    """What the rig's last Key Reduction did (as stored on ``obj.procloco_keys``), or None
    when Key Reduction is off or never ran."""
    if not is_enabled(obj) or not obj.procloco_keys.keys_before:
        return None
    settings = obj.procloco_keys
    return Reduction(int(settings.keys_before), int(settings.keys_after), float(settings.foot_error),
                     float(settings.angle_error), 0, 0.0, bool(settings.within))
