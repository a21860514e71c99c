# SPDX-License-Identifier: GPL-3.0-or-later
"""Running the core simulation (``core.locomotion.sim.Simulation``) for one :class:`~.job.Job`, frame
by frame, or for several rigs in one simulation (:func:`batch_simulation`, :func:`run_all`;
which rigs go together: ``.crowd``).

Only glue: :func:`_character` is the one conversion of a rig's settings into the core's
inputs — the per-step commands (speed with the Gait Changes' ramps, heading: constant,
turning, or steered along a path curve; step height, foot spacing, pelvis physics), the
gait and its scheduled changes, Gait: Auto, burst progression and the gait randomizer
(``core.locomotion.sim.Effects``), the flexible spine's settings and the creature-size scaling
(``core.locomotion.scaling``). :func:`run` moves the scene's animated obstacles to each frame before
the step into it and hands out the tracks the rig is written from
(:class:`~.job.RigTracks`).

The shell's frame index ``f`` is the core's frame ``f``: the state after ``f`` steps, the
step into it following the commands of time ``f dt``; a Gait Change at frame ``k`` begins
before the step into frame ``k``.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import pickle
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...core.geometry import wrap_angle
from ...core.locomotion import scaling
from ...core.locomotion.footprints import PlannerParams
from ...core.locomotion.gait import Gait
from ...core.locomotion.morphology import LegBatch, Morphology
from ...core.locomotion.rig import Rig
from ...core.locomotion.sim import (
    Controls,
    Effects,
    GaitChange,
    PathFollower,
    Simulation,
    SpeedRamp,
    speed_schedule,
)
from ...core.locomotion.spine import SpineParams
from ...core.locomotion.types import ControllerParams
from ...core.world.terrain import NO_SURFACE
from .job import Job, RigTracks

__all__ = [
    "CHECKPOINT_FRAMES", "Checkpoints", "auto_track", "batch_key", "batch_simulation", "ground_function",
    "planning_cell", "run", "run_all", "simulation_inputs", "simulation_of", "speed_at", "spine_params",
    "spine_tracks", "step_digests", "world_tracks",
]


def spine_params(job: Job) -> SpineParams:
    """The flexible spine's settings of a job (thesis §4.2, §4.4)."""
    return SpineParams(
        turn_rate=max(job.spine_turn_rate, 1e-3),
        relax_time=max(job.spine_relax_time, 1e-3),
        visual_yaw=job.use_visual_yaw,
        visual_yaw_gain=job.visual_yaw_gain,
    )


def speed_at(job: Job) -> Callable[[float], float]:
    """The commanded speed at each time ``t`` (seconds from the first frame): the rig's
    speed, then each gait change's speed reached evenly over its transition time from
    whatever the speed was when the change began (a change at the first frame: at once)."""
    return speed_schedule(job.speed, [
        SpeedRamp(c.frame_index * job.dt, c.transition_time if c.frame_index > 0 else 0.0, c.speed)
        for c in job.gait_changes if c.speed is not None])


def _window(job: Job, leg_len: float) -> tuple[int, float]:
    auto = job.auto_gait or job.held_auto
    speeds = [job.speed] + [c.speed for c in job.gait_changes if c.speed is not None]
    return scaling.planning_window(leg_len, auto, speeds)


def planning_cell(job: Job, leg_len: float) -> float:
    """The footstep planner's cell size (m) for ``job`` (grids fixed in the world)."""
    return _window(job, leg_len)[1]


def simulation_of(job: Job) -> Simulation:
    """The core simulation of ``job`` (its terrain read and at its first frame): the one
    conversion of the rig's settings into the core's inputs."""
    return batch_simulation([job])


@dataclass
class _Character:
    """One rig's inputs to a shared :class:`Simulation` (see :func:`batch_simulation`)."""

    morphology: Morphology
    gait: Gait
    start_xy: np.ndarray
    start_yaw: float
    speed_of: Callable[[float], float]
    path: np.ndarray | None
    spacing: np.ndarray
    changes: list[tuple[float, Gait, float]]
    effects: Effects
    params: ControllerParams
    planner: PlannerParams


