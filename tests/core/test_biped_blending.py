# SPDX-License-Identifier: GPL-3.0-or-later
"""Playback with parametric blending and the most stable blend point (§3.4)."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.biped import quat, synth
from procloco_addon.core.biped.blending import Plan, contact_schedule, one_hot_plan, plan_footprints, play
from procloco_addon.core.biped.clip import ClipRole
from procloco_addon.core.biped.database import ClipDatabase
from procloco_addon.core.biped.graph import relative_to_right
from procloco_addon.core.biped.skeleton import LEFT, RIGHT


@pytest.fixture(scope="module")
def db() -> ClipDatabase:
    skel = synth.make_skeleton()
    return ClipDatabase(skel, synth.standard_library(skel))


def _index(db: ClipDatabase, role: ClipRole) -> int:
    return next(i.index for i in db.infos if i.role is role)


@pytest.mark.parametrize("role", [ClipRole.WALK_FORWARD, ClipRole.WALK_LEFT, ClipRole.RUN_RIGHT])
def test_one_clip_plays_back_its_own_root_motion(db: ClipDatabase, role: ClipRole) -> None:
    c = _index(db, role)
    clip = db.clips[c]
    plan = one_hot_plan(db, np.array([c, c, c]), np.zeros(3), 0.0)
    pb = play(db, plan, clip.dt)
    # Three strides of the clip: the root ends where three cycle transforms put it.
    pos, yaw = np.zeros(3), 0.0
    for _ in range(3):
        pos, yaw = quat.compose2(pos, yaw, db.cycle_pos[c], db.cycle_yaw[c])
    assert np.allclose(pb.root_pos[-1], pos, atol=5e-3)
    assert abs(quat.wrap_angle(pb.root_yaw[-1] - yaw)) < 1e-3
    assert pb.t[-1] == pytest.approx(3 * clip.duration, abs=clip.dt)


def _switch_plan(db: ClipDatabase, a: int, b: int, at: float) -> Plan:
    """Three strides of clip ``a``; in the middle one the weights jump to clip ``b`` at phase ``at``."""
    s = 65
    w = np.zeros((3, s, len(db.clips)))
    w[:, :, a] = 1.0
    after = np.linspace(0.0, 1.0, s) >= at
    w[1, after, a] = 0.0
    w[1, after, b] = 1.0
    w[2, :, a] = 0.0
    w[2, :, b] = 1.0
    return Plan(np.array([a, a, a]), w, np.zeros(3), 0.0)


@pytest.mark.parametrize("other", [ClipRole.RUN_FORWARD, ClipRole.RUN_LEFT, ClipRole.WALK_LEFT])
def test_switching_weights_does_not_move_the_planted_foot(db: ClipDatabase, other: ClipRole) -> None:
    # Walk and run both have the right foot flat on the ground at phase 0.12 (mid-stance of
    # the run, early stance of the walk); the weights jump from one clip to the other there.
    walk, run = _index(db, ClipRole.WALK_FORWARD), _index(db, other)
    plan = _switch_plan(db, walk, run, 0.12)
    moved = {}
    for blend_point in (True, False):
        pb = play(db, plan, 1.0 / 120.0, blend_point=blend_point)
        frames = np.flatnonzero((pb.u > 1.05) & (pb.u < 1.18))
        assert np.all(pb.contact[frames, RIGHT] >= 0)
        low = np.argmin(pb.points_local[frames, RIGHT, :, 2], axis=1)
        p = pb.points[frames, RIGHT, low]
        same = low == low[len(low) // 2]
        moved[blend_point] = float(np.linalg.norm(p[same, :2] - p[same][0, :2], axis=1).max())
        if blend_point:
            single = pb.contact[frames, LEFT] < 0
            assert np.all(pb.alpha[frames][single] > 0.95)  # the blend point is the right foot
    assert moved[True] < 1e-3
    if other is not ClipRole.WALK_LEFT:
        assert moved[False] > 0.05  # the naive blend slides the foot by centimetres


def test_contact_schedule_alternates_feet(db: ClipDatabase) -> None:
    seq = [
        ClipRole.START,
        ClipRole.WALK_FORWARD,
        ClipRole.RUN_FORWARD,
        ClipRole.JUMP,
        ClipRole.RUN_LEFT,
        ClipRole.WALK_RIGHT,
        ClipRole.STOP,
    ]
    plan = one_hot_plan(db, np.array([_index(db, r) for r in seq]), np.zeros(3), 0.0)
    sched = contact_schedule(db, plan)
    # Left standing, right standing, then one left per segment and one right per later segment.
    assert len(sched) == 2 * len(seq) + 1
    assert sched.side.tolist() == [LEFT] + [RIGHT, LEFT] * len(seq)
    assert np.all(np.diff(sched.u_td) >= 0)
    assert np.all(sched.u_lo > sched.u_td)


def test_planned_footprints_match_the_played_ones(db: ClipDatabase) -> None:
    # The footprint graph predicts each next right footprint from the clip alone; playing
    # the chain must leave its footprints there (up to the start and stop cross-fades).
    role = ClipRole.WALK_FORWARD
    seq = [ClipRole.START, role, role, role, ClipRole.STOP]
    clips = np.array([_index(db, r) for r in seq])
    plan = one_hot_plan(db, clips, np.zeros(3), 0.0)
    start = db.infos[clips[0]]
    rp = [quat.compose2(np.zeros(3), 0.0, start.right_start.pos, start.right_start.yaw)]
    rp.append(quat.compose2(np.zeros(3), 0.0, start.end_right_pos, start.end_right_yaw))
    for c in clips[1:-1]:
        rel, rel_yaw = relative_to_right(db.infos[c], db.infos[c].end_right_pos, db.infos[c].end_right_yaw)
        rp.append(quat.compose2(rp[-1][0], rp[-1][1], rel, rel_yaw))
    right_pos = np.array([p for p, _ in rp])
    right_yaw = np.array([float(y) for _, y in rp])
    want = plan_footprints(db, plan, (right_pos, right_yaw))
    pb = play(db, plan, 1.0 / 60.0)
    err = np.linalg.norm(want.pos[:, :2] - pb.footprints.pos[:, :2], axis=1)
    assert err.max() < 0.03
    assert np.abs(quat.wrap_angle(want.yaw - pb.footprints.yaw)).max() < 0.03


@pytest.mark.parametrize("role", [ClipRole.WALK_LEFT, ClipRole.WALK_RIGHT_WIDE, ClipRole.RUN_LEFT])
def test_strides_keep_the_clips_footprint_geometry(db: ClipDatabase, role: ClipRole) -> None:
    # Away from cross-fades, one right footprint to the next is exactly the clip's edge in
    # the footprint graph: the graph's predictions hold locally.
    c = _index(db, role)
    plan = one_hot_plan(db, np.array([c] * 5), np.zeros(3), 0.0)
    fp = play(db, plan, 1.0 / 120.0).footprints
    right = np.flatnonzero(fp.side == RIGHT)
    a, b = right[2], right[3]
    rel, rel_yaw = quat.relative2(fp.pos[a], fp.yaw[a], fp.pos[b], fp.yaw[b])
    want, want_yaw = relative_to_right(db.infos[c], db.infos[c].end_right_pos, db.infos[c].end_right_yaw)
    assert np.allclose(rel[:2], want[:2], atol=0.01)
    assert abs(quat.wrap_angle(rel_yaw - want_yaw)) < 0.01
