# SPDX-License-Identifier: GPL-3.0-or-later
"""Motion metrics on hand-made arrays: each one detects what it claims to measure."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core import metrics as mx
from procloco_addon.core.gait import Gait


def test_stance_runs_and_sliding() -> None:
    contact = np.array([[1, 0], [1, 1], [0, 1], [1, 1], [1, 0]], dtype=bool)
    leg, first, last = mx.stance_runs(contact)
    assert list(zip(leg.tolist(), first.tolist(), last.tolist(), strict=True)) == [
        (0, 0, 1),
        (0, 3, 4),
        (1, 1, 3),
    ]
    foot = np.zeros((5, 2, 3))
    foot[4, 0, 0] = 0.003  # leg 0 slides 3 mm in its second stance
    foot[1:4, 1, 1] = 0.5  # leg 1 stands still at y = 0.5
    foot[2, 0, 2] = 1.0  # leg 0 in the air: not a slide
    slide = mx.stance_sliding(foot, contact)
    np.testing.assert_allclose(slide, [0.003, 0.0])


def test_penetration_against_a_surface_function() -> None:
    def plane(xy: np.ndarray) -> np.ndarray:
        return 0.1 * xy[:, 0]

    pts = np.array([[[1.0, 0.0, 0.1], [2.0, 5.0, 0.19]]])
    np.testing.assert_allclose(mx.penetration_depth(pts, plane), [[0.0, 0.01]], atol=1e-12)


def test_box_intrusion_depth() -> None:
    center = np.array([[0.0, 0.0, 0.0]])
    size = np.array([[1.0, 0.4, 0.3]])
    yaw = np.array([np.pi / 2])  # long side along y
    pts = np.array([[0.0, 0.45, 0.1], [0.15, 0.0, 0.2], [0.3, 0.0, 0.1], [0.0, 0.0, 0.35]])
    np.testing.assert_allclose(mx.box_intrusion(pts, center, size, yaw), [0.05, 0.05, 0.0, 0.0], atol=1e-12)


def test_bone_length_and_joint_limit_errors() -> None:
    joints = np.array([[[[0.0, 0.0, 0.0], [0.0, 0.0, -0.5], [0.3, 0.0, -0.9]]]])  # (F=1, L=1, 3, 3)
    lengths = np.array([[0.5, 0.5]])
    err = mx.bone_length_error(joints, lengths, np.array([2]))
    assert err[0] == pytest.approx(0.0, abs=1e-12)
    stretched = joints.copy()
    stretched[0, 0, 2] = [0.3, 0.0, -0.91]
    assert mx.bone_length_error(stretched, lengths, np.array([2]))[0] > 1e-3
    angles = np.array([[[0.1, 2.0]]])
    excess = mx.joint_limit_excess(angles, np.array([[0.0, 0.0]]), np.array([[1.0, 1.5]]))
    assert excess[0] == pytest.approx(0.5)
    # wrapping: 2π - 0.1 is the same angle as -0.1
    assert (
        mx.joint_limit_excess(np.array([[[2 * np.pi - 0.1]]]), np.array([[-0.2]]), np.array([[0.2]]))[0]
        == 0.0
    )


def test_joint_angles_from_positions_match_the_chain() -> None:
    # a planar chain in the xz plane (normal +y): first segment straight down, then bent 90°
    joints = np.array([[[[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, -1.0]]]])
    ang = mx.joint_angles(joints, np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([2]))
    # axis a = b x n = z x y = -x: the first segment points at -90° from -x toward +z
    np.testing.assert_allclose(ang[0, 0], [-np.pi / 2, np.pi / 2])


def test_reach_and_extension() -> None:
    end = np.zeros((2, 1, 3))
    target = np.array([[[0.02, 0.0, 0.0]], [[0.5, 0.0, 0.0]]])
    assert mx.reach_error(end, target)[0] == pytest.approx(0.5)
    assert mx.reach_error(end, target, np.array([[True], [False]]))[0] == pytest.approx(0.02)
    hip = np.array([[[0.0, 0.0, 1.0]], [[0.0, 0.0, 1.1]]])
    np.testing.assert_allclose(mx.extension(hip, end, np.array([1.0])), [1.1])


def _contact_from_gait(gait: Gait, dt: float, frames: int, shift: int = 0) -> tuple[np.ndarray, np.ndarray]:
    needle = np.mod(np.arange(frames) * dt / gait.cycle_time, 1.0)
    swing = gait.in_swing(needle)
    contact = ~np.roll(swing, shift, axis=0)
    return contact, needle


def test_swing_phase_errors_measure_frames() -> None:
    gait = Gait(np.array([0.1, 0.6]), np.array([0.3, 0.45]), cycle_time=1.0)
    dt = 1.0 / 30.0
    contact, needle = _contact_from_gait(gait, dt, 120)
    good = mx.swing_phase_errors(contact, needle, dt / gait.cycle_time, gait.swing_start, gait.swing_duration)
    assert good.n_events >= 12
    assert good.max_abs <= 1.0
    late = mx.swing_phase_errors(
        *_contact_from_gait(gait, dt, 120, shift=3),
        dt / gait.cycle_time,
        gait.swing_start,
        gait.swing_duration,
    )
    assert late.max_abs > 2.5
    # ignored frames are not judged
    ignore = np.ones_like(contact)
    assert (
        mx.swing_phase_errors(contact, needle, dt, gait.swing_start, gait.swing_duration, ignore).n_events
        == 0
    )


def test_periodicity_error() -> None:
    t = np.arange(100)
    s = np.sin(2 * np.pi * t / 20)
    assert mx.periodicity_error(s, 20) < 1e-12
    assert mx.periodicity_error(s + 0.001 * t, 20) == pytest.approx(0.02)
    with pytest.raises(ValueError, match="shorter"):
        mx.periodicity_error(s[:10], 20)


def test_report_lists_each_failed_check() -> None:
    ok = mx.MotionReport(
        stance_slide=np.array([0.001]),
        penetration=0.0,
        avoid_intrusion=0.0,
        bone_length_error=np.array([1e-9]),
        joint_limit_excess=np.array([0.0]),
        reach_error=np.array([0.001]),
        extension=np.array([0.95]),
    )
    assert ok.passed
    assert ok.failures() == []
    assert "stance slide max" in ok.summary()
    bad = mx.MotionReport(
        stance_slide=np.array([0.003]),
        penetration=0.006,
        avoid_intrusion=0.01,
        bone_length_error=np.array([1e-3]),
        joint_limit_excess=np.array([0.1]),
        reach_error=np.array([0.02]),
        extension=np.array([1.01]),
        hover=0.006,
    )
    text = "\n".join(bad.failures())
    for word in (
        "slides",
        "below a surface",
        "avoided obstacle",
        "bone length",
        "limits",
        "misses",
        "stretched",
        "hangs",
    ):
        assert word in text
    assert len(bad.failures()) == 8
