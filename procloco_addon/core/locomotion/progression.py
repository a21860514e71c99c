# SPDX-License-Identifier: GPL-3.0-or-later
"""Non-linear (burst-like) progression and the gait randomizer (thesis §4.3).

Insects and spiders rarely hold a constant speed: they accelerate towards a top speed, hold
it for a while, slow down to a stall, wait, and go again. The progression here drives each
character's speed through such bursts. One burst is a raised-cosine wave whose amplitude is
the user's speed:

    stall (speed 0) -> rise (half a wavelength) -> hold (max speed) -> fall (half a wavelength)

The wavelength, the stall ("static") period and the max-speed period are drawn again for
every burst from user ranges, so no two bursts (and no two characters) look alike. Speed is
always within ``[0, max_speed]`` and the distance covered in a step is the exact integral of
the wave over the step, whatever ``dt`` is.

The gait randomizer (same section) draws random gait circles for a character: swing start
and duration per leg as cycle fractions (:meth:`RandomGait.to_gait` gives a
``core.locomotion.gait.Gait``). A random gait
never has all feet in swing at once, and each foot lifts before the foot that lifted just
before it lands, so the swing sectors chain around and cover the whole circle. When both
effects are on, a character gets a new random gait each time it comes to a stall
(:func:`effects_step`).

Everything is vectorised over characters: state arrays are ``(n_chars,)``. All randomness
goes through the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .gait import Gait

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# Burst segments, in the order they follow each other.
STALL = 0
RISE = 1
HOLD = 2
FALL = 3

_MAX_SEGMENT_HOPS = 10_000  # guards the segment loop against a pathological dt


def _check_range(name: str, rng_: tuple[float, float], positive: bool) -> None:
    lo, hi = rng_
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo > hi or lo < 0.0 or (positive and lo <= 0.0):
        need = "0 < low <= high" if positive else "0 <= low <= high"
        raise ValueError(f"{name} must be a finite range with {need}, got {rng_!r}")


@dataclass(frozen=True)
class ProgressionParams:
    """User settings of the burst-like progression.

    ``max_speed`` is the wave amplitude in m/s (the speed the user asked for). The three
    ranges are in seconds; each burst draws its values uniformly inside them.
    ``wavelength`` is the duration of one rise plus one fall (the full raised-cosine wave).
    """

    max_speed: float
    wavelength: tuple[float, float] = (0.8, 2.4)
    static_period: tuple[float, float] = (0.15, 0.8)
    max_speed_period: tuple[float, float] = (0.0, 1.2)

    def __post_init__(self) -> None:
        if not np.isfinite(self.max_speed) or self.max_speed < 0.0:
            raise ValueError(f"max_speed must be finite and >= 0, got {self.max_speed!r}")
        _check_range("wavelength", self.wavelength, positive=True)
        _check_range("static_period", self.static_period, positive=False)
        _check_range("max_speed_period", self.max_speed_period, positive=False)


@dataclass(frozen=True)
class ProgressionState:
    """Where each character is in its current burst; all arrays are ``(n_chars,)``.

    ``segment`` is one of STALL, RISE, HOLD, FALL; ``elapsed`` the time spent in it;
    ``duration`` its drawn length; ``half_wave`` the rise/fall duration of the current burst.
    """

    segment: IntArray
    elapsed: FloatArray
    duration: FloatArray
    half_wave: FloatArray

    @property
    def n_chars(self) -> int:
        return int(self.segment.shape[0])

    @classmethod
    def start(cls, n_chars: int, params: ProgressionParams, rng: np.random.Generator) -> ProgressionState:
        """Every character starts standing still, for its own random static period."""
        duration = rng.uniform(*params.static_period, size=n_chars)
        half_wave = 0.5 * rng.uniform(*params.wavelength, size=n_chars)
        return cls(
            segment=np.full(n_chars, STALL, dtype=np.int64),
            elapsed=np.zeros(n_chars),
            duration=duration,
            half_wave=half_wave,
        )


@dataclass(frozen=True)
class ProgressionStep:
    """What one step of the progression gives the controller; arrays are ``(n_chars,)``.

    ``speed`` is the speed at the end of the step (m/s), ``distance`` the exact distance
    covered during the step (m), ``stalled`` is True for characters whose speed reached zero
    (entered a stall) during the step.
    """

    speed: FloatArray
    distance: FloatArray
    stalled: BoolArray


def _speed_in_segment(
    segment: IntArray, t: FloatArray, half_wave: FloatArray, vmax: FloatArray | float
) -> FloatArray:
    phase = np.pi * np.clip(t / half_wave, 0.0, 1.0)
    rise = 0.5 * vmax * (1.0 - np.cos(phase))
    fall = 0.5 * vmax * (1.0 + np.cos(phase))
    out = np.where(segment == RISE, rise, np.where(segment == FALL, fall, 0.0))
    return np.where(segment == HOLD, vmax, out)


def _distance_in_segment(
    segment: IntArray, t0: FloatArray, t1: FloatArray, half_wave: FloatArray, vmax: FloatArray | float
) -> FloatArray:
    """Exact integral of the speed over ``[t0, t1]`` inside one segment.

    The speed is never negative, so neither is its integral: near the start of a rise (and the
    end of a fall) ``span - sin_diff`` cancels to a few ulps of ``span`` and may round just
    below zero; it is clamped at 0, which is within rounding of the exact value."""
    k = np.pi / half_wave
    sin_diff = (np.sin(k * t1) - np.sin(k * t0)) / k
    span = t1 - t0
    rise = np.maximum(0.5 * vmax * (span - sin_diff), 0.0)
    fall = np.maximum(0.5 * vmax * (span + sin_diff), 0.0)
    out = np.where(segment == RISE, rise, np.where(segment == FALL, fall, 0.0))
    return np.where(segment == HOLD, vmax * span, out)


def progression_step(
    state: ProgressionState,
    params: ProgressionParams,
    dt: float,
    rng: np.random.Generator,
    enabled: bool | BoolArray = True,
    max_speed: npt.ArrayLike | None = None,
) -> tuple[ProgressionState, ProgressionStep]:
    """Advance every character's burst by ``dt`` seconds.

    ``max_speed`` (``(n_chars,)`` or scalar, m/s) overrides ``params.max_speed``, for crowds
    whose characters walk at different speeds (or a speed the user animates).

    ``enabled`` (scalar or ``(n_chars,)``) switches the effect per character. A disabled
    character moves at ``max_speed`` and is parked at the end of a max-speed hold, so
    switching the effect back on continues from full speed into a fall, without a jump in
    speed. Disabled characters draw no random numbers.
    """
    if dt < 0.0 or not np.isfinite(dt):
        raise ValueError(f"dt must be finite and >= 0, got {dt!r}")
    n = state.n_chars
    on = np.broadcast_to(np.asarray(enabled, dtype=bool), (n,))
    top = params.max_speed if max_speed is None else max_speed
    vmax = np.broadcast_to(np.asarray(top, dtype=np.float64), (n,))
    if np.any(vmax < 0.0) or not np.all(np.isfinite(vmax)):
        raise ValueError("max_speed must be finite and >= 0")

    segment = state.segment.copy()
    elapsed = state.elapsed.copy()
    duration = state.duration.copy()
    half_wave = state.half_wave.copy()
    remaining = np.where(on, float(dt), 0.0)
    distance = np.zeros(n)
    stalled = np.zeros(n, dtype=bool)

    for _ in range(_MAX_SEGMENT_HOPS):
        active = remaining > 0.0
        if not active.any():
            break
        left = np.maximum(duration - elapsed, 0.0)
        use = np.minimum(remaining, left)
        covered = _distance_in_segment(segment, elapsed, elapsed + use, half_wave, vmax)
        distance += np.where(active, covered, 0.0)
        # Land exactly on the segment end when it is reached (no round-off creep).
        elapsed = np.where(active & (remaining >= left), duration, elapsed + np.where(active, use, 0.0))
        remaining = remaining - np.where(active, use, 0.0)
        # Characters that reached the end of their segment move on to the next one; the
        # draws are made in character order so a seed always gives the same sequence.
        done = active & (elapsed >= duration) & (remaining > 0.0)
        if not done.any():
            continue
        nxt = (segment + 1) % 4
        idx = np.flatnonzero(done)
        for seg_value in (STALL, RISE, HOLD, FALL):
            sel = idx[nxt[idx] == seg_value]
            if sel.size == 0:
                continue
            if seg_value == STALL:
                duration[sel] = rng.uniform(*params.static_period, size=sel.size)
                stalled[sel] = True
            elif seg_value == RISE:
                half_wave[sel] = 0.5 * rng.uniform(*params.wavelength, size=sel.size)
                duration[sel] = half_wave[sel]
            elif seg_value == HOLD:
                duration[sel] = rng.uniform(*params.max_speed_period, size=sel.size)
            else:
                duration[sel] = half_wave[sel]
        segment[idx] = nxt[idx]
        elapsed[idx] = 0.0
    else:  # pragma: no cover - needs dt thousands of times longer than a burst
        raise RuntimeError("progression_step: dt spans too many bursts; use a smaller step")

    # A segment that ended exactly at the end of the step is reported as the next one,
    # so a fall that reaches zero counts as a stall in this step, not the next.
    ended = on & (elapsed >= duration) & (segment == FALL)
    if ended.any():
        idx = np.flatnonzero(ended)
        duration[idx] = rng.uniform(*params.static_period, size=idx.size)
        segment[idx] = STALL
        elapsed[idx] = 0.0
        stalled[idx] = True

    speed = _speed_in_segment(segment, elapsed, half_wave, vmax)
    off = ~on
    if off.any():
        segment[off] = HOLD
        elapsed[off] = 0.0
        duration[off] = 0.0
        speed = np.where(off, vmax, speed)
        distance = np.where(off, vmax * float(dt), distance)

    new_state = ProgressionState(segment=segment, elapsed=elapsed, duration=duration, half_wave=half_wave)
    return new_state, ProgressionStep(speed=speed, distance=distance, stalled=stalled)


# --------------------------------------------------------------------------- random gaits


@dataclass(frozen=True)
class GaitRandomizerParams:
    """Bounds for random gaits, as fractions of the gait cycle.

    ``min_swing``/``max_swing`` bound each leg's swing duration; ``min_overlap`` is how long
    (at least) a foot is still in swing when the next foot in the chain lifts; ``min_gap``
    is the least phase difference between two consecutive lift-offs. ``concentration`` is
    the Dirichlet concentration of the lift-off gaps: large values give evenly spread
    lift-offs, small values clustered ones. ``max_feet_in_swing`` caps how many feet may
    be in the air together (``None``: all but one); it must allow at least two, since a
    foot lifting before the previous one lands means two feet swing together.
    """

    min_swing: float = 0.15
    max_swing: float = 0.6
    min_overlap: float = 0.02
    min_gap: float = 0.04
    concentration: float = 4.0
    max_feet_in_swing: int | None = None
    max_tries: int = 64

    def __post_init__(self) -> None:
        if not 0.0 < self.min_swing <= self.max_swing < 1.0:
            raise ValueError("need 0 < min_swing <= max_swing < 1")
        if not 0.0 < self.min_overlap < self.min_gap:
            raise ValueError("need 0 < min_overlap < min_gap")
        if self.concentration <= 0.0 or self.max_tries < 1:
            raise ValueError("concentration must be > 0 and max_tries >= 1")
        if self.max_feet_in_swing is not None and self.max_feet_in_swing < 2:
            raise ValueError("max_feet_in_swing must be at least 2 (or None)")


@dataclass(frozen=True)
class RandomGait:
    """A gait as gait circles: per leg (legs in the character's own order) the swing start
    and swing duration as fractions of the cycle, ``(n_legs,)`` each. ``order`` lists the
    legs in the order they lift off around the circle: ``order[k + 1]`` lifts while
    ``order[k]`` is still in swing (cyclically)."""

    swing_start: FloatArray
    swing_duration: FloatArray
    order: IntArray = field(repr=False)

    def to_gait(self, cycle_time: float, name: str = "Random gait") -> Gait:
        """The same circles as a :class:`core.locomotion.gait.Gait` (what the gait manager runs)."""
        return Gait(self.swing_start.copy(), self.swing_duration.copy(), cycle_time, name)


def feet_in_swing(swing_start: FloatArray, swing_duration: FloatArray, phase: FloatArray) -> BoolArray:
    """Which feet are in swing at each cycle phase: ``(n_phases, n_legs)`` booleans.

    A foot is in swing on the half-open arc ``[start, start + duration)`` (mod 1).
    """
    rel = np.mod(np.asarray(phase, dtype=float)[:, None] - swing_start[None, :], 1.0)
    return rel < swing_duration[None, :]


def _max_feet_in_swing(start: FloatArray, duration: FloatArray) -> int:
    # The count of swinging feet only rises at a lift-off, so its maximum is reached
    # right at one of the swing starts.
    return int(feet_in_swing(start, duration, start).sum(axis=1).max())


def random_gait(
    n_legs: int, rng: np.random.Generator, params: GaitRandomizerParams | None = None
) -> RandomGait:
    """Draw one random gait for ``n_legs`` legs (thesis §4.3, figure 4.17).

    The legs lift off in a random order around the circle with random gaps; each foot's
    swing lasts longer than the gap to the next lift-off, so the next foot lifts before
    this one lands and the swing sectors chain around the whole circle. Durations that
    would put every foot in the air at once (or more than ``max_feet_in_swing``) are drawn
    again; when no draw fits, each foot lands just after the next one lifts, which keeps at
    most two feet in the air. With two legs both rules
    cannot hold strictly: each foot lands exactly when the other lifts (sectors touch).
    """
    p = params or GaitRandomizerParams()
    if n_legs < 2:
        raise ValueError("a random gait needs at least two legs (one foot must stay on the ground)")
    cap = n_legs - 1 if p.max_feet_in_swing is None else min(p.max_feet_in_swing, n_legs - 1)
    order = rng.permutation(n_legs).astype(np.int64)
    offset = rng.uniform(0.0, 1.0)

    if n_legs == 2:
        g_lo = max(p.min_swing, 1.0 - p.max_swing)
        g_hi = min(p.max_swing, 1.0 - p.min_swing)
        g0 = rng.uniform(g_lo, g_hi) if g_lo <= g_hi else 0.5
        gaps = np.array([g0, 1.0 - g0])
        durations = gaps.copy()
    else:
        gaps = np.full(n_legs, 1.0 / n_legs)
        for _ in range(p.max_tries):
            cand = rng.dirichlet(np.full(n_legs, p.concentration))
            if cand.min() >= p.min_gap and (cand + p.min_overlap).max() <= p.max_swing:
                gaps = cand
                break
        starts = np.mod(offset + np.concatenate(([0.0], np.cumsum(gaps)[:-1])), 1.0)
        shortest = np.maximum(gaps + p.min_overlap, p.min_swing)
        # Last resort: each foot lands just after the next one lifts, so at most two feet
        # swing together (the minimum the chain needs).
        durations = gaps + min(p.min_overlap, 0.5 * gaps.min())
        drawn = (rng.uniform(shortest, np.maximum(shortest, p.max_swing)) for _ in range(p.max_tries))
        for cand_d in itertools.chain(drawn, [shortest]):
            if _max_feet_in_swing(starts, cand_d) <= cap and cand_d.max() < 1.0:
                durations = cand_d
                break

    starts_in_order = np.mod(offset + np.concatenate(([0.0], np.cumsum(gaps)[:-1])), 1.0)
    swing_start = np.empty(n_legs)
    swing_duration = np.empty(n_legs)
    swing_start[order] = starts_in_order
    swing_duration[order] = durations
    if n_legs == 2:
        # Touching sectors: take each duration from the rounded starts themselves so the
        # landing and the other foot's lift-off are the very same phase.
        swing_duration[order] = np.mod(np.roll(starts_in_order, -1) - starts_in_order, 1.0)
    return RandomGait(swing_start=swing_start, swing_duration=swing_duration, order=order)


def regait_stalled(
    stalled: BoolArray,
    n_legs: IntArray | list[int],
    rng: np.random.Generator,
    params: GaitRandomizerParams | None = None,
) -> dict[int, RandomGait]:
    """A new random gait for every stalled character, keyed by character index (in order)."""
    legs = np.broadcast_to(np.asarray(n_legs, dtype=np.int64), stalled.shape)
    return {int(c): random_gait(int(legs[c]), rng, params) for c in np.flatnonzero(stalled)}


@dataclass(frozen=True)
class EffectsStep:
    """One step of both effects: the progression output and the gaits drawn this step."""

    progression: ProgressionStep
    new_gaits: dict[int, RandomGait]


def effects_step(
    state: ProgressionState,
    params: ProgressionParams,
    dt: float,
    rng: np.random.Generator,
    n_legs: IntArray | list[int],
    progression_on: bool | BoolArray = True,
    randomize_gait: bool | BoolArray = True,
    gait_params: GaitRandomizerParams | None = None,
    max_speed: npt.ArrayLike | None = None,
) -> tuple[ProgressionState, EffectsStep]:
    """Progression plus gait randomizer, coupled as in thesis §4.3.

    Characters with both effects on get a new random gait each time they stall. A character
    with only the randomizer on keeps the gait it was given at the start
    (:func:`initial_gaits`); with only the progression on, its gait never changes.
    """
    new_state, step = progression_step(state, params, dt, rng, enabled=progression_on, max_speed=max_speed)
    n = state.n_chars
    both = np.broadcast_to(np.asarray(progression_on, dtype=bool), (n,)) & np.broadcast_to(
        np.asarray(randomize_gait, dtype=bool), (n,)
    )
    gaits = regait_stalled(step.stalled & both, n_legs, rng, gait_params)
    return new_state, EffectsStep(progression=step, new_gaits=gaits)


def initial_gaits(
    n_legs: IntArray | list[int],
    rng: np.random.Generator,
    randomize_gait: bool | BoolArray = True,
    gait_params: GaitRandomizerParams | None = None,
) -> dict[int, RandomGait]:
    """The random gait each character starts with when its randomizer is on."""
    legs = np.atleast_1d(np.asarray(n_legs, dtype=np.int64))
    on = np.broadcast_to(np.asarray(randomize_gait, dtype=bool), legs.shape)
    return regait_stalled(on, legs, rng, gait_params)


def mean_speed_fraction(params: ProgressionParams) -> float:
    """Expected mean speed over many bursts as a fraction of ``max_speed`` (for planning
    the cycle time or a path's duration): each rise and fall averages half the top speed."""
    wl = 0.5 * sum(params.wavelength)
    st = 0.5 * sum(params.static_period)
    hold = 0.5 * sum(params.max_speed_period)
    total = wl + st + hold
    return float((0.5 * wl + hold) / total) if total > 0 else 1.0


__all__ = [
    "FALL",
    "HOLD",
    "RISE",
    "STALL",
    "EffectsStep",
    "GaitRandomizerParams",
    "ProgressionParams",
    "ProgressionState",
    "ProgressionStep",
    "RandomGait",
    "effects_step",
    "feet_in_swing",
    "initial_gaits",
    "mean_speed_fraction",
    "progression_step",
    "random_gait",
    "regait_stalled",
]