def _character(job: Job) -> _Character:
    """One rig's part of a simulation."""
    leg_len = float(np.mean(job.info.leg_length))
    origin = job.info.body.origin
    start_yaw = float(np.arctan2(job.info.body.forward[1], job.info.body.forward[0]))
    speed_of = speed_at(job)
    spacing = job.foot_offset.copy()
    spacing[:, 1] += (job.spacing - 1.0) * job.morphology.rest_foot[:, 1]
    if job.path is not None:
        # start along the path when the rig roughly faces it, else turn toward it walking
        heading0 = PathFollower.for_leg(job.path, leg_len).heading_from(origin[:2], speed_of(0.0))[0]
        start_yaw = heading0 if abs(float(wrap_angle(heading0 - start_yaw))) < 0.5 else start_yaw
    # Gait changes at the first frame set the gait the walk starts with; later ones start a
    # transition before the step into their frame. With Auto the changes' speeds still
    # count (speed_at), their gaits do not.
    gait: Gait = job.gait
    changes = []
    for change in job.gait_changes if job.auto_gait is None else ():
        if change.frame_index == 0:
            gait = change.gait
        else:
            changes.append((change.frame_index * job.dt, change.gait, change.transition_time))
    effects = _effects(job)
    auto_physics = job.auto_gait is not None or job.held_auto is not None
    window = _window(job, leg_len)
    params, planner = scaling.scaled_params(leg_len, job.step_height, auto_physics=auto_physics,
                                            window=window)
    return _Character(job.morphology, gait, origin[:2].copy(), start_yaw, speed_of,
                      None if job.path is None else job.path[:, :2], spacing, changes, effects, params,
                      planner)


def _effects(job: Job) -> Effects:
    """Burst progression and the gait randomizer of ``job``."""
    first_gait_set = any(c.frame_index == 0 for c in job.gait_changes) and job.auto_gait is None
    return Effects(progression=job.use_progression,
                   # a Gait Change at the first frame wins over the randomizer's first gait
                   randomize_gait=job.use_gait_randomizer and (job.use_progression or not first_gait_set),
                   cycle_time=job.gait.cycle_time)


def batch_key(job: Job) -> tuple[Any, ...]:
    """What rigs must share to be simulated together (besides their frames and terrain):
    the lift of the terrain (their mean foot height) and the seed of rigs whose effects draw
    random numbers."""
    # The terrain is raised by the rig's mean foot height (``lift``): the core has one terrain
    # per simulation. (Raising every foot by ``Morphology.foot_lift`` over unraised ground
    # instead is not the same walk: the pelvis keeps its height above the ground, not the feet.)
    # The controller's constants differ per character only in what size scaling sets.
    effects = _effects(job)
    return (round(job.lift, 9), job.seed if effects.progression or effects.randomize_gait else None)


def batch_simulation(jobs: Sequence[Job]) -> Simulation:
    """:func:`simulation_inputs` made into a :class:`Simulation`."""
    return Simulation(**simulation_inputs(jobs))


