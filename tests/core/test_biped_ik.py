# SPDX-License-Identifier: GPL-3.0-or-later
"""The two-stage IK (§3.8): IK point, body offset, leg swivel, reach."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from procloco_addon.core.biped import quat, synth
from procloco_addon.core.biped.blending import Playback, one_hot_plan, play
from procloco_addon.core.biped.clip import ClipRole
from procloco_addon.core.biped.database import ClipDatabase
from procloco_addon.core.biped.ik import IKSettings, achieved_points, point_targets, solve, swing_lift
from procloco_addon.core.biped.planner import stance_slide
from procloco_addon.core.biped.skeleton import LEFT, RIGHT, forward_kinematics
from procloco_addon.core.biped.trajectory import transfer


@pytest.fixture(scope="module")
def db() -> ClipDatabase:
    skel = synth.make_skeleton()
    return ClipDatabase(skel, synth.standard_library(skel))


@pytest.fixture(scope="module")
def played(db: ClipDatabase) -> Playback:
    roles = [
        ClipRole.START,
        ClipRole.WALK_FORWARD,
        ClipRole.WALK_LEFT_WIDE,
        ClipRole.WALK_FORWARD,
        ClipRole.STOP,
    ]
    clips = np.array([next(i.index for i in db.infos if i.role is r) for r in roles])
    return play(db, one_hot_plan(db, clips, np.zeros(3), 0.0), 1.0 / 60.0)


def _desired(pb: Playback, amount: float) -> tuple[np.ndarray, np.ndarray]:
    """Footprints moved a few centimetres (alternating sideways, some forward) and turned."""
    fp = pb.footprints
    n = len(fp)
    pos = fp.pos.copy()
    k = np.arange(n)
    pos[2:-2, 0] += amount * np.sin(0.7 * k[2:-2])
    pos[2:-2, 1] += amount * np.cos(1.3 * k[2:-2])
    yaw = fp.yaw.copy()
    yaw[2:-2] += 2.0 * amount * np.sin(k[2:-2])
    return pos, yaw


def _solve(db: ClipDatabase, pb: Playback, amount: float, settings: IKSettings) -> tuple:
    want_pos, want_yaw = _desired(pb, amount)
    fp = pb.footprints
    body_pos, body_yaw = transfer(pb.t, pb.root_pos, pb.root_yaw, fp.time, fp.pos, fp.yaw, want_pos, want_yaw)
    return solve(db.skeleton, pb, body_pos, body_yaw, want_pos, want_yaw, settings), want_pos, want_yaw


def test_ik_point_is_the_lower_of_heel_and_toe(played: Playback) -> None:
    targets, which = point_targets(played, played.footprints.pos, played.footprints.yaw)
    planted = played.contact >= 0
    assert np.array_equal(which >= 0, planted)
    low = np.argmin(played.points_local[..., 2], axis=2)
    assert np.array_equal(which[planted], low[planted])
    # With the desired footprints equal to the played ones, the targets are the played points.
    f, s = np.nonzero(planted)
    got = played.points[f, s, which[f, s]]
    assert np.abs(targets[f, s] - got).max() < 0.01


@pytest.mark.parametrize("swivel", ["analytic", "search"])
def test_planted_points_reach_their_targets_and_do_not_slide(
    db: ClipDatabase, played: Playback, swivel: str
) -> None:
    result, _, _ = _solve(db, played, 0.05, IKSettings(swivel=swivel))
    pts = achieved_points(db.skeleton, result)
    f, s = np.nonzero(result.ik_point >= 0)
    err = np.linalg.norm(pts[f, s, result.ik_point[f, s]] - result.targets[f, s], axis=1)
    assert err.max() < 1e-6
    slide = stance_slide(pts, result.ik_point, played.contact)
    assert np.nanmax(slide) < 1e-6


def test_bone_lengths_and_knee_hinge_are_kept(db: ClipDatabase, played: Playback) -> None:
    skel = db.skeleton
    result, _, _ = _solve(db, played, 0.05, IKSettings())
    pos, _rot = forward_kinematics(skel, result.joint_rot, result.pelvis_pos)
    lengths = np.linalg.norm(pos[:, 1:] - pos[:, skel.parents[1:]], axis=-1)
    assert np.allclose(lengths, np.linalg.norm(skel.offsets[1:], axis=1), rtol=1e-9)
    for side in (LEFT, RIGHT):
        # The shin turns relative to the thigh about the thigh's own lateral axis only.
        knee = result.joint_rot[:, skel.leg(side).knee]
        axis = quat.log(knee)
        assert np.abs(axis[:, [0, 2]]).max() < 1e-6


def test_the_analytic_swivel_is_as_good_as_the_search(db: ClipDatabase, played: Playback) -> None:
    analytic, _, _ = _solve(db, played, 0.05, IKSettings(swivel="analytic"))
    search, _, _ = _solve(db, played, 0.05, IKSettings(swivel="search"))
    # The golden-section search (the thesis' method) converges on the closed form: keeping the
    # knee's hinge axis is the swivel that changes thigh and shin the least.
    assert np.abs(search.swivel_cost - analytic.swivel_cost).max() < 1e-5
    assert analytic.swivel_cost.mean() <= 1.001 * search.swivel_cost.mean()


def test_body_offset_takes_the_slow_part_of_the_correction(db: ClipDatabase, played: Playback) -> None:
    # Every desired footprint 8 cm to the left: the body should move over, not the legs.
    fp = played.footprints
    want_pos = fp.pos + np.array([0.0, 0.08, 0.0])
    want_pos[:2] = fp.pos[:2]
    want_pos[-2:] = fp.pos[-2:]
    result = solve(db.skeleton, played, played.root_pos, played.root_yaw, want_pos, fp.yaw)
    mid = (played.u > 1.5) & (played.u < 3.5)
    assert np.abs(result.body_offset[mid, 1] - 0.08).mean() < 0.02


def test_pelvis_comes_down_when_a_foot_is_out_of_reach(db: ClipDatabase, played: Playback) -> None:
    fp = played.footprints
    want_pos = fp.pos.copy()
    want_pos[5:8, 2] -= 0.12  # three footprints in a 12 cm dip
    result = solve(
        db.skeleton,
        played,
        played.root_pos,
        played.root_yaw,
        want_pos,
        fp.yaw,
        dataclasses.replace(IKSettings(), body_spacings=(4.0,)),
    )
    assert (result.pelvis_pos[:, 2] - played.pelvis_pos[:, 2]).min() < -0.01
    pts = achieved_points(db.skeleton, result)
    f, s = np.nonzero(result.ik_point >= 0)
    err = np.linalg.norm(pts[f, s, result.ik_point[f, s]] - result.targets[f, s], axis=1)
    assert err.max() < 0.01


def test_swing_lift_clears_a_step_edge_and_spares_lift_off_and_touchdown() -> None:
    # A foot point swinging from the ground at x = 0 onto a 0.2 m step whose edge is at
    # x = 0.5: its height rises smoothly from 0 to 0.2 (as the interpolated correction does),
    # so halfway it would cut through the edge.
    n_stance, n_swing = 10, 21
    planted = np.r_[np.ones(n_stance, bool), np.zeros(n_swing, bool), np.ones(n_stance, bool)]
    u = np.r_[np.zeros(n_stance), np.linspace(0.0, 1.0, n_swing + 2)[1:-1], np.ones(n_stance)]
    x = u
    z = 0.2 * u * u * (3.0 - 2.0 * u)
    pts = np.stack((x, np.zeros_like(x), z), axis=-1)[:, None, :]

    def ground(xy: np.ndarray) -> np.ndarray:
        return np.where(xy[..., 0] > 0.5, 0.2, 0.0)

    assert (ground(pts[..., :2])[:, 0] - z).max() > 0.05  # without the lift it cuts the edge
    lift = swing_lift(pts, planted, ground, 0.02)
    assert np.all(lift[planted] == 0.0)
    assert np.all(lift >= 0.0)
    lifted = z + lift
    over = ~planted & (x > 0.5)
    assert np.all(lifted[over] >= 0.2)  # above the step wherever it is over it
    swing = np.flatnonzero(~planted)
    mid = swing[(u[swing] > 0.2) & (u[swing] < 0.8) & (x[swing] > 0.5)]
    assert np.all(lifted[mid] >= 0.2 + 0.02 - 1e-9)  # with the clearance away from the ends
    # Smooth arches: no jump from frame to frame, little lift just after lift-off and just
    # before touchdown.
    assert np.abs(np.diff(lift)).max() < 0.5 * lift.max()
    assert lift[swing[0]] < 0.1 * lift.max()
    assert lift[swing[-1]] < 0.5 * lift.max()
