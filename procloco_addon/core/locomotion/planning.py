# SPDX-License-Identifier: GPL-3.0-or-later
"""Plan orchestration (thesis §3.2.1, §3.6): which swinging feet need a new plan
(``replan_needed``), where each planned foot should land (``landing``: the body part it hangs
from extrapolated to its touch-down, the preferred footprint half a stance sweep ahead of its
rest position, figures 3.5-3.7), the planning windows (``windows``), the footprint planner's
requests and its retries (``requests``, ``search``: wider, then without the other feet and
slices for a foot that must move), the choice between its couple, the straight fallback step
and staying down (``choose``), and the new trajectories written into the feet's plans
(``commit``: snapped onto the exact surface, moved off holes). ``planner_params`` builds each
foot's ``PlannerParams``; the planner itself is ``core.locomotion.footprints``."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..geometry import column_pair, rotate_xy, vector_norm, wrap_angle
from ..world.pathing import points_at_each
from ..world.terrain import Environment, WindowGrids, WindowParams
from . import spine_link
from .fallback import straight_step
from .footprints import Couple, FootRequest, LegGeometry, PlannerParams, plan_footsteps
from .morphology import LegBatch
from .obstacles import Watch, onto_support, ring_points, swing_planned, watch_reset
from .pelvis import Body
from .reach import within_reach_all
from .rig import Rig
from .spine_link import SpineLink
from .state import FootState
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

#: A character's planner settings at a step height: ``(char, step_height) -> PlannerParams``
#: (``Controller.planner_params``, made once and kept).
ParamsOf = Callable[[int, float], PlannerParams]
#: A leg's planner geometry at a step height: ``(leg, step_height) -> LegGeometry``
#: (``Controller.leg_geometry``, made once and kept).
GeometryOf = Callable[[int, float], LegGeometry]


def replan_needed(
    rig: Rig, p: ControllerParams, feet: FootState, ctl: StepControls, progress: FloatArray, swing: BoolArray,
    blocked: BoolArray | None,
) -> BoolArray:
    """``(N,)`` swinging feet (``swing (N,)``) to re-plan from where they are (sequences 1-3,
    §3.6): before ``replan_until`` of their swing (``progress (N,)``), when the commanded
    heading, speed or spacing changed noticeably since their plan; at any time when a
    moving obstacle now cuts their way (``blocked (N,)``, ``obstacles.look_around``; None
    where nothing moves; also kept in ``feet.blocked``)."""
    plan = feet.plan
    leg_len = rig.legs.leg_length
    lc = rig.leg_char
    early = progress < p.replan_until
    heading = np.abs(wrap_angle(ctl.heading[lc] - plan.heading)) > p.replan_heading
    v, v0 = ctl.speed[lc], plan.speed
    speed = np.abs(v - v0) > np.maximum(p.replan_speed * np.maximum(v, v0), 0.05 * leg_len)
    spacing = vector_norm(ctl.spacing - plan.spacing) > p.replan_spacing * leg_len
    need = swing & early & (heading | speed | spacing)
    feet.blocked[:] = False
    if blocked is not None:
        feet.blocked = swing & blocked
        need |= feet.blocked
    return np.asarray(need)


def landing_refs(
    body: Body, link: SpineLink, legs_data: LegBatch, p: ControllerParams, legs: IntArray, ctl: StepControls,
    remaining: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Where the body part each leg in ``legs (m,)`` hangs from will be when the foot lands
    ``remaining (N,)`` seconds from now: ground position ``(m, 2)``, heading ``(m,)``, and
    that part's rest position ``(m, 3)`` and rest heading ``(m,)`` in the body frame.

    A rigid pelvis is extrapolated with its speed and bounded turn; a spine node along its
    spine (``spine_link.landing_refs``)."""
    c_of = legs_data.leg_char[legs]
    turn = np.clip(
        wrap_angle(ctl.heading[c_of] - body.yaw[c_of]),
        -p.max_turn_rate * remaining[legs],
        p.max_turn_rate * remaining[legs],
    )
    yaw_land = body.yaw[c_of] + turn
    yaw_mid = body.yaw[c_of] + 0.5 * turn
    travel = (ctl.speed[c_of] * remaining[legs])[:, None] * column_pair(np.cos(yaw_mid), np.sin(yaw_mid))
    ref_xy = body.pos[c_of, :2] + travel
    ref_rest = np.zeros((legs.size, 3))
    rest_yaw = np.zeros(legs.size)
    spine_link.landing_refs(
        link, legs_data, legs, c_of, ctl, remaining, (ref_xy, yaw_land, ref_rest, rest_yaw)
    )
    return ref_xy, yaw_land, ref_rest, rest_yaw


