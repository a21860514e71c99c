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
   safeguarded Newton iterations from a table of the leg's reach over that factor, made once
   per leg set, so the leg keeps its silhouette and the pose depends on the target only),
   then run CCD sweeps with per-joint limits (the thesis's solver) and finish with a few
   damped-least-squares iterations with an active set of limits, which get out of the
   straight-leg and joint-on-limit stalls where CCD alone stops short. Joint positions are
   rebuilt from angles and segment lengths, so bone lengths are exact by construction.

All legs are processed with the same numpy calls; Python loops run over joints and CCD
sweeps only. Shapes use ``N`` legs and ``s`` the longest leg's segment count.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..geometry import cross, sum_last, vector_norm
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


#: Knots of the table of each leg's reach over ``κ`` (:class:`BendLegs`): the Newton
#: iterations of :func:`solve_bend` start from the table's linear interpolation, two steps
#: from the answer (three reach evaluations) instead of about five from ``κ = 1``.
_BEND_KNOTS = 33


def _bend_reach(
    kappa: FloatArray, hinge: FloatArray, lengths: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Joint angles ``(N, s)`` and reach ``(N,)`` of chains bent by ``kappa (N,)``
    (:func:`solve_bend`), the end effector ``(N,)`` as a complex number (x + iy), and what
    :func:`_bend_slope` takes besides: the unclamped hinge turns ``(N, s)`` and each segment
    as a complex number ``(N, s)``."""
    # (called a few times per leg and frame: written with few, plain array operations; the
    # planar chain as complex numbers: the end is sum(l e^{iφ}))
    raw = kappa[:, None] * hinge
    th = np.minimum(np.maximum(raw, lo), hi)
    th[:, 0] = 0.0
    z = lengths * np.exp(1j * th.cumsum(axis=1))
    end = np.add.reduce(z, axis=1)
    return th, np.abs(end), end, raw, z


def _bend_slope(
    raw: FloatArray, hinge: FloatArray, lo: FloatArray, hi: FloatArray, z: FloatArray, end: FloatArray,
    r: FloatArray,
) -> FloatArray:
    """d(reach)/dκ ``(N,)`` of the chains :func:`_bend_reach` gave ``raw, z, end, r`` (found
    only when a Newton step is taken): d|E|/dκ = Re(conj(E) dE) / |E| with
    dE = i sum(l φ' e^{iφ})."""
    dphi = (hinge * ((raw > lo) & (raw < hi))).cumsum(axis=1)
    return np.asarray(-(end.conj() * np.add.reduce(z * dphi, axis=1)).imag / np.maximum(r, 1e-12))


@dataclass(frozen=True, eq=False)
class BendLegs:
    """What :func:`solve_bend` finds from the legs alone, once per leg set: segment
    ``lengths``, ``n_segments``, limits ``lo``/``hi`` ``(N, s)``, the ``hinge`` pattern (rest
    hinges; a leg straight at rest bends toward the side its limits allow), the ``valid``
    joints, the reach straight and folded ``(N,)``, the reach at ``κ`` = ``knots`` ``(K,)``,
    ``knot_reach (N, K)``, and each leg's ``total_length (N,)``."""

    lengths: FloatArray
    n_segments: IntArray
    lo: FloatArray
    hi: FloatArray
    hinge: FloatArray
    valid: npt.NDArray[np.bool_]
    r_straight: FloatArray
    r_folded: FloatArray
    knots: FloatArray
    knot_reach: FloatArray
    max_bend: float
    total_length: FloatArray

    @classmethod
    def make(
        cls, lengths: FloatArray, n_segments: IntArray, lo: FloatArray, hi: FloatArray, rest: FloatArray,
        max_bend: float = 3.0,
    ) -> BendLegs:
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
        knots = np.linspace(0.0, max_bend, _BEND_KNOTS)
        k = knots.size
        every = np.repeat(np.arange(n), k)  # (n * k,) each leg at every knot
        _, reach, _, _, _ = _bend_reach(np.tile(knots, n), hinge[every], lengths[every], lo[every], hi[every])
        knot_reach = reach.reshape(n, k)
        return cls(lengths, n_segments, lo, hi, hinge, valid, knot_reach[:, 0].copy(),
                   knot_reach[:, -1].copy(), knots, knot_reach, float(max_bend), lengths.sum(axis=1))

    def take(self, rows: IntArray) -> BendLegs:
        """These legs only."""
        return BendLegs(self.lengths[rows], self.n_segments[rows], self.lo[rows], self.hi[rows],
                        self.hinge[rows], self.valid[rows], self.r_straight[rows], self.r_folded[rows],
                        self.knots, self.knot_reach[rows], self.max_bend, self.total_length[rows])


def solve_bend(
    target: FloatArray,
    legs: BendLegs,
    *,
    iterations: int = 40,
    tolerance: float = 1e-10,
) -> tuple[FloatArray, FloatArray]:
    """Shape-preserving start for chains of any length (``legs``: :class:`BendLegs`);
    returns angles ``(N, s)`` and where their end effectors are ``(N,)`` (x + iy).

    The hinges take ``κ`` times their rest angles (clamped to their limits; a leg straight at
    rest bends toward the side its limits allow), with one ``κ ∈ [0, max_bend]`` per leg
    found by safeguarded Newton iterations (bisection whenever a step would leave the bracket)
    so the chain's reach equals the target distance, starting from the leg's table of reach
    over ``κ``; the hip pitch then aims the chain at the target. The leg keeps its rest
    silhouette, only more or less folded, and the pose depends on the target alone (no drift
    from frame to frame). Targets closer than the most folded pose stay at ``κ = max_bend``;
    beyond reach the leg is straight. Callers refine with ``solve_ccd``/``solve_dls`` where
    limits interfere.
    """
    n = target.shape[0]
    rows = np.arange(n)
    hinge, lengths, lo, hi, max_bend = legs.hinge, legs.lengths, legs.lo, legs.hi, legs.max_bend
    dist = np.sqrt(sum_last(target * target))
    tol = tolerance * legs.total_length
    # out of reach either way: straight, or folded as far as allowed
    too_far = legs.r_straight <= dist
    too_close = legs.r_folded >= dist
    settled = too_far | too_close
    # the start: the table's knots either side of the target distance, interpolated
    k = legs.knots.size
    j = np.minimum(np.maximum(np.add.reduce(legs.knot_reach > dist[:, None], axis=1), 1), k - 1)
    r0, r1 = legs.knot_reach[rows, j - 1], legs.knot_reach[rows, j]
    span = r0 - r1
    guess = legs.knots[j - 1] + (legs.knots[1] - legs.knots[0]) * np.minimum(
        np.maximum((r0 - dist) / np.where(span > 0.0, span, 1.0), 0.0), 1.0)
    kappa = np.where(too_far, 0.0, np.where(too_close, max_bend, guess))
    # safeguarded Newton on κ: the reach shrinks as the leg folds, so [k_lo, k_hi] brackets
    # the answer and a Newton step that leaves it is replaced by bisection
    k_lo = np.zeros(n)  # straight: longest reach
    k_hi = np.full(n, max_bend)
    for i in range(iterations + 1):
        th, r, end, raw, z = _bend_reach(kappa, hinge, lengths, lo, hi)
        if i == iterations:
            break
        f = r - dist
        done = settled | (np.abs(f) <= tol) | (k_hi - k_lo <= 1e-12)
        if np.count_nonzero(done) == n:
            break
        dr = _bend_slope(raw, hinge, lo, hi, z, end, r)
        longer = f > 0.0
        k_lo = np.where(longer, kappa, k_lo)
        k_hi = np.where(longer, k_hi, kappa)
        falling = dr < -1e-12
        newton = kappa - f / np.where(falling, dr, -1.0)
        ok = falling & (newton >= k_lo) & (newton <= k_hi)
        kappa = np.where(done, kappa, np.where(ok, newton, 0.5 * (k_lo + k_hi)))
    hip = wrap_to_limits(np.arctan2(target[:, 1], target[:, 0]) - np.arctan2(end.imag, end.real), lo[:, 0],
                         hi[:, 0])
    th[:, 0] = hip
    return np.where(legs.valid, th, 0.0), end * np.exp(1j * hip)


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
    # per joint: 1.0 where the leg has it (a turn times 0 is none), the middle of its limits
    active_joint = (np.arange(s)[None, :] < n_segments[:, None]).astype(np.float64).T.copy()
    mid = (0.5 * (lo + hi)).T.copy()
    lo_t, hi_t = lo.T.copy(), hi.T.copy()
    tx, ty = target[:, 0], target[:, 1]
    tol2 = tolerance * tolerance
    turned = np.empty((n, 2))
    for _ in range(max_sweeps):
        pts = forward_planar(theta, lengths)
        end = pts[rows, n_segments]
        miss = end - target
        if np.count_nonzero(sum_last(miss * miss) <= tol2) == n:
            break
        for j in range(s - 1, -1, -1):
            pivot = pts[:, j]
            v_end = end - pivot
            ex, ey = v_end[:, 0], v_end[:, 1]
            px, py = pivot[:, 0], pivot[:, 1]
            vtx, vty = tx - px, ty - py
            cross = ex * vty - ey * vtx
            dot = ex * vtx + ey * vty
            # wrap_to_limits, the middle of the limits found once
            th_j = theta[:, j]
            m = mid[j]
            wrapped = (th_j + np.arctan2(cross, dot) - m + np.pi) % _TWO_PI - np.pi + m
            turn = (np.minimum(np.maximum(wrapped, lo_t[j]), hi_t[j]) - th_j) * active_joint[j]
            theta[:, j] = th_j + turn
            c = np.cos(turn)
            sn = np.sin(turn)
            turned[:, 0] = c * ex - sn * ey
            turned[:, 1] = sn * ex + c * ey
            end = pivot + turned
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
    # the legs still iterating (``todo``), their angles ``th`` and their rows of the inputs,
    # taken again only when legs finish (the arithmetic is the same for every leg: a leg
    # stalled on a limit with the target along it gets out by the last bits of its gradient)
    todo = np.arange(n)
    th = theta
    t_len, t_seg, t_target, t_lo, t_hi = lengths, n_segments, target, lo, hi
    t_lo_in, t_hi_in = lo + 1e-9, hi - 1e-9
    t_valid = np.arange(s)[None, :] < n_segments[:, None]
    t_lam2 = (damping * np.add.reduce(lengths, axis=1)) ** 2
    t_tol2 = np.zeros(n) + np.asarray(tolerance, dtype=np.float64) ** 2
    rows = todo
    for _ in range(max_iterations):
        pts = forward_planar(th, t_len)
        end = pts[rows, t_seg]
        err = t_target - end
        converged = sum_last(err * err) <= t_tol2
        if np.count_nonzero(converged):
            theta[todo] = th
            if np.count_nonzero(converged) == converged.size:
                return theta
            keep = ~converged
            todo, th, pts, end, err = todo[keep], th[keep], pts[keep], end[keep], err[keep]
            rows = np.arange(todo.size)
            t_len, t_seg, t_target = lengths[todo], n_segments[todo], target[todo]
            t_lo, t_hi, t_lo_in, t_hi_in = lo[todo], hi[todo], t_lo_in[keep], t_hi_in[keep]
            t_valid, t_lam2, t_tol2 = t_valid[keep], t_lam2[keep], t_tol2[keep]
        # the Jacobian's columns (-r_y, r_x), r from each joint to the end effector
        r = end[:, None, :] - pts[:, :s, :]
        jx = -r[..., 1]
        jy = r[..., 0]
        ex, ey = err[:, 0], err[:, 1]
        grad = jx * ex[:, None] + jy * ey[:, None]  # (m, s)
        blocked = ((th <= t_lo_in) & (grad < 0.0)) | ((th >= t_hi_in) & (grad > 0.0))
        free = t_valid & ~blocked
        jx *= free
        jy *= free
        a11 = sum_last(jx * jx) + t_lam2
        a22 = sum_last(jy * jy) + t_lam2
        a12 = sum_last(jx * jy)
        det = a11 * a22 - a12 * a12
        x0 = (a22 * ex - a12 * ey) / det
        x1 = (a11 * ey - a12 * ex) / det
        step = jx * x0[:, None] + jy * x1[:, None]
        biggest = np.maximum.reduce(np.abs(step), axis=1, keepdims=True)
        step *= np.minimum(1.0, max_turn / np.maximum(biggest, 1e-12))
        step += th
        th = np.minimum(np.maximum(step, t_lo), t_hi)
    theta[todo] = th
    return theta


@dataclass(frozen=True, eq=False)
class _LegSet:
    """What :func:`solve_legs` finds from a ``LegBatch`` alone, once per batch: for the leg
    plane, ``rest_xy (N, 2)`` (the rest foot's horizontal offset from the hip), the fade
    length ``fade (N,)``, the rest
    normal ``normal (N, 3)`` and its quarter turn about z ``normal_turned`` (z zeroed), the
    legs of one, two and more segments (``one``, ``two``, ``many``) and the last ones'
    :class:`BendLegs`."""

    rest_xy: FloatArray
    fade: FloatArray
    normal: FloatArray
    normal_flat: FloatArray
    normal_turned: FloatArray
    one: IntArray
    two: IntArray
    many: IntArray
    bend: BendLegs


_LEG_SETS: weakref.WeakKeyDictionary[LegBatch, _LegSet] = weakref.WeakKeyDictionary()


def _leg_set(legs: LegBatch) -> _LegSet:
    """:class:`_LegSet` of ``legs``, made on first use (a ``LegBatch`` is immutable)."""
    made = _LEG_SETS.get(legs)
    if made is None:
        rest_xy = np.ascontiguousarray((legs.rest_foot - legs.hip_offset)[:, :2])
        nrm = legs.plane_normal
        flat = nrm.copy()
        flat[:, 2] = 0.0
        turned = np.stack([-nrm[:, 1], nrm[:, 0], np.zeros(legs.n_legs)], axis=1)
        seg = legs.n_segments
        many = np.flatnonzero(seg >= 3)
        bend = BendLegs.make(legs.segment_lengths[many], seg[many], legs.joint_min[many],
                             legs.joint_max[many], legs.rest_angles[many])
        made = _LegSet(rest_xy, 0.25 * legs.leg_length, nrm, flat, turned, np.flatnonzero(seg == 1),
                       np.flatnonzero(seg == 2), many, bend)
        _LEG_SETS[legs] = made
    return made


def leg_plane_normals(
    target_body: FloatArray, legs: _LegSet, yaw_weight: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Leg-plane normals ``(N, 3)`` in the body frame for feet at ``target_body (N, 3)`` (from
    the hips), and the unit hip-target lines ``(N, 3)``.

    The rest normal is turned about the body's z axis by ``yaw_weight`` times the foot's yaw
    (the angle between its rest and current horizontal directions from the hip, faded out as
    the foot comes under the hip), then the component along the hip-target line is removed.
    """
    d = target_body
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    rx, ry = legs.rest_xy[:, 0], legs.rest_xy[:, 1]
    # the dot and cross products of the rest foot's horizontal direction with the foot's
    yaw = np.arctan2(-ry * dx + rx * dy, rx * dx + ry * dy)
    h2 = dx * dx + dy * dy
    fade = np.minimum(np.sqrt(h2) / legs.fade, 1.0)
    psi = yaw_weight * fade * yaw
    pref = np.cos(psi)[:, None] * legs.normal_flat
    pref += np.sin(psi)[:, None] * legs.normal_turned
    pref[:, 2] = legs.normal[:, 2]
    d_len = np.sqrt(h2 + dz * dz)[:, None]
    # (a target at the hip itself: no line, d_hat 0)
    d_hat = d / np.where(d_len > 1e-12, d_len, np.inf)
    normal = pref - sum_last(pref * d_hat)[:, None] * d_hat
    norm = vector_norm(normal, keepdims=True)
    # target along the preferred normal itself: keep the unprojected rest normal
    return np.where(norm > 1e-6, normal / np.maximum(norm, 1e-12), legs.normal), d_hat


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
    p = prev - np.add.reduce(prev * axis, axis=1)[:, None] * axis
    p_len = vector_norm(p, keepdims=True)
    p /= np.maximum(p_len, 1e-12)
    side = cross(axis, p)  # p turned a quarter about the axis
    # the turn from p to normal about the axis: sin = (p x normal) . axis = (axis x p) . normal
    turn = np.arctan2(np.add.reduce(side * normal, axis=1), np.add.reduce(p * normal, axis=1))
    turn = np.minimum(np.maximum(turn, -max_turn), max_turn)[:, None]
    # Rodrigues about the axis; p is perpendicular to it
    out = np.cos(turn) * p
    out += np.sin(turn) * side
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
    ls = _leg_set(legs)
    n = legs.n_legs
    theta0 = legs.rest_angles if init is None else init
    target_body = ((target_world - hip_world)[:, None, :] @ body_rot)[:, 0]  # body_rot^T (target - hip)
    normal_body, axis = leg_plane_normals(target_body, ls, legs.yaw_weight)
    if prev_normal is not None:
        prev = np.asarray(prev_normal, dtype=np.float64)
        normal_body = follow_normals(normal_body, prev, axis, max_plane_turn)
    a, b = plane_axes(normal_body, _UP)
    target_2d = np.empty((n, 2))
    np.add.reduce(target_body * a, axis=1, out=target_2d[:, 0])
    np.add.reduce(target_body * b, axis=1, out=target_2d[:, 1])

    theta = theta0.copy()
    one, two, many, bend = ls.one, ls.two, ls.many, ls.bend
    if mask is not None:  # the legs to solve only
        solve = np.asarray(mask, dtype=bool)
        one, two = one[solve[one]], two[solve[two]]
        keep = np.flatnonzero(solve[many])
        if keep.size < many.size:
            many, bend = many[keep], bend.take(keep)
    if two.size:
        theta[two, :2] = solve_two_segment(
            target_2d[two], legs.segment_lengths[two, :2], legs.joint_min[two, :2], legs.joint_max[two, :2]
        )
    if one.size:
        theta[one, 0] = wrap_to_limits(
            np.arctan2(target_2d[one, 1], target_2d[one, 0]), legs.joint_min[one, 0], legs.joint_max[one, 0]
        )
    if many.size:
        idx = many
        t_i = target_2d[idx]
        lengths, n_seg, lo, hi = bend.lengths, bend.n_segments, bend.lo, bend.hi
        rows_i = np.arange(idx.size)
        tol_i = (np.zeros(n) + tolerance)[idx]
        if init is None or shape_preserving:
            start, end = solve_bend(t_i, bend)
            miss_start = end - (t_i[:, 0] + 1j * t_i[:, 1])
            err_start = np.sqrt(miss_start.real * miss_start.real + miss_start.imag * miss_start.imag)
        else:
            start = theta0[idx]
            err_start = vector_norm(forward_planar(start, lengths)[rows_i, n_seg] - t_i)
        theta[idx] = start
        if init is not None and shape_preserving and prev_normal is not None:
            # Frame after frame: from last frame's pose toward the shape-preserving one by a
            # bounded step per joint. Where the two agree (most frames) that is the
            # shape-preserving pose itself; where it jumps (a joint reaching its limit folds
            # the leg another way) the leg gets there over a few frames, the damped least
            # squares (the smallest joint motion) reaching the target from the stepped pose.
            prev = theta0[idx]
            far = (np.abs(start - prev) > max_plane_turn).any(axis=1).nonzero()[0]
            if far.size:
                t_f, len_f, nseg_f = t_i[far], lengths[far], n_seg[far]
                prev_f = prev[far]
                turn = np.minimum(np.maximum(start[far] - prev_f, -max_plane_turn), max_plane_turn)
                stepped = prev_f + turn
                followed = solve_dls(
                    t_f, len_f, nseg_f, lo[far], hi[far], stepped,
                    max_iterations=polish_iterations, tolerance=1e-3 * tol_i[far],
                )
                end_f = forward_planar(followed, len_f)[np.arange(far.size), nseg_f]
                # (to well within the tolerance: planted feet would creep by it otherwise);
                # where it does not get there, the shape-preserving start and CCD below
                ok = vector_norm(end_f - t_f) <= tol_i[far]
                theta[idx[far[ok]]] = followed[ok]
                err_start[far[ok]] = 0.0
        # CCD and the polish only where the start misses (joint limits, odd targets)
        miss = (err_start > tol_i).nonzero()[0]
        if miss.size:
            t_m, len_m, nseg_m = t_i[miss], lengths[miss], n_seg[miss]
            lo_m, hi_m = lo[miss], hi[miss]
            ccd = solve_ccd(
                t_m, len_m, nseg_m, lo_m, hi_m, start[miss], max_sweeps=max_sweeps, tolerance=tol_i[miss]
            )
            refined = solve_dls(
                t_m, len_m, nseg_m, lo_m, hi_m, ccd, max_iterations=polish_iterations, tolerance=tol_i[miss]
            )
            err_refined = vector_norm(forward_planar(refined, len_m)[np.arange(miss.size), nseg_m] - t_m)
            # out of reach, the straight start is already the closest pose: keep the better one
            better = err_refined < err_start[miss]
            theta[idx[miss[better]]] = refined[better]

    pts = forward_planar(theta, legs.segment_lengths)
    # the leg plane's axes and normal in the world: body_rot @ (a, b, normal)
    axes = np.empty((n, 3, 3))
    axes[..., 0] = a
    axes[..., 1] = b
    axes[..., 2] = normal_body
    world = body_rot @ axes
    # (coordinate by coordinate: the operations run along the joints, not over triples)
    joints_world = np.empty((*pts.shape[:2], 3))
    p0, p1 = pts[..., 0], pts[..., 1]
    for c in range(3):
        col = p0 * world[:, None, c, 0]
        col += p1 * world[:, None, c, 1]
        col += hip_world[:, None, c]
        joints_world[..., c] = col
    end_world = joints_world[np.arange(n), legs.n_segments]
    error = vector_norm(end_world - target_world)
    normal_world = world[..., 2]
    return IKResult(
        joints=joints_world, plane_normal=normal_world, angles=theta, error=error, normal_body=normal_body
    )
