# SPDX-License-Identifier: GPL-3.0-or-later
"""The system loop (thesis §3.1, §3.6): many characters stepped together, per-frame arrays out.

``Simulation`` wires the controller (``locomotion.controller.Controller``: gait manager, feet,
planner, pelvis, pseudo-physics, IK) to user-level commands:

- ``Controls``: speed, heading *or* a polyline path to follow, step height, per-leg spacing
  (relative foot positions), pelvis physics on/off, IK on/off; constant, or a function of
  time for scheduled changes;
- ``GaitChange``: a new gait for some characters at a given time, reached over a
  transition time (thesis §3.3); a change of speed with it is a ``SpeedRamp`` of
  ``speed_schedule``;
- ``Effects``: per character, burst progression and the gait randomizer (thesis §4.3);
- creature-size scaling of the controller's constants: ``scaling.scaled_params``.

Frame 0 is settled by a vanishing step (``1e-9 dt``) before it is recorded: the controller's
initial pose does not yet keep the hips within reach of the feet (its reach guard runs in a
step), and the step moves nothing else.

``Simulation.run`` returns a ``SimResult``: pelvis transforms, every leg joint's world
position, leg-plane normals, joint angles, contact flags, chosen and preferred footprints,
the needles and disks, the spine joints and bone rotations of characters walking with a
flexible spine (``spine=SpineParams(...)``, thesis §4.2), and per-step planner statistics
and timings. Frame 0 is the state
before the first step; frame ``f`` is after ``f`` steps of ``dt`` seconds, and the step into
it follows the controls of its time ``f dt`` (with the gait changes due by then).

The result is deterministic: the same inputs (and ``seed``, used for ``phase="random"`` and
the ``Effects``) give identical arrays.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .. import metrics as mx
from ..geometry import rotation_matrices, wrap_angle
from ..world.terrain import NO_SURFACE, ROLE_AVOID, Environment
from . import crowd
from .autogait import AutoGait, AutoGaitParams
from .controller import Controller
from .footprints import PlannerParams
from .gait import Gait
from .morphology import LegBatch, Morphology
from .progression import ProgressionParams, ProgressionState, effects_step, initial_gaits
from .spine import SpineParams
from .state import Phase
from .types import ControllerParams, PlannerLOD, StepControls, StepStats

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Burst progression's settings (its top speed is each character's commanded speed).
_BURSTS = ProgressionParams(max_speed=0.0)
#: A path follower's look-ahead and the distance over which it stops, in leg lengths.
PATH_LOOKAHEAD = 1.0
PATH_STOP = 0.5
#: ... or its look-ahead, when that is farther: where the character will be this many
#: seconds on at its commanded speed (a galloping creature aims past the next bend)
PATH_LOOKAHEAD_TIME = 0.5


@dataclass(frozen=True)
class Controls:
    """What the user asks for; scalars apply to every character, arrays are ``(C,)``.

    - ``speed``: m/s along the heading (or the path).
    - ``heading``: radians from world +X, counter-clockwise; None keeps the start heading.
    - ``path``: one ``(k, 2)`` world polyline per character (or None for a character that
      uses ``heading``); the character walks along it and stops at its end.
    - ``step_height``: metres of clearance of a swinging foot.
    - ``spacing``: ``(N, 2)`` body-frame xy offset of each foot from its rest position
      (thesis figure 3.7); None for none.
    - ``pelvis_physics``: pogo-particle pelvis height (thesis §4.1).
    - ``ik``: solve the legs (LOD: False for characters nobody sees).
    """

    speed: float | npt.ArrayLike = 0.3
    heading: float | npt.ArrayLike | None = None
    path: Sequence[npt.ArrayLike | None] | None = None
    step_height: float | npt.ArrayLike = 0.05
    spacing: npt.ArrayLike | None = None
    pelvis_physics: bool | npt.ArrayLike = False
    ik: bool | npt.ArrayLike = True


@dataclass(frozen=True)
class GaitChange:
    """At ``time`` seconds, start moving characters ``chars`` (None: all) toward ``gait``
    (one ``Gait`` for all of them, or one per character) over ``transition_time`` seconds."""

    time: float
    gait: Gait | Sequence[Gait]
    chars: Sequence[int] | None = None
    transition_time: float = 1.0


@dataclass(frozen=True)
class SpeedRamp:
    """From ``time`` seconds, the commanded speed goes evenly to ``speed`` m/s over
    ``duration`` seconds, from whatever it was when the ramp began (0: at once)."""

    time: float
    duration: float
    speed: float


def speed_schedule(speed: float, ramps: Sequence[SpeedRamp]) -> Callable[[float], float]:
    """The commanded speed at each time ``t``: ``speed``, then each ramp (in time order) in
    turn."""
    steps: list[tuple[float, float, float, float]] = []  # start, duration, from, to

    def speed_at(t: float) -> float:
        v = speed
        for t0, duration, v0, v1 in steps:
            if t >= t0:
                v = v1 if duration <= 0.0 else v0 + (v1 - v0) * min((t - t0) / duration, 1.0)
        return v

    for ramp in sorted(ramps, key=lambda r: r.time):
        steps.append((ramp.time, ramp.duration, speed_at(ramp.time), ramp.speed))  # noqa: PERF401 (reads steps)
    return speed_at


@dataclass(frozen=True)
class Effects:
    """Burst progression and the gait randomizer of one character (thesis §4.3).

    ``progression``: the character walks in bursts up to its commanded speed (standing
    still at first); ``randomize_gait``: with the progression, each stall draws a new
    random gait, reached over half a cycle; without it, the character starts with one random
    gait (left out with Gait: Auto, which chooses the gait itself); ``cycle_time``: the
    random gaits' cycle (s)."""

    progression: bool = False
    randomize_gait: bool = False
    cycle_time: float = 1.0


