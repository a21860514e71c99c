# SPDX-License-Identifier: GPL-3.0-or-later
"""Burst-like progression and the gait randomizer (thesis §4.3)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from procloco_addon.core.locomotion.gait import Gait
from procloco_addon.core.locomotion.progression import (
    HOLD,
    GaitRandomizerParams,
    ProgressionParams,
    ProgressionState,
    effects_step,
    feet_in_swing,
    initial_gaits,
    mean_speed_fraction,
    progression_step,
    random_gait,
)


def run(params: ProgressionParams, n_chars: int, dt: float, seconds: float, seed: int = 0,
        enabled: bool | np.ndarray = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speeds, distances and stall flags, each ``(n_steps, n_chars)``."""
    rng = np.random.default_rng(seed)
    state = ProgressionState.start(n_chars, params, rng)
    speeds, dists, stalls = [], [], []
    for _ in range(round(seconds / dt)):
        state, out = progression_step(state, params, dt, rng, enabled=enabled)
        speeds.append(out.speed)
        dists.append(out.distance)
        stalls.append(out.stalled)
    return np.array(speeds), np.array(dists), np.array(stalls)


def standstill_runs(still: np.ndarray) -> np.ndarray:
    """Lengths (in steps) of the runs of True in a boolean sequence, in order."""
    padded = np.concatenate([[False], still, [False]]).astype(int)
    edges = np.flatnonzero(np.diff(padded))
    return edges[1::2] - edges[::2]


ranges = st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.5)).map(lambda t: (t[0], t[0] + t[1]))


@given(
    vmax=st.floats(0.0, 5.0),
    wl=st.tuples(st.floats(0.05, 1.0), st.floats(0.0, 2.0)).map(lambda t: (t[0], t[0] + t[1])),
    static=ranges,
    hold=ranges,
    dt=st.sampled_from([1 / 120, 1 / 24, 0.2, 0.7]),
)
# A rise from rest whose first step's integral cancelled to -1e-17 m before it was clamped.
@example(vmax=1.0, wl=(1.0, 1.0), static=(1.0, 1.0), hold=(0.0, 0.0), dt=1 / 24)
def test_speed_stays_within_zero_and_max(vmax: float, wl: tuple[float, float], static: tuple[float, float],
                                         hold: tuple[float, float], dt: float) -> None:
    params = ProgressionParams(max_speed=vmax, wavelength=wl, static_period=static, max_speed_period=hold)
    speed, dist, _ = run(params, n_chars=4, dt=dt, seconds=12.0)
    assert speed.min() >= 0.0
    assert speed.max() <= vmax + 1e-12
    assert dist.min() >= 0.0
    assert dist.max() <= vmax * dt + 1e-12


def test_stalls_occur_with_zero_speed_for_the_static_period() -> None:
    params = ProgressionParams(max_speed=1.0, wavelength=(0.6, 1.0), static_period=(0.3, 0.5),
                               max_speed_period=(0.2, 0.4))
    dt = 1 / 200
    speed, _, stalls = run(params, n_chars=3, dt=dt, seconds=20.0)
    # A burst lasts at most 1.0 + 0.5 + 0.4 s, so 20 s holds more than ten stalls per character.
    assert (stalls.sum(axis=0) >= 10).all()
    for c in range(3):
        # Durations of the runs of exact standstill, leaving out the start and the end.
        runs = standstill_runs(speed[:, c] == 0.0)[1:-1] * dt
        assert runs.size >= 9
        assert runs.min() >= 0.3 - 2 * dt
        assert runs.max() <= 0.5 + 2 * dt
        # Top speed is reached in every burst (the hold period is never empty here).
        assert speed[:, c].max() == pytest.approx(1.0)


def test_effect_off_gives_constant_speed_and_no_stalls() -> None:
    params = ProgressionParams(max_speed=1.7)
    speed, dist, stalls = run(params, n_chars=5, dt=1 / 24, seconds=10.0, enabled=False)
    assert np.all(speed == 1.7)
    assert np.allclose(dist, 1.7 / 24)
    assert not stalls.any()


def test_effect_can_be_switched_per_character() -> None:
    params = ProgressionParams(max_speed=1.0)
    speed, _, stalls = run(params, n_chars=2, dt=1 / 24, seconds=10.0, enabled=np.array([True, False]))
    assert np.all(speed[:, 1] == 1.0)
    assert not stalls[:, 1].any()
    assert stalls[:, 0].any()
    assert speed[:, 0].std() > 0.1


