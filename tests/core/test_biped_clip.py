# SPDX-License-Identifier: GPL-3.0-or-later
"""Biped skeleton, clips, contact detection, the clip synthesiser and the clip database."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from procloco_addon.core.biped import quat, synth
from procloco_addon.core.biped.clip import (
    Clip,
    ClipRole,
    contact_runs,
    detect_contacts,
    extract_cycle,
    recorded_clip,
)
from procloco_addon.core.biped.database import ClipDatabase
from procloco_addon.core.biped.skeleton import LEFT, RIGHT, LegJoints, Skeleton, forward_kinematics


@pytest.fixture(scope="module")
def skel() -> Skeleton:
    return synth.make_skeleton()


@pytest.fixture(scope="module")
def clips(skel: Skeleton) -> list[Clip]:
    return synth.standard_library(skel)


@pytest.fixture(scope="module")
def db(skel: Skeleton, clips: list[Clip]) -> ClipDatabase:
    return ClipDatabase(skel, clips)


def _held_point_drift(clip: Clip, skel: Skeleton) -> float:
    """Largest frame-to-frame motion of a planted foot's lower point (same point both frames)."""
    pts = clip.foot_points_world(skel)
    assert clip.contacts is not None
    worst = 0.0
    for side in (LEFT, RIGHT):
        low = np.argmin(pts[:, side, :, 2], axis=1)
        p = pts[np.arange(len(pts)), side, low]
        same = clip.contacts[1:, side] & clip.contacts[:-1, side] & (low[1:] == low[:-1])
        if np.any(same):
            worst = max(worst, float(np.linalg.norm(np.diff(p[:, :2], axis=0)[same], axis=1).max()))
    return worst


def test_skeleton_rejects_bad_legs() -> None:
    good = synth.make_skeleton()
    with pytest.raises(ValueError, match="knee must be a child"):
        Skeleton(
            good.names,
            good.parents,
            good.offsets,
            dataclasses.replace(good.left, knee=good.left.ankle),
            good.right,
        )
    offsets = good.offsets.copy()
    offsets[good.left.knee] = 0.0
    with pytest.raises(ValueError, match="zero-length"):
        Skeleton(good.names, good.parents, offsets, good.left, good.right)
    with pytest.raises(ValueError, match="descendants of the ankle"):
        Skeleton(
            good.names,
            good.parents,
            good.offsets,
            LegJoints(
                good.left.hip, good.left.knee, good.left.ankle, heel=good.right.heel, toe=good.left.toe
            ),
            good.right,
        )


def test_forward_kinematics_keeps_bone_lengths(skel: Skeleton) -> None:
    rot = quat.normalize(np.random.default_rng(0).normal(size=(20, skel.n_joints, 4)))
    pos, _ = forward_kinematics(skel, rot, np.zeros((20, 3)))
    lengths = np.linalg.norm(pos[:, 1:] - pos[:, skel.parents[1:]], axis=-1)
    assert np.allclose(lengths, np.linalg.norm(skel.offsets[1:], axis=1))


def test_synthesised_clips_plant_their_feet(skel: Skeleton, clips: list[Clip]) -> None:
    roles = {c.role for c in clips}
    assert roles == set(ClipRole)
    for clip in clips:
        assert _held_point_drift(clip, skel) < 1e-6, clip.name
        pts = clip.foot_points_world(skel)
        assert pts[..., 2].min() > -1e-6, clip.name  # never below the ground


def test_synthesised_legs_reach_without_stretching(skel: Skeleton, clips: list[Clip]) -> None:
    for clip in clips:
        pos, _ = forward_kinematics(skel, clip.joint_rot, clip.pelvis_pos)
        for side in (LEFT, RIGHT):
            leg = skel.leg(side)
            d = np.linalg.norm(pos[:, leg.ankle] - pos[:, leg.hip], axis=1)
            assert d.max() <= skel.thigh_length[side] + skel.shin_length[side] + 1e-9, clip.name


def test_detected_contacts_match_the_synthesised_ones(skel: Skeleton, clips: list[Clip]) -> None:
    for clip in clips:
        assert clip.contacts is not None
        detected = detect_contacts(clip.foot_points_world(skel), clip.dt)
        for side in (LEFT, RIGHT):
            # A touchdown on the very last frame has no speed to judge by: leave it out.
            last = clip.n_frames - 1
            truth = [r for r in contact_runs(clip.contacts[:, side]) if r[0] < last - 1]
            found = [r for r in contact_runs(detected[:, side]) if r[0] < last - 1]
            assert len(found) == len(truth), (clip.name, side)
            for (a, b), (c, d) in zip(truth, found, strict=True):
                assert abs(a - c) <= 3, (clip.name, side)
                assert abs(b - d) <= 3, (clip.name, side)


