# SPDX-License-Identifier: GPL-3.0-or-later
"""Pelvis pseudo-physics (thesis §4.1): the pogo particle driven by the gait circles."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.locomotion.gait import Gait, GaitManager, in_swing, stance_elapsed
from procloco_addon.core.locomotion.pelvis_physics import (
    PelvisPhysics,
    PelvisPhysicsParams,
    foot_acceleration,
    node_acceleration,
    phase_times,
)

G = 9.81


def _pelvis_heights(
    gait: Gait, dt: float, seconds: float, preferred: float = 1.0, params: PelvisPhysicsParams | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Node height per frame and the all-feet-in-swing flag per frame."""
    n = gait.n_legs
    legs = np.zeros(n, dtype=np.int64)
    mgr = GaitManager(legs, [gait])
    phys = PelvisPhysics(legs, 1, params=params)
    phys.reset(np.array([preferred]), mgr.needle[legs], mgr.rate()[legs], mgr.disk_start, mgr.disk_duration)
    heights, flight = [], []
    for _ in range(round(seconds / dt)):
        needle = mgr.needle[legs].copy()
        h = phys.step(dt, needle, mgr.rate()[legs], mgr.disk_start, mgr.disk_duration, np.array([preferred]))
        step = mgr.advance(dt)
        heights.append(h[0])
        flight.append(bool(step.swing.all()))
    return np.array(heights), np.array(flight)


def test_reception_stops_the_fall_and_propulsion_launches_to_the_preferred_height() -> None:
    # one foot, stance of 0.4 s then swing of 0.4 s, starting at touch-down while falling
    h, v, dt = 1.0, -1.0, 1.0 / 2000.0
    t = 0.0
    while t < 0.8 - 1e-12:
        swing = t >= 0.4
        progress = min(t / 0.4, 0.999999)
        a = foot_acceleration(
            np.array([swing]),
            np.array([progress if not swing else 0.0]),
            np.array([0.4]),
            np.array([0.4]),
            np.array([h]),
            np.array([v]),
            np.array([1.0]),
            G,
            dt,
        )[0]
        v += (a - G) * dt
        h += v * dt
        t += dt
        if abs(t - 0.2) < dt / 2:
            assert v == pytest.approx(0.0, abs=0.02)  # end of reception: at rest
    assert h == pytest.approx(1.0, abs=0.01)  # landed back at the preferred height


def test_pelvis_acceleration_is_the_weighted_mean_of_the_feet() -> None:
    a_foot = np.array([20.0, 0.0, 10.0, 5.0])
    node = np.array([0, 0, 1, 1])
    np.testing.assert_allclose(node_acceleration(a_foot, node, 2, G), [10.0 - G, 7.5 - G])
    np.testing.assert_allclose(
        node_acceleration(a_foot, node, 2, G, np.array([3.0, 1.0, 1.0, 1.0])), [15.0 - G, 7.5 - G]
    )
    # a node without legs falls freely
    np.testing.assert_allclose(node_acceleration(a_foot, node, 3, G)[2], -G)


def test_symmetric_gait_gives_a_periodic_sinusoid_like_height() -> None:
    gait = Gait(np.array([0.0]), np.array([0.5]), cycle_time=0.8)  # thesis figure 4.5(a)
    dt = 1.0 / 30.0
    heights, _ = _pelvis_heights(gait, dt, 4.0)
    frames = round(gait.cycle_time / dt)
    last = heights[-2 * frames :]
    # periodic: one cycle repeats the previous one
    assert np.abs(last[frames:] - last[:frames]).max() < 1e-3
    # sinusoid-like: a single sine at the cycle frequency explains almost all of it
    t = np.arange(last.size) * dt
    basis = np.stack(
        [np.ones_like(t), np.sin(2 * np.pi * t / gait.cycle_time), np.cos(2 * np.pi * t / gait.cycle_time)],
        axis=1,
    )
    coef, *_ = np.linalg.lstsq(basis, last, rcond=None)
    residual = last - basis @ coef
    r2 = 1.0 - residual.var() / last.var()
    assert r2 > 0.97
    amplitude = np.hypot(coef[1], coef[2])
    assert amplitude > 0.05  # it really moves (g T² / 32 ≈ 0.2 m for this cycle)