def test_speed_is_smooth_and_switching_back_on_does_not_jump() -> None:
    params = ProgressionParams(max_speed=2.0, wavelength=(0.5, 1.5), static_period=(0.0, 0.5),
                               max_speed_period=(0.0, 0.5))
    dt = 1 / 60
    rng = np.random.default_rng(3)
    state = ProgressionState.start(1, params, rng)
    speeds = []
    for i in range(1200):
        on = not 400 <= i < 500  # switched off for 100 steps in the middle
        state, out = progression_step(state, params, dt, rng, enabled=on)
        speeds.append(out.speed[0])
    # The steepest slope of a raised cosine of amplitude v and wavelength w is v·π/w.
    max_change = 2.0 * np.pi / 0.5 * dt
    assert np.abs(np.diff(speeds)).max() <= max_change * (1 + 1e-9)
    assert state.segment[0] in (0, 1, 2, 3)
    assert speeds[499] == 2.0


def test_distance_is_exact_so_the_step_size_does_not_matter() -> None:
    """One character draws the same bursts at any dt; the distance must then agree."""
    params = ProgressionParams(max_speed=1.3)
    _, d_coarse, st_coarse = run(params, n_chars=1, dt=0.25, seconds=30.0, seed=11)
    v_fine, d_fine, st_fine = run(params, n_chars=1, dt=0.25 / 64, seconds=30.0, seed=11)
    # Distance covered by the end of every coarse step, both ways.
    at_coarse = np.cumsum(d_coarse[:, 0])
    at_fine = np.cumsum(d_fine[:, 0])[63::64]
    assert at_coarse == pytest.approx(at_fine, rel=1e-9, abs=1e-12)
    assert st_coarse.sum() == st_fine.sum()
    # ... and it is the integral of the reported speed (trapezoids on the fine steps).
    v = np.concatenate([[0.0], v_fine[:, 0]])
    integral = np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.25 / 64)[63::64]
    assert np.abs(at_coarse - integral).max() < 1e-4
    # And the mean speed is the one the ranges predict, within sampling noise.
    _, d_long, _ = run(params, n_chars=20, dt=0.1, seconds=120.0, seed=5)
    assert d_long.sum(axis=0).mean() / 120.0 / 1.3 == pytest.approx(mean_speed_fraction(params), rel=0.05)


def test_same_seed_same_sequence_other_seed_differs() -> None:
    params = ProgressionParams(max_speed=1.0)
    a = run(params, n_chars=3, dt=1 / 24, seconds=8.0, seed=42)
    b = run(params, n_chars=3, dt=1 / 24, seconds=8.0, seed=42)
    c = run(params, n_chars=3, dt=1 / 24, seconds=8.0, seed=43)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)
    assert not np.array_equal(a[0], c[0])


def test_each_character_can_have_its_own_top_speed() -> None:
    params = ProgressionParams(max_speed=1.0)
    top = np.array([0.5, 2.0, 0.0])
    rng = np.random.default_rng(9)
    state = ProgressionState.start(3, params, rng)
    speeds = []
    for _ in range(400):
        state, out = progression_step(state, params, 1 / 30, rng, max_speed=top)
        speeds.append(out.speed)
        assert np.all(out.distance <= top / 30 + 1e-12)
    speeds_arr = np.array(speeds)
    assert speeds_arr.max(axis=0) == pytest.approx(top)
    assert speeds_arr.min() == 0.0
    _, off = progression_step(state, params, 1 / 30, rng, enabled=False, max_speed=top)
    assert off.speed == pytest.approx(top)


def test_disabled_character_is_parked_at_full_speed() -> None:
    params = ProgressionParams(max_speed=1.0)
    rng = np.random.default_rng(0)
    state = ProgressionState.start(1, params, rng)
    state, _ = progression_step(state, params, 0.1, rng, enabled=False)
    assert state.segment[0] == HOLD
    state, out = progression_step(state, params, 1e-3, rng, enabled=True)
    assert out.speed[0] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize(
    "kwargs",
    [{"max_speed": -1.0}, {"max_speed": 1.0, "wavelength": (0.0, 1.0)},
     {"max_speed": 1.0, "static_period": (0.5, 0.2)}, {"max_speed": 1.0, "max_speed_period": (-0.1, 0.2)}],
)
def test_bad_progression_settings_are_refused(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError):
        ProgressionParams(**kwargs)  # type: ignore[arg-type]


# ------------------------------------------------------------------------- random gaits

PHASES = np.linspace(0.0, 1.0, 2000, endpoint=False)


def check_gait(start: np.ndarray, duration: np.ndarray) -> None:
    n = start.size
    assert ((start >= 0.0) & (start < 1.0)).all()
    assert ((duration > 0.0) & (duration < 1.0)).all()
    # Both at fine phase samples and exactly at every lift-off (where the count peaks).
    in_swing = feet_in_swing(start, duration, np.concatenate([PHASES, start]))
    count = in_swing.sum(axis=1)
    assert count.max() < n, "all feet in the air"
    assert count.min() >= 1, "the swing sectors do not cover the circle"
    # The chain: sorted by lift-off, each foot is still in swing when the next one lifts
    # (for two legs the sectors touch: it lands exactly when the other lifts).
    order = np.argsort(start)
    nxt = np.roll(order, -1)
    gap = np.mod(start[nxt] - start[order], 1.0)
    if n >= 3:
        assert (duration[order] > gap).all()
    else:
        assert np.allclose(duration[order], gap)