@pytest.mark.parametrize("radius", [1.6, 4.0, -1.6, -4.0])
def test_walk_on_an_arc_has_curvature_one_over_radius(db: ClipDatabase, radius: float) -> None:
    role = next(r for r, rad in synth.WALK_RADII.items() if rad == radius)
    info = next(i for i in db.infos if i.role is role)
    assert info.curvature == pytest.approx(1.0 / radius, rel=0.01)


def test_database_contact_intervals_are_in_normal_form(db: ClipDatabase) -> None:
    for info in db.by_role("walk", "run", "jump"):
        assert info.right_start.td == 0.0
        assert 0.2 < info.left_step.td < 0.8
        sides = [iv.side for iv in info.intervals]
        assert sides == [RIGHT, LEFT], info.name
    start = db.first("start")
    assert start is not None
    # Standing: both feet down at phase 0, the left steps first.
    assert [(iv.side, iv.td == 0.0) for iv in start.intervals] == [(LEFT, True), (RIGHT, True), (LEFT, False)]


def test_database_footprints_match_the_clip(db: ClipDatabase, skel: Skeleton) -> None:
    info = next(i for i in db.infos if i.role is ClipRole.WALK_FORWARD)
    rs, ls = info.right_start, info.left_step
    w = synth.WALK
    assert rs.pos[1] == pytest.approx(-0.5 * w.step_width, abs=1e-3)
    assert ls.pos[1] == pytest.approx(0.5 * w.step_width, abs=1e-3)
    assert ls.pos[0] - rs.pos[0] == pytest.approx(0.5 * w.speed * w.cycle, abs=2e-3)
    assert info.end_right_pos[0] - rs.pos[0] == pytest.approx(w.speed * w.cycle, abs=2e-3)


def test_extract_cycle_cuts_one_stride(skel: Skeleton) -> None:
    base = synth.gait_clip(skel, synth.WALK, 0.0, ClipRole.WALK_FORWARD)
    # Two strides recorded from the middle of a stride, without contacts.
    n = base.n_frames - 1
    shift = n // 3
    idx = (np.arange(2 * n + 1) + shift) % n
    loops = (np.arange(2 * n + 1) + shift) // n
    step = base.root_pos[-1] - base.root_pos[0]
    long = Clip(
        "rec",
        ClipRole.WALK_FORWARD,
        base.dt,
        base.root_pos[idx] + loops[:, None] * step,
        base.root_yaw[idx],
        base.pelvis_pos[idx],
        base.joint_rot[idx],
    )
    cut = extract_cycle(long, skel)
    assert cut.n_frames == pytest.approx(base.n_frames, abs=3)
    assert cut.contacts is not None
    assert cut.contacts[0, RIGHT]
    assert cut.contacts[-1, RIGHT]
    assert not cut.contacts[-2, RIGHT]
    assert np.allclose(cut.root_pos[0], 0.0)
    with pytest.raises(ValueError, match="no complete right-foot stride"):
        extract_cycle(dataclasses.replace(long, contacts=np.zeros((long.n_frames, 2), bool)), skel)


def test_clips_fit_a_larger_skeleton() -> None:
    big = synth.make_skeleton(1.4)
    assert synth.body_scale(big) == pytest.approx(1.4)
    clips = synth.standard_library(big)
    for clip in clips:
        assert _held_point_drift(clip, big) < 1e-6, clip.name
    db = ClipDatabase(big, clips)
    walk_left = next(i for i in db.infos if i.role is ClipRole.WALK_LEFT)
    assert walk_left.curvature == pytest.approx(1.0 / (1.6 * 1.4), rel=0.01)
    walk = next(i for i in db.infos if i.role is ClipRole.WALK_FORWARD)
    assert walk.speed == pytest.approx(synth.WALK.speed * 1.4, rel=0.01)
    # The pelvis as far below the rest height as the reference body's, scaled.
    gait = synth.fit_gait(synth.WALK, big)
    assert big.offsets[0][2] - gait.pelvis_height == pytest.approx(
        1.4 * (synth.REFERENCE_STAND - synth.WALK.pelvis_height)
    )


def test_spine_and_arms_are_found_by_shape() -> None:
    skel = synth.make_skeleton()
    assert [skel.names[j] for j in synth.spine_chain(skel)] == ["spine", "chest", "head"]
    (lu, _ll), (_ru, rl) = synth.hanging_arms(skel)
    assert skel.names[lu] == "upper_arm.L"
    assert skel.names[rl] == "forearm.R"


