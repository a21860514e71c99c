# SPDX-License-Identifier: GPL-3.0-or-later
"""The character controller: feet and pelvis of many characters, one step at a time
(thesis §3.2, §3.6; pelvis pseudo-physics §4.1).

Per step, for all characters at once:

1. **Heading and needle.** The heading turns toward the commanded one at a bounded rate.
   The gait's needle advances; when the commanded speed (and, for a rigid body, its turn:
   planted feet far from the pelvis sweep sideways) would make a stance sweep longer than
   the legs allow, the needle runs faster (a shorter cycle) so feet keep up with the body
   instead of over-stretching. What the legs allow (``stroke_limit``, from the rest pose):
   every foot within reach at both ends of its sweep, a landing foot never crossing nor
   crowding a neighbour's planted foot, and never more than ``max_stroke`` leg lengths.
2. **Pelvis in the ground plane** (§3.2.2): speed along the heading, plus the feet-error
   feedback (figure 3.9): the mean offset between preferred and chosen footprints, when it
   exceeds ``feedback_threshold`` leg lengths, is worked off over a cycle.
3. **Feet** (§3.2.1, figure 3.5). A foot entering swing gets a *preferred footprint*: where
   the pelvis will be when it lands (speed and heading extrapolated), plus the leg's rest
   position and the user's spacing offset, plus half the stance sweep forward so the foot
   passes under its rest position at mid-stance (figures 3.6, 3.7). The footprint planner
   (``footprints.plan_footstep``) returns the best couple; the foot follows the trajectory at
   constant speed over the rest of its swing. A swinging foot is re-planned from where it is
   (sequences 1-3, §3.6) when the commanded heading or speed changed noticeably since its
   plan, when its spacing changed, or when a moving obstacle now cuts its remaining
   trajectory or its target. Stance feet are locked; when the support under one moves or
   becomes forbidden (sequence 4), that foot takes a short forced step to a new footprint.
   Moving obstacles are watched on two rings around each planted foot (and each landing
   spot): one closing in makes the foot step away (or re-plan its landing) before it
   arrives; one that reaches a foot anyway pushes it out the shorter way, aside rather than
   onto the top of an avoided obstacle. A foot left behind (it would need the pelvis to sink
   more than ``max_drop``) steps early, also when its gait swing could not be planned.
4. **Pelvis height, pitch and roll** (§3.2.2, figure 3.8): the upper convex hull of the
   terrain under the body box and of the planted feet (and the targets of swinging feet),
   along the body's forward axis for height and pitch and along its left axis for roll;
   the pelvis sits ``body_thickness`` above it, low-pass filtered over a fraction of a cycle.
   With pseudo-physics on, that height is the preferred height ``y_T`` of the pogo particles
   (``pelvis_physics``). Finally, if a leg would have to stretch beyond ``reach_margin`` of
   its length, the pelvis is lowered just enough ("the pelvis stays above its feet").
5. **Legs**: IK (``ik.solve_legs``) from the hips to the feet.

**Flexible spine** (thesis §4.2, §4.4; ``core.spine``), per character: a character whose
morphology has a spine and which is given ``SpineParams`` walks on its *virtual pelvis
nodes* instead of one rigid pelvis. Steps 1-2 of the spine replace the heading and the
ground-plane motion (the head turns, the other nodes follow it on the previous spine); each
foot is planned in the frame of its own node, predicted along the spine to where the node
will be when the foot lands; every node gets its own hull height (``spine.terrain_guides``)
and, with pseudo-physics on, its own pogo particles (the legs hanging from it; the head
node, without legs, keeps its guide), its own pitch (environment averaged with the pitch
its feet induce) and, with visual yaw, the sway of §4.4; step 4 draws the spine as a
Hermite curve sampled at the bones' lengths and repeats it on guides moved toward the feet
while a leg cannot reach (``spine.repeat_for_reach``, in place of the pelvis reach guard).
The hips ride with their node (or the spine bone that carries them) and the IK poses each
leg in that frame. Characters without ``SpineParams`` move exactly as described above.

Characters may differ in morphology and gait; legs live on one flat axis (``LegBatch``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from .footprints import FootRequest, PlannerParams, plan_footsteps
from .gait import Gait, GaitManager
from .geometry import vector_norm, wrap_angle
from .hull import hull_height_and_pitch
from .ik import IKResult, solve_legs
from .morphology import LegBatch
from .pelvis_physics import PelvisPhysics, PelvisPhysicsParams
from .spine import (
    SpineModel,
    SpineParams,
    SpinePlan,
    SpinePose,
    SpineState,
    build_spine,
    hip_positions,
    leg_frames,
    node_pitch,
    plan_spine,
    pose_rows,
    pose_with_rows,
    refit,
    repeat_for_reach,
    terrain_guides,
    visual_yaw,
)
from .terrain import NO_SURFACE, Environment, WindowParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

_VOID = NO_SURFACE * 0.5
#: A change of the needle rate in one step by more than this factor re-makes the pelvis
#: particles' orbit (see ``Controller.step``).
RATE_JUMP = 2.0


def rotation_matrices(yaw: FloatArray, pitch: FloatArray, roll: FloatArray) -> FloatArray:
    """Body-to-world rotations ``(n, 3, 3)``: yaw about world z, then pitch (nose up
    positive), then roll (left side up positive) about the body's own axes."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    # Rz(yaw) @ Ry'(pitch, nose up = about -y) @ Rx(roll) multiplied out (the step asks for
    # these a few times; two stacked 3x3 products cost more than the nine entries)
    out = np.empty((yaw.shape[0], 3, 3))
    out[:, 0, 0] = cy * cp
    out[:, 0, 1] = -sy * cr - cy * sp * sr
    out[:, 0, 2] = sy * sr - cy * sp * cr
    out[:, 1, 0] = sy * cp
    out[:, 1, 1] = cy * cr - sy * sp * sr
    out[:, 1, 2] = -cy * sr - sy * sp * cr
    out[:, 2, 0] = sp
    out[:, 2, 1] = cp * sr
    out[:, 2, 2] = cp * cr
    return out


def stroke_limits(
    legs: LegBatch,
    reach: FloatArray,
    low: FloatArray,
    clearance: FloatArray,
    cap: FloatArray,
    samples: int = 97,
) -> FloatArray:
    """Longest stance sweep ``(C,)`` (metres) each character's legs allow when walking
    straight ahead: a foot lands half a sweep ahead of its rest position and lifts half a
    sweep behind it (thesis figures 3.6, 3.7), so

    - every foot must stay within ``reach (N,)`` of its hip at both ends, with the hip
      ``low (N,)`` above the ground (horizontally: ``sqrt(reach² - low²)``);
    - a foot landing must stay behind a neighbour's planted foot that is about to lift (at
      its far end) and ``clearance (C,)`` away from it, without the two legs crossing (the
      planner forbids both: the neighbour's foot box and legs crossing, thesis §3.5.1).
      Pairs already crossing or crowded at rest are left out (the stroke cannot help them).

    Neither is ever more than ``cap (C,)``. Rest geometry only (body frame, x forward)."""
    c = legs.n_chars
    hip = legs.hip_offset[:, :2]
    rest = legs.rest_foot[:, :2] - hip
    out = np.asarray(cap, dtype=np.float64).copy()
    # reach: |rest ± s/2 x| <= H  <=>  s <= 2 (sqrt(H² - y²) - |x|)
    horizontal = np.sqrt(np.maximum(reach * reach - low * low, 0.0))
    room = np.sqrt(np.maximum(horizontal * horizontal - rest[:, 1] ** 2, 0.0)) - np.abs(rest[:, 0])
    np.minimum.at(out, legs.leg_char, np.maximum(2.0 * room, 0.0))
    # neighbours: ordered pairs (i lands, j lifts) of the same character
    i, j = np.nonzero((legs.leg_char[:, None] == legs.leg_char[None, :]) & ~np.eye(legs.n_legs, dtype=bool))
    if i.size == 0:
        return out
    owner = legs.leg_char[i]
    s = np.linspace(0.0, 1.0, samples)[None, :] * out[owner][:, None]  # (p, k)
    shift = np.stack([0.5 * s, np.zeros_like(s)], axis=-1)
    foot_i = legs.rest_foot[i, None, :2] + shift
    foot_j = legs.rest_foot[j, None, :2] - shift
    hip_i = np.broadcast_to(hip[i, None], foot_i.shape)
    hip_j = np.broadcast_to(hip[j, None], foot_j.shape)

    def side(a: FloatArray, b: FloatArray, q: FloatArray) -> FloatArray:
        d = b - a
        e = q - a
        return np.asarray(d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0])

    cross = (side(hip_i, foot_i, hip_j) * side(hip_i, foot_i, foot_j) < 0.0) & (
        side(hip_j, foot_j, hip_i) * side(hip_j, foot_j, foot_i) < 0.0
    )
    bad = cross | (np.linalg.norm(foot_i - foot_j, axis=-1) < clearance[owner][:, None])
    keep = ~bad[:, 0]
    first = np.where(bad.any(axis=1), np.argmax(bad, axis=1), samples)
    limit = np.where(first < samples, s[np.arange(i.size), np.maximum(first - 1, 0)], out[owner])
    np.minimum.at(out, owner[keep], limit[keep])
    return out[:c]


def leg_arch_shares(legs: LegBatch) -> FloatArray:
    """``(N,)`` how high each leg's inner joints rise above its hip-foot line at rest, as a
    share of the half-height a two-segment leg of the same length bends over that distance
    (``sqrt(L² - C²) / 2``): near 1 for a spider's or an insect's legs (knees above the
    hip), 0 for legs whose knees bend forward or back under the hip."""
    joints = legs.rest_joints
    rows = np.arange(legs.n_legs)
    hip = joints[:, 0]
    foot = joints[rows, legs.n_segments]
    d = foot - hip
    chord2 = np.einsum("ij,ij->i", d, d)
    inner = joints[:, 1:]
    along = np.einsum("nkj,nj->nk", inner - hip[:, None], d)
    t = np.clip(along / np.maximum(chord2, 1e-18)[:, None], 0.0, 1.0)
    above = inner[..., 2] - (hip[:, None, 2] + t * d[:, None, 2])
    valid = np.arange(inner.shape[1])[None, :] < (legs.n_segments - 1)[:, None]
    rise = np.where(valid, above, 0.0).max(axis=1, initial=0.0)
    half = 0.5 * np.sqrt(np.maximum(legs.leg_length**2 - chord2, 0.0))
    return np.asarray(np.clip(np.where(half > 1e-9, rise / np.maximum(half, 1e-12), 0.0), 0.0, 1.0))