@dataclass(frozen=True)
class Landing:
    """The touch-down of every foot to plan, row ``j`` for leg ``legs[j]`` (``(m, ...)``):
    the predicted pose of the body part it hangs from (``pelvis_land (m, 2)``, ``yaw_land``,
    its rest position ``ref_rest (m, 3)`` and rest heading ``rest_yaw``); the preferred
    footprint ``preferred_xy (m, 2)``; the hip reference halfway through the coming stance
    ``pelvis_ref (m, 2)``, the horizontal ``reach`` allowed from it and half the coming
    stance sweep ``sweep_half``; and the hip now ``hip_now (m, 3)``."""

    legs: IntArray
    chars: IntArray
    pelvis_land: FloatArray
    yaw_land: FloatArray
    ref_rest: FloatArray
    rest_yaw: FloatArray
    preferred_xy: FloatArray
    pelvis_ref: FloatArray
    reach: FloatArray
    sweep_half: FloatArray
    hip_now: FloatArray


def landing(
    env: Environment, rig: Rig, p: ControllerParams, body: Body, link: SpineLink, feet: FootState,
    legs: IntArray, ctl: StepControls, remaining: FloatArray, stance_time: FloatArray,
    land_stance: FloatArray, hips: FloatArray,
) -> Landing:
    """The ``Landing`` of every leg in ``legs``; also writes their ``feet.preferred`` (its
    height, the ground there, comes with ``commit``'s query).

    ``remaining (N,)``: seconds left of each swing; ``stance_time (N,)``: the following
    stance's duration; ``land_stance (N,)``: the stance fraction already gone when the foot
    lands (0 for a gait swing, more for a forced step in the middle of a stance); ``hips
    (N, 3)``: the hips now."""
    legs_data = rig.legs
    c_of = rig.leg_char[legs]
    # predicted pelvis (or spine node) pose at each foot's touch-down
    pelvis_land, yaw_land, ref_rest, rest_yaw = landing_refs(body, link, legs_data, p, legs, ctl, remaining)
    # land so the foot passes under its rest position at mid-stance (figure 3.6, 3.7)
    sweep = (0.5 - land_stance[legs]) * ctl.speed[c_of] * stance_time[legs]
    offset = (
        legs_data.rest_foot[legs, :2]
        - ref_rest[:, :2]
        + ctl.spacing[legs]
        + column_pair(sweep, np.zeros(legs.size))
    )
    preferred_xy = pelvis_land + rotate_xy(offset, yaw_land - rest_yaw)
    feet.preferred[legs, :2] = preferred_xy  # (the ground under them: asked by ``commit``)
    # reach is judged from the hips halfway through the coming stance: a footprint within
    # the reach minus half the sweep stays within reach from touch-down to lift-off
    rest_stance = (1.0 - land_stance[legs]) * stance_time[legs]
    pelvis_ref = pelvis_land + (0.5 * ctl.speed[c_of] * rest_stance)[:, None] * column_pair(
        np.cos(yaw_land), np.sin(yaw_land))
    low = rig.rest_height[legs] * (1.0 - p.max_drop)
    horizontal = np.sqrt(np.maximum(rig.comfort_reach[legs] ** 2 - low * low, 0.0))
    sweep_half = 0.5 * ctl.speed[c_of] * rest_stance
    reach = np.maximum(
        horizontal - sweep_half,
        rig.rest_horizontal[legs] + 0.5 * p.candidate_radius * legs_data.leg_length[legs],
    )
    return Landing(legs, c_of, pelvis_land, yaw_land, ref_rest, rest_yaw, preferred_xy, pelvis_ref, reach,
                   sweep_half, hips[legs])


