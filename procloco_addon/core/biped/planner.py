# SPDX-License-Identifier: GPL-3.0-or-later
"""The whole biped pipeline (biped thesis chapter 3), from a start pose to a goal.

1. **Search** the footprint graph with A* (§3.2) → right footprints and clips (and short
   strides where a foot must land on every tread of a stair).
2. **Smooth** the footprints (§3.3), snapping them back onto their platforms. Every
   footprint keeps the *terrace* it was planned on (the tread of a stair, a landing, the
   ground) with its whole sole supported there, through smoothing, refinement and
   re-spacing, so no foot is set down over a step's edge or into a riser.
3. **Play** the clips (§3.4) and **refine** the footprints towards the clips' own (§3.5).
4. Carry the played **body trajectory** onto the desired footprints (§3.6).
5. **Blend groups** (§3.7): walks and runs become one group blended by the path's
   curvature τ and the walk/run parameter s; strides whose count no longer fits the
   blended clips are laid out again (:mod:`.respace`, the thesis' future work); play
   again, refine again, carry again.
6. **IK** (§3.8): body offset, then the legs, holding the lower of heel and toe; swinging
   feet are lifted over the edges they pass (:func:`.ik.swing_lift`).

:func:`plan_biped` returns every frame's root, pelvis and joint rotations plus the
footprints and per-stage timings. Everything is deterministic for a given generator.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import quat
from .blend_groups import lowpass, path_curvature, speed_parameter, turning_weights
from .blending import Footprints, Plan, Playback, one_hot_plan, plan_footprints, play
from .database import ClipDatabase
from .graph import (
    FootprintGraph,
    GoalOffSurfaceError,
    GraphSettings,
    NoClipsError,
    PlanCancelled,
    PlanningError,
    StartOffSurfaceError,
    relative_to_right,
    stride_geometry,
)
from .ik import IKResult, IKSettings, solve
from .refine import refine
from .respace import respace
from .skeleton import LEFT, RIGHT, Skeleton, forward_kinematics
from .smoothing import smooth_footprints
from .surface import WalkableSurface
from .trajectory import transfer

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

__all__ = ["BipedMotion", "PlanCancelled", "PlannerSettings", "PlanningError", "plan_biped"]


@dataclass(frozen=True)
class PlannerSettings:
    """Everything the pipeline can be tuned by (seconds, metres, radians).

    ``dt`` is the output frame step. ``sigma`` is in strides (§3.7.2);
    ``curvature_window`` the time before and after a frame of the three-point curvature;
    ``curvature_spacing`` the knot spacing of its B-spline low-pass (§3.7.1).
    ``blend_groups=False`` keeps the graph's clips (with cross-fades only);
    ``allow_run=False`` keeps s = 0 (the thesis' Turns scenario). ``respace`` adds or removes
    strides where the blended clips' stride does not fit the footprints (measured in
    ``benchmarks/bench_biped.py``: it halves the mismatch and the legs' correction).
    ``tau_from_smoothed`` measures the curvature on the smoothed footprints rather than on
    the first refinement's, which inherits the zig-zag of the graph's discrete clips.
    """

    dt: float = 1.0 / 60.0
    graph: GraphSettings = field(default_factory=GraphSettings)
    smoothing_iterations: int = 4
    refinement_iterations: int = 10
    crossfade: float = 0.3
    blend_groups: bool = True
    allow_run: bool = True
    curvature_window: float = 0.4
    curvature_spacing: float = 1.0
    sigma: float = 2.0
    tau_from_smoothed: bool = True
    respace: bool = True
    ik: IKSettings = field(default_factory=IKSettings)


@dataclass(frozen=True)
class BipedMotion:
    """The planned motion, ``F`` frames at ``dt`` seconds.

    ``root_pos (F, 3)``/``root_yaw (F,)``: the character's ground frame; ``pelvis_pos
    (F, 3)``: the pelvis in it; ``joint_rot (F, J, 4)``: local joint rotations (see
    :mod:`.skeleton`); ``contact (F, 2)``: footprint index each foot stands on (-1 swing);
    ``ik_targets (F, 2, 3)``: where the IK held each foot's lower point (NaN in swing).
    ``footprints``: the desired footprints (positions, headings, sides, stance times);
    ``clips (K,)``/``weights (K, S, C)``: the final plan; ``timings``: seconds per stage.
    """

    dt: float
    root_pos: FloatArray
    root_yaw: FloatArray
    pelvis_pos: FloatArray
    joint_rot: FloatArray
    contact: IntArray
    ik_targets: FloatArray
    footprints: Footprints
    clips: IntArray
    weights: FloatArray
    timings: dict[str, float]
    expansions: int
    playback: Playback
    ik: IKResult
    respaced: tuple[tuple[int, int, int], ...] = ()

    @property
    def n_frames(self) -> int:
        return len(self.root_yaw)


class _Clock:
    def __init__(self) -> None:
        self.times: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.times[name] = self.times.get(name, 0.0) + now - self._t
        self._t = now


def _check(progress: Callable[[float, str], bool] | None, fraction: float, stage: str) -> None:
    if progress is not None and not progress(fraction, stage):
        raise PlanCancelled()


def _group_weights(
    db: ClipDatabase,
    plan: Plan,
    tau_u: Callable[[FloatArray], FloatArray],
    s_u: Callable[[FloatArray], FloatArray],
) -> FloatArray:
    """New per-segment weights: walk and run segments become the blend group (§3.7)."""
    weights = plan.weights.copy()
    n_seg, n_samp, _ = weights.shape
    walks = db.by_role("walk")
    runs = db.by_role("run")
    phase = np.linspace(0.0, 1.0, n_samp)
    for k in range(n_seg):
        fam = db.infos[int(plan.clips[k])].role.family
        if fam not in ("walk", "run"):
            continue
        u = k + phase
        tau = tau_u(u)
        s = s_u(u) if runs else np.zeros(n_samp)
        w = np.zeros((n_samp, len(db.clips)))
        if walks:
            ww = turning_weights(tau, np.array([i.curvature for i in walks]))
            w[:, [i.index for i in walks]] += (1.0 - s)[:, None] * ww
        else:
            s = np.ones(n_samp)
        if runs:
            wr = turning_weights(tau, np.array([i.curvature for i in runs]))
            w[:, [i.index for i in runs]] += s[:, None] * wr
        weights[k] = w / w.sum(axis=1, keepdims=True)
    return weights


def _speed_knots(db: ClipDatabase, plan: Plan) -> tuple[FloatArray, FloatArray]:
    """Fixed values of s at the ends of special clips and of the animation (§3.7.2)."""
    fu = [0.0, float(plan.n_segments)]
    fs = [0.0, 0.0]
    for k, c in enumerate(plan.clips):
        role = db.infos[int(c)].role
        if role.family in ("walk", "run"):
            continue
        value = 1.0 if role.is_running else 0.0
        fu += [float(k), float(k + 1)]
        fs += [value, value]
    return np.array(fu), np.array(fs)


def foot_size(skel: Skeleton) -> tuple[float, float]:
    """Half length and half width (m) of the sole :meth:`.WalkableSurface.supports` checks:
    half the heel-to-toe distance of the rest pose (the longer foot), and half of that (no
    rig gives the foot's width; a human foot is about a third as wide as it is long, plus
    room for the skin)."""
    pos, _ = forward_kinematics(skel, quat.identity((skel.n_joints,)), skel.offsets[0])
    length = max(
        float(np.linalg.norm(pos[skel.leg(s).toe, :2] - pos[skel.leg(s).heel, :2])) for s in (LEFT, RIGHT)
    )
    return 0.5 * length, 0.25 * length


def _short_stride_lefts(
    db: ClipDatabase,
    plan: Plan,
    want: Footprints,
    right_pos: FloatArray,
    right_yaw: FloatArray,
    scales: FloatArray,
) -> Footprints:
    """Left footprints of the graph's short strides where the graph put them (the clip's own
    left step on the shortened stride), not where the clip's natural stride would."""
    pos = want.pos.copy()
    yaw = want.yaw.copy()
    for k in range(1, plan.n_segments - 1):
        f = float(scales[k - 1])
        if f == 1.0:
            continue
        info = db.infos[int(plan.clips[k])]
        _, _, left_p, left_y = stride_geometry(db, info, f)
        p, y = quat.compose2(right_pos[k], float(right_yaw[k]), left_p, left_y)
        idx = np.flatnonzero((want.segment == k) & (want.side == LEFT))
        pos[idx[-1:]] = p
        yaw[idx[-1:]] = float(y)
    return want.with_poses(pos, np.unwrap(yaw))