@dataclass(frozen=True, eq=False)
class SimResult:
    """Per-frame arrays of a run (``F`` frames, ``C`` characters, ``N`` legs, ``s`` segments).

    - ``time (F,)``; ``dt``.
    - ``pelvis_position (F, C, 3)``, ``pelvis_rotation (F, C, 3, 3)`` (body to world),
      ``yaw``, ``pitch``, ``roll`` ``(F, C)``.
    - ``joints (F, N, s + 1, 3)`` hip, inner joints, end effector (rows past a leg's end
      repeat its end effector); ``plane_normal (F, N, 3)``; ``angles (F, N, s)``.
    - ``foot (F, N, 3)``: where the controller put each foot (the IK target).
    - ``contact (F, N)``: planted; ``forced (F, N)``: in a forced step (support moved);
      ``plan_failed (F, N)``: a swing the planner could not serve (the foot stayed down).
    - ``ground (F, N)``: the highest surface under each end effector at that frame (moving
      obstacles where they were then), for penetration checks.
    - ``footprint (F, N, 3)``: the chosen footprint of each foot's current or last swing;
      ``preferred (F, N, 3)``: the controller's preferred footprint for it.
    - ``needle (F, C)``, ``phase_step (F, C)`` (needle advance of the step into the frame),
      ``phase_rate (F, C)`` (the needle's speed, cycles/s: the controller speeds it up when
      the stride would be too long), ``disk_start``, ``disk_duration`` ``(F, N)``.
    - ``speed (F, C)``: the speed asked of the controller (m/s, after a path's end and burst
      progression); ``auto_band (F, C)``: Gait: Auto's gait index (-1 without Auto).
    - ``ik_error (F, N)``: distance from each end effector to its target.
    - ``leg_frame (F, N, 3, 3)``: body-to-world rotation of what each leg hangs from (the
      pelvis, or its spine node or carrier bone).
    - ``spine_joints (F, C, J, 3)``: world spine joints, head first (``J`` the longest spine;
      rows past a spine's end repeat its last joint; characters without a spine hold their
      pelvis position); ``spine_rotation (F, C, J - 1, 3, 3)``: each spine bone's rotation
      from its rest (body-frame) direction to the world (identity where there is no bone);
      ``spine_n_joints (C,)``: joints of each character's spine (0 without one).
    - ``stats``: per-step counters ``(F,)`` (``n_plans``, ``n_failed``, ``n_couples``,
      ``n_paths``, ``n_windows``, ``n_replans``, ``n_forced``, ``n_relaxed``, ``n_fallback``,
      ``n_bent``);
      ``seconds``: per-phase times
      ``(F,)`` (``maps``, ``planning``, ``ik``, ``physics``, ``spine``, ``rest``).
    """

    dt: float
    legs: LegBatch
    time: FloatArray
    pelvis_position: FloatArray
    pelvis_rotation: FloatArray
    yaw: FloatArray
    pitch: FloatArray
    roll: FloatArray
    joints: FloatArray
    plane_normal: FloatArray
    angles: FloatArray
    foot: FloatArray
    contact: BoolArray
    forced: BoolArray
    plan_failed: BoolArray
    ground: FloatArray
    footprint: FloatArray
    preferred: FloatArray
    needle: FloatArray
    phase_step: FloatArray
    phase_rate: FloatArray
    speed: FloatArray
    auto_band: IntArray
    ik_error: FloatArray
    disk_start: FloatArray
    disk_duration: FloatArray
    leg_frame: FloatArray
    spine_joints: FloatArray
    spine_rotation: FloatArray
    spine_n_joints: IntArray
    stats: dict[str, IntArray] = field(default_factory=dict)
    seconds: dict[str, FloatArray] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    @property
    def leg_char(self) -> IntArray:
        return self.legs.leg_char

    @property
    def end_effector(self) -> FloatArray:
        """``(F, N, 3)`` end-effector positions from the joints."""
        return self.joints[:, np.arange(self.legs.n_legs), self.legs.n_segments]

    @property
    def hips(self) -> FloatArray:
        return self.joints[:, :, 0]


