# SPDX-License-Identifier: GPL-3.0-or-later
"""The fast two-stage IK that pins planted feet to their footprints (biped thesis §3.8).

*IK point* (§3.8.3). A planted foot is held by whichever of its heel and toe is lower in
the animation at that frame: the heel just after touchdown, the toe as the heel rises. The
point's target is where the clip put it, carried from the original footprint to the
desired one by the footprint's rigid ground transform; it is held constant over each run
of frames with the same IK point, so a planted point cannot slide at all.

*Body offset* (§3.8.1). For every frame with a planted foot, a few iterations of

    F = p_ik − (p + q p_loc),   T = (q p_loc) × F,   p ← p + α F,   yaw ← yaw + β T_z

(α = ½, β = 1) move and turn the body towards the foot target — ``F`` pulls like a
force, ``T`` turns like its torque (written for our right-handed axes; the thesis' Unity
axes are left-handed). With both feet planted the two results are averaged. The offsets
are then low-passed by hierarchical B-splines: the body takes the slow part of the
correction, the legs the fast part. The root only turns about the vertical.

*Legs* (§3.8.2). With the body fixed, the foot's position and rotation leave one degree of
freedom per leg: the swivel of the knee about the hip–ankle line. The thesis searches it
(15–20 iterations); ``swivel="search"`` does the same (a golden-section search of the
angle that keeps thigh and shin closest to their animated rotations, squared angles
summed). ``swivel="analytic"`` (the default) is the closed form the thesis lists as future
work: the swivel that keeps the knee's hinge axis — fixed in the thigh — closest to its
animated direction. Measured on the Jumps scene (benchmarks/bench_biped.py), the search
ends at the same mean cost (no frame more than 1e-4 rad² apart) and makes the IK stage
five times slower; putting the knee in the plane of the animated knee instead costs five
times more rotation, mostly near a straight leg where that plane is ill-defined.
During swing the ankle correction is interpolated between the surrounding stances, so
the legs move continuously into and out of every footprint. If a target is out of reach
the pelvis is lowered (smoothly) until the leg reaches it.

*Swing clearance.* The clips swing their feet over flat ground; stepping up a stair the
interpolated correction alone would drag the toes through the riser's edge, and stepping
down it would lower the foot before it has left the step above. Every swinging frame the
foot's points (the ankle, every joint under it, and points along the sole from heel to
toe) are compared with the ground under them: where one is below the ground plus
``swing_clearance`` (the clearance easing in over the first and out over the last seventh of
the swing, so that lift-off and touchdown are untouched), the ankle is lifted. The lift over
each swing is the upper envelope of smooth arches, one per frame that needs lifting, each
rising from zero at lift-off to that frame's need and falling back to zero at touchdown: the
foot clears every edge and still leaves and meets the ground with zero vertical speed
added. A held point whose ground differs from its footprint's height by more than
``ground_tolerance`` (it hangs over an edge) keeps the footprint's height instead.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import quat
from .blending import Playback
from .skeleton import LEFT, RIGHT, Skeleton, foot_points, forward_kinematics
from .splines import hierarchical_fit

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_GOLDEN = 0.5 * (np.sqrt(5.0) - 1.0)


@dataclass(frozen=True)
class IKSettings:
    """Body-offset gains and iterations, B-spline spacings (s), swivel method, how far
    (metres) a swinging foot stays above the ground it passes over."""

    alpha: float = 0.5
    beta: float = 1.0
    body_iterations: int = 10
    body_spacings: tuple[float, ...] = (1.0, 0.5)
    swivel: str = "analytic"
    swivel_iterations: int = 20
    reach: float = 0.999
    swing_clearance: float = 0.02


@dataclass(frozen=True)
class IKResult:
    """Final motion: ``root_pos (F, 3)``, ``root_yaw (F,)``, ``pelvis_pos (F, 3)``,
    ``joint_rot (F, J, 4)``; ``targets (F, 2, 3)`` the IK point targets (NaN in swing),
    ``ik_point (F, 2)`` which point held each foot (0 heel, 1 toe, -1 swing),
    ``body_offset (F, 3)``/``body_turn (F,)`` the low-passed body correction and
    ``swivel_cost (F, 2)`` the squared rotation change of thigh and shin per leg."""

    root_pos: FloatArray
    root_yaw: FloatArray
    pelvis_pos: FloatArray
    joint_rot: FloatArray
    targets: FloatArray
    ik_point: IntArray
    body_offset: FloatArray
    body_turn: FloatArray
    swivel_cost: FloatArray


def _ground_map(
    orig_pos: FloatArray,
    orig_yaw: FloatArray,
    want_pos: FloatArray,
    want_yaw: FloatArray,
    idx: IntArray,
    points: FloatArray,
) -> FloatArray:
    """Carry points ``(M, 3)`` by the ground transforms of footprints ``idx (M,)``."""
    dyaw = want_yaw[idx] - orig_yaw[idx]
    rel = points - orig_pos[idx]
    return want_pos[idx] + quat.rot2(dyaw, rel)


@dataclass(frozen=True)
class _LegGeometry:
    """One leg over all frames: the hip, the unit hip→ankle direction ``e``, the swivel basis
    ``u, v`` (``u`` towards the animated knee), the hip angle, the ankle target and the
    animated knee, ankle, thigh and shin."""

    hip: FloatArray
    e: FloatArray
    u: FloatArray
    v: FloatArray
    cos_b: FloatArray
    sin_b: FloatArray
    target: FloatArray
    hinge0: FloatArray
    knee0: FloatArray
    ankle0: FloatArray
    thigh0: FloatArray
    shin0: FloatArray
    l1: float

    def rotations(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """World rotations of thigh and shin with the knee swivelled by ``theta (F,)``."""
        n_dir = np.cos(theta)[:, None] * self.u + np.sin(theta)[:, None] * self.v
        knee = self.hip + self.l1 * (self.cos_b[:, None] * self.e + self.sin_b[:, None] * n_dir)
        hinge = np.cross(knee - self.hip, self.target - knee)
        flat = np.linalg.norm(hinge, axis=1) < 1e-9
        hinge[flat] = self.hinge0[flat]
        # Each bone turns so that its animated direction and knee hinge map onto the new
        # ones: the knee stays a pure hinge and the thigh keeps its twist.
        rt = quat.from_two_frames(self.knee0 - self.hip, self.hinge0, knee - self.hip, hinge)
        rs = quat.from_two_frames(self.ankle0 - self.knee0, self.hinge0, self.target - knee, hinge)
        return quat.mul(rt, self.thigh0), quat.mul(rs, self.shin0)

    def cost(self, theta: FloatArray) -> FloatArray:
        """Squared rotation change of thigh and shin from the animation (what the swivel minimises)."""
        t_new, s_new = self.rotations(theta)
        return np.asarray(
            quat.angle_between(t_new, self.thigh0) ** 2 + quat.angle_between(s_new, self.shin0) ** 2
        )


def _golden_search(geom: _LegGeometry, iterations: int, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Per-frame golden-section minimisation of the swivel cost over ``[lo, hi]`` radians."""
    a = lo.copy()
    b = hi.copy()
    c = b - _GOLDEN * (b - a)
    d = a + _GOLDEN * (b - a)
    fc, fd = geom.cost(c), geom.cost(d)
    for _ in range(iterations):
        left = fc < fd  # the minimum lies in [a, d]
        b = np.where(left, d, b)
        a = np.where(left, a, c)
        new_c = np.where(left, b - _GOLDEN * (b - a), d)
        new_d = np.where(left, c, a + _GOLDEN * (b - a))
        f_new = geom.cost(np.where(left, new_c, new_d))
        fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
        c, d = new_c, new_d
    return 0.5 * (a + b)


