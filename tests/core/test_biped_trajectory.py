# SPDX-License-Identifier: GPL-3.0-or-later
"""Splines and the body trajectory carried from original to desired footprints (§3.6)."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.biped import quat
from procloco_addon.core.biped.splines import bspline_fit, catmull_rom, hierarchical_fit
from procloco_addon.core.biped.trajectory import midpoint_curve, midpoints, transfer


def test_catmull_rom_passes_through_its_points() -> None:
    rng = np.random.default_rng(0)
    pts = np.cumsum(rng.normal(size=(8, 3)), axis=0)
    times = np.cumsum(rng.uniform(0.3, 1.0, 8))
    assert np.allclose(catmull_rom(pts, times, times), pts, atol=1e-9)


def test_centripetal_catmull_rom_barely_overshoots_a_sharp_corner() -> None:
    # Unevenly spaced points around a right angle: the uniform spline swings 16 cm past the
    # corner, the centripetal one 1.5 cm.
    pts = np.array([[0.0, 0.0], [4.0, 0.0], [4.2, 0.0], [4.2, 0.2], [4.2, 4.0]])
    times = np.arange(5.0)
    t = np.linspace(0.0, 4.0, 401)
    centripetal = catmull_rom(pts, times, t)
    uniform = catmull_rom(pts, times, t, alpha=0.0)
    assert centripetal[:, 0].max() < 4.2 + 0.02
    assert centripetal[:, 1].min() > -0.02
    assert uniform[:, 0].max() > 4.2 + 0.1


def test_bspline_lowpass_removes_a_fast_wiggle_and_keeps_the_trend() -> None:
    t = np.linspace(0.0, 10.0, 601)
    trend = 0.3 * t
    wiggle = 0.05 * np.sin(2 * np.pi * 2.0 * t)  # 2 Hz, like a walk's sway
    fit = bspline_fit(t, trend + wiggle, 1.0)(t)[:, 0]
    assert np.abs(fit - trend)[30:-30].max() < 0.01


def test_bspline_bridges_frames_without_data() -> None:
    t = np.linspace(0.0, 4.0, 201)
    y = np.where(t < 2.0, 1.0, 3.0)
    w = ((t < 1.0) | (t > 3.0)).astype(float)
    fit = hierarchical_fit(t, y, (1.0, 0.5), t, weights=w)[:, 0]
    assert np.allclose(fit[t < 0.8], 1.0, atol=0.05)
    assert np.allclose(fit[t > 3.2], 3.0, atol=0.05)
    assert 1.0 < fit[100] < 3.0  # the middle is bridged, not dropped to zero


def _footprints(n: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    side = np.arange(n) % 2
    pos = np.column_stack((np.arange(n) * 0.6, np.where(side == 0, 0.09, -0.09), np.zeros(n)))
    yaw = 0.02 * np.sin(np.arange(n))
    time = np.arange(n) * 0.5 + 0.25
    return pos, yaw, time


def test_midpoints_are_between_consecutive_footprints() -> None:
    pos, yaw, time = _footprints()
    m, my, mt = midpoints(pos, yaw, time)
    assert np.allclose(m, 0.5 * (pos[1:] + pos[:-1]))
    assert np.allclose(mt, 0.5 * (time[1:] + time[:-1]))
    assert np.allclose(my, 0.5 * (yaw[1:] + yaw[:-1]))


def test_transfer_onto_the_same_footprints_changes_nothing() -> None:
    pos, yaw, time = _footprints()
    t = np.linspace(0.0, 6.0, 361)
    body = np.column_stack((1.2 * t, 0.02 * np.sin(4 * np.pi * t), np.zeros_like(t)))
    body_yaw = 0.01 * np.cos(t)
    new_pos, new_yaw = transfer(t, body, body_yaw, time, pos, yaw, pos, yaw)
    assert np.allclose(new_pos, body, atol=1e-12)
    assert np.allclose(new_yaw, body_yaw, atol=1e-12)


@pytest.mark.parametrize("angle", [0.3, -1.2, 2.5])
def test_transfer_onto_moved_footprints_moves_the_body_rigidly(angle: float) -> None:
    pos, yaw, time = _footprints()
    t = np.linspace(0.0, 6.0, 361)
    body = np.column_stack((1.2 * t, 0.02 * np.sin(4 * np.pi * t), 0.9 + np.zeros_like(t)))
    body_yaw = np.zeros_like(t)
    shift = np.array([3.0, -2.0, 0.5])
    want = quat.rot2(angle, pos) + shift
    new_pos, new_yaw = transfer(t, body, body_yaw, time, pos, yaw, want, yaw + angle)
    assert np.allclose(new_pos, quat.rot2(angle, body) + shift, atol=1e-9)
    assert np.allclose(new_yaw, body_yaw + angle, atol=1e-9)


def test_midpoint_headings_interpolate_linearly_between_midpoints() -> None:
    pos, _, time = _footprints()
    yaw = np.linspace(0.0, 1.0, len(pos))
    _, heading = midpoint_curve(pos, yaw, time, np.array([0.5 * (time[3] + time[4])]))
    assert heading[0] == pytest.approx(0.5 * (yaw[3] + yaw[4]), abs=1e-12)