def test_two_thirds_swing_gives_a_ballistic_flight() -> None:
    gait = Gait(np.array([0.0]), np.array([2.0 / 3.0]), cycle_time=0.9)  # thesis figure 4.5(b)
    dt = 1.0 / 60.0
    heights, flight = _pelvis_heights(gait, dt, 3.6)
    frames = round(gait.cycle_time / dt)
    h = heights[-2 * frames :]
    fl = flight[-2 * frames :]
    # during the flight the height is an exact parabola under gravity
    second = h[2:] - 2.0 * h[1:-1] + h[:-2]
    inside = fl[2:] & fl[1:-1] & fl[:-2]
    assert inside.sum() > frames / 2
    np.testing.assert_allclose(second[inside], -G * dt * dt, rtol=1e-6)
    # the flight takes two thirds of the cycle and the pelvis comes back where it left
    assert fl[:frames].mean() == pytest.approx(2.0 / 3.0, abs=1.5 / frames)
    # the apex of the flight is well above the preferred height, the stance dips below it
    assert h.max() > 1.0 + 0.1
    assert h.min() < 1.0


def test_frame_rate_barely_changes_the_curve() -> None:
    gait = Gait(np.array([0.0, 0.5]), np.array([0.4, 0.4]), cycle_time=1.0)
    h24, _ = _pelvis_heights(gait, 1.0 / 24.0, 3.0)
    h60, _ = _pelvis_heights(gait, 1.0 / 60.0, 3.0)
    # compare at the common times (every 0.5 s is a frame of both)
    assert np.abs(h24[11::12] - h60[29::30]).max() < 2e-3


def test_node_height_is_the_weighted_mean_of_its_particles() -> None:
    phys = PelvisPhysics(np.array([0, 0, 1]), 2, weights=np.array([1.0, 3.0, 1.0]))
    phys.height = np.array([1.0, 2.0, 5.0])
    np.testing.assert_allclose(phys.node_height(), [1.75, 5.0])


def test_a_step_equals_its_sub_steps_integrated_one_by_one() -> None:
    gait = Gait(np.array([0.0, 0.5, 0.25, 0.75]), np.full(4, 0.3), 0.8)
    legs = np.array([0, 0, 1, 1], dtype=np.int64)
    mgr = GaitManager(np.zeros(4, dtype=np.int64), [gait])
    rate = mgr.rate()[np.zeros(4, dtype=np.int64)]
    phys = PelvisPhysics(legs, 2)
    pref = np.array([0.5, 0.6])
    phys.reset(pref, mgr.needle[:4].copy(), rate, mgr.disk_start, mgr.disk_duration)
    height, velocity = phys.height.copy(), phys.velocity.copy()
    dt, needle = 1.0 / 24.0, mgr.needle[:4].copy() + 0.1
    phys.step(dt, needle, rate, mgr.disk_start, mgr.disk_duration, pref)
    # the same sub-steps, one foot_acceleration call each
    n_sub = int(np.ceil(dt / phys.params.max_substep - 1e-9))
    h = dt / n_sub
    period = 1.0 / rate
    d = mgr.disk_duration
    for k in range(n_sub):
        phase = needle + (k + 0.5) * h * rate
        progress = stance_elapsed(phase, mgr.disk_start, d) / (1.0 - d)
        a = foot_acceleration(in_swing(phase, mgr.disk_start, d), progress, (1.0 - d) * period, d * period,
                              height, velocity, pref[legs], G, h)
        velocity = velocity + (a - G) * h
        height = height + velocity * h
    np.testing.assert_allclose(phys.height, height, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(phys.velocity, velocity, rtol=1e-12, atol=1e-12)
    # phase times of many sub-steps at once are those of each alone
    phases = needle + (np.arange(n_sub)[:, None] + 0.5) * h * rate
    swing = in_swing(phases, mgr.disk_start, d)
    progress = stance_elapsed(phases, mgr.disk_start, d) / (1.0 - d)
    many = phase_times(swing, progress, (1.0 - d) * period, d * period, G, h)
    one = phase_times(swing[3], progress[3], (1.0 - d) * period, d * period, G, h)
    assert many.reception[3].tolist() == one.reception.tolist()
    np.testing.assert_array_equal(many.t_prop[3], one.t_prop)