def point_targets(
    pb: Playback,
    want_pos: FloatArray,
    want_yaw: FloatArray,
    ground: Callable[[FloatArray], FloatArray] | None = None,
    ground_tolerance: float = np.inf,
) -> tuple[FloatArray, IntArray]:
    """IK point targets ``(F, 2, 3)`` (NaN in swing) and the point used ``(F, 2)`` (§3.8.3).

    ``ground(xy (M, 2)) -> z (M,)`` puts every held point exactly on the ground (it is the
    lowest point of a planted foot); without it the point keeps the height the clip gave it
    above its footprint. Ground more than ``ground_tolerance`` away from the footprint's
    height is not the footprint's (the point hangs over an edge): the footprint's height is
    used there.
    """
    n = pb.n_frames
    fp = pb.footprints
    low = np.argmin(pb.points_local[..., 2], axis=2)  # (F, 2)
    targets = np.full((n, 2, 3), np.nan)
    which = np.full((n, 2), -1, dtype=np.int64)
    frames = np.arange(n)
    for s in (LEFT, RIGHT):
        ci = pb.contact[:, s]
        planted = ci >= 0
        key = np.where(planted, ci * 2 + low[:, s], -1)
        start = np.concatenate(([True], key[1:] != key[:-1]))
        anchor = np.maximum.accumulate(np.where(start, frames, 0))
        pts = pb.points[anchor, s, low[anchor, s]]  # the point where the run began
        idx = np.flatnonzero(planted)
        targets[idx, s] = _ground_map(fp.pos, fp.yaw, want_pos, want_yaw, ci[idx], pts[idx])
        if ground is not None and len(idx):
            z = ground(targets[idx, s, :2])
            own = want_pos[ci[idx], 2]
            z = np.where(np.abs(z - own) <= ground_tolerance, z, own)
            targets[idx, s, 2] = np.where(np.isfinite(z), z, targets[idx, s, 2])
        which[idx, s] = low[idx, s]
    return targets, which