def _recorded(skel: Skeleton, clip: Clip, periodic: bool) -> Clip:
    """``clip`` as a recording in the world (pelvis position and rotation) read back."""
    pelvis_world = clip.root_pos + quat.rot2(clip.root_yaw, clip.pelvis_pos)
    pelvis_rot = quat.mul(quat.from_yaw(clip.root_yaw), clip.joint_rot[:, 0])
    return recorded_clip(
        "rec", clip.role, skel, clip.dt, pelvis_world, pelvis_rot, clip.joint_rot, clip.contacts, periodic
    )


@pytest.mark.parametrize("role", [ClipRole.WALK_FORWARD, ClipRole.WALK_LEFT])
def test_a_recorded_stride_loops_with_its_root(skel: Skeleton, clips: list[Clip], role: ClipRole) -> None:
    """One recorded stride of a walk, its root derived from the pelvis: the pose relative to
    the root must end the stride as it began it, or the feet jump at every join of the loop
    (they jumped by 18 cm when the average was padded with copies of the end frames)."""
    clip = next(c for c in clips if c.role is role)
    mismatch = {}
    for periodic in (True, False):
        rec = _recorded(skel, clip, periodic)
        pos, _ = forward_kinematics(skel, rec.joint_rot, rec.pelvis_pos)
        feet = pos[:, [skel.left.heel, skel.left.toe, skel.right.heel, skel.right.toe]]
        assert np.abs(feet[-1] - feet[0]).max() < 1e-3
        assert rec.root_yaw[-1] - rec.root_yaw[0] == pytest.approx(
            clip.root_yaw[-1] - clip.root_yaw[0], abs=1e-3
        )
        # How the root moves over the first and the last frame, each in its own heading.
        first = quat.rot2(-rec.root_yaw[0], rec.root_pos[1] - rec.root_pos[0])
        last = quat.rot2(-rec.root_yaw[-1], rec.root_pos[-1] - rec.root_pos[-2])
        turn = (rec.root_yaw[1] - rec.root_yaw[0]) - (rec.root_yaw[-1] - rec.root_yaw[-2])
        mismatch[periodic] = (float(np.linalg.norm(first - last) / np.linalg.norm(first)), abs(float(turn)))
    # Known to loop, the root runs on into the next stride without a kink.
    assert mismatch[True][0] < 0.02
    assert mismatch[True][1] < 1e-3
    assert mismatch[False][0] > 0.1  # not known to loop: its speed jumps at the join
    assert mismatch[False][1] > 5e-3


def _arm_angles(skel: Skeleton, clip: Clip) -> tuple[np.ndarray, np.ndarray]:
    """Left upper arm's pitch from hanging straight down and the elbow's bend, both seen from
    the side in the character frame, forwards positive (degrees, per frame)."""
    pos, _ = forward_kinematics(skel, clip.joint_rot, clip.pelvis_pos)
    upper, lower = synth.hanging_arms(skel)[0]
    hand = next(j for j in range(skel.n_joints) if skel.parents[j] == lower)
    u = pos[:, lower] - pos[:, upper]
    f = pos[:, hand] - pos[:, lower]
    pitch_u = np.degrees(np.arctan2(u[:, 0], -u[:, 2]))
    pitch_f = np.degrees(np.arctan2(f[:, 0], -f[:, 2]))
    return pitch_u, pitch_f - pitch_u


@pytest.mark.parametrize("rest_bend", [0.0, 15.0])
def test_arms_swing_gently_and_elbows_hang_nearly_straight(rest_bend: float) -> None:
    skel = synth.make_skeleton()
    if rest_bend:
        # A rig modelled with its elbows already bent: the hands 15° ahead of the forearms.
        offsets = skel.offsets.copy()
        for tag in ("L", "R"):
            j = skel.index(f"hand.{tag}")
            length = np.linalg.norm(offsets[j])
            a = np.radians(rest_bend)
            offsets[j] = [length * np.sin(a), offsets[j][1], -length * np.cos(a)]
        skel = Skeleton(skel.names, skel.parents, offsets, skel.left, skel.right)
    lib = {c.role: c for c in synth.standard_library(skel, run=False, jump=False)}
    _, idle_elbow = _arm_angles(skel, lib[ClipRole.IDLE])
    assert idle_elbow == pytest.approx(np.degrees(synth.WALK.elbow), abs=1.0)  # relaxed, not bent twice
    swing, elbow = _arm_angles(skel, lib[ClipRole.WALK_FORWARD])
    assert 8.0 <= 0.5 * (swing.max() - swing.min()) <= 15.0  # about ±11°, not ±30°
    assert elbow.min() >= np.degrees(synth.WALK.elbow) - 1.0
    assert elbow.max() <= np.degrees(synth.WALK.elbow + synth.WALK.elbow_swing) + 1.0
    # The elbow bends most with the arm at the front of its swing.
    assert np.corrcoef(swing, elbow)[0, 1] > 0.9
