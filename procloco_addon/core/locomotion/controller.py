"""The character controller: feet and pelvis of many characters, one step at a time
(thesis §3.2, §3.6; pelvis pseudo-physics §4.1). ``Controller`` is the thin orchestrator: it
holds the state and calls the functions of the other ``locomotion`` modules in the order
below; each step's phases are timed by ``profile.Profiler`` around those calls.

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
   (``footprints.plan_footsteps``, through ``planning``) returns the best couple; the foot
   follows the trajectory at
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

**Flexible spine** (thesis §4.2, §4.4; ``core.locomotion.spine``), per character: a character whose
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

Where each concern lives: ``state`` (per-foot phase and swing plan), ``rig`` (fixed geometry,
stride rule), ``planning`` (plan orchestration), ``obstacles`` (moving obstacles, supports,
push-out), ``fallback`` (straight steps), ``pelvis`` (hull pose, feedback, pogo particles),
``spine_link`` (spine groups), ``reach`` (reach guard, stretched legs, IK), ``stepping``
(landings, forced steps, swing timing), ``types``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ..geometry import clip, rotate_xy, rotation_matrices, wrap_angle
from ..world.terrain import Environment, WindowGrids
from . import crowd, obstacles, pelvis, planning, reach, spine_link, stepping
from .footprints import LegGeometry, PlannerParams
from .gait import Gait, GaitManager, GaitStep
from .ik import IKResult
from .morphology import LegBatch
from .obstacles import Watch
from .pelvis import Body, Pogo
from .pelvis_physics import PelvisPhysics
from .profile import Profiler
from .rig import Rig, build_rig, character_params, rate_scale
from .spine import SpineParams
from .spine_link import SpineGroup, SpineLink
from .state import FootState, sample_polyline, start_feet, support_points, swing_parameter
from .stepping import Flags, World
from .types import (
    VOID,
    BoolArray,
    ControllerParams,
    FloatArray,
    IntArray,
    PlannerLOD,
    StepControls,
    StepStats,
)


class Controller:
    """State and step of many characters (see the module docstring).

    ``env``: the environment; ``legs``: every character's legs (``LegBatch``); ``gaits``: one
    ``Gait`` per character; ``start_xy (C, 2)``, ``start_yaw (C,)``: initial pelvis ground
    position and heading; ``phase (C,)``: initial needle phases; ``params``: one
    ``ControllerParams`` for all, or one per character differing only in
    ``rig.PER_CHARACTER`` (creature-size scaling; ``params`` keeps the first character's,
    ``char_params`` all of them, the rig their per-character arrays); ``planner``: optional
    per-character ``PlannerParams`` (replacing the derived ones except step height, reach,
    foot size and height change); ``lod``: optional per-character ``PlannerLOD``;
    ``controls``: the first step's commands (for the initial planning of feet that start in
    swing); ``spine``: optional per-character ``SpineParams`` (None: a rigid body) for
    characters whose morphology has a spine (``Morphology.with_spine``).

    State: ``rig`` (fixed geometry), ``body`` (pelvis poses), ``feet`` (per-foot phase and
    plan), ``link`` (spine nodes and groups), ``watch`` (obstacle rings), ``pogo`` (pelvis
    particles), ``gait``, and the legs' ``angles`` and last ``ik_result``.
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
        params: ControllerParams | Sequence[ControllerParams] | None = None,
        planner: Sequence[PlannerParams | None] | None = None,
        lod: Sequence[PlannerLOD | None] | None = None,
        spine: Sequence[SpineParams | None] | None = None,
        avoid: Sequence[bool] | None = None,
    ) -> None:
        self.env = env
        self.legs = legs
        c, n = legs.n_chars, legs.n_legs
        self.char_params: list[ControllerParams] = character_params(params, c)
        # the shared knobs (the per-character ones, PER_CHARACTER, are the rig's arrays)
        self.params = p = self.char_params[0] if c else ControllerParams()
        self.n_chars, self.n_legs = c, n
        self.leg_char = legs.leg_char
        self.link: SpineLink = spine_link.build_link(legs, spine)
        # the characters without a spine when some have one (else None: all rigid)
        self._rigid: IntArray | None = None if not self.link.groups else np.flatnonzero(~self.link.has_spine)
        #: The ground under the bodies (``pelvis.hull_points``) when ``_move_feet`` asked for it.
        self._hull_ground: FloatArray | None = None
        self.gait = GaitManager(legs.leg_char, gaits, phase)
        self.time = 0.0
        self.rig: Rig = build_rig(legs, p, self.char_params)
        # the characters that see the others (crowd): their bodies and feet this step
        self.avoid: BoolArray = (np.zeros(c, dtype=bool) if avoid is None
                                 else np.broadcast_to(np.asarray(avoid, dtype=bool), (c,)).copy())
        self.bodies: crowd.BodyBoxes | None = None
        self._spine_n_joints: IntArray | None = None  # (body_boxes)
        self.discs: tuple[FloatArray, FloatArray] = crowd.footprint_discs(self.rig)
        self._near = np.zeros((c, c), dtype=bool)  # crowd.neighbours of this step
        self._crowded = np.zeros(c, dtype=bool)  # characters with a neighbour
        self._was_near = [np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)]  # (_crowd_near)
        self._planner_override = list(planner) if planner is not None else [None] * c
        # the planner's settings per character and geometry per leg, made once (planner_params,
        # leg_geometry)
        self._planner_cache: dict[tuple[object, ...], PlannerParams] = {}
        self._leg_cache: dict[tuple[int, float], LegGeometry] = {}
        self.lod: list[PlannerLOD | None] = list(lod) if lod is not None else [None] * c
        self.body: Body = pelvis.start_body(start_xy, start_yaw, c, n)
        # the body's rotations and rigid hips, kept while it neither moves nor turns (a step
        # asks for them up to seven times): the yaw, pitch and roll they were made from, the
        # rotations (read only), and the position and rotations of the hips
        self._rot_key: tuple[bytes, bytes, bytes] | None = None
        self._rot = np.zeros((0, 3, 3))
        self._hips_of: tuple[bytes, FloatArray] | None = None
        self._hips = np.zeros((0, 3))
        # the needle already runs at the speed the commanded stroke asks for
        self.gait.rate_scale = rate_scale(self.rig, self.gait, self.link.has_spine,
                                          np.asarray(controls.speed, dtype=np.float64))
        foot = self._walking_start(controls)
        self.watch: Watch = obstacles.make_watch(env, self.rig, p, foot)
        self.feet: FootState = start_feet(foot, p.trajectory_samples)
        self.angles = legs.rest_angles.copy()
        # last step's leg-plane normals (body frame): the plane turns on from them
        self.leg_normals: FloatArray | None = None
        self.ik_result: IKResult | None = None
        self._start_pelvis(controls)
        self._start_swings(controls)
        self._reach_guard()
        self._solve_ik(controls)

    def _walking_start(self, controls: StepControls) -> FloatArray:
        """``(N, 3)`` feet as if already walking: a planted foot where the stance sweep has
        brought it, a foot in its swing sector at its lift-off spot (no stumble at the first
        frame)."""
        g, legs, n = self.gait, self.legs, self.n_legs
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
        foot_xy = self.body.pos[legs.leg_char, :2] + rotate_xy(rest_xy, self.body.yaw[legs.leg_char])
        h = self.env.height_at(foot_xy)
        return np.column_stack([foot_xy, np.where(h > VOID, h, 0.0)])

    def _start_pelvis(self, controls: StepControls) -> None:
        """The initial pelvis pose from the hull, the pogo particles and the spines."""
        body, link = self.body, self.link
        support = support_points(self.feet, self.feet.swinging)
        height, pitch, roll = pelvis.hull_pose(self.env, self.rig, self.params.body_samples, body, support)
        body.pitch, body.roll = pitch, roll
        body.height_target = height
        body.pos[:, 2] = height
        on = np.asarray(controls.pelvis_physics, dtype=bool).copy()
        # the needle rate the pelvis particles' orbit was made for (re-made when it jumps)
        self.pogo = Pogo(PelvisPhysics(link.leg_node, link.n_nodes, params=self.params.physics,
                                       gravity=self.rig.gravity, group=self.leg_char), on,
                         self.gait.rate()[self.leg_char].copy())
        pref_nodes = spine_link.start(link, self.env.height_at, body, support, height)
        if np.any(on):
            self.pogo.physics.reset(
                pref_nodes,
                self.gait.needle[self.leg_char],
                self.gait.rate()[self.leg_char],
                self.gait.disk_start,
                self.gait.disk_duration,
            )
            centered = self.pogo.physics.centered_height()
            body.pos[:, 2] = np.where(on, centered[link.node_start[:-1]], height)
            pref_nodes = np.where(on[link.node_char], centered, pref_nodes)
        if link.groups:
            self._spine_pose(pref_nodes, on, 0.0, self.feet.swinging)

    def _start_swings(self, controls: StepControls) -> None:
        """Feet that start inside their swing sector are planned right away (a failed plan
        is tried again at the first step)."""
        g, n = self.gait, self.n_legs
        start_swing = g.swing.copy()
        if not np.any(start_swing):
            return
        needle = g.needle[self.leg_char]
        period = 1.0 / g.rate()[self.leg_char]
        progress = np.where(start_swing, np.mod(needle - g.disk_start, 1.0) / g.disk_duration, 0.0)
        swing_time = g.disk_duration * period
        stance_time = (1.0 - g.disk_duration) * period
        flags = self.feet.flags()
        self._plan(np.flatnonzero(start_swing), controls, flags, progress, (1.0 - progress) * swing_time,
                   stance_time, np.zeros(n), StepStats(), Profiler({}))
        failed = flags[2]
        self.feet.set_flags(start_swing & ~failed, flags[1], failed)
        self.feet.retry = start_swing & failed

    # ---------------------------------------------------------------- read-outs
    @property
    def pos(self) -> FloatArray:
        """``(C, 3)`` pelvis positions."""
        return self.body.pos

    @property
    def yaw(self) -> FloatArray:
        """``(C,)`` pelvis headings (radians from world +X)."""
        return self.body.yaw

    @property
    def pitch(self) -> FloatArray:
        """``(C,)`` pelvis pitch (nose up positive)."""
        return self.body.pitch

    @property
    def roll(self) -> FloatArray:
        """``(C,)`` pelvis roll (left side up positive)."""
        return self.body.roll

    @property
    def feedback(self) -> FloatArray:
        """``(N, 2)`` footprint errors still to work off (thesis figure 3.9)."""
        return self.body.feedback

    @property
    def foot(self) -> FloatArray:
        """``(N, 3)`` feet (on the ground they are planned on)."""
        return self.feet.foot

    @property
    def target(self) -> FloatArray:
        """``(N, 3)`` each foot's footprint (where a swinging one lands)."""
        return self.feet.plan.target

    @property
    def preferred(self) -> FloatArray:
        """``(N, 3)`` each foot's last preferred footprint."""
        return self.feet.preferred

    @property
    def traj(self) -> FloatArray:
        """``(N, k + 1, 3)`` each foot's swing trajectory samples."""
        return self.feet.plan.traj

    @property
    def swinging(self) -> BoolArray:
        """``(N,)`` feet in the air."""
        return self.feet.swinging

    @property
    def forced(self) -> BoolArray:
        """``(N,)`` feet on a forced step."""
        return self.feet.forced

    @property
    def plan_failed(self) -> BoolArray:
        """``(N,)`` feet down in their swing sector because their plan failed."""
        return self.feet.plan_failed

    @property
    def spine_params(self) -> list[SpineParams | None]:
        """Each character's ``SpineParams`` (None: a rigid body)."""
        return self.link.params

    @property
    def spine_groups(self) -> list[SpineGroup]:
        """The groups of spine characters (``spine_link``)."""
        return self.link.groups

    @property
    def n_nodes(self) -> int:
        """Pelvis nodes of every character (one per rigid one, ``K`` per spine)."""
        return self.link.n_nodes

    @property
    def leg_node(self) -> IntArray:
        """``(N,)`` the pelvis node each leg hangs from."""
        return self.link.leg_node

    @property
    def stroke_limit(self) -> FloatArray:
        """``(C,)`` the longest stance sweep the legs allow (metres)."""
        return self.rig.stroke_limit

    @property
    def comfort_reach(self) -> FloatArray:
        """``(N,)`` reach beyond which a planted foot steps early."""
        return self.rig.comfort_reach

    @property
    def guard_reach(self) -> FloatArray:
        """``(N,)`` reach the pelvis sinks to keep its feet within."""
        return self.rig.guard_reach

    @property
    def body_thickness(self) -> FloatArray:
        """``(C,)`` body thickness of every character."""
        return self.rig.body_thickness

    @property
    def foot_half(self) -> FloatArray:
        """``(C, 2)`` foot box half extents of every character."""
        return self.rig.foot_half

    def rotations(self) -> FloatArray:
        """``(C, 3, 3)`` current body-to-world rotations (read only; made again when the body
        turned)."""
        body = self.body
        key = (body.yaw.tobytes(), body.pitch.tobytes(), body.roll.tobytes())
        if key != self._rot_key:
            rot = rotation_matrices(body.yaw, body.pitch, body.roll)
            rot.setflags(write=False)
            self._rot_key, self._rot = key, rot
        return self._rot

    def hips_world(self, rot: FloatArray | None = None) -> FloatArray:
        """``(N, 3)`` world hips: the rigid body's, or where the spine put them."""
        link = self.link
        if link.all_legs:  # every leg on a spine: nothing rigid
            return np.array(link.hips, copy=True)
        r = self.rotations() if rot is None else rot
        pos = self.body.pos.tobytes()
        made = self._hips_of
        if made is not None and made[1] is r and made[0] == pos:  # (the kept rotations, unchanged)
            hips = self._hips.copy()
        else:
            lc = self.leg_char
            hips = self.body.pos[lc] + np.einsum("nij,nj->ni", r[lc], self.legs.hip_offset)
            if r is self._rot:
                self._hips_of, self._hips = (pos, r), hips.copy()
        if link.groups:
            hips[link.spine_legs] = link.hips[link.spine_legs]
        return np.asarray(hips)

    def leg_rotations(self) -> FloatArray:
        """``(N, 3, 3)`` body-to-world rotation of the body part each leg hangs from: the
        pelvis, or the leg's spine node (or carrier bone)."""
        link = self.link
        if link.all_legs:
            return np.array(link.leg_rot, copy=True)
        rot = self.rotations()[self.leg_char]
        if link.groups:
            rot[link.spine_legs] = link.leg_rot[link.spine_legs]
        return np.asarray(rot)

    def spine_joints(self) -> FloatArray:
        """``(C, J, 3)`` world spine joints (head first), see ``spine_link.joints``."""
        return spine_link.joints(self.link, self.body.pos)

    def spine_rotations(self) -> FloatArray:
        """``(C, J - 1, 3, 3)`` spine bone rotations, see ``spine_link.bone_rotations``."""
        return spine_link.bone_rotations(self.link, self.n_chars)

    def ik_targets(self) -> FloatArray:
        """``(N, 3)`` where each leg's end-effector goes: its foot, raised by its
        ``Morphology.foot_lift``."""
        return reach.ik_targets(self.rig, self.feet.foot)

    def planner_params(self, char: int, step_height: float) -> PlannerParams:
        """A character's planner settings at a step height (``planning.planner_params``),
        made once per character, LOD and step height and shared by its feet."""
        level = self.lod[char]
        key = (char, float(step_height), None if level is None else (level.max_couples_after_first,
                                                                     level.slice_size))
        made = self._planner_cache.get(key)
        if made is None:
            made = planning.planner_params(self.rig, self.params, level, self._planner_override[char],
                                           char, step_height)
            self._planner_cache[key] = made
        return made

    def leg_geometry(self, leg: int, step_height: float) -> LegGeometry:
        """What the planner checks of a leg (``planning.leg_geometry``), made once per leg
        and step height."""
        key = (leg, float(step_height))
        made = self._leg_cache.get(key)
        if made is None:
            made = planning.leg_geometry(self.rig, self.params, leg, step_height)
            self._leg_cache[key] = made
        return made

    # ---------------------------------------------------------------- the step
    def step(self, dt: float, ctl: StepControls) -> StepStats:
        """Advance every character by ``dt`` seconds under the commands ``ctl``."""
        stats = StepStats()
        prof = Profiler(stats.seconds, self.params.clock)
        self.time += dt
        gstep, needle_before, rate_leg = self._advance(dt, ctl, prof)
        if np.logical_or.reduce(self.avoid):
            self._see_others()
        flags = self.feet.flags()
        sched = stepping.schedule(self._world(), self.feet, flags, dt, ctl, gstep, rate_leg, stats)
        if np.logical_or.reduce(sched.to_plan):
            forced = flags[1]
            land_stance = np.where(
                forced,
                clip(gstep.stance_progress + sched.remaining / np.maximum(sched.stance_time, 1e-9), 0.0, 1.0),
                0.0,
            )
            land_stance = np.where(self.feet.forced_behind, np.minimum(land_stance, 0.5), land_stance)
            self._plan(sched.to_plan.nonzero()[0], ctl, flags, sched.start_u, sched.remaining,
                       sched.stance_time, land_stance, stats, prof)
        swinging = self._move_feet(gstep, sched.progress, flags)
        self._pelvis_height(dt, ctl, needle_before, rate_leg, swinging, prof)
        with prof.phase("ik"):
            stats.n_bent = self._solve_ik(ctl)
        prof.finish()
        return stats

    def _advance(
        self, dt: float, ctl: StepControls, prof: Profiler
    ) -> tuple[GaitStep, FloatArray, FloatArray]:
        """Steps 1-2: heading and needle, the pelvis in the ground plane (spines: steps 1-2
        of thesis §4.2), the feet-error feedback. Returns the gait's step, the needle before
        it and the needle rate ``(N,)``."""
        p, body, lc = self.params, self.body, self.leg_char
        turn = clip(wrap_angle(ctl.heading - body.yaw), -p.max_turn_rate * dt, p.max_turn_rate * dt)
        body.yaw = wrap_angle(body.yaw + turn)
        scale = rate_scale(self.rig, self.gait, self.link.has_spine, ctl.speed, turn / dt)
        needle_before = self.gait.needle[lc]  # (a fancy index: a copy)
        gstep = self.gait.advance(dt, scale)
        rate_leg = self.gait.rate()[lc]
        step = ctl.speed * dt
        body.pos[:, 0] += step * np.cos(body.yaw)
        body.pos[:, 1] += step * np.sin(body.yaw)
        if self.link.groups:
            with prof.phase("spine"):
                spine_link.advance(self.link, body, ctl, dt)
        move = pelvis.feedback_move(self.leg_char, p, body.feedback, self.rig.char_leg_length,
                                    self.gait.cycle_time, dt)
        if move is not None:
            body.pos[:, :2] += move
            spine_link.shift(self.link, move)
        return gstep, needle_before, rate_leg

    def _push_out(self, legs: IntArray, surface: FloatArray) -> None:
        obstacles.push_out(self.env, self.watch, self.feet.foot, legs, surface, self.hips_world()[legs],
                           self.rig.guard_reach[legs], self.rig.support_tolerance)

    def _world(self) -> World:
        """What the foot-state rules (``stepping``) read besides the feet."""
        return World(self.env, self.watch, self.rig, self.params, self.gait,
                     None if self.ik_result is None else self.ik_result.error, self.hips_world,
                     self.leg_rotations, self._free_hips, self._push_out,
                     None if self.bodies is None else self._crowd_near)

    def body_boxes(self) -> crowd.BodyBoxes:
        """Every character's body boxes now (``crowd.body_boxes``; along a spine, per bone)."""
        if self._spine_n_joints is None:  # (fixed: made at the first look)
            self._spine_n_joints = np.array(
                [m.spine.n_joints if m.spine is not None and sp is not None else 0
                 for m, sp in zip(self.legs.morphologies, self.link.params, strict=True)], dtype=np.int64)
        joints = self.spine_joints() if self.link.groups else None
        rig = self.rig
        return crowd.body_boxes(rig.box_center, rig.box_half, self.body.pos, self.body.yaw, joints,
                                self._spine_n_joints)

    def disc_centers(self) -> FloatArray:
        """``(C, 2)`` world centres of the characters' footprint discs (``self.discs``)."""
        dc = self.discs[0]
        cos, sin = np.cos(self.body.yaw), np.sin(self.body.yaw)
        turned = np.stack([cos * dc[:, 0] - sin * dc[:, 1], sin * dc[:, 0] + cos * dc[:, 1]], axis=1)
        return np.asarray(self.body.pos[:, :2] + turned)

    def _see_others(self) -> None:
        """This step's body boxes and, for the characters that avoid the others, which
        others are near enough to matter (a leg and the keep-out margin beyond their discs)."""
        self.bodies = self.body_boxes()
        reach = (0.5 + crowd.KEEP_OUT) * self.rig.char_leg_length
        self._near = crowd.neighbours(self.disc_centers(), self.discs[1], reach, self.avoid)
        self._crowded = self._near.any(axis=1)
        if not self._crowded.any():
            self.bodies = None  # nobody near anybody: nothing to check this step
            for was in self._was_near:
                was[:] = False

    def _crowd_near(self, points: FloatArray, which: BoolArray, kind: int) -> BoolArray:
        """``(N,)`` feet ``which`` of characters that avoid the others whose ``points (N, 3)``
        another character's body has come within half ``crowd.KEEP_OUT`` of since the last
        look of this ``kind`` (0: planted feet, 1: landing spots): once per approach, so a
        foot that cannot get away does not try again at every step."""
        near = np.zeros(self.n_legs, dtype=bool)
        legs = np.flatnonzero(which & self._crowded[self.leg_char])
        if legs.size and self.bodies is not None:
            near[legs] = crowd.inside_other(self.bodies, points[legs, :2], self.leg_char[legs],
                                            0.5 * crowd.KEEP_OUT * self.legs.leg_length[legs])
        was = self._was_near[kind]
        self._was_near[kind] = near
        return np.asarray(near & ~was)

    def _crowd_windows(self, grids: dict[int, WindowGrids]) -> dict[int, WindowGrids]:
        """The planning windows of characters that avoid the others with the other bodies
        (``crowd.KEEP_OUT`` around them) and feet (planted, or where they land) avoided."""
        if self.bodies is None:
            return grids
        feet = self.feet
        spot = np.where(feet.swinging[:, None], feet.plan.target[:, :2], feet.foot[:, :2])
        sole = np.max(self.rig.sole_half, axis=1)[self.leg_char]
        out = dict(grids)
        b = self.bodies
        for ch, grid in grids.items():
            if self._crowded[ch]:
                near = self._near[ch]
                mine = near[b.owner]
                boxes = crowd.BodyBoxes(b.owner[mine], b.center[mine], b.half[mine], b.yaw[mine])
                feet_near = near[self.leg_char]
                margin = crowd.KEEP_OUT * float(self.rig.char_leg_length[ch])
                out[ch] = crowd.mark_window(grid, boxes, ch, margin, spot[feet_near],
                                            self.leg_char[feet_near], sole[feet_near])
        return out

    def _free_hips(self) -> FloatArray:
        """``(N, 3)`` the hips at the height the pelvis wants, before the reach guard lowered
        it (spines: before step 4 pulled them toward the feet)."""
        hips = self.hips_world()
        hips[:, 2] += self.body.guard_drop[self.leg_char]
        if self.link.groups:
            hips[self.link.spine_legs] = self.link.hips_free[self.link.spine_legs]
        return hips

    def _plan(
        self, legs: IntArray, ctl: StepControls, flags: Flags, start_u: FloatArray, remaining: FloatArray,
        stance_time: FloatArray, land_stance: FloatArray, stats: StepStats, prof: Profiler,
    ) -> None:
        """Plan the best couple of every leg in ``legs`` (``planning``); see
        ``planning.landing`` and ``planning.choose`` for the arguments."""
        env, rig, p = self.env, self.rig, self.params
        land = planning.landing(env, rig, p, self.body, self.link, self.feet, legs, ctl, remaining,
                                stance_time, land_stance, self.hips_world())
        u_grid = planning.swing_grid(p.trajectory_samples)
        with prof.phase("maps"):
            grids = planning.windows(env, rig, p, self.body, sorted(set(land.chars.tolist())), stats)
            grids = self._crowd_windows(grids)
        with prof.phase("planning"):
            reqs, rows_of = planning.requests(rig, p, land, self.feet, flags[0], flags[1], ctl, grids,
                                              self.planner_params, self.leg_geometry)
            couples = planning.search(reqs, [bool(flags[1][r[0]]) for r in rows_of], stats)
            done = planning.choose(env, rig, p, land, self.feet, flags, rows_of, couples, ctl, u_grid, stats)
        planning.commit(env, rig, p, self.watch, self.feet, self.body, land, done, ctl, start_u, u_grid)

    def _move_feet(self, gstep: GaitStep, progress: FloatArray, flags: Flags) -> BoolArray:
        """Step 3, second half: swinging feet along their trajectories (pushed out of
        obstacles that moved into them), then the feet's phases. Returns the swinging feet."""
        feet = self.feet
        _, forced, failed = flags
        active = (gstep.swing | forced) & ~failed
        u = swing_parameter(feet, progress)
        moving = active.nonzero()[0]
        if moving.size:
            feet.foot[moving] = sample_polyline(feet.plan.traj[moving], u[moving])
            if self.watch.dynamic:
                # an obstacle that moved into a swinging foot pushes it out, up or aside (the
                # trajectory is re-planned at the next step); the ground under the bodies that
                # the pelvis height reads next (hull_pose) comes in the same query (a query of
                # many points: one of a single point may take another path)
                xy = feet.foot[moving, :2]
                rigid = self._rigid
                if moving.size > 1 and (rigid is None or rigid.size):
                    under = pelvis.hull_points(self.rig, self.params.body_samples, self.body, rigid)
                    heights = self.env.height_at(np.concatenate([xy, under]))
                    surface, self._hull_ground = heights[: moving.size], heights[moving.size :]
                else:
                    surface = self.env.height_at(xy)
                hit = surface > feet.foot[moving, 2]
                if np.logical_or.reduce(hit):
                    self._push_out(moving[hit], surface[hit])
        # a gait swing whose plan failed leaves the foot planted
        feet.set_flags(active, forced, failed & (gstep.swing | forced))
        return np.asarray(active)

    def _pelvis_height(
        self, dt: float, ctl: StepControls, needle_before: FloatArray, rate_leg: FloatArray,
        swinging: BoolArray, prof: Profiler,
    ) -> None:
        """Step 4: pelvis height, pitch, roll (spines: per node, steps 3-4 of thesis §4.2),
        the pogo particles, the reach guard."""
        p, body, link = self.params, self.body, self.link
        alpha = 1.0 - np.exp(-dt / np.maximum(p.height_time * self.gait.cycle_time, 1e-6))
        rigid = self._rigid
        support = support_points(self.feet, swinging)
        ground, self._hull_ground = self._hull_ground, None
        if rigid is None or rigid.size:
            hull = pelvis.hull_pose(self.env, self.rig, p.body_samples, body, support, rigid, ground)
            pelvis.settle(body, hull, alpha, rigid)
        pref = body.height_target
        if link.groups:
            with prof.phase("spine"):
                pref = spine_link.guides(link, self.env.height_at, body.height_target, support, alpha)
        physics_on = np.asarray(ctl.pelvis_physics, dtype=bool)
        with prof.phase("physics"):
            z = pelvis.pogo_heights(self.pogo, self.gait, self.leg_char, link.node_char, physics_on,
                                    needle_before, rate_leg, pref, dt)
        if link.groups:
            if rigid is not None and rigid.size:
                body.pos[rigid, 2] = z[link.node_start[rigid]]
            with prof.phase("spine"):
                self._spine_pose(z, physics_on, dt, swinging)
        else:
            body.pos[:, 2] = z
        self._reach_guard()

    def _spine_pose(self, node_z: FloatArray, physics_on: BoolArray, dt: float, swinging: BoolArray) -> None:
        """Step 4 of the spines (``spine_link.pose``) at node heights ``node_z (n_nodes,)``."""
        rig, feet = self.rig, self.feet
        at = spine_link.PoseInputs(feet.foot, swinging, feet.plan.target, feet.swing_u, rig.guard_reach,
                                   rig.foot_lift, rig.body_thickness)
        spine_link.pose(self.link, self.body, self.params, at, node_z, physics_on, dt)

    def _reach_guard(self) -> None:
        """Lower a pelvis whose legs would have to stretch past ``reach_margin``."""
        hips = self.hips_world()  # (the rotations only where a leg is on the rigid pelvis)
        drop = reach.guard_drop(self.rig, self.params, hips, self.feet.foot, self.link.spine_legs)
        self.body.guard_drop = drop
        self.body.pos[:, 2] -= drop

    def _solve_ik(self, ctl: StepControls) -> int:
        """Step 5: pose every leg; returns how many swinging feet were moved to what their
        legs reach."""
        if self.link.groups:
            hips, leg_rot = self.hips_world(), self.leg_rotations()
        else:
            rot = self.rotations()
            hips, leg_rot = self.hips_world(rot), rot[self.leg_char]
        mask = np.asarray(ctl.ik, dtype=bool)[self.leg_char]
        res, bent = reach.solve_ik(self.env, self.rig, self.params, hips, leg_rot, self.feet.foot,
                                   self.feet.swinging, self.angles, self.leg_normals, mask)
        self.angles = res.angles
        self.leg_normals = res.normal_body
        self.ik_result = res
        return bent