class PathFollower:
    """Heading toward a look-ahead point on a polyline ``(k, 2)``; speed to 0 at its end.

    The heading aims ``lookahead`` metres further along the path than the point of the path
    nearest to the character: at first the nearest of the whole path (a character starting
    beside the middle of a path joins it there), then the nearest among those not behind its
    progress so far and at most two look-aheads beyond it (progress never goes back, so a
    path crossing itself is followed in order); over the last ``stop_distance`` the speed
    eases to 0 as the square root of the distance left (stopping in finite time; a linear
    ramp only approaches the end).

    ``lookahead_time``: at a speed where the character covers more than ``lookahead`` in that
    many seconds, it looks that far ahead instead (``command``'s ``speed``).

    Generate Locomotion's follower used to look ``max(leg, speed / 2)`` ahead of the nearest
    point of the whole path and stop dead ``0.05`` leg before the end; walking a U-turn and
    an S-curve (spider, wolf, ant) this one ends 0.001-0.003 leg from the path's end
    instead of 0.005-0.04, as close to the path or closer, with the same motion figures."""

    def __init__(self, points: npt.ArrayLike, lookahead: float, stop_distance: float,
                 lookahead_time: float = 0.0) -> None:
        self.source = np.array(points, dtype=np.float64)
        pts = self.source[..., :2].reshape(-1, 2)
        if pts.shape[0] < 2:
            raise ValueError("a path needs at least two points")
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        keep = np.concatenate([[True], seg > 1e-12])
        pts = pts[keep]
        if pts.shape[0] < 2:
            raise ValueError("the path has no length")
        self.points = pts
        self.seg = np.diff(pts, axis=0)
        self.seg_len = np.linalg.norm(self.seg, axis=1)
        self.arc = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.length = float(self.arc[-1])
        self.lookahead = lookahead
        self.lookahead_time = lookahead_time
        self.stop_distance = stop_distance
        self.s: float | None = None  # progress along the path (m), None before the first command

    @classmethod
    def for_leg(cls, points: npt.ArrayLike, leg: float) -> PathFollower:
        """The follower of a character with legs ``leg`` metres long: ``PATH_LOOKAHEAD``,
        ``PATH_STOP`` and ``PATH_LOOKAHEAD_TIME``."""
        return cls(points, PATH_LOOKAHEAD * leg, PATH_STOP * leg, PATH_LOOKAHEAD_TIME)

    def start_heading(self) -> float:
        d = self.points[1] - self.points[0]
        return float(np.arctan2(d[1], d[0]))

    def heading_from(self, xy: FloatArray, speed: float = 0.0) -> tuple[float, float]:
        """``(heading, distance left along the path)`` for a character at ``xy`` ``(2,)``
        walking at ``speed`` (m/s), without moving on along the path."""
        ahead = max(self.lookahead, self.lookahead_time * speed)
        p, seg, seg_len, cum = self.points, self.seg, self.seg_len, self.arc
        t = np.clip(np.einsum("ij,ij->i", xy[None] - p[:-1], seg) / np.maximum(seg_len ** 2, 1e-18), 0.0, 1.0)
        near = p[:-1] + t[:, None] * seg
        dist = np.linalg.norm(near - xy[None], axis=1)
        s_proj = cum[:-1] + t * seg_len
        if self.s is None:
            s_here = float(s_proj[int(np.argmin(dist))])
        else:
            window = (s_proj >= self.s - 1e-9) & (s_proj <= self.s + 2.0 * ahead + 1e-9)
            k = int(np.flatnonzero(window)[np.argmin(dist[window])]) if np.any(window) else -1
            s_here = max(self.s, float(s_proj[k])) if k >= 0 else self.s
        s_goal = min(s_here + ahead, cum[-1])
        j = int(np.clip(np.searchsorted(cum, s_goal) - 1, 0, len(seg) - 1))
        u = (s_goal - cum[j]) / max(seg_len[j], 1e-18)
        goal = p[j] + u * seg[j]
        d = goal - xy
        if np.linalg.norm(d) < 1e-9:
            d = seg[-1]
        return float(np.arctan2(d[1], d[0])), float(cum[-1] - s_here)

    def command(self, xy: FloatArray, speed: float = 0.0) -> tuple[float, float]:
        """``(heading, speed factor)`` for a character at ``xy`` ``(2,)`` asked to walk at
        ``speed`` (m/s)."""
        heading, left = self.heading_from(xy, speed)
        self.s = self.length - left
        factor = float(np.sqrt(np.clip(left / max(self.stop_distance, 1e-9), 0.0, 1.0)))
        return heading, 0.0 if left < 1e-3 * self.stop_distance else factor


def _per_char(value: npt.ArrayLike, c: int, dtype: type[np.generic]) -> npt.NDArray[Any]:
    """A fresh ``(c,)`` array of ``value`` (a scalar for all, or one per character) as
    ``dtype``: ``np.broadcast_to(...).copy()`` without its cost."""
    out = np.empty(c, dtype=dtype)
    out[...] = np.asarray(value, dtype=dtype)
    return out