def body_offset(
    pb: Playback,
    body_pos: FloatArray,
    body_yaw: FloatArray,
    targets: FloatArray,
    which: IntArray,
    settings: IKSettings,
) -> tuple[FloatArray, FloatArray]:
    """Per-frame body translation ``(F, 3)`` and turn ``(F,)`` toward the foot targets,
    low-passed by hierarchical B-splines (§3.8.1)."""
    n = pb.n_frames
    sum_p = np.zeros((n, 3))
    sum_y = np.zeros(n)
    count = np.zeros(n)
    for s in (LEFT, RIGHT):
        idx = np.flatnonzero(which[:, s] >= 0)
        if len(idx) == 0:
            continue
        p_loc = pb.points_local[idx, s, which[idx, s]]
        p = body_pos[idx].copy()
        yaw = body_yaw[idx].copy()
        tgt = targets[idx, s]
        for _ in range(settings.body_iterations):
            lever = quat.rot2(yaw, p_loc)
            force = tgt - (p + lever)
            torque_z = lever[:, 0] * force[:, 1] - lever[:, 1] * force[:, 0]
            p = p + settings.alpha * force
            yaw = yaw + settings.beta * torque_z
        sum_p[idx] += p - body_pos[idx]
        sum_y[idx] += yaw - body_yaw[idx]
        count[idx] += 1
    has = count > 0
    if not np.any(has):
        return np.zeros((n, 3)), np.zeros(n)
    off_p = sum_p / np.maximum(count, 1)[:, None]
    off_y = sum_y / np.maximum(count, 1)
    data = np.column_stack((off_p, off_y))
    fit = hierarchical_fit(pb.t, data, settings.body_spacings, pb.t, weights=has.astype(float))
    return fit[:, :3], fit[:, 3]


def knee_axis(knee_rot: FloatArray) -> FloatArray:
    """The knee's hinge axis in the thigh frame, from its animated rotations ``(F, 4)``:
    the angle-weighted mean rotation axis (the rest lateral axis ``+y`` if it never bends)."""
    r = quat.log(knee_rot)
    big = int(np.argmax(np.linalg.norm(r, axis=1)))
    if np.linalg.norm(r[big]) < 1e-6:
        return np.array([0.0, 1.0, 0.0])
    r = np.where(np.sum(r * r[big], axis=1, keepdims=True) < 0.0, -r, r)
    axis = r.sum(axis=0)
    return axis / np.linalg.norm(axis)


def _interpolate_swing(values: FloatArray, planted: NDArray[np.bool_]) -> FloatArray:
    """Fill non-planted frames of ``values (F, D)`` by smoothstep between the neighbouring
    planted frames (held before the first and after the last)."""
    n = len(values)
    idx = np.flatnonzero(planted)
    if len(idx) == 0:
        return np.zeros_like(values)
    frames = np.arange(n)
    j = np.clip(np.searchsorted(idx, frames, side="right") - 1, 0, len(idx) - 1)
    a = idx[j]
    b = idx[np.minimum(j + 1, len(idx) - 1)]
    x = np.where(b > a, (frames - a) / np.maximum(b - a, 1), 0.0)
    x = np.clip(x, 0.0, 1.0)
    w = (x * x * (3 - 2 * x))[:, None]
    out = values[a] * (1 - w) + values[b] * w
    out[frames < idx[0]] = values[idx[0]]
    out[planted] = values[planted]
    return out


