# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate Locomotion without the operator around it: used by the operator, the batch
command and the benchmark.

The work for one rig is a :class:`Job` in three stages:

1. :func:`prepare` reads everything from Blender and checks every bad input of the design
   ("Bad input") — it raises :class:`GenerateError` with a message for the user and changes
   nothing in the scene. It is :func:`read` (settings, rig: quick) then :func:`read_terrain`
   (the scene's meshes, animated ones played over the range), the latter as progress steps
   so the operator shows it and stops on Esc;
2. :func:`simulate` runs the core simulation, one frame per step, as a generator yielding
   the fraction done (so a modal operator can show progress and stop on Esc with nothing
   written);
3. :func:`write` converts the result into pose-bone keys of a **new** Action assigned to the
   rig (the previous Action is remembered, see :mod:`..actions`).

Many rigs at once (:func:`generate`, the operator): every rig read first, then the rigs that
can walk together in one simulation (:mod:`.crowd`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable, Generator, Iterator, Sequence
from typing import Any

import bpy
import numpy as np

from ...core.locomotion import gait as core_gait
from ...core.steps import run_steps, scaled_steps
from .. import actions, pose_writer, rig, scene_terrain, validate
from ..gait import rig_gait
from ..rig import controls
from ..rig.rest import nearest_rotation
from . import crowd, property_group, simulation
from .job import GaitChange, Job, settings_values

__all__ = [
    "ACTION_KIND",
    "GaitChange",
    "GenerateError",
    "Job",
    "default_gait",
    "detect_into_settings",
    "generate",
    "prepare",
    "read",
    "read_terrain",
    "settings_legs",
    "simulate",
    "stale_bones",
    "write",
    "write_all",
]

# Presets tried, in this order, when a rig has no gait of its own yet.
_DEFAULT_PRESETS = ("biped_walk", "quadruped_walk", "pentapod_robot", "hexapod_tripod",
                    "octopod_alternating_tetrapod")


class GenerateError(ValueError):
    """Generation refused; the message is meant for the user."""


# ---------------------------------------------------------------------------------------
# Settings <-> legs and gait


def settings_legs(obj: bpy.types.Object) -> list[rig.LegChain] | None:
    """The enabled legs listed in ``obj.procloco.legs`` (validated), or None if the list is empty."""
    items = list(obj.procloco.legs)
    if not items:
        return None
    legs = []
    for item in items:
        if not item.enabled:
            continue
        label = item.label or item.name
        if not label:
            raise GenerateError(f"A leg of '{obj.name}' has no label: name it (L1, R1, ...) in Rig & Legs")
        legs.append(rig.leg_from_bones(obj, item.hip, item.end, label))
    if not legs:
        raise GenerateError(f"Every leg of '{obj.name}' is disabled: enable at least one in Rig & Legs")
    labels = [leg.label for leg in legs]
    twice = sorted({lb for lb in labels if labels.count(lb) > 1})
    if twice:
        raise GenerateError(f"Legs of '{obj.name}' share the label {', '.join(twice)}: labels must be unique")
    return legs


#: The metachronal wave of rigs with more leg pairs than the presets: rows a quarter cycle
#: apart on each side, every fourth row in step, each foot up this share of the cycle.
WAVE_SWING = 0.22


def default_gait(labels: Sequence[str]) -> core_gait.Gait:
    """A shipped preset matching ``labels``; for more leg pairs than the presets have
    (``L1``, ``R1`` ... ``L11``, ``R11``: a centipede) the octopod wave repeated along the
    body (on each side the rows swing back to front a quarter cycle apart, every fourth row in
    step, the two sides half a cycle apart: a metachronal wave four rows long); else a wave
    gait (one foot up at a time, back to front)."""
    wanted = sorted(labels)
    for name in _DEFAULT_PRESETS:
        try:
            preset = core_gait.find_gait_preset(name)
        except core_gait.GaitError:
            continue
        if sorted(preset.legs) == wanted:
            return preset.gait(labels)
    n = len(labels)
    rows = n // 2
    if n % 2 == 0 and rows > 4 and wanted == sorted(f"{s}{k}" for s in "LR" for k in range(1, rows + 1)):
        start = np.array([(0.25 * (rows - int(lb[1:])) + (0.5 if lb[0] == "R" else 0.0)) % 1.0
                          for lb in labels])
        return core_gait.Gait(start, np.full(n, WAVE_SWING), 1.0, "metachronal wave")
    start = (np.arange(n)[::-1] / n) % 1.0
    duration = np.full(n, min(0.45, 0.9 / n))
    return core_gait.Gait(start, duration, max(0.6, 0.15 * n), "wave")


#: Defaults for a rig with no speed or step height set yet, in leg lengths: a stride of
#: ``STRIDE`` per cycle (no faster than Gait: Auto walks its legs without running its cycle
#: faster: ``AutoGaitParams.top_speed``), feet lifted by ``STEP``; the gait's cycle scaled by
#: the square root of the leg length over ``REFERENCE_LEG`` (dynamic similarity), within
#: ``CYCLE_SCALE``.
STRIDE = 0.8
STEP = 0.15
REFERENCE_LEG = 0.9
CYCLE_SCALE = (0.5, 1.6)


def scaled_defaults(leg_length: float, cycle_time: float, top_speed: float = math.inf) -> dict[str, float]:
    """Speed, step height and cycle time for a creature whose legs are ``leg_length`` long,
    walking the gait whose preset cycle is ``cycle_time`` seconds: a 9 cm bird and a 2 m
    horse both get a first walk in proportion to their size. The speed is at most
    ``top_speed`` (m/s): a beetle whose legs are crowded along its body walks no faster
    than its Auto gait keeps its swings (``AutoGaitParams.top_speed``)."""
    cycle = cycle_time * float(np.clip(np.sqrt(leg_length / REFERENCE_LEG), *CYCLE_SCALE))
    return {"speed": min(STRIDE * leg_length / cycle, top_speed), "step_height": STEP * leg_length,
            "cycle_time": cycle}


def leg_reason(item: Any) -> str:
    """Why Detect Legs chose the leg ``item`` (a ``PROCLOCO_PG_leg``); "" once its hip or
    end-effector was changed by hand."""
    return str(item.reason) if item.detected == f"{item.hip}>{item.end}" else ""


def detect_into_settings(obj: bpy.types.Object) -> list[rig.LegChain]:
    """Detect the legs of ``obj`` and store them in ``obj.procloco.legs``.

    A leg keeps its gait sector and foot offset when a leg with the same label was there
    before; new legs get the default gait. A rig whose speed and step height were never set
    gets :func:`scaled_defaults` for its leg length. Each leg's ``reason`` says why it was
    chosen. Raises ``rig.RigError`` (and changes nothing) when no leg is found.
    """
    settings = obj.procloco
    legs = rig.detect_legs(obj)
    keyed = leg_controls(obj, legs)
    settings.controls_drive = settings.drive_legs
    if not settings.legs:
        rig_gait.set_new_rig_default(obj)  # no gait chosen yet: Auto
    scaled = None
    if not settings.is_property_set("speed") and not settings.is_property_set("step_height"):
        top = math.inf
        try:
            info = rig.read_rig(obj, legs)
            length = float(info.leg_length.mean())
            if rig_gait.is_auto(obj):
                auto = rig_gait.auto_params(obj, info)
                top = auto.top_speed() if auto is not None else math.inf
        except (rig.RigError, core_gait.GaitError):
            length = 0.0  # Generate will say what is wrong; the defaults stay as they are
        if length > 0.0:
            scaled = scaled_defaults(length, float(default_gait([leg.label for leg in legs]).cycle_time), top)
    labels = [leg.label for leg in legs]
    old = {item.label or item.name: (item.swing_start, item.swing_duration, tuple(item.offset), item.enabled)
           for item in settings.legs}
    gait = default_gait(labels)
    settings.legs.clear()
    for k, leg in enumerate(legs):
        item = settings.legs.add()
        item.name = leg.label
        item.label = leg.label
        item.hip = leg.hip
        item.end = leg.end
        item.controls = keyed[k]
        item.reason = leg.reason
        item.detected = f"{leg.hip}>{leg.end}"
        if leg.label in old:
            start, duration, offset, enabled = old[leg.label]
            item.swing_start, item.swing_duration = start, duration
            item.offset, item.enabled = offset, enabled
        else:
            item.swing_start = float(gait.swing_start[k])
            item.swing_duration = float(gait.swing_duration[k])
    if not all(label in old for label in labels):
        settings.cycle_time = float(gait.cycle_time)
    if scaled is not None:
        for key, value in scaled.items():
            setattr(settings, key, value)
    settings.active_leg_index = min(settings.active_leg_index, len(legs) - 1)
    return legs


def leg_controls(obj: bpy.types.Object, legs: Sequence[rig.LegChain]) -> list[str]:
    """Per leg, the controls Generate Locomotion will key for it on a control rig
    (``"IK foot_ik.L, pole thigh_ik_target.L"``), ``""`` when it keys the leg's own bones."""
    try:
        info = rig.read_rig(obj, legs, obj.procloco.forward_axis)
    except rig.RigError:
        return [""] * len(legs)
    plan, _warnings = plan_keys(obj, info)
    return [controls.describe_leg(lc) for lc in plan.legs]


def _gait_of(obj: bpy.types.Object, legs: Sequence[rig.LegChain], from_settings: bool) -> core_gait.Gait:
    labels = [leg.label for leg in legs]
    if not from_settings:
        return default_gait(labels)
    settings = obj.procloco
    by_label = {item.label or item.name: item for item in settings.legs}
    start = np.array([by_label[lb].swing_start for lb in labels])
    duration = np.array([by_label[lb].swing_duration for lb in labels])
    for lb, d in zip(labels, duration, strict=True):
        if d <= 0.0 or d >= 1.0:
            kind = "zero" if d <= 0.0 else "full-cycle"
            raise GenerateError(f"Leg {lb} of '{obj.name}' has a {kind} swing ({d:g}): a foot must both "
                                "lift and land in every cycle")
    try:
        return core_gait.Gait(start, duration, float(settings.cycle_time), settings.gait_preset)
    except core_gait.GaitError as err:
        raise GenerateError(f"Gait of '{obj.name}': {err}") from err


def _gait_changes(
    obj: bpy.types.Object, legs: Sequence[rig.LegChain], frames: np.ndarray, warnings: list[str]
) -> tuple[GaitChange, ...]:
    """The rig's gait changes in frame order, each gait mapped onto the legs by label.
    Changes after the last frame are left out with a warning."""
    labels = [leg.label for leg in legs]
    out = []
    for k, item in enumerate(obj.procloco.gait_changes):
        where = f"Gait change {k + 1} of '{obj.name}' ({item.name or 'unnamed'} at frame {item.frame})"
        try:
            preset = core_gait.parse_gait_preset(json.loads(item.gait), f"{item.name or 'gait'}.json")
            gait = preset.gait(labels)
        except (ValueError, TypeError) as err:  # bad JSON, bad preset, legs not the rig's
            raise GenerateError(f"{where} cannot be used: {err}. Remove it and add it again") from err
        if item.frame > frames[-1]:
            warnings.append(f"{where} is after the last frame: left out")
            continue
        out.append(GaitChange(max(int(item.frame - frames[0]), 0), gait, float(item.transition_time),
                              float(item.speed) if item.use_speed else None, item.name))
    return tuple(sorted(out, key=lambda c: c.frame_index))


def _offsets_of(obj: bpy.types.Object, legs: Sequence[rig.LegChain], from_settings: bool) -> np.ndarray:
    out = np.zeros((len(legs), 2))
    if from_settings:
        by_label = {item.label or item.name: item for item in obj.procloco.legs}
        for k, leg in enumerate(legs):
            out[k] = tuple(by_label[leg.label].offset)
    return out


def path_points(context: bpy.types.Context, path: bpy.types.Object) -> np.ndarray:
    """The path curve as a world polyline ``(n, 3)`` (its first spline, evaluated)."""
    if path.type != "CURVE":
        raise GenerateError(f"Path '{path.name}' is not a curve: pick a curve object to follow")
    depsgraph = context.evaluated_depsgraph_get()
    ev = path.evaluated_get(depsgraph)
    try:
        mesh = ev.to_mesh()
    except RuntimeError:
        mesh = None
    if mesh is None:
        raise GenerateError(f"Path '{path.name}' is empty: give the curve some points")
    try:
        n = len(mesh.vertices)
        co = np.empty(n * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        n_e = len(mesh.edges)
        edges = np.empty(n_e * 2, dtype=np.int32)
        mesh.edges.foreach_get("vertices", edges)
    finally:
        ev.to_mesh_clear()
    if n < 2 or n_e == 0:
        raise GenerateError(f"Path '{path.name}' is empty: give the curve some points")
    pts = co.reshape(n, 3).astype(np.float64)
    order = _polyline_order(n, edges.reshape(n_e, 2))
    m = np.array(ev.matrix_world, dtype=np.float64)
    world = pts[order] @ m[:3, :3].T + m[:3, 3]
    keep = np.concatenate([[True], np.linalg.norm(np.diff(world, axis=0), axis=1) > 1e-9])
    world = world[keep]
    if world.shape[0] < 2:
        raise GenerateError(f"Path '{path.name}' is empty: its points all coincide")
    return world


def _polyline_order(n: int, edges: np.ndarray) -> np.ndarray:
    """Vertex order of the first connected chain, walked from its first end."""
    nbrs: list[list[int]] = [[] for _ in range(n)]
    for a, b in edges:
        nbrs[int(a)].append(int(b))
        nbrs[int(b)].append(int(a))
    start = next((i for i in range(n) if len(nbrs[i]) == 1), int(edges[0, 0]))
    order = [start]
    seen = {start}
    cur = start
    while True:
        nxt = next((j for j in nbrs[cur] if j not in seen), None)
        if nxt is None:
            break
        order.append(nxt)
        seen.add(nxt)
        cur = nxt
    return np.array(order, dtype=np.int64)


# ---------------------------------------------------------------------------------------
# Jobs


def stale_bones(obj: bpy.types.Object) -> set[str]:
    """Bones whose current pose comes from ProcLoco, not from the user: those the rig's
    generated Action keys and the user's own previous Action does not.

    A new generation reads them at rest and keys them at rest, so switching the spine off or
    generating over a secondary-motion bake does not freeze the spine or the tail in the
    last pose the earlier Action gave them. (Bones the user animates or posed keep their
    current pose, as always.)
    """
    current = actions.generated_action(obj)
    if current is None:
        return set()
    stale = actions.keyed_pose_bones(current, obj)
    _remembered, previous = actions.previous_action(obj)
    if previous is not None and not actions.is_generated(previous):
        stale -= actions.keyed_pose_bones(previous, obj)
    return stale


def animated_bones(obj: bpy.types.Object) -> set[str]:
    """Pose bones the rig's own animation moves: its active Action (unless ProcLoco made
    it) and the Actions of its NLA strips that play (tracks and strips not muted)."""
    adt = obj.animation_data
    if adt is None:
        return set()
    out = set() if actions.is_generated(adt.action) else actions.keyed_pose_bones(adt.action, obj)
    for track in adt.nla_tracks:
        if not track.mute:
            for strip in track.strips:
                if not strip.mute and strip.action is not None:
                    out |= actions.keyed_pose_bones(strip.action, obj)
    return out


def kept_bones(obj: bpy.types.Object, info: rig.RigInfo, keyed: Sequence[str]) -> tuple[str, ...]:
    """The bones the solved bones hang from (their ancestors and the bones they follow
    through constraints, not solved themselves nor ``keyed``) that the rig's own animation
    moves (:func:`animated_bones`), in the rig's order. The walk is solved with them as
    posed when it is read; the new Action keys them there: once it replaces the rig's
    Action they would keep whatever pose the last frame evaluated gave them (a pelvis bent
    at the end of an idle), and an NLA strip under it would go on moving them, carrying the
    planted feet along."""
    animated = animated_bones(obj)
    if not animated:
        return ()
    driven = set(info.driven_bones)
    above: set[str] = set()
    for name in driven:
        parent = info.parents[name]
        while parent is not None and parent not in above:
            above.add(parent)
            parent = info.parents[parent]
    # on a control rig also the controls they follow through constraints (a Rigify
    # horse's shoulder control, which its front leg's ORG- chain hangs from)
    above |= set(controls.ConstraintGraph(obj).upstream(driven))
    skip = driven | set(keyed)
    return tuple(pb.name for pb in obj.pose.bones if pb.name in above and pb.name in animated
                 and pb.name not in skip)


def prepare(context: bpy.types.Context, obj: bpy.types.Object | None) -> Job:
    """Read and check everything for one rig. Raises :class:`GenerateError`; changes nothing."""
    job = read(context, obj)
    for _fraction in read_terrain(context, job):
        pass
    return job


def read_terrain(context: bpy.types.Context, job: Job) -> Iterator[float]:
    """Read the job's terrain (animated objects played over its frames), yielding the
    fraction done, and check there is ground under the rig. Raises :class:`GenerateError`;
    changes nothing (the scene's frame is put back, also when closed early)."""
    t0 = time.perf_counter()
    obj = bpy.data.objects[job.obj_name]
    objs = [bpy.data.objects[name] for name in job.terrain_objects]
    leg_len = float(np.mean(job.info.leg_length))
    try:
        terrain = yield from scene_terrain.build_environment_steps(context, objs, job.frames,
                                                                   z_offset=job.lift)
        scene_terrain.check_ground_under(terrain, job.info.contact, obj.name, reach=leg_len)
    except scene_terrain.TerrainError as err:
        raise GenerateError(str(err) + scene_terrain.hidden_note(context, [obj])) from err
    job.terrain = terrain
    job.warnings.extend(terrain.warnings)
    job.timings["read_s"] = job.timings.get("read_s", 0.0) + time.perf_counter() - t0


def read(context: bpy.types.Context, obj: bpy.types.Object | None, cache: rig.ReadCache | None = None) -> Job:
    """Read and check the rig and its settings (not the terrain: :func:`read_terrain`).
    ``cache``: rigs read before (Live Preview's), reused while unchanged (see ``rig.ReadCache``)."""
    with rig.reading_once(cache):  # one reading of the rest arrays for every leg and the rig
        return _read(context, obj)


def _read(context: bpy.types.Context, obj: bpy.types.Object | None) -> Job:
    t0 = time.perf_counter()
    if obj is None or obj.type != "ARMATURE":
        name = "Nothing" if obj is None else f"'{obj.name}'"
        raise GenerateError(f"{name} is not an armature: select a rig")
    scene = context.scene
    settings = obj.procloco
    start, end = property_group.frame_range(settings, scene)
    problem = (validate.placement_problem(obj) or validate.tweak_mode_problem(obj)
               or validate.non_finite_setting(settings, f"'{obj.name}'")
               or validate.frame_range_problem(obj.name, start, end))
    if problem is not None:
        raise GenerateError(problem)
    stale = stale_bones(obj)
    try:
        legs = settings_legs(obj)
        from_settings = legs is not None
        info = rig.read_rig(obj, legs, settings.forward_axis, spine=bool(settings.use_spine), at_rest=stale)
        limits = (float(settings.spine_yaw_limit), float(settings.spine_pitch_limit))
        # (copies of a rig read together share their morphology: it is in the body frame)
        morph = rig.shared(info, ("morphology", *limits), lambda: rig.morphology_of(info, *limits))
    except rig.RigError as err:
        raise GenerateError(str(err)) from err
    gait = _gait_of(obj, info.legs, from_settings)
    path = None
    if settings.path is not None:
        path = path_points(context, settings.path)
    frames = np.arange(start, end + 1, dtype=np.int64)
    fps = scene.render.fps / scene.render.fps_base
    objs = scene_terrain.terrain_objects(context, [obj], settings.terrain_collection)
    leg_len = float(np.mean(info.leg_length))
    _check_scaled_settings(obj, leg_len)
    lift = float(np.mean(info.foot_height))
    if not objs:
        raise GenerateError("No ground mesh found: add a mesh under the creature (or choose the terrain "
                            "collection)" + scene_terrain.hidden_note(context, [obj]))
    heading = float(np.arctan2(info.body.forward[1], info.body.forward[0])) + float(settings.heading)
    # (copies of a plain rig read together key the same bones)
    plan, shared_warnings = rig.shared(info, ("plan",), lambda: plan_keys(obj, info), plain=True)
    warnings = list(shared_warnings)
    changes = _gait_changes(obj, info.legs, frames, warnings)
    auto = None
    # a rig with no legs listed has no gait chosen yet, unless the Gait was set (Circles)
    if rig_gait.is_auto(obj) or not (from_settings or settings.is_property_set("gait_mode")):
        try:
            # (copies read together with the same Auto settings share them: the legs' stroke
            # limit is a search over the morphology)
            auto = rig.shared(info, ("auto", *limits, float(settings.gait_speed_scale),
                                     str(settings.auto_gait_overrides)),
                              lambda: rig_gait.auto_params(obj, info, morph))
        except core_gait.GaitError as err:
            raise GenerateError(f"Gait of '{obj.name}': {err}") from err
        if auto is None:
            labels = ", ".join(leg.label for leg in info.legs)
            warnings.append(f"Auto gait knows no gaits for {len(info.legs)} legs ({labels}): '{obj.name}' "
                            "walks with its gait circles")
        elif settings.use_gait_randomizer:
            warnings.append(f"'{obj.name}' uses Auto gait: the gait randomizer is left out")
    held = tuple(pb.name for pb in obj.pose.bones
                 if pb.name in stale and pb.name not in info.driven_bones and pb.name not in plan.keyed_bones)
    job = Job(
        obj_name=obj.name,
        info=info,
        morphology=morph,
        terrain=None,
        terrain_objects=tuple(o.name for o in objs),
        lift=lift,
        gait=gait,
        frames=frames,
        dt=1.0 / fps,
        heading=heading,
        path=path,
        foot_offset=_offsets_of(obj, info.legs, from_settings),
        **settings_values(settings),
        gait_changes=changes,
        auto_gait=auto,
        warnings=warnings,
        held_bones=held,
        kept_bones=kept_bones(obj, info, [*plan.keyed_bones, *held]),
        plan=plan,
        check_after=any(w not in info.warnings for w in warnings),
    )
    job.timings["read_s"] = time.perf_counter() - t0
    return job


#: Fastest walk accepted, in leg lengths per second (the controller keeps planted feet still
#: up to about this; a gallop is 3-5).
_MAX_SPEED_LEGS = 6.0
#: Highest step accepted, in leg lengths (a foot cannot lift higher than its leg is long).
_MAX_STEP_LEGS = 1.0


def _check_scaled_settings(obj: bpy.types.Object, leg_len: float) -> None:
    """Refuse speeds and step heights no creature of this size could walk with."""
    settings = obj.procloco
    speeds = [("Speed", float(settings.speed))]
    speeds += [(f"Speed of gait change {c.name or k + 1}", float(c.speed))
               for k, c in enumerate(settings.gait_changes) if c.use_speed]
    for what, speed in speeds:
        if speed > _MAX_SPEED_LEGS * leg_len:
            raise GenerateError(f"{what} of '{obj.name}' is {speed:g} m/s, more than {_MAX_SPEED_LEGS:g} leg "
                                f"lengths ({leg_len:.3g} m) per second: lower it")
    if float(settings.step_height) > _MAX_STEP_LEGS * leg_len:
        raise GenerateError(f"Step Height of '{obj.name}' is {settings.step_height:g} m, more than "
                            f"{_MAX_STEP_LEGS:g} leg lengths ({leg_len:.3g} m): lower it")


def plan_keys(obj: bpy.types.Object, info: rig.RigInfo) -> tuple[controls.ControlPlan, list[str]]:
    """What to key for ``info``'s solved bones (:func:`.controls.plan_controls`) and the
    warnings for the user: the rig's own (constraints ProcLoco does not drive through, on
    bones no control was found for), drivers on keyed channels, limit constraints and
    constraints following objects outside the rig."""
    others = [b for b in info.spine if b != info.body_bone] if info.spine_layout is not None else []
    others += [t for t in info.foot_ik_targets if t is not None]  # carried with the solved feet
    plan = controls.plan_controls(obj, [(leg.bones, leg.foot) for leg in info.legs], info.body_bone, others)
    ik_bones = {t[0] for t in info.ik_targets if t is not None}
    # Controls that read_rig already solves (an IK target beside a plain rig's foot) are
    # keyed from that exact solution.
    solved_too = [c for c in plan.controls if c.bone in info.driven_bones]
    if solved_too:
        plan = dataclasses.replace(
            plan, direct=(*plan.direct, *(c.bone for c in solved_too)),
            controls=tuple(c for c in plan.controls if c not in solved_too))
    # The bones of a leg that an IK solves without a pole (MMD's knee IK) are keyed at their
    # solved pose too: Blender's IK starts from it, and without a pole the knee would swing
    # about the hip-to-target axis from wherever the IK settles at each frame.
    seeded = [b for leg, target in zip(info.legs, info.ik_targets, strict=True) if target is not None
              and _poleless_ik(obj, leg.bones) for b in leg.bones if b not in plan.direct]
    if seeded:
        plan = dataclasses.replace(plan, direct=(*plan.direct, *seeded))
    handled = set(info.driven_bones) - set(plan.uncovered)
    # read_rig's warnings name bones whose constraints override their keys: on a control rig
    # those bones are reached through their controls and are not keyed.
    warnings = [w for w in info.warnings if not any(f"bone '{b}' " in w for b in handled)]
    keyed = [*plan.keyed_bones, *ik_bones]
    warnings += controls.driver_warnings(obj, keyed)
    warnings += controls.constraint_warnings(controls.ConstraintGraph(obj), keyed, info.driven_bones)
    return plan, list(dict.fromkeys(warnings))


def _poleless_ik(obj: bpy.types.Object, bones: Sequence[str]) -> bool:
    """Whether an enabled IK constraint on one of ``bones`` has no pole target."""
    return any(c.type == "IK" and c.enabled and c.influence > 0.0 and c.pole_target is None
               for b in bones for c in obj.pose.bones[b].constraints)


def simulate(job: Job, kept: simulation.Checkpoints | None = None) -> Iterator[float]:
    """Run the core simulation for ``job``, yielding the fraction of frames done (once per
    frame). ``kept``: the rig's last run, to start from (Live Preview; ``simulation.run``).

    The result lands in ``job.result`` when the generator is exhausted.
    """
    t0 = time.perf_counter()
    yield from simulation.run(job, kept)
    job.timings["simulate_s"] = time.perf_counter() - t0


def write(context: bpy.types.Context, job: Job) -> bpy.types.Action:
    """Write ``job.result`` as a new Action on the rig and assign it (previous one remembered)."""
    return write_all(context, [job])[0]


def write_all(context: bpy.types.Context, jobs: Sequence[Job]) -> list[bpy.types.Action]:
    """:func:`write_all_steps` run through."""
    return run_steps(write_all_steps(context, jobs))


def write_all_steps(context: bpy.types.Context, jobs: Sequence[Job],
                    measure: bool = False) -> Generator[float, None, list[bpy.types.Action]]:
    """Write every job's result as a new Action on its rig and assign it: all or nothing.
    Yields the fraction done; returns the new Actions.

    Each Action is keyed and assigned in turn (the controls of a control rig are solved
    through the evaluated rig, so its Action must be assigned while it is written); when
    anything fails, or the steps are closed before the end (Esc), the Actions made so far are
    deleted, every rig gets back what it had (its Action, slot and pose), and an error is
    raised again. A rig's earlier generated Action is superseded (deleted, its name taken
    over) once all are written, unless the animator kept it (fake user, NLA, another object).

    ``measure``: then measure each written result on the posed rig and store the figures on
    the rig's settings (:mod:`..quality.measure`); a measurement that fails is a warning.
    """
    from ..quality import measure as quality

    made: list[bpy.types.Action] = []
    measured: list[Any] = []
    share = 0.85 if measure else 1.0  # measuring evaluates the rig once per frame
    done: list[tuple[bpy.types.Object, actions.Assignment]] = []
    superseded: list[tuple[bpy.types.Action, bpy.types.Action]] = []
    frame = (context.scene.frame_current, context.scene.frame_subframe)
    try:
        # Every rig's pose solved first (numpy over every frame: the first half of the work),
        # the copies of a creature together; then each keyed and checked on its rig.
        solved = yield from scaled_steps(rig.solve_poses_steps(_pose_inputs(jobs)), 0.0, 0.5 * share)
        for k, job in enumerate(jobs):
            obj = bpy.data.objects[job.obj_name]
            done.append((obj, actions.remember_assignment(obj)))
            current = actions.generated_action(obj)
            # A re-generation supersedes the earlier walk (or loop), never a bake layered on
            # one, nor a walk of another kind (a loop made from a walk keeps the walk).
            own = (current is not None and _SECONDARY_SOURCE not in current
                   and current.get(ACTION_KIND, "") == job.action_kind)
            steps = _keyed_action_steps(context, job, solved[k], own, superseded)
            while True:
                try:
                    fraction = next(steps)
                except StopIteration as finished:
                    made.append(finished.value)
                    break
                try:
                    yield share * (0.5 + 0.5 * (k + fraction) / len(jobs))
                except BaseException:
                    steps.close()  # this rig's Action deleted, its pose put back
                    raise
        if measure:
            yield share  # written and assigned; Esc from here on still takes everything back
            # every rig measured in one pass over the frames (one scene evaluation per frame)
            try:
                results = yield from scaled_steps(quality.measure_all_steps(context, jobs), share, 1.0)
            except Exception as err:  # the walks stand; only their figures are missing
                results = [err] * len(jobs)
            for job, figures in zip(jobs, results, strict=True):
                if isinstance(figures, Exception):
                    job.warnings.append(f"could not measure the result: {figures}")
                measured.append(None if isinstance(figures, Exception) else figures)
    except BaseException:  # an error, or closed early (GeneratorExit): nothing is left
        for action, (obj, _memo) in zip(made, done, strict=False):
            actions.restore_pose(obj, action)
        for obj, memo in reversed(done):
            actions.undo_assignment(obj, memo)
        for action in made:
            bpy.data.actions.remove(action)
        # the Actions given back animate the rig again as they did
        context.scene.frame_set(frame[0], subframe=frame[1])
        raise
    actions.delete_superseded(superseded)
    for job, action, figures in zip(jobs, made, measured, strict=False):
        obj = bpy.data.objects[job.obj_name]
        if figures is None:
            quality.clear(obj)
        else:
            quality.store(obj, action, job, figures)
    return made


# The key a bake's Action carries (see secondary.bake.SECONDARY_SOURCE).
_SECONDARY_SOURCE = "_procloco_secondary_source"
#: The key a generated Action of another kind than a walk carries (Job.action_kind).
ACTION_KIND = "_procloco_kind"


def _pose_inputs(jobs: Sequence[Job]) -> list[rig.PoseInputs]:
    """What ``rig.solve_poses_steps`` solves each finished job's pose from; jobs on one
    terrain share one ground function (their feet are pitched together)."""
    grounds: dict[int, rig.GroundFn] = {}
    out = []
    for job in jobs:
        assert job.result is not None
        body_world, joints_world = simulation.world_tracks(job)
        leg_frames, spine_rotation, spine_joints = simulation.spine_tracks(job)
        key = id(job.terrain)
        if key not in grounds:
            grounds[key] = simulation.ground_function(job)
        out.append(rig.PoseInputs(job.info, body_world, tuple(joints_world), grounds[key], spine_rotation,
                                  spine_joints, leg_frames, ~np.asarray(job.result.swing, dtype=bool)))
    return out


def _keyed_action_steps(
    context: bpy.types.Context, job: Job, tracks: rig.PoseTracks, replace: bool,
    superseded: list[tuple[bpy.types.Action, bpy.types.Action]],
) -> Generator[float, None, bpy.types.Action]:
    """A new generated Action holding ``job.result``, whose pose ``tracks`` were solved by
    ``rig.solve_poses_steps``, keyed on the rig's bones or their controls (:mod:`..pose_writer`)
    and assigned to the rig (``replace``, ``superseded``: see
    :func:`.actions.assign_generated_action`); yields the fraction done. On failure (or closed
    early) the Action is deleted and the rig's pose put back; the caller puts back the rig's
    assignment."""

    t0 = time.perf_counter()
    obj = bpy.data.objects[job.obj_name]
    assert job.result is not None
    info = job.info
    plan = job.plan
    if plan is None:
        plan, _warnings = plan_keys(obj, info)
    request = pose_writer.PoseRequest(
        frames=job.frames,
        bones=tracks.bones,
        armature=None,  # (it follows from the channels, when a control or a check needs it)
        keyed_location=tracks.keyed_location,
        world0=info.world,
        rest_local=info.rest_local,
        parents=info.parents,
        basis=info.basis,
        legs=tuple(leg.bones for leg in info.legs),
        rotations=tracks.rotations,
        locations=tracks.locations,
    )
    action = actions.new_action(obj, f"ProcLoco {job.action_kind}".strip())
    if job.action_kind:
        action[ACTION_KIND] = job.action_kind
    frames = job.frames.astype(np.float64)
    try:
        if job.held_bones:
            n = len(job.held_bones)
            rest_rotation = np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), (frames.size, n, 4))
            actions.write_pose_bone_transforms(action, obj, frames[[0, -1]], job.held_bones,
                                               rotations=rest_rotation[:2], locations=np.zeros((2, n, 3)))
        if job.kept_bones:
            basis = np.stack([info.basis[name] for name in job.kept_bones])  # (K, 4, 4)
            size = np.linalg.norm(basis[:, :3, :3], axis=1)  # (K, 3) each axis's scale
            turn = rig.matrix_to_quaternion(nearest_rotation(basis[:, :3, :3] / size[:, None, :]))
            actions.write_pose_bone_transforms(
                action, obj, frames[[0, -1]], job.kept_bones, rotations=np.stack([turn, turn]),
                locations=np.stack([basis[:, :3, 3]] * 2), scales=np.stack([size, size]))
        keyed = [*dict.fromkeys([*tracks.bones, *plan.keyed_bones, *job.held_bones, *job.kept_bones])]
        actions.remember_pose(action, obj, keyed, [(s.bone, s.prop) for s in plan.switches])
        # with Key Reduction on, the reduction's passes take the last fifth of the progress
        from ..keys import reduce

        written = 0.8 if reduce.is_enabled(obj) else 1.0
        report = yield from scaled_steps(pose_writer.write_pose_steps(
            action, obj, request, plan, check=job.check_after, replace=replace, superseded=superseded),
            0.0, written)
        if job.auto_gait is not None:
            rig_gait.store_auto_track(action, simulation.auto_track(job))
        job.key_reduction = yield from scaled_steps(_reduce_keys_steps(obj, action, job, plan), written, 1.0)
    except BaseException:  # an error, or closed early (Esc)
        actions.restore_pose(obj, action)
        bpy.data.actions.remove(action)
        raise
    off = [(leg.label, err * info.scale) for leg, err in zip(info.legs, report.leg_error, strict=False)
           if err * info.scale > 0.01]
    if off:
        job.warnings.append("after keying, the evaluated feet are off the plan: "
                            + ", ".join(f"leg {label} by {100.0 * err:.1f} cm" for label, err in off))
    job.keyed_bones = tuple(report.keyed)
    job.timings["write_s"] = time.perf_counter() - t0
    return action


def _reduce_keys_steps(obj: bpy.types.Object, action: bpy.types.Action, job: Job,
                       plan: controls.ControlPlan) -> Generator[float, None, Any]:
    """Key Reduction of the written walk when the rig has it on (see :mod:`..keys.reduce`):
    each leg's touch-downs and lift-offs stay keys of its bones and controls."""
    from ..keys import reduce

    assert job.result is not None
    stance = ~np.asarray(job.result.swing, dtype=bool)  # (F, legs)
    contacts = reduce.contact_frames(stance)
    required: dict[str, np.ndarray] = {}
    planted: dict[str, np.ndarray] = {}  # each leg's bones and controls stand with its foot
    chains = [(*leg.bones, *leg.foot) for leg in job.info.legs]
    for k, names in enumerate(reduce.leg_keyed_bones(plan, chains)):
        for name in names:
            required[name] = required.get(name, np.zeros(len(job.frames), dtype=bool)) | contacts[:, k]
            planted[name] = planted.get(name, np.zeros(len(job.frames), dtype=bool)) | stance[:, k]
    feet = [b for leg in job.info.legs for b in (leg.bones[-1], *leg.foot)]
    return (yield from reduce.reduce_if_enabled_steps(obj, action, job.frames, feet, required, planted))


def generate(
    context: bpy.types.Context,
    objects: Sequence[bpy.types.Object],
    progress: Callable[[str, float], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
    measure: bool = False,
) -> list[bpy.types.Action] | None:
    """Generate every rig in ``objects``; all are checked before anything is written, and
    rigs that can walk together do so in one simulation (:mod:`.crowd`).
    ``measure``: store the quality figures of each result (see :func:`write_all_steps`).

    Returns the new Actions, or None when ``should_cancel`` asked to stop (nothing written).
    Raises :class:`GenerateError` (nothing written) on bad input.
    """
    jobs = crowd.read_all(context, objects)
    groups = crowd.batches(jobs)  # the rigs that walk in one simulation
    for _fraction in crowd.read_terrain(context, groups):
        pass
    for names, fraction in crowd.simulate(groups):
        if progress is not None:
            progress(names, fraction)
        if should_cancel is not None and should_cancel():
            return None
    return run_steps(write_all_steps(context, jobs, measure))