def windows(
    env: Environment, rig: Rig, p: ControllerParams, body: Body, chars: list[int], stats: StepStats
) -> dict[int, WindowGrids]:
    """The planning window of every character in ``chars`` around its pelvis, in one call
    (the moving crates near any of them are rasterised together)."""
    params = [
        WindowParams(
            n_cells=int(rig.window_cells[c]),
            cell=float(rig.window_cell[c]),
            foot_half_extents=(float(rig.foot_half[c, 0]), float(rig.foot_half[c, 1])),
            foot_yaw=float(body.yaw[c]),
        )
        for c in chars
    ]
    stats.n_windows += len(chars)
    return dict(zip(chars, env.windows(body.pos[chars, :2], params), strict=True))


def requests(
    rig: Rig, p: ControllerParams, land: Landing, feet: FootState, swinging: BoolArray, forced: BoolArray,
    ctl: StepControls, grids: dict[int, WindowGrids], params_of: ParamsOf, geometry_of: GeometryOf,
) -> tuple[list[FootRequest], list[tuple[int, int, int, FloatArray]]]:
    """One ``FootRequest`` per foot of ``land``, grouped by character, and for each its
    ``(leg, row in land, character, hip at the stance reference (2,))``. The hips and feet
    of every planned leg's character are found for all planned legs at once (pairs of a
    planned leg and a leg of its character)."""
    legs_data = rig.legs
    legs, c_of = land.legs, land.chars
    m = legs.size
    # the pairs (row j, leg of row j's character), row by row
    first = legs_data.leg_start[c_of]
    count = legs_data.leg_start[c_of + 1] - first
    pair_row = np.arange(m).repeat(count)
    bounds = np.concatenate([[0], count.cumsum()])
    pair_leg = first[pair_row] + np.arange(pair_row.size) - bounds[:-1][pair_row]
    # each character's hips at the row's stance reference, its other feet where they stand
    # or where swinging ones will land
    hips = land.pelvis_ref[pair_row] + rotate_xy(
        legs_data.hip_offset[pair_leg, :2] - land.ref_rest[pair_row, :2],
        (land.yaw_land - land.rest_yaw)[pair_row],
    )
    own = pair_leg == legs[pair_row]
    other = (~own).nonzero()[0]
    other_hips = hips[other]
    other_feet = np.where(swinging[pair_leg[other], None], feet.plan.target[pair_leg[other], :2],
                          feet.foot[pair_leg[other], :2])
    own_row = own.nonzero()[0].tolist()
    cut = (bounds - np.arange(m + 1)).tolist()  # row j's other legs: other[cut[j]:cut[j + 1]]
    step_heights = np.asarray(ctl.step_height, dtype=np.float64)[c_of].tolist()
    yaw_land, hip_z = land.yaw_land.tolist(), land.hip_now[:, 2].tolist()
    reach, sweep_half = land.reach.tolist(), land.sweep_half.tolist()
    thickness = rig.body_thickness[c_of].tolist()
    out: list[FootRequest] = []
    rows_of: list[tuple[int, int, int, FloatArray]] = []
    legs_list, chars = legs.tolist(), c_of.tolist()
    for j in c_of.argsort(kind="stable").tolist():
        leg, c = legs_list[j], chars[j]
        step_height = step_heights[j]
        # the hip may sink toward a footprint by as much as the reach guard lowers it; a
        # foot stepping because it was left behind, by half of max_drop: it lands where it
        # will not be left behind again at once
        sink_share = p.guard_max_drop if not forced[leg] else 0.5 * p.max_drop
        hip_own = hips[own_row[j]]
        out.append(FootRequest(
            grids[c], feet.foot[leg], land.preferred_xy[j], hip_own, other_hips[cut[j]:cut[j + 1]],
            other_feet[cut[j]:cut[j + 1]], params_of(c, step_height), yaw_land[j], hip_z[j],
            geometry_of(leg, step_height), leg_reach=reach[j], reach_sweep=sweep_half[j],
            reach_sink=sink_share * thickness[j],
        ))
        rows_of.append((leg, j, c, hip_own))
    return out, rows_of


