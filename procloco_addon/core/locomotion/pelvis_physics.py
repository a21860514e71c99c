# SPDX-License-Identifier: GPL-3.0-or-later
"""Pelvis pseudo-physics: the pogo-stick particle (thesis §4.1).

The pelvis height is a particle pushed up by the feet in stance and pulled down by gravity;
the forces come from the gait circles alone, so the user tunes nothing but the gait and the
preferred height. Each foot's stance is split into equal halves (thesis figure 4.5):

- *reception* (first half): the foot brings the falling pelvis to a stop, aiming at
  ``v_T = 0`` at the end of the half (eq. 4.4b): ``a_foot = g + (v_T - v) / T``;
- *propulsion* (second half): the foot aims at the take-off velocity of a ballistic flight
  that ends at the preferred height ``y_T`` when the foot lands again (eq. 4.5c):
  ``v_0 = (y_T - y) / T + g T / 2`` with ``T`` = rest of propulsion + swing, then
  ``a_foot = g + (v_0 - v) / T_propulsion`` (eq. 4.4b again);
- *swing*: ``a_foot = 0``.

Here ``g`` is the gravity magnitude (positive; the thesis writes the same equations with a
negative ``g``). Each foot's acceleration is computed "as if it were alone" (thesis §4.1):
every foot drives its own pogo particle with its own height and velocity, and the pelvis
acceleration is the (weighted) mean ``a_pelvis = Σ w_i (a_i - g) / Σ w_i``, so the pelvis
height is the weighted mean of the particles. Feeding every foot the shared pelvis state
instead makes a closed loop whose equilibrium drifts far above the preferred height when
some feet are in swing (the mean force is then too small and the propulsion term
compensates); the per-foot reading is stable and reaches its periodic orbit within a cycle.

Legs attach to *pelvis nodes* (one per character by default; the spine adds more): a node's
height is the weighted mean of the particles of the legs attached to it.

Integration is semi-implicit Euler with sub-steps no longer than ``max_substep`` (the
needle moves linearly inside a frame), so the result barely depends on the frame rate and a
flight phase is an exact parabola (second differences equal ``-g h²``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .gait import in_swing, stance_elapsed

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class PelvisPhysicsParams:
    """``gravity`` in m/s² (lower it for a softer, smaller bounce), ``max_substep`` in s,
    ``warmup_cycles``: gait cycles run before the first frame so the particles start on
    their periodic orbit instead of falling from rest; ``centered``: report the bounce
    around the preferred height (see ``PelvisPhysics.centered_height``)."""

    gravity: float = 9.81
    max_substep: float = 1.0 / 240.0
    warmup_cycles: int = 4
    centered: bool = True


def foot_acceleration(
    swing: BoolArray,
    stance_progress: FloatArray,
    stance_time: FloatArray,
    swing_time: FloatArray,
    height: FloatArray,
    velocity: FloatArray,
    preferred: FloatArray,
    gravity: float,
    min_time: float,
) -> FloatArray:
    """Per-foot upward acceleration ``a_foot (N,)`` (eq. 4.4b, 4.5c).

    ``stance_progress`` is the fraction of stance done (0 at touch-down), ``stance_time``
    and ``swing_time`` the phase durations in seconds, ``height``/``velocity`` the foot's
    particle state, ``preferred`` the height ``y_T``. Remaining times are floored at
    ``min_time`` (one integration step) so the last step of a phase is not singular.
    """
    t = phase_times(swing, stance_progress, stance_time, swing_time, gravity, min_time)
    return _acceleration(t.stance_g, t.time_left, t.aim, t.flight, t.half_g_flight, height, velocity,
                         preferred)


@dataclass(frozen=True)
class PhaseTimes:
    """What :func:`foot_acceleration` needs from the feet's phases alone, shape ``(..., N)``
    each: in ``reception`` / ``propulsion``, the time left of the reception ``t_rec`` and
    of the propulsion ``t_prop``, and ``half_g_flight`` = ``0.5 g (t_prop + swing_time)``
    with ``flight`` = ``t_prop + swing_time``. The acceleration ``G + (X - v) / T``
    (:func:`_acceleration`) reads them as ``stance_g`` (``G``: ``g`` in stance, 0 in swing),
    ``time_left`` (``T``: ``t_rec`` in reception, ``t_prop`` in propulsion, inf in swing)
    and ``aim`` (1 in propulsion, where ``X`` is the take-off velocity ``v0``, else 0)."""

    reception: BoolArray
    propulsion: BoolArray
    t_rec: FloatArray
    t_prop: FloatArray
    flight: FloatArray
    half_g_flight: FloatArray
    stance_g: FloatArray
    time_left: FloatArray
    aim: FloatArray


def phase_times(
    swing: BoolArray,
    stance_progress: FloatArray,
    stance_time: FloatArray,
    swing_time: FloatArray,
    gravity: float | FloatArray,
    min_time: float | FloatArray,
) -> PhaseTimes:
    """The phase-only part of :func:`foot_acceleration`, for phases of any shape ``(..., N)``
    (all the sub-steps of a frame at once); ``gravity``: one for all or ``(N,)``."""
    reception = ~swing & (stance_progress < 0.5)
    propulsion = ~swing & ~reception
    t_rec = np.maximum((0.5 - stance_progress) * stance_time, min_time)
    t_prop = np.maximum((1.0 - stance_progress) * stance_time, min_time)
    t_flight = t_prop + swing_time
    stance_g = np.where(swing, 0.0, gravity)
    time_left = np.where(reception, t_rec, np.where(propulsion, t_prop, np.inf))
    return PhaseTimes(reception, propulsion, t_rec, t_prop, t_flight, 0.5 * gravity * t_flight, stance_g,
                      time_left, propulsion.astype(np.float64))


def _acceleration(
    stance_g: FloatArray, time_left: FloatArray, aim: FloatArray, flight: FloatArray,
    half_g_flight: FloatArray, height: FloatArray, velocity: FloatArray, preferred: FloatArray,
) -> FloatArray:
    """``a_foot (N,)`` from one sub-step's :class:`PhaseTimes` fields and the particles' state:
    ``G + (X - v) / T``, i.e. ``g + (0 - v) / t_rec`` in reception (eq. 4.4b aiming at
    ``v_T = 0``), ``g + (v0 - v) / t_prop`` in propulsion with ``v0 = (y_T - y) / flight +
    g flight / 2`` (eq. 4.5c), 0 in swing."""
    return stance_g + (((preferred - height) / flight + half_g_flight) * aim - velocity) / time_left


def substep_maps(
    t: PhaseTimes, h: FloatArray | float, preferred: FloatArray, gravity: float | FloatArray,
    pad: bool = False,
) -> FloatArray:
    """Each sub-step's update of the particles as ``(K, N, 3, 3)`` affine maps of ``(height,
    velocity, 1)``: sub-steps of length ``h`` (one for all or ``(K, N)``) with the phase times
    ``t`` (``(K, N)`` fields) toward heights ``preferred (N,)``. Semi-implicit Euler with
    :func:`_acceleration`: ``v' = v + (a - g) h``, ``y' = y + v' h``, where ``a - g`` is affine
    in ``y`` and ``v``. ``pad``: ``K`` rounded up to a power of two with identities."""
    k, n = t.time_left.shape
    rows = 1 << max(k - 1, 0).bit_length() if pad else k
    inv_t = 1.0 / t.time_left  # (0 in swing)
    aim = t.aim * inv_t
    # v' = cv v + ch y + c0
    cv = 1.0 - h * inv_t
    ch = -(h * aim) / t.flight
    c0 = h * ((t.stance_g - gravity) + (preferred / t.flight + t.half_g_flight) * aim)
    out = np.empty((rows, n, 3, 3))
    m = out[:k]
    m[..., 0, 0] = 1.0 + h * ch
    m[..., 0, 1] = h * cv
    m[..., 0, 2] = h * c0
    m[..., 1, 0] = ch
    m[..., 1, 1] = cv
    m[..., 1, 2] = c0
    m[..., 2, :] = _LAST_ROW
    out[k:] = _IDENTITY
    return out


_LAST_ROW = np.array([0.0, 0.0, 1.0])
_IDENTITY = np.eye(3)


def node_acceleration(
    a_foot: FloatArray, leg_node: IntArray, n_nodes: int, gravity: float, weights: FloatArray | None = None
) -> FloatArray:
    """Pelvis-node accelerations ``(n_nodes,)``: the weighted mean of ``a_foot - g``."""
    w = np.ones_like(a_foot) if weights is None else weights
    total = np.bincount(leg_node, weights=w, minlength=n_nodes)
    acc = np.bincount(leg_node, weights=w * (a_foot - gravity), minlength=n_nodes)
    return np.divide(acc, total, out=np.full(n_nodes, -gravity), where=total > 0.0)


class PelvisPhysics:
    """Per-foot pogo particles for many pelvis nodes.

    ``leg_node (N,)``: the node each leg pushes (flat node index across characters);
    ``n_nodes``; ``weights (N,)`` per-leg mass shares (default equal); ``gravity (N,)``: each
    leg's own gravity (characters of different sizes; default ``params.gravity`` for all);
    ``group (N,)``: the character of each leg (default one for all): a reset's sub-steps
    follow the longest span of each character's own legs, so a character's orbit does not
    depend on who else is stepped with it.
    """

    def __init__(
        self,
        leg_node: IntArray,
        n_nodes: int,
        weights: npt.ArrayLike | None = None,
        params: PelvisPhysicsParams | None = None,
        gravity: npt.ArrayLike | None = None,
        group: npt.ArrayLike | None = None,
    ) -> None:
        self.leg_node = np.asarray(leg_node, dtype=np.int64)
        self.n_nodes = int(n_nodes)
        n = self.leg_node.shape[0]
        self.weights = (
            np.ones(n)
            if weights is None
            else np.broadcast_to(np.asarray(weights, dtype=np.float64), (n,)).copy()
        )
        self.params = params or PelvisPhysicsParams()
        self.gravity: float | FloatArray = (
            self.params.gravity if gravity is None
            else np.broadcast_to(np.asarray(gravity, dtype=np.float64), (n,)).copy()
        )
        self.group = np.zeros(n, dtype=np.int64) if group is None else np.asarray(group, dtype=np.int64)
        self.n_groups = int(self.group.max()) + 1 if n else 0
        self.height = np.zeros(n)
        self.velocity = np.zeros(n)
        self.offset = np.zeros(self.n_nodes)
        # each node's total weight (the weights are fixed)
        self._node_weight = np.bincount(self.leg_node, weights=self.weights, minlength=self.n_nodes)

    def centered_height(self, node: FloatArray | None = None) -> FloatArray:
        """``(n_nodes,)`` node heights minus their running mean offset from the preferred height.

        In the thesis's model ``y_T`` is the height at touch-down, so the orbit's mean sits
        below (long stances) or above (long flights) it: a hexapod in a tetrapod gait would
        walk a third of its height lower with physics on. Subtracting the offset (averaged
        over two cycles) keeps the body at the height the user set and the bounce's shape.
        ``node``: :meth:`node_height` when the caller has it already.
        """
        if node is None:
            node = self.node_height()
        if not self.params.centered:
            return node
        return node - self.offset

    def node_height(self) -> FloatArray:
        """``(n_nodes,)`` weighted mean height of each node's particles."""
        total = self._node_weight
        acc = np.bincount(self.leg_node, weights=self.weights * self.height, minlength=self.n_nodes)
        return np.divide(acc, total, out=np.zeros(self.n_nodes), where=total > 0.0)

    def node_velocity(self) -> FloatArray:
        total = np.bincount(self.leg_node, weights=self.weights, minlength=self.n_nodes)
        acc = np.bincount(self.leg_node, weights=self.weights * self.velocity, minlength=self.n_nodes)
        return np.divide(acc, total, out=np.zeros(self.n_nodes), where=total > 0.0)

    def reset(
        self,
        preferred_node_height: FloatArray,
        needle_leg: FloatArray,
        rate_leg: FloatArray,
        disk_start: FloatArray,
        disk_duration: FloatArray,
        nodes: BoolArray | None = None,
    ) -> None:
        """Put every particle on (close to) its periodic orbit at the needle phases given.

        A particle is at rest at the end of reception (mid-stance); each one starts there at
        its node's preferred height, then runs ``warmup_cycles`` cycles plus the way round to
        the current phase (each leg with its own sub-step length). ``nodes (n_nodes,)``: only
        these nodes are reset (default all).
        """
        if nodes is not None:
            keep_legs = ~np.asarray(nodes, dtype=bool)[self.leg_node]
            keep_nodes = ~np.asarray(nodes, dtype=bool)
            saved = (self.height.copy(), self.velocity.copy(), self.offset.copy())
            self.reset(preferred_node_height, needle_leg, rate_leg, disk_start, disk_duration)
            self.height[keep_legs] = saved[0][keep_legs]
            self.velocity[keep_legs] = saved[1][keep_legs]
            self.offset[keep_nodes] = saved[2][keep_nodes]
            return
        self.height = np.asarray(preferred_node_height, dtype=np.float64)[self.leg_node].copy()
        self.velocity = np.zeros_like(self.height)
        period = 1.0 / np.maximum(rate_leg, 1e-9)
        mid_stance = disk_start + disk_duration + 0.5 * (1.0 - disk_duration)
        span = self.params.warmup_cycles + np.mod(needle_leg - mid_stance, 1.0)
        total = span * period
        if not np.any(total > 0.0):
            return
        # each character's sub-steps: as many as its longest span needs (a leg of a character
        # with fewer waits out the last rows: a step of 0)
        n_leg = self._substep_counts(total)
        h = total / n_leg
        rows = np.arange(int(n_leg.max()))[:, None]
        preferred = self.height.copy()
        phases = mid_stance + (rows + 0.5) * h * rate_leg
        self._substeps(phases, rate_leg, disk_start, disk_duration, preferred, np.where(rows < n_leg, h, 0.0),
                       self._group_max(h))
        # one more cycle, every leg of a node in step, to measure the orbit's mean offset
        n_leg = self._substep_counts(period)
        h = period / n_leg
        n_max = int(n_leg.max())
        n_node = np.full(self.n_nodes, float(n_max))
        n_node[self.leg_node] = n_leg
        min_time = self._group_max(h)
        pref_node = np.asarray(preferred_node_height, dtype=np.float64)
        rows = np.arange(n_max)[:, None]
        phases = needle_leg + (rows + 0.5) * h * rate_leg
        heights = self._substeps(phases, rate_leg, disk_start, disk_duration, preferred,
                                 np.where(rows < n_leg, h, 0.0), min_time, trace=True)
        # the node heights after each sub-step (:meth:`node_height` of every row at once), summed in order
        bins = (rows * self.n_nodes + self.leg_node).reshape(-1)
        sums = np.bincount(bins, weights=(self.weights * heights).reshape(-1), minlength=n_max * self.n_nodes)
        total = self._node_weight
        node = np.divide(sums.reshape(n_max, self.n_nodes), total, out=np.zeros((n_max, self.n_nodes)),
                         where=total > 0.0)
        self.offset = np.where(rows < n_node, node - pref_node, 0.0).cumsum(axis=0)[-1] / n_node

    def _substep_counts(self, span: FloatArray) -> FloatArray:
        """``(N,)`` sub-steps of each leg over ``span (N,)`` seconds: those the longest span
        of its group needs at ``max_substep`` (at least one)."""
        longest = np.zeros(self.n_groups)
        np.maximum.at(longest, self.group, span)
        return np.asarray(np.maximum(1.0, np.ceil(longest / self.params.max_substep))[self.group])

    def _group_max(self, h: FloatArray) -> FloatArray:
        """``(N,)`` the longest sub-step ``h (N,)`` of each leg's group (the shortest phase
        time; a group whose sub-steps are all 0 takes the longest of all)."""
        most = np.zeros(self.n_groups)
        np.maximum.at(most, self.group, h)
        per_leg = most[self.group]
        return np.asarray(np.where(per_leg > 0.0, per_leg, h.max()))

    def _substeps(
        self,
        phases: FloatArray,
        rate_leg: FloatArray,
        disk_start: FloatArray,
        disk_duration: FloatArray,
        preferred: FloatArray,
        h: FloatArray | float,
        min_time: FloatArray | float | None = None,
        trace: bool = False,
    ) -> FloatArray:
        """Integrate one sub-step of length ``h`` per row of needle ``phases`` ``(K, N)`` (each
        leg's phase at the middle of the sub-step), in order. What depends on the phases
        alone (swing or stance, stance progress) is found for all rows at once; so is each
        sub-step's update of a particle, which is affine in its height and velocity
        (:func:`substep_maps`): the updates are then applied in order, or composed in a
        balanced tree of 3x3 products when only the end matters. ``trace``: return the heights
        after every sub-step ``(K, N)`` (else only the last ``(1, N)``)."""
        period = 1.0 / np.maximum(rate_leg, 1e-9)
        swing = in_swing(phases, disk_start, disk_duration)
        progress = stance_elapsed(phases, disk_start, disk_duration) / (1.0 - disk_duration)
        stance_time = (1.0 - disk_duration) * period
        swing_time = disk_duration * period
        if min_time is None:
            min_time = h if isinstance(h, float) else float(np.max(h))
        t = phase_times(swing, progress, stance_time, swing_time, self.gravity, min_time)
        state = np.empty((self.height.shape[0], 3, 1))  # (height, velocity, 1) of each particle
        state[:, 0, 0] = self.height
        state[:, 1, 0] = self.velocity
        state[:, 2, 0] = 1.0
        if trace:
            maps = substep_maps(t, h, preferred, self.gravity)
            seen = np.empty(phases.shape)
            for k in range(phases.shape[0]):
                state = maps[k] @ state
                seen[k] = state[:, 0, 0]
        else:
            maps = substep_maps(t, h, preferred, self.gravity, pad=True)
            while maps.shape[0] > 1:  # (a power of two: padded with identities)
                maps = maps[1::2] @ maps[0::2]
            state = maps[0] @ state
        self.height, self.velocity = state[:, 0, 0].copy(), state[:, 1, 0].copy()
        return seen if trace else self.height[None]

    def step(
        self,
        dt: float,
        needle_leg: FloatArray,
        rate_leg: FloatArray,
        disk_start: FloatArray,
        disk_duration: FloatArray,
        preferred_node_height: FloatArray,
    ) -> FloatArray:
        """Advance ``dt`` seconds from needle phases ``needle_leg (N,)`` (at the step's start)
        moving at ``rate_leg (N,)`` cycles/s; returns the node heights ``(n_nodes,)``.

        ``preferred_node_height (n_nodes,)`` is each node's ``y_T`` for this step. The raw
        heights are returned; ``centered_height`` gives them around ``y_T``.
        """
        n_sub = max(1, math.ceil(dt / self.params.max_substep - 1e-9))
        h = dt / n_sub
        pref_node = np.asarray(preferred_node_height, dtype=np.float64)
        preferred = pref_node[self.leg_node]
        phases = needle_leg + (np.arange(n_sub)[:, None] + 0.5) * h * rate_leg
        self._substeps(phases, rate_leg, disk_start, disk_duration, preferred, h)
        # running mean of the offset over about two cycles of each node's legs
        period = np.zeros(self.n_nodes)
        np.maximum.at(period, self.leg_node, 1.0 / np.maximum(rate_leg, 1e-9))
        alpha = 1.0 - np.exp(-dt / np.maximum(2.0 * period, 1e-9))
        node = self.node_height()
        self.offset += alpha * (node - pref_node - self.offset)
        return node