class Simulation:
    """Many characters walking in one environment.

    ``morphologies``: one per character; ``gaits``: one per character (or one for all);
    ``start_xy``: ``(C, 2)`` initial pelvis ground positions (default: the start of each
    path, else the origin); ``start_yaw``: ``(C,)`` or scalar (default: along the path);
    ``controls``: ``Controls`` or ``f(time) -> Controls``; ``gait_changes``: scheduled
    ``GaitChange``s; ``phase``: ``(C,)`` initial needle phases, ``"random"`` (seeded by
    ``seed``) or None (all 0); ``params``: one ``ControllerParams`` for all characters, or
    one per character (each creature's ``scaling.scaled_params``) differing only in
    ``rig.PER_CHARACTER`` (else a ``ValueError`` names the field); ``planner``: optional
    per-character ``PlannerParams``;
    ``lod``: optional per-character ``PlannerLOD`` (thesis §3.7); ``spine``: ``SpineParams``
    for every character (or one per character, None for a rigid body) walking with the
    flexible spine of its morphology (``Morphology.with_spine``; thesis §4.2, §4.4);
    ``auto_gait``: ``AutoGaitParams`` per character (None: its gait as given) whose gait,
    stride and cycle follow its commanded speed (``autogait.AutoGait``; its starting gait
    replaces ``gaits`` and scheduled ``GaitChange``s leave it alone); ``effects``: per
    character ``Effects`` (burst progression, gait randomizer; None: none), drawn from
    ``seed``; ``avoid``: per character, whether it sees the others (``crowd``: their bodies
    and feet are obstacles for its feet, and it steers around them; None: none does). A
    character following a path (``PathFollower``) looks one mean leg length
    ahead (or half a second of its commanded speed, when that is farther) and eases to a
    stop over the last half leg.
    """

    def __init__(
        self,
        env: Environment,
        morphologies: Sequence[Morphology],
        gaits: Gait | Sequence[Gait],
        *,
        start_xy: npt.ArrayLike | None = None,
        start_yaw: npt.ArrayLike | None = None,
        controls: Controls | Callable[[float], Controls] | None = None,
        gait_changes: Sequence[GaitChange] = (),
        dt: float = 1.0 / 30.0,
        phase: npt.ArrayLike | Literal["random"] | None = None,
        seed: int = 0,
        params: ControllerParams | Sequence[ControllerParams] | None = None,
        planner: Sequence[PlannerParams | None] | None = None,
        lod: Sequence[PlannerLOD | None] | None = None,
        spine: SpineParams | Sequence[SpineParams | None] | None = None,
        auto_gait: Sequence[AutoGaitParams | None] | None = None,
        effects: Sequence[Effects | None] | None = None,
        avoid: Sequence[bool] | None = None,
    ) -> None:
        if not dt > 0.0:
            raise ValueError("dt must be positive")
        self.env = env
        self.dt = float(dt)
        self.legs = LegBatch.stack(morphologies)
        c = self.legs.n_chars
        gait_list = [gaits] * c if isinstance(gaits, Gait) else list(gaits)
        if len(gait_list) != c:
            raise ValueError(f"{len(gait_list)} gaits for {c} characters")
        self._controls = controls if controls is not None else Controls()
        first = self._controls(0.0) if callable(self._controls) else self._controls
        self._followers: list[PathFollower | None] = [None] * c
        leg_len = np.bincount(self.legs.leg_char, weights=self.legs.leg_length, minlength=c) / np.bincount(
            self.legs.leg_char, minlength=c
        )
        self._leg_len = leg_len
        if first.path is not None:
            self._set_paths(first.path)
        xy = np.zeros((c, 2))
        yaw = np.zeros(c)
        for i, f in enumerate(self._followers):
            if f is not None:
                xy[i] = f.points[0]
                yaw[i] = f.start_heading()
        if start_xy is not None:
            xy = np.asarray(start_xy, dtype=np.float64).reshape(c, 2).copy()
        if start_yaw is not None:
            yaw = np.broadcast_to(np.asarray(start_yaw, dtype=np.float64), (c,)).copy()
        elif first.heading is not None:
            yaw = np.where(
                [f is None for f in self._followers],
                np.broadcast_to(np.asarray(first.heading, dtype=np.float64), (c,)),
                yaw,
            )
        if isinstance(phase, str):
            if phase != "random":
                raise ValueError("phase must be an array, 'random' or None")
            phase_arr = np.random.default_rng(seed).uniform(0.0, 1.0, c)
        else:
            phase_arr = (
                np.zeros(c)
                if phase is None
                else np.broadcast_to(np.asarray(phase, dtype=np.float64), (c,)).copy()
            )
        self._start_yaw = yaw.copy()
        self._held_heading: FloatArray | None = None
        self._changes = sorted(gait_changes, key=lambda g: g.time)
        self._next_change = 0
        auto_list = list(auto_gait) if auto_gait is not None else [None] * c
        if avoid is not None and len(avoid) != c:
            raise ValueError(f"{len(avoid)} avoid switches for {c} characters")
        self._init_effects(effects, auto_list, gait_list, seed)
        step0 = self._resolve(first, xy, yaw)
        if self._prog_chars.size:  # bursts start standing still
            step0.speed[self._prog_chars] = 0.0
        self.auto_gait = AutoGait(auto_list, step0.speed)
        gait_list = self.auto_gait.gaits(gait_list)
        self.controller = Controller(
            env,
            self.legs,
            gait_list,
            xy,
            yaw,
            step0,
            phase=phase_arr,
            params=params,
            planner=planner,
            lod=lod,
            spine=[spine] * c if isinstance(spine, SpineParams) else spine,
            avoid=avoid,
        )
        self._steered: FloatArray | None = None
        self._offset = np.zeros(c)  # steering's turn from the commanded heading (rad)
        self.time = 0.0
        self._n_steps = 0
        self._frames: list[dict[str, npt.NDArray[np.generic]]] = []
        self._leg_rows = np.arange(self.legs.n_legs)
        self._stats: list[StepStats] = []
        # The controller's initial pose does not yet keep the hips within reach of the feet
        # (its reach guard runs in a step): a vanishing step settles frame 0, moving nothing.
        stats0 = self.controller.step(1e-9 * self.dt, step0)
        self._speed = step0.speed.copy()
        self._record(stats0)

    def _init_effects(self, effects: Sequence[Effects | None] | None, auto: Sequence[AutoGaitParams | None],
                      gaits: list[Gait], seed: int) -> None:
        """Burst progression's state and the randomizer's first gaits (into ``gaits``)."""
        c = self.legs.n_chars
        eff = list(effects) if effects is not None else [None] * c
        if len(eff) != c:
            raise ValueError(f"{len(eff)} effects for {c} characters")
        self._effects = eff
        self._rng = np.random.default_rng(seed)
        prog = [i for i, e in enumerate(eff) if e is not None and e.progression]
        self._prog_chars = np.array(prog, dtype=np.int64)
        # Gait: Auto chooses the gait itself: no randomizer for its characters.
        self._randomize: BoolArray = np.array(
            [e is not None and e.randomize_gait and a is None for e, a in zip(eff, auto, strict=True)],
            dtype=np.bool_)
        n_legs = np.bincount(self.legs.leg_char, minlength=c)
        self._prog_legs = [int(n_legs[i]) for i in prog]
        self._prog_state = (ProgressionState.start(len(prog), _BURSTS, self._rng) if prog else None)
        # Thesis §4.3: without stalls the randomizer only draws the gait a character starts with.
        alone = [i for i in range(c) if self._randomize[i] and i not in prog]
        if alone:
            drawn = initial_gaits([int(n_legs[i]) for i in alone], self._rng)
            for k, i in enumerate(alone):
                e = eff[i]
                assert e is not None
                gaits[i] = drawn[k].to_gait(e.cycle_time, "Random gait")

    def _progress(self, speed: FloatArray) -> None:
        """Burst progression of one step on the commanded ``speed`` ``(C,)`` (in place); a
        stall of a character with the randomizer starts its transition to a new random gait."""
        if self._prog_state is None:
            return
        idx = self._prog_chars
        self._prog_state, fx = effects_step(self._prog_state, _BURSTS, self.dt, self._rng,
                                            self._prog_legs, randomize_gait=self._randomize[idx],
                                            max_speed=np.maximum(speed[idx], 0.0))
        speed[idx] = fx.progression.speed
        for k, new in sorted(fx.new_gaits.items()):
            e = self._effects[int(idx[k])]
            assert e is not None
            self.controller.gait.start_transition([int(idx[k])], [new.to_gait(e.cycle_time, "Random gait")],
                                                  0.5 * e.cycle_time)

    # ---------------------------------------------------------------- controls
    def _set_paths(self, paths: Sequence[npt.ArrayLike | None]) -> None:
        c = self.legs.n_chars
        if len(paths) != c:
            raise ValueError(f"{len(paths)} paths for {c} characters")
        for i, pts in enumerate(paths):
            if pts is None:
                self._followers[i] = None
                continue
            arr = np.asarray(pts, dtype=np.float64)
            f = self._followers[i]
            # the same path again keeps its follower (and the progress along it)
            if f is None or f.source.shape != arr.shape or not np.array_equal(f.source, arr):
                self._followers[i] = PathFollower.for_leg(arr, float(self._leg_len[i]))

    def _resolve(self, ctl: Controls, xy: FloatArray, yaw: FloatArray) -> StepControls:
        c = self.legs.n_chars
        n = self.legs.n_legs
        speed = _per_char(ctl.speed, c, np.float64)
        if ctl.heading is None:
            # no heading asked: keep the last one (the start heading at first)
            heading = (self._start_yaw if self._held_heading is None else self._held_heading).copy()
        else:
            heading = _per_char(ctl.heading, c, np.float64)
        if ctl.path is not None:
            self._set_paths(ctl.path)
        for i, f in enumerate(self._followers):
            if f is not None:
                h, factor = f.command(xy[i], float(speed[i]))
                heading[i] = h
                speed[i] *= factor
        self._held_heading = heading.copy()
        spacing = (
            np.zeros((n, 2))
            if ctl.spacing is None
            else np.asarray(ctl.spacing, dtype=np.float64).reshape(n, 2)
        )
        return StepControls(
            speed=speed,
            # (not wrapped: the controller turns by wrapped differences)
            heading=heading,
            step_height=_per_char(ctl.step_height, c, np.float64),
            spacing=spacing,
            pelvis_physics=_per_char(ctl.pelvis_physics, c, np.bool_),
            ik=_per_char(ctl.ik, c, np.bool_),
        )

    # ---------------------------------------------------------------- stepping
    def step(self, controls: Controls | None = None) -> StepStats:
        """One step of ``dt``; ``controls`` overrides the simulation's own for this step.

        The step leads to the frame of time ``t = time + dt``: its controls are those of
        ``t`` and the gait changes due by ``t`` begin before it (so a frame's pose follows
        the commands of its own time)."""
        t_end = (self._n_steps + 1) * self.dt
        ctl_user = (
            controls
            if controls is not None
            else (self._controls(t_end) if callable(self._controls) else self._controls)
        )
        ctrl = self.controller
        # the order of the shell's loop that Generate Locomotion's results were made with:
        # commands (a path's end), bursts and their new gaits, scheduled gait changes, Auto
        step_ctl = self._resolve(ctl_user, ctrl.pos[:, :2], ctrl.yaw)
        self._progress(step_ctl.speed)
        while (
            self._next_change < len(self._changes)
            and self._changes[self._next_change].time <= t_end + 1e-12
        ):
            change = self._changes[self._next_change]
            chars = list(range(self.legs.n_chars)) if change.chars is None else list(change.chars)
            g = [change.gait] * len(chars) if isinstance(change.gait, Gait) else list(change.gait)
            manual = [k for k, ch in enumerate(chars) if self.auto_gait.params[ch] is None]
            if manual:
                ctrl.gait.start_transition([chars[k] for k in manual], [g[k] for k in manual],
                                           change.transition_time)
            self._next_change += 1
        if ctrl.avoid.any():
            step_ctl = self._steer(step_ctl)
        self.auto_gait.update(ctrl.gait, step_ctl.speed)
        self._speed = step_ctl.speed.copy()
        stats = ctrl.step(self.dt, step_ctl)
        self._n_steps += 1
        self.time = self._n_steps * self.dt  # (not a running sum: no drift over long runs)
        self._record(stats)
        return stats

    def _steer(self, step_ctl: StepControls) -> StepControls:
        """The commanded headings and speeds of characters that avoid the others, steered
        around them (``crowd.steer``; the user's commands stay the preferred ones)."""
        ctrl = self.controller
        velocity = self._speed[:, None] * np.stack([np.cos(ctrl.yaw), np.sin(ctrl.yaw)], axis=1)
        heading, speed = crowd.steer(ctrl.disc_centers(), ctrl.discs[1], velocity, step_ctl.heading,
                                     step_ctl.speed, ctrl.avoid, self._steered)
        # the turn away from the commanded heading is taken at once but given back no faster
        # than the body turns (each jump of the commanded heading re-plans the swinging feet)
        limit = ctrl.params.max_turn_rate * self.dt
        offset = wrap_angle(heading - step_ctl.heading)
        back = (np.abs(offset) < np.abs(self._offset)) & (offset * self._offset >= 0.0)
        self._offset = np.where(back, self._offset + np.clip(offset - self._offset, -limit, limit), offset)
        heading = step_ctl.heading + self._offset
        self._steered = speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
        return replace(step_ctl, heading=heading, speed=speed)

    def run(self, n_steps: int, on_step: Callable[[Simulation], None] | None = None) -> SimResult:
        """Run ``n_steps`` steps (calling ``on_step(self)`` before each, e.g. to move
        obstacles) and return every frame recorded so far."""
        for _ in range(int(n_steps)):
            if on_step is not None:
                on_step(self)
            self.step()
        return self.result()

    def _record(self, stats: StepStats) -> None:
        """Keep this frame. What the frames give at once is left to :meth:`result`: the body
        rotations (from yaw, pitch and roll), the contacts (from the feet's phases), the
        needle's steps and, over ground that never moves, the ground under the feet (one
        point query for every frame)."""
        ctrl = self.controller
        res = ctrl.ik_result
        assert res is not None
        frame = {
            "pos": ctrl.pos.copy(),
            "yaw": ctrl.yaw.copy(),
            "pitch": ctrl.pitch.copy(),
            "roll": ctrl.roll.copy(),
            "joints": res.joints.copy(),
            "normal": res.plane_normal.copy(),
            "angles": res.angles.copy(),
            "foot": ctrl.ik_targets(),
            "phase": ctrl.feet.phase.copy(),
            "footprint": ctrl.target.copy(),
            "preferred": ctrl.preferred.copy(),
            "needle": ctrl.gait.needle.copy(),
            "phase_rate": ctrl.gait.rate(),
            "speed": self._speed.copy(),
            "auto_band": np.array(self.auto_gait.band, dtype=np.int64),
            "ik_error": res.error.copy(),
            "disk_start": ctrl.gait.disk_start.copy(),
            "disk_duration": ctrl.gait.disk_duration.copy(),
            "leg_frame": ctrl.leg_rotations(),
            "spine_joints": ctrl.spine_joints(),
            "spine_rotation": ctrl.spine_rotations(),
        }
        end_xy = res.joints[self._leg_rows, self.legs.n_segments, :2]
        if self.env.dynamic:  # the ground under the feet now: it moves
            frame["ground"] = self.env.height_at(end_xy)
        else:
            frame["end_xy"] = end_xy
        self._frames.append(frame)
        self._stats.append(stats)

    @property
    def n_frames(self) -> int:
        """Frames recorded so far."""
        return len(self._frames)

    def last_joints(self) -> npt.NDArray[np.float64]:
        """The joints of the last frame recorded (``joints`` of :meth:`result`'s frame): the
        recorded array itself, read it without writing to it."""
        return self._frames[-1]["joints"]  # type: ignore[return-value]

    def snapshot(self, memo: dict[int, Any]) -> Simulation:
        """The state at the current frame, to :meth:`resume` a run from later: a deep copy
        without the frames recorded so far (the run that keeps them hands them back);
        ``memo``: objects the copy shares with this simulation, as ``copy.deepcopy`` takes
        (its terrain, the creatures' fixed geometry). What is shared is not kept: a terrain
        whose boxes move is set for each frame by the caller (as the scene's terrain is),
        both in the run the snapshot comes from and in the run resumed from it."""
        frames, stats = self._frames, self._stats
        self._frames, self._stats = [], []
        try:
            return copy.deepcopy(self, dict(memo))
        finally:
            self._frames, self._stats = frames, stats

    def resume(self, memo: dict[int, Any], record: Simulation, n_frames: int,
               controls: Controls | Callable[[float], Controls],
               gait_changes: Sequence[GaitChange]) -> Simulation:
        """A simulation to step on from this :meth:`snapshot` (taken at frame ``n_frames - 1``
        of the run ``record``): a copy with ``record``'s first ``n_frames`` frames and the
        new run's ``controls`` and ``gait_changes`` (equal to the old ones' up to here; the
        caller knows, e.g. by digests of both)."""
        sim = copy.deepcopy(self, dict(memo))
        sim._controls = controls
        sim._changes = sorted(gait_changes, key=lambda g: g.time)
        sim._frames = [dict(fr) for fr in record._frames[:n_frames]]
        sim._stats = record._stats[:n_frames]
        return sim

    def result(self, n_frames: int | None = None) -> SimResult:
        """Everything recorded so far as a ``SimResult`` (or its first ``n_frames`` frames,
        e.g. for a preview while the rest runs)."""
        fr = self._frames if n_frames is None else self._frames[:n_frames]
        asked = [f for f in fr if "ground" not in f]
        if asked:  # the ground under the feet of frames over ground that never moves, kept
            n = self.legs.n_legs
            ground = self.env.height_at(np.concatenate([f.pop("end_xy") for f in asked]))
            for k, f in enumerate(asked):
                f["ground"] = ground[k * n : (k + 1) * n]

        def stack(key: str) -> npt.NDArray[np.generic]:
            return np.stack([f[key] for f in fr])

        yaw = stack("yaw").astype(np.float64)
        pitch = stack("pitch").astype(np.float64)
        roll = stack("roll").astype(np.float64)
        phase = stack("phase")
        needle = stack("needle").astype(np.float64)
        before = np.concatenate([needle[:1], needle[:-1]])  # (the first frame: itself, a step of 0)

        names = (
            "n_plans",
            "n_failed",
            "n_couples",
            "n_paths",
            "n_windows",
            "n_replans",
            "n_forced",
            "n_relaxed",
            "n_fallback",
            "n_bent",
        )
        step_stats = self._stats[: len(fr)]
        stats = {k: np.array([getattr(s, k) for s in step_stats], dtype=np.int64) for k in names}
        phases = ("maps", "planning", "ik", "physics", "spine", "rest")
        seconds = {k: np.array([s.seconds.get(k, 0.0) for s in step_stats]) for k in phases}
        return SimResult(
            dt=self.dt,
            legs=self.legs,
            time=np.arange(len(fr)) * self.dt,
            pelvis_position=stack("pos").astype(np.float64),
            pelvis_rotation=rotation_matrices(yaw.reshape(-1), pitch.reshape(-1), roll.reshape(-1)).reshape(
                (*yaw.shape, 3, 3)),
            yaw=yaw,
            pitch=pitch,
            roll=roll,
            joints=stack("joints").astype(np.float64),
            plane_normal=stack("normal").astype(np.float64),
            angles=stack("angles").astype(np.float64),
            foot=stack("foot").astype(np.float64),
            contact=~((phase == int(Phase.SWING)) | (phase == int(Phase.FORCED))),
            forced=phase == int(Phase.FORCED),
            plan_failed=phase == int(Phase.STUCK),
            ground=stack("ground").astype(np.float64),
            footprint=stack("footprint").astype(np.float64),
            preferred=stack("preferred").astype(np.float64),
            needle=needle,
            phase_step=np.mod(needle - before, 1.0),
            phase_rate=stack("phase_rate").astype(np.float64),
            speed=stack("speed").astype(np.float64),
            auto_band=stack("auto_band").astype(np.int64),
            ik_error=stack("ik_error").astype(np.float64),
            disk_start=stack("disk_start").astype(np.float64),
            disk_duration=stack("disk_duration").astype(np.float64),
            leg_frame=stack("leg_frame").astype(np.float64),
            spine_joints=stack("spine_joints").astype(np.float64),
            spine_rotation=stack("spine_rotation").astype(np.float64),
            spine_n_joints=np.array(
                [m.spine.n_joints if m.spine is not None and sp is not None else 0
                 for m, sp in zip(self.legs.morphologies, self.controller.spine_params, strict=True)],
                dtype=np.int64,
            ),
            stats=stats,
            seconds=seconds,
        )


