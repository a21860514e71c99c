# SPDX-License-Identifier: GPL-3.0-or-later
"""3D pendulums: secondary motion layered on top of an existing animation (thesis chapter 5).

Every bone of a chain is a pendulum: a bar of fixed length hanging from an anchor (its
father's tip, or for a tree's root the point where the chain meets the body) and pulled
toward a *target direction* by two planar spring-dampers. The state of a pendulum is its
**error**: two angles, one per plane, that tell how far the bar is from its target. The
target comes from the underlying animation (or is gravity, -Z), so with no perturbation
the error stays exactly zero and the pendulums replay the animation untouched; the
pendulums are a superimposed layer (thesis §5.4).

What perturbs a pendulum:

- its anchor changing velocity. The root anchor moves with the body (the whole motion
  counts); an inner pendulum's anchor is its father's tip, and only the part of that
  motion that is not in the animation counts (father pursuit, thesis §5.3.1);
- the body it hangs from changing its *angular* velocity (``anchor_frame``): a sway, a yaw
  oscillation, a turn starting or stopping leaves the masses behind while the targets turn
  with the body, so a tail lags and swings; a steady turn carries the chain as animated;
- explicit impulses (:class:`Impulses`): a mass displaced in world space. The displacement
  drags the ancestors toward it, bottom-up (son pursuit, thesis §5.3.2; a father sums,
  averages or weighs its sons' pulls, ``combine``) and the children follow in the top-down
  pass.

Design choices, and where they depart from the thesis:

- *Settling time.* Eq. 5.1, ``Ts = -ln(tol) / (ζ ω0)``, counts only the decay envelope.
  It ignores the ``1/sqrt(1-ζ²)`` factor of an underdamped response and the ``(1 + ω0 t)``
  factor of a critically damped one (at ζ = 1 the response is still at 20 % of its
  initial error at that ``Ts``). :func:`natural_frequency` therefore solves for the ω0 at
  which a spring released from rest enters the 5 % band for good exactly at ``Ts``; eq. 5.2
  then gives ``k`` and ``c``. :func:`natural_frequency_envelope` is eq. 5.1 as printed.
- *Two planar springs.* The error ``(θx, θz)`` holds the angle of the bar toward the
  target frame's x axis and toward its z axis (the thesis's XY and ZY planes around a Y
  target). Each is an independent spring-damper. They are combined into a direction by
  the exponential map of the sphere at the target (rotate the target by ``|θ|`` toward
  ``θx·x + θz·z``), so the bar keeps its length exactly and the two angles are the planar
  angles whenever the other one is zero.
- *Inertia.* The thesis holds a mass in place while its anchor moves (§5.3.1). Done
  literally, an anchor moving at constant speed leans the chain back by an angle that
  grows as the bars get shorter, and it depends on the time step. Here a mass keeps its
  *velocity* while its anchor moves: the geometric correction of §5.3.1 is applied to the
  part of the anchor's displacement that its previous velocity does not explain
  (the second difference of its position). Constant-velocity motion leaves the chain
  as animated; starts, stops, bobbing and turns make it swing.
- *Angular inertia.* An animated target is carried by the body's rotation, so without
  more a rotating body carries its chains rigidly (the thesis's anchors only translate).
  The same rule is applied to the body's rotation: the masses keep their angular
  velocity, and what turns them back is the part of the body's turn over a step that its
  previous turn does not explain, ``δ = D_k D_{k-1}ᵀ`` with ``D_k`` the body's rotation
  over step k. Every held bar turns back by δ in the world (its error changes by -δ), and
  with ``reaction`` every anchor below the root also feels how far δ carried it round the
  root (the lever arm); linearised this is the chain of point masses again, driven by
  ``e'' + 2ζω0 e' + ω0² e = -β''`` for a body yaw β. Gravity bars do not turn with the
  body and are not held; with ``reaction`` a gravity son feels its anchor's whole world
  motion (it follows no animation). Centripetal effects of the chain's own rotation are
  left out, so that a steady turn leaves the chain as animated; the root anchor's path
  still counts in full (a tail hanging behind a body that turns about its middle leans
  out of the turn, steadily). Without ``anchor_frame`` a rotating body carries its chains
  rigidly, as before.
- *When a push acts.* The springs step first and the step's pushes (anchor moved, body
  turned) are applied to the result, with the share ``1 / (1 + ζω0h)`` that makes them
  exactly the forcing of the discretised spring-damper: a bar on a body yawing at Ω
  follows the analytic driven response within 1 % in amplitude and 0.01 rad in phase at
  120 Hz. (Applying a push before the step, to the current bar, leads the response by one
  internal step.)
- *Sons push back (``reaction``, default on).* In the thesis a son follows its father but
  never acts on it. One-way coupling cannot hand energy back: a pendulum shaken below its
  resonance swings wider than its pivot, so a lightly damped chain shaken near its
  frequency amplifies link after link (an 8-bar tail shaken by 1 cm whirls round). Here a
  father also feels its sons' spring forces; linearised, the two passes are then exactly
  the dynamics of point masses on rods. A chain's slowest swing is slower than one bar's,
  so each tree is stiffened to give that swing the requested frequency (see
  ``_tree_modes``): a single bar settles exactly at Ts, a chain within about 1-4 Ts.
  ``reaction=False`` gives the thesis's one-way scheme.
- *Swing limit.* A bar stops at :data:`MAX_SWING` (170°) from its target and errors are
  kept continuous across the upside-down direction, so a violent start cannot spin a
  chain round or blow the simulation up.
- *Fixed internal rate.* The springs are integrated with a damped Störmer-Verlet step at
  ``rate_hz`` (default 120 Hz, doubled automatically for stiff springs and stiffened
  trees) whatever the animation's frame rate; the animation is interpolated between its
  samples (heads by cubic Hermite, frames by normalised blend) and the pendulum errors are
  interpolated back at the sample times.
- *Vectorised.* All pendulums of all trees of all characters are one flat array, sorted
  by depth; each pass is a loop over depth levels, and every level is a few numpy
  operations over all pendulums at that depth. With a few hundred pendulums per level
  numpy's per-call overhead dominates, so the level loop keeps calls few: what does not
  wait for the father (the sons' offsets, their first mirror, the anchors' pushes) is
  done for all pendulums before the loop, gathers use ``take``, and a father's swing
  reaches its sons as two mirrors (no cross products).

Frames: a pendulum's animated frame is a rotation matrix whose columns are the bone's
x, y and z axes in world space, y pointing from the bone's head to its tail (Blender's
bone convention). Twist about the bar is not simulated: the output keeps the animated
twist and only swings the bar.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..steps import run_steps

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

TOLERANCE_FRACTION = 0.05
"""The settling band: a spring has settled once it stays within 5 % of its initial error."""

DEFAULT_RATE_HZ = 120.0
"""Internal integration rate, independent of the scene's frame rate."""

MAX_OMEGA_STEP = 0.5
"""Largest ``ω0·h`` allowed; the internal rate is raised (doubled) until every spring fits."""
MAX_FAST_STEP = 0.5
"""Largest ``Ω·h`` for the fastest swing of a tree: the sons' reactions are explicit, and
chains of 6-10 bars were seen to go unstable at 1.0."""

MAX_SWING = np.radians(170.0)
"""A bar never swings further than this from its target: it stops there (its speed away from
the target is lost). The thesis has no joint limits; without a bound, a violent start (a body
jumping to full speed in one frame) could whirl a light chain round and round, and in the
one-way passes nothing takes that energy back out."""

REST_ANIMATION = 0
"""Rest direction: the animated bone direction (the pendulum replays the animation)."""
REST_GRAVITY = 1
"""Rest direction: straight down, world -Z (the bar hangs)."""

Combine = Literal["sum", "average", "weighted"]

_GRAVITY_FRAME = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""Target frame of a gravity pendulum: x = world X, y (the bar) = -Z, z = x × y = world Y."""


# ---------------------------------------------------------------------------------------
# Spring-dampers (thesis §5.2)
# ---------------------------------------------------------------------------------------


def _released_response(tau: FloatArray, zeta: FloatArray) -> FloatArray:
    """Unit error released from rest, ω0 = 1: x(τ) of ``x'' + 2ζx' + x = 0``, x(0) = 1."""
    out = np.empty(np.broadcast(tau, zeta).shape)
    tau, zeta = np.broadcast_arrays(tau, zeta)
    under = zeta < 1.0
    crit = zeta == 1.0
    over = zeta > 1.0
    if np.any(under):
        z, t = zeta[under], tau[under]
        wd = np.sqrt(1.0 - z * z)
        out[under] = np.exp(-z * t) * (np.cos(wd * t) + z / wd * np.sin(wd * t))
    if np.any(crit):
        t = tau[crit]
        out[crit] = (1.0 + t) * np.exp(-t)
    if np.any(over):
        z, t = zeta[over], tau[over]
        s = np.sqrt(z * z - 1.0)
        r1, r2 = -z + s, -z - s
        out[over] = (r2 * np.exp(r1 * t) - r1 * np.exp(r2 * t)) / (r2 - r1)
    return out