@dataclass(frozen=True)
class ControllerParams:
    """Controller knobs. Lengths marked "× leg" are fractions of the character's mean leg
    length; times marked "× cycle" fractions of its gait cycle.

    - ``window_cells``, ``window_cell``: the planning window (thesis: 70 cells of 7 cm);
      ``window_cell=None`` uses 0.13 × leg (7 cm for a half-metre spider leg).
    - ``slice_size``: height slices of the planner in metres (None: no slices);
      ``max_couples_after_first``: the planner's LOD budget (None: full search).
    - ``candidate_radius``, ``fixed_distance`` (× leg): planner search around the preferred
      footprint; ``max_height_change`` (× leg): highest step up or down a footprint may be.
    - ``max_stroke`` (× leg): longest stance sweep before the needle speeds up.
    - ``max_turn_rate``: rad/s.
    - re-planning thresholds: ``replan_heading`` (rad), ``replan_speed`` (relative),
      ``replan_spacing`` (× leg); heading/speed/spacing re-plans only before
      ``replan_until`` of the swing.
    - ``feedback_threshold`` (× leg) and ``feedback_gain`` (offset share worked off per cycle).
    - ``reach_margin``: largest hip-to-foot distance allowed, as a share of the leg length;
      the pelvis sinks to keep it, by at most ``guard_max_drop`` (× body thickness). A
      spine's nodes are pulled toward the feet instead (step 4 repeated), each by at most
      the same distance; ``reach_release_time`` (s): time constant over which a node's pull
      lets go once no leg needs it (the pull itself acts at once); ``swing_reach_slack``: a
      swinging foot pulls only beyond ``1 + swing_reach_slack × (1 - swing progress)`` of the
      reach, so the body follows a foot going down a step as it comes down (the swinging
      foot itself goes to the nearest point its leg reaches meanwhile).
    - ``height_time`` (× cycle): time constant of the pelvis height/pitch/roll filter.
    - ``trajectory_samples``: samples kept of each swing trajectory (constant speed).
    - ``snap_tolerance`` (× step height): a footprint may be lowered by up to this much onto
      the exact surface under its point (the planner's grid height is the highest surface
      under the whole foot box).
    - ``body_samples``: terrain samples under the body box (along, across).
    - ``support_tolerance``: metres the support under a planted foot may move before the
      foot steps again; ``ik_tolerance``: metres within which the leg IK stops.
    - ``watch_distance`` (× leg): a planted foot also steps away when a moving obstacle comes
      within this distance of its foot box (the ground there rose above the foot or became
      forbidden since it landed), before the obstacle reaches it.
    - ``forced_swing``: duration of a forced step as a share of the leg's swing duration.
    - ``clock``: the clock of the per-phase timings in ``StepStats.seconds`` (wall time; a
      benchmark on a shared machine may pass ``time.process_time``).
    - ``max_drop`` (× body thickness), ``step_early_reach`` (share of the leg length): a
      planted foot that would need the pelvis to sink more than ``max_drop`` to stay within
      ``step_early_reach`` of its hip steps early (a forced step) instead, before the leg is
      stretched. Such a step waits while it would leave its character with fewer than
      ``min_planted`` feet down (one less than its legs at most), unless the pelvis would
      have to drop more than ``urgent_drop`` (× body thickness) to keep the foot.
    """

    window_cells: int = 70
    window_cell: float | None = None
    slice_size: float | None = 0.1
    max_couples_after_first: int | None = None
    candidate_radius: float = 0.25
    fixed_distance: float = 0.5
    max_height_change: float = 0.5
    max_stroke: float = 0.9
    max_turn_rate: float = 2.0
    replan_heading: float = 0.15
    replan_speed: float = 0.25
    replan_spacing: float = 0.05
    replan_until: float = 0.6
    feedback_threshold: float = 0.1
    feedback_gain: float = 1.0
    reach_margin: float = 0.97
    height_time: float = 0.25
    trajectory_samples: int = 32
    snap_tolerance: float = 0.5
    body_samples: tuple[int, int] = (5, 3)
    support_tolerance: float = 0.002
    ik_tolerance: float = 1e-5
    watch_distance: float = 0.15
    forced_swing: float = 0.6
    max_drop: float = 0.15
    step_early_reach: float = 0.92
    guard_max_drop: float = 0.5
    reach_release_time: float = 0.2
    swing_reach_slack: float = 0.1
    min_planted: int = 2
    urgent_drop: float = 0.45
    clock: Callable[[], float] = time.perf_counter
    physics: PelvisPhysicsParams = field(default_factory=PelvisPhysicsParams)


@dataclass(frozen=True)
class PlannerLOD:
    """A character's planner level of detail (thesis §3.7): couples evaluated after the first
    valid one (None: full search, 0: stop at the first) and the height-slice size in metres
    (None: no slices, go over everything)."""

    max_couples_after_first: int | None = None
    slice_size: float | None = 0.1


@dataclass(frozen=True)
class StepControls:
    """Commands for one step. ``speed``, ``heading``, ``step_height``: ``(C,)`` (m/s,
    radians from world +X, metres); ``spacing``: ``(N, 2)`` body-frame xy offset of each foot
    from its rest position; ``pelvis_physics``: ``(C,)`` bool; ``ik``: ``(C,)`` bool (False
    skips the IK of a character, e.g. off-screen under LOD)."""

    speed: FloatArray
    heading: FloatArray
    step_height: FloatArray
    spacing: FloatArray
    pelvis_physics: BoolArray
    ik: BoolArray


@dataclass
class StepStats:
    """Planner statistics of one step: plans, failed plans, couples and paths evaluated,
    windows cut, re-plans, forced steps, plans retried without the other feet and slices
    (``n_relaxed``), straight fallback steps (``n_fallback``), swinging feet moved to the
    closest point their leg reaches (``n_bent``); and seconds per phase
    (``maps``, ``planning``, ``ik``, ``physics``, ``spine``, ``rest``)."""

    n_plans: int = 0
    n_failed: int = 0
    n_couples: int = 0
    n_paths: int = 0
    n_windows: int = 0
    n_replans: int = 0
    n_forced: int = 0
    n_relaxed: int = 0
    n_fallback: int = 0
    n_bent: int = 0
    seconds: dict[str, float] = field(default_factory=dict)


@dataclass(eq=False)
class _SpineGroup:
    """Characters stepped together through the spine functions: one shared ``SpineModel``
    and ``SpineParams``. ``chars (g,)``; ``legs (g, L)`` flat leg rows; ``nodes (g, K)`` flat
    pelvis-node rows; ``plan``/``pose``: the last steps 1-2 and step 4; ``height``,
    ``pitch (g, K)``: each node's filtered preferred height and pitch (deviation from rest);
    ``reach_shift (g, K, 3)``: how far the last step 4 moved each node's guide so the legs
    reach their feet (released gradually, see ``ControllerParams.reach_release_time``)."""

    model: SpineModel
    params: SpineParams
    chars: IntArray
    legs: IntArray
    nodes: IntArray
    plan: SpinePlan
    pose: SpinePose | None = None
    height: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    pitch: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    reach_shift: FloatArray | None = None