def crowd_intrusion(result: SimResult) -> FloatArray:
    """``(F, N)`` how deep each end effector is inside another character's body box at each
    frame (metres, 0 outside; ``crowd.feet_in_bodies``, the boxes along a spine per bone)."""
    legs = result.legs
    box_center = np.array([m.body_box_center for m in legs.morphologies])
    box_half = np.array([m.body_box_half for m in legs.morphologies])
    end = result.end_effector
    out = np.zeros(end.shape[:2])
    for f in range(result.n_frames):
        boxes = crowd.body_boxes(box_center, box_half, result.pelvis_position[f], result.yaw[f],
                                 result.spine_joints[f], result.spine_n_joints)
        out[f] = crowd.feet_in_bodies(boxes, end[f, :, :2], legs.leg_char)
    return out


def check_motion(
    result: SimResult, env: Environment, *, settle: float = 0.0, chars: Sequence[int] | None = None
) -> mx.MotionReport:
    """Measure a result against ``DESIGN.md``'s thresholds (``metrics``).

    Penetration uses the ground recorded under each foot at each frame (so moving obstacles
    count where they were); static avoided boxes are also checked for feet entering them
    from the side.

    ``settle``: seconds at the start not judged for gait phases (a gait transition or the
    first swings); ``chars``: only these characters' legs (default all). Frames of forced
    steps and failed plans are not judged for gait phases.
    """
    legs = result.legs
    leg_sel = np.arange(legs.n_legs) if chars is None else np.flatnonzero(np.isin(legs.leg_char, list(chars)))
    end = result.end_effector[:, leg_sel]
    hips = result.hips[:, leg_sel]
    contact = result.contact[:, leg_sel]
    seg = legs.segment_lengths[leg_sel]
    nseg = legs.n_segments[leg_sel]
    leg_len = legs.leg_length[leg_sel]
    target = result.foot[:, leg_sel]
    body_up = result.leg_frame[:, leg_sel][..., 2]
    # an end-effector stands its foot lift above the ground (a rig's ankle over its sole)
    depth = result.ground[:, leg_sel] + legs.foot_lift[leg_sel] - end[..., 2]
    boxes = env.boxes
    # moving boxes are judged by the per-frame ground (their top), static ones also from the side
    avoid = (boxes.role == ROLE_AVOID) & ~boxes.dynamic
    intrusion = 0.0
    if np.any(avoid):
        flat = end.reshape(-1, 3)
        intrusion = float(
            mx.box_intrusion(flat, boxes.center[avoid], boxes.size[avoid], boxes.yaw[avoid]).max()
        )
    reachable = np.linalg.norm(target - hips, axis=2) <= leg_len[None, :] * (1.0 - 1e-6)
    skip = result.forced[:, leg_sel] | result.plan_failed[:, leg_sel]
    skip = skip | np.vstack([skip[:1], skip[:-1]])
    lc = legs.leg_char[leg_sel]
    phase = mx.swing_phase_errors(
        contact,
        result.needle[:, lc],
        result.phase_step[:, lc],
        result.disk_start[:, leg_sel],
        result.disk_duration[:, leg_sel],
        ignore=skip,
        first_frame=max(1, int(np.ceil(settle / result.dt))),
    )
    notes = []
    if result.plan_failed[:, leg_sel].any():
        notes.append(f"planner failures: {int(result.stats['n_failed'].sum())}")
    return mx.MotionReport(
        stance_slide=mx.stance_sliding(end, contact),
        penetration=float(max(depth.max(), 0.0)),
        avoid_intrusion=intrusion,
        bone_length_error=mx.bone_length_error(result.joints[:, leg_sel], seg, nseg),
        # angles measured from the posed joints, not taken from the solver's bookkeeping
        joint_limit_excess=mx.joint_limit_excess(
            mx.joint_angles(result.joints[:, leg_sel], result.plane_normal[:, leg_sel], body_up, nseg),
            legs.joint_min[leg_sel],
            legs.joint_max[leg_sel],
        ),
        reach_error=mx.reach_error(end, target, reachable),
        extension=mx.target_extension(hips, target, leg_len),
        phase=phase,
        notes=tuple(notes),
        hover=float(np.where(contact & (result.ground[:, leg_sel] > 0.5 * NO_SURFACE), -depth, 0.0).max(
            initial=0.0)),
    )