def simulation_inputs(jobs: Sequence[Job]) -> dict[str, Any]:
    """The arguments of the one core simulation of every rig of ``jobs`` (their shared terrain read and at its
    first frame; their frames, seconds per frame and :func:`batch_key` alike): each rig a
    character with its own morphology, gait and gait changes, speeds, heading or path,
    settings, effects and start (its ``phase`` and ``cycle_scale`` already in its gaits, see
    ``crowd.vary``), seeing the others when its Avoid Other Rigs is on."""
    terrain = jobs[0].terrain
    if terrain is None:
        raise RuntimeError("the job's terrain has not been read (generate.read_terrain)")
    if any(job.terrain is not terrain for job in jobs):
        raise RuntimeError("the rigs of one simulation share one terrain (crowd.read_terrain)")
    if len({batch_key(job) for job in jobs}) > 1:
        raise RuntimeError("rigs of different terrain lifts or seeds in one simulation (crowd.batches)")
    chars = [_character(job) for job in jobs]
    dt = jobs[0].dt
    spacing = np.concatenate([c.spacing for c in chars])
    paths = [c.path for c in chars]
    path = None if all(p is None for p in paths) else paths
    base_heading = np.array([job.heading for job in jobs])
    turn_rate = np.array([job.turn_rate for job in jobs])
    step_height = np.array([job.step_height for job in jobs])
    pelvis_physics = np.array([job.use_pelvis_physics for job in jobs])
    single = len(jobs) == 1

    def controls(t: float) -> Controls:
        speed = np.array([c.speed_of(t) for c in chars])
        if single:  # (scalars, as a rig alone always had them)
            return Controls(speed=float(speed[0]), heading=float(base_heading[0] + turn_rate[0] * t),
                            path=path, step_height=float(step_height[0]), spacing=spacing,
                            pelvis_physics=bool(pelvis_physics[0]))
        return Controls(speed=speed, heading=base_heading + turn_rate * t, path=path, step_height=step_height,
                        spacing=spacing, pelvis_physics=pelvis_physics)

    changes = [GaitChange(time, gait, chars=None if single else [i], transition_time=transition)
               for i, c in enumerate(chars) for time, gait, transition in c.changes]
    phases = np.array([job.phase for job in jobs])
    spine = [spine_params(job) if job.morphology.spine is not None else None for job in jobs]
    avoid = [job.use_avoid_others for job in jobs]
    seeds = [job.seed for job, c in zip(jobs, chars, strict=True)
             if c.effects.progression or c.effects.randomize_gait]
    return {
        "env": terrain.environment, "morphologies": [c.morphology for c in chars],
        "gaits": [c.gait for c in chars], "start_xy": np.array([c.start_xy for c in chars]),
        "start_yaw": [c.start_yaw for c in chars], "controls": controls, "gait_changes": changes, "dt": dt,
        "seed": seeds[0] if seeds else jobs[0].seed, "phase": phases if np.any(phases != 0.0) else None,
        "params": chars[0].params if single else [c.params for c in chars],
        "planner": [c.planner for c in chars],
        "spine": spine if any(sp is not None for sp in spine) else None,
        "auto_gait": [job.auto_gait for job in jobs], "effects": [c.effects for c in chars],
        # Avoid Other Rigs: bodies and planted feet of the others kept clear, paths steered
        # around them (core.locomotion.crowd); a rig alone has no one to avoid
        "avoid": avoid if not single and any(avoid) else None,
    }


def run(job: Job, kept: Checkpoints | None = None) -> Iterator[float]:
    """Simulate ``job`` (one core step per frame after the first); yields the fraction done
    (once per frame) and stores its :class:`~.job.RigTracks` in ``job.result``. Meanwhile
    ``job.partial(n)`` gives the first ``n`` frames' tracks (Live Preview writes a frame
    before the rest ran). ``kept``: the states of the rig's last run (Live Preview's), from
    which the frames this job's inputs leave as they were are taken instead of simulated
    again (see :class:`Checkpoints`); it then keeps this run's."""
    return run_all([job], kept)


def run_all(jobs: Sequence[Job], kept: Checkpoints | None = None) -> Iterator[float]:
    """:func:`run` for rigs simulated together (:func:`batch_simulation`): one core step per
    frame moves every rig; each job gets its own tracks."""
    terrain = jobs[0].terrain
    if terrain is None:
        raise RuntimeError("the job's terrain has not been read (generate.read_terrain)")
    n_frames = jobs[0].frames.shape[0]
    terrain.apply_frame(0)
    inputs = simulation_inputs(jobs)
    first = 0
    if kept is None:
        sim = Simulation(**inputs)
    else:
        sim, first = kept.start(inputs, terrain, n_frames)
    for i, job in enumerate(jobs):
        job.partial = functools.partial(_partial_tracks, sim, i)
    for f in range(first + 1):  # (frames taken from the last run: nothing to do)
        yield (f + 1) / n_frames
    for f in range(first + 1, n_frames):
        terrain.apply_frame(f)
        sim.step()
        yield (f + 1) / n_frames
        if kept is not None:  # (after the yield: Live Preview shows a frame before it is kept)
            kept.reached(sim, f)
    res = sim.result()
    for i, job in enumerate(jobs):
        job.result = RigTracks.of(res, i)


#: Frames between two states a :class:`Checkpoints` keeps besides those before each Gait
#: Change, before the current frame and at the last frame (a copy of a wolf's state takes
#: about 0.5-1.5 ms, against 3 ms a step; an edit at a frame not foreseen, a terrain object
#: moved, re-simulates up to this many frames more).
CHECKPOINT_FRAMES = 20