def plan_biped(
    db: ClipDatabase,
    surface: WalkableSurface,
    start_pos: FloatArray,
    start_yaw: float,
    goal: FloatArray,
    goal_yaw: float | None = None,
    settings: PlannerSettings | None = None,
    rng: np.random.Generator | None = None,
    progress: Callable[[float, str], bool] | None = None,
) -> BipedMotion:
    """Plan a biped's walk from a standing start to a standing stop at ``goal``.

    ``start_pos (3,)``/``start_yaw``: the character's ground frame at the first frame;
    ``goal (2 or 3,)``: where its ground frame should end (``goal_yaw``: facing, optional).
    ``progress(fraction, stage)`` is called between stages (and during the search); when it
    returns False the planning stops with :class:`PlanCancelled`. Raises a
    :class:`PlanningError` subclass with a message for the user when no plan exists.
    """
    settings = settings or PlannerSettings()
    rng = rng or np.random.default_rng(0)
    clock = _Clock()
    surface = surface.with_foot(*foot_size(db.skeleton))
    start_info = db.first("start")
    stop_info = db.first("stop")
    if start_info is None or stop_info is None or not db.by_role("walk"):
        raise NoClipsError("the planner needs at least a START, a STOP and one WALK clip")
    start_pos = np.asarray(start_pos, dtype=float)
    goal_xy = np.asarray(goal, dtype=float)[:2]
    if not bool(surface.supported(goal_xy[None])[0]):
        raise GoalOffSurfaceError("the goal is not on a walkable surface")
    if not bool(surface.supported(start_pos[None, :2])[0]):
        raise StartOffSurfaceError("the character does not stand on a walkable surface")
    z0 = float(surface.height_at(start_pos[None, :2])[0])
    start_pos = np.array([start_pos[0], start_pos[1], z0])

    # 1. Search: from the right footprint after the START clip.
    _check(progress, 0.0, "search")
    rs = start_info.right_start
    r0_pos, r0_yaw = quat.compose2(start_pos, start_yaw, rs.pos, rs.yaw)
    r1_pos, r1_yaw = quat.compose2(start_pos, start_yaw, start_info.end_right_pos, start_info.end_right_yaw)
    r1_pos = np.array([r1_pos[0], r1_pos[1], float(surface.raster_height(r1_pos[None, :2])[0])])
    if not np.isfinite(r1_pos[2]):
        raise StartOffSurfaceError("there is no room in front of the character to start walking")
    families = ("walk", "run", "jump") if settings.allow_run else ("walk", "jump")
    graph = FootprintGraph(db, surface, settings.graph, rng, families)
    search_progress = None if progress is None else (lambda f: progress(0.4 * f, "search"))
    path = graph.search(r1_pos, float(r1_yaw), goal_xy, goal_yaw, stop_info, search_progress)
    clips = np.concatenate(([start_info.index], path.clips, [stop_info.index])).astype(np.int64)
    right_pos = np.vstack((r0_pos[None], path.right_pos))
    right_yaw = np.concatenate(([float(r0_yaw)], path.right_yaw))
    # Put the stop exactly on the goal: move the last right footprint by the residual.
    end_rel, end_rel_yaw = relative_to_right(stop_info, stop_info.cycle_pos, stop_info.cycle_yaw)
    end_xy = right_pos[-1, :2] + quat.rot2(right_yaw[-1], end_rel[:2])
    want_yaw = float(right_yaw[-1] + end_rel_yaw) if goal_yaw is None else float(goal_yaw)
    turn = quat.wrap_angle(want_yaw - (right_yaw[-1] + end_rel_yaw))
    right_yaw[-1] += turn
    right_pos[-1, :2] = goal_xy - quat.rot2(right_yaw[-1], end_rel[:2])
    del end_xy
    clock.lap("search")

    plan = one_hot_plan(db, clips, start_pos, start_yaw)
    want = plan_footprints(db, plan, (right_pos, right_yaw))
    if path.scales is not None:
        want = _short_stride_lefts(db, plan, want, right_pos, right_yaw, path.scales)
    n_fp = len(want)
    fixed = np.zeros(n_fp, dtype=bool)
    fixed[:2] = True  # the standing start
    fixed[-2:] = True  # the stop at the goal
    island = surface.island_at(want.pos)
    bad = island < 0
    if np.any(bad):
        # A footprint the graph placed within tolerance of an edge: its nearest island.
        island[bad] = surface.island_at(surface.snap(want.pos[bad]))
    end_snap = surface.snap(want.pos[-2:], island[-2:])
    want_pos = want.pos.copy()
    want_pos[-2:, 2] = end_snap[:, 2]
    # Each footprint's terrace: where its sole is supported nearest to where the clips put it
    # (the graph checked that there is such a place within a few centimetres).
    terrace = surface.terrace_at(want_pos)
    move = ~fixed
    want_pos[move] = surface.snap(want_pos[move], island[move], yaw=want.yaw[move])
    terrace[move] = surface.terrace_at(want_pos[move])
    # Segments of short strides (stairs): never re-laid at the clips' natural stride.
    short = np.zeros(len(clips), dtype=bool)
    if path.scales is not None:
        short[1:-1] = path.scales < 1.0 - 1e-9

    # 2. Smoothing.
    _check(progress, 0.4, "smoothing")
    want_pos, want_yaw_arr = smooth_footprints(
        want_pos, want.yaw, want.side, fixed, island, surface, settings.smoothing_iterations, terrace
    )
    smooth_pos, smooth_yaw = want_pos, want_yaw_arr
    respaced: tuple[tuple[int, int, int], ...] = ()
    clock.lap("smoothing")

    # 3-4. Play, refine, carry the body.
    _check(progress, 0.45, "playback")
    pb = play(db, plan, settings.dt, settings.crossfade)
    clock.lap("playback")
    fp = pb.footprints
    want_pos, want_yaw_arr = refine(
        fp.pos,
        fp.yaw,
        want_pos,
        want_yaw_arr,
        fixed,
        island,
        surface,
        settings.refinement_iterations,
        terrace,
    )
    clock.lap("refinement")
    body_pos, body_yaw = transfer(
        pb.t, pb.root_pos, pb.root_yaw, fp.time, fp.pos, fp.yaw, want_pos, want_yaw_arr
    )
    clock.lap("body_trajectory")

    # 5. Blend groups, then play, refine and carry again.
    if settings.blend_groups:
        _check(progress, 0.6, "blend groups")
        if settings.tau_from_smoothed:
            tau_body, _ = transfer(
                pb.t, pb.root_pos, pb.root_yaw, fp.time, fp.pos, fp.yaw, smooth_pos, smooth_yaw
            )
        else:
            tau_body = body_pos
        tau = lowpass(
            pb.t, path_curvature(pb.t, tau_body, settings.curvature_window), settings.curvature_spacing
        )
        fu, fs = _speed_knots(db, plan)

        def tau_u(u: FloatArray) -> FloatArray:
            return np.interp(u, pb.u, tau)

        def s_u(u: FloatArray) -> FloatArray:
            if not settings.allow_run:
                return np.zeros_like(u)
            return speed_parameter(u, fu, fs, settings.sigma)

        plan = Plan(plan.clips, _group_weights(db, plan, tau_u, s_u), plan.start_pos, plan.start_yaw)
        if settings.respace:
            smoothed = Footprints(
                want.side, want.segment, want.u_td, want.u_lo, smooth_pos, smooth_yaw, want.time
            )
            spaced, island = respace(db, plan, smoothed, surface, island, short, terrace)
            if spaced.terrace is not None:
                terrace = spaced.terrace
            plan = spaced.plan
            smooth_pos, smooth_yaw = spaced.footprints.pos, spaced.footprints.yaw
            fixed = np.zeros(len(smooth_pos), dtype=bool)
            fixed[:2] = fixed[-2:] = True
            respaced = spaced.changes
        clock.lap("blend_groups")
        _check(progress, 0.65, "playback")
        pb = play(db, plan, settings.dt, settings.crossfade)
        clock.lap("playback")
        fp = pb.footprints
        # Refine the smoothed footprints again, now towards the blended clips: starting from
        # the first refinement would keep the zig-zag of the graph's discrete clips.
        want_pos, want_yaw_arr = refine(
            fp.pos,
            fp.yaw,
            smooth_pos,
            smooth_yaw,
            fixed,
            island,
            surface,
            settings.refinement_iterations,
            terrace,
        )
        clock.lap("refinement")
        body_pos, body_yaw = transfer(
            pb.t, pb.root_pos, pb.root_yaw, fp.time, fp.pos, fp.yaw, want_pos, want_yaw_arr
        )
        clock.lap("body_trajectory")

    # 6. IK.
    _check(progress, 0.8, "inverse kinematics")
    result = solve(
        db.skeleton,
        pb,
        body_pos,
        body_yaw,
        want_pos,
        want_yaw_arr,
        settings.ik,
        surface.height_at,
        ground_tolerance=0.5 * surface.max_step,
    )
    clock.lap("ik")
    _check(progress, 1.0, "done")
    footprints = Footprints(fp.side, fp.segment, fp.u_td, fp.u_lo, want_pos, want_yaw_arr, fp.time)
    return BipedMotion(
        settings.dt,
        result.root_pos,
        result.root_yaw,
        result.pelvis_pos,
        result.joint_rot,
        pb.contact,
        result.targets,
        footprints,
        plan.clips,
        plan.weights,
        clock.times,
        path.expansions,
        pb,
        result,
        respaced,
    )


