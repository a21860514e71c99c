# SPDX-License-Identifier: GPL-3.0-or-later
"""Motion metrics on hand-made arrays: each one detects what it claims to measure."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core import metrics as mx
from procloco_addon.core.locomotion.gait import Gait


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


def test_stance_displacement_is_per_frame_and_sliding_its_worst() -> None:
    contact = np.array([[1, 0], [1, 1], [0, 1], [1, 1], [1, 0]], dtype=bool)
    foot = np.zeros((5, 2, 3))
    foot[4, 0, 0] = 0.003
    foot[3, 1, 2] = 0.001
    disp = mx.stance_displacement(foot, contact)
    assert disp.shape == (5, 2)
    np.testing.assert_allclose(disp[:, 0], [0.0, 0.0, 0.0, 0.0, 0.003])
    np.testing.assert_allclose(disp[:, 1], [0.0, 0.0, 0.0, 0.001, 0.0])
    np.testing.assert_allclose(mx.stance_sliding(foot, contact), disp.max(axis=0))
    assert mx.stance_sliding(foot, np.zeros((5, 2), dtype=bool)).tolist() == [0.0, 0.0]


def _still_legs(n_frames: int = 6) -> dict[str, np.ndarray]:
    """Two legs of length 1 standing on z = 0 under hips at z = 0.8, ends 0.05 up (their
    foot height), one probe per foot besides the end-effector, touching the ground."""
    hip = np.zeros((n_frames, 2, 3))
    hip[:, 1, 1] = 0.5
    hip[..., 2] = 0.8
    end = hip.copy()
    end[..., 2] = 0.05
    probes = np.stack([end, end - np.array([0.0, 0.0, 0.05])], axis=2)  # (F, L, 2, 3)
    return {"end_effector": end, "hip": hip, "target": end.copy(),
            "contact": np.ones((n_frames, 2), dtype=bool), "leg_length": np.ones(2), "probes": probes,
            "surface": np.zeros((n_frames, 2, 2)),
            "lift": np.array([[0.05, 0.0], [0.05, 0.0]])}


def test_posed_quality_of_a_still_stance_is_clean() -> None:
    q = mx.posed_quality(**_still_legs())
    for _key, figure in q.figures():
        assert figure.value == pytest.approx(0.0, abs=1e-12)
        assert not figure.failed
    assert q.few_feet_down.frame == -1
    assert q.over_stretched.frame == -1


def test_posed_quality_finds_each_fault_at_its_worst_frame() -> None:
    a = _still_legs()
    a["end_effector"][3:, 1, 0] += [0.001, 0.004, 0.003]  # leg 1 slides, worst at frame 4
    a["probes"][3:, 1, :, 0] += np.array([0.001, 0.004, 0.003])[:, None]
    a["probes"][2, 0, 1, 2] = -0.02  # leg 0's sole 2 cm into the ground at frame 2
    q = mx.posed_quality(**a)
    assert (q.slide.value, q.slide.frame, q.slide.leg) == (pytest.approx(0.004), 4, 1)
    assert q.slide.failed
    assert (q.penetration.value, q.penetration.frame, q.penetration.leg) == (pytest.approx(0.02), 2, 0)
    assert q.reach.value == pytest.approx(0.004)  # the slid foot left its target
    # Leg 0 held 3 cm up at frames 1 and 2, and 4 mm up at frame 4 (still down)
    b = _still_legs()
    b["end_effector"][1:3, 0, 2] += 0.03
    b["probes"][1:3, 0, :, 2] += 0.03
    b["probes"][4, 0, :, 2] += 0.004  # 4 mm up: still down (within MAX_PENETRATION)
    q = mx.posed_quality(**b)
    assert q.few_feet_down.value == 2
    assert q.few_feet_down.failed
    assert q.few_feet_down.frame == 1
    assert q.hover == pytest.approx(0.03)
    # A foot over no ground is not down; a swinging one is never counted.
    b["surface"][5, 1] = -np.inf
    b["contact"][1:3, 0] = False
    q = mx.posed_quality(**b)
    assert (q.few_feet_down.value, q.few_feet_down.frame, q.hover) == (1, 5, np.inf)


def test_posed_quality_counts_over_stretched_frames_asked_or_posed() -> None:
    a = _still_legs()
    a["target"][2, 0, 2] = -0.3  # asked to reach 1.1 leg lengths below the hip
    a["end_effector"][4, 1, 2] = -0.25  # posed 1.05 (a stretchy bone)
    q = mx.posed_quality(**a)
    assert q.over_stretched.value == 2
    assert (q.over_stretched.frame, q.over_stretched.leg) == (2, 0)
    assert q.stretch == pytest.approx(1.1)
    assert q.reach.value == pytest.approx(0.3)  # frame 4's target was reachable, the foot was not there
    # Within the bone-length tolerance a straight leg is not over-stretched.
    b = _still_legs()
    b["target"][2, 0, 2] = 0.8 - (1.0 + 0.5 * mx.MAX_BONE_LENGTH_ERROR)
    assert mx.posed_quality(**b).over_stretched.value == 0