def _arch_envelope(need: FloatArray) -> FloatArray:
    """The lift over one swing of ``m`` frames (``need (m,)``, the frames between two
    stances): the upper envelope of one arch per frame, each zero at both stances (with zero
    slope) and equal to that frame's need at its frame, so the result is at least ``need``."""
    m = len(need)
    u = np.arange(1, m + 1) / (m + 1)
    peak = u[None, :]  # arch j peaks at frame j
    x = u[:, None]
    up = x / peak
    down = (1.0 - x) / (1.0 - peak)
    a = np.clip(np.where(x <= peak, up, down), 0.0, 1.0)
    arch = a * a * (3.0 - 2.0 * a)
    return np.max(arch * np.maximum(need, 0.0)[None, :], axis=1)


def swing_lift(
    points: FloatArray,
    planted: NDArray[np.bool_],
    ground: Callable[[FloatArray], FloatArray],
    clearance: float,
) -> FloatArray:
    """How much to lift a swinging foot ``(F,)`` so that its points ``(F, P, 3)`` clear the
    ground under them by ``clearance`` (eased in and out at the ends of each swing); zero
    while ``planted (F,)``. Ground the points are not over (NaN) asks for nothing."""
    n = len(planted)
    lift = np.zeros(n)
    swing = np.flatnonzero(~planted)
    if len(swing) == 0:
        return lift
    # Runs of swinging frames.
    breaks = np.flatnonzero(np.diff(swing) > 1)
    starts = np.concatenate(([0], breaks + 1))
    ends = np.concatenate((breaks + 1, [len(swing)]))
    pts = points[swing]
    h = ground(pts[..., :2])
    run_of = np.repeat(np.arange(len(starts)), ends - starts)
    m = (ends - starts)[run_of]
    u = (np.arange(len(swing)) - starts[run_of] + 1) / (m + 1)
    ease = np.minimum(1.0, 8.0 * u * (1.0 - u))
    short = np.where(np.isfinite(h), h + (clearance * ease)[:, None] - pts[..., 2], -np.inf)
    need = np.max(short, axis=1)
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        if np.any(need[a:b] > 0.0):
            lift[swing[a:b]] = _arch_envelope(need[a:b])
    return lift


def _foot_points_in_ankle(skel: Skeleton, pb: Playback, side: int) -> FloatArray:
    """Points of one foot in its ankle joint's frame per frame ``(F, P, 3)``: the ankle,
    every joint under it, and three points along the sole between heel and toe."""
    leg = skel.leg(side)
    sub = [j for j in range(skel.n_joints) if skel.is_descendant(j, leg.ankle)]
    rel = pb.joint_pos_local[:, sub] - pb.joint_pos_local[:, leg.ankle][:, None, :]
    heel = pb.joint_pos_local[:, leg.heel] - pb.joint_pos_local[:, leg.ankle]
    toe = pb.joint_pos_local[:, leg.toe] - pb.joint_pos_local[:, leg.ankle]
    sole = heel[:, None, :] + np.array([0.25, 0.5, 0.75])[None, :, None] * (toe - heel)[:, None, :]
    rel = np.concatenate((rel, sole), axis=1)
    inv = quat.conj(pb.joint_rot_local[:, leg.ankle])[:, None, :]
    return quat.rotate(np.broadcast_to(inv, (*rel.shape[:2], 4)), rel)


def _smooth_drop(drop: FloatArray, k: int) -> FloatArray:
    """Smooth a non-positive correction while staying at or below it (min filter, then mean)."""
    if k <= 1:
        return drop
    pad = k // 2
    xp = np.pad(drop, pad, mode="edge")
    win = np.lib.stride_tricks.sliding_window_view(xp, k).min(axis=1)
    mp = np.pad(win, pad, mode="edge")
    return np.convolve(mp, np.ones(k) / k, mode="valid")


