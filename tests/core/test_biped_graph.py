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
)
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
    for c, nd in zip(g.edges.clip[ok[0]], nodes[0][ok[0]], strict=True):
        info = db.infos[int(c)]
        rel, rel_yaw = relative_to_right(info, info.end_right_pos, info.end_right_yaw)
        want, want_yaw = quat.compose2(pos, yaw, rel, rel_yaw)
        got, got_yaw = g.node_pose(int(nd))
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
