# SPDX-License-Identifier: GPL-3.0-or-later
"""Running the core character controller for one :class:`~.generate.Job`, frame by frame.

Only glue: the controller (``core.locomotion``) does the locomotion. This module turns
the rig settings into per-step commands (speed, heading — constant, turning, or steered
along a path curve — step height, foot spacing, pelvis physics) and the flexible spine's
settings (``core.spine.SpineParams``), moves the scene's animated obstacles to each frame
before the step, and records what the rig needs per frame: the body frame in the world,
every leg joint, the frame each leg hangs from, and the spine's joints and bone rotations.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ...core.autogait import AutoGait
from ...core.footprints import PlannerParams
from ...core.locomotion.controller import Controller
from ...core.locomotion.types import ControllerParams, StepControls
from ...core.morphology import LegBatch
from ...core.pelvis_physics import PelvisPhysicsParams
from ...core.progression import ProgressionParams, ProgressionState, effects_step, initial_gaits
from ...core.spine import SpineParams
from ...core.terrain import NO_SURFACE

if TYPE_CHECKING:
    from .generate import GaitChange, Job

__all__ = [
    "SimResult", "auto_track", "ground_function", "path_heading", "planning_cell", "run", "speed_schedule",
    "spine_params",
    "spine_tracks", "world_tracks",
]


@dataclass
class SimResult:
    """Per-frame results, ``F`` frames: ``body`` ``(F, 4, 4)`` body-to-world transforms,
    ``joints`` ``(F, n_legs, s + 1, 3)`` world joints (hip first), ``swing`` ``(F, n_legs)``
    feet in the air, ``feet`` ``(F, n_legs, 3)`` end-effector targets, ``ik_error``
    ``(F, n_legs)`` distance from each end-effector to its target; ``needle`` ``(F,)`` the
    gait needle's phase and ``phase_rate`` ``(F,)`` its speed in cycles per second (the
    controller speeds it up when the stride would be too long); ``forced`` ``(F, n_legs)``
    feet taking a forced step (their support moved or became forbidden); ``plan_failed``
    ``(F, n_legs)`` feet whose footstep plan failed (they stay planted); ``disk_start``
    ``(F, n_legs)`` each leg's swing start on the gait circle (changes with gait transitions);
    ``leg_frame`` ``(F, n_legs, 3, 3)`` body-to-world rotation of what each leg hangs from
    (the body, or its spine bone); with the flexible spine, ``spine_joints`` ``(F, J, 3)``
    world spine joints (head first) and ``spine_rotation`` ``(F, J - 1, 3, 3)`` each spine
    bone's rotation from its rest (body-frame) direction (None without a spine);
    ``disk_duration`` ``(F, n_legs)`` each leg's swing duration on the gait circle;
    ``speed`` ``(F,)`` the speed asked of the controller (m/s, after burst progression and
    a path's end); ``auto_band`` ``(F,)`` Auto's gait index (-1 without Auto)."""

    body: np.ndarray
    joints: np.ndarray
    swing: np.ndarray
    feet: np.ndarray
    ik_error: np.ndarray
    needle: np.ndarray
    phase_rate: np.ndarray
    forced: np.ndarray
    plan_failed: np.ndarray
    disk_start: np.ndarray
    leg_frame: np.ndarray
    spine_joints: np.ndarray | None = None
    spine_rotation: np.ndarray | None = None
    disk_duration: np.ndarray | None = None
    speed: np.ndarray | None = None
    auto_band: np.ndarray | None = None


def path_heading(path: np.ndarray, xy: np.ndarray, lookahead: float) -> tuple[float, float]:
    """Heading toward the point ``lookahead`` metres further along the path than the point
    of ``path`` ``(n, 3)`` nearest to ``xy`` ``(2,)``; also the distance left to the path's end."""
    p = path[:, :2]
    seg = np.diff(p, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    t = np.clip(np.einsum("ij,ij->i", xy[None] - p[:-1], seg) / np.maximum(seg_len ** 2, 1e-18), 0.0, 1.0)
    near = p[:-1] + t[:, None] * seg
    k = int(np.argmin(np.linalg.norm(near - xy[None], axis=1)))
    s_here = cum[k] + t[k] * seg_len[k]
    s_goal = min(s_here + lookahead, cum[-1])
    j = int(np.clip(np.searchsorted(cum, s_goal) - 1, 0, len(seg) - 1))
    u = (s_goal - cum[j]) / max(seg_len[j], 1e-18)
    goal = p[j] + u * seg[j]
    d = goal - xy
    if np.linalg.norm(d) < 1e-9:
        d = seg[-1]
    return float(np.arctan2(d[1], d[0])), float(cum[-1] - s_here)


def _controls(job: Job, legs: LegBatch, speed: float, heading: float) -> StepControls:
    rest_y = legs.rest_foot[:, 1]
    spacing = job.foot_offset.copy()
    spacing[:, 1] += (job.spacing - 1.0) * rest_y
    return StepControls(
        speed=np.array([speed]),
        heading=np.array([heading]),
        step_height=np.array([job.step_height]),
        spacing=spacing,
        pelvis_physics=np.array([job.use_pelvis_physics]),
        ik=np.array([True]),
    )


def spine_params(job: Job) -> SpineParams:
    """The flexible spine's settings of a job (thesis §4.2, §4.4)."""
    return SpineParams(
        turn_rate=max(job.spine_turn_rate, 1e-3),
        relax_time=max(job.spine_relax_time, 1e-3),
        visual_yaw=job.use_visual_yaw,
        visual_yaw_gain=job.visual_yaw_gain,
    )


def speed_schedule(job: Job) -> Callable[[float], float]:
    """The commanded speed at each time ``t`` (seconds from the first frame): the rig's
    speed, then each gait change's speed reached evenly over its transition time from
    whatever the speed was when the change began (a change at the first frame: at once)."""
    ramps: list[tuple[float, float, float, float]] = []  # start, duration, from, to

    def speed_at(t: float) -> float:
        v = job.speed
        for t0, duration, v0, v1 in ramps:
            if t >= t0:
                v = v1 if duration <= 0.0 else v0 + (v1 - v0) * min((t - t0) / duration, 1.0)
        return v

    for change in job.gait_changes:
        if change.speed is not None:
            t0 = change.frame_index * job.dt
            duration = change.transition_time if change.frame_index > 0 else 0.0
            ramps.append((t0, duration, speed_at(t0), change.speed))
    return speed_at


#: Leg length (m) at which the simulation's physical constants are the real ones.
REFERENCE_LEG = 0.7325  # the Rigify wolf's


def planning_cell(job: Job, leg_len: float) -> float:
    """The footstep planner's cell size (m) for ``job`` (grids fixed in the world)."""
    return _window(job, leg_len)[1]


def _window(job: Job, leg_len: float) -> tuple[int, float]:
    """Cells and cell size of the planning window: 70 cells of 0.065 leg (4.5 legs across);
    with Gait: Auto grown when the fastest stride would put a landing foot beyond its edge (the
    window is centred on the pelvis; a front foot lands up to about a leg and a half plus a
    stride ahead of where the pelvis was at lift-off). Cells and size grow alike, by the
    square root of the needed growth, so planning stays affordable at a gallop."""
    cells, cell = 70, 0.065 * leg_len
    auto = job.auto_gait or job.held_auto
    if auto is None:  # (the circles' walks keep the window they were tuned with)
        return cells, cell
    v_max = max([job.speed] + [c.speed for c in job.gait_changes if c.speed is not None])
    half = 1.5 * leg_len + v_max * float(auto.schedule([v_max])[2][0])
    growth = half / (0.5 * cells * cell)
    if growth <= 1.0:
        return cells, cell
    return int(np.ceil(cells * np.sqrt(growth))), cell * float(np.sqrt(growth))


def run(job: Job) -> Iterator[float]:
    """Simulate ``job`` (one controller step per frame after the first); yields the fraction
    done and stores a :class:`SimResult` in ``job.result``."""
    legs = LegBatch.stack([job.morphology])
    n_frames = job.frames.shape[0]
    terrain = job.terrain
    if terrain is None:
        raise RuntimeError("the job's terrain has not been read (generate.read_terrain)")
    terrain.apply_frame(0)
    origin = job.info.body.origin
    start_yaw = float(np.arctan2(job.info.body.forward[1], job.info.body.forward[0]))
    leg_len = float(np.mean(job.info.leg_length))
    rng = np.random.default_rng(job.seed)
    progression = ProgressionParams(max_speed=max(job.speed, 0.0))
    prog_state = ProgressionState.start(1, progression, rng) if job.use_progression else None
    gait = job.gait
    randomize = job.use_gait_randomizer and job.auto_gait is None  # Auto chooses the gait itself
    if randomize and not job.use_progression:
        # Thesis §4.3: without stalls the randomizer only draws the gait the creature starts with.
        gait = initial_gaits([legs.n_legs], rng)[0].to_gait(job.gait.cycle_time, "Random gait")
    # Gait changes at the first frame set the gait the walk starts with; later ones start a
    # transition at their frame.
    changes_at: dict[int, list[GaitChange]] = {}
    # With Auto the changes' speeds still count (speed_schedule), their gaits do not.
    for change in job.gait_changes if job.auto_gait is None else ():
        if change.frame_index == 0:
            gait = change.gait
        else:
            changes_at.setdefault(change.frame_index, []).append(change)
    speed_at = speed_schedule(job)

    def command(t: float, xy: np.ndarray) -> tuple[float, float]:
        speed = speed_at(t)
        if job.path is not None:
            heading, left = path_heading(job.path, xy, max(leg_len, 0.5 * job.speed))
            if left < 0.05 * leg_len:
                speed = 0.0
            return speed, heading
        return speed, job.heading + job.turn_rate * t

    speed0, heading0 = command(0.0, origin[:2])
    if job.path is not None:
        start_yaw = heading0 if abs(np.angle(np.exp(1j * (heading0 - start_yaw)))) < 0.5 else start_yaw
    speed0 = 0.0 if prog_state is not None else speed0
    ctl = _controls(job, legs, speed0, heading0)
    auto = AutoGait([job.auto_gait], [speed0]) if job.auto_gait is not None else None
    if auto is not None:
        gait = auto.gaits([gait])[0]
    # Planning cells and height slices scale with the creature (the core's defaults are
    # tuned for half-metre legs: 7 cm cells, 10 cm slices), so a rig scaled ×100 plans the
    # same steps on a 100 times larger terrain.
    # The pelvis's pogo-stick bounces by about g T² for a cycle of T seconds. With the gait
    # circles T is the rig's cycle time whatever its size, and a 2 cm wolf would bob by its
    # own leg length: gravity then scales with the creature (real gravity at REFERENCE_LEG),
    # so a rig scaled x0.01 or x100 bobs the same for its size. With Gait: Auto the cycle
    # follows the Froude number (T grows as the square root of the size) and real gravity
    # keeps the bounce to scale. The planted feet's support tolerance (2 mm at
    # REFERENCE_LEG) and the leg IK's (10 µm there) scale with the creature either way.
    size = leg_len / REFERENCE_LEG
    gravity = 9.81 * (size if job.auto_gait is None and job.held_auto is None else 1.0)
    cells, cell = _window(job, leg_len)
    params = ControllerParams(window_cells=cells, window_cell=cell, slice_size=0.14 * leg_len,
                              support_tolerance=0.002 * size, ik_tolerance=1e-5 * size,
                              physics=PelvisPhysicsParams(gravity=gravity))
    planner = PlannerParams(step_height=job.step_height, slice_size=0.14 * leg_len, leg_reach=leg_len,
                            candidate_radius=params.candidate_radius * leg_len,
                            fixed_distance=params.fixed_distance * leg_len, edge_height=0.055 * leg_len)
    spine = [spine_params(job)] if job.morphology.spine is not None else None
    sim = Controller(terrain.environment, legs, [gait], origin[None, :2], np.array([start_yaw]), ctl,
                     params=params, planner=[planner], spine=spine)

    n_legs = legs.n_legs
    s1 = legs.max_segments + 1
    body = np.empty((n_frames, 4, 4))
    joints = np.empty((n_frames, n_legs, s1, 3))
    swing = np.zeros((n_frames, n_legs), dtype=bool)
    feet = np.empty((n_frames, n_legs, 3))
    ik_error = np.zeros((n_frames, n_legs))
    needle = np.zeros(n_frames)
    phase_rate = np.zeros(n_frames)
    forced = np.zeros((n_frames, n_legs), dtype=bool)
    failed = np.zeros((n_frames, n_legs), dtype=bool)
    disk_start = np.zeros((n_frames, n_legs))
    disk_duration = np.zeros((n_frames, n_legs))
    speed_track = np.zeros(n_frames)
    auto_band = np.full(n_frames, -1, dtype=np.int64)
    leg_frame = np.empty((n_frames, n_legs, 3, 3))
    n_spine = job.morphology.spine.n_joints if spine is not None and job.morphology.spine is not None else 0
    spine_joints = np.empty((n_frames, n_spine, 3)) if n_spine else None
    spine_rotation = np.empty((n_frames, n_spine - 1, 3, 3)) if n_spine else None

    def result_of(n: int) -> SimResult:
        """The first ``n`` frames' results (views of the arrays being filled)."""
        return SimResult(body[:n], joints[:n], swing[:n], feet[:n], ik_error[:n], needle[:n], phase_rate[:n],
                         forced[:n], failed[:n], disk_start[:n], leg_frame[:n],
                         None if spine_joints is None else spine_joints[:n],
                         None if spine_rotation is None else spine_rotation[:n], disk_duration[:n],
                         speed_track[:n], auto_band[:n])

    # Live Preview writes the current frame's pose before the rest of the range is simulated.
    job.partial = result_of

    def record(f: int) -> None:
        body[f] = np.eye(4)
        body[f, :3, :3] = sim.rotations()[0]
        body[f, :3, 3] = sim.pos[0]
        res = sim.ik_result
        assert res is not None
        joints[f] = res.joints
        ik_error[f] = res.error
        swing[f] = sim.swinging
        feet[f] = sim.ik_targets()
        needle[f] = float(sim.gait.needle[0])
        phase_rate[f] = float(sim.gait.rate()[0])
        forced[f] = sim.forced
        failed[f] = sim.plan_failed
        disk_start[f] = sim.gait.disk_start
        disk_duration[f] = sim.gait.disk_duration
        if auto is not None:
            auto_band[f] = int(auto.band[0])
        leg_frame[f] = sim.leg_rotations()
        if spine_joints is not None and spine_rotation is not None:
            spine_joints[f] = sim.spine_joints()[0]
            spine_rotation[f] = sim.spine_rotations()[0]

    # The controller's initial pose does not yet keep the hips within reach of the feet (its
    # reach guard runs in step()): a vanishing step settles frame 0 without moving anything.
    sim.step(1e-9 * job.dt, ctl)
    speed_track[0] = speed0
    record(0)
    yield 1.0 / n_frames
    for f in range(1, n_frames):
        terrain.apply_frame(f)
        t = f * job.dt
        speed, heading = command(t, sim.pos[0, :2])
        if prog_state is not None:
            progression = ProgressionParams(max_speed=max(speed, 0.0))
            prog_state, effects = effects_step(prog_state, progression, job.dt, rng, [legs.n_legs],
                                               randomize_gait=randomize)
            speed = float(effects.progression.speed[0])
            if 0 in effects.new_gaits:  # a stall: the next burst walks with a new random gait
                new = effects.new_gaits[0].to_gait(job.gait.cycle_time, "Random gait")
                sim.gait.start_transition([0], [new], 0.5 * job.gait.cycle_time)
        for change in changes_at.get(f, ()):
            sim.gait.start_transition([0], [change.gait], change.transition_time)
        if auto is not None:
            auto.update(sim.gait, [speed])
        speed_track[f] = speed
        sim.step(job.dt, _controls(job, legs, speed, heading))
        record(f)
        yield (f + 1) / n_frames
    job.result = result_of(n_frames)


def auto_track(job: Job) -> Any:
    """What Auto chose over a finished job's frames, as ``gait.rig_gait.AutoTrack``."""
    from ..gait import rig_gait

    res: SimResult = job.result
    params = job.auto_gait
    if res is None or params is None or res.speed is None or res.auto_band is None:
        raise RuntimeError("the simulation has not run with Auto gait")
    return rig_gait.AutoTrack(job.frames.copy(), res.speed.copy(), res.auto_band.copy(), params.names,
                              rig_gait.boundary_speeds(params), res.disk_start.copy(),
                              np.asarray(res.disk_duration).copy(), res.needle.copy(), True)


def world_tracks(job: Job) -> tuple[np.ndarray, list[np.ndarray]]:
    """The body frames ``(F, 4, 4)`` and per-leg world joints ``(F, k + 1, 3)`` of a finished job."""
    res: SimResult = job.result
    if res is None:
        raise RuntimeError("the simulation has not run")
    joints = [res.joints[:, i, : len(leg.bones) + 1] for i, leg in enumerate(job.info.legs)]
    return res.body, joints


def spine_tracks(job: Job) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The frames the legs hang from ``(F, n_legs, 3, 3)`` and, with a spine, its bones'
    rotations ``(F, J - 1, 3, 3)`` and joints ``(F, J, 3)`` (else None) of a finished job:
    what ``rig.solve_pose`` takes as ``leg_frames``, ``spine_rotation``, ``spine_joints``."""
    res: SimResult = job.result
    if res is None:
        raise RuntimeError("the simulation has not run")
    return res.leg_frame, res.spine_rotation, res.spine_joints


def ground_function(job: Job) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``ground(frame_index (n,), xy (n, 2)) -> (n,)``: the scene's surface heights at those
    frames (moving obstacles where they are then), ``-inf`` over nothing."""
    terrain = job.terrain
    if terrain is None:
        raise RuntimeError("the job's terrain has not been read (generate.read_terrain)")

    def heights(xy: np.ndarray) -> np.ndarray:
        h = terrain.environment.height_at(xy) - terrain.z_offset
        return np.where(h > NO_SURFACE * 0.5, h, -np.inf)

    def ground(frame_index: np.ndarray, xy: np.ndarray) -> np.ndarray:
        if not terrain.dynamic_index:
            return heights(xy)
        out = np.empty(xy.shape[0])
        for f in np.unique(frame_index):
            terrain.apply_frame(int(f))
            pick = frame_index == f
            out[pick] = heights(xy[pick])
        return out

    ground.dynamic = bool(terrain.dynamic_index)  # type: ignore[attr-defined]
    return ground