@pytest.mark.parametrize("n_legs", [2, 3, 4, 5, 6, 8])
def test_random_gaits_never_lift_all_feet_and_cover_the_circle(n_legs: int) -> None:
    params = GaitRandomizerParams()
    rng = np.random.default_rng(n_legs)
    orders = set()
    for _ in range(1000):
        g = random_gait(n_legs, rng, params)
        check_gait(g.swing_start, g.swing_duration)
        assert (g.swing_duration <= params.max_swing + 1e-12).all()
        # ``order`` is the lift-off chain: each listed leg lifts while the previous swings.
        rel = np.mod(g.swing_start[np.roll(g.order, -1)] - g.swing_start[g.order], 1.0)
        assert (rel <= g.swing_duration[g.order] + 1e-12).all()
        orders.add(tuple(np.roll(g.order, -int(np.argmin(g.swing_start[g.order])))))
    # The lift-off order really is random: most cyclic orders show up.
    expected = min(200, int(np.prod(np.arange(1, n_legs))))
    assert len(orders) >= 0.8 * expected


def test_random_gaits_respect_a_cap_on_feet_in_the_air() -> None:
    params = GaitRandomizerParams(max_feet_in_swing=3, max_swing=0.6)
    rng = np.random.default_rng(0)
    for _ in range(300):
        g = random_gait(8, rng, params)
        check_gait(g.swing_start, g.swing_duration)
        assert feet_in_swing(g.swing_start, g.swing_duration, np.concatenate([PHASES, g.swing_start])).sum(
            axis=1).max() <= 3


def test_random_gait_runs_in_the_gait_manager() -> None:
    g = random_gait(6, np.random.default_rng(4)).to_gait(cycle_time=0.8)
    assert isinstance(g, Gait)
    assert g.cycle_time == 0.8
    lifted = g.in_swing(PHASES)  # (n_phases, n_legs) from core.locomotion.gait's own reading
    assert lifted.sum(axis=1).max() < 6
    assert lifted.sum(axis=1).min() >= 1


def test_random_gaits_same_seed_same_sequence() -> None:
    def draw(seed: int) -> list[np.ndarray]:
        rng = np.random.default_rng(seed)
        return [np.concatenate([g.swing_start, g.swing_duration])
                for g in (random_gait(6, rng) for _ in range(50))]

    a, b, c = draw(7), draw(7), draw(8)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(np.array_equal(x, y) for x, y in zip(a, c, strict=True))


def test_one_leg_and_bad_bounds_are_refused() -> None:
    with pytest.raises(ValueError):
        random_gait(1, np.random.default_rng(0))
    with pytest.raises(ValueError):
        GaitRandomizerParams(min_swing=0.7, max_swing=0.6)
    with pytest.raises(ValueError):
        GaitRandomizerParams(max_feet_in_swing=1)


def test_gait_is_redrawn_at_each_stall_only_when_both_effects_are_on() -> None:
    params = ProgressionParams(max_speed=1.0, wavelength=(0.3, 0.6), static_period=(0.1, 0.3),
                               max_speed_period=(0.0, 0.2))
    rng = np.random.default_rng(2)
    n_legs = [4, 8, 6]
    state = ProgressionState.start(3, params, rng)
    start = initial_gaits(n_legs, rng, randomize_gait=np.array([True, True, False]))
    assert sorted(start) == [0, 1]
    assert start[1].swing_start.shape == (8,)
    stall_count = np.zeros(3, dtype=int)
    gait_count = np.zeros(3, dtype=int)
    for _ in range(600):
        state, out = effects_step(state, params, 1 / 30, rng, n_legs,
                                  progression_on=True, randomize_gait=np.array([True, True, False]))
        stall_count += out.progression.stalled
        for c, g in out.new_gaits.items():
            assert out.progression.stalled[c]
            assert g.swing_start.shape == (n_legs[c],)
            gait_count[c] += 1
    assert stall_count.min() >= 5
    assert gait_count[0] == stall_count[0]
    assert gait_count[1] == stall_count[1]
    assert gait_count[2] == 0
    # Progression off: no stalls, so never a new gait, even with the randomizer on.
    state = ProgressionState.start(2, params, rng)
    for _ in range(100):
        state, out = effects_step(state, params, 1 / 30, rng, [4, 4], progression_on=False)
        assert out.new_gaits == {}