def settling_factor(damping: ArrayLike, tolerance: float = TOLERANCE_FRACTION) -> FloatArray:
    """Dimensionless settling time ``ω0·Ts`` of a spring released from rest.

    The last time at which ``|x(t)| = tolerance · |x(0)|``, for ω0 = 1. It depends on the
    damping ratio only; eq. 5.1 approximates it by ``-ln(tolerance) / ζ``.

    damping: ζ > 0, any shape. Returns the same shape.
    """
    zeta = np.asarray(damping, dtype=np.float64)
    if np.any(~(zeta > 0.0)):
        raise ValueError("damping ratio ζ must be > 0")
    if not 0.0 < tolerance < 1.0:
        raise ValueError("tolerance must be in (0, 1)")
    flat = zeta.reshape(-1)
    lo = np.zeros_like(flat)
    hi = np.empty_like(flat)
    under = flat < 1.0
    # Underdamped: the extrema are at kπ/ωd with |x| = exp(-ζkπ/ωd). The last one above the
    # band is k = K; the response leaves the band for good between it and the next extremum.
    zu = flat[under]
    wd = np.sqrt(1.0 - zu * zu)
    k_last = np.floor(-np.log(tolerance) * wd / (zu * np.pi))
    lo[under] = k_last * np.pi / wd
    hi[under] = (k_last + 1.0) * np.pi / wd
    # Critically and overdamped: monotone decay; the slow root bounds the crossing.
    zo = flat[~under]
    slow = np.where(zo > 1.0, zo - np.sqrt(np.maximum(zo * zo - 1.0, 0.0)), 1.0)
    hi[~under] = (-np.log(tolerance) + 4.0) / slow + 10.0
    # The response at extremum k has sign (-1)^k: after an odd extremum it rises to the band.
    k_all = np.zeros_like(flat)
    k_all[under] = k_last
    sign = np.where(np.mod(k_all, 2.0) == 1.0, -1.0, 1.0)
    # Bisection on x(τ) - sign·tol, which changes sign exactly once in [lo, hi].
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        above = sign * _released_response(mid, flat) > tolerance
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return (0.5 * (lo + hi)).reshape(zeta.shape)


def natural_frequency(
    settling_time: ArrayLike, damping: ArrayLike, tolerance: float = TOLERANCE_FRACTION
) -> FloatArray:
    """ω0 (rad/s) such that a spring released from rest settles within ``tolerance`` at ``Ts``.

    settling_time: Ts > 0 seconds; damping: ζ > 0 (broadcast together).
    """
    ts = np.asarray(settling_time, dtype=np.float64)
    if np.any(~(ts > 0.0)):
        raise ValueError("settling time Ts must be > 0 seconds")
    return settling_factor(damping, tolerance) / ts


def natural_frequency_envelope(
    settling_time: ArrayLike, damping: ArrayLike, tolerance: float = TOLERANCE_FRACTION
) -> FloatArray:
    """Eq. 5.1 as printed: ``ω0 = -ln(tolerance) / (ζ · Ts)`` (decay envelope only)."""
    ts = np.asarray(settling_time, dtype=np.float64)
    zeta = np.asarray(damping, dtype=np.float64)
    if np.any(~(ts > 0.0)) or np.any(~(zeta > 0.0)):
        raise ValueError("Ts and ζ must be > 0")
    return -np.log(tolerance) / (zeta * ts)