# Parts of a simulation that never change once it is made (the creatures' fixed geometry and
# settings): shared between a simulation and the copies of its states.
_FIXED = (Rig, LegBatch, Morphology, ControllerParams, PlannerParams, SpineParams)


def _digest(value: Any) -> bytes:
    return hashlib.blake2b(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL), digest_size=16).digest()


def step_digests(inputs: dict[str, Any], n_frames: int) -> list[bytes]:
    """What each frame of a simulation made from ``inputs`` (:func:`simulation_inputs`) is
    made from: item 0 digests every argument but the per-step ones (the commands and the
    gait changes), item ``f`` the commands and the gait changes due of the step into frame
    ``f`` (as ``Simulation.step`` takes them). Two simulations on one terrain whose first
    ``k + 1`` items are equal have equal states at frame ``k``: the simulation is a function
    of its arguments and of what each step takes (same code, same process)."""
    controls = inputs["controls"]
    changes = sorted(inputs["gait_changes"], key=lambda g: g.time)
    dt = float(inputs["dt"])
    fixed = {k: v for k, v in inputs.items() if k not in ("env", "controls", "gait_changes")}
    first = controls(0.0)
    try:
        out = [_digest((fixed, first))]
    except (pickle.PicklingError, TypeError, AttributeError):  # (an argument pickle cannot take)
        return [os.urandom(16) for _ in range(n_frames)]  # equal to no other run's: nothing reused
    names = [f.name for f in dataclasses.fields(first)]
    due, due_key = 0, b""
    for f in range(1, n_frames):
        t_end = f * dt  # (Simulation.step: (steps so far + 1) * dt)
        ctl = controls(t_end)
        # (a command that is the very object of the first step's, its foot spacing or path
        # arrays, is in item 0 already)
        values = tuple("=" if getattr(ctl, k) is getattr(first, k) else getattr(ctl, k) for k in names)
        count = sum(1 for c in changes if c.time <= t_end + 1e-12)
        if count != due:
            due, due_key = count, _digest(changes[:count])
        out.append(_digest((values, due_key)))
    return out


