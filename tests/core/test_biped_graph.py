# SPDX-License-Identifier: GPL-3.0-or-later
"""The footprint graph and its A* search (§3.2)."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.biped import quat, synth
from procloco_addon.core.biped.database import ClipDatabase
from procloco_addon.core.biped.graph import (
    FootprintGraph,
    GoalUnreachableError,
    GraphSettings,
    NoClipsError,
    relative_to_right,
    stride_geometry,
)
from procloco_addon.core.biped.scenarios import stairs
from procloco_addon.core.biped.surface import WalkableSurface, rectangle


@pytest.fixture(scope="module")
def db() -> ClipDatabase:
    skel = synth.make_skeleton()
    return ClipDatabase(skel, synth.standard_library(skel))


@pytest.fixture(scope="module")
def gap_world() -> WalkableSurface:
    # Two platforms 1.4 m apart: too far to step, close enough to jump (2.6 m jump).
    return WalkableSurface.from_polygons(
        [rectangle((2.0, 0.0, 0.0), (6.0, 3.0)), rectangle((8.9, 0.0, 0.0), (5.0, 3.0))]
    )


def test_nodes_depend_only_on_the_seed(db: ClipDatabase, gap_world: WalkableSurface) -> None:
    a = FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(7))
    b = FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(7))
    c = FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(8))
    assert np.array_equal(a.cell_xy, b.cell_xy)
    assert np.array_equal(a.heading_offset, b.heading_offset)
    assert not np.array_equal(a.cell_xy, c.cell_xy)
    # Nodes are only where a foot fits.
    assert gap_world.fits(a.cell_xy[a.cell_ok]).all()
    assert not a.cell_ok[~gap_world.fits(a.cell_xy)].any()


def test_edges_follow_the_clips_within_tolerance(db: ClipDatabase, gap_world: WalkableSurface) -> None:
    g = FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(1))
    pos, yaw = np.array([0.5, 0.2, 0.0]), 0.3
    nodes, ok = g.successors(pos[None], np.array([yaw]))
    assert ok.sum() >= 5
    natural = g.edges.scale == 1.0
    assert (ok[0] & natural).sum() >= 5
    for col in np.flatnonzero(ok[0]):
        info = db.infos[int(g.edges.clip[col])]
        rel, rel_yaw, _, _ = stride_geometry(db, info, float(g.edges.scale[col]))
        if natural[col]:
            own, own_yaw = relative_to_right(info, info.end_right_pos, info.end_right_yaw)
            assert np.allclose(rel, own)
            assert rel_yaw == pytest.approx(own_yaw)
        want, want_yaw = quat.compose2(pos, yaw, rel, rel_yaw)
        got, got_yaw = g.node_pose(int(nodes[0, col]))
        assert np.linalg.norm(got[:2] - want[:2]) <= g.tol_p + 1e-12
        assert abs(quat.wrap_angle(got_yaw - want_yaw)) <= g.tol_h + 1e-12


def test_only_the_jump_crosses_the_gap(db: ClipDatabase, gap_world: WalkableSurface) -> None:
    g = FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(1))
    # Right footprints along the edge of the first platform, facing the gap.
    xs = np.linspace(3.0, 4.6, 9)
    pos = np.column_stack((xs, np.full(9, -0.06), np.zeros(9)))
    nodes, ok = g.successors(pos, np.zeros(9))
    crossing = np.zeros_like(ok)
    for i in range(len(xs)):
        for j in np.flatnonzero(ok[i]):
            p, _ = g.node_pose(int(nodes[i, j]))
            crossing[i, j] = p[0] > 5.2
    families = np.array([db.infos[int(c)].role.family for c in g.edges.clip])
    assert crossing.any()
    assert np.all(families[np.nonzero(crossing)[1]] == "jump")


def test_search_reaches_the_goal_across_the_gap(db: ClipDatabase, gap_world: WalkableSurface) -> None:
    g = FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(3))
    stop = db.first("stop")
    assert stop is not None
    path = g.search(np.array([0.6, -0.09, 0.0]), 0.0, np.array([10.0, 0.0]), None, stop)
    families = [db.infos[int(c)].role.family for c in path.clips]
    assert families.count("jump") == 1
    end, end_yaw = relative_to_right(stop, stop.cycle_pos, stop.cycle_yaw)
    body_end, _ = quat.compose2(path.right_pos[-1], path.right_yaw[-1], end, end_yaw)
    assert np.linalg.norm(body_end[:2] - [10.0, 0.0]) <= g.settings.goal_radius
    assert gap_world.fits(path.right_pos).all()


@pytest.mark.parametrize("heading", [np.pi / 2, -np.pi / 2, np.pi])
def test_goal_heading_is_honoured(db: ClipDatabase, heading: float) -> None:
    square = WalkableSurface.from_polygons([rectangle((3.0, 0.0, 0.0), (8.0, 8.0))])
    g = FootprintGraph(db, square, GraphSettings(), np.random.default_rng(3))
    stop = db.first("stop")
    assert stop is not None
    path = g.search(np.array([0.6, -0.09, 0.0]), 0.0, np.array([3.0, 0.5]), heading, stop)
    _, end_yaw = relative_to_right(stop, stop.cycle_pos, stop.cycle_yaw)
    assert abs(quat.wrap_angle(path.right_yaw[-1] + end_yaw - heading)) <= g.settings.goal_heading_tolerance


def test_a_gap_wider_than_any_jump_is_unreachable_at_once(db: ClipDatabase) -> None:
    far = WalkableSurface.from_polygons(
        [rectangle((2.0, 0.0, 0.0), (6.0, 3.0)), rectangle((12.0, 0.0, 0.0), (4.0, 3.0))]
    )
    g = FootprintGraph(db, far, GraphSettings(), np.random.default_rng(0))
    stop = db.first("stop")
    assert stop is not None
    with pytest.raises(GoalUnreachableError, match="no gap narrow enough"):
        g.search(np.array([0.6, -0.09, 0.0]), 0.0, np.array([12.0, 0.0]), None, stop)


def test_without_jumps_the_gap_is_unreachable(db: ClipDatabase, gap_world: WalkableSurface) -> None:
    g = FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(0), families=("walk",))
    stop = db.first("stop")
    assert stop is not None
    with pytest.raises(GoalUnreachableError):
        g.search(np.array([0.6, -0.09, 0.0]), 0.0, np.array([10.0, 0.0]), None, stop)
    with pytest.raises(NoClipsError):
        FootprintGraph(db, gap_world, GraphSettings(), np.random.default_rng(0), families=("swim",))


def test_a_step_up_is_walked_not_jumped(db: ClipDatabase) -> None:
    # Ground, then a 15 cm step up to a long platform 1 m ahead: a jump crosses no gap here.
    step_world = WalkableSurface.from_polygons(
        [rectangle((0.5, 0.0, 0.0), (3.0, 3.0)), rectangle((4.0, 0.0, 0.15), (4.0, 3.0))], cell=0.025
    )
    g = FootprintGraph(db, step_world, GraphSettings(), np.random.default_rng(1))
    xs = np.linspace(0.0, 1.6, 17)
    pos = np.column_stack((xs, np.full(len(xs), -0.06), np.zeros(len(xs))))
    nodes, ok = g.successors(pos, np.zeros(len(xs)))
    up = np.zeros_like(ok)
    for i, j in zip(*np.nonzero(ok), strict=True):
        up[i, j] = g.node_pose(int(nodes[i, j]))[0][2] > 0.1
    families = np.array([db.infos[int(c)].role.family for c in g.edges.clip])
    assert up.any()
    assert "walk" in set(families[np.nonzero(up)[1]])  # walked (or run) up, never jumped
    assert not ok[:, families == "jump"].any()  # no gap anywhere: no jump at all


def test_stairs_are_climbed_a_tread_at_a_time(db: ClipDatabase) -> None:
    sc = stairs()
    surf = sc.surface().with_foot(0.12, 0.06)
    g = FootprintGraph(db, surf, GraphSettings(), np.random.default_rng(2), families=("walk",))
    stop = db.first("stop")
    assert stop is not None
    path = g.search(np.array([0.6, -0.09, 0.0]), 0.0, np.array([4.8, 0.0]), None, stop)
    assert path.scales is not None
    # Natural strides on the flat, short ones on the 35 cm treads.
    assert (path.scales < 1.0).any()
    assert (path.scales == 1.0).any()
    # Every right footprint wholly on a tread, never two rises above the one before (its
    # left step in between takes one).
    assert surf.supports(path.right_pos, path.right_yaw).all()
    assert np.diff(path.right_pos[:, 2]).max() <= 2 * 0.15 + 1e-6
    assert path.right_pos[-1, 2] == pytest.approx(0.6)
    for k, (clip, f) in enumerate(zip(path.clips, path.scales, strict=True)):
        _, _, left, left_yaw = stride_geometry(db, db.infos[int(clip)], float(f))
        lp, _ = quat.compose2(path.right_pos[k], path.right_yaw[k], left, left_yaw)
        z = float(surf.raster_height(lp[None, :2])[0])
        assert abs(z - path.right_pos[k, 2]) <= g.settings.max_step_height
        assert abs(path.right_pos[k + 1, 2] - z) <= g.settings.max_step_height


def test_short_strides_only_near_the_goal_on_open_ground(db: ClipDatabase) -> None:
    square = WalkableSurface.from_polygons([rectangle((3.0, 0.0, 0.0), (10.0, 6.0))])
    g = FootprintGraph(db, square, GraphSettings(), np.random.default_rng(4), families=("walk",))
    short = g.edges.scale < 1.0
    pos = np.array([[0.0, 0.0, 0.0], [5.5, 0.0, 0.0]])
    _, ok = g.successors(pos, np.zeros(2))
    assert not ok[:, short].any()  # no goal known, no step in the way: the clips as they are
    g.goal_xy = np.array([6.0, 0.0])
    _, ok = g.successors(pos, np.zeros(2))
    assert not ok[0, short].any()  # far from the goal
    assert ok[1, short].any()  # close to it: shorter steps to stop in the right place
