# SPDX-License-Identifier: GPL-3.0-or-later
"""Leg inverse kinematics, vectorised over every leg of every character (thesis §3.1).

A leg is solved in two stages (joint model in ``morphology``):

1. the *leg plane*: it contains the hip and the target. Its normal is the leg's rest
   normal, turned about the body's up axis by the foot's horizontal yaw for splayed legs,
   then made perpendicular to the hip-target line (the smallest twist that puts the target
   in the plane). Knees therefore keep bending the way they do at rest and never flip.
   Solved frame after frame (``prev_normal``), the plane turns from last frame's toward
   that one by a bounded angle per frame: where the wanted plane jumps (the foot half a turn
   from its rest direction, or the hip-target line along the turned rest normal) the leg
   turns over a few frames instead of in one, and returns to the wanted plane after.
2. the planar chain. Two-segment legs use the closed-form law-of-cosines solution. Longer
   legs start from a shape-preserving guess (the rest bend scaled by one factor found by
   safeguarded Newton iterations, so the leg keeps its silhouette and the pose depends on
   the target only),
   then run CCD sweeps with per-joint limits (the thesis's solver) and finish with a few
   damped-least-squares iterations with an active set of limits, which get out of the
   straight-leg and joint-on-limit stalls where CCD alone stops short. Joint positions are
   rebuilt from angles and segment lengths, so bone lengths are exact by construction.

All legs are processed with the same numpy calls; Python loops run over joints and CCD
sweeps only. Shapes use ``N`` legs and ``s`` the longest leg's segment count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..geometry import cross, vector_norm
from .morphology import LegBatch, plane_axes

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_UP = np.array([0.0, 0.0, 1.0])
_TWO_PI = 2.0 * np.pi


@dataclass(frozen=True, eq=False)
class IKResult:
    """Solved legs.

    - ``joints``: ``(N, s + 1, 3)`` hip, inner joints and end effector (rows past a leg's end
      repeat the end effector), in the frame the targets were given in.
    - ``plane_normal``: ``(N, 3)`` leg-plane normals in that frame; hinge angles turn about it.
    - ``angles``: ``(N, s)`` joint angles (hip pitch, then hinges); pass back as ``init`` of the
      next solve for temporal coherence.
    - ``error``: ``(N,)`` distance from end effector to target (0 when reachable).
    - ``normal_body``: ``(N, 3)`` the leg-plane normals in each leg's body frame; pass back as
      ``prev_normal`` of the next solve so the leg plane turns continuously.
    """

    joints: FloatArray
    plane_normal: FloatArray
    angles: FloatArray
    error: FloatArray
    normal_body: FloatArray | None = None


def wrap_to_limits(angle: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Clamp angles to ``[lo, hi]`` after choosing the 2π-turn closest to the range."""
    mid = 0.5 * (lo + hi)
    wrapped = (angle - mid + np.pi) % _TWO_PI - np.pi + mid
    return np.minimum(np.maximum(wrapped, lo), hi)  # np.clip without its dispatch cost


def forward_planar(angles: FloatArray, lengths: FloatArray) -> FloatArray:
    """Planar joint positions ``(N, s + 1, 2)`` (hip at the origin) of chains with joint
    ``angles (N, s)`` and segment ``lengths (N, s)``."""
    # (ndarray methods, not np.cumsum: this runs a dozen times per frame and step)
    phi = angles.cumsum(axis=1)
    seg = np.empty((*phi.shape, 2))
    seg[..., 0] = lengths * np.cos(phi)
    seg[..., 1] = lengths * np.sin(phi)
    out = np.zeros((angles.shape[0], angles.shape[1] + 1, 2))
    seg.cumsum(axis=1, out=out[:, 1:])
    return out