def spring_constants(
    settling_time: ArrayLike, damping: ArrayLike, mass: float = 1.0, tolerance: float = TOLERANCE_FRACTION
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(ω0, k, c)`` from the settling time and damping ratio (eq. 5.1 corrected, eq. 5.2).

    ``k = m ω0²`` and ``c = 2 m ζ ω0``.
    """
    omega0 = natural_frequency(settling_time, damping, tolerance)
    zeta = np.asarray(damping, dtype=np.float64)
    return omega0, mass * omega0**2, 2.0 * mass * zeta * omega0


def spring_step(
    x: ArrayLike, x_prev: ArrayLike, omega0: ArrayLike, damping: ArrayLike, h: float
) -> FloatArray:
    """One damped Störmer-Verlet step of ``x'' + 2ζω0 x' + ω0² x = 0`` (rest at 0).

    The velocity in the damping term is the central difference ``(x⁺ - x⁻) / 2h``, which
    keeps the scheme second order and free of overshoot at ζ ≥ 1 while ``ω0·h < 1``.
    Shapes broadcast: ``x`` and ``x_prev`` (..., k); ``omega0`` and ``damping`` (...,) or
    (..., 1).
    """
    a = np.asarray(damping) * np.asarray(omega0) * h
    b = (np.asarray(omega0) * h) ** 2
    xa, xp = np.asarray(x, dtype=np.float64), np.asarray(x_prev, dtype=np.float64)
    return (2.0 * xa - (1.0 - a) * xp - b * xa) / (1.0 + a)


def release_curve(
    settling_time: float, damping: float, duration: float, rate_hz: float = DEFAULT_RATE_HZ
) -> tuple[FloatArray, FloatArray]:
    """A unit error released from rest, integrated at ``rate_hz``: ``(t, x)``, each (m,)."""
    omega0 = float(natural_frequency(settling_time, damping))
    h = _internal_step(np.array([omega0]), rate_hz)
    m = int(np.ceil(duration / h)) + 1
    x = np.empty(m)
    x[0] = 1.0
    prev, cur = 1.0, 1.0
    for i in range(1, m):
        prev, cur = cur, float(spring_step(cur, prev, omega0, damping, h))
        x[i] = cur
    return np.arange(m) * h, x


def _internal_step(omega0: FloatArray, rate_hz: float) -> float:
    if not rate_hz > 0.0:
        raise ValueError("rate_hz must be > 0")
    h = 1.0 / rate_hz
    top = float(np.max(omega0)) if omega0.size else 0.0
    while top * h > MAX_OMEGA_STEP:
        h *= 0.5
    return h


# ---------------------------------------------------------------------------------------
# Small batched vector helpers (hot path: plain arithmetic on (m, 3) arrays)
# ---------------------------------------------------------------------------------------


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.einsum("...i,...i->...", a, b)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _normalize(v: FloatArray) -> FloatArray:
    n = np.sqrt(_dot(v, v))
    return v / np.maximum(n, 1e-300)[..., None]


def _exp_dir(theta: FloatArray, frame: FloatArray) -> FloatArray:
    """Bar direction for an error ``theta`` (..., 2) in a target ``frame`` (..., 3, 3)."""
    ang = np.sqrt(theta[..., 0] ** 2 + theta[..., 1] ** 2)
    sinc = np.sinc(ang / np.pi)  # sin(a)/a, exact 1 at 0
    return (
        np.cos(ang)[..., None] * frame[..., :, 1]
        + (sinc * theta[..., 0])[..., None] * frame[..., :, 0]
        + (sinc * theta[..., 1])[..., None] * frame[..., :, 2]
    )


def _log_dir(direction: FloatArray, frame: FloatArray) -> FloatArray:
    """Error (..., 2) of a unit bar ``direction`` (..., 3) relative to a target ``frame``."""
    c = _dot(direction, frame[..., :, 1])
    s1 = _dot(direction, frame[..., :, 0])
    s2 = _dot(direction, frame[..., :, 2])
    sn = np.sqrt(s1 * s1 + s2 * s2)
    ang = np.arctan2(sn, c)
    scale = np.where(sn > 1e-12, ang / np.maximum(sn, 1e-300), 1.0)
    return np.stack([scale * s1, scale * s2], axis=-1)


def _swing(a: FloatArray, b: FloatArray, fallback: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Axis (..., 3) and angle (...,) of the shortest rotation taking unit ``a`` to unit ``b``.

    When ``a`` and ``b`` are opposite, the rotation is about ``fallback`` (a unit vector
    perpendicular to ``a``).
    """
    k = _cross(a, b)
    s = np.sqrt(_dot(k, k))
    c = _dot(a, b)
    angle = np.arctan2(s, c)
    axis = np.where((s > 1e-12)[..., None], k / np.maximum(s, 1e-300)[..., None], fallback)
    return axis, angle


def _rotation_matrix(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Rotation matrices (..., 3, 3) about unit ``axis`` (..., 3) by ``angle`` (...,)."""
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    out = np.empty((*axis.shape[:-1], 3, 3))
    out[..., 0, 0] = c + x * x * t
    out[..., 0, 1] = x * y * t - z * s
    out[..., 0, 2] = x * z * t + y * s
    out[..., 1, 0] = y * x * t + z * s
    out[..., 1, 1] = c + y * y * t
    out[..., 1, 2] = y * z * t - x * s
    out[..., 2, 0] = z * x * t - y * s
    out[..., 2, 1] = z * y * t + x * s
    out[..., 2, 2] = c + z * z * t
    return out


def orthonormalize_frames(frame: ArrayLike) -> FloatArray:
    """Nearest-ish right-handed orthonormal frames (..., 3, 3) keeping the y column's direction.

    y is normalised, x is made perpendicular to it (Gram-Schmidt), z = x × y. Use it on
    bone matrices that carry scale or numerical drift.
    """
    f = np.asarray(frame, dtype=np.float64)
    return _frames_from_xy(f[..., :, 0], f[..., :, 1])


def _frames_from_xy(x_axis: FloatArray, y_axis: FloatArray) -> FloatArray:
    """:func:`orthonormalize_frames` of frames given by their x and y columns (..., 3)."""
    y = _normalize(y_axis)
    x = x_axis - _dot(x_axis, y)[..., None] * y
    xn = np.sqrt(_dot(x, x))
    degenerate = ~(xn > 1e-9)
    if np.any(degenerate):
        # A degenerate x (parallel to y) falls back to any perpendicular axis.
        alt = np.where((np.abs(y[..., 0]) < 0.9)[..., None], np.array([1.0, 0.0, 0.0]),
                       np.array([0.0, 1.0, 0.0]))
        alt = alt - _dot(alt, y)[..., None] * y
        x = np.where(degenerate[..., None], alt, x)
        xn = np.sqrt(_dot(x, x))
    out = np.empty((*y.shape, 3))
    x = x / np.maximum(xn, 1e-300)[..., None]
    out[..., :, 0] = x
    out[..., :, 1] = y
    x0, x1, x2, y0, y1, y2 = x[..., 0], x[..., 1], x[..., 2], y[..., 0], y[..., 1], y[..., 2]
    np.subtract(x1 * y2, x2 * y1, out=out[..., 0, 2])  # z = x × y
    np.subtract(x2 * y0, x0 * y2, out=out[..., 1, 2])
    np.subtract(x0 * y1, x1 * y0, out=out[..., 2, 2])
    return out


# ---------------------------------------------------------------------------------------
# Trees of pendulums
# ---------------------------------------------------------------------------------------


class PendulumForest:
    """Many trees of pendulums (all chains of all rigs) as flat arrays.

    parent: (n,) index of each pendulum's father, -1 for a tree root (anchored to the body).
        Any order is accepted; fathers need not come before sons.
    length: (n,) bar lengths (m), > 0. Used for the inertia of the masses only: the bars'
        positions come from the animated heads, so animated bone lengths are kept.
    settling_time: (n,) Ts (s) > 0; damping: (n,) ζ > 0 (ζ = 1 critical, < 1 underdamped,
        > 1 overdamped).
    rest_mode: (n,) REST_ANIMATION (target = the animated direction) or REST_GRAVITY
        (target = world -Z). Default: all REST_ANIMATION.
    influence: (n,) in [0, 1], how much of the simulated swing reaches the output (the
        dynamics are not changed). Default 1.
    child_weight: (n,) >= 0, the weight of a pendulum's pull on its father with
        ``combine="weighted"`` (e.g. its mass). Default 1.
    mass: (n,) > 0, the point mass at each bar's tip (used with ``reaction``). Default 1.
    reaction: True (default): a father also feels its sons' springs pushing back, so a
        tree moves like a chain of point masses on rods (linearised, the two passes are
        then exact, see ``PendulumSimulator._reactions``). A chain's slowest swing is
        slower than one bar's, so each tree's springs are stiffened (``tree_scale``) to
        give that slowest swing the requested frequency; a whole chain then settles within
        about 1-4 Ts (a single bar exactly at Ts).
        False: the thesis's one-way passes, each bar with its own Ts and no stiffening. One-way coupling
        cannot hand energy back: a pendulum shaken below its resonance swings wider than
        its pivot, so an underdamped chain shaken near its frequency amplifies link after
        link (an 8-bone tail shaken by 1 cm at resonance whirls round).
    combine: how a father integrates the errors its sons' pulls give it (son pursuit,
        thesis §5.3.3 step 2): "sum" (the thesis's choice, default), "average" (divided
        by the number of sons), "weighted" (weighted average by ``child_weight``).
    """

    def __init__(
        self,
        parent: ArrayLike,
        length: ArrayLike,
        settling_time: ArrayLike,
        damping: ArrayLike,
        *,
        rest_mode: ArrayLike | None = None,
        influence: ArrayLike | None = None,
        child_weight: ArrayLike | None = None,
        combine: Combine = "sum",
        mass: ArrayLike | None = None,
        reaction: bool = True,
    ) -> None:
        par = np.asarray(parent, dtype=np.int64).reshape(-1)
        n = par.size
        self.n = n

        def per_node(value: ArrayLike | None, default: float, name: str) -> FloatArray:
            arr = np.full(n, default) if value is None else np.asarray(value, dtype=np.float64)
            arr = np.broadcast_to(arr, (n,)).astype(np.float64)
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} must be finite")
            return arr

        self.parent = par
        self.length = per_node(length, 0.0, "length")
        self.settling_time = per_node(settling_time, 0.0, "settling_time")
        self.damping = per_node(damping, 0.0, "damping")
        self.rest_mode = per_node(rest_mode, REST_ANIMATION, "rest_mode").astype(np.int64)
        self.influence = per_node(influence, 1.0, "influence")
        self.child_weight = per_node(child_weight, 1.0, "child_weight")
        self.mass = per_node(mass, 1.0, "mass")
        self.reaction = bool(reaction)
        self.combine: Combine = combine

        if np.any((par < -1) | (par >= n)):
            raise ValueError("parent indices must be -1 or in [0, n)")
        if np.any(par == np.arange(n)):
            raise ValueError("a pendulum cannot be its own father")
        if np.any(~(self.length > 0.0)):
            raise ValueError("every pendulum needs a length > 0 (zero-length bones cannot swing)")
        if np.any(~(self.settling_time > 0.0)):
            raise ValueError("settling time Ts must be > 0 seconds")
        if np.any(~(self.damping > 0.0)):
            raise ValueError("damping ratio ζ must be > 0")
        if np.any((self.influence < 0.0) | (self.influence > 1.0)):
            raise ValueError("influence must be in [0, 1]")
        if np.any(self.child_weight < 0.0):
            raise ValueError("child_weight must be >= 0")
        if np.any(~(self.mass > 0.0)):
            raise ValueError("mass must be > 0")
        if not np.all(np.isin(self.rest_mode, (REST_ANIMATION, REST_GRAVITY))):
            raise ValueError("rest_mode must be REST_ANIMATION or REST_GRAVITY")
        if combine not in ("sum", "average", "weighted"):
            raise ValueError(f"combine must be 'sum', 'average' or 'weighted', not {combine!r}")

        self.depth = _depths(par)
        # Internal order: by depth, ties by input index (stable), so fathers precede sons
        # and the result does not depend on how the caller ordered the pendulums.
        self.order: IntArray = np.lexsort((np.arange(n), self.depth)).astype(np.int64)
        self.rank: IntArray = np.empty(n, dtype=np.int64)
        self.rank[self.order] = np.arange(n)
        sorted_parent = par[self.order]
        self.parent_sorted: IntArray = np.where(
            sorted_parent >= 0, self.rank[np.maximum(sorted_parent, 0)], -1
        )
        depth_sorted = self.depth[self.order]
        bounds = np.flatnonzero(np.diff(depth_sorted)) + 1
        edges = [0, *bounds.tolist(), n] if n else [0]
        self.levels: list[tuple[int, int]] = [(edges[i], edges[i + 1]) for i in range(len(edges) - 1)]
        self.omega0 = natural_frequency(self.settling_time, self.damping)
        self.gain = self._pull_gain()
        if self.reaction:
            self.tree_scale, self.fastest = _tree_modes(self)
        else:
            self.tree_scale, self.fastest = np.ones(n), self.omega0.copy()

    def _pull_gain(self) -> FloatArray:
        """Factor of each pendulum's pull on its father, from ``combine`` (input order)."""
        n = self.n
        has_father = self.parent >= 0
        fathers = self.parent[has_father]
        if self.combine == "sum":
            return np.ones(n)
        if self.combine == "average":
            count = np.bincount(fathers, minlength=n).astype(np.float64)
            gain = np.ones(n)
            gain[has_father] = 1.0 / count[fathers]
            return gain
        total = np.bincount(fathers, weights=self.child_weight[has_father], minlength=n)
        gain = np.zeros(n)
        ok = has_father & (total[np.maximum(self.parent, 0)] > 0.0)
        gain[ok] = self.child_weight[ok] / total[self.parent[ok]]
        gain[~has_father] = 1.0
        return gain

    @property
    def n_trees(self) -> int:
        return int(np.count_nonzero(self.parent < 0))

    @classmethod
    def chains(
        cls,
        chain_lengths: list[ArrayLike],
        settling_time: float | ArrayLike = 0.6,
        damping: float | ArrayLike = 0.4,
        **kwargs: object,
    ) -> PendulumForest:
        """A forest of unbranched chains; ``chain_lengths[i]`` holds chain i's bar lengths."""
        parent: list[int] = []
        lengths: list[float] = []
        for chain in chain_lengths:
            ls = np.asarray(chain, dtype=np.float64).reshape(-1)
            start = len(parent)
            parent.extend([-1, *list(range(start, start + ls.size - 1))])
            lengths.extend(ls.tolist())
        return cls(parent, lengths, settling_time, damping, **kwargs)  # type: ignore[arg-type]


def _depths(parent: IntArray) -> IntArray:
    """Depth of every node (roots 0); raises on cycles. Linear passes, no recursion."""
    n = parent.size
    depth = np.full(n, -1, dtype=np.int64)
    depth[parent < 0] = 0
    for _ in range(n + 1):
        unknown = depth < 0
        if not np.any(unknown):
            return depth
        fathers = parent[unknown]
        ready = depth[fathers] >= 0
        if not np.any(ready):
            raise ValueError("the parent array has a cycle: pendulums must form trees")
        idx = np.flatnonzero(unknown)[ready]
        depth[idx] = depth[parent[idx]] + 1
    raise ValueError("the parent array has a cycle: pendulums must form trees")  # pragma: no cover


def _tree_modes(forest: PendulumForest) -> tuple[FloatArray, FloatArray]:
    """Per pendulum: its tree's stiffness scale and the tree's fastest swing (rad/s).

    Linearised about the rest pose with all bars of a tree treated as collinear, small
    absolute swing angles φ of point masses ``m`` on bars ``L`` obey ``M φ'' = -K φ`` with
    ``M_ij = L_i L_j Σ m_k`` over the pendulums k hanging below both i and j (zero unless
    one is an ancestor of the other) and ``K = diag(m L² ω0²)``. A chain's slowest swing is
    much slower than one bar's (a uniform 4-bar chain: 0.35 ω0). With the slowest
    eigenvalue ``Ω²`` and the root's ω0, every bar of the tree runs at ``s·ω0`` with
    ``s = ω0_root / Ω`` (its ζ kept), so the tree's slowest swing has the requested
    frequency. Measured on kicked chains of 2-10 equal bars (Ts = 0.6 s, ζ 0.2-1): the tip
    settles within 1-4.2 Ts, and a chain shaken at any frequency never amplifies along its
    length.
    Returns (n,) scales and (n,) fastest scaled swing frequencies, for the time step.
    """
    n = forest.n
    scale = np.ones(n)
    fastest = forest.omega0.copy()
    roots = np.flatnonzero(forest.parent < 0)
    # Members of every tree, by depth, without recursion.
    tree = np.arange(n)
    for s, e in forest.levels[1:]:
        nodes = forest.order[s:e]
        tree[nodes] = tree[forest.parent[nodes]]
    for r in roots:
        members = np.flatnonzero(tree == r)
        if members.size == 1:
            continue
        local = {int(g): i for i, g in enumerate(members)}
        k = members.size
        below = np.eye(k, dtype=bool)  # below[i, j]: j is i or hangs below i
        for j, g in enumerate(members):
            f = int(forest.parent[g])
            while f >= 0:
                below[local[f], j] = True
                f = int(forest.parent[f])
        m = forest.mass[members]
        L = forest.length[members]
        w = forest.omega0[members]
        shared = (below.astype(float) * m[None, :]) @ below.T.astype(float)  # Σ m over common descendants
        M = shared * np.outer(L, L)
        K = np.diag(m * L * L * w * w)
        chol = np.linalg.cholesky(M)
        inv = np.linalg.inv(chol)
        eig = np.linalg.eigvalsh(inv @ K @ inv.T)
        s_tree = forest.omega0[r] / np.sqrt(eig[0])
        scale[members] = s_tree
        fastest[members] = s_tree * np.sqrt(eig[-1])
    return scale, fastest


# ---------------------------------------------------------------------------------------
# The simulator
# ---------------------------------------------------------------------------------------


@dataclass
class PendulumState:
    """Simulation state, in the forest's internal (depth-sorted) order; r = number of trees.

    theta, theta_prev: (n, 2) errors at the current and the previous internal step.
    dev, dev_prev: (n, 3) how far each anchor is from its animated head (simulated minus
        animated, world) at the last two steps; zero for tree roots.
    anchor, anchor_prev: (r + g, 3) world anchors of the tree roots and, with reactions, the
        animated heads of the g gravity sons, at the last two steps.
    anchor_frame: (r, 3, 3) world frames of the bodies the trees hang from at the last step
        and anchor_turn: (r, 3, 3) their rotation over that step (``R_k R_{k-1}ᵀ``); None
        until :meth:`PendulumSimulator.step` is given anchor frames.
    head: (n, 3) simulated world anchors (bone heads); direction: (n, 3) simulated unit
        bars; local: (n, 3) the same bars in their target frames; target: (n, 3, 3)
        target frames of the last step.
    """

    theta: FloatArray
    theta_prev: FloatArray
    dev: FloatArray
    dev_prev: FloatArray
    anchor: FloatArray
    anchor_prev: FloatArray
    head: FloatArray
    direction: FloatArray
    local: FloatArray
    target: FloatArray
    anchor_frame: FloatArray | None = None
    anchor_turn: FloatArray | None = None
    time: float = 0.0
    steps: int = 0


class PendulumSimulator:
    """Steps a :class:`PendulumForest` at a fixed internal rate (vectorised over all trees).

    Poses are given in the caller's (input) order: ``head_anim`` (n, 3) animated world bone
    heads and ``frame_anim`` (n, 3, 3) animated world bone frames (columns x, y = head→tail,
    z; orthonormal, see :func:`orthonormalize_frames`). ``anchor_frame`` (n, 3, 3), optional:
    world frames of the bodies the trees hang from (only the tree roots' rows are read; see
    :func:`simulate`).
    """

    def __init__(self, forest: PendulumForest, rate_hz: float = DEFAULT_RATE_HZ) -> None:
        self.forest = forest
        fastest = forest.fastest * (MAX_OMEGA_STEP / MAX_FAST_STEP)
        self.h = _internal_step(np.maximum(forest.omega0 * forest.tree_scale, fastest), rate_hz)
        order = forest.order
        n = forest.n
        self._length = forest.length[order]
        # Trees are stiffened so that their slowest swing runs at the requested ω0 (see
        # _tree_modes); ζ is kept.
        self._omega0 = (forest.omega0 * forest.tree_scale)[order][:, None]
        self._zeta = forest.damping[order][:, None]
        self._gravity = forest.rest_mode[order] == REST_GRAVITY
        self._any_gravity = bool(np.any(self._gravity))
        self._gain = forest.gain[order]
        self._parent = forest.parent_sorted
        self._n_roots = r = forest.levels[0][1] if forest.levels else 0
        # Reaction on each father's mass per unit of its son's spring acceleration:
        # its angle gets -(m_s L_s) / (m_f L_f) · F_s, i.e. its mass moves -(m_s L_s / m_f) F_s h²,
        # with F_s = -ω_s² θ_s along the son's target axes. Sons grouped by father, so that
        # summing their reactions is one reduceat.
        sons = np.flatnonzero(self._parent >= 0) if forest.reaction else np.zeros(0, dtype=np.int64)
        sons = sons[np.argsort(self._parent[sons], kind="stable")]
        self._sons = sons
        fathers = self._parent[sons]
        self._react_fathers, self._react_starts = np.unique(fathers, return_index=True)
        mass = forest.mass[order]
        reaction_gain = (mass[sons] * self._length[sons] / mass[fathers])[:, None] * self.h**2
        self._react_coef = np.repeat(reaction_gain * self._omega0[sons] ** 2, 2, axis=1)  # (s, 2)
        # Spring step as x⁺ = c1·x - c2·x⁻ (see spring_step), per level, precomputed.
        a = self._zeta * self._omega0 * self.h
        b = (self._omega0 * self.h) ** 2
        c1, c2 = (2.0 - b) / (1.0 + a), (1.0 - a) / (1.0 + a)
        self._c1, self._c2 = c1, c2
        # A push (anchor moved, body turned) is a forcing of the spring-damper; its discrete
        # form x⁺ = c1·x - c2·x⁻ + h²f / (1 + ζω0h) gives it the share 1 / (1 + ζω0h) (the
        # central-difference damper reads the jump over two steps and takes the rest).
        self._push_share = 1.0 / (1.0 + a[:, 0])
        root = np.arange(n)
        for s, e in forest.levels[1:]:
            root[s:e] = root[self._parent[s:e]]
        self._root = root
        # Pendulums held back when their body turns: those pulled toward the animation (a
        # gravity target does not turn with the body); one way, only the roots (a son feels
        # its body only through its father's swing, as for the body's translation).
        held = ~self._gravity
        if not forest.reaction:
            held[r:] = False
        self._held = held
        # Anchors whose own world motion is felt: the roots', and with reactions those of
        # gravity sons (no animation to follow: the world is their frame).
        hanging = np.flatnonzero(self._gravity[r:]) + r if forest.reaction else np.zeros(0, np.int64)
        self._hanging = hanging.astype(np.int64)
        self._felt = np.concatenate([np.arange(r), self._hanging]).astype(np.int64)
        self._levels = [
            _Level(
                slice(s, e),
                None if s == 0 else self._parent[s:e],
                slice(max(s - r, 0), max(e - r, 0)),
                np.repeat(self._length[s:e, None], 3, axis=1),
                np.repeat(c1[s:e], 2, axis=1),
                np.repeat(c2[s:e], 2, axis=1),
                np.repeat(self._push_share[s:e, None], 3, axis=1),
                bool(np.any(held[s:e])),
            )
            for s, e in forest.levels
        ]
        self.state: PendulumState | None = None

    def targets(self, frame: FloatArray) -> FloatArray:
        """Target frames (internal order) for animated frames (internal order, (..., n, 3, 3))."""
        if not self._any_gravity:
            return frame
        target = frame.copy()
        target[..., self._gravity, :, :] = _GRAVITY_FRAME
        return target

    # -- API -------------------------------------------------------------------------------

    def reset(
        self,
        head_anim: ArrayLike,
        frame_anim: ArrayLike,
        head_velocity: ArrayLike | None = None,
        anchor_frame: ArrayLike | None = None,
        anchor_angular_velocity: ArrayLike | None = None,
    ) -> PendulumState:
        """Start at rest relative to the animated pose (gravity pendulums start where animated).

        head_velocity: (n, 3) world anchor velocities at the start, and
        anchor_angular_velocity: (n, 3) world angular velocities (rad/s) of the anchor frames
        (only the roots' rows are used), so that a body already in steady motion or in a
        steady turn does not kick its chains. anchor_frame: (n, 3, 3) the anchor frames at
        the start (see :meth:`step`).
        """
        order = self.forest.order

        def sorted_or_none(value: ArrayLike | None) -> FloatArray | None:
            return None if value is None else _take_n(np.asarray(value, dtype=np.float64), order)

        return self._reset_sorted(
            _take_n(np.asarray(head_anim, dtype=np.float64), order),
            _take_n(np.asarray(frame_anim, dtype=np.float64), order),
            sorted_or_none(head_velocity),
            sorted_or_none(anchor_frame),
            sorted_or_none(anchor_angular_velocity),
        )

    def _reset_sorted(
        self,
        head: FloatArray,
        frame: FloatArray,
        velocity: FloatArray | None,
        anchor_frame: FloatArray | None = None,
        angular_velocity: FloatArray | None = None,
    ) -> PendulumState:
        n, r = self.forest.n, self._n_roots
        target = self.targets(frame)
        theta = _log_dir(frame[:, :, 1], target)
        anchor = head.take(self._felt, axis=0)
        anchor_prev = anchor.copy()
        dev_prev = np.zeros((n, 3))
        if velocity is not None:
            anchor_prev -= velocity.take(self._felt, axis=0) * self.h
            # A bar starts at rest against its target: an animated one moves with the
            # animation, a gravity one stays put in the world (its tip moves with its anchor
            # only). Where a son's anchor (its father's tip) does not move as animated, its
            # deviation from the animation starts moving: no kick at the first step.
            moving = velocity.copy()
            for s, e in self.forest.levels[1:]:
                fathers = self._parent[s:e]
                moving[s:e] = np.where(self._gravity[fathers, None], moving[fathers], velocity[s:e])
            dev_prev[r:] = (velocity[r:] - moving[r:]) * self.h
        turned = None
        if anchor_frame is not None:
            turned = np.broadcast_to(np.eye(3), (r, 3, 3)).copy()
            if angular_velocity is not None:
                turned = _rotvec_matrix(angular_velocity[:r] * self.h)
        self.state = PendulumState(
            theta=theta, theta_prev=theta.copy(), dev=np.zeros((n, 3)), dev_prev=dev_prev,
            anchor=anchor, anchor_prev=anchor_prev,
            head=head.copy(), direction=_exp_dir(theta, target), local=_exp_local(theta), target=target,
            anchor_frame=None if anchor_frame is None else orthonormalize_frames(anchor_frame[:r]),
            anchor_turn=turned,
        )
        return self.state

    def step(
        self,
        head_anim: ArrayLike,
        frame_anim: ArrayLike,
        impulse: ArrayLike | None = None,
        anchor_frame: ArrayLike | None = None,
    ) -> PendulumState:
        """Advance one internal step ``h``, to the animated pose given for its end.

        impulse: optional (n, 3) world displacements of the bar tips (masses), applied at
        the start of the step; zero rows leave a pendulum alone.
        anchor_frame: optional (n, 3, 3) world frames of the bodies the trees hang from (the
        roots' rows are read): a change of their angular velocity perturbs the trees. Give
        it at every step; the first one given (at reset or here) starts from a steady body.
        """
        order = self.forest.order
        head = _take_n(np.asarray(head_anim, dtype=np.float64), order)
        frame = _take_n(np.asarray(frame_anim, dtype=np.float64), order)
        imp = None if impulse is None else _take_n(np.asarray(impulse, dtype=np.float64), order)
        spin = None
        if anchor_frame is not None:
            anchors = _take_n(np.asarray(anchor_frame, dtype=np.float64), order)
            spin = self._anchor_spin(orthonormalize_frames(anchors[: self._n_roots]))
        return self._step_sorted(head, frame, imp, spin)

    def _anchor_spin(self, rot: FloatArray) -> FloatArray | None:
        """Unexplained turn (rotation vectors, (r, 3)) of the anchors reaching ``rot`` (r, 3, 3)."""
        st = self.state
        if st is None:
            raise RuntimeError("call reset() before step()")
        if st.anchor_frame is None or st.anchor_turn is None:
            st.anchor_frame = rot.copy()
            st.anchor_turn = np.broadcast_to(np.eye(3), rot.shape).copy()
            return None
        turn = rot @ np.swapaxes(st.anchor_frame, -1, -2)
        spin = _rotation_log(turn @ np.swapaxes(st.anchor_turn, -1, -2))
        st.anchor_frame, st.anchor_turn = rot.copy(), turn
        return _steady_to_zero(spin[None])[0] if np.any(spin) else None

    def _step_sorted(
        self, head: FloatArray, frame: FloatArray, impulse: FloatArray | None, spin: FloatArray | None = None
    ) -> PendulumState:
        """One step in internal order; ``spin`` (r, 3): the anchors' unexplained turn, or None."""
        st = self.state
        if st is None:
            raise RuntimeError("call reset() before step()")
        if impulse is not None and np.any(impulse != 0.0):
            self._son_pursuit(st, impulse)
        target = self.targets(frame)
        push = self._anchor_push(st, head, spin)
        hold = None
        if spin is not None:
            # In its own target frame, each held bar turns back by the body's turn.
            spin_n = spin.take(self._root, axis=0) * self._push_share[:, None]
            spin_n[~self._held] = 0.0
            hold = _rotvec_matrix(-np.einsum("mi,mij->mj", spin_n, target))
        self._father_pursuit(st, head, frame, target, push, hold)
        st.time += self.h
        st.steps += 1
        return st

    # -- the two passes (thesis §5.3.3) ----------------------------------------------------

    def _son_pursuit(self, st: PendulumState, impulse: FloatArray) -> None:
        """Bottom-up pass (thesis §5.3.2): displaced masses drag their ancestors.

        A displaced pendulum's error grows by the angle, at its anchor, between its bar and
        the line to the displaced mass. Its father's mass is dragged onto that line at one
        bar length from the displaced mass; that is the father's perturbation, and so on up
        to the fixed root anchor. A father adds up the errors its sons give it (``combine``:
        sum, average or weighted average). Masses are displaced and released: errors move,
        their rates do not. The children below a displaced mass follow in the top-down pass.
        """
        L = self._length
        mass = st.head + L[:, None] * st.direction
        moved = np.any(impulse != 0.0, axis=1)
        own = moved.copy()
        goal = mass + impulse  # where each mass is pulled to, before the bar constraint
        eps = np.zeros_like(st.theta)
        for s, e in reversed(self.forest.levels):
            idx = np.flatnonzero(moved[s:e]) + s
            if idx.size == 0:
                continue
            new_dir = _normalize(goal[idx] - st.head[idx])
            mine = own[idx]
            if np.any(mine):
                im = idx[mine]
                own_theta = _nearest_turn(_log_dir(new_dir[mine], st.target[im]), st.theta[im])
                eps[im] += own_theta - st.theta[im]
            fathers = self._parent[idx]
            inner = fathers >= 0
            if not np.any(inner):
                continue
            ci, fi = idx[inner], fathers[inner]
            dragged = goal[ci] - L[ci, None] * new_dir[inner]
            gain = self._gain[ci]
            to_dragged = _normalize(dragged - st.head[fi])
            pull = _nearest_turn(_log_dir(to_dragged, st.target[fi]), st.theta[fi]) - st.theta[fi]
            np.add.at(eps, fi, gain[:, None] * pull)
            np.add.at(goal, fi, gain[:, None] * (dragged - mass[fi]))
            moved[fi] = True
        st.theta += eps
        st.theta_prev += eps
        st.theta_prev, st.theta = _limit_swing(st.theta_prev, st.theta)
        st.local = _exp_local(st.theta)

    def _anchor_push(self, st: PendulumState, head: FloatArray, spin: FloatArray | None) -> FloatArray:
        """World displacement (n, 3) by which each anchor moved this step beyond what its
        previous velocity explains, before the father's swing is added (``_father_pursuit``).

        A root's anchor: the second difference of its world position. With reactions every
        pendulum feels its tree root's, and, when the body turns (``spin``), the turn's
        carrying of its animated head round the root (the lever arm; a steady turn carries
        nothing), except a gravity pendulum, which follows no animation and feels its
        anchor's whole world motion (its animated head's, its father's swing added in the
        pass). Minus the sons' spring reactions on their fathers (``_reactions`` below).
        """
        r = self._n_roots
        felt = head[:r] if self._hanging.size == 0 else head.take(self._felt, axis=0)
        felt_push = felt - 2.0 * st.anchor + st.anchor_prev
        st.anchor_prev = st.anchor
        st.anchor = felt.copy()
        if self.forest.reaction:
            push = felt_push[:r].take(self._root, axis=0)
            if spin is not None and push.shape[0] > r:
                lever = head[r:] - head[self._root[r:]]
                push[r:] += _turn_back_delta(lever, spin[self._root[r:]])
            if self._hanging.size:
                push[self._hanging] = felt_push[r:]
        else:
            push = np.zeros_like(head)
            push[:r] = felt_push
        self._reactions(st, push)
        return push

    def _reactions(self, st: PendulumState, push: FloatArray) -> None:
        """Subtract from ``push`` (n, 3) every father's mass displacement by its sons' springs.

        Linearised, a chain of point masses on rods obeys the two passes exactly when each
        father's acceleration also carries minus its sons' own spring forces, scaled by
        ``m_s L_s / (m_f L_f)``: for a uniform chain, φₖ'' = -Fₖ₋₁ + 2Fₖ - Fₖ₊₁ in absolute
        angles. The sons' forces come from the state at the start of the step, like every
        spring force of the Verlet step. Damping acts on each bar's own swing and is not
        handed on (feeding it back explicitly is unstable for stiff dampers).
        """
        sons = self._sons
        if sons.size == 0 or not st.theta.any():
            return
        w = st.theta.take(sons, axis=0) * self._react_coef
        tgt = st.target.take(sons, axis=0)
        pull = tgt[:, :, 0] * w[:, 0:1] + tgt[:, :, 2] * w[:, 1:2]
        push[self._react_fathers] -= np.add.reduceat(pull, self._react_starts, axis=0)

    def _father_pursuit(
        self,
        st: PendulumState,
        head: FloatArray,
        frame: FloatArray,
        target: FloatArray,
        push: FloatArray,
        hold: FloatArray | None = None,
    ) -> None:
        """Top-down pass (thesis §5.3.1): each anchor's unexplained motion perturbs its bar.

        Level by level from the roots: place the anchor (a root's animated head; otherwise
        the father's simulated bone carrying the animated head offset), let the mass keep
        its velocity while the anchor accelerates (the error turns by the angle that the
        anchor's acceleration displacement makes at the mass) and, when the body turns
        beyond its steady turn, while the target turns with the body (``hold`` (n, 3, 3):
        each bar's turn back in its target frame); then step both planar springs. The bar
        geometry is done in each target's local coordinates (x, y = the target direction,
        z), where the two error angles live. ``push`` (n, 3): the anchors' pushes before
        the fathers' swings (``_anchor_push``), world.

        A father's swing is the shortest rotation R from its animated bar a to its simulated
        bar b; it carries a son's animated offset v to R v. R is the product of the mirror
        across the plane normal to a and the mirror across the plane normal to h = a + b, so
        ``R v - v = -2 a (a·v) - 2 h (h·w) / (h·h)`` with ``w = v - 2 a (a·v)``: the parts
        from a and v are known for every son before the pass, only h waits for the father.
        """
        r = self._n_roots
        n_sons = head.shape[0] - r
        if n_sons:
            father = self._parent[r:]
            lever = head[r:] - head.take(father, axis=0)  # each son's animated offset from its father
            anim_father = frame[:, :, 1].take(father, axis=0)
            mirrored = anim_father * (-2.0 * np.einsum("mi,mi->m", anim_father, lever))[:, None]
            twice_w = 2.0 * (lever + mirrored)  # 2 w
        new_dev = st.dev_prev  # overwritten level by level once read: the oldest deviation
        for lv in self._levels:
            sl = lv.sl
            tgt = target[sl]
            if lv.father is None:
                st.head[sl] = head[sl]
                pw = push[sl]
            else:
                fp, ss = lv.father, lv.sons
                half = anim_father[ss] + st.direction.take(fp, axis=0)  # h
                hh = np.einsum("mi,mi->m", half, half)
                w2 = twice_w[ss]
                if hh.min() > 2e-9:
                    turned = mirrored[ss] - half * (np.einsum("mi,mi->m", half, w2) / hh)[:, None]
                else:
                    turned = self._turned_opposite(half, hh, w2, mirrored[ss], lever[ss], frame[fp, :, 0])
                dev = new_dev.take(fp, axis=0) + turned
                d2 = dev - 2.0 * st.dev[sl] + new_dev[sl]
                new_dev[sl] = dev
                pw = push[sl] + d2
                np.add(head[sl], dev, out=st.head[sl])
            held = hold is not None and lv.held
            theta = st.theta[sl]
            new_theta = lv.c1 * theta - lv.c2 * st.theta_prev[sl]
            local = None
            if held or pw.any():
                # The mass moved on by the step; the anchor moved by the push meanwhile (and the
                # target turned by the body's turn) while the mass did not: the bar turns.
                bar = lv.length * _exp_local(new_theta)
                if held:
                    assert hold is not None
                    bar = np.einsum("mij,mj->mi", hold[sl], bar)
                bar -= np.einsum("mi,mij->mj", pw * lv.share, tgt)  # in target coordinates
                pushed, size = _log_local_sized(bar)
                new_theta = _nearest_turn(pushed, new_theta)
                local = bar / size[:, None]
            limited, new_theta = _limit_swing(theta, new_theta)
            if limited is not theta:
                local = None
            st.theta_prev[sl] = limited
            st.theta[sl] = new_theta
            if local is None:
                local = _exp_local(new_theta, st.local[sl])
            else:
                st.local[sl] = local
            st.direction[sl] = np.einsum("mij,mj->mi", tgt, local)
        st.dev_prev, st.dev = st.dev, new_dev
        st.target = target

    @staticmethod
    def _turned_opposite(
        half: FloatArray,
        hh: FloatArray,
        twice_w: FloatArray,
        mirrored: FloatArray,
        lever: FloatArray,
        axis: FloatArray,
    ) -> FloatArray:
        """``R v - v`` when some fathers' bars point opposite to their animation (h ≈ 0): those
        turn by π about the father's x axis (``axis`` (m, 3)), ``R v = 2 x (x·v) - v``."""
        opposite = hh <= 2e-9
        safe = np.where(opposite, 1.0, hh)
        turned = mirrored - half * (np.einsum("mi,mi->m", half, twice_w) / safe)[:, None]
        x, v = axis[opposite], lever[opposite]
        turned[opposite] = 2.0 * (x * np.einsum("mi,mi->m", x, v)[:, None] - v)
        return turned

    # -- output ----------------------------------------------------------------------------

    def pose(
        self, theta: FloatArray, head: FloatArray, frame: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """World heads (..., n, 3) and frames (..., n, 3, 3) for errors, all internal order.

        theta (..., n, 2), head (..., n, 3), frame (..., n, 3, 3): errors and the animated
        pose they apply to. Influence scales each bone's swing away from its animation.
        """
        anim_dir = frame[..., :, 1]
        sim_dir = _exp_dir(theta, self.targets(frame))
        axis, angle = _swing(anim_dir, sim_dir, frame[..., :, 0])
        angle = angle * self.forest.influence[self.forest.order]
        out_head = np.empty_like(head)
        for s, e in self.forest.levels:
            sl = slice(s, e)
            if s == 0:
                out_head[..., sl, :] = head[..., sl, :]
                continue
            fp = self._parent[sl]
            rel = head[..., sl, :] - head[..., fp, :]
            moved = out_head[..., fp, :] - head[..., fp, :]
            turned = _rotate_delta(rel, axis[..., fp, :], angle[..., fp])
            out_head[..., sl, :] = head[..., sl, :] + moved + turned
        rotation = _rotation_matrix(axis, angle) @ frame
        return out_head, rotation


def _hermite_tangents(t: FloatArray, p: FloatArray) -> FloatArray:
    """Catmull-Rom style tangents (dp/dt) of samples ``p`` (T, ...) at times ``t`` (T,)."""
    m = np.zeros_like(p)
    if t.size < 2:
        return m
    shape = (-1,) + (1,) * (p.ndim - 1)
    if t.size == 2:
        m[:] = (p[1] - p[0]) / (t[1] - t[0])
        return m
    m[1:-1] = (p[2:] - p[:-2]) / (t[2:] - t[:-2]).reshape(shape)
    # Ends: derivative of the parabola through the three end samples (second order).
    m[0] = _end_derivative(t[0], t[1], t[2], p[0], p[1], p[2])
    m[-1] = _end_derivative(t[-1], t[-2], t[-3], p[-1], p[-2], p[-3])
    return m


def _end_derivative(
    t0: float, t1: float, t2: float, p0: FloatArray, p1: FloatArray, p2: FloatArray
) -> FloatArray:
    """d/dt at ``t0`` of the parabola through (t0, p0), (t1, p1), (t2, p2)."""
    return (
        p0 * ((2 * t0 - t1 - t2) / ((t0 - t1) * (t0 - t2)))
        + p1 * ((t0 - t2) / ((t1 - t0) * (t1 - t2)))
        + p2 * ((t0 - t1) / ((t2 - t0) * (t2 - t1)))
    )


def _hermite(
    p0: FloatArray, p1: FloatArray, m0: FloatArray, m1: FloatArray, dt: float, f: FloatArray
) -> FloatArray:
    """Cubic Hermite between two samples ``dt`` apart at fraction ``f``: smooth anchor
    accelerations, so the springs feel the same motion at any sample rate."""
    f2, f3 = f * f, f * f * f
    return (
        (2 * f3 - 3 * f2 + 1) * p0
        + (f3 - 2 * f2 + f) * dt * m0
        + (-2 * f3 + 3 * f2) * p1
        + (f3 - f2) * dt * m1
    )


@dataclass(frozen=True)
class _Level:
    """One depth level of the internal order: its slice, fathers (internal indices), its
    slice among the non-roots (``sons``), lengths (m, 3), spring coefficients (m, 2), and
    whether any of it is held back by a turning body."""

    sl: slice
    father: IntArray | None
    sons: slice
    length: FloatArray
    c1: FloatArray
    c2: FloatArray
    share: FloatArray
    held: bool


_TINY = 1e-300  # added to 0/0-prone ratios: sin(x)/x and atan2(s, c)/s tend to 1 at 0

# (a @ _SKEW).reshape(-1, 3, 3) is the cross-product matrix [a]×, so that [a]× b = a × b.
_SKEW = np.zeros((3, 9))
_SKEW[2, 1], _SKEW[1, 2], _SKEW[2, 3], _SKEW[0, 5], _SKEW[1, 6], _SKEW[0, 7] = -1.0, 1.0, 1.0, -1.0, -1.0, 1.0

STEADY_TURN = 1e-12
"""Anchor turns smaller than this (rad per internal step) are rounding in a steady turn: zero."""


def _exp_local(theta: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """Unit bar (m, 3) in target-local coordinates for errors (m, 2): y is the target.
    Written into ``out`` (m, 3) when given."""
    ang = np.hypot(theta[:, 0], theta[:, 1]) + _TINY
    if out is None:
        out = np.empty((theta.shape[0], 3))
    out[:, 0::2] = theta * (np.sin(ang) / ang)[:, None]
    out[:, 1] = np.cos(ang)
    return out


def _log_local_sized(bar: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Errors (m, 2) of bars (m, 3) in target-local coordinates (any positive length), and the
    bars' lengths (m,)."""
    sn = np.hypot(bar[:, 0], bar[:, 2]) + _TINY
    scale = (np.arctan2(sn, bar[:, 1]) + _TINY) / sn
    return bar[:, 0::2] * scale[:, None], np.hypot(sn, bar[:, 1])


def _limit_swing(before: FloatArray, after: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Stop bars that swing past :data:`MAX_SWING`: the error is scaled back onto the limit
    and its previous value set equal to it (no speed left). Shapes (m, 2)."""
    if after.size == 0 or np.abs(after).max() <= MAX_SWING * np.sqrt(0.5):
        return before, after  # quick: no component large enough to be over the limit
    size = np.sqrt(after[:, 0] * after[:, 0] + after[:, 1] * after[:, 1])
    over = size > MAX_SWING
    if not np.any(over):
        return before, after
    after = after.copy()
    after[over] *= (MAX_SWING / size[over])[:, None]
    before = before.copy()
    before[over] = after[over]
    return before, after


def _nearest_turn(theta: FloatArray, reference: FloatArray) -> FloatArray:
    """The error equal to ``theta`` (m, 2) as a bar direction that is closest to ``reference``.

    A direction at angle ``a`` from the target along unit ``u`` is also ``(a + 2πk) u`` for any
    integer k. The log maps return ``a`` in [0, π]; a bar swung past upside down would then
    jump by 2π between steps and the Verlet history would read that as a huge velocity. Picking
    the turn nearest the previous error keeps the error continuous (the spring then unwinds
    whole turns, like a torsion spring).
    """
    if reference.size == 0 or np.abs(reference).max() <= 2.0:
        return theta  # only errors near or past π can change branch
    a = np.sqrt(theta[:, 0] * theta[:, 0] + theta[:, 1] * theta[:, 1])
    far = np.abs(reference).max(axis=1) > 2.0
    u = theta / np.maximum(a, 1e-300)[:, None]
    turns = np.round(((reference * u).sum(axis=1) - a) / (2.0 * np.pi))
    turns = np.where(far & (a > 1e-12), turns, 0.0)
    return theta + (2.0 * np.pi * turns)[:, None] * u


def _rotvec_matrix(rotvec: FloatArray) -> FloatArray:
    """Rotation matrices (..., 3, 3) of rotation vectors (..., 3) (axis × angle, rad).

    ``R = I + a [w]× + b [w]×²`` with ``a = sin θ / θ`` and ``b = (1 - cos θ) / θ²``: exactly
    the identity for a zero vector, accurate for tiny ones.
    """
    w = np.asarray(rotvec, dtype=np.float64)
    shape = w.shape[:-1]
    w = w.reshape(-1, 3)
    angle, a, b = _rodrigues_factors(w)
    out = w[:, :, None] * (w * b[:, None])[:, None, :]  # b w wᵀ
    out += ((w * a[:, None]) @ _SKEW).reshape(-1, 3, 3)
    out.reshape(-1, 9)[:, ::4] += (1.0 - b * angle * angle)[:, None]  # a view: out is new
    return out.reshape(*shape, 3, 3)


def _rodrigues_factors(w: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``θ = |w|``, ``sin θ / θ`` and ``(1 - cos θ) / θ² = ½ (sin(θ/2) / (θ/2))²`` of rotation
    vectors (m, 3), without cancellation for tiny angles and exact at zero."""
    square = np.einsum("mi,mi->m", w, w)
    angle = np.sqrt(square)
    if square.size == 0 or square.max() < 1e-4:
        # Turns over one step are small: the series to θ⁴ are exact to rounding below 0.01 rad.
        return angle, 1.0 - square / 6.0 * (1.0 - square / 20.0), 0.5 - square / 24.0 * (1.0 - square / 30.0)
    t = angle + _TINY
    half = 0.5 * angle + _TINY
    sinc_half = np.sin(half) / half
    return angle, np.sin(t) / t, 0.5 * sinc_half * sinc_half


def _rotation_log(rot: FloatArray) -> FloatArray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3); angles in [0, π]."""
    s = 0.5 * np.stack(
        [rot[..., 2, 1] - rot[..., 1, 2], rot[..., 0, 2] - rot[..., 2, 0], rot[..., 1, 0] - rot[..., 0, 1]],
        axis=-1,
    )
    sn = np.sqrt(_dot(s, s))
    cs = 0.5 * (rot[..., 0, 0] + rot[..., 1, 1] + rot[..., 2, 2] - 1.0)
    angle = np.arctan2(sn, cs)
    out = s * np.where(sn > 1e-300, angle / np.maximum(sn, 1e-300), 1.0)[..., None]
    wide = cs < -0.5  # beyond 120°: sin θ loses the axis; read it from the symmetric part
    if np.any(wide):
        r = rot[wide]
        c = cs[wide]
        axes = (0.5 * (r + np.swapaxes(r, -1, -2)) - c[:, None, None] * np.eye(3)) / (1.0 - c)[:, None, None]
        pick = np.argmax(np.diagonal(axes, axis1=-2, axis2=-1), axis=-1)
        axis = _normalize(axes[np.arange(r.shape[0]), :, pick])
        sign = np.where(_dot(axis, s[wide]) < 0.0, -1.0, 1.0)
        out[wide] = axis * (sign * angle[wide])[:, None]
    return out


def _steady_to_zero(spin: FloatArray) -> FloatArray:
    """Zero the turns (rotation vectors, (..., 3)) below :data:`STEADY_TURN` (in place)."""
    tiny = _dot(spin, spin) < STEADY_TURN * STEADY_TURN
    spin[tiny] = 0.0
    return spin


def _turn_back_delta(v: FloatArray, spin: FloatArray) -> FloatArray:
    """``v - Rᵀ v`` for the rotations R of rotation vectors ``spin`` (m, 3); v (m, 3).

    How far a point at ``v`` from the centre of an unexplained turn was carried by it.
    """
    angle, a, b = _rodrigues_factors(spin)
    # Rᵀ v = v - a (s × v) + b (s (s·v) - θ² v)
    across = np.einsum("mij,mj->mi", (spin @ _SKEW).reshape(-1, 3, 3), v)
    along = spin * np.einsum("mi,mi->m", spin, v)[:, None] - (angle * angle)[:, None] * v
    return a[:, None] * across - b[:, None] * along


def _take_n(arr: FloatArray, order: IntArray) -> FloatArray:
    """Reorder the pendulum axis: axis 0 for (n,), (n, 3), (n, 3, 3) inputs."""
    return arr[order]


def _rotate_delta(v: FloatArray, axis: FloatArray, angle: FloatArray) -> FloatArray:
    """``rotate(v) - v``; exactly zero for a zero angle, so unperturbed chains stay exact."""
    ca, sa = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return _cross(axis, v) * sa + (axis * _dot(axis, v)[..., None] - v) * (1.0 - ca)


# ---------------------------------------------------------------------------------------
# Whole animations
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Impulses:
    """Explicit perturbations: at ``time[j]`` (s), displace the tip of pendulum ``node[j]``
    (input index) by ``displacement[j]`` (world, m). Shapes (m,), (m,), (m, 3)."""

    time: FloatArray
    node: IntArray
    displacement: FloatArray

    @classmethod
    def none(cls) -> Impulses:
        return cls(np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros((0, 3)))


@dataclass(frozen=True)
class PendulumResult:
    """Secondary motion sampled at the animation's times, in the caller's pendulum order.

    head: (T, n, 3) world bone heads; rotation: (T, n, 3, 3) world bone frames (columns
    x, y, z; the animated twist kept); theta: (T, n, 2) errors (rad) from the targets;
    step: the internal step (s) used.
    """

    head: FloatArray
    rotation: FloatArray
    theta: FloatArray
    step: float


def simulate(
    forest: PendulumForest,
    times: ArrayLike,
    head_anim: ArrayLike,
    frame_anim: ArrayLike,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    impulses: Impulses | None = None,
    anchor_frame: ArrayLike | None = None,
) -> PendulumResult:
    """Run the pendulums over a sampled animation and return the layered motion
    (:func:`simulate_steps` run to its end; same arguments)."""
    return run_steps(simulate_steps(forest, times, head_anim, frame_anim, rate_hz=rate_hz, impulses=impulses,
                                    anchor_frame=anchor_frame))


def simulate_steps(
    forest: PendulumForest,
    times: ArrayLike,
    head_anim: ArrayLike,
    frame_anim: ArrayLike,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    impulses: Impulses | None = None,
    anchor_frame: ArrayLike | None = None,
    slice_steps: int = 2048,
) -> Generator[float, None, PendulumResult]:
    """Run the pendulums over a sampled animation, yielding the fraction of internal steps
    done about every ``slice_steps`` steps (so a caller can show progress and stop: closing
    the generator stops the work), and return the layered motion.

    times: (T,) strictly increasing sample times (s), e.g. frame / fps;
    head_anim: (T, n, 3) animated world bone heads; frame_anim: (T, n, 3, 3) animated world
    bone frames (re-orthonormalised here). The springs step at ``rate_hz`` whatever the
    sample rate: the animation is interpolated between samples (heads by cubic Hermite,
    frames by normalised linear blend) and the errors are interpolated back at the sample
    times, so 24 and 60 samples per second give the same motion at shared times.

    anchor_frame: optional (T, n, 3, 3) world frames of the body each tree hangs from (for a
    bone chain, the frame of the root bone's parent bone, or of the object); only the tree
    roots' rows are read (a son hangs from its father). When given, the body's angular
    motion perturbs the trees: a change of its angular velocity (a sway, a yaw oscillation,
    a turn starting or stopping) makes the chains lag and swing, a steady turn carries them
    as animated. Rotations are interpolated between samples by a cubic Hermite curve of
    their rotation vectors. None: the anchors' rotation carries the chains rigidly (only
    their translation perturbs).
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    n_t = t.size
    head_in = np.asarray(head_anim, dtype=np.float64)
    frame_in = np.asarray(frame_anim, dtype=np.float64)
    n = forest.n
    if head_in.shape != (n_t, n, 3) or frame_in.shape != (n_t, n, 3, 3):
        raise ValueError(f"expected head (T, n, 3) and frame (T, n, 3, 3) with T={n_t}, n={n}; "
                         f"got {head_in.shape} and {frame_in.shape}")
    if n_t == 0:
        raise ValueError("the animation has no samples")
    if n_t > 1 and np.any(np.diff(t) <= 0.0):
        raise ValueError("sample times must be strictly increasing")
    if not (np.all(np.isfinite(head_in)) and np.all(np.isfinite(frame_in))):
        raise ValueError("the animated pose contains NaN or infinite values")
    anchor_in = None
    if anchor_frame is not None:
        anchor_in = np.asarray(anchor_frame, dtype=np.float64)
        if anchor_in.shape != (n_t, n, 3, 3):
            raise ValueError(f"expected anchor_frame (T, n, 3, 3) with T={n_t}, n={n}; got {anchor_in.shape}")
        if not np.all(np.isfinite(anchor_in)):
            raise ValueError("the anchor frames contain NaN or infinite values")
    sim = PendulumSimulator(forest, rate_hz)
    order = forest.order
    head = head_in[:, order]
    frame = orthonormalize_frames(frame_in[:, order])
    if n == 0:
        return PendulumResult(np.zeros((n_t, 0, 3)), np.zeros((n_t, 0, 3, 3)), np.zeros((n_t, 0, 2)), sim.h)

    tangent = _hermite_tangents(t, head)
    sim._reset_sorted(head[0], frame[0], tangent[0] if n_t > 1 else None)
    h = sim.h
    n_steps = int(np.ceil((t[-1] - t[0]) / h - 1e-9))
    theta_steps = np.empty((n_steps + 1, n, 2))
    assert sim.state is not None
    theta_steps[0] = sim.state.theta

    imp = impulses if impulses is not None else Impulses.none()
    imp_step = np.floor((np.asarray(imp.time, dtype=np.float64) - t[0]) / h).astype(np.int64) + 1
    imp_node = forest.rank[np.asarray(imp.node, dtype=np.int64)] if len(imp.node) else np.zeros(0, np.int64)
    imp_disp = np.asarray(imp.displacement, dtype=np.float64).reshape(-1, 3)
    kicked = set(imp_step.tolist())

    step_times = t[0] + h * np.arange(1, n_steps + 1)
    seg = np.clip(np.searchsorted(t, step_times, side="right") - 1, 0, max(n_t - 2, 0))
    frac = np.clip((step_times - t[seg]) / (t[seg + 1] - t[seg]), 0.0, 1.0) if n_t > 1 else np.zeros(n_steps)
    nxt = np.minimum(seg + 1, n_t - 1)
    spins: FloatArray | None = None
    turning = np.zeros(n_steps, dtype=bool)
    if anchor_in is not None and n_steps:
        rot = orthonormalize_frames(anchor_in[:, order[: sim._n_roots]])
        spins = _anchor_spins(t, rot, h, seg, frac)
        turning = np.any(spins != 0.0, axis=(1, 2))
    # The animation at the internal steps, interpolated a batch of steps at a time: one numpy
    # call per batch instead of per step, the batch small enough (~4k pendulum-steps) for its
    # temporaries to stay in the processor's cache.
    batch = max(1, min(4096 // n, slice_steps))
    frame_xy = np.ascontiguousarray(np.swapaxes(frame[..., :2], -1, -2))  # (T, n, 2, 3): x and y
    next_report = slice_steps
    for lo_k in range(0, n_steps, batch):
        if lo_k >= next_report:
            next_report = lo_k + slice_steps
            yield lo_k / n_steps
        hi_k = min(lo_k + batch, n_steps)
        a, b = seg[lo_k:hi_k], nxt[lo_k:hi_k]
        f = frac[lo_k:hi_k, None, None]
        dt = (t[b] - t[a])[:, None, None]
        heads_k = _hermite(head[a], head[b], tangent[a], tangent[b], dt, f)
        xy_a = frame_xy[a]
        xy_k = xy_a + f[..., None] * (frame_xy[b] - xy_a)  # x and y blended; z follows from them
        frames_k = _frames_from_xy(xy_k[..., 0, :], xy_k[..., 1, :])
        for k in range(lo_k, hi_k):
            impulse = None
            if k + 1 in kicked:
                hit = imp_step == k + 1
                impulse = np.zeros((n, 3))
                np.add.at(impulse, imp_node[hit], imp_disp[hit])
            spin = spins[k] if spins is not None and turning[k] else None
            sim._step_sorted(heads_k[k - lo_k], frames_k[k - lo_k], impulse, spin)
            theta_steps[k + 1] = sim.state.theta

    # Errors at the sample times, interpolated between the internal steps around them.
    pos = (t - t[0]) / h
    lo = np.clip(np.floor(pos + 1e-9).astype(np.int64), 0, n_steps)
    hi = np.minimum(lo + 1, n_steps)
    w = np.clip(pos - lo, 0.0, 1.0)[:, None, None]
    theta = theta_steps[lo] * (1.0 - w) + theta_steps[hi] * w
    out_head, rotation = sim.pose(theta, head, frame)
    rank = forest.rank
    return PendulumResult(out_head[:, rank], rotation[:, rank], theta[:, rank], h)


def _anchor_spins(t: FloatArray, rot: FloatArray, h: float, seg: IntArray, frac: FloatArray) -> FloatArray:
    """Unexplained turns of the anchors at the internal steps: (K, r, 3) rotation vectors.

    t: (T,) sample times, T >= 2; rot: (T, r, 3, 3) anchor rotations at the samples; step k
    (1..K) lies in segment ``seg[k-1]`` at fraction ``frac[k-1]``. Between samples the
    rotation follows a cubic Hermite curve of its rotation vector relative to the segment's
    start, with Catmull-Rom angular velocities at the samples (a steady turn stays steady).
    With ``D_k = R_k R_{k-1}ᵀ`` the anchor's turn over step k, the unexplained part is
    ``δ_k = D_k D_{k-1}ᵀ`` (``D_0`` from the angular velocity at the start, so a body already
    turning steadily does not kick its chains); turns below :data:`STEADY_TURN` are zero.
    """
    swap = np.swapaxes
    rel = _rotation_log(rot[1:] @ swap(rot[:-1], -1, -2))  # (T-1, r, 3): each segment's turn
    dt = np.diff(t)
    omega = np.empty_like(rot[..., 0])  # (T, r, 3) world angular velocities
    if t.size == 2:
        omega[:] = rel[0] / dt[0]
    else:
        omega[1:-1] = (rel[1:] + rel[:-1]) / (t[2:] - t[:-2])[:, None, None]
        zero = np.zeros_like(rel[0])
        omega[0] = _end_derivative(t[0], t[1], t[2], zero, rel[0], rel[0] + rel[1])
        omega[-1] = _end_derivative(t[-1], t[-2], t[-3], zero, -rel[-1], -(rel[-1] + rel[-2]))
    f = frac[:, None, None]
    f2, f3 = f * f, f * f * f
    phi = (dt[seg][:, None, None] * ((f3 - 2 * f2 + f) * omega[seg] + (f3 - f2) * omega[seg + 1])
           + (-2 * f3 + 3 * f2) * rel[seg])
    steps = np.concatenate([rot[:1], _rotvec_matrix(phi) @ rot[seg]])  # (K+1, r, 3, 3)
    turn = steps[1:] @ swap(steps[:-1], -1, -2)  # D_1..D_K
    before = np.concatenate([_rotvec_matrix(omega[0] * h)[None], turn[:-1]])  # D_0..D_{K-1}
    return _steady_to_zero(_rotation_log(turn @ swap(before, -1, -2)))
