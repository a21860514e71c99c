# SPDX-License-Identifier: GPL-3.0-or-later
"""The foot-state rules of a step (step 3 of ``Controller.step``, before planning): which
feet land (a forced step when its own time is up, a gait swing at the gait's touch-down; a
landing spot taken meanwhile starts the step again), which planted feet must step now (their
support went, or they are left behind and enough others stay down: ``reach``), which
swinging feet are re-planned (``planning.replan_needed``), how long a forced step lasts, and
every foot's swing timing for the planner (``Schedule``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..geometry import clip
from ..world.terrain import Environment
from .gait import GaitManager, GaitStep
from .obstacles import Watch, check_supports, look_around, spot_taken
from .planning import replan_needed
from .reach import catch_up_time, overstretched, wait_for_support
from .rig import Rig
from .state import FootState
from .types import VOID, BoolArray, ControllerParams, FloatArray, IntArray, StepControls, StepStats

Flags = tuple[BoolArray, BoolArray, BoolArray]


@dataclass(frozen=True)
class World:
    """What the rules read besides the feet: the environment, the watch rings, the rig,
    the knobs, the gait, the last IK's error ``ik_error (N,)`` (None before the first), and
    the controller's read-outs as calls: ``hips()`` and ``leg_rot()`` now, ``free_hips()``
    (at the height the pelvis wants, see ``reach.overstretched``), ``push(legs, surface)``
    (``obstacles.push_out`` of those feet); ``crowd(points, which, kind)``: which of the
    points ``(N, 3)`` of feet ``which (N,)`` another character's body has come near since
    the last look of that ``kind`` (``crowd``; None: the characters do not see each other)."""

    env: Environment
    watch: Watch
    rig: Rig
    params: ControllerParams
    gait: GaitManager
    ik_error: FloatArray | None
    hips: Callable[[], FloatArray]
    leg_rot: Callable[[], FloatArray]
    free_hips: Callable[[], FloatArray]
    push: Callable[[IntArray, FloatArray], None]
    crowd: Callable[[FloatArray, BoolArray, int], BoolArray] | None = None


@dataclass
class Schedule:
    """One step's swing timing of every foot ``(N,)``: swing ``progress``, the progress
    ``start_u`` where a new trajectory starts (where the foot is now), seconds ``remaining``
    of the swing and of the following stance (``stance_time``), and the feet to plan."""

    progress: FloatArray
    start_u: FloatArray
    remaining: FloatArray
    stance_time: FloatArray
    to_plan: BoolArray


def land(
    env: Environment, feet: FootState, landing: BoolArray, flags: Flags, under: FloatArray | None
) -> IntArray:
    """Feet ``landing (N,)`` touch down on their targets (``flags`` = (swinging, forced,
    failed) updated in place); ``under (N,)``: the surface under their targets when the
    caller asked already (``spot_taken``). Returns their legs. Where something moves, the
    watch remembers what is around them at the step's look (``obstacles.look_around``)."""
    legs = landing.nonzero()[0]
    if legs.size == 0:
        return legs
    feet.foot[legs] = feet.plan.target[legs]
    h = env.height_at(feet.plan.target[legs, :2]) if under is None else under[legs]
    feet.support_z[legs] = np.where(h > VOID, h, 0.0)
    flags[1][legs] = False
    flags[0][legs] = False
    feet.dodged[legs] = False
    return legs


