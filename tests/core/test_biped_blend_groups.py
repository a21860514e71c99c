# SPDX-License-Identifier: GPL-3.0-or-later
"""Blend groups: curvature estimate, turning weights and the walk/run parameter (§3.7)."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.biped.blend_groups import (
    circle_curvature,
    lowpass,
    path_curvature,
    speed_parameter,
    turning_weights,
)


@pytest.mark.parametrize("radius", [0.8, 1.6, 4.0, 12.0])
def test_three_points_on_a_circle_give_one_over_the_radius(radius: float) -> None:
    ang = np.array([0.1, 0.5, 1.3])
    pts = radius * np.column_stack((np.cos(ang), np.sin(ang)))
    assert circle_curvature(pts[0], pts[1], pts[2]) == pytest.approx(1.0 / radius, rel=1e-9)
    assert circle_curvature(pts[2], pts[1], pts[0]) == pytest.approx(-1.0 / radius, rel=1e-9)


def _walked_circle(radius: float, sway: float) -> tuple[np.ndarray, np.ndarray]:
    # A body walking a circle at 1.2 m/s, swaying side to side once per step (2 Hz).
    t = np.linspace(0.0, 12.0, 721)
    a = 1.2 * t / radius
    r = radius + sway * np.sin(2 * np.pi * 2.0 * t) * np.sign(radius)
    return t, np.column_stack((r * np.sin(a), radius - r * np.cos(a), np.zeros_like(t)))


@pytest.mark.parametrize("radius", [1.6, 4.0, -2.5, -10.0])
def test_curvature_of_a_walked_circle_is_within_two_percent(radius: float) -> None:
    t, pos = _walked_circle(radius, 0.0)
    tau = lowpass(t, path_curvature(t, pos, 0.4), 1.0)
    assert np.allclose(tau, 1.0 / radius, rtol=0.02)


@pytest.mark.parametrize("radius", [1.6, -4.0])
def test_lowpass_removes_the_sway_from_the_curvature(radius: float) -> None:
    t, pos = _walked_circle(radius, 0.02)
    raw = path_curvature(t, pos, 0.4)
    tau = lowpass(t, raw, 1.0)
    inner = slice(120, -120)
    assert np.abs(raw[inner] - 1.0 / radius).max() > 0.05  # the sway shows in the raw estimate
    assert np.abs(tau[inner] - 1.0 / radius).max() < 0.015


def test_straight_line_has_zero_curvature() -> None:
    t = np.linspace(0.0, 5.0, 301)
    pos = np.column_stack((t, 0.5 * t, np.zeros_like(t)))
    assert np.allclose(path_curvature(t, pos), 0.0, atol=1e-9)


def test_turning_weights_interpolate_between_the_bracketing_clips() -> None:
    taus = np.array([-0.625, -0.25, 0.0, 0.25, 0.625])
    w = turning_weights(np.array([0.1, 0.25, -0.4, 2.0, -2.0]), taus)
    assert np.allclose(w.sum(axis=1), 1.0)
    assert np.allclose(w[0], [0, 0, 0.6, 0.4, 0])
    assert np.allclose(w[1], [0, 0, 0, 1, 0])
    assert np.allclose(w[2], [0.4, 0.6, 0, 0, 0])
    assert np.allclose(w[3], [0, 0, 0, 0, 1])  # beyond the range: the nearest clip
    assert np.allclose(w[4], [1, 0, 0, 0, 0])
    # The order of the clips does not matter.
    perm = np.array([3, 0, 4, 2, 1])
    assert np.allclose(turning_weights(np.array([0.1]), taus[perm])[0], w[0][perm])


def test_speed_relaxes_to_walking_between_distant_runs() -> None:
    # Runs fixed at u = 5 and u = 15 (two jumps far apart); sigma = 2 strides.
    u = np.linspace(0.0, 20.0, 2001)
    s = speed_parameter(u, np.array([0.0, 5.0, 6.0, 15.0, 16.0, 20.0]), np.array([0, 1, 1, 1, 1, 0.0]), 2.0)
    at = lambda x: s[np.argmin(np.abs(u - x))]  # noqa: E731
    assert at(5.0) == 1.0
    assert at(6.0) == 1.0
    assert at(15.0) == 1.0
    assert at(7.0) == pytest.approx(0.5)
    assert at(8.0) == 0.0
    assert at(10.5) == 0.0
    assert at(13.0) == 0.0
    assert at(14.0) == pytest.approx(0.5)
    assert at(3.0) == 0.0
    assert at(4.0) == pytest.approx(0.5)
    assert np.all((s >= 0.0) & (s <= 1.0))


def test_speed_stays_up_between_close_runs() -> None:
    # Two jumps only 3 strides apart: there is no time to slow down, s stays at 1.
    u = np.linspace(6.0, 9.0, 31)
    s = speed_parameter(u, np.array([0.0, 5.0, 6.0, 9.0, 10.0, 20.0]), np.array([0, 1, 1, 1, 1, 0.0]), 2.0)
    assert np.allclose(s, 1.0)