def solve_legs(
    skel: Skeleton,
    pb: Playback,
    root_pos: FloatArray,
    root_yaw: FloatArray,
    targets: FloatArray,
    which: IntArray,
    want_yaw: FloatArray,
    settings: IKSettings,
    ground: Callable[[FloatArray], FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Leg rotations that put the IK points on their targets (§3.8.2); with ``ground``, the
    swinging feet lifted clear of it (see the module docstring).

    Returns ``(joint_rot (F, J, 4), pelvis_pos (F, 3), swivel_cost (F, 2))``.
    """
    n = pb.n_frames
    fp = pb.footprints
    yaw_q = quat.from_yaw(root_yaw)[:, None, :]
    jpos_w = root_pos[:, None, :] + quat.rot2(root_yaw[:, None], pb.joint_pos_local)
    jrot_w = quat.mul(yaw_q, pb.joint_rot_local)
    ankle_targets = []
    foot_targets = []
    for s in (LEFT, RIGHT):
        leg = skel.leg(s)
        planted = which[:, s] >= 0
        ankle = jpos_w[:, leg.ankle]
        foot_rot = jrot_w[:, leg.ankle]
        d_ankle = np.zeros((n, 3))
        d_turn = np.zeros(n)
        idx = np.flatnonzero(planted)
        if len(idx):
            ci = pb.contact[idx, s]
            # Target foot rotation: the played one, turned with its footprint.
            turn = (want_yaw[ci] - fp.yaw[ci]) + pb.root_yaw[idx] - root_yaw[idx]
            rot_t = quat.mul(quat.from_yaw(turn), foot_rot[idx])
            point_ankle_local = pb.points_local[idx, s, which[idx, s]] - pb.joint_pos_local[idx, leg.ankle]
            in_foot = quat.rotate(quat.conj(pb.joint_rot_local[idx, leg.ankle]), point_ankle_local)
            a_t = targets[idx, s] - quat.rotate(rot_t, in_foot)
            d_ankle[idx] = a_t - ankle[idx]
            d_turn[idx] = turn
        filled = _interpolate_swing(np.column_stack((d_ankle, d_turn)), planted)
        a_target = ankle + filled[:, :3]
        f_target = quat.mul(quat.from_yaw(filled[:, 3]), foot_rot)
        if ground is not None and not np.all(planted):
            local = _foot_points_in_ankle(skel, pb, s)
            pts = a_target[:, None, :] + quat.rotate(
                np.broadcast_to(f_target[:, None, :], (*local.shape[:2], 4)), local
            )
            a_target[:, 2] += swing_lift(pts, planted, ground, settings.swing_clearance)
        ankle_targets.append(a_target)
        foot_targets.append(f_target)

    # Lower the pelvis where a leg cannot reach (the thesis' "stays above its feet").
    pelvis_pos = pb.pelvis_pos.copy()
    drop = np.zeros(n)
    for s in (LEFT, RIGHT):
        leg = skel.leg(s)
        reach = settings.reach * (skel.thigh_length[s] + skel.shin_length[s])
        d = ankle_targets[s] - jpos_w[:, leg.hip]
        dh2 = np.sum(d[:, :2] ** 2, axis=1)
        dz_max = np.sqrt(np.maximum(reach**2 - dh2, 0.0)) - (jpos_w[:, leg.hip, 2] - ankle_targets[s][:, 2])
        drop = np.minimum(drop, dz_max)
    if np.any(drop < 0.0):
        k = max(1, round(0.25 / pb.dt) | 1)
        drop = _smooth_drop(drop, k)
        pelvis_pos[:, 2] += drop
        jpos_local, _ = forward_kinematics(skel, pb.joint_rot, pelvis_pos)
        jpos_w = root_pos[:, None, :] + quat.rot2(root_yaw[:, None], jpos_local)

    joint_rot = pb.joint_rot.copy()
    cost = np.zeros((n, 2))
    for s in (LEFT, RIGHT):
        leg = skel.leg(s)
        hip = jpos_w[:, leg.hip]
        knee0 = jpos_w[:, leg.knee]
        ankle0 = jpos_w[:, leg.ankle]
        thigh0 = jrot_w[:, leg.hip]
        shin0 = jrot_w[:, leg.knee]
        target = ankle_targets[s]
        l1, l2 = skel.thigh_length[s], skel.shin_length[s]
        d = target - hip
        dist = np.linalg.norm(d, axis=1)
        e = d / np.maximum(dist, 1e-9)[:, None]
        dist_c = np.clip(dist, abs(l1 - l2) + 1e-6, (l1 + l2) * (1 - 1e-9))
        target = hip + e * dist_c[:, None]
        cos_b = np.clip((l1**2 + dist_c**2 - l2**2) / (2 * l1 * dist_c), -1.0, 1.0)
        sin_b = np.sqrt(1.0 - cos_b**2)
        ref = knee0 - hip
        u = ref - np.sum(ref * e, axis=1, keepdims=True) * e
        bad = np.linalg.norm(u, axis=1) < 1e-6
        if np.any(bad):
            fwd = quat.rotate(thigh0[bad], np.broadcast_to(np.array([1.0, 0.0, 0.0]), (int(bad.sum()), 3)))
            u[bad] = fwd - np.sum(fwd * e[bad], axis=1, keepdims=True) * e[bad]
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
        v = np.cross(e, u)
        # The knee's hinge axis, fixed in the thigh: the leg's animated bend plane even where
        # the leg is almost straight.
        hinge0 = quat.rotate(thigh0, np.broadcast_to(knee_axis(pb.joint_rot[:, leg.knee]), (n, 3)))
        bend = np.cross(knee0 - hip, ankle0 - knee0)
        if float(np.sum(hinge0 * bend)) < 0.0:
            hinge0 = -hinge0
        geom = _LegGeometry(hip, e, u, v, cos_b, sin_b, target, hinge0, knee0, ankle0, thigh0, shin0, l1)
        # Closed form: the swivel that keeps the hinge axis closest to the animated one
        # (the new hinge is sin θ u − cos θ v, up to its length).
        theta = np.arctan2(np.sum(hinge0 * u, axis=1), -np.sum(hinge0 * v, axis=1))
        if settings.swivel == "search":
            theta = _golden_search(geom, settings.swivel_iterations, theta - 1.0, theta + 1.0)
        elif settings.swivel != "analytic":
            raise ValueError(f"unknown swivel method {settings.swivel!r}")
        thigh_new, shin_new = geom.rotations(theta)
        cost[:, s] = geom.cost(theta)
        parent_rot = jrot_w[:, int(skel.parents[leg.hip])]
        joint_rot[:, leg.hip] = quat.mul(quat.conj(parent_rot), thigh_new)
        joint_rot[:, leg.knee] = quat.mul(quat.conj(thigh_new), shin_new)
        joint_rot[:, leg.ankle] = quat.mul(quat.conj(shin_new), foot_targets[s])
    return quat.hemisphere(joint_rot), pelvis_pos, cost


def solve(
    skel: Skeleton,
    pb: Playback,
    body_pos: FloatArray,
    body_yaw: FloatArray,
    want_pos: FloatArray,
    want_yaw: FloatArray,
    settings: IKSettings | None = None,
    ground: Callable[[FloatArray], FloatArray] | None = None,
    ground_tolerance: float = np.inf,
) -> IKResult:
    """Both IK stages for a played plan carried onto the body trajectory ``body_pos/yaw``
    (``ground``, ``ground_tolerance``: see :func:`point_targets`; the swinging feet clear
    ``ground`` too)."""
    settings = settings or IKSettings()
    targets, which = point_targets(pb, want_pos, want_yaw, ground, ground_tolerance)
    off_p, off_y = body_offset(pb, body_pos, body_yaw, targets, which, settings)
    root_pos = body_pos + off_p
    root_yaw = body_yaw + off_y
    joint_rot, pelvis_pos, cost = solve_legs(
        skel, pb, root_pos, root_yaw, targets, which, want_yaw, settings, ground
    )
    return IKResult(root_pos, root_yaw, pelvis_pos, joint_rot, targets, which, off_p, off_y, cost)


def achieved_points(skel: Skeleton, result: IKResult) -> FloatArray:
    """Heel and toe of both feet in the world for an IK result: ``(F, 2, 2, 3)``."""
    jpos, _ = forward_kinematics(skel, result.joint_rot, result.pelvis_pos)
    return result.root_pos[:, None, None, :] + quat.rot2(
        result.root_yaw[:, None, None], foot_points(skel, jpos)
    )