def schedule(
    w: World, feet: FootState, flags: Flags, dt: float, ctl: StepControls, gstep: GaitStep,
    rate_leg: FloatArray, stats: StepStats,
) -> Schedule:
    """Step 3, first half: landings, forced steps, the swing timing of every foot and
    which feet to plan (``flags`` = (swinging, forced, failed) ``(N,)`` updated in place;
    ``rate_leg (N,)``: the needle rate)."""
    p, env, tol = w.params, w.env, w.rig.support_tolerance
    swinging, forced, failed = flags
    # a forced step lands when its own time is up (not at the gait's touch-down)
    landing = (
        (gstep.landed & ~forced) | (forced & (feet.forced_elapsed + dt >= feet.forced_duration))
    ) & swinging
    # a moving obstacle may have taken the landing spot since the last check: step again
    taken, under = spot_taken(env, w.watch, feet, feet.plan.target, landing, tol)
    bad_landing = taken & (feet.restarts < 2)
    feet.restarts = np.where(bad_landing, feet.restarts + 1, np.where(landing, 0, feet.restarts))
    landed = land(env, feet, landing & ~bad_landing, flags, under)
    feet.forced_elapsed = np.where(forced, feet.forced_elapsed + dt, 0.0)
    lifted = gstep.lifted | (feet.retry & gstep.swing)
    feet.retry[:] = False
    # a normal lift ends a forced step
    forced &= ~gstep.lifted
    progress = np.where(
        forced, clip(feet.forced_elapsed / feet.forced_duration, 0.0, 1.0), gstep.swing_progress
    )
    # where the foot is now: the progress of the previous frame (a new trajectory starts there)
    step_progress = np.where(forced, dt / feet.forced_duration, rate_leg * dt / w.gait.disk_duration)
    start_u = clip(progress - step_progress, 0.0, 1.0)
    remaining = (1.0 - progress) * np.where(forced, feet.forced_duration, gstep.swing_time)
    swing = swinging & (gstep.swing | forced)
    blocked = looked = None
    if w.watch.dynamic:  # every look of the rules in one query
        blocked, looked = look_around(env, w.watch, feet, landed, swing, ~swinging, progress, tol)
    replan = replan_needed(w.rig, p, feet, ctl, progress, swing, blocked)
    # a foot still down in its swing sector (its plan failed) is planted like any other:
    # it must step when its support goes or when it is left behind
    planted = ~gstep.swing | failed
    support_gone = check_supports(env, feet, looked, tol, w.push)
    if w.crowd is not None:
        # another character's body comes near a planted foot: it steps away; one covers a
        # swinging foot's landing spot: the swing is re-planned
        support_gone |= w.crowd(feet.foot, ~swinging, 0)
        replan |= w.crowd(feet.plan.target, swinging & (gstep.swing | forced) & ~replan, 1)
    behind, stretch = overstretched(w.rig, p, w.free_hips(), feet.foot, ~swinging)
    behind &= ~support_gone
    behind &= ~wait_for_support(w.rig, p, behind & planted & ~forced, stretch, swinging | lifted, w.ik_error)
    forced_new = ((support_gone | behind) & planted & ~forced) | bad_landing
    # a foot left behind lands under its rest place at the latest (as at mid-stance):
    # landed where its late stance would have it, it would be left behind again at once
    feet.forced_behind = np.where(
        forced_new, behind & planted & ~bad_landing, feet.forced_behind & forced
    )
    forced_time = forced_step_time(w, feet, dt, ctl, gstep, forced_new)
    rushed = replan & feet.blocked & ~forced_new & (remaining < 0.5 * forced_time)
    forced_new |= rushed
    if np.logical_or.reduce(forced_new):
        forced |= forced_new
        feet.forced_duration[forced_new] = forced_time[forced_new]
        # a forced step leaves in the frame it starts (its first frame's share of the
        # swing is done): the leg is already stretched, a frame later it would be more
        feet.forced_elapsed[forced_new] = dt
        progress = np.where(forced_new, dt / feet.forced_duration, progress)
        start_u = np.where(forced_new, 0.0, start_u)
        remaining = np.where(forced_new, feet.forced_duration - dt, remaining)
        stats.n_forced = int((forced_new & ~rushed).sum())
    feet.swing_u = clip(progress, 0.0, 1.0)
    # a foot whose plan failed stays down this cycle (it steps early if it gets left behind)
    stats.n_replans = int((replan & ~lifted).sum())
    return Schedule(progress, start_u, remaining, gstep.stance_time, lifted | forced_new | replan)

def forced_step_time(
    w: World, feet: FootState, dt: float, ctl: StepControls, gstep: GaitStep, forced_new: BoolArray
) -> FloatArray:
    """``(N,)`` the duration of a forced step: a share of the gait swing (a swing cut by
    a moving obstacle near its end gets it for its new way: in the frames left it would
    jump there); a foot left behind for cycles (its plans failed) has more than a stride
    to cover."""
    forced_time = np.maximum(w.params.forced_swing * gstep.swing_time, 2.0 * dt)
    if np.logical_or.reduce(forced_new & feet.forced_behind):
        catch_up = np.maximum(forced_time, catch_up_time(
            w.rig, w.gait.disk_duration, ctl.speed, gstep.swing_time, w.hips(), w.leg_rot(), feet.foot))
        forced_time = np.where(feet.forced_behind, catch_up, forced_time)
    return np.asarray(forced_time)
