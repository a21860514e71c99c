# SPDX-License-Identifier: GPL-3.0-or-later
"""Walkable surfaces: heights, islands separated by gaps, fitting and snapping."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from procloco_addon.core.biped.surface import WalkableSurface, arc_band, rectangle


@pytest.fixture(scope="module")
def two_platforms() -> WalkableSurface:
    # Two 4 x 2 m platforms with a 1 m gap between x = 4 and x = 5; the second one 0.1 m higher.
    return WalkableSurface.from_polygons(
        [rectangle((2.0, 0.0, 0.0), (4.0, 2.0)), rectangle((7.0, 0.0, 0.1), (4.0, 2.0))]
    )


def test_heights_are_exact_on_a_slope() -> None:
    tri = np.array([[[0.0, 0.0, 0.0], [4.0, 0.0, 1.0], [0.0, 4.0, 0.5]]])
    surf = WalkableSurface.from_triangles(tri)
    pts = np.array([[1.0, 1.0], [2.0, 0.5], [0.3, 3.0]])
    expected = pts[:, 0] * 0.25 + pts[:, 1] * 0.125
    assert np.allclose(surf.height_at(pts), expected, atol=1e-12)
    assert np.isnan(surf.height_at(np.array([[3.9, 3.9]])))[0]


def test_a_gap_separates_islands(two_platforms: WalkableSurface) -> None:
    isl = two_platforms.island_at(np.array([[1.0, 0.0], [4.5, 0.0], [8.0, 0.0]]))
    assert isl[0] >= 0
    assert isl[2] >= 0
    assert isl[0] != isl[2]
    assert isl[1] == -1


def test_a_step_higher_than_max_step_separates_islands() -> None:
    surf = WalkableSurface.from_polygons(
        [rectangle((1.0, 0.0, 0.0), (2.0, 2.0)), rectangle((3.0, 0.0, 0.5), (2.0, 2.0))], max_step=0.2
    )
    isl = surf.island_at(np.array([[0.5, 0.0], [3.5, 0.0]]))
    assert isl[0] != isl[1]


def test_fits_keeps_a_margin_from_edges(two_platforms: WalkableSurface) -> None:
    m = two_platforms.margin
    xs = np.array([[4.0 - 0.5 * m, 0.0], [4.0 - 2.0 * m, 0.0], [2.0, 1.0 - 0.5 * m], [2.0, 0.0]])
    assert two_platforms.fits(xs).tolist() == [False, True, False, True]
    assert two_platforms.supported(xs).all()


def test_snap_stays_on_its_island(two_platforms: WalkableSurface) -> None:
    near_far_side = np.array([[4.9, 0.0, 0.0]])  # in the gap, closer to the second platform
    island_a = two_platforms.island_at(np.array([[1.0, 0.0]]))
    snapped = two_platforms.snap(near_far_side, island_a)
    assert snapped[0, 0] < 4.0 - two_platforms.margin + 1e-9
    assert two_platforms.fits(snapped).all()
    assert snapped[0, 2] == pytest.approx(0.0)
    free = two_platforms.snap(near_far_side)  # no island given: the nearest one
    assert free[0, 0] > 5.0
    assert free[0, 2] == pytest.approx(0.1)


def test_snap_keeps_points_that_fit(two_platforms: WalkableSurface) -> None:
    pts = np.array([[1.0, 0.3, 5.0], [7.5, -0.2, -3.0]])
    snapped = two_platforms.snap(pts)
    assert np.allclose(snapped[:, :2], pts[:, :2])
    assert np.allclose(snapped[:, 2], [0.0, 0.1])


def test_arc_band_is_one_island() -> None:
    surf = WalkableSurface.from_polygons(arc_band((0.0, 0.0, 0.0), 3.0, 4.0, 0.0, np.pi, n=16))
    ang = np.linspace(0.1, np.pi - 0.1, 20)
    pts = np.column_stack((3.5 * np.cos(ang), 3.5 * np.sin(ang)))
    isl = surf.island_at(pts)
    assert (isl >= 0).all()
    assert len(set(isl.tolist())) == 1
    assert surf.fits(pts).all()
    assert not surf.supported(np.array([[0.0, 2.0]]))[0]


def test_rejects_empty_input() -> None:
    with pytest.raises(ValueError, match="at least one triangle"):
        WalkableSurface.from_triangles(np.zeros((0, 3, 3)))


def test_blocked_triangles_cut_the_ground() -> None:
    ground = rectangle((0.0, 0.0, 0.0), (6.0, 6.0))
    crate = rectangle((0.0, 0.0, 0.5), (1.0, 1.0))  # the top of a crate to keep off
    surf = WalkableSurface.from_triangles(
        np.array([[ground[0], ground[1], ground[2]], [ground[0], ground[2], ground[3]]]),
        blocked=np.array([[crate[0], crate[1], crate[2]], [crate[0], crate[2], crate[3]]]),
    )
    assert not surf.supported(np.array([[0.0, 0.0]]))[0]
    assert surf.supported(np.array([[2.0, 0.0]]))[0]
    assert not surf.fits(np.array([[0.55, 0.0]]))[0]  # too close to the crate for a foot


def test_bounds_limit_the_raster() -> None:
    big = rectangle((0.0, 0.0, 0.0), (1000.0, 1000.0))
    surf = WalkableSurface.from_polygons([big], bounds=(-5.0, -5.0, 5.0, 5.0))
    assert max(surf.z.shape) <= 10.0 / surf.cell + 2
    assert surf.height_at(np.array([[1.0, 1.0]]))[0] == pytest.approx(0.0)


@pytest.fixture(scope="module")
def steps() -> WalkableSurface:
    # Three treads 0.35 m deep, 0.15 m apart in height, ascending along +x; one island.
    treads = [rectangle((0.175 + 0.35 * k, 0.0, 0.15 * k), (0.35, 1.6)) for k in range(3)]
    return WalkableSurface.from_polygons(treads, cell=0.025, max_step=0.2).with_foot(0.1, 0.05)


def test_steps_are_one_island_but_separate_terraces(steps: WalkableSurface) -> None:
    pts = np.array([[0.175, 0.0], [0.525, 0.0], [0.875, 0.0]])
    assert len(set(steps.island_at(pts).tolist())) == 1
    assert len(set(steps.terrace_at(pts).tolist())) == 3


def test_a_foot_is_supported_only_wholly_on_one_tread(steps: WalkableSurface) -> None:
    # A 0.2 m foot along the flight: centred on the middle tread it fits; 8 cm off centre
    # its toe is in the riser above or its heel over the edge below.
    on = steps.supports(np.array([[0.525, 0.0]]), np.array([0.0]))
    toe_in_riser = steps.supports(np.array([[0.605, 0.0]]), np.array([0.0]))
    heel_over_edge = steps.supports(np.array([[0.445, 0.0]]), np.array([0.0]))
    assert on.tolist() == [True]
    assert toe_in_riser.tolist() == [False]
    assert heel_over_edge.tolist() == [False]
    # Turned along the tread, the same off-centre foot fits: the sole is heading-aware.
    assert steps.supports(np.array([[0.605, 0.0]]), np.array([np.pi / 2])).tolist() == [True]
    assert steps.straddles_step(np.array([[0.605, 0.0]]), np.array([0.0])).tolist() == [True]
    assert not steps.straddles_step(np.array([[0.525, 0.0]]), np.array([0.0]))[0]
    # The old centre test would have let the straddling foot stand (its disc is on the island).
    assert steps.fits(np.array([[0.605, 0.0]]))[0]


def test_snap_with_a_heading_puts_the_sole_back_on_its_tread(steps: WalkableSurface) -> None:
    pts = np.array([[0.6, 0.1, 0.0], [0.44, -0.2, 0.0]])
    terrace = steps.terrace_at(np.array([[0.525, 0.0], [0.525, 0.0]]))
    yaw = np.array([0.05, -0.05])
    snapped = steps.snap(pts, steps.island_at(pts), yaw=yaw, terrace=terrace)
    assert steps.supports(snapped, yaw, terrace).all()
    assert np.allclose(snapped[:, 2], 0.15)
    # Moved no farther than needed: about the overlap plus the raster's half-cell slack.
    assert np.all(np.linalg.norm(snapped[:, :2] - pts[:, :2], axis=1) < 0.1)


def test_crate_sides_raise_no_numpy_warning() -> None:
    ground = rectangle((0.0, 0.0, 0.0), (4.0, 4.0))
    top = rectangle((0.0, 0.0, 0.5), (1.0, 1.0))
    side = np.array([[[0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [0.5, 0.5, 0.5]]])  # seen edge-on from above
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        surf = WalkableSurface.from_triangles(
            np.array([[ground[0], ground[1], ground[2]], [ground[0], ground[2], ground[3]]]),
            blocked=np.concatenate((np.array([[top[0], top[1], top[2]], [top[0], top[2], top[3]]]), side)),
        )
    assert not surf.supported(np.array([[0.0, 0.0]]))[0]
    assert surf.supported(np.array([[1.5, 0.0]]))[0]
