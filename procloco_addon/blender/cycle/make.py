# SPDX-License-Identifier: GPL-3.0-or-later
"""Make Cycle without the operator around it: used by the operator and the batch command.

A game-ready loop of ``N`` whole gait cycles, as a new generated Action:

1. :func:`read` reads the rig like Generate Locomotion (:func:`..locomotion.generate.read`)
   and refuses, changing nothing, what cannot loop: a path, turning, gait changes, burst
   progression, the gait randomizer, no speed, a root bone that is not one;
2. :func:`run_steps` (progress steps) reads the terrain and refuses ground that is not flat
   and level under the whole walk, or that moves; finds the gait's real cycle (the
   controller may shorten it so the legs keep up, see ``core.locomotion.rig``) and rounds it to
   whole frames and the stride to a whole number of the footstep planner's cells (its
   grids are fixed in the world: see :func:`_fit_stride`), the speed following (Gait: Auto
   is held at the gait it picks at the rig's speed); simulates a warm-up and the loop; finds the first whole
   cycle from which the walk repeats (``core.locomotion.cycle.steady_start``) and refuses a walk that
   does not settle; cuts ``N`` cycles, closes them exactly and takes the root motion off
   (``core.locomotion.cycle``);
3. the loop is written by Generate's writer (``generate.write_all_steps``: control rigs,
   undo of a failed write); then the root bone's keys (root motion kept), the exact
   closing of every F-curve and the Cycles modifiers (:func:`..actions.make_cyclic`).

Frames: the loop starts at the rig's first frame (its frame range's start) and lasts
``N * P`` frames, ``P`` frames per cycle; its last key is its first (moved on by ``N``
strides on the root bone when root motion is kept).
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import bpy
import numpy as np

from ...core.locomotion import cycle as core_cycle
from ...core.locomotion.autogait import AutoGait
from ...core.world.terrain import NO_SURFACE
from .. import actions
from ..locomotion import generate, simulation
from ..locomotion.job import RigTracks

__all__ = ["CycleError", "CycleJob", "make_cycles", "read", "root_bone_problem", "simulate_steps",
           "write_steps"]

#: Warm-ups tried in turn, in cycles: most walks settle within a few cycles (the wolf in 4,
#: the robot in 5); a small creature's pelvis bounce (real gravity, Gait: Auto) takes far
#: longer to die down, and its footsteps to repeat (the example tarantula: 36 cycles).
WARMUP_ROUNDS = (6, 48)
#: A walk repeats when every joint comes back to within this fraction of the leg length
#: (moved on by the stride) one cycle later...
STEADY_TOLERANCE = 1e-3
#: ...and every body and spine rotation to within this angle (radians).
STEADY_ANGLE = math.radians(0.1)
#: Level ground: every height under the walk within this fraction of the leg length.
LEVEL_TOLERANCE = 1e-3


class CycleError(generate.GenerateError):
    """Make Cycle refused; the message is meant for the user. Nothing was changed."""


@dataclass
class CycleJob:
    """One rig's loop: the Generate job that simulates the warm-up and the loop, and what
    Make Cycle found out about it."""

    job: generate.Job
    cycles: int
    root_motion: str  # "IN_PLACE" or "ROOT_BONE"
    root_bone: str
    first_frame: int
    fps: float
    asked_speed: float
    asked_cycle: float = 0.0  # the gait's cycle (s) before rounding to whole frames
    period: int = 0  # frames per cycle
    stretch: float = 1.0  # cycle time x stretch, speed / stretch
    warmup: int = 0  # frames simulated before the loop
    loop_error: float = 0.0  # how far the walk was from repeating (m), spread over the loop
    stride: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) world, one cycle
    closing: float = 0.0  # largest key change made to close every F-curve exactly
    stride_cells: int = 0  # the stride in planning cells (0: not a whole number, kept as it was)
    action: Any = None

    @property
    def obj_name(self) -> str:
        return self.job.obj_name

    def summary(self) -> str:
        """One line for the user: cycles, frames, stride, and what was changed to make it loop."""
        stride = float(np.linalg.norm(self.stride))
        where = "in place" if self.root_motion == "IN_PLACE" else f"root motion on '{self.root_bone}'"
        text = (f"{self.cycles} cycle{'s' if self.cycles > 1 else ''} of {self.period} frames "
                f"({self.period / self.fps:.3f} s, frames {self.first_frame}-"
                f"{self.first_frame + self.cycles * self.period}), stride {stride:.4g} m, {where}")
        asked = self.asked_speed * self.asked_cycle
        if abs(self.stretch - 1.0) > 1e-9 or abs(stride - asked) > 1e-9 * max(asked, 1.0):
            text += (f"; the cycle of {self.asked_cycle * self.fps:.2f} frames rounded to {self.period}"
                     + (f", the stride of {asked:.4g} m to {self.stride_cells} planning cells"
                        if self.stride_cells else ", the stride kept")
                     + f": speed {self.job.speed:.4g} m/s instead of {self.asked_speed:.4g}")
        return text


def _refuse_unsteady(obj: bpy.types.Object, job: generate.Job) -> None:
    settings = obj.procloco
    name = f"'{obj.name}'"
    reasons = []
    if settings.path is not None:
        reasons.append("it follows a path (clear the Path: a loop walks a straight line)")
    if abs(float(settings.turn_rate)) > 0.0:
        reasons.append("it turns (set Turn Rate to 0)")
    if len(settings.gait_changes):
        reasons.append("it has Gait Changes (a loop keeps one gait and one speed: remove them)")
    if settings.use_progression:
        reasons.append("Burst Progression changes its speed (switch it off in Effects)")
    if settings.use_gait_randomizer:
        reasons.append("the Gait Randomizer changes its gait (switch it off in Effects)")
    if job.speed <= 0.0:
        reasons.append("its speed is 0 (a loop needs a walk)")
    if reasons:
        raise CycleError(f"Make Cycle needs a steady walk, but {name}: " + "; ".join(reasons)
                         + ". Nothing was changed")


def root_bone_problem(obj: bpy.types.Object, bone: str, keyed: Sequence[str]) -> str | None:
    """Why ``bone`` cannot carry the root motion of ``obj`` whose generation keys ``keyed``
    bones (None when it can): it must exist, have no parent, be an ancestor of every keyed
    bone and not be keyed itself."""
    if not bone:
        return f"Root Motion on a root bone needs the bone: pick the root bone of '{obj.name}'"
    data = obj.data.bones.get(bone)
    if data is None:
        return f"'{obj.name}' has no bone '{bone}' to carry the root motion"
    if data.parent is not None:
        return (f"Bone '{bone}' of '{obj.name}' has a parent ('{data.parent.name}'): the root motion goes on "
                "a root bone")
    if bone in keyed:
        return (f"Bone '{bone}' of '{obj.name}' is one ProcLoco animates (body or leg): pick a bone above "
                "them to carry the root motion")
    outside = [b for b in keyed if not _descends(obj.data.bones[b], bone)]
    if outside:
        return (f"Bone '{bone}' of '{obj.name}' is not above {', '.join(repr(b) for b in outside[:3])}: "
                "the root bone must carry every animated bone")
    return None


def _descends(bone: Any, ancestor: str) -> bool:
    while bone is not None:
        if bone.name == ancestor:
            return True
        bone = bone.parent
    return False


def read(context: bpy.types.Context, obj: bpy.types.Object | None) -> CycleJob:
    """Read and check the rig for Make Cycle (not the terrain: :func:`run_steps`). Raises
    :class:`..generate.GenerateError` (:class:`CycleError` for a walk that cannot loop)."""
    job = generate.read(context, obj)
    assert obj is not None
    _refuse_unsteady(obj, job)
    settings = obj.procloco_cycle
    scene = context.scene
    fps = scene.render.fps / scene.render.fps_base
    root_motion = str(settings.root_motion)
    if root_motion == "ROOT_BONE":
        plan = job.plan
        keyed = list(dict.fromkeys([*(plan.keyed_bones if plan is not None else ()), *job.info.driven_bones]))
        problem = root_bone_problem(obj, str(settings.root_bone), keyed)
        if problem is not None:
            raise CycleError(problem)
    job.action_kind = "Cycle"  # a loop made from a walk leaves the walk (kept with a fake user)
    if job.auto_gait is not None:
        # Auto picks one gait at one speed: held, so the cycle can be rounded to whole frames.
        job.gait = AutoGait([job.auto_gait], [job.speed]).gaits([job.gait])[0]
        job.held_auto, job.auto_gait = job.auto_gait, None
    return CycleJob(job=job, cycles=int(settings.cycles), root_motion=root_motion,
                    root_bone=str(settings.root_bone), first_frame=int(job.frames[0]), fps=fps,
                    asked_speed=job.speed)


def _check_level(cj: CycleJob, frames: int) -> None:
    """Refuse ground that moves, or is not flat and level under the walk of ``frames``."""
    job = cj.job
    terrain = job.terrain
    assert terrain is not None
    if terrain.dynamic_index:
        moving = ", ".join(f"'{terrain.objects[i]}'" for i in terrain.dynamic_index[:3])
        raise CycleError(f"Make Cycle needs still ground, but {moving} move: a loop cannot meet them again")
    leg = float(np.mean(job.info.leg_length))
    origin = np.asarray(job.info.body.origin, dtype=np.float64)[:2]
    forward = np.array([math.cos(job.heading), math.sin(job.heading)])
    side = np.array([-forward[1], forward[0]])
    reach = float(np.max(np.linalg.norm(np.asarray(job.info.contact)[:, :2] - origin, axis=1)))
    half = max(reach, leg) + leg
    length = job.speed * frames * job.dt
    u = np.arange(-half, length + half + 1e-9, 0.05 * leg)
    v = np.arange(-half, half + 1e-9, 0.05 * leg)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    xy = origin + uu.reshape(-1, 1) * forward + vv.reshape(-1, 1) * side
    h = terrain.environment.height_at(xy)
    if np.any(h <= NO_SURFACE * 0.5):
        raise CycleError(f"Make Cycle needs ground under the whole walk of '{job.obj_name}' "
                         f"({length:.3g} m ahead of it): make the ground larger")
    spread = float(h.max() - h.min())
    if spread > LEVEL_TOLERANCE * leg:
        raise CycleError(f"Make Cycle needs flat, level ground, but under the walk of '{job.obj_name}' "
                         f"the ground rises and falls by {100.0 * spread:.3g} cm: a loop on uneven ground "
                         "cannot close")


def _probe_period(cj: CycleJob) -> float:
    """The gait's real cycle in seconds: the needle's rate after the first step (the
    controller speeds it up when the stride would outrun the legs)."""
    job = cj.job
    frames = job.frames
    job.frames = frames[:2]
    try:
        for _ in simulation.run(job):
            pass
        assert job.result is not None
        rate = float(job.result.phase_rate[1])
    finally:
        job.frames = frames
        job.result = None
    return 1.0 / rate


def _fit_stride(cj: CycleJob, true_cycle: float) -> None:
    """Set the gait's cycle time and the speed so that a cycle lasts exactly ``P`` frames and
    the stride is a whole number of planning cells, as near the walk's own as the legs allow.

    Why whole cells: the footstep planner chooses footprints on grids fixed in the world, so
    a stride that is not a whole number of cells meets the grid differently at every cycle,
    and a footprint near a cell's edge lands in one cell or the next (the wolf's hind feet
    5 cm apart every third cycle). The cycle time is the gait's real one (the controller's
    shortening when the stride would outrun the legs taken into the cycle, so it does not
    apply any more); the number of cells is rounded to the nearest when the legs had room,
    down when they did not. When no whole number of cells gives exactly ``P`` frames, the
    cycle time is stretched by ``k`` and the speed divided by it (the same stride)."""
    job = cj.job
    period_s = cj.period / cj.fps
    stride = cj.asked_speed * true_cycle
    limited = true_cycle < job.gait.cycle_time * (1.0 - 1e-9)
    leg = float(np.mean(job.info.leg_length))
    base_gait, base_speed = job.gait, job.speed
    cells = stride / simulation.planning_cell(job, leg)
    first = round(cells) if not limited else math.floor(cells + 1e-6)
    for n in (first, first - 1):
        if n < 1:
            break
        job.gait = base_gait.with_cycle_time(period_s)
        for _ in range(50):  # Auto's planning window, and so its cell, grows with the speed
            speed = n * simulation.planning_cell(job, leg) / period_s
            if abs(speed - job.speed) <= 1e-12 * speed:
                break
            job.speed = speed
        if abs(_probe_period(cj) - period_s) <= 1e-9 * period_s:
            cj.stretch = period_s / true_cycle
            cj.stride_cells = n
            return
    # Cycle time x k and speed / k: the same stroke (the same speed-up by the controller),
    # the same stride, and a cycle of exactly P frames.
    job.gait = base_gait.with_cycle_time(base_gait.cycle_time * cj.stretch)
    job.speed = base_speed / cj.stretch


def _points(res: RigTracks) -> np.ndarray:
    """Every tracked world point of a result as ``(F, M, 3)``."""
    parts = [res.body[:, None, :3, 3], res.joints.reshape(res.joints.shape[0], -1, 3), res.feet]
    if res.spine_joints is not None:
        parts.append(res.spine_joints)
    return np.concatenate(parts, axis=1)


def _rotations(res: RigTracks) -> list[np.ndarray]:
    out = [res.body[:, None, :3, :3], res.leg_frame]
    if res.spine_rotation is not None:
        out.append(res.spine_rotation)
    return out


def _max_turn(rot: np.ndarray, period: int, start: int, cycles: int) -> float:
    a = rot[start:start + cycles * period + 1]
    b = rot[start + period:start + (cycles + 1) * period + 1]
    rel = np.einsum("fmji,fmjk->fmik", a, b)
    cos = np.clip(0.5 * (np.trace(rel, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
    return float(np.arccos(cos).max())


def _loop_result(cj: CycleJob, start: int) -> RigTracks:
    """The loop cut from the simulated walk at frame ``start``: ``N * P + 1`` frames, closed
    exactly, the root motion taken off (it goes on the root bone, or nowhere)."""
    res = cj.job.result
    assert res is not None
    n = cj.cycles * cj.period
    cut = slice(start, start + n + 1)
    drift = cj.cycles * cj.stride
    # back to where the rig stands: the loop's first body position is the walk's first
    shift = res.body[start, :3, 3] - res.body[0, :3, 3]
    shift[2] = 0.0

    def points(p: np.ndarray) -> np.ndarray:
        shape = p[cut].shape
        flat = p[cut].reshape(shape[0], -1, 3)
        return core_cycle.remove_drift(core_cycle.close_points(flat, drift), drift, shift).reshape(shape)

    def rotations(r: np.ndarray) -> np.ndarray:
        shape = r[cut].shape
        return core_cycle.close_rotations(r[cut].reshape(shape[0], -1, 3, 3)).reshape(shape)

    body = res.body[cut].copy()
    body[:, :3, 3] = points(res.body[:, None, :3, 3])[:, 0]
    body[:, :3, :3] = rotations(res.body[:, None, :3, :3])[:, 0]
    swing = res.swing[cut].copy()
    swing[-1] = swing[0]

    def same(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[cut].copy()

    return RigTracks(
        body=body, joints=points(res.joints), swing=swing, feet=points(res.feet),
        ik_error=res.ik_error[cut].copy(), needle=res.needle[cut].copy(),
        phase_rate=res.phase_rate[cut].copy(),
        forced=res.forced[cut].copy(), plan_failed=res.plan_failed[cut].copy(),
        disk_start=res.disk_start[cut].copy(), leg_frame=rotations(res.leg_frame),
        spine_joints=None if res.spine_joints is None else points(res.spine_joints),
        spine_rotation=None if res.spine_rotation is None else rotations(res.spine_rotation),
        disk_duration=same(res.disk_duration), speed=same(res.speed), auto_band=same(res.auto_band))


def simulate_steps(context: bpy.types.Context, cj: CycleJob) -> Generator[tuple[str, float], None, None]:
    """Terrain, checks and simulation of one loop as progress steps ``(text, fraction)``;
    ``cj.job.result`` ends holding the loop, ``cj.job.frames`` its frames."""
    job = cj.job
    name = job.obj_name
    for fraction in generate.read_terrain(context, job):
        yield f"{name}: reading the terrain", 0.1 * fraction
    true_cycle = _probe_period(cj)
    cj.asked_cycle = true_cycle
    try:
        period, stretch = core_cycle.whole_period(true_cycle, cj.fps)
    except ValueError as err:
        raise CycleError(f"Make Cycle of '{name}': {err}") from err
    cj.period, cj.stretch = period, stretch
    _fit_stride(cj, true_cycle)
    leg = float(np.mean(job.info.leg_length))
    share = 0.7 / len(WARMUP_ROUNDS)
    for k, warmup in enumerate(WARMUP_ROUNDS):
        total = (warmup + cj.cycles + 1) * period + 1
        _check_level(cj, total)
        job.frames = cj.first_frame + np.arange(total, dtype=np.int64)
        for fraction in simulation.run(job):
            yield (f"{name}: simulating {warmup} cycles of warm-up and {cj.cycles} of loop",
                   0.1 + share * (k + fraction))
        res = job.result
        assert res is not None
        if np.abs(res.phase_rate[1:] * period * job.dt - 1.0).max() > 1e-6:
            raise CycleError(f"The gait cycle of '{name}' changed during the walk: a loop needs a steady "
                             "gait")
        points = _points(res)
        rotations = _rotations(res)
        start, error = core_cycle.steady_start(points, period, cj.cycles, STEADY_TOLERANCE * leg)
        while start >= 0 and max(_max_turn(r, period, start, cj.cycles) for r in rotations) > STEADY_ANGLE:
            start, error = core_cycle.steady_start(points, period, cj.cycles, STEADY_TOLERANCE * leg,
                                                   earliest=start // period + 1)
        if start >= 0:
            break
    if start < 0:
        raise CycleError(f"The walk of '{name}' did not settle into a steady cycle within "
                         f"{WARMUP_ROUNDS[-1]} cycles (it still differs by {1000.0 * error:.2f} mm from one "
                         "cycle to the next): nothing was changed. A slower walk, or Pelvis Physics off, "
                         "often settles")
    cj.warmup = start
    cj.loop_error = error
    # The body's own motion: the controller moves it by exactly speed x dt a frame on a
    # straight line (what is left of the other points' cycle-to-cycle error is spread).
    assert res is not None
    cj.stride = core_cycle.stride_of(res.body[:, None, :3, 3], period, start, cj.cycles)
    cj.stride[2] = 0.0  # level ground: the stride is horizontal
    job.result = _loop_result(cj, start)
    job.frames = cj.first_frame + np.arange(cj.cycles * period + 1, dtype=np.int64)
    yield f"{name}: loop found", 0.8


def _root_keys(cj: CycleJob, obj: bpy.types.Object, action: bpy.types.Action) -> set[tuple[str, int]]:
    """Key the root motion on the root bone: a straight line of ``N`` strides over the loop.
    Returns its location channels (they repeat with an offset)."""
    frames = cj.job.frames.astype(np.float64)
    bone = obj.data.bones[cj.root_bone]
    to_arm = np.linalg.inv(np.array(obj.matrix_world, dtype=np.float64)[:3, :3])
    rest = np.array(bone.matrix_local, dtype=np.float64)[:3, :3]
    drift_local = rest.T @ (to_arm @ (cj.cycles * cj.stride))
    weight = np.linspace(0.0, 1.0, frames.size)
    locations = (weight[:, None] * drift_local[None])[:, None, :]
    rotations = np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), (frames.size, 1, 4))
    actions.write_pose_bone_transforms(action, obj, frames, [cj.root_bone], rotations=rotations,
                                       locations=locations)
    path = f'pose.bones["{bpy.utils.escape_identifier(cj.root_bone)}"].location'
    return {(path, a) for a in range(3)}


def write_steps(context: bpy.types.Context,
                jobs: Sequence[CycleJob]) -> Generator[float, None, list[bpy.types.Action]]:
    """Write every loop as a new Action (Generate's writer), then its root keys, exact closing
    and Cycles modifiers. Yields the fraction done; returns the Actions."""
    made = yield from generate.write_all_steps(context, [cj.job for cj in jobs])
    for cj, action in zip(jobs, made, strict=True):
        obj = bpy.data.objects[cj.obj_name]
        offset: set[tuple[str, int]] = set()
        if cj.root_motion == "ROOT_BONE":
            offset = _root_keys(cj, obj, action)
        cj.closing = actions.make_cyclic(action, obj, offset)
        cj.action = action
    return made


def make_cycles(context: bpy.types.Context, objects: Sequence[bpy.types.Object],
                progress: Any = None) -> list[CycleJob]:
    """Make Cycle straight through for ``objects`` (the batch command); every rig is read and
    checked before anything is written. Raises :class:`..generate.GenerateError`."""
    jobs = [read(context, obj) for obj in objects]
    for cj in jobs:
        for text, fraction in simulate_steps(context, cj):
            if progress is not None:
                progress(text, fraction)
    for _ in write_steps(context, jobs):
        pass
    return jobs