def search(reqs: list[FootRequest], must_move: list[bool], stats: StepStats) -> list[Couple]:
    """Every request's couple from the batched planner. Where every footprint near the
    preferred one is taken (an obstacle, another foot), it looks twice as far before giving
    up; a foot that must move (``must_move``), crowded by the other feet or boxed in by
    slices, tries again without them."""
    couples = plan_footsteps(reqs)
    wide = [i for i, cp in enumerate(couples) if not cp.ok and cp.n_targets == 0]
    if wide:
        again = plan_footsteps([
            replace(reqs[i], params=replace(
                reqs[i].params,
                candidate_radius=2.0 * reqs[i].params.candidate_radius,
                fixed_distance=2.0 * reqs[i].params.fixed_distance,
            ))
            for i in wide
        ])
        for i, cp in zip(wide, again, strict=True):
            couples[i] = cp
    relax = [i for i, cp in enumerate(couples) if not cp.ok and must_move[i]]
    if relax:
        none = np.zeros((0, 2))
        again = plan_footsteps([
            replace(reqs[i], other_hips_xy=none, other_feet_xy=none, params=replace(
                reqs[i].params,
                candidate_radius=2.0 * reqs[i].params.candidate_radius,
                fixed_distance=2.0 * reqs[i].params.fixed_distance,
                slice_size=None,
            ))
            for i in relax
        ])
        for i, cp in zip(relax, again, strict=True):
            couples[i] = cp
        stats.n_relaxed += len(relax)
    return list(couples)


#: A chosen swing: (leg, row in the ``Landing``, character, samples ``(k + 1, 3)``, target ``(3,)``).
Chosen = tuple[int, int, int, FloatArray, FloatArray]


def _within_reach(
    rig: Rig, p: ControllerParams, land: Landing, rows_of: list[tuple[int, int, int, FloatArray]],
    couples: list[Couple], forced: BoolArray, u_grid: FloatArray,
) -> dict[int, tuple[bool, FloatArray]]:
    """For each couple with a trajectory (by its index): whether its swing may be taken and
    the swing sampled at ``u_grid``. A swing that would leave the leg's reach is not taken,
    unless the foot must move (``forced``: its way out may be a detour); every swing is
    checked at once (``reach.within_reach_all``)."""
    trajs = [(i, cp.trajectory) for i, cp in enumerate(couples) if cp.ok and cp.trajectory is not None]
    sampled: dict[int, FloatArray] = {}
    if trajs:  # every swing sampled in one go
        swings = points_at_each([tr for _, tr in trajs], u_grid)
        sampled = dict(zip([i for i, _ in trajs], swings, strict=True))
    judged = [i for i in sampled if not forced[rows_of[i][0]]]
    ok = dict.fromkeys(sampled, True)
    if judged:
        at = [rows_of[i][1] for i in judged]
        hip_land = land.pelvis_land[at] + np.array([rows_of[i][3] for i in judged]) - land.pelvis_ref[at]
        ok.update(zip(judged, within_reach_all(
            rig, p, np.array([rows_of[i][0] for i in judged]), np.stack([sampled[i] for i in judged]),
            land.hip_now[at], hip_land).tolist(), strict=True))
    return {i: (ok[i], samples) for i, samples in sampled.items()}


