# SPDX-License-Identifier: GPL-3.0-or-later
"""Game-ready loops: whole-frame cycles, the steady start, exact closing, root motion off."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core.locomotion import cycle

finite = st.floats(-1.0, 1.0, allow_nan=False)


@given(st.floats(0.4, 3.0), st.sampled_from([12.0, 24.0, 25.0, 29.97, 30.0, 60.0]))
def test_whole_period_fills_whole_frames(cycle_time: float, fps: float) -> None:
    period, stretch = cycle.whole_period(cycle_time, fps)
    assert period == round(cycle_time * fps)
    assert cycle_time * stretch * fps == pytest.approx(period, rel=1e-12)
    assert abs(stretch - 1.0) <= 0.5 / (cycle_time * fps) + 1e-12  # never more than half a frame


def test_whole_period_refuses_a_cycle_of_a_few_frames() -> None:
    with pytest.raises(ValueError, match="at least 4"):
        cycle.whole_period(0.1, 24.0)
    with pytest.raises(ValueError, match="no length"):
        cycle.whole_period(float("nan"), 24.0)


def _walk(n_frames: int, period: int, stride: np.ndarray, transient: float = 0.0,
          decay: float = 0.5) -> np.ndarray:
    """(F, 3, 3) points moving on by ``stride`` per cycle with a periodic wobble, plus a
    transient dying by ``decay`` per cycle."""
    f = np.arange(n_frames, dtype=np.float64)
    phase = 2.0 * np.pi * f / period
    wave = np.stack([np.sin(phase + k) for k in range(3)], axis=1)
    wobble = wave[:, :, None] * np.array([0.01, 0.02, 0.03])
    out = wobble + (f / period)[:, None, None] * stride
    out[:, :, 2] += transient * decay ** (f / period)[:, None]
    return out


def test_a_walk_that_repeats_is_steady_from_its_first_cycle() -> None:
    stride = np.array([0.3, 0.1, 0.0])
    pts = _walk(60, 12, stride)
    start, err = cycle.steady_start(pts, 12, 2, 1e-9)
    assert start == 12
    assert err < 1e-12
    assert cycle.stride_of(pts, 12, start, 2) == pytest.approx(stride)


def test_the_steady_start_waits_for_a_transient_to_die_down() -> None:
    pts = _walk(12 * 14 + 1, 12, np.array([0.3, 0.0, 0.0]), transient=0.1, decay=0.5)
    start, err = cycle.steady_start(pts, 12, 1, 1e-3)
    # from cycle j the transient falls by 0.05 * 0.5^j * 0.5^(k/P) over frame k of the next
    # cycle; the mean fall (the stride's z) taken off, 0.025 * 0.5^j is left at k = P
    expected = next(j for j in range(1, 12) if 0.025 * 0.5 ** j <= 1e-3)
    assert start == 12 * expected
    assert err <= 1e-3
    late, best = cycle.steady_start(pts[: 12 * 4 + 1], 12, 1, 1e-3)
    assert late == -1
    assert best > 1e-3


def test_loop_error_needs_one_cycle_beyond_the_loop() -> None:
    pts = _walk(25, 12, np.zeros(3))
    with pytest.raises(ValueError, match="shorter"):
        cycle.loop_error(pts, 12, 1, 1)


@given(st.lists(finite, min_size=27, max_size=27), st.lists(finite, min_size=3, max_size=3))
def test_close_points_ends_exactly_one_drift_from_the_start(values: list[float], drift: list[float]) -> None:
    pts = np.array(values).reshape(3, 3, 3).repeat(3, axis=0)  # (9, 3, 3)
    out = cycle.close_points(pts, drift)
    assert np.array_equal(out[0], pts[0])
    assert np.allclose(out[-1], out[0] + np.array(drift), atol=1e-15)
    # the correction grows evenly: it never moves a frame by more than the closing error
    error = np.abs(pts[-1] - pts[0] - np.array(drift))
    assert np.all(np.abs(out - pts) <= error[None] + 1e-12)


def test_remove_drift_leaves_the_loop_in_place() -> None:
    stride = np.array([0.4, -0.2, 0.0])
    pts = cycle.close_points(_walk(25, 12, stride), 2 * stride)
    out = cycle.remove_drift(pts, 2 * stride, origin_shift=np.array([1.0, 0.0, 0.0]))
    assert np.array_equal(out[-1], out[0])
    # a wobble without drift: what is left is the periodic part
    assert np.allclose(out[12], out[0], atol=1e-12)
    assert out[0] == pytest.approx(pts[0] - np.array([1.0, 0.0, 0.0]))


@given(st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3))
def test_rotation_log_inverts_rotation_exp(w: list[float]) -> None:
    v = np.array(w)
    if np.linalg.norm(v) > 3.1:
        v *= 3.1 / np.linalg.norm(v)
    r = cycle.rotation_exp(v)
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(cycle.rotation_log(r), v, atol=1e-7)


def test_close_rotations_turns_the_last_frame_onto_the_first_evenly() -> None:
    f = np.arange(13, dtype=np.float64)
    # a body yawing slightly back and forth, 0.6 degrees off at the end
    w = np.stack([np.zeros(13), 0.01 * np.sin(f), 0.02 * np.sin(2 * np.pi * f / 12) + 1e-3 * f / 12], axis=1)
    rot = cycle.rotation_exp(w)[:, None]
    out = cycle.close_rotations(rot)
    assert np.array_equal(out[-1], out[0])
    assert np.allclose(out[0], rot[0], atol=1e-15)
    change = np.linalg.norm(cycle.rotation_log(np.einsum("fmij,fmkj->fmik", out, rot)), axis=-1)
    end_error = np.linalg.norm(cycle.rotation_log(rot[0, 0] @ rot[-1, 0].T))
    assert change.max() <= end_error * 1.0001
    assert np.allclose(change[:, 0], end_error * f / 12, atol=1e-4 * end_error + 1e-12)
