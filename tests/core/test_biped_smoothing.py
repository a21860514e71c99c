# SPDX-License-Identifier: GPL-3.0-or-later
"""Binomial smoothing of footprints (§3.3) and refinement by local similarity maps (§3.5)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core.biped import quat
from procloco_addon.core.biped.refine import refine, refine_step
from procloco_addon.core.biped.smoothing import smooth_footprints, smooth_positions, smooth_rotations
from procloco_addon.core.biped.surface import WalkableSurface, rectangle


def test_binomial_kernel_weights() -> None:
    p = np.zeros((9, 1))
    p[4] = 16.0
    out = smooth_positions(p)
    assert out[2:7, 0].tolist() == [1.0, 4.0, 6.0, 4.0, 1.0]


def test_straight_evenly_spaced_footprints_do_not_move() -> None:
    p = np.column_stack((np.arange(10) * 0.7, np.full(10, 0.1), np.zeros(10)))
    assert np.allclose(smooth_positions(p)[2:-2], p[2:-2])


@given(st.lists(st.floats(-1.5, 1.5), min_size=6, max_size=12))
def test_rotation_smoothing_is_the_binomial_average_of_headings(yaws: list[float]) -> None:
    # Consecutive headings closer than π, so the relative logarithms are the angle steps.
    y = np.cumsum(np.clip(np.array(yaws), -1.5, 1.5))
    out = smooth_rotations(quat.from_yaw(y))
    expected = smooth_positions(y[:, None])[:, 0]
    got = y + quat.wrap_angle(quat.yaw_of(out) - y)
    assert np.allclose(got[2:-2], expected[2:-2], atol=1e-9)


def test_smoothing_reduces_zigzag_and_keeps_fixed_ends() -> None:
    surf = WalkableSurface.from_polygons([rectangle((5.0, 0.0, 0.0), (14.0, 4.0))])
    n = 14
    side = np.arange(n) % 2
    x = np.arange(n) * 0.6
    wobble = 0.15 * np.sin(np.arange(n) * 2.1)
    y = np.where(side == 0, 0.1, -0.1) + wobble
    pos = np.column_stack((x, y, np.zeros(n)))
    yaw = 0.3 * np.sin(np.arange(n) * 1.7)
    fixed = np.zeros(n, bool)
    fixed[[0, 1, -2, -1]] = True
    island = surf.island_at(pos)
    new_pos, new_yaw = smooth_footprints(pos, yaw, side, fixed, island, surf, iterations=4)
    assert np.allclose(new_pos[fixed], pos[fixed])
    assert np.allclose(new_yaw[fixed], yaw[fixed])
    for s in (0, 1):
        lateral = new_pos[side == s, 1]
        assert np.abs(np.diff(lateral, 2)).sum() < 0.5 * np.abs(np.diff(pos[side == s, 1], 2)).sum()
    # Left stays left of right: the feet are smoothed separately.
    after = new_pos[side == 0, 1].mean() - new_pos[side == 1, 1].mean()
    together = pos.copy()
    for _ in range(4):
        together = smooth_positions(together, fixed)
    collapsed = together[side == 0, 1][1:-1].mean() - together[side == 1, 1][1:-1].mean()
    assert after > 0.12
    assert abs(collapsed) < 0.06
    assert np.abs(np.diff(new_yaw)).sum() < np.abs(np.diff(yaw)).sum()


def test_smoothing_snaps_back_onto_the_surface() -> None:
    surf = WalkableSurface.from_polygons([rectangle((3.0, 0.0, 0.0), (8.0, 1.0))])
    n = 10
    side = np.arange(n) % 2
    pos = np.column_stack((np.arange(n) * 0.6, np.where(side == 0, 0.3, -0.3), np.zeros(n)))
    pos[4:6, 1] += 0.3  # pushed towards the edge; smoothing spreads it, snapping pulls it in
    fixed = np.zeros(n, bool)
    fixed[[0, 1, -2, -1]] = True
    new_pos, _ = smooth_footprints(
        pos, np.zeros(n), side, fixed, surf.island_at(np.clip(pos, -0.3, 10)), surf
    )
    assert surf.fits(new_pos[~fixed]).all()


def _similarity(p: np.ndarray, angle: float, scale: float, shift: np.ndarray) -> np.ndarray:
    out = p.copy()
    out[:, :2] = scale * quat.rot2(angle, p[:, :2]) + shift
    return out


def test_refinement_fixed_point_is_a_similar_copy_of_the_original() -> None:
    rng = np.random.default_rng(0)
    n = 12
    orig = np.column_stack(
        (np.arange(n) * 0.6, np.where(np.arange(n) % 2, -0.1, 0.1) + 0.05 * rng.normal(size=n), np.zeros(n))
    )
    orig_yaw = 0.1 * rng.normal(size=n)
    want = _similarity(orig, 0.4, 1.1, np.array([2.0, -1.0]))
    want_yaw = orig_yaw + 0.4
    pos, yaw = refine_step(orig, orig_yaw, want, want_yaw, np.zeros(n, bool))
    assert np.allclose(pos, want)
    assert np.allclose(yaw, want_yaw)


def test_refinement_restores_the_clips_stance_width() -> None:
    n = 16
    side = np.arange(n) % 2
    orig = np.column_stack((np.arange(n) * 0.6, np.where(side == 0, 0.09, -0.09), np.zeros(n)))
    # The desired footprints were squeezed onto the centre line (too much smoothing, say).
    want = orig.copy()
    want[2:-2, 1] = 0.0
    fixed = np.zeros(n, bool)
    fixed[[0, 1, -2, -1]] = True
    pos, _ = refine(orig, np.zeros(n), want, np.zeros(n), fixed, np.zeros(n, np.int64), None, iterations=10)
    width = np.abs(pos[1:, 1] - pos[:-1, 1])
    assert np.all(width[4:-4] > 0.12)
    assert np.allclose(pos[fixed], want[fixed])