def solve_two_segment(target: FloatArray, lengths: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Closed-form angles ``(N, 2)`` for two-segment planar legs.

    ``target (N, 2)`` in the leg plane (hip at the origin), ``lengths (N, 2)``, limits
    ``(N, 2)``. The knee bends on the side its limits allow (sign of the limits' middle);
    out-of-reach targets give the straightest allowed leg pointing at them.
    """
    l1 = lengths[:, 0]
    l2 = lengths[:, 1]
    r2 = np.einsum("ij,ij->i", target, target)
    cos_k = np.clip((r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2), -1.0, 1.0)
    side = np.where(lo[:, 1] + hi[:, 1] >= 0.0, 1.0, -1.0)
    knee = np.clip(side * np.arccos(cos_k), lo[:, 1], hi[:, 1])
    hip = np.arctan2(target[:, 1], target[:, 0]) - np.arctan2(l2 * np.sin(knee), l1 + l2 * np.cos(knee))
    return np.stack([wrap_to_limits(hip, lo[:, 0], hi[:, 0]), knee], axis=1)


# What solve_bend finds from the legs alone (hinge pattern, the reach straight and folded):
# the same legs every frame, so found once per leg set (a few entries: the calls per frame
# pass the same legs).
_BendSetup = tuple[FloatArray, npt.NDArray[np.bool_], FloatArray, FloatArray]
_BEND_SETUP: dict[tuple[object, ...], _BendSetup] = {}


def _bend_reach(
    kappa: FloatArray, hinge: FloatArray, lengths: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Joint angles ``(N, s)``, reach and d(reach)/dκ ``(N,)`` of chains bent by ``kappa (N,)``
    (:func:`solve_bend`)."""
    # (called some ten times per leg and frame: written with few, plain array operations)
    raw = kappa[:, None] * hinge
    th = np.minimum(np.maximum(raw, lo), hi)
    th[:, 0] = 0.0
    free = (raw > lo) & (raw < hi)
    dth = np.where(free, hinge, 0.0)
    phi = th.cumsum(axis=1)
    dphi = dth.cumsum(axis=1)
    c, sn = np.cos(phi), np.sin(phi)
    ex, ey = np.add.reduce(lengths * c, axis=1), np.add.reduce(lengths * sn, axis=1)
    ld = lengths * dphi
    dex, dey = -np.add.reduce(ld * sn, axis=1), np.add.reduce(ld * c, axis=1)
    r = np.sqrt(ex * ex + ey * ey)
    dr = (ex * dex + ey * dey) / np.maximum(r, 1e-12)
    return th, r, dr


def _bend_setup(
    lengths: FloatArray, n_segments: IntArray, lo: FloatArray, hi: FloatArray, rest: FloatArray,
    max_bend: float,
) -> _BendSetup:
    """``(hinge (N, s), valid (N, s), reach straight (N,), reach folded (N,))`` of
    :func:`solve_bend`'s legs, cached by value (read only)."""
    arrays = (lengths, n_segments, lo, hi, rest)
    key = (float(max_bend), *((a.dtype.str, a.shape, a.tobytes()) for a in arrays))
    made = _BEND_SETUP.get(key)
    if made is not None:
        return made
    n, s = rest.shape
    valid = np.arange(s)[None, :] < n_segments[:, None]
    hinge = rest.copy()
    hinge[:, 0] = 0.0
    hinge = np.where(valid, hinge, 0.0)
    straight = np.abs(hinge).sum(axis=1) < 1e-3
    if straight.any():
        side = np.where(lo + hi >= 0.0, 1.0, -1.0)
        default = np.where(valid, 0.3 * side, 0.0)
        default[:, 0] = 0.0
        hinge[straight] = default[straight]
    _, r_straight, _ = _bend_reach(np.zeros(n), hinge, lengths, lo, hi)
    _, r_folded, _ = _bend_reach(np.full(n, max_bend), hinge, lengths, lo, hi)
    for a in (hinge, valid, r_straight, r_folded):
        a.flags.writeable = False
    if len(_BEND_SETUP) >= 64:
        _BEND_SETUP.clear()
    made = (hinge, valid, r_straight, r_folded)
    _BEND_SETUP[key] = made
    return made


def solve_bend(
    target: FloatArray,
    lengths: FloatArray,
    n_segments: IntArray,
    lo: FloatArray,
    hi: FloatArray,
    rest: FloatArray,
    *,
    max_bend: float = 3.0,
    iterations: int = 40,
    tolerance: float = 1e-10,
) -> FloatArray:
    """Shape-preserving start for chains of any length; returns angles ``(N, s)``.

    The hinges take ``κ`` times their rest angles (clamped to their limits; a leg straight at
    rest bends toward the side its limits allow), with one ``κ ∈ [0, max_bend]`` per leg
    found by safeguarded Newton iterations (bisection whenever a step would leave the bracket)
    so the chain's reach equals the target distance; the hip pitch then
    aims the chain at the target. The leg keeps its rest silhouette, only more or less
    folded, and the pose depends on the target alone (no drift from frame to frame).
    Targets closer than the most folded pose stay at ``κ = max_bend``; beyond reach the leg
    is straight. Callers refine with ``solve_ccd``/``solve_dls`` where limits interfere.
    """
    n = rest.shape[0]
    rows = np.arange(n)
    hinge, valid, r_straight, r_folded = _bend_setup(lengths, n_segments, lo, hi, rest, max_bend)
    dist = np.sqrt(np.einsum("ij,ij->i", target, target))

    # safeguarded Newton on κ: the reach shrinks as the leg folds, so [k_lo, k_hi] brackets
    # the answer and a Newton step that leaves it is replaced by bisection
    k_lo = np.zeros(n)  # straight: longest reach
    k_hi = np.full(n, max_bend)
    tol = tolerance * lengths.sum(axis=1)
    # out of reach either way: straight, or folded as far as allowed
    too_far = r_straight <= dist
    too_close = r_folded >= dist
    kappa = np.where(too_far, 0.0, np.where(too_close, max_bend, 1.0))
    settled = too_far | too_close
    th = None  # the angles at the final kappa, when the loop ends on it
    for _ in range(iterations):
        th_k, r, dr = _bend_reach(kappa, hinge, lengths, lo, hi)
        f = r - dist
        done = settled | (np.abs(f) <= tol) | (k_hi - k_lo <= 1e-12)
        if done.all():
            th = th_k
            break
        longer = f > 0.0
        k_lo = np.where(longer, kappa, k_lo)
        k_hi = np.where(longer, k_hi, kappa)
        falling = dr < -1e-12
        newton = kappa - f / np.where(falling, dr, -1.0)
        ok = falling & (newton >= k_lo) & (newton <= k_hi)
        kappa = np.where(done, kappa, np.where(ok, newton, 0.5 * (k_lo + k_hi)))
    if th is None:
        th, _, _ = _bend_reach(kappa, hinge, lengths, lo, hi)
    end = forward_planar(th, lengths)[rows, n_segments]
    th[:, 0] = np.arctan2(target[:, 1], target[:, 0]) - np.arctan2(end[:, 1], end[:, 0])
    th[:, 0] = wrap_to_limits(th[:, 0], lo[:, 0], hi[:, 0])
    return np.where(valid, th, 0.0)


def solve_ccd(
    target: FloatArray,
    lengths: FloatArray,
    n_segments: IntArray,
    lo: FloatArray,
    hi: FloatArray,
    init: FloatArray,
    *,
    max_sweeps: int = 40,
    tolerance: float | FloatArray = 1e-5,
) -> FloatArray:
    """CCD with joint limits on planar chains; returns angles ``(N, s)``.

    Each sweep visits the joints from the end effector to the hip and turns each one so the
    end effector points at ``target (N, 2)``, clamped to ``[lo, hi]``. Joints at or past a
    leg's ``n_segments`` are left alone. Sweeps stop once every leg is within ``tolerance``
    (metres; one for all or ``(N,)``) or after ``max_sweeps``.
    """
    theta = init.copy()
    n, s = theta.shape
    rows = np.arange(n)
    active_joint = np.arange(s)[None, :] < n_segments[:, None]
    for _ in range(max_sweeps):
        pts = forward_planar(theta, lengths)
        end = pts[rows, n_segments]
        if np.all(np.einsum("ij,ij->i", end - target, end - target) <= tolerance * tolerance):
            break
        for j in range(s - 1, -1, -1):
            pivot = pts[:, j]
            v_end = end - pivot
            v_t = target - pivot
            cross = v_end[:, 0] * v_t[:, 1] - v_end[:, 1] * v_t[:, 0]
            dot = v_end[:, 0] * v_t[:, 0] + v_end[:, 1] * v_t[:, 1]
            new = wrap_to_limits(theta[:, j] + np.arctan2(cross, dot), lo[:, j], hi[:, j])
            turn = np.where(active_joint[:, j], new - theta[:, j], 0.0)
            theta[:, j] += turn
            c = np.cos(turn)
            sn = np.sin(turn)
            end = pivot + np.stack(
                [c * v_end[:, 0] - sn * v_end[:, 1], sn * v_end[:, 0] + c * v_end[:, 1]], axis=1
            )
    return theta


def solve_dls(
    target: FloatArray,
    lengths: FloatArray,
    n_segments: IntArray,
    lo: FloatArray,
    hi: FloatArray,
    init: FloatArray,
    *,
    max_iterations: int = 30,
    tolerance: float | FloatArray = 1e-5,
    damping: float = 0.02,
    max_turn: float = 0.35,
) -> FloatArray:
    """Damped least squares with joint limits on planar chains; returns angles ``(N, s)``.

    Finishes what CCD leaves: CCD stalls when a joint sits on a limit (a straight hock, a
    locked wrist) and the target needs the others to move together. Each iteration solves
    ``dθ = Jᵀ (J Jᵀ + λ² I)⁻¹ e`` with the joints that are pushed into a limit removed from
    the Jacobian (an active set), λ = ``damping`` times the leg length; steps are capped at
    ``max_turn`` radians. ``J Jᵀ`` is 2 × 2, so the solve is closed-form for all legs at once.
    ``tolerance``: metres, one for all or ``(N,)``.
    """
    theta = init.copy()
    n, s = theta.shape
    rows = np.arange(n)
    valid = np.arange(s)[None, :] < n_segments[:, None]
    lam2 = (damping * lengths.sum(axis=1)) ** 2
    tol2 = np.broadcast_to(np.asarray(tolerance, dtype=np.float64) ** 2, (n,))
    todo = rows
    # the legs still iterating: their rows of the inputs, taken again only when legs finish
    t_len, t_seg, t_target, t_lo, t_hi, t_valid, t_lam2, t_tol2 = (lengths, n_segments, target, lo, hi, valid,
                                                                   lam2, tol2)
    for _ in range(max_iterations):
        th = theta[todo]
        pts = forward_planar(th, t_len)
        end = pts[np.arange(todo.size), t_seg]
        err = t_target - end
        converged = np.einsum("ij,ij->i", err, err) <= t_tol2
        if converged.all():
            break
        if converged.any():  # go on with the others only
            keep = ~converged
            todo, th, pts, end, err = todo[keep], th[keep], pts[keep], end[keep], err[keep]
            t_len, t_seg, t_target = lengths[todo], n_segments[todo], target[todo]
            t_lo, t_hi, t_valid, t_lam2, t_tol2 = lo[todo], hi[todo], valid[todo], lam2[todo], tol2[todo]
        r = end[:, None, :] - pts[:, :s, :]
        jac = np.empty((todo.size, 2, s))  # (m, 2, s)
        jac[:, 0] = -r[..., 1]
        jac[:, 1] = r[..., 0]
        grad = np.einsum("mks,mk->ms", jac, err)
        at_lo = (th <= t_lo + 1e-9) & (grad < 0.0)
        at_hi = (th >= t_hi - 1e-9) & (grad > 0.0)
        free = t_valid & ~at_lo & ~at_hi
        jac = jac * free[:, None, :]
        a11 = np.einsum("ms,ms->m", jac[:, 0], jac[:, 0]) + t_lam2
        a22 = np.einsum("ms,ms->m", jac[:, 1], jac[:, 1]) + t_lam2
        a12 = np.einsum("ms,ms->m", jac[:, 0], jac[:, 1])
        det = a11 * a22 - a12 * a12
        x0 = (a22 * err[:, 0] - a12 * err[:, 1]) / det
        x1 = (a11 * err[:, 1] - a12 * err[:, 0]) / det
        step = jac[:, 0] * x0[:, None] + jac[:, 1] * x1[:, None]
        biggest = np.abs(step).max(axis=1, keepdims=True)
        step *= np.minimum(1.0, max_turn / np.maximum(biggest, 1e-12))
        theta[todo] = np.minimum(np.maximum(th + step, t_lo), t_hi)
    return theta


def leg_plane_normals(
    target_body: FloatArray,
    hip_body: FloatArray,
    rest_foot_body: FloatArray,
    rest_normal_body: FloatArray,
    yaw_weight: FloatArray,
    leg_length: FloatArray,
) -> FloatArray:
    """Leg-plane normals ``(N, 3)`` in the body frame for feet at ``target_body (N, 3)``.

    The rest normal is turned about the body's z axis by ``yaw_weight`` times the foot's yaw
    (the angle between its rest and current horizontal directions from the hip, faded out as
    the foot comes under the hip), then the component along the hip-target line is removed.
    """
    d = target_body - hip_body
    d_h = d[:, :2]
    r_h = (rest_foot_body - hip_body)[:, :2]
    yaw = np.arctan2(r_h[:, 0] * d_h[:, 1] - r_h[:, 1] * d_h[:, 0], np.einsum("ij,ij->i", r_h, d_h))
    fade = np.minimum(np.maximum(vector_norm(d_h) / (0.25 * leg_length), 0.0), 1.0)
    psi = yaw_weight * fade * yaw
    c = np.cos(psi)
    sn = np.sin(psi)
    pref = np.empty_like(rest_normal_body)
    pref[:, 0] = c * rest_normal_body[:, 0] - sn * rest_normal_body[:, 1]
    pref[:, 1] = sn * rest_normal_body[:, 0] + c * rest_normal_body[:, 1]
    pref[:, 2] = rest_normal_body[:, 2]
    d_len = vector_norm(d, keepdims=True)
    d_hat = np.divide(d, d_len, out=np.zeros_like(d), where=d_len > 1e-12)
    normal = pref - np.einsum("ij,ij->i", pref, d_hat)[:, None] * d_hat
    norm = vector_norm(normal, keepdims=True)
    # target along the preferred normal itself: keep the unprojected rest normal
    return np.where(norm > 1e-6, normal / np.maximum(norm, 1e-12), rest_normal_body)


def follow_normals(
    normal: FloatArray, prev: FloatArray, axis: FloatArray, max_turn: float
) -> FloatArray:
    """Leg-plane normals ``(N, 3)`` that turn from last frame's ``prev (N, 3)`` toward the
    wanted ``normal (N, 3)`` by at most ``max_turn`` radians.

    ``normal`` is perpendicular to the unit hip-target lines ``axis (N, 3)``; ``prev`` is first
    made so too (the smallest twist that puts this frame's target in last frame's plane), then
    turned about ``axis`` toward ``normal``. The wanted normal is a function of the target
    alone but not a continuous one: the turned rest normal's yaw wraps at half a turn behind
    the hip, and its projection is unstable where the hip-target line nearly lies along it.
    Followed this way the plane never flips from one frame to the next, and it comes back to
    the wanted one as soon as that stops jumping (so poses do not drift). Where ``prev`` lies
    along the axis the wanted normal is taken as it is.
    """
    p = prev - np.einsum("ij,ij->i", prev, axis)[:, None] * axis
    p_len = vector_norm(p, keepdims=True)
    p = p / np.maximum(p_len, 1e-12)
    sin = np.einsum("ij,ij->i", cross(p, normal), axis)
    cos = np.einsum("ij,ij->i", p, normal)
    turn = np.minimum(np.maximum(np.arctan2(sin, cos), -max_turn), max_turn)
    # Rodrigues about the axis; p is perpendicular to it
    out = np.cos(turn)[:, None] * p + np.sin(turn)[:, None] * cross(axis, p)
    return np.where(p_len > 1e-6, out, normal)


def solve_legs(
    legs: LegBatch,
    hip_world: FloatArray,
    body_rot: FloatArray,
    target_world: FloatArray,
    init: FloatArray | None = None,
    *,
    max_sweeps: int = 12,
    polish_iterations: int = 30,
    tolerance: float | FloatArray = 1e-5,
    shape_preserving: bool = True,
    mask: npt.NDArray[np.bool_] | None = None,
    prev_normal: FloatArray | None = None,
    max_plane_turn: float = 0.35,
) -> IKResult:
    """Pose every leg so its end effector reaches ``target_world``.

    - ``hip_world``: ``(N, 3)`` hip joint positions in the world.
    - ``body_rot``: ``(N, 3, 3)`` rotation (body to world) of the body each leg hangs from.
    - ``target_world``: ``(N, 3)`` end-effector targets.
    - ``tolerance``: metres within which a leg's solve stops, one for all or ``(N,)``.
    - ``init``: ``(N, s)`` starting angles (the previous frame's); rest angles by default.
      Used as the CCD start of legs with three or more segments when ``shape_preserving``
      is False; with it True (the default) those legs start from ``solve_bend``.
    - ``mask``: optional ``(N,)`` legs to solve; the others keep ``init`` (and their joints
      are rebuilt from it), e.g. off-screen characters under LOD.
    - ``prev_normal``: ``(N, 3)`` last frame's leg-plane normals in the body frame
      (``IKResult.normal_body``); the plane then turns toward this frame's wanted one by at
      most ``max_plane_turn`` radians (:func:`follow_normals`), and legs of three or more
      segments start from ``init`` moved toward the shape-preserving pose by at most that
      much per joint, so a foot moving by small steps moves every bone by small steps.
    """
    n = legs.n_legs
    rows = np.arange(n)
    theta0 = legs.rest_angles if init is None else init
    rot_t = np.transpose(body_rot, (0, 2, 1))
    target_body = np.einsum("nij,nj->ni", rot_t, target_world - hip_world)
    zero = np.zeros((n, 3))
    rest_foot_rel = legs.rest_foot - legs.hip_offset
    normal_body = leg_plane_normals(
        target_body, zero, rest_foot_rel, legs.plane_normal, legs.yaw_weight, legs.leg_length
    )
    if prev_normal is not None:
        t_len = vector_norm(target_body, keepdims=True)
        axis = np.divide(target_body, t_len, out=np.zeros_like(target_body), where=t_len > 1e-12)
        prev = np.asarray(prev_normal, dtype=np.float64)
        normal_body = follow_normals(normal_body, prev, axis, max_plane_turn)
    a, b = plane_axes(normal_body, _UP)
    target_2d = np.stack(
        [np.einsum("ij,ij->i", target_body, a), np.einsum("ij,ij->i", target_body, b)], axis=1
    )

    theta = theta0.copy()
    solve = np.ones(n, dtype=bool) if mask is None else mask.astype(bool)
    two = solve & (legs.n_segments == 2)
    if two.any():
        idx = np.flatnonzero(two)
        theta[idx, :2] = solve_two_segment(
            target_2d[idx], legs.segment_lengths[idx, :2], legs.joint_min[idx, :2], legs.joint_max[idx, :2]
        )
    one = solve & (legs.n_segments == 1)
    if one.any():
        idx = np.flatnonzero(one)
        theta[idx, 0] = wrap_to_limits(
            np.arctan2(target_2d[idx, 1], target_2d[idx, 0]), legs.joint_min[idx, 0], legs.joint_max[idx, 0]
        )
    many = solve & (legs.n_segments >= 3)
    if many.any():
        idx = np.flatnonzero(many)
        args = (
            target_2d[idx],
            legs.segment_lengths[idx],
            legs.n_segments[idx],
            legs.joint_min[idx],
            legs.joint_max[idx],
        )
        rows_i = np.arange(idx.size)
        tol_i = np.broadcast_to(np.asarray(tolerance, dtype=np.float64), (n,))[idx]

        def miss_of(th: FloatArray) -> FloatArray:
            return np.asarray(np.linalg.norm(forward_planar(th, args[1])[rows_i, args[2]] - args[0], axis=1))

        start = solve_bend(*args, legs.rest_angles[idx]) if init is None or shape_preserving else theta0[idx]
        err_start = miss_of(start)
        theta[idx] = start
        if init is not None and shape_preserving and prev_normal is not None:
            # Frame after frame: from last frame's pose toward the shape-preserving one by a
            # bounded step per joint. Where the two agree (most frames) that is the
            # shape-preserving pose itself; where it jumps (a joint reaching its limit folds
            # the leg another way) the leg gets there over a few frames, the damped least
            # squares (the smallest joint motion) reaching the target from the stepped pose.
            prev = theta0[idx]
            far = np.flatnonzero(np.any(np.abs(start - prev) > max_plane_turn, axis=1))
            if far.size:
                t_f, len_f, nseg_f = args[0][far], args[1][far], args[2][far]
                stepped = prev[far] + np.clip(start[far] - prev[far], -max_plane_turn, max_plane_turn)
                followed = solve_dls(
                    t_f, len_f, nseg_f, args[3][far], args[4][far], stepped,
                    max_iterations=polish_iterations, tolerance=1e-3 * tol_i[far],
                )
                end_f = forward_planar(followed, len_f)[np.arange(far.size), nseg_f]
                # (to well within the tolerance: planted feet would creep by it otherwise);
                # where it does not get there, the shape-preserving start and CCD below
                ok = np.linalg.norm(end_f - t_f, axis=1) <= tol_i[far]
                theta[idx[far[ok]]] = followed[ok]
                err_start[far[ok]] = 0.0
        # CCD and the polish only where the start misses (joint limits, odd targets)
        miss = np.flatnonzero(err_start > tol_i)
        if miss.size:
            t_m, len_m, nseg_m = args[0][miss], args[1][miss], args[2][miss]
            lo_m, hi_m = args[3][miss], args[4][miss]
            ccd = solve_ccd(
                t_m, len_m, nseg_m, lo_m, hi_m, start[miss], max_sweeps=max_sweeps, tolerance=tol_i[miss]
            )
            refined = solve_dls(
                t_m, len_m, nseg_m, lo_m, hi_m, ccd, max_iterations=polish_iterations, tolerance=tol_i[miss]
            )
            err_refined = np.linalg.norm(
                forward_planar(refined, len_m)[np.arange(miss.size), nseg_m] - t_m, axis=1
            )
            # out of reach, the straight start is already the closest pose: keep the better one
            better = err_refined < err_start[miss]
            theta[idx[miss[better]]] = refined[better]

    pts = forward_planar(theta, legs.segment_lengths)
    joints_body = pts[..., 0:1] * a[:, None, :] + pts[..., 1:2] * b[:, None, :]
    joints_world = hip_world[:, None, :] + np.einsum("nij,nkj->nki", body_rot, joints_body)
    end = joints_world[rows, legs.n_segments]
    error = np.linalg.norm(end - target_world, axis=1)
    normal_world = np.einsum("nij,nj->ni", body_rot, normal_body)
    return IKResult(
        joints=joints_world, plane_normal=normal_world, angles=theta, error=error, normal_body=normal_body
    )
