# SPDX-License-Identifier: GPL-3.0-or-later
"""Adding and removing footprints when the blended stride no longer fits (thesis §4.3 future work)."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.biped import quat, synth
from procloco_addon.core.biped.blending import Footprints, Plan, one_hot_plan, plan_footprints
from procloco_addon.core.biped.clip import ClipRole
from procloco_addon.core.biped.database import ClipDatabase
from procloco_addon.core.biped.graph import relative_to_right
from procloco_addon.core.biped.respace import clip_strides, respace
from procloco_addon.core.biped.skeleton import RIGHT


@pytest.fixture(scope="module")
def db() -> ClipDatabase:
    skel = synth.make_skeleton()
    return ClipDatabase(skel, synth.standard_library(skel))


def _chain(db: ClipDatabase, roles: list[ClipRole]) -> tuple[Plan, Footprints]:
    """A one-clip-per-stride plan and its footprints, chained from the origin."""
    clips = np.array([next(i.index for i in db.infos if i.role is r) for r in roles])
    plan = one_hot_plan(db, clips, np.zeros(3), 0.0)
    start = db.infos[clips[0]]
    poses = [
        quat.compose2(np.zeros(3), 0.0, start.right_start.pos, start.right_start.yaw),
        quat.compose2(np.zeros(3), 0.0, start.end_right_pos, start.end_right_yaw),
    ]
    for c in clips[1:-1]:
        rel, rel_yaw = relative_to_right(db.infos[c], db.infos[c].end_right_pos, db.infos[c].end_right_yaw)
        poses.append(quat.compose2(poses[-1][0], poses[-1][1], rel, rel_yaw))
    pos = np.array([p for p, _ in poses])
    yaw = np.array([float(y) for _, y in poses])
    return plan, plan_footprints(db, plan, (pos, yaw))


def _as(db: ClipDatabase, plan: Plan, role: ClipRole) -> Plan:
    """The same plan with every walk/run stride blended entirely into ``role``."""
    w = plan.weights.copy()
    target = next(i.index for i in db.infos if i.role is role)
    for k, c in enumerate(plan.clips):
        if db.infos[int(c)].role.family in ("walk", "run"):
            w[k] = 0.0
            w[k, :, target] = 1.0
    return Plan(plan.clips, w, plan.start_pos, plan.start_yaw)


def _right_strides(fp: Footprints) -> np.ndarray:
    right = fp.pos[fp.side == RIGHT]
    return np.linalg.norm(np.diff(right[:, :2], axis=0), axis=1)


def test_walking_over_running_footprints_adds_footprints(db: ClipDatabase) -> None:
    roles = [ClipRole.START] + [ClipRole.RUN_FORWARD] * 5 + [ClipRole.STOP]
    plan, fp = _chain(db, roles)
    walking = _as(db, plan, ClipRole.WALK_FORWARD)
    out, island = respace(db, walking, fp, None, np.zeros(len(fp), np.int64))
    strides = clip_strides(db)
    walk = strides[next(i.index for i in db.infos if i.role is ClipRole.WALK_FORWARD)]
    n_group = sum(db.infos[int(c)].role.family == "walk" for c in out.plan.clips)
    assert n_group > 5  # more strides: a walk covers the same ground in shorter ones
    inner = _right_strides(out.footprints)[1:-1]  # the strides between the start and the stop
    assert np.allclose(inner, walk, rtol=0.1)
    assert len(island) == len(out.footprints)
    # The ends are where they were: the start and the stop stances.
    assert np.allclose(out.footprints.pos[:2], fp.pos[:2])
    assert np.allclose(out.footprints.pos[-2:], fp.pos[-2:])


def test_running_over_walking_footprints_removes_footprints(db: ClipDatabase) -> None:
    roles = [ClipRole.START] + [ClipRole.WALK_FORWARD] * 9 + [ClipRole.STOP]
    plan, fp = _chain(db, roles)
    running = _as(db, plan, ClipRole.RUN_FORWARD)
    out, _ = respace(db, running, fp, None, np.zeros(len(fp), np.int64))
    n_group = sum(db.infos[int(c)].role.family in ("walk", "run") for c in out.plan.clips)
    assert n_group < 9
    assert out.changes == ((1, 9, n_group),)
    # Feet still alternate and every segment has its right footprint.
    assert np.all(np.diff(out.footprints.side[1:]) != 0)


def test_fitting_strides_are_left_alone(db: ClipDatabase) -> None:
    roles = [ClipRole.START] + [ClipRole.WALK_FORWARD] * 6 + [ClipRole.STOP]
    plan, fp = _chain(db, roles)
    out, _ = respace(db, plan, fp, None, np.zeros(len(fp), np.int64))
    assert out.changes == ()
    assert out.plan is plan
    assert np.array_equal(out.footprints.pos, fp.pos)