def stance_slide(points: FloatArray, which: IntArray, contact: IntArray) -> FloatArray:
    """Largest horizontal drift (m) of each footprint's holding point over its stance.

    ``points (F, 2, 2, 3)`` heel/toe in the world, ``which (F, 2)`` the held point per frame
    (-1 swing), ``contact (F, 2)`` the footprint index. Returns ``(N,)`` per footprint
    (NaN for footprints never held): for each run of frames holding the same point, the
    distance of that point from where it was at the run's first frame.
    """
    n_fp = int(contact.max()) + 1 if contact.size else 0
    out = np.full(n_fp, np.nan)
    frames = np.arange(len(points))
    for s in (LEFT, RIGHT):
        ci = contact[:, s]
        key = np.where(which[:, s] >= 0, ci * 2 + which[:, s], -1)
        start = np.concatenate(([True], key[1:] != key[:-1]))
        anchor = np.maximum.accumulate(np.where(start, frames, 0))
        held = np.flatnonzero(key >= 0)
        if len(held) == 0:
            continue
        p = points[held, s, which[held, s]]
        a = points[anchor[held], s, which[held, s]]
        drift = np.linalg.norm(p[:, :2] - a[:, :2], axis=1)
        for i in np.unique(ci[held]):
            sel = ci[held] == i
            out[i] = max(np.nan_to_num(out[i], nan=0.0), float(drift[sel].max()))
    return out