class Checkpoints:
    """One rig's simulation as its last run left it, kept by Live Preview to start the next
    run of that rig from: the run's :func:`step_digests`, its states (deep copies of the
    ``Simulation`` at frame 0, every :data:`CHECKPOINT_FRAMES` frames, before each Gait
    Change and before :attr:`current`, and at the last frame) and its recorded frames. A run
    on the same terrain object (the preview's ``TerrainCache`` hands the same one while the
    terrain is unchanged) whose first frames are made from the same inputs starts from the
    latest state among them (an edit of a later Gait Change, one added at the current frame,
    or the range made longer, re-simulates only from there); a run of a cut-short
    regeneration keeps the states it reached. The walk is the same as simulated from frame 0,
    bit for bit."""

    def __init__(self) -> None:
        #: The frame index the next run shows first (Live Preview's current frame).
        self.current = 0
        #: When the next run's terrain is not the kept run's: the world xy bounds ``(m, 4)``
        #: (x0, y0, x1, y1) of what changed between them (None: unknown, nothing is reused).
        self.changed: np.ndarray | None = None
        self.terrain: Any = None
        self.seen = np.empty((0, 4))  # (frames, 4): the bounds of the terrain each step looked at
        self._looks = _Looks(None)  # (every run's and state's terrain: the run's own in it)
        self.digests: list[bytes] = []
        self.states: dict[int, Simulation] = {}
        self.sim: Simulation | None = None
        self._at: set[int] = set()
        self._memo: dict[int, Any] = {}

    def clear(self) -> None:
        self.__init__()  # type: ignore[misc]

    def start(self, inputs: dict[str, Any], terrain: Any, n_frames: int) -> tuple[Simulation, int]:
        """The simulation of ``inputs`` at its latest frame the kept run has (a copy of that
        state), or made anew at frame 0; with that frame index. Keeps this run from now on."""
        digests = step_digests(inputs, n_frames)
        looks = self._looks
        looks.env = inputs["env"]
        looks.take()
        inputs = {**inputs, "env": looks}
        same = 0
        if self.sim is not None and (terrain is self.terrain or self._unseen_change(terrain)):
            for old, new in zip(self.digests, digests, strict=False):
                if old != new:
                    break
                same += 1
            if terrain is not self.terrain:  # only the frames before the first look at what changed
                assert self.changed is not None
                same = min(same, _first_look(self.seen[:same], self.changed, _margin(inputs)))
        kept = {f: s for f, s in self.states.items() if f < same}
        first = max(kept, default=-1)
        seen = self.seen[:first + 1]
        if first < 0:
            sim = Simulation(**inputs)
            first = 0
            kept = {}
            looks.note(sim.last_joints()[..., :2])
            seen = looks.take()[None]
        else:
            assert self.sim is not None
            # (the controls and gait changes equal for the frames kept; the new ones' from here on)
            sim = kept[first].resume(self._memo, self.sim, first + 1, inputs["controls"],
                                     inputs["gait_changes"])
        dt = float(inputs["dt"])
        changes = {round(g.time / dt) - 1 for g in inputs["gait_changes"]}
        self._at = {f for f in (*changes, self.current - 1, n_frames - 1) if 0 < f < n_frames}
        self._memo = _fixed_parts(sim)
        self.terrain, self.digests, self.states, self.sim = terrain, digests, kept, sim
        self.changed = None
        # (the frames not reached yet looked everywhere, as far as the next run knows)
        rest = np.tile([-np.inf, -np.inf, np.inf, np.inf], (n_frames - seen.shape[0], 1))
        self.seen = np.concatenate([seen, rest])
        if first not in kept:
            self._keep(sim, first)
        return sim, first

    def _unseen_change(self, terrain: Any) -> bool:
        """The kept run's terrain and ``terrain`` differ only where :attr:`changed` says, and
        neither moves over the range nor is raised differently."""
        old = self.terrain
        return (self.changed is not None and old is not None and not old.dynamic_index
                and not terrain.dynamic_index and old.z_offset == terrain.z_offset)

    def reached(self, sim: Simulation, f: int) -> None:
        """``sim`` is at frame ``f``: note where it looked, keep a copy of its state if it is
        one to keep."""
        if f > 0:
            # (the ground under the frame's feet is asked when the result is made)
            self._looks.note(sim.last_joints()[..., :2])
            self.seen[f] = self._looks.take()
        if (f % CHECKPOINT_FRAMES == 0 or f in self._at) and f not in self.states:
            self._keep(sim, f)

    def _keep(self, sim: Simulation, f: int) -> None:
        self.states[f] = sim.snapshot(self._memo)  # (its frames taken from the run when resumed)


def _fixed_parts(sim: Simulation) -> dict[int, Any]:
    """A ``copy.deepcopy`` memo that shares the terrain and the fixed parts of ``sim``
    (:data:`_FIXED`, among its own and its controller's attributes) with its copies."""
    env = sim.env
    memo: dict[int, Any] = {id(env): env}
    if isinstance(env, _Looks):
        memo[id(env.env)] = env.env
    for value in (*vars(sim).values(), *vars(sim.controller).values()):
        items = value if isinstance(value, list | tuple) else (value,)
        for item in items:
            if isinstance(item, _FIXED):
                memo[id(item)] = item
    return memo


def _partial_tracks(sim: Simulation, char: int, n: int) -> RigTracks:
    return RigTracks.of(sim.result(n), char)


def auto_track(job: Job) -> Any:
    """What Auto chose over a finished job's frames, as ``gait.rig_gait.AutoTrack``."""
    from ..gait import rig_gait

    res = job.result
    params = job.auto_gait
    if res is None or params is None or res.speed is None or res.auto_band is None:
        raise RuntimeError("the simulation has not run with Auto gait")
    return rig_gait.AutoTrack(job.frames.copy(), res.speed.copy(), res.auto_band.copy(), params.names,
                              rig_gait.boundary_speeds(params), res.disk_start.copy(),
                              np.asarray(res.disk_duration).copy(), res.needle.copy(), True)


def world_tracks(job: Job) -> tuple[np.ndarray, list[np.ndarray]]:
    """The body frames ``(F, 4, 4)`` and per-leg world joints ``(F, k + 1, 3)`` of a finished job."""
    res = job.result
    if res is None:
        raise RuntimeError("the simulation has not run")
    joints = [res.joints[:, i, : len(leg.bones) + 1] for i, leg in enumerate(job.info.legs)]
    return res.body, joints


