# SPDX-License-Identifier: GPL-3.0-or-later
"""Parametric blending with the most stable blend point (biped thesis §3.4).

A :class:`Plan` says what plays: ``K`` segments, each one stride from a right footprint to
the next, with clip weights that may vary over the segment's phase (a single clip, or a
blend group, §3.7). Time inside the plan is the *segment coordinate* ``u`` (segment index
plus phase): all clips of a segment are played at the same phase, and a segment lasts the
weighted mean of its clips' durations, so blended strides stay in step. Consecutive
segments cross-fade their weights over ``crossfade`` seconds (0.3 s in the thesis).

:func:`play` turns a plan into per-frame motion. The root's yaw advances by the weighted
mean of the clips' yaw increments. Its position is *not* the weighted mean of the clips'
root displacements: that would keep the centre of gravity fixed when the weights change
and slide the planted feet (figure 3.3). Instead the root is placed so that the *blend
point* moves exactly as the clips move it. The blend point lies on the line between the two
feet (each foot represented by the lower of its heel and toe); it is the point of that line
whose velocity, blended from the clips' own foot velocities, is smallest (§3.4):

    α = clamp((|v_L|² − v_R·v_L) / |v_R − v_L|², 0, 1),   p_s = p_L + α (p_R − p_L)

With the right foot planted in every clip, α = 1 and the right foot does not move whatever
the weights do. The root's heading follows the same rule: it turns so that the heading of
the blend point's foot changes by the clips' blended turn, so a planted foot does not
pivot either when the weights change (the thesis blends the clips' rotation increments
only, which twists a planted foot whose heading relative to the body differs between the
clips). In a flight phase, with no foot on the ground, the root follows the plain weighted
mean of the clips' root motion. The velocities come from each clip alone, so there is no cyclic dependency
between the blend point and the motion it corrects, and the whole playback is vectorised
over frames (one cumulative sum at the end).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import quat
from .database import ClipDatabase
from .skeleton import LEFT, RIGHT, foot_points, forward_kinematics

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Plan:
    """What plays when.

    ``clips (K,)``: the clip the footprint graph chose for each segment (it says whether the
    segment is a blend group member or a special clip); ``weights (K, S, C)``: the clip
    weights over each segment's phase, sampled at ``S`` equally spaced phases (rows sum to
    1); ``start_pos (3,)``/``start_yaw``: the root at the first frame.
    """

    clips: IntArray
    weights: FloatArray
    start_pos: FloatArray
    start_yaw: float

    @property
    def n_segments(self) -> int:
        return len(self.clips)


def one_hot_plan(
    db: ClipDatabase, clips: IntArray, start_pos: FloatArray, start_yaw: float, samples: int = 33
) -> Plan:
    """A plan that plays each chosen clip alone (cross-fades only at the boundaries)."""
    clips = np.asarray(clips, dtype=np.int64)
    w = np.zeros((len(clips), samples, len(db.clips)))
    w[np.arange(len(clips)), :, clips] = 1.0
    return Plan(clips, w, np.asarray(start_pos, dtype=float), float(start_yaw))


@dataclass(frozen=True)
class Footprints:
    """A footprint sequence (alternating feet), arrays ``(N, ...)``.

    ``side``: 0 left, 1 right; ``segment``: the segment that made it; ``u_td``/``u_lo``:
    touchdown and lift-off in segment coordinates; ``pos (N, 3)``/``yaw``: the footprint;
    ``time``: the middle of its stance in seconds (filled in by playback).
    """

    side: IntArray
    segment: IntArray
    u_td: FloatArray
    u_lo: FloatArray
    pos: FloatArray
    yaw: FloatArray
    time: FloatArray

    def __len__(self) -> int:
        return len(self.side)

    def with_poses(self, pos: FloatArray, yaw: FloatArray) -> Footprints:
        return Footprints(self.side, self.segment, self.u_td, self.u_lo, pos, yaw, self.time)


def _segment_weights(plan: Plan, k: IntArray, phase: FloatArray) -> FloatArray:
    """Clip weights ``(M, C)`` of segments ``k (M,)`` at phases ``(M,)`` in [0, 1]."""
    s = plan.weights.shape[1]
    f = np.clip(phase, 0.0, 1.0) * (s - 1)
    i0 = np.minimum(np.floor(f).astype(np.int64), s - 2)
    w = (f - i0)[:, None]
    return plan.weights[k, i0] * (1.0 - w) + plan.weights[k, i0 + 1] * w


def contact_schedule(db: ClipDatabase, plan: Plan) -> Footprints:
    """Which footprints the plan makes and when (segment coordinates).

    Each segment's contacts are the weighted means of its clips' contact intervals at the
    segment's middle (its clips must share one contact pattern). A left contact at a
    segment's phase 0 continues the previous left footprint; a contact still on at a
    segment's end lasts into the next segment as long as that segment's clips keep the
    foot down.
    """
    k_all = np.arange(plan.n_segments)
    mid_w = _segment_weights(plan, k_all, np.full(plan.n_segments, 0.5))
    start_w = _segment_weights(plan, k_all, np.zeros(plan.n_segments))
    side: list[int] = []
    seg: list[int] = []
    td: list[float] = []
    lo: list[float] = []
    last = [-1, -1]
    for k in range(plan.n_segments):
        w = mid_w[k]
        members = [db.infos[c] for c in np.flatnonzero(w > 1e-9)]
        pattern = [(iv.side, iv.td == 0.0) for iv in members[0].intervals]
        for info in members[1:]:
            if [(iv.side, iv.td == 0.0) for iv in info.intervals] != pattern:
                raise ValueError(
                    f"clips {members[0].name!r} and {info.name!r} are blended but their foot contacts differ"
                )
        ww = np.array([w[info.index] for info in members])
        ww /= ww.sum()
        # How long a contact from the previous segment lasts: the clips at this segment's start.
        w0 = start_w[k] / max(float(start_w[k].sum()), 1e-12)
        init_end = sum(w0[c] * np.array(db.infos[c].initial_contact_end) for c in np.flatnonzero(w0 > 1e-9))
        for s in (LEFT, RIGHT):
            j = last[s]
            if j >= 0 and lo[j] >= k - 1e-9:
                lo[j] = k + float(init_end[s]) if init_end[s] > 0.0 else float(k)
        for n_iv in range(len(pattern)):
            ivs = [info.intervals[n_iv] for info in members]
            s = ivs[0].side
            t_d = float(sum(wi * iv.td for wi, iv in zip(ww, ivs, strict=True)))
            l_o = float(sum(wi * iv.lo for wi, iv in zip(ww, ivs, strict=True)))
            if k > 0 and s == LEFT and ivs[0].td == 0.0:
                continue  # continuation of the previous left footprint
            side.append(s)
            seg.append(k)
            td.append(k + t_d)
            lo.append(k + l_o)
            last[s] = len(side) - 1
    end = float(plan.n_segments)
    lo = [min(x, end) for x in lo]
    n = len(side)
    return Footprints(
        np.array(side, dtype=np.int64),
        np.array(seg, dtype=np.int64),
        np.array(td),
        np.array(lo),
        np.zeros((n, 3)),
        np.zeros(n),
        np.zeros(n),
    )


def plan_footprints(db: ClipDatabase, plan: Plan, right_poses: tuple[FloatArray, FloatArray]) -> Footprints:
    """The footprints the plan *wants*: each segment's clip footprints placed so that its
    right footprint lies on the given right poses ``(pos (K, 3), yaw (K,))`` (segment 0 is
    placed from the plan's start root instead)."""
    sched = contact_schedule(db, plan)
    pos = np.zeros((len(sched), 3))
    yaw = np.zeros(len(sched))
    rp, ry = right_poses
    for i in range(len(sched)):
        k = int(sched.segment[i])
        info = db.infos[int(plan.clips[k])]
        root_pos: FloatArray
        root_yaw: FloatArray | float
        if k == 0:
            root_pos, root_yaw = plan.start_pos, plan.start_yaw
        else:
            rs = info.right_start
            inv_pos, inv_yaw = quat.relative2(rs.pos, rs.yaw, np.zeros(3), 0.0)
            root_pos, root_yaw = quat.compose2(rp[k], ry[k], inv_pos, inv_yaw)
        ivs = [
            iv
            for iv in info.intervals
            if iv.side == sched.side[i] and not (k > 0 and iv.side == LEFT and iv.td == 0.0)
        ]
        # The n-th footprint of this side in this segment.
        nth = int(np.sum((sched.segment[:i] == k) & (sched.side[:i] == sched.side[i])))
        iv = ivs[nth]
        p, y = quat.compose2(np.asarray(root_pos, dtype=float), float(root_yaw), iv.pos, iv.yaw)
        pos[i] = p
        yaw[i] = float(y)
    yaw = np.unwrap(yaw)
    return sched.with_poses(pos, yaw)


@dataclass(frozen=True)
class Playback:
    """Per-frame result of :func:`play` (``F`` frames, ``J`` joints).

    ``t, u (F,)``: time and segment coordinate; ``root_pos (F, 3)``, ``root_yaw (F,)``;
    ``joint_rot (F, J, 4)``, ``pelvis_pos (F, 3)``: the blended pose; ``joint_pos_local``
    ``(F, J, 3)`` and ``joint_rot_local (F, J, 4)``: its forward kinematics in the character
    frame; ``points_local``/``points (F, 2, 2, 3)``: heel and toe of both feet in the
    character frame and in the world; ``alpha (F,)``: the blend point parameter;
    ``footprints``: the footprints the motion leaves; ``contact (F, 2)``: index of the
    footprint each foot stands on, -1 in swing.
    """

    dt: float
    t: FloatArray
    u: FloatArray
    weights: FloatArray
    columns: IntArray
    root_pos: FloatArray
    root_yaw: FloatArray
    joint_rot: FloatArray
    pelvis_pos: FloatArray
    joint_pos_local: FloatArray
    joint_rot_local: FloatArray
    points_local: FloatArray
    points: FloatArray
    alpha: FloatArray
    footprints: Footprints
    contact: IntArray

    @property
    def n_frames(self) -> int:
        return len(self.t)


def _columns(db: ClipDatabase, plan: Plan) -> tuple[IntArray, IntArray]:
    """Playback columns: one per looping clip, one per (non-looping clip, segment) use."""
    used = plan.weights.max(axis=1) > 0.0  # (K, C)
    clips: list[int] = []
    segs: list[int] = []
    for c in np.flatnonzero(used.any(axis=0)):
        if db.loops[c]:
            clips.append(int(c))
            segs.append(-1)
    for k in range(plan.n_segments):
        for c in np.flatnonzero(used[k]):
            if not db.loops[c]:
                clips.append(int(c))
                segs.append(k)
    return np.array(clips, dtype=np.int64), np.array(segs, dtype=np.int64)


def _column_weights(
    plan: Plan, col_clip: IntArray, col_seg: IntArray, k: IntArray, phase: FloatArray
) -> FloatArray:
    w = _segment_weights(plan, k, phase)[:, col_clip]
    return w * ((col_seg[None, :] < 0) | (col_seg[None, :] == k[:, None]))


def weight_grid(
    db: ClipDatabase,
    plan: Plan,
    col_clip: IntArray,
    col_seg: IntArray,
    crossfade: float,
    per_segment: int = 48,
) -> tuple[FloatArray, FloatArray]:
    """Column weights on a fine grid of ``u``, with the boundary cross-fades.

    Returns ``(u_grid (G,), weights (G, C'))``.
    """
    n_seg = plan.n_segments
    u = np.linspace(0.0, n_seg, n_seg * per_segment + 1)
    k = np.clip(np.floor(u).astype(np.int64), 0, n_seg - 1)
    w = _column_weights(plan, col_clip, col_seg, k, u - k)
    seg_dur = _segment_weights(plan, np.arange(n_seg), np.full(n_seg, 0.5)) @ db.duration
    b = np.clip(np.rint(u).astype(np.int64), 1, max(n_seg - 1, 1))
    if n_seg > 1:
        half = np.minimum(
            0.5 * crossfade / np.minimum(seg_dur[b - 1], seg_dur[np.minimum(b, n_seg - 1)]), 0.45
        )
        near = np.abs(u - b) < half
        if np.any(near):
            un, bn, hn = u[near], b[near], half[near]
            x = np.clip((un - bn + hn) / (2 * hn), 0.0, 1.0)
            beta = (x * x * (3 - 2 * x))[:, None]
            w_prev = _column_weights(plan, col_clip, col_seg, bn - 1, np.clip(un - (bn - 1), 0.0, 1.0))
            w_next = _column_weights(plan, col_clip, col_seg, bn, np.clip(un - bn, 0.0, 1.0))
            w[near] = (1 - beta) * w_prev + beta * w_next
    w /= np.maximum(w.sum(axis=1, keepdims=True), 1e-12)
    return u, w


def play(
    db: ClipDatabase,
    plan: Plan,
    dt: float,
    crossfade: float = 0.3,
    blend_point: bool = True,
    anchor_heading: bool = True,
) -> Playback:
    """Play a plan from its start root, one frame every ``dt`` seconds (§3.4).

    ``blend_point=False`` moves the root by the plain weighted mean of the clips' root
    displacements instead (the naive blend the thesis warns about; kept for comparison);
    ``anchor_heading=False`` turns it by the weighted mean of the clips' turns (as in the
    thesis) instead of keeping the blend point's foot heading.
    """
    skel = db.skeleton
    col_clip, col_seg = _columns(db, plan)
    u_grid, w_grid = weight_grid(db, plan, col_clip, col_seg, crossfade)
    t_eff = w_grid @ db.duration[col_clip]
    t_grid = np.concatenate(([0.0], np.cumsum(0.5 * (t_eff[1:] + t_eff[:-1]) * np.diff(u_grid))))
    t_end = float(t_grid[-1])
    n = round(t_end / dt) + 1
    t = np.minimum(np.arange(n) * dt, t_end)
    u = np.interp(t, t_grid, u_grid)
    n_seg = plan.n_segments
    # Per-frame column weights (linear in u between grid samples).
    g = np.clip(np.searchsorted(u_grid, u, side="right") - 1, 0, len(u_grid) - 2)
    a = ((u - u_grid[g]) / (u_grid[g + 1] - u_grid[g]))[:, None]
    weights = w_grid[g] * (1 - a) + w_grid[g + 1] * a
    # Only the (frame, column) pairs with a weight are sampled: a frame blends a handful of
    # clips, not all of them. Pairs come frame by frame (np.nonzero is row-major), so the
    # weighted sums over each frame's clips are np.add.reduceat over the pairs.
    rows, cols = np.nonzero(weights > 0.0)
    w = weights[rows, cols]
    starts = np.flatnonzero(np.concatenate(([True], rows[1:] != rows[:-1])))

    def blend(values: FloatArray) -> FloatArray:
        """Weighted sum per frame of per-pair values ``(M, ...)`` → ``(F, ...)``."""
        return np.add.reduceat(w.reshape((-1,) + (1,) * (values.ndim - 1)) * values, starts, axis=0)

    # Phases now and at the next frame, per pair.
    u_next = np.concatenate((u[1:], u[-1:]))
    seg = col_seg[cols]
    looping = seg < 0
    base = np.clip(np.floor(u).astype(np.int64), 0, n_seg - 1)[rows]
    ph = np.where(looping, u[rows] - base, np.clip(u[rows] - seg, 0.0, 1.0))
    ph_next = np.where(looping, u_next[rows] - base, np.clip(u_next[rows] - seg, 0.0, 1.0))
    cidx = col_clip[cols]
    ph_pose = np.minimum(ph, 1.0)

    r0, y0 = db.sample_root(cidx, ph)
    r1, y1 = db.sample_root(cidx, ph_next)
    naive_dyaw = blend(y1 - y0)

    # Blended pose and its forward kinematics in the character frame.
    joint_rot = quat.normalize(blend(db.sample("joint_rot", cidx, ph_pose)))
    pelvis_pos = blend(db.sample("pelvis_pos", cidx, ph_pose))
    jpos, jrot = forward_kinematics(skel, joint_rot, pelvis_pos)
    pts_local = foot_points(skel, jpos)  # (F, 2, 2, 3)
    fr = np.arange(n)
    nxt = np.minimum(fr + 1, n - 1)

    if blend_point:
        # Each clip's own motion of the foot points over this frame, in the character frame.
        p0 = db.sample_points(cidx, ph)
        p1 = db.sample_points(cidx, ph_next)
        disp = blend(quat.rot2(-y0[:, None, None], p1 - p0))  # (F, 2, 2, 3)
        low = np.argmin(pts_local[..., 2], axis=2)  # (F, 2): heel (0) or toe (1), per foot
        p_now = np.stack([pts_local[fr, s, low[:, s]] for s in (LEFT, RIGHT)], axis=1)  # (F, 2, 3)
        p_nxt = np.stack([pts_local[nxt, s, low[:, s]] for s in (LEFT, RIGHT)], axis=1)
        v = np.stack([disp[fr, s, low[:, s]] for s in (LEFT, RIGHT)], axis=1)
        v_l, v_r = v[:, LEFT], v[:, RIGHT]
        den = np.sum((v_r - v_l) ** 2, axis=1)
        num = np.sum(v_l * v_l, axis=1) - np.sum(v_r * v_l, axis=1)
        alpha = np.where(den > 1e-14, np.clip(num / np.maximum(den, 1e-300), 0.0, 1.0), 0.5)
        al = alpha[:, None]
        # With no foot on the ground (a run's flight) nothing anchors the blend point: the
        # root then moves as the clips' roots do.
        support = blend(db.sample("contact", cidx, ph_pose)).max(axis=1)
        # Heading: the same rule for rotations. The feet's headings change, in each clip, by
        # the clip's own turn; the root turns so that the blend point's foot heading changes
        # by the blended amount, whatever the change of weights does to the pose.
        wrap = ph_next > 1.0
        lam0 = db.sample("foot_yaw", cidx, ph_pose)
        lam1 = db.sample("foot_yaw", cidx, np.where(wrap, ph_next - 1.0, ph_next))
        d_psi = blend((y1 - y0)[:, None] + quat.wrap_angle(lam1 - lam0))
        head = pts_local[:, :, 1, :2] - pts_local[:, :, 0, :2]
        lam = np.arctan2(head[..., 1], head[..., 0])  # (F, 2)
        d_lam = quat.wrap_angle(lam[nxt] - lam)
        anchored_dyaw = (d_psi[:, LEFT] - d_lam[:, LEFT]) + alpha * (
            (d_psi[:, RIGHT] - d_lam[:, RIGHT]) - (d_psi[:, LEFT] - d_lam[:, LEFT])
        )
        dyaw = support * anchored_dyaw + (1.0 - support) * naive_dyaw if anchor_heading else naive_dyaw
    else:
        alpha = np.full(n, np.nan)
        dyaw = naive_dyaw
    dyaw[-1] = 0.0
    root_yaw = plan.start_yaw + np.concatenate(([0.0], np.cumsum(dyaw[:-1])))

    # The plain weighted mean of the clips' root displacements.
    naive = quat.rot2(root_yaw, blend(quat.rot2(-y0, r1 - r0)))
    if blend_point:
        s_now = p_now[:, LEFT] + al * (p_now[:, RIGHT] - p_now[:, LEFT])
        s_nxt = p_nxt[:, LEFT] + al * (p_nxt[:, RIGHT] - p_nxt[:, LEFT])
        v_s = v_l + al * (v_r - v_l)
        yaw_next = root_yaw[nxt]
        anchored = quat.rot2(root_yaw, v_s + s_now) - quat.rot2(yaw_next, s_nxt)
        # Heights always follow the clips' roots; the footprints' heights enter through the
        # body trajectory (§3.6).
        step = naive.copy()
        step[:, :2] = support[:, None] * anchored[:, :2] + (1.0 - support[:, None]) * naive[:, :2]
    else:
        step = naive
    step[-1] = 0.0
    root_pos = plan.start_pos + np.concatenate((np.zeros((1, 3)), np.cumsum(step[:-1], axis=0)))
    points = root_pos[:, None, None, :] + quat.rot2(root_yaw[:, None, None], pts_local)

    # Footprints the motion leaves, and which one each foot stands on.
    sched = contact_schedule(db, plan)
    m = len(sched)
    fp_pos = np.zeros((m, 3))
    fp_yaw = np.zeros(m)
    fp_time = np.zeros(m)
    contact = np.full((n, 2), -1, dtype=np.int64)
    for i in range(m):
        s = int(sched.side[i])
        frames = np.flatnonzero((u >= sched.u_td[i] - 1e-9) & (u <= sched.u_lo[i] + 1e-9))
        if len(frames) == 0:
            frames = np.array([int(np.argmin(np.abs(u - 0.5 * (sched.u_td[i] + sched.u_lo[i]))))])
        contact[frames, s] = i
        foot = points[frames, s]  # (m, 2, 3)
        mid = 0.5 * (foot[:, 0] + foot[:, 1])
        head = foot[:, 1, :2] - foot[:, 0, :2]
        ang = np.arctan2(head[:, 1], head[:, 0])
        fp_pos[i] = (mid[:, 0].mean(), mid[:, 1].mean(), foot[:, :, 2].min(axis=1).mean())
        fp_yaw[i] = np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())
        fp_time[i] = float(np.interp(0.5 * (sched.u_td[i] + sched.u_lo[i]), u, t))
    fp_yaw = np.unwrap(fp_yaw)
    footprints = Footprints(sched.side, sched.segment, sched.u_td, sched.u_lo, fp_pos, fp_yaw, fp_time)
    return Playback(
        dt,
        t,
        u,
        weights,
        col_clip,
        root_pos,
        root_yaw,
        joint_rot,
        pelvis_pos,
        jpos,
        jrot,
        pts_local,
        points,
        alpha,
        footprints,
        contact,
    )