class Controller:
    """State and step of many characters (see the module docstring).

    ``env``: the environment; ``legs``: every character's legs (``LegBatch``); ``gaits``: one
    ``Gait`` per character; ``start_xy (C, 2)``, ``start_yaw (C,)``: initial pelvis ground
    position and heading; ``phase (C,)``: initial needle phases; ``planner``: optional
    per-character ``PlannerParams`` (replacing the derived ones except step height, reach,
    foot size and height change); ``lod``: optional per-character ``PlannerLOD``;
    ``controls``: the first step's commands (for the initial planning of feet that start in
    swing); ``spine``: optional per-character ``SpineParams`` (None: a rigid body) for
    characters whose morphology has a spine (``Morphology.with_spine``).
    """

    def __init__(
        self,
        env: Environment,
        legs: LegBatch,
        gaits: Sequence[Gait],
        start_xy: npt.ArrayLike,
        start_yaw: npt.ArrayLike,
        controls: StepControls,
        *,
        phase: npt.ArrayLike | None = None,
        params: ControllerParams | None = None,
        planner: Sequence[PlannerParams | None] | None = None,
        lod: Sequence[PlannerLOD | None] | None = None,
        spine: Sequence[SpineParams | None] | None = None,
    ) -> None:
        self.env = env
        self.legs = legs
        self.params = p = params or ControllerParams()
        c = legs.n_chars
        n = legs.n_legs
        self.n_chars, self.n_legs = c, n
        self.leg_char = legs.leg_char
        self._setup_nodes(spine)
        self.gait = GaitManager(legs.leg_char, gaits, phase)
        self.time = 0.0
        mean_leg = np.bincount(legs.leg_char, weights=legs.leg_length, minlength=c) / np.bincount(
            legs.leg_char, minlength=c
        )
        self.char_leg_length = mean_leg
        self.body_thickness = np.array([m.body_thickness for m in legs.morphologies])
        self.box_center = np.array([m.body_box_center for m in legs.morphologies])
        self.box_half = np.array([m.body_box_half for m in legs.morphologies])
        self.foot_half = np.array([m.foot_half_extents for m in legs.morphologies])
        # the part of each foot the others may not land on (a foot box unless the
        # morphology gives a smaller sole)
        self.sole_half = np.array([m.foot_half_extents if m.sole_half_extents is None else m.sole_half_extents
                                   for m in legs.morphologies])
        # how far each end-effector stands above the ground the feet are planned on (a rig's
        # feet of different heights on ground raised by their mean height)
        self.foot_lift = legs.foot_lift
        self.window_cell = (
            np.clip(0.065 * mean_leg, 0.005, 0.25)
            if p.window_cell is None
            else np.full(c, float(p.window_cell))
        )
        self._planner_override = list(planner) if planner is not None else [None] * c
        self.lod: list[PlannerLOD | None] = list(lod) if lod is not None else [None] * c
        rest_vec = legs.rest_foot - legs.hip_offset
        self.rest_height = -rest_vec[:, 2]
        self.rest_horizontal = np.linalg.norm(rest_vec[:, :2], axis=1)
        rest_dist = np.linalg.norm(rest_vec, axis=1)
        self.leg_arch = leg_arch_shares(legs)
        # comfortable reach: never tighter than the rest pose itself
        self.comfort_reach = np.minimum(
            np.maximum(p.step_early_reach * legs.leg_length, 1.02 * rest_dist), 0.995 * legs.leg_length
        )
        self.guard_reach = np.minimum(
            np.maximum(p.reach_margin * legs.leg_length, 1.01 * rest_dist), 0.999 * legs.leg_length
        )
        # the longest stance sweep the legs allow (the needle runs faster beyond it), never
        # less than a quarter of max_stroke: a leg's reach with the pelvis half its allowed
        # drop lower, and neighbouring feet kept two foot boxes and half a planning cell apart
        # (their toes do not meet as they sweep; a foot may land nearer, its box off the
        # other's sole, but a longer sweep then crowds the next footfalls)
        cap = p.max_stroke * mean_leg
        low = self.rest_height - 0.5 * p.max_drop * self.body_thickness[legs.leg_char]
        clearance = 2.0 * self.foot_half.max(axis=1) + 0.5 * self.window_cell
        self.stroke_limit = np.maximum(
            stroke_limits(legs, self.comfort_reach, low, clearance, cap), 0.25 * cap
        )
        self.env_dynamic = bool(env.boxes.dynamic.any()) or any(soup.dynamic for soup in env.soups)
        # pelvis
        self.pos = np.zeros((c, 3))
        self.pos[:, :2] = np.asarray(start_xy, dtype=np.float64).reshape(c, 2)
        self.yaw = np.broadcast_to(np.asarray(start_yaw, dtype=np.float64), (c,)).copy()
        self.pitch = np.zeros(c)
        self.roll = np.zeros(c)
        self.height_target = np.zeros(c)
        self.guard_drop = np.zeros(c)  # how far the reach guard lowered each pelvis last
        self.feedback = np.zeros((n, 2))
        # feet
        # start as if already walking: a planted foot is where the stance sweep has brought it,
        # a foot in its swing sector waits at its lift-off spot (no stumble at the first frame)
        g = self.gait
        # the needle already runs at the speed the commanded stroke asks for
        g.rate_scale = self._rate_scale(np.asarray(controls.speed, dtype=np.float64))
        period = 1.0 / g.rate()[legs.leg_char]
        stance_time = (1.0 - g.disk_duration) * period
        stance_done: FloatArray = np.where(
            g.swing,
            1.0,
            np.mod(g.needle[legs.leg_char] - g.disk_start - g.disk_duration, 1.0) / (1.0 - g.disk_duration),
        ).astype(np.float64)
        speed0 = np.asarray(controls.speed, dtype=np.float64)[legs.leg_char]
        sweep = np.asarray((0.5 - stance_done) * speed0 * stance_time, dtype=np.float64)
        spacing0 = np.asarray(controls.spacing, dtype=np.float64).reshape(n, 2)
        rest_xy = np.asarray(
            legs.rest_foot[:, :2] + spacing0 + np.column_stack([sweep, np.zeros(n)]), dtype=np.float64
        )
        foot_xy = self.pos[legs.leg_char, :2] + self._rotate_xy(rest_xy, self.yaw[legs.leg_char])
        self.foot = np.column_stack([foot_xy, self._surface(foot_xy)])
        self.support_z = self.foot[:, 2].copy()
        # points watched around each planted foot for moving obstacles: two rings, at the foot
        # box's corner distance plus watch_distance and half of it, and what was there at the
        # last step (or when the foot landed)
        ring = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
        dirs = np.stack([np.cos(ring), np.sin(ring)], axis=1)
        corner = np.linalg.norm(self.foot_half, axis=1)[legs.leg_char]
        outer = corner + p.watch_distance * legs.leg_length
        inner = corner + 0.5 * p.watch_distance * legs.leg_length
        self._watch_offsets = np.concatenate(
            [outer[:, None, None] * dirs[None], inner[:, None, None] * np.roll(dirs, 1, axis=0)[None]], axis=1
        )  # (N, 16, 2), the inner ring turned half a step
        self.watch_ground = np.zeros((n, 16))
        self.watch_forbidden = np.zeros((n, 16), dtype=bool)
        self._watch_reset(np.arange(n), self.foot)
        self.support_target = self.foot[:, 2].copy()
        self.target = self.foot.copy()
        self.preferred = self.foot.copy()
        self.swinging = np.zeros(n, dtype=bool)
        self.forced = np.zeros(n, dtype=bool)
        self.forced_behind = np.zeros(n, dtype=bool)  # forced steps of feet left behind
        self._swing_u = np.ones(n)  # swing progress of each foot this step (1: planted)
        self.dodged = np.zeros(n, dtype=bool)  # this swing was re-planned for an obstacle closing in
        self.forced_elapsed = np.zeros(n)
        self.forced_duration = np.ones(n)
        k = p.trajectory_samples
        self.traj = np.repeat(self.foot[:, None, :], k + 1, axis=1)
        self.traj_u0 = np.zeros(n)
        # what was under each trajectory sample when it was planned (moving obstacles are
        # judged against it)
        self.traj_ground = np.zeros((n, k + 1))
        self.traj_forbidden = np.zeros((n, k + 1), dtype=bool)
        self.plan_heading = np.zeros(n)
        self.plan_speed = np.zeros(n)
        self.plan_spacing = np.zeros((n, 2))
        self.plan_failed = np.zeros(n, dtype=bool)
        self.blocked = np.zeros(n, dtype=bool)  # swings a moving obstacle cut this step
        self.restarts = np.zeros(n, dtype=np.int64)  # steps started again because the spot was taken
        self.angles = legs.rest_angles.copy()
        # last step's leg-plane normals (body frame): the plane turns on from them
        self.leg_normals: FloatArray | None = None
        self.ik_result: IKResult | None = None
        # initial pelvis pose from the hull
        height, pitch, roll = self._hull_pose(controls)
        self.pitch, self.roll = pitch, roll
        self.height_target = height
        self.pos[:, 2] = height
        self.physics = PelvisPhysics(self.leg_node, self.n_nodes, params=p.physics)
        self._physics_on = np.asarray(controls.pelvis_physics, dtype=bool).copy()
        # the needle rate the pelvis particles' orbit was made for (re-made when it jumps)
        self._physics_rate = self.gait.rate()[self.leg_char].copy()
        pref_nodes = self._spine_start(height)
        if np.any(self._physics_on):
            self.physics.reset(
                pref_nodes,
                self.gait.needle[self.leg_char],
                self.gait.rate()[self.leg_char],
                self.gait.disk_start,
                self.gait.disk_duration,
            )
            centered = self.physics.centered_height()
            self.pos[:, 2] = np.where(self._physics_on, centered[self.node_start[:-1]], height)
            pref_nodes = np.where(self._physics_on[self.node_char], centered, pref_nodes)
        if self.spine_groups:
            self._spine_pose(pref_nodes, self._physics_on, 0.0)
        # feet that start inside their swing sector are planned right away
        self._start_in_swing = np.zeros(n, dtype=bool)
        start_swing = self.gait.swing.copy()
        if np.any(start_swing):
            needle = self.gait.needle[self.leg_char]
            period = 1.0 / self.gait.rate()[self.leg_char]
            progress = np.where(
                start_swing, np.mod(needle - self.gait.disk_start, 1.0) / self.gait.disk_duration, 0.0
            )
            swing_time = self.gait.disk_duration * period
            stance_time = (1.0 - self.gait.disk_duration) * period
            self._plan(
                np.flatnonzero(start_swing),
                controls,
                progress,
                (1.0 - progress) * swing_time,
                stance_time,
                np.zeros(n),
                StepStats(),
                _Timer({}),
            )
            self.swinging = start_swing & ~self.plan_failed
            self._start_in_swing = start_swing & self.plan_failed
        self._reach_guard()
        self._solve_ik(controls)

    # ---------------------------------------------------------------- small helpers
    def _rate_scale(self, speed: FloatArray, yaw_rate: FloatArray | None = None) -> FloatArray:
        """``(C,)`` needle speed-up for the commanded ``speed (C,)`` and the body's
        ``yaw_rate (C,)`` (rad/s): the stance sweep at the gait's own cycle, over the longest
        the legs allow (``stroke_limit``), at least 1. A rigid body turning sweeps its planted
        feet sideways too (the farther from the pelvis, the more); a spine's nodes follow
        the head's path, so only their speed counts."""
        lc = self.leg_char
        stance = (1.0 - self.gait.disk_duration) * self.gait.cycle_time[lc]
        foot_speed = np.asarray(speed, dtype=np.float64)[lc]
        if yaw_rate is not None:
            w = np.where(self.has_spine, 0.0, np.asarray(yaw_rate, dtype=np.float64))[lc]
            r = self.legs.rest_foot[:, :2]
            foot_speed = np.hypot(foot_speed - w * r[:, 1], w * r[:, 0])
        stroke = np.zeros(self.n_chars)
        np.maximum.at(stroke, lc, foot_speed * stance)
        # in steps of 1/1024 (rounded up): characters that differ only by rounding (a rig
        # read at 100 times its size) keep exactly the same cycle
        steps = np.ceil(stroke / self.stroke_limit * 1024.0 - 1e-6) / 1024.0
        return np.asarray(np.maximum(1.0, steps))

    @staticmethod
    def _rotate_xy(v: FloatArray, yaw: FloatArray) -> FloatArray:
        c, s = np.cos(yaw), np.sin(yaw)
        out = np.empty((v.shape[0], 2))
        out[:, 0] = c * v[:, 0] - s * v[:, 1]
        out[:, 1] = s * v[:, 0] + c * v[:, 1]
        return out

    def _surface(self, xy: FloatArray) -> FloatArray:
        h = self.env.height_at(xy)
        return np.where(h > _VOID, h, 0.0)

    def rotations(self) -> FloatArray:
        """``(C, 3, 3)`` current body-to-world rotations."""
        return rotation_matrices(self.yaw, self.pitch, self.roll)

    def hips_world(self, rot: FloatArray | None = None) -> FloatArray:
        """``(N, 3)`` world hips: the rigid body's, or where the spine put them."""
        if self.spine_legs.size == self.legs.n_legs:  # every leg on a spine: nothing rigid
            return np.array(self._spine_hips, copy=True)
        r = self.rotations() if rot is None else rot
        hips = self.pos[self.leg_char] + np.einsum("nij,nj->ni", r[self.leg_char], self.legs.hip_offset)
        if self.spine_groups:
            hips[self.spine_legs] = self._spine_hips[self.spine_legs]
        return np.asarray(hips)

    def leg_rotations(self) -> FloatArray:
        """``(N, 3, 3)`` body-to-world rotation of the body part each leg hangs from: the
        pelvis, or the leg's spine node (or carrier bone)."""
        if self.spine_legs.size == self.legs.n_legs:
            return np.array(self._spine_leg_rot, copy=True)
        rot = self.rotations()[self.leg_char]
        if self.spine_groups:
            rot[self.spine_legs] = self._spine_leg_rot[self.spine_legs]
        return np.asarray(rot)

    def spine_joints(self) -> FloatArray:
        """``(C, J, 3)`` world spine joints (head first) of every character, ``J`` the most
        joints of any spine; rows past a spine's end repeat its last joint, characters
        without a spine hold their pelvis position."""
        out = np.repeat(self.pos[:, None, :], self.max_spine_joints, axis=1)
        for g in self.spine_groups:
            if g.pose is None:
                continue
            j = g.model.n_joints
            out[g.chars, :j] = g.pose.joints
            out[g.chars, j:] = g.pose.joints[:, -1:]
        return out

    def spine_rotations(self) -> FloatArray:
        """``(C, J - 1, 3, 3)`` rotation of every spine bone from its rest (body-frame)
        direction to the world (``SpinePose.bone_rotation``); identity past a spine's end and
        for characters without a spine."""
        out = np.zeros((self.n_chars, max(self.max_spine_joints - 1, 0), 3, 3))
        out[:] = np.eye(3)
        for g in self.spine_groups:
            if g.pose is not None:
                out[g.chars, : g.model.n_joints - 1] = g.pose.bone_rotation
        return out

    # ---------------------------------------------------------------- spine set-up
    def _setup_nodes(self, spine: Sequence[SpineParams | None] | None) -> None:
        """Pelvis nodes (one per rigid character, ``K`` per spine) and the spine groups."""
        c, lc = self.n_chars, self.leg_char
        params = list(spine) if spine is not None else [None] * c
        if len(params) != c:
            raise ValueError(f"{len(params)} spine settings for {c} characters")
        self.spine_params = params
        self.has_spine = np.array([sp is not None for sp in params], dtype=bool)
        counts = np.ones(c, dtype=np.int64)
        groups: dict[tuple[int, SpineParams], list[int]] = {}
        models: dict[int, SpineModel] = {}
        for i, sp in enumerate(params):
            if sp is None:
                continue
            model = self.legs.morphologies[i].spine
            if model is None:
                raise ValueError(f"character {i} has spine settings but its morphology has no spine")
            counts[i] = model.n_keys
            models[id(model)] = model
            groups.setdefault((id(model), sp), []).append(i)
        self.node_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.n_nodes = int(self.node_start[-1])
        self.node_char = np.repeat(np.arange(c), counts)
        local = np.where(self.has_spine[lc], self.legs.pelvis_node, 0)
        self.leg_node = (self.node_start[lc] + local).astype(np.int64)
        self.spine_legs = np.flatnonzero(self.has_spine[lc])
        self.max_spine_joints = max((m.n_joints for m in models.values()), default=0)
        self._spine_hips = np.zeros((self.n_legs, 3))
        self._spine_hips_free = np.zeros((self.n_legs, 3))  # before the reach repeat of step 4
        self._spine_leg_rot = np.zeros((self.n_legs, 3, 3))
        self.spine_groups: list[_SpineGroup] = []
        for (mid, sp), chars in groups.items():
            model = models[mid]
            ch = np.array(chars, dtype=np.int64)
            start = self.legs.leg_start
            leg_rows = np.stack([np.arange(start[i], start[i + 1]) for i in chars])
            nodes = self.node_start[ch][:, None] + np.arange(model.n_keys)[None, :]
            empty = SpinePlan(np.zeros((ch.size, model.n_keys, 2)), np.zeros((ch.size, model.n_keys)),
                              np.zeros((ch.size, model.n_keys)), np.zeros(ch.size), np.zeros(ch.size))
            self.spine_groups.append(_SpineGroup(model, sp, ch, leg_rows, nodes, empty))

    def _spine_start(self, height: FloatArray) -> FloatArray:
        """Spines at rest where the bodies stand; returns every node's preferred height
        ``(n_nodes,)`` (the rigid characters' hull heights ``height (C,)`` for theirs)."""
        pref = np.asarray(height, dtype=np.float64)[self.node_char].copy()
        for g in self.spine_groups:
            state = SpineState.at_rest(g.model, self.pos[g.chars, :2], self.yaw[g.chars])
            g.plan = plan_spine(g.model, state, g.params, self.yaw[g.chars], 0.0, 0.0)
            h, env_pitch = terrain_guides(g.model, g.plan, self.env.height_at, self._support_feet()[g.legs])
            g.height = h
            g.pitch = node_pitch(g.model, g.plan, h, env_pitch, self._support_feet()[g.legs], g.params)
            pref[g.nodes] = h
        return pref

    def planner_params(
        self, char: int, step_height: float, leg_reach: float | None = None, leg: int | None = None,
        sweep: float = 0.0, sink: bool = True,
    ) -> PlannerParams:
        """The planner settings of a character for this step (``leg_reach``: horizontal
        distance allowed from the hip reference, default the mean leg length). With ``leg``,
        also that leg's checks against its hip's height: its 3D reach (the comfortable
        reach, ``sweep`` metres of coming stance sweep, the pelvis sinking by at most as much
        as the reach guard lowers it, ``guard_max_drop`` of its thickness, or without
        ``sink`` half of ``max_drop``: a foot stepping because it was left behind lands where
        it will not be left behind again at once), its line to the hip clear of
        the ground (bowed by half the arch its knees take at rest), and no footprint hanging
        over a height step of more than ``snap_tolerance`` of the step height (or a 1:4 slope
        under the foot)."""
        p = self.params
        length = float(self.char_leg_length[char])
        reach = length if leg_reach is None else float(leg_reach)
        level = self.lod[char]
        half = (float(self.foot_half[char, 0]), float(self.foot_half[char, 1]))
        sole = (float(self.sole_half[char, 0]), float(self.sole_half[char, 1]))
        per_leg: dict[str, float] = {}
        if leg is not None:
            per_leg = {
                "reach_3d": float(self.comfort_reach[leg]),
                "reach_sweep": float(sweep),
                "reach_sink": float(
                    (p.guard_max_drop if sink else 0.5 * p.max_drop) * self.body_thickness[char]
                ),
                "leg_length": float(self.legs.leg_length[leg]),
                "leg_arch": float(0.5 * self.leg_arch[leg]),
                "max_straddle": max(p.snap_tolerance * float(step_height), 0.25 * max(half)),
            }
        override = self._planner_override[char]
        if override is None:
            return PlannerParams(
                step_height=float(step_height),
                slice_size=p.slice_size if level is None else level.slice_size,
                leg_reach=reach,
                candidate_radius=p.candidate_radius * length,
                fixed_distance=p.fixed_distance * length,
                foot_half_extents=half,
                sole_half_extents=sole,
                max_couples_after_first=p.max_couples_after_first
                if level is None
                else level.max_couples_after_first,
                max_height_change=p.max_height_change * length,
                **per_leg,  # type: ignore[arg-type]
            )
        return replace(
            override,
            step_height=float(step_height),
            leg_reach=reach,
            foot_half_extents=half,
            sole_half_extents=sole,
            max_height_change=p.max_height_change * length,
            **per_leg,  # type: ignore[arg-type]
        )

    # ---------------------------------------------------------------- the step
    def step(self, dt: float, ctl: StepControls) -> StepStats:
        """Advance every character by ``dt`` seconds under the commands ``ctl``."""
        stats = StepStats()
        timer = _Timer(stats.seconds, self.params.clock)
        p = self.params
        lc = self.leg_char
        self.time += dt

        # 1. heading, needle
        turn = np.clip(wrap_angle(ctl.heading - self.yaw), -p.max_turn_rate * dt, p.max_turn_rate * dt)
        self.yaw = wrap_angle(self.yaw + turn)
        rate_scale = self._rate_scale(ctl.speed, turn / dt)
        needle_before = self.gait.needle[lc].copy()
        gstep = self.gait.advance(dt, rate_scale)
        rate_leg = self.gait.rate()[lc]

        # 2. pelvis in the ground plane (spines: steps 1-2 of thesis §4.2)
        fwd = np.stack([np.cos(self.yaw), np.sin(self.yaw)], axis=1)
        self.pos[:, :2] += (ctl.speed * dt)[:, None] * fwd
        if self.spine_groups:
            timer.lap("rest")
            self._spine_advance(ctl, dt)
            timer.lap("spine")
        self._apply_feedback(dt)

        # 3. feet: landings, forced steps, plans, swing positions
        timer.lap("rest")
        # a forced step lands when its own time is up (not at the gait's touch-down)
        landing = (
            (gstep.landed & ~self.forced) | (self.forced & (self.forced_elapsed + dt >= self.forced_duration))
        ) & self.swinging
        # a moving obstacle may have taken the landing spot since the last check: step again
        bad_landing = self._spot_taken(self.target, landing) & (self.restarts < 2)
        self.restarts = np.where(bad_landing, self.restarts + 1, np.where(landing, 0, self.restarts))
        self._land(landing & ~bad_landing)
        self.forced_elapsed = np.where(self.forced, self.forced_elapsed + dt, 0.0)
        lifted = gstep.lifted | (self._start_in_swing & gstep.swing)
        self._start_in_swing[:] = False
        # a normal lift ends a forced step
        self.forced &= ~gstep.lifted
        progress = np.where(
            self.forced, np.clip(self.forced_elapsed / self.forced_duration, 0.0, 1.0), gstep.swing_progress
        )
        # where the foot is now: the progress of the previous frame (a new trajectory starts there)
        step_progress = np.where(
            self.forced, dt / self.forced_duration, rate_leg * dt / self.gait.disk_duration
        )
        start_u = np.clip(progress - step_progress, 0.0, 1.0)
        swing_time = np.where(self.forced, self.forced_duration, gstep.swing_time)
        remaining = (1.0 - progress) * swing_time
        stance_time = gstep.stance_time

        replan = self._replan_needed(ctl, progress, gstep.swing)
        # a foot still down in its swing sector (its plan failed) is planted like any other:
        # it must step when its support goes or when it is left behind
        planted = ~gstep.swing | self.plan_failed
        support_gone = self._check_supports()
        behind, stretch = self._overstretched()
        behind &= ~support_gone
        behind &= ~self._wait_for_support(behind & planted & ~self.forced, stretch, lifted)
        forced_new = ((support_gone | behind) & planted & ~self.forced) | bad_landing
        # a foot left behind lands under its rest place at the latest (as at mid-stance):
        # landed where its late stance would have it, it would be left behind again at once
        self.forced_behind = np.where(
            forced_new, behind & planted & ~bad_landing, self.forced_behind & self.forced
        )
        # a swing cut by a moving obstacle near its end gets the time of a forced step for its
        # new way (in the frames left it would jump there)
        forced_time = np.maximum(p.forced_swing * gstep.swing_time, 2.0 * dt)
        # a foot left behind for cycles (its plans failed) has more than a stride to cover
        if np.any(forced_new & self.forced_behind):
            catch_up = np.maximum(forced_time, self._catch_up_time(ctl, gstep.swing_time))
            forced_time = np.where(self.forced_behind, catch_up, forced_time)
        rushed = replan & self.blocked & ~forced_new & (remaining < 0.5 * forced_time)
        forced_new |= rushed
        if np.any(forced_new):
            self.forced |= forced_new
            self.forced_duration[forced_new] = forced_time[forced_new]
            # a forced step leaves in the frame it starts (its first frame's share of the
            # swing is done): the leg is already stretched, a frame later it would be more
            self.forced_elapsed[forced_new] = dt
            first = dt / self.forced_duration
            progress = np.where(forced_new, first, progress)
            start_u = np.where(forced_new, 0.0, start_u)
            swing_time = np.where(forced_new, self.forced_duration, swing_time)
            remaining = np.where(forced_new, self.forced_duration - dt, remaining)
            stats.n_forced = int((forced_new & ~rushed).sum())
        self._swing_u = np.clip(progress, 0.0, 1.0)
        # a foot whose plan failed stays down this cycle (it steps early if it gets left behind)
        to_plan = lifted | forced_new | replan
        stats.n_replans = int((replan & ~lifted).sum())
        timer.lap("rest")
        if np.any(to_plan):
            land_stance = np.where(
                self.forced,
                np.clip(gstep.stance_progress + remaining / np.maximum(stance_time, 1e-9), 0.0, 1.0),
                0.0,
            )
            land_stance = np.where(self.forced_behind, np.minimum(land_stance, 0.5), land_stance)
            self._plan(
                np.flatnonzero(to_plan), ctl, start_u, remaining, stance_time, land_stance, stats, timer
            )
        active = (gstep.swing | self.forced) & ~self.plan_failed
        self.swinging = active
        u = np.clip((progress - self.traj_u0) / np.maximum(1.0 - self.traj_u0, 1e-9), 0.0, 1.0)
        moving = np.flatnonzero(active)
        if moving.size:
            self.foot[moving] = _sample_polyline(self.traj[moving], u[moving])
            if self.env_dynamic:
                # an obstacle that moved into a swinging foot pushes it out, up or aside (the
                # trajectory is re-planned at the next step)
                surface = self.env.height_at(self.foot[moving, :2])
                hit = surface > self.foot[moving, 2]
                if np.any(hit):
                    self._push_out(moving[hit], surface[hit])
        # a gait swing whose plan failed leaves the foot planted
        self.plan_failed &= gstep.swing | self.forced

        # 4. pelvis height, pitch, roll (spines: per node, steps 3-4 of thesis §4.2)
        alpha = 1.0 - np.exp(-dt / np.maximum(p.height_time * self.gait.cycle_time, 1e-6))
        rigid = None if not self.spine_groups else np.flatnonzero(~self.has_spine)
        if rigid is None or rigid.size:
            height, pitch, roll = self._hull_pose(ctl, rigid)
            sel = slice(None) if rigid is None else rigid
            a = alpha[sel]
            self.height_target[sel] += a * (height - self.height_target[sel])
            self.pitch[sel] += a * (pitch - self.pitch[sel])
            self.roll[sel] += a * (roll - self.roll[sel])
        pref = self.height_target
        if self.spine_groups:
            timer.lap("rest")
            pref = self._spine_guides(alpha)
            timer.lap("spine")
        physics_on = np.asarray(ctl.pelvis_physics, dtype=bool)
        switched_on = physics_on & ~self._physics_on
        # The particles' orbit belongs to a needle rate: one much faster or slower at once (a
        # turn on the spot speeding the gait up from the first frame) leaves them on an orbit
        # whose flights are sized for the old cycle, metres high on a slow gait's long stance.
        # Such a jump (over RATE_JUMP in one step) puts them on the new rate's orbit.
        ratio = rate_leg / np.maximum(self._physics_rate, 1e-12)
        jumped = np.zeros(self.n_chars, dtype=bool)
        np.logical_or.at(jumped, self.leg_char, (ratio > RATE_JUMP) | (ratio < 1.0 / RATE_JUMP))
        switched_on |= physics_on & jumped
        self._physics_rate = rate_leg.copy()
        if np.any(switched_on):
            self.physics.reset(
                pref,
                needle_before,
                rate_leg,
                self.gait.disk_start,
                self.gait.disk_duration,
                nodes=switched_on[self.node_char],
            )
        self._physics_on = physics_on.copy()
        z = pref.copy()
        if np.any(physics_on):
            timer.lap("rest")
            g_start, g_duration = self.gait.disk_start, self.gait.disk_duration
            self.physics.step(dt, needle_before, rate_leg, g_start, g_duration, pref)
            z = np.where(physics_on[self.node_char], self.physics.centered_height(), z)
            timer.lap("physics")
        if self.spine_groups:
            if rigid is not None and rigid.size:
                self.pos[rigid, 2] = z[self.node_start[rigid]]
            timer.lap("rest")
            self._spine_pose(z, physics_on, dt)
            timer.lap("spine")
        else:
            self.pos[:, 2] = z
        self._reach_guard()

        # 5. legs
        timer.lap("rest")
        stats.n_bent = self._solve_ik(ctl)
        timer.lap("ik")
        return stats

    # ---------------------------------------------------------------- spine
    def _support_feet(self) -> FloatArray:
        """``(N, 3)`` feet as the body rests on them: planted ones where they stand,
        swinging ones where they will land."""
        return np.asarray(np.where(self.swinging[:, None], self.target, self.foot))

    def _body_from_plan(self, g: _SpineGroup) -> None:
        """The body frame of spine characters from their anchor node on the ground plane
        (the pelvis the planner windows and the records refer to)."""
        m = g.model
        k = m.anchor_key
        yaw = wrap_angle(g.plan.key_heading[:, k] - m.rest_key_heading[k])
        self.yaw[g.chars] = yaw
        rest = np.broadcast_to(m.key_rest[k, :2], (yaw.size, 2))
        self.pos[g.chars, :2] = g.plan.key_xy[:, k] - self._rotate_xy(rest, yaw)

    def _spine_advance(self, ctl: StepControls, dt: float) -> None:
        """Steps 1-2 (thesis §4.2.1-4.2.2): the head turns toward the commanded heading and
        moves ``speed * dt``; the other nodes follow on the previous spine. Hips move with
        their node in the ground plane until step 4 places them."""
        for g in self.spine_groups:
            old = g.plan.key_xy
            g.plan = plan_spine(
                g.model, SpineState(old), g.params, ctl.heading[g.chars], ctl.speed[g.chars] * dt, dt
            )
            shift = g.plan.key_xy - old
            self._spine_hips[g.legs, :2] += shift[:, g.model.leg_key]
            self._spine_hips_free[g.legs, :2] += shift[:, g.model.leg_key]
            self._body_from_plan(g)

    def _spine_guides(self, alpha: FloatArray) -> FloatArray:
        """Step 3 (thesis §4.2.3): each node's preferred height (its hull slice plus its rest
        height) and pitch (environment and feet), low-pass filtered like the rigid pelvis.
        Returns every node's preferred height ``(n_nodes,)`` (rigid characters: their hull
        height)."""
        pref = self.height_target[self.node_char].copy()
        support = self._support_feet()
        for g in self.spine_groups:
            feet = support[g.legs]
            height, env_pitch = terrain_guides(g.model, g.plan, self.env.height_at, feet)
            a = alpha[g.chars][:, None]
            g.height = g.height + a * (height - g.height)
            pitch = node_pitch(g.model, g.plan, g.height, env_pitch, feet, g.params)
            g.pitch = g.pitch + a * (pitch - g.pitch)
            pref[g.nodes] = g.height
        return pref

    def _spine_pose(self, node_z: FloatArray, physics_on: BoolArray, dt: float) -> None:
        """Step 4 (thesis §4.2.4): the spine curve through the nodes at ``node_z
        (n_nodes,)`` (nodes without legs keep their guide), turned by the visual yaw (§4.4),
        repeated on guides pulled toward the feet while a leg cannot reach; then the hips,
        leg frames and body frame of every spine character."""
        for g in self.spine_groups:
            m = g.model
            has_legs = np.bincount(m.leg_key, minlength=m.n_keys) > 0
            z = np.where(physics_on[g.chars][:, None] & has_legs[None, :], node_z[g.nodes], g.height)
            yaw = g.plan.key_heading
            if g.params.visual_yaw:
                yaw = yaw + visual_yaw(m, g.plan, self.foot[g.legs], g.params)
            guide = np.concatenate([g.plan.key_xy, z[..., None]], axis=-1)
            pose = build_spine(m, guide, yaw, g.pitch)
            self._spine_hips_free[g.legs] = hip_positions(m, pose)
            # bounded like the rigid pelvis's guard: a foot beyond help steps early instead
            shift = self.params.guard_max_drop * float(self.body_thickness[g.chars[0]])
            free = pose
            reach = self._spine_reach(g)
            # a swinging foot pulls as if it were already down at its landing height (within
            # its growing reach), so the body is as low as that foot needs when it lands
            feet = self.foot[g.legs].copy()
            swing = self.swinging[g.legs]
            feet[swing, 2] = np.minimum(feet[swing, 2], self.target[g.legs][swing, 2])
            feet[..., 2] += self.foot_lift[g.legs]
            pose = repeat_for_reach(m, pose, feet, reach, iterations=6, max_shift=shift)
            pose, g.reach_shift = self._release_pull(g, free, pose, feet, reach, dt)
            g.pose = pose
            self._spine_hips[g.legs] = hip_positions(m, pose)
            self._spine_leg_rot[g.legs] = leg_frames(m, pose)
            aj = int(m.key_joint[m.anchor_key])
            frame = pose.joint_frame[:, aj]
            self.pos[g.chars] = pose.joints[:, aj] - np.einsum("cij,j->ci", frame, m.joint_rest[aj])
            self.yaw[g.chars] = np.arctan2(frame[:, 1, 0], frame[:, 0, 0])
            self.pitch[g.chars] = np.arctan2(frame[:, 2, 0], np.hypot(frame[:, 0, 0], frame[:, 1, 0]))
            self.roll[g.chars] = 0.0
            self.height_target[g.chars] = self.pos[g.chars, 2]

    def _release_pull(
        self, g: _SpineGroup, free: SpinePose, pulled: SpinePose, feet: FloatArray, reach: FloatArray,
        dt: float,
    ) -> tuple[SpinePose, FloatArray]:
        """A node pulled toward a stretched leg's foot goes back to its guide over
        ``reach_release_time``, not in one frame when the foot steps (the chest would drop and
        spring back by centimetres per frame); the pull itself acts at once. ``free``: step
        4 without pulls, ``pulled``: with this frame's pulls. Returns the pose and each
        node's guide shift ``(g, K, 3)`` (kept for the next frame)."""
        need = pulled.guide_xyz - free.guide_xyz
        if g.reach_shift is None or g.reach_shift.shape != need.shape or dt <= 0.0:
            return pulled, need
        decayed = g.reach_shift * float(np.exp(-dt / max(self.params.reach_release_time, 1e-9)))
        keep = vector_norm(decayed) > vector_norm(need)
        if not np.any(keep):
            return pulled, need
        trial = np.where(keep[..., None], decayed, need)
        m = g.model
        slow = refit(m, free, free.guide_xyz + trial)
        # kept only where it leaves no leg further from its foot than the pull did
        over = vector_norm(feet - hip_positions(m, slow)) > np.maximum(
            vector_norm(feet - hip_positions(m, pulled)), reach
        ) + 1e-9
        ok = ~over.any(axis=1)
        rows = np.flatnonzero(ok)
        pose = pose_with_rows(pulled, rows, pose_rows(slow, rows)) if rows.size else pulled
        return pose, np.where(ok[:, None, None], trial, need)

    def _spine_reach(self, g: _SpineGroup) -> FloatArray:
        """``(g, L)`` how far each leg of a spine group may reach before it pulls its node
        toward its foot: the guard's reach for a planted foot; for a swinging one (which pulls
        as if already down at its landing height), more the earlier in its swing
        (``swing_reach_slack``), so that the body lowers gradually over a swing down a step,
        not all at once as the foot lands."""
        legs = g.legs
        early = 1.0 - self._swing_u[legs]
        slack = np.where(self.swinging[legs], self.params.swing_reach_slack * early, 0.0)
        return np.asarray(self.guard_reach[legs] * (1.0 + slack))

    def _landing_refs(
        self, legs: IntArray, ctl: StepControls, remaining: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Where the body part each leg in ``legs`` hangs from will be when the foot lands
        ``remaining (N,)`` seconds from now: ground position ``(m, 2)``, heading ``(m,)``, and
        that part's rest position ``(m, 3)`` and rest heading ``(m,)`` in the body frame.

        A rigid pelvis is extrapolated with its speed and bounded turn. A spine node moves
        along the spine it is on (the nodes follow the head's path, thesis §4.2.2) and past
        the head along the head's own extrapolated arc."""
        p = self.params
        c_of = self.leg_char[legs]
        turn = np.clip(
            wrap_angle(ctl.heading[c_of] - self.yaw[c_of]),
            -p.max_turn_rate * remaining[legs],
            p.max_turn_rate * remaining[legs],
        )
        yaw_land = self.yaw[c_of] + turn
        yaw_mid = self.yaw[c_of] + 0.5 * turn
        travel = (ctl.speed[c_of] * remaining[legs])[:, None] * np.stack(
            [np.cos(yaw_mid), np.sin(yaw_mid)], axis=1
        )
        ref_xy = self.pos[c_of, :2] + travel
        ref_rest = np.zeros((legs.size, 3))
        rest_yaw = np.zeros(legs.size)
        for g in self.spine_groups:
            rows = np.flatnonzero(np.isin(c_of, g.chars))
            if rows.size == 0:
                continue
            m, plan = g.model, g.plan
            chars = c_of[rows]
            r = np.searchsorted(g.chars, chars)
            k = m.leg_key[legs[rows] - self.legs.leg_start[chars]]
            xy = plan.key_xy[r]  # (m, K, 2)
            heading = plan.key_heading[r]
            arc = np.concatenate([np.zeros((rows.size, 1)),
                                  np.cumsum(vector_norm(xy[:, 1:] - xy[:, :-1]), axis=1)], axis=1)
            speed = ctl.speed[chars]
            dist = speed * remaining[legs[rows]]
            at = np.arange(rows.size)
            s = arc[at, k] - dist
            # on the spine: between node i and node i + 1
            i = np.clip(np.sum(arc[:, 1:-1] < s[:, None], axis=1), 0, m.n_keys - 2)
            span = arc[at, i + 1] - arc[at, i]
            f = np.clip((s - arc[at, i]) / np.maximum(span, 1e-12), 0.0, 1.0)
            on_xy = xy[at, i] + f[:, None] * (xy[at, i + 1] - xy[at, i])
            on_yaw = heading[at, i] + f * wrap_angle(heading[at, i + 1] - heading[at, i])
            # past the head: the head's arc toward the commanded heading
            ahead = np.maximum(-s, 0.0)
            limit = g.params.turn_rate * ahead / np.maximum(speed, 1e-9)
            head_turn = np.clip(wrap_angle(ctl.heading[chars] - plan.steer_heading[r]), -limit, limit)
            mid = heading[:, 0] + 0.5 * head_turn
            past_xy = xy[:, 0] + ahead[:, None] * np.stack([np.cos(mid), np.sin(mid)], axis=1)
            past = s < 0.0
            ref_xy[rows] = np.where(past[:, None], past_xy, on_xy)
            yaw_land[rows] = np.where(past, heading[:, 0] + head_turn, on_yaw)
            ref_rest[rows] = m.key_rest[k]
            rest_yaw[rows] = m.rest_key_heading[k]
        return ref_xy, yaw_land, ref_rest, rest_yaw

    # ---------------------------------------------------------------- feet
    def _land(self, landing: BoolArray) -> None:
        legs = np.flatnonzero(landing)
        if legs.size == 0:
            return
        self.foot[legs] = self.target[legs]
        self.support_z[legs] = self._surface(self.target[legs, :2])
        self.forced[legs] = False
        self.swinging[legs] = False
        self.dodged[legs] = False
        self._watch_reset(legs)

    # ------------------------------------------------- watching for moving obstacles
    def _watched_spot(self, legs: IntArray) -> FloatArray:
        """``(m, 3)`` the spot watched for each leg: where a planted foot stands, where a
        swinging foot will land."""
        return np.asarray(np.where(self.swinging[legs, None], self.target[legs], self.foot[legs]))

    def _watch_reset(self, legs: IntArray, spot: FloatArray | None = None) -> None:
        """Remember what is around the watched spots of ``legs`` (or ``spot (m, 3)``) now (a
        foot landed, or a swing was planned)."""
        if not self.env_dynamic or legs.size == 0:
            return
        at = self._watched_spot(legs) if spot is None else spot
        pts = (at[:, None, :2] + self._watch_offsets[legs]).reshape(-1, 2)
        self.watch_ground[legs] = self.env.height_at(pts).reshape(legs.size, -1)
        self.watch_forbidden[legs] = self.env.forbidden_at(pts).reshape(legs.size, -1)

    def _watch(self, legs: IntArray) -> tuple[FloatArray, BoolArray, BoolArray]:
        """Query the watched spots of ``legs`` and the rings around them (one query).

        Returns the surface ``(m,)`` and forbidden flags ``(m,)`` at the spots, and whether a
        moving obstacle closes in on each spot ``(m,)`` (since the last look, a ring point rose
        above the spot or became forbidden). The rings' memory moves on to now."""
        m = legs.size
        k = self._watch_offsets.shape[1]
        spot = self._watched_spot(legs)
        ring = spot[:, None, :2] + self._watch_offsets[legs]
        xy = np.concatenate([spot[:, :2], ring.reshape(-1, 2)])
        heights = self.env.height_at(xy)
        forbidden = self.env.forbidden_at(xy)
        tol = self.params.support_tolerance
        ring_h = heights[m:].reshape(m, k)
        ring_f = forbidden[m:].reshape(m, k)
        rose = (ring_h > self.watch_ground[legs] + tol) & (ring_h > spot[:, 2, None] + tol)
        coming = (rose | (ring_f & ~self.watch_forbidden[legs])).any(axis=1)
        self.watch_ground[legs] = ring_h
        self.watch_forbidden[legs] = ring_f
        return heights[:m], forbidden[:m], coming

    def _replan_needed(self, ctl: StepControls, progress: FloatArray, gait_swing: BoolArray) -> BoolArray:
        p = self.params
        swing = self.swinging & (gait_swing | self.forced)
        leg_len = self.legs.leg_length
        lc = self.leg_char
        early = progress < p.replan_until
        heading = np.abs(wrap_angle(ctl.heading[lc] - self.plan_heading)) > p.replan_heading
        v, v0 = ctl.speed[lc], self.plan_speed
        speed = np.abs(v - v0) > np.maximum(p.replan_speed * np.maximum(v, v0), 0.05 * leg_len)
        spacing = vector_norm(ctl.spacing - self.plan_spacing) > p.replan_spacing * leg_len
        need = swing & early & (heading | speed | spacing)
        self.blocked[:] = False
        if self.env_dynamic:
            self.blocked = swing & self._trajectory_blocked(swing, progress)
            need |= self.blocked
        return need

    def _trajectory_blocked(self, swing: BoolArray, progress: FloatArray) -> BoolArray:
        """Swinging feet whose remaining trajectory or target a moving obstacle now cuts."""
        legs = np.flatnonzero(swing)
        out = np.zeros(self.n_legs, dtype=bool)
        if legs.size == 0:
            return out
        k_all = self.traj.shape[1]
        # every other sample (and the landing one): a few centimetres apart on a stride
        cols = np.unique(np.concatenate([np.arange(0, k_all, 2), [k_all - 1]]))
        k = cols.size
        u = np.clip(
            (progress[legs] - self.traj_u0[legs]) / np.maximum(1.0 - self.traj_u0[legs], 1e-9), 0.0, 1.0
        )
        ahead = np.linspace(0.0, 1.0, k_all)[cols][None, :] >= u[:, None]
        pts = self.traj[legs][:, cols]
        flat = pts.reshape(-1, 3)
        surface = self.env.height_at(flat[:, :2]).reshape(legs.size, k)
        forbidden = self.env.forbidden_at(flat[:, :2]).reshape(legs.size, k)
        tol = self.params.support_tolerance
        # only what changed since the plan counts: something rose into the path, or became forbidden
        risen = (surface > self.traj_ground[legs][:, cols] + tol) & (surface > pts[..., 2] + tol)
        cut = ahead & (risen | (forbidden & ~self.traj_forbidden[legs][:, cols]))
        # the landing spot itself must still be there
        land_surface = surface[:, -1]
        moved = np.abs(land_surface - self.support_target[legs]) > tol
        # and nothing moving may be closing in on it (once per swing: a foot that already
        # moved its landing spot away lands; _spot_taken still stops it landing on the obstacle)
        coming = self._watch(legs)[2] & ~self.dodged[legs]
        self.dodged[legs] |= coming
        out[legs] = cut.any(axis=1) | moved | coming
        return out

    def _check_supports(self) -> BoolArray:
        """Planted feet whose support moved, rose into them or became forbidden (thesis
        sequence 4)."""
        planted = ~self.swinging
        out = np.zeros(self.n_legs, dtype=bool)
        if not self.env_dynamic or not np.any(planted):
            return out
        legs = np.flatnonzero(planted)
        # the foot's own spot, and something moving closing in around it (it steps away
        # before the obstacle reaches it)
        surface, forbidden, coming = self._watch(legs)
        tol = self.params.support_tolerance
        buried = surface > self.foot[legs, 2] + tol
        bad = (np.abs(surface - self.support_z[legs]) > tol) | buried
        out[legs] = bad | forbidden | coming
        if np.any(buried):
            # an obstacle slid under a planted foot anyway: it pushes the foot out (the foot
            # steps off from there)
            at = legs[buried]
            self._push_out(at, surface[buried])
            self.support_z[at] = self._surface(self.foot[at, :2])
        return out

    def _push_out(self, legs: IntArray, surface: FloatArray) -> None:
        """Feet of ``legs`` that a moving obstacle ran into (its top ``surface (m,)`` is above
        them) are pushed out of it the shorter way: up onto its top (never onto an avoided
        obstacle while there is room beside it), or aside to the nearest point around them
        (the watch rings, one to three times as far) that is free at their height and within
        the leg's reach."""
        m = legs.size
        offsets = np.concatenate([f * self._watch_offsets[legs] for f in (1.0, 2.0, 3.0)], axis=1)
        k = offsets.shape[1]
        here = self.foot[legs, :2]
        pts = np.concatenate([here, (here[:, None, :] + offsets).reshape(-1, 2)])
        heights = self.env.height_at(pts)
        forbidden = self.env.forbidden_at(pts)
        ring_h = heights[m:].reshape(m, k)
        ring_f = forbidden[m:].reshape(m, k)
        z = self.foot[legs, 2]
        tol = self.params.support_tolerance
        free = (ring_h <= z[:, None] + tol) & ~ring_f & (ring_h > _VOID)
        # within the leg's reach
        hips = self.hips_world()[legs]
        top = np.maximum(ring_h, z[:, None])
        spots = np.concatenate([here[:, None, :] + offsets, top[..., None]], axis=2)
        free &= vector_norm(spots - hips[:, None, :]) <= self.guard_reach[legs, None]
        # the nearest ring with room, and on it the point facing away from the obstacle
        # (the mean direction of the points it covers), so the foot is not pushed ahead of it
        radius = np.linalg.norm(offsets, axis=2)
        unit = offsets / np.maximum(radius, 1e-12)[..., None]
        covered = np.where(~free[..., None], unit, 0.0).sum(axis=1)
        norm = np.maximum(np.linalg.norm(covered, axis=1), 1e-12)
        away = -np.einsum("mkd,md->mk", unit, covered) / norm[:, None]
        ring_no = np.repeat(np.arange(3), k // 3)[None, :]
        first = np.min(np.where(free, ring_no, 3), axis=1)
        rank = np.where(free & (ring_no == first[:, None]), away, -np.inf)
        pick = np.argmax(rank, axis=1)
        best = np.where(free.any(axis=1), radius[np.arange(m), pick], np.inf)
        aside = (best < surface - z) | (forbidden[:m] & np.isfinite(best))
        side, up = legs[aside], legs[~aside]
        self.foot[side, :2] += offsets[aside, pick[aside]]
        self.foot[side, 2] = np.maximum(self.foot[side, 2], ring_h[aside, pick[aside]])
        self.foot[up, 2] = surface[~aside]

    def _catch_up_time(self, ctl: StepControls, swing_time: FloatArray) -> FloatArray:
        """Seconds ``(N,)`` a foot left behind takes to come back under its rest place at
        twice the mean ground speed of a gait swing (its stride over its swing time), at
        most a cycle: a foot held back for cycles (its plans failed) covers more than a
        stride, and in a forced step's fixed share of a swing its leg would whip over."""
        share = np.maximum(self.gait.disk_duration, 1e-9)
        cycle = swing_time / share  # the needle's cycle now (sped up for long strides)
        stride_speed = ctl.speed[self.leg_char] / share
        rot = self.leg_rotations()
        rest = self.hips_world() + np.einsum("nij,nj->ni", rot, self.legs.rest_foot - self.legs.hip_offset)
        gap = vector_norm(rest[:, :2] - self.foot[:, :2])
        return np.asarray(np.minimum(gap / np.maximum(2.0 * stride_speed, 1e-9), cycle))

    def _overstretched(self) -> tuple[BoolArray, FloatArray]:
        """Planted feet left so far behind (or aside) that keeping them would need the pelvis
        to drop more than ``max_drop`` of its body thickness: they step early. (A spine's
        hips are taken where the spine would put them before step 4 pulls them toward the
        feet: a foot left behind must step, not drag the body back.) Also returns how far
        the pelvis would have to drop for each foot ``(N,)`` (inf: beyond reach)."""
        planted = ~self.swinging
        hips = self.hips_world()
        # judged from the height the pelvis wants, not from where the reach guard has already
        # lowered it (else a foot dragging the pelvis down never counts as left behind)
        hips[:, 2] += self.guard_drop[self.leg_char]
        if self.spine_groups:
            hips[self.spine_legs] = self._spine_hips_free[self.spine_legs]
        reach = self.comfort_reach
        d_h = vector_norm(hips[:, :2] - self.foot[:, :2])
        top = self.foot[:, 2] + self.foot_lift + np.sqrt(np.maximum(reach * reach - d_h * d_h, 0.0))
        need = np.where(d_h < reach, hips[:, 2] - top, np.inf)
        over = planted & (need > self.params.max_drop * self.body_thickness[self.leg_char])
        return np.asarray(over), np.asarray(need, dtype=np.float64)

    def _wait_for_support(self, candidates: BoolArray, stretch: FloatArray, lifted: BoolArray) -> BoolArray:
        """Which feet left behind (``candidates``) wait a little before their forced step:
        those that would leave their character with fewer than ``min_planted`` feet on the
        ground (a walking wolf or human does not fling every foot up at once), as long as
        the pelvis would have to drop less than ``urgent_drop`` (× body thickness) to keep
        them (``stretch (N,)``, metres; the reach guard lowers it meanwhile) and its leg
        still reaches it. The most stretched feet of a character go first."""
        wait = np.zeros(self.n_legs, dtype=bool)
        if not np.any(candidates):
            return wait
        p = self.params
        airborne = self.swinging | lifted
        down = np.bincount(self.leg_char, weights=(~airborne).astype(np.float64), minlength=self.n_chars)
        n_legs = np.bincount(self.leg_char, minlength=self.n_chars)
        need = np.minimum(p.min_planted, n_legs - 1)
        urgent = stretch > p.urgent_drop * self.body_thickness[self.leg_char]
        if self.ik_result is not None:  # a planted foot its leg no longer reaches: now
            urgent |= self.ik_result.error > 1e-3 * self.legs.leg_length
        for leg in np.flatnonzero(candidates)[np.argsort(-stretch[candidates], kind="stable")].tolist():
            c = int(self.leg_char[leg])
            if urgent[leg] or down[c] - 1 >= need[c]:
                down[c] -= 1  # this one steps
            else:
                wait[leg] = True
        return wait

    def _spot_taken(self, points: FloatArray, which: BoolArray) -> BoolArray:
        """Whether a moving obstacle now covers the footprints ``points (N, 3)`` of legs
        ``which (N,)`` (rose above them or made them forbidden since they were planned)."""
        out = np.zeros(self.n_legs, dtype=bool)
        legs = np.flatnonzero(which)
        if not self.env_dynamic or legs.size == 0:
            return out
        xy = points[legs, :2]
        surface = self.env.height_at(xy)
        newly_forbidden = self.env.forbidden_at(xy) & ~self.traj_forbidden[legs, -1]
        out[legs] = (surface > points[legs, 2] + self.params.support_tolerance) | newly_forbidden
        return out

    def _plan(
        self,
        legs: IntArray,
        ctl: StepControls,
        start_u: FloatArray,
        remaining: FloatArray,
        stance_time: FloatArray,
        land_stance: FloatArray,
        stats: StepStats,
        timer: _Timer,
    ) -> None:
        """Plan the best couple of every leg in ``legs``.

        ``start_u (N,)``: the swing progress at which the new trajectory starts (where the
        foot is now). A failed re-plan of a foot already in the air keeps its trajectory; a
        failed plan of a foot on the ground leaves it there (``plan_failed``).

        ``remaining (N,)``: seconds left of each swing; ``stance_time (N,)``: the following
        stance's duration; ``land_stance (N,)``: the stance fraction already gone when the foot
        lands (0 for a gait swing, more for a forced step in the middle of a stance).
        """
        p = self.params
        lc = self.leg_char
        legs_data = self.legs
        c_of = lc[legs]
        # predicted pelvis (or spine node) pose at each foot's touch-down
        pelvis_land, yaw_land, ref_rest, rest_yaw = self._landing_refs(legs, ctl, remaining)
        # land so the foot passes under its rest position at mid-stance (figure 3.6, 3.7)
        sweep = (0.5 - land_stance[legs]) * ctl.speed[c_of] * stance_time[legs]
        offset = (
            legs_data.rest_foot[legs, :2]
            - ref_rest[:, :2]
            + ctl.spacing[legs]
            + np.column_stack([sweep, np.zeros(legs.size)])
        )
        preferred_xy = pelvis_land + self._rotate_xy(offset, yaw_land - rest_yaw)
        self.preferred[legs, :2] = preferred_xy
        self.preferred[legs, 2] = self._surface(preferred_xy)
        # reach is judged from the hips halfway through the coming stance: a footprint within
        # the reach minus half the sweep stays within reach from touch-down to lift-off
        rest_stance = (1.0 - land_stance[legs]) * stance_time[legs]
        pelvis_ref = pelvis_land + (0.5 * ctl.speed[c_of] * rest_stance)[:, None] * np.stack(
            [np.cos(yaw_land), np.sin(yaw_land)], axis=1
        )
        low = self.rest_height[legs] * (1.0 - p.max_drop)
        horizontal = np.sqrt(np.maximum(self.comfort_reach[legs] ** 2 - low * low, 0.0))
        sweep_half = 0.5 * ctl.speed[c_of] * rest_stance
        reach = np.maximum(
            horizontal - sweep_half,
            self.rest_horizontal[legs] + 0.5 * p.candidate_radius * legs_data.leg_length[legs],
        )
        hip_offset_xy = legs_data.hip_offset[:, :2]
        hip_now = self.hips_world()[legs]
        row_of = {int(leg): j for j, leg in enumerate(legs.tolist())}
        timer.lap("rest")
        k = p.trajectory_samples
        u_grid = np.linspace(0.0, 1.0, k + 1)
        done: list[tuple[int, int, int, FloatArray, FloatArray]] = []
        # every window of the step in one call (the moving crates near any of them are
        # rasterised together), then every foot in one plan_footsteps call
        chars = np.unique(c_of).tolist()
        windows = [
            WindowParams(
                n_cells=p.window_cells,
                cell=float(self.window_cell[c]),
                foot_half_extents=(float(self.foot_half[c, 0]), float(self.foot_half[c, 1])),
                foot_yaw=float(self.yaw[c]),
            )
            for c in chars
        ]
        grids_of = dict(zip(chars, self.env.windows(self.pos[chars, :2], windows), strict=True))
        stats.n_windows += len(chars)
        timer.lap("maps")
        requests: list[FootRequest] = []
        rows_of: list[tuple[int, int, int, FloatArray]] = []
        for c in chars:
            sl = legs_data.leg_slice(c)
            for leg in legs[c_of == c].tolist():
                j = row_of[leg]
                params = self.planner_params(c, float(ctl.step_height[c]), float(reach[j]), leg,
                                             float(sweep_half[j]), sink=not self.forced[leg])
                hips = pelvis_ref[j] + self._rotate_xy(
                    hip_offset_xy[sl] - ref_rest[j, :2],
                    np.full(sl.stop - sl.start, yaw_land[j] - rest_yaw[j]),
                )
                own = leg - sl.start
                others = np.ones(sl.stop - sl.start, dtype=bool)
                others[own] = False
                other_idx = np.arange(sl.start, sl.stop)[others]
                # other feet: where they stand, or where swinging ones will land
                other_feet = np.where(
                    self.swinging[other_idx, None], self.target[other_idx, :2], self.foot[other_idx, :2]
                )
                requests.append(FootRequest(grids_of[c], self.foot[leg], preferred_xy[j], hips[own],
                                            hips[others], other_feet, params, float(yaw_land[j]),
                                            float(hip_now[j, 2])))
                rows_of.append((leg, j, c, hips[own]))
        couples = plan_footsteps(requests)
        # every footprint near the preferred one is taken (an obstacle, another foot): look
        # twice as far before giving up
        wide = [i for i, cp in enumerate(couples) if not cp.ok and cp.n_targets == 0]
        if wide:
            again = plan_footsteps([
                replace(requests[i], params=replace(
                    requests[i].params,
                    candidate_radius=2.0 * requests[i].params.candidate_radius,
                    fixed_distance=2.0 * requests[i].params.fixed_distance,
                ))
                for i in wide
            ])
            for i, cp in zip(wide, again, strict=True):
                couples[i] = cp
        # a foot that must move, crowded by the other feet or boxed in by slices: try without them
        relax = [i for i, cp in enumerate(couples) if not cp.ok and self.forced[rows_of[i][0]]]
        if relax:
            none = np.zeros((0, 2))
            again = plan_footsteps([
                replace(requests[i], other_hips_xy=none, other_feet_xy=none, params=replace(
                    requests[i].params,
                    candidate_radius=2.0 * requests[i].params.candidate_radius,
                    fixed_distance=2.0 * requests[i].params.fixed_distance,
                    slice_size=None,
                ))
                for i in relax
            ])
            for i, cp in zip(relax, again, strict=True):
                couples[i] = cp
            stats.n_relaxed += len(relax)
        for (leg, j, c, hip_own), couple in zip(rows_of, couples, strict=True):
            stats.n_plans += 1
            stats.n_couples += couple.n_couples
            stats.n_paths += couple.n_paths
            samples = couple.trajectory.point_at(u_grid) if couple.trajectory is not None else None
            hip_land = pelvis_land[j] + hip_own - pelvis_ref[j]
            # a swing that would leave the leg's reach is not taken, unless the foot must
            # move (its way out may be a detour)
            if (
                couple.ok
                and samples is not None
                and (self.forced[leg] or self._within_reach(leg, samples, hip_now[j], hip_land))
            ):
                target = np.asarray(couple.footprint, dtype=np.float64).copy()
            elif ((self.forced[leg] and not self.swinging[leg]) or self.blocked[leg]) and (
                straight := self._straight_step(
                    leg, self.foot[leg], preferred_xy[j], u_grid, float(ctl.step_height[c]),
                    p.candidate_radius * float(legs_data.leg_length[leg]), hip_now[j], hip_land,
                )
            ) is not None:
                # a foot that must move (left behind, or its support gone), or whose swing a
                # moving obstacle cut, and that the planner cannot serve steps straight to its
                # preferred spot (or the nearest one it can)
                samples, target = straight
                stats.n_failed += 1
                stats.n_fallback += 1
            else:
                stats.n_failed += 1
                if not self.swinging[leg]:
                    self.plan_failed[leg] = True
                    # a foot that must move tries again at the next step (the body moved)
                    self.forced[leg] = False
                continue
            self.plan_failed[leg] = False
            done.append((leg, j, c, samples, target))
        timer.lap("planning")
        if not done:
            return
        # every new trajectory at once: land on the exact surface under the foot's point
        # (the planner's grid height is the highest point under the whole foot box), easing
        # the change in over the second half of the swing
        leg_ids = np.array([d[0] for d in done])
        rows = np.array([d[1] for d in done])
        chars = np.array([d[2] for d in done])
        samples_all = np.stack([d[3] for d in done])
        targets = np.stack([d[4] for d in done])
        ease = np.clip((u_grid - 0.5) / 0.5, 0.0, 1.0)
        ease = ease * ease * (3.0 - 2.0 * ease)
        # a footprint whose point hangs over a hole (its foot box only partly on the edge)
        # moves onto the ground its box reaches, over the second half of the swing
        hole = self.env.height_at(targets[:, :2]) <= _VOID
        for i in np.flatnonzero(hole).tolist():
            shift = self._onto_support(targets[i, :2], int(chars[i]))
            if shift is not None:
                samples_all[i, :, :2] += shift[None, :] * ease[:, None]
                targets[i, :2] += shift
        exact = self._surface(targets[:, :2])
        drop = targets[:, 2] - exact
        snap = ((drop >= -1e-9) & (drop <= p.snap_tolerance * ctl.step_height[chars])) | (
            exact > targets[:, 2]
        )
        samples_all[..., 2] -= np.where(snap, drop, 0.0)[:, None] * ease[None, :]
        targets[:, 2] = np.where(snap, exact, targets[:, 2])
        samples_all[:, -1] = targets
        self.traj[leg_ids] = samples_all
        if self.env_dynamic:
            flat = samples_all[..., :2].reshape(-1, 2)
            self.traj_ground[leg_ids] = self.env.height_at(flat).reshape(leg_ids.size, -1)
            self.traj_forbidden[leg_ids] = self.env.forbidden_at(flat).reshape(leg_ids.size, -1)
        self.traj_u0[leg_ids] = start_u[leg_ids]
        self.target[leg_ids] = targets
        self.support_target[leg_ids] = exact
        self._watch_reset(leg_ids, targets)
        self.plan_heading[leg_ids] = ctl.heading[chars]
        self.plan_speed[leg_ids] = ctl.speed[chars]
        self.plan_spacing[leg_ids] = ctl.spacing[leg_ids]
        self.feedback[leg_ids] = targets[:, :2] - preferred_xy[rows]
        timer.lap("rest")

    def _onto_support(self, xy: FloatArray, char: int) -> FloatArray | None:
        """The shortest shift ``(2,)``, within the foot box's size or a planning cell,
        whichever is more (the planner sees the ground per cell), that puts a footprint's
        point ``xy`` over ground (not over a hole, not into an avoided obstacle), with a
        quarter of the box's half size to spare; None if there is none."""
        half = float(np.max(self.foot_half[char]))
        if half <= 0.0:
            return None
        radius = max(2.0 * half, float(self.window_cell[char]))
        grid = np.linspace(-radius, radius, 17)
        off = np.stack(np.meshgrid(grid, grid, indexing="ij"), axis=-1).reshape(-1, 2)
        off = off[np.argsort(np.hypot(off[:, 0], off[:, 1]), kind="stable")][1:]
        norm = np.hypot(off[:, 0], off[:, 1])[:, None]
        spare = off + 0.25 * half * off / np.maximum(norm, 1e-12)
        pts = np.concatenate([xy[None, :] + off, xy[None, :] + spare])
        ok = (self.env.height_at(pts) > _VOID) & ~self.env.forbidden_at(pts)
        good = ok[: off.shape[0]] & ok[off.shape[0]:]
        if not np.any(good):
            return None
        return np.asarray(spare[int(np.flatnonzero(good)[0])], dtype=np.float64)

    def _within_reach(
        self, leg: int, samples: FloatArray, hip_start: FloatArray, hip_end_xy: FloatArray
    ) -> bool:
        """Whether a swing ``samples (k + 1, 3)`` stays within leg ``leg``'s length of its hip
        moving from ``hip_start (3,)`` to ``hip_end_xy (2,)`` at touch-down (rising or sinking
        with the feet), the pelvis lowered as far as the reach guard ever lowers it. The
        planner's paths may detour around obstacles farther than a leg reaches; such a couple
        is not taken."""
        dist = self._hip_distance(leg, samples, hip_start, hip_end_xy)
        u = np.linspace(0.0, 1.0, samples.shape[0])
        return bool(np.all(dist <= self._reach_bound(leg, float(dist[0]), u)))

    def _hip_distance(
        self, leg: int, samples: FloatArray, hip_start: FloatArray, hip_end_xy: FloatArray
    ) -> FloatArray:
        """``(..., k + 1)`` distances of swing samples ``(..., k + 1, 3)`` to the hip of ``leg``
        moving from ``hip_start (3,)`` to ``hip_end_xy (..., 2)`` (see ``_within_reach``)."""
        u = np.linspace(0.0, 1.0, samples.shape[-2])
        end_xy = np.broadcast_to(hip_end_xy, (*samples.shape[:-2], 2))
        end = np.concatenate(
            [end_xy, (hip_start[2] + samples[..., -1, 2] - samples[..., 0, 2])[..., None]], axis=-1
        )
        hip = hip_start + u[:, None] * (end[..., None, :] - hip_start)
        horizontal = np.linalg.norm(samples[..., :2] - hip[..., :2], axis=-1)
        drop = self.params.guard_max_drop * float(self.body_thickness[self.leg_char[leg]])
        below = hip[..., 2] - (samples[..., 2] + self.foot_lift[leg])
        vertical = np.where(below > 0.0, np.maximum(below - drop, 0.0), -below)
        return np.asarray(np.hypot(horizontal, vertical))

    def _reach_bound(self, leg: int, start: float, u: FloatArray) -> FloatArray:
        """How far a swing's samples at ``u`` may be from the hip: the leg's length, or for a
        foot that starts beyond it (left behind), a bound shrinking from there to it."""
        length = float(self.legs.leg_length[leg])
        return np.asarray(length + max(start - length, 0.0) * (1.0 - u))

    def _straight_step(
        self, leg: int, start: FloatArray, target_xy: FloatArray, u: FloatArray, step_height: float,
        search: float, hip_start: FloatArray, hip_end_xy: FloatArray,
    ) -> tuple[FloatArray, FloatArray] | None:
        """Last resort when the planner finds no couple for a foot that must move: a straight
        arc lifted ``step_height`` over what it crosses, to ``target_xy`` or else the nearest
        spot around it (up to the step's length or ``search`` metres away, whichever is more)
        that the leg can step to: landing on a surface outside avoided obstacles, the line not
        through an avoided obstacle (a foot standing on one may leave across it), and nothing
        on the way taller, above the higher end, than the leg's hip stands above its foot at
        rest less ``step_height`` (higher, the leg could not fold enough to pass). None when
        there is no such spot: the foot stays rather than step onto air or out of reach.

        Returns the samples ``(k + 1, 3)`` at ``u (k + 1,)`` and the landing point ``(3,)``."""
        reach = max(float(np.linalg.norm(target_xy - start[:2])), search) + 1e-3
        ring = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
        radii = np.linspace(0.1, 1.0, 6) * reach
        dirs = np.stack([np.cos(ring), np.sin(ring)], axis=1)
        around = target_xy[None, None, :] + radii[:, None, None] * dirs[None, :, :]
        spots = np.concatenate([target_xy[None, :], around.reshape(-1, 2)])  # nearest first
        n_u = u.shape[0]
        xy = start[None, None, :2] + u[None, :, None] * (spots - start[:2])[:, None, :]
        flat = xy.reshape(-1, 2)
        surface = self.env.height_at(flat).reshape(-1, n_u)
        forbidden = self.env.forbidden_at(flat).reshape(-1, n_u)
        landing = (surface[:, -1] > _VOID) & ~forbidden[:, -1]
        # leaving an avoided obstacle the foot stands on is allowed; entering one is not
        leaving = np.logical_and.accumulate(forbidden, axis=1)
        crossing = (forbidden & ~leaving)[:, 1:-1].any(axis=1)
        end_z = np.where(surface[:, -1] > _VOID, surface[:, -1], start[2])
        # the arc rises from the ground under the start (a foot already in the air is not
        # lifted a step height above where it is: re-plan after re-plan it would ratchet up)
        z0 = min(float(start[2]), float(surface[0, 0])) if surface[0, 0] > _VOID else float(start[2])
        base = z0 + u[None, :] * (end_z - z0)[:, None]
        # a foot leaving an avoided obstacle that came at it goes out sideways at its height
        # (as the planner's swings do, pathing.clearance_elevation), not over the top
        tall = leaving & (surface > start[2] + step_height)
        under = np.where((surface > _VOID) & ~tall, surface, base)
        climb = np.maximum((under - base).max(axis=1), 0.0)
        rest = float(self.rest_height[leg])
        ok = landing & ~crossing & (climb <= max(rest - step_height, 0.25 * rest))
        lift = climb + step_height
        z = base + 4.0 * u[None, :] * (1.0 - u[None, :]) * lift[:, None]
        # from where the foot is: never below the straight line from it down to the landing
        z = np.maximum(z, start[2] + u[None, :] * (end_z - start[2])[:, None])
        z[:, 0] = start[2]
        inner = (u > 0.0) & (u < 1.0)
        # clear of the ground at each sample and at its neighbours: the polyline between two
        # samples must not cut the edge of a stair or crate lying between them
        near = under.copy()
        near[:, 1:] = np.maximum(near[:, 1:], under[:, :-1])
        near[:, :-1] = np.maximum(near[:, :-1], under[:, 1:])
        z[:, inner] = np.maximum(z[:, inner], near[:, inner] + 0.25 * step_height)
        # and within the leg's length of the hip all the way (the hip moving to touch-down)
        pts = np.concatenate([xy, z[..., None]], axis=2)
        dist = self._hip_distance(leg, pts, hip_start, hip_end_xy)
        ok &= (dist <= self._reach_bound(leg, float(dist[0, 0]), u)[None, :]).all(axis=1)
        if not np.any(ok):
            return None
        k = int(np.flatnonzero(ok)[0])
        return self._clear_end_segments(pts[k].copy(), step_height), np.array(
            [spots[k, 0], spots[k, 1], float(end_z[k])]
        )

    def _clear_end_segments(self, pts: FloatArray, step_height: float) -> FloatArray:
        """The first and last segments of a straight step's samples ``pts (k + 1, 3)`` made
        to clear any ground edge they cross (a foot lifting off just below a stair, or
        landing just past one): the foot then rises straight up from its start, or comes
        straight down onto its landing, from the height of the ground it passes."""
        if pts.shape[0] < 3:
            return pts
        t = np.linspace(0.0, 1.0, 33)[1:-1]
        for a, b, moved in ((0, 1, 1), (-1, -2, -2)):
            line = pts[a][None, :] + t[:, None] * (pts[b] - pts[a])[None, :]
            ground = self.env.height_at(line[:, :2])
            if np.any(ground > line[:, 2]):
                pts[moved, :2] = pts[a, :2]
                pts[moved, 2] = max(float(pts[moved, 2]), float(ground.max()) + 0.25 * step_height)
        return pts

    def _apply_feedback(self, dt: float) -> None:
        """Thesis figure 3.9: move the pelvis by the mean footprint error when it matters."""
        p = self.params
        c = self.n_chars
        mean: FloatArray = np.stack(
            [np.bincount(self.leg_char, weights=self.feedback[:, k], minlength=c) for k in (0, 1)], axis=1
        )
        mean = mean / np.bincount(self.leg_char, minlength=c)[:, None]
        significant = vector_norm(mean) > p.feedback_threshold * self.char_leg_length
        if not np.any(significant):
            return
        share = np.clip(p.feedback_gain * dt / self.gait.cycle_time, 0.0, 1.0)
        move = np.where(significant[:, None], mean * share[:, None], 0.0)
        self.pos[:, :2] += move
        for g in self.spine_groups:
            shift = move[g.chars]
            g.plan.key_xy[...] += shift[:, None, :]
            self._spine_hips[g.legs, :2] += shift[:, None, :]
            self._spine_hips_free[g.legs, :2] += shift[:, None, :]
        # the part worked off is consumed
        self.feedback -= np.where(
            significant[self.leg_char, None], self.feedback * share[self.leg_char, None], 0.0
        )

    # ---------------------------------------------------------------- pelvis
    def _hull_pose(
        self, ctl: StepControls, chars: IntArray | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Hull height (+ body thickness), pitch and roll under each character (or only
        under ``chars``; the results are then ``(len(chars),)``).

        Thesis figure 3.8 works on a vertical slice along the body: the terrain under the body
        box is sampled on a grid and reduced to its highest point across the body at each
        position along it (and along the body at each position across it, for roll), then the
        planted feet (and the targets of swinging ones) are added.
        """
        if chars is None:
            pos, yaw, box_center, box_half = self.pos, self.yaw, self.box_center, self.box_half
            thickness = self.body_thickness
            leg_rows = np.arange(self.n_legs)
            row_of = np.arange(self.n_chars)
        else:
            pos, yaw = self.pos[chars], self.yaw[chars]
            box_center, box_half = self.box_center[chars], self.box_half[chars]
            thickness = self.body_thickness[chars]
            leg_rows = np.flatnonzero(np.isin(self.leg_char, chars))
            row_of = np.full(self.n_chars, -1)
            row_of[chars] = np.arange(len(chars))
        c = pos.shape[0]
        na, nc = self.params.body_samples
        sa = np.linspace(-1.0, 1.0, na)
        sc = np.linspace(-1.0, 1.0, nc)
        grid = np.stack(np.meshgrid(sa, sc, indexing="ij"), axis=-1).reshape(-1, 2)
        local = box_center[:, None, :] + grid[None, :, :] * box_half[:, None, :]
        cy, sy = np.cos(yaw)[:, None], np.sin(yaw)[:, None]

        def to_world(loc: FloatArray) -> FloatArray:
            return np.asarray(
                pos[:, None, :2]
                + np.stack(
                    [cy * loc[..., 0] - sy * loc[..., 1], sy * loc[..., 0] + cy * loc[..., 1]], axis=-1
                )
            )

        ground = self.env.height_at(to_world(local).reshape(-1, 2)).reshape(c, na, nc)
        ground = np.where(ground > _VOID, ground, -np.inf)
        along_z = ground.max(axis=2)  # (c, na)
        across_z = ground.max(axis=1)  # (c, nc)
        along_local = np.stack(
            [
                box_center[:, None, 0] + sa[None, :] * box_half[:, None, 0],
                np.broadcast_to(box_center[:, None, 1], (c, na)),
            ],
            axis=-1,
        )
        across_local = np.stack(
            [
                np.broadcast_to(box_center[:, None, 0], (c, nc)),
                box_center[:, None, 1] + sc[None, :] * box_half[:, None, 1],
            ],
            axis=-1,
        )
        width = max(na, nc)

        def padded(loc: FloatArray, z: FloatArray) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
            pts = np.zeros((c, width, 3))
            ok = np.zeros((c, width), dtype=bool)
            k = loc.shape[1]
            pts[:, :k, :2] = to_world(loc)
            pts[:, :k, 2] = np.where(np.isfinite(z), z, 0.0)
            ok[:, :k] = np.isfinite(z)
            return pts, ok

        along_pts, along_ok = padded(along_local, along_z)
        across_pts, across_ok = padded(across_local, across_z)
        # feet: planted feet where they are, swinging feet where they will land
        owner = self.leg_char[leg_rows]
        feet = np.where(self.swinging[leg_rows, None], self.target[leg_rows], self.foot[leg_rows])
        n_feet = int(np.bincount(row_of[owner], minlength=c).max())
        slot = leg_rows - self.legs.leg_start[owner]
        feet_pts = np.zeros((c, n_feet, 3))
        feet_ok = np.zeros((c, n_feet), dtype=bool)
        feet_pts[row_of[owner], slot] = feet
        feet_ok[row_of[owner], slot] = True
        fwd = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        left = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
        # both slices (forward for height and pitch, left for roll) in one batched call
        both_h, both_a = hull_height_and_pitch(
            np.concatenate(
                [
                    np.concatenate([along_pts, feet_pts], axis=1),
                    np.concatenate([across_pts, feet_pts], axis=1),
                ]
            ),
            np.concatenate([pos[:, :2], pos[:, :2]]),
            np.concatenate([fwd, left]),
            np.concatenate(
                [np.concatenate([along_ok, feet_ok], axis=1), np.concatenate([across_ok, feet_ok], axis=1)]
            ),
        )
        height, pitch, roll = both_h[:c], both_a[:c], both_a[c:]
        return height + thickness, pitch, roll

    def _reach_guard(self) -> None:
        """Lower a pelvis whose legs would have to stretch past ``reach_margin``."""
        rot = self.rotations()
        hips = self.hips_world(rot)
        reach = self.guard_reach
        d_h = vector_norm(hips[:, :2] - self.foot[:, :2])
        allowed = self.foot[:, 2] + self.foot_lift + np.sqrt(np.maximum(reach * reach - d_h * d_h, 0.0))
        excess = np.maximum(hips[:, 2] - allowed, 0.0)
        if self.spine_groups:
            # spines keep their legs within reach in step 4 (repeat_for_reach)
            excess[self.spine_legs] = 0.0
        drop = np.zeros(self.n_chars)
        np.maximum.at(drop, self.leg_char, excess)
        # bounded (a foot beyond any help steps early instead), and continuous in the feet
        self.guard_drop = np.minimum(drop, self.params.guard_max_drop * self.body_thickness)
        self.pos[:, 2] -= self.guard_drop

    # ---------------------------------------------------------------- legs
    def ik_targets(self) -> FloatArray:
        """``(N, 3)`` where each leg's end-effector goes: its foot, raised by its
        ``Morphology.foot_lift``."""
        out = self.foot.copy()
        out[:, 2] += self.foot_lift
        return out

    def _solve_ik(self, ctl: StepControls) -> int:
        """Pose every leg; returns how many swinging feet were moved to what their legs
        reach."""
        rot = self.rotations()
        hips = self.hips_world(rot)
        leg_rot = self.leg_rotations() if self.spine_groups else rot[self.leg_char]
        mask = np.asarray(ctl.ik, dtype=bool)[self.leg_char]
        res = solve_legs(
            self.legs, hips, leg_rot, self.ik_targets(), self.angles, mask=None if mask.all() else mask,
            tolerance=self.params.ik_tolerance, prev_normal=self.leg_normals,
        )
        self.angles = res.angles
        self.leg_normals = res.normal_body
        # A swinging foot goes where its leg reaches: a point of its trajectory beyond the leg
        # (the hip rose or moved on more than foreseen) or nearer the hip than its joints fold
        # (a robot knee stopping at 160°) is replaced by the closest point the leg reaches,
        # unless that point is under the ground. Planted feet never move.
        missed = np.flatnonzero(self.swinging & mask & (res.error > 1e-3 * self.legs.leg_length))
        if missed.size:
            end = res.joints[missed, self.legs.n_segments[missed]]
            end[:, 2] -= self.foot_lift[missed]  # the foot, on the ground it is planned on
            ground = self.env.height_at(end[:, :2])
            above = end[:, 2] >= ground - 1e-9
            moved = missed[above]
            if moved.size:
                self.foot[moved] = end[above]
                error = res.error.copy()
                error[moved] = 0.0
                res = replace(res, error=error)
        self.ik_result = res
        return int(moved.size) if missed.size else 0


def _sample_polyline(samples: FloatArray, u: FloatArray) -> FloatArray:
    """Points at parameters ``u (m,)`` in [0, 1] of polylines ``(m, k + 1, 3)`` sampled at
    uniform parameters (linear interpolation)."""
    k = samples.shape[1] - 1
    x = np.clip(u, 0.0, 1.0) * k
    i = np.minimum(np.floor(x).astype(np.int64), k - 1)
    f = (x - i)[:, None]
    rows = np.arange(samples.shape[0])
    return np.asarray(samples[rows, i] * (1.0 - f) + samples[rows, i + 1] * f)


class _Timer:
    """Accumulates seconds of ``clock`` (wall time by default) into named phases."""

    def __init__(self, into: dict[str, float], clock: Callable[[], float] = time.perf_counter) -> None:
        self.into = into
        self.clock = clock
        self.last = clock()

    def lap(self, name: str) -> None:
        now = self.clock()
        self.into[name] = self.into.get(name, 0.0) + now - self.last
        self.last = now