def choose(
    env: Environment, rig: Rig, p: ControllerParams, land: Landing, feet: FootState,
    flags: tuple[BoolArray, BoolArray, BoolArray],
    rows_of: list[tuple[int, int, int, FloatArray]], couples: list[Couple], ctl: StepControls,
    u_grid: FloatArray, stats: StepStats,
) -> list[Chosen]:
    """Each planned foot's swing: the planner's couple if it stays within reach (or the foot
    must move: its way out may be a detour); else, for a foot that must move (left behind,
    or its support gone) or whose swing a moving obstacle cut, the straight fallback step;
    else nothing. A failed re-plan of a foot already in the air keeps its trajectory; a
    failed plan of a foot on the ground leaves it there (``failed``; a forced one tries
    again at the next step: ``forced`` is cleared). ``flags`` = (swinging, forced, failed)
    ``(N,)``, the last two updated in place."""
    swinging, forced, failed = flags
    done: list[Chosen] = []
    within = _within_reach(rig, p, land, rows_of, couples, forced, u_grid)
    for i, ((leg, j, c, hip_own), couple) in enumerate(zip(rows_of, couples, strict=True)):
        stats.n_plans += 1
        stats.n_couples += couple.n_couples
        stats.n_paths += couple.n_paths
        samples = within[i][1] if i in within else None
        if couple.ok and samples is not None and within[i][0]:
            target = np.asarray(couple.footprint, dtype=np.float64).copy()
        elif ((forced[leg] and not swinging[leg]) or feet.blocked[leg]) and (
            straight := straight_step(
                env, rig, p, leg, feet.foot[leg], land.preferred_xy[j], u_grid, float(ctl.step_height[c]),
                p.candidate_radius * float(rig.legs.leg_length[leg]), land.hip_now[j],
                land.pelvis_land[j] + hip_own - land.pelvis_ref[j],
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
            if not swinging[leg]:
                failed[leg] = True
                # a foot that must move tries again at the next step (the body moved)
                forced[leg] = False
            continue
        failed[leg] = False
        done.append((leg, j, c, samples, target))
    return done


def commit(
    env: Environment, rig: Rig, p: ControllerParams, watch: Watch, feet: FootState, body: Body,
    land: Landing, done: list[Chosen], ctl: StepControls, start_u: FloatArray, u_grid: FloatArray,
) -> None:
    """Write every chosen swing into the feet's plans at once, starting at swing progress
    ``start_u (N,)`` (where the foot is now): land on the exact surface under the foot's
    point (the planner's grid height is the highest point under the foot's sole), easing
    the change in over the second half of the swing; a footprint whose point hangs over a
    hole (its foot box only partly on the edge) moves onto the ground its box reaches, over
    the second half of the swing. Also the footprint error ``body.feedback``, and the ground
    under every planned foot's preferred footprint (``feet.preferred``, in the same query)."""
    pref = land.preferred_xy

    def preferred(h: FloatArray) -> None:
        feet.preferred[land.legs, 2] = np.where(h > VOID, h, 0.0)

    if not done:
        preferred(env.height_at(pref))
        return
    leg_ids = np.array([d[0] for d in done])
    rows = np.array([d[1] for d in done])
    chars = np.array([d[2] for d in done])
    samples_all = np.array([d[3] for d in done])
    targets = np.array([d[4] for d in done])
    ease = _second_half_ease(u_grid.tobytes())
    samples_all[:, -1, :2] = targets[:, :2]
    n = samples_all.shape[0] * samples_all.shape[1]

    def ask(first: bool) -> tuple[FloatArray, FloatArray, BoolArray]:
        # the ground under the footprints; where things move, in one query with the swings'
        # samples (the last one is the footprint) and the watch rings of their landing spots;
        # the first time, with the preferred footprints last
        if not watch.dynamic:
            xy = targets[:, :2]
        else:
            xy = np.concatenate([samples_all[..., :2].reshape(-1, 2), ring_points(watch, leg_ids, targets)])
        m = xy.shape[0]
        asked = np.concatenate([xy, pref]) if first else xy
        heights = env.height_at(asked)
        if first:
            preferred(heights[m:])
            heights = heights[:m]
        if not watch.dynamic:
            return heights, np.zeros(0), np.zeros(0, dtype=bool)
        k = samples_all.shape[1]
        return heights[k - 1 : n : k], heights, env.forbidden_at(asked)[:m]

    h, heights, flags = ask(True)
    shifted = False
    for i in (h <= VOID).nonzero()[0].tolist():
        shift = onto_support(env, rig, targets[i, :2], int(chars[i]))
        if shift is not None:
            samples_all[i, :, :2] += shift[None, :] * ease[:, None]
            targets[i, :2] += shift
            shifted = True
    if shifted:
        h, heights, flags = ask(False)
    exact = np.where(h > VOID, h, 0.0)
    drop = targets[:, 2] - exact
    snap = ((drop >= -1e-9) & (drop <= p.snap_tolerance * ctl.step_height[chars])) | (
        exact > targets[:, 2]
    )
    samples_all[..., 2] -= np.where(snap, drop, 0.0)[:, None] * ease[None, :]
    targets[:, 2] = np.where(snap, exact, targets[:, 2])
    samples_all[:, -1] = targets
    plan = feet.plan
    plan.traj[leg_ids] = samples_all
    ring: tuple[FloatArray, BoolArray, FloatArray, BoolArray] | None = None
    near = None
    if watch.dynamic:
        plan.ground[leg_ids] = heights[:n].reshape(leg_ids.size, -1)
        plan.forbidden[leg_ids] = flags[:n].reshape(leg_ids.size, -1)
        near = swing_planned(env, watch, leg_ids, samples_all, targets)
        ring = (heights[n:], flags[n:], plan.ground[leg_ids, -1], plan.forbidden[leg_ids, -1])
    plan.u0[leg_ids] = start_u[leg_ids]
    plan.target[leg_ids] = targets
    plan.support[leg_ids] = exact
    watch_reset(env, watch, leg_ids, targets, ring, near)
    plan.heading[leg_ids] = ctl.heading[chars]
    plan.speed[leg_ids] = ctl.speed[chars]
    plan.spacing[leg_ids] = ctl.spacing[leg_ids]
    body.feedback[leg_ids] = targets[:, :2] - land.preferred_xy[rows]


@functools.lru_cache(maxsize=8)
def swing_grid(samples: int) -> FloatArray:
    """The swing parameters ``u`` of a plan's ``samples + 1`` trajectory samples, 0 to 1
    (made once per count; read-only)."""
    u = np.linspace(0.0, 1.0, samples + 1)
    u.setflags(write=False)
    return u


@functools.lru_cache(maxsize=8)
def _second_half_ease(u_bytes: bytes) -> FloatArray:
    """``commit``'s ease over the second half of a swing at the parameters whose bytes are
    ``u_bytes`` (0 up to half way, then smoothstep to 1; made once per grid, read-only)."""
    u = np.frombuffer(u_bytes, dtype=np.float64)
    ease = np.clip((u - 0.5) / 0.5, 0.0, 1.0)
    ease = ease * ease * (3.0 - 2.0 * ease)
    ease.setflags(write=False)
    return ease


def planner_params(
    rig: Rig, p: ControllerParams, level: PlannerLOD | None, override: PlannerParams | None,
    char: int, step_height: float,
) -> PlannerParams:
    """The planner settings of a character at a step height, shared by its feet (the
    controller makes them once per character, LOD and step height): the derived ones, or the
    character's own ``override`` settings, with the step height, the mean leg length as
    reach and the height change from ``ControllerParams``. ``level``: the character's LOD."""
    length = float(rig.char_leg_length[char])
    if override is None:
        return PlannerParams(
            step_height=float(step_height),
            slice_size=rig.slice_size[char] if level is None else level.slice_size,
            leg_reach=length,
            candidate_radius=p.candidate_radius * length,
            fixed_distance=p.fixed_distance * length,
            max_couples_after_first=p.max_couples_after_first
            if level is None
            else level.max_couples_after_first,
            max_height_change=p.max_height_change * length,
        )
    return replace(override, step_height=float(step_height), leg_reach=length,
                   max_height_change=p.max_height_change * length)


def leg_geometry(rig: Rig, p: ControllerParams, leg: int, step_height: float) -> LegGeometry:
    """What the planner checks of leg ``leg`` (the controller makes it once per leg and step
    height): its foot box and sole, its 3D reach (the comfortable reach), its line to the hip
    clear of the ground (bowed by half the arch its knees take at rest), and no footprint
    hanging over a height step of more than ``snap_tolerance`` of the step height (or a 1:4
    slope under the foot)."""
    char = int(rig.leg_char[leg])
    half = (float(rig.foot_half[char, 0]), float(rig.foot_half[char, 1]))
    return LegGeometry(
        foot_half_extents=half,
        sole_half_extents=(float(rig.sole_half[char, 0]), float(rig.sole_half[char, 1])),
        reach_3d=float(rig.comfort_reach[leg]),
        leg_length=float(rig.legs.leg_length[leg]),
        leg_arch=float(0.5 * rig.leg_arch[leg]),
        max_straddle=max(p.snap_tolerance * float(step_height), 0.25 * max(half)),
    )