def spine_tracks(job: Job) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The frames the legs hang from ``(F, n_legs, 3, 3)`` and, with a spine, its bones'
    rotations ``(F, J - 1, 3, 3)`` and joints ``(F, J, 3)`` (else None) of a finished job:
    what ``rig.solve_pose`` takes as ``leg_frames``, ``spine_rotation``, ``spine_joints``."""
    res = job.result
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


class _Looks:
    """A simulation's terrain (``core.world.terrain.Environment``) noting the world xy bounds
    of what it is asked (points, planning windows, rectangles) until :meth:`take`n. An
    answer depends only on the scene inside what is asked (a window's cells on the scene
    over their own bounds), so a run that never looked at a part of the scene walks the
    same without it."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self._lo = np.full(2, np.inf)
        self._hi = np.full(2, -np.inf)

    def __getattr__(self, name: str) -> Any:
        if name in ("env", "_lo", "_hi") or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.env, name)

    def __deepcopy__(self, memo: dict[int, Any]) -> _Looks:
        return self  # (the states of a run share it: it is the terrain of the run resumed)

    def note(self, xy: Any, pad: Any = None) -> None:
        """Note the points ``xy`` ``(n, 2)`` (``pad``: ``(n, 1)``, the half sides of squares
        about them)."""
        p = (xy if type(xy) is np.ndarray and xy.ndim == 2 and xy.shape[1] == 2
             else np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        if p.shape[0]:  # (a point that is not a number asks nothing: fmin and fmax pass it over)
            lo, hi = (p, p) if pad is None else (p - pad, p + pad)
            self._lo = np.fmin(self._lo, np.fmin.reduce(lo, axis=0))
            self._hi = np.fmax(self._hi, np.fmax.reduce(hi, axis=0))

    def take(self) -> np.ndarray:
        """``(4,)`` x0, y0, x1, y1 of what was asked since the last take (empty: inf, -inf)."""
        out = np.concatenate([self._lo, self._hi])
        self._lo = np.full(2, np.inf)
        self._hi = np.full(2, -np.inf)
        return out

    def height_at(self, xy: Any) -> Any:
        self.note(xy)
        return self.env.height_at(xy)

    def forbidden_at(self, xy: Any) -> Any:
        self.note(xy)
        return self.env.forbidden_at(xy)

    def moving_near(self, lo: Any, hi: Any) -> Any:
        self.note(lo)
        self.note(hi)
        return self.env.moving_near(lo, hi)

    def windows(self, centers_xy: Any, params: Any = None) -> Any:
        ctr = np.asarray(centers_xy, dtype=np.float64).reshape(-1, 2)
        plist = [params] * ctr.shape[0] if params is None or not isinstance(params, list | tuple) else params
        # (a window's cells reach half its side and a cell of margin from its centre, rounded)
        half = np.array([(0.5 * p.n_cells + 2.0) * p.cell if p is not None else np.inf for p in plist])
        self.note(ctr, half[:, None])
        return self.env.windows(centers_xy, params)


def _margin(inputs: dict[str, Any]) -> float:
    """How far beyond what changed a look may be affected: two planning cells."""
    params = inputs["params"]
    cells = [p.window_cell for p in (params if isinstance(params, list) else [params])]
    return 2.0 * float(max(cells))


def _first_look(seen: np.ndarray, changed: np.ndarray, margin: float) -> int:
    """The first frame among ``seen`` ``(F, 4)`` (each frame's looks' bounds) whose looks
    come within ``margin`` of a box of ``changed`` ``(m, 4)``; F when none does."""
    if seen.shape[0] == 0:
        return 0
    c = np.asarray(changed, dtype=np.float64).reshape(-1, 4)
    hit = ((seen[:, None, 0] <= c[None, :, 2] + margin) & (seen[:, None, 2] >= c[None, :, 0] - margin)
           & (seen[:, None, 1] <= c[None, :, 3] + margin) & (seen[:, None, 3] >= c[None, :, 1] - margin))
    hits = np.flatnonzero(hit.any(axis=1))
    return int(hits[0]) if hits.size else int(seen.shape[0])
