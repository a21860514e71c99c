# SPDX-License-Identifier: GPL-3.0-or-later
"""Leg IK: reach, exact bone lengths, joint limits, knee side, frames, vectorisation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from procloco_addon.core.locomotion import ik
from procloco_addon.core.locomotion import morphology as morph
from procloco_addon.core.locomotion.morphology import LegBatch, plane_axes
from procloco_addon.core.metrics import bone_length_error, joint_angles, joint_limit_excess

CREATURES = ["spider", "hexapod", "pentapod", "quadruped", "biped"]


def _identity(n: int) -> np.ndarray:
    return np.broadcast_to(np.eye(3), (n, 3, 3)).copy()


def _rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _reachable_targets(batch: LegBatch, rng: np.random.Generator, spread: float) -> np.ndarray:
    """End effectors of random in-limit poses in each leg's rest plane (body frame)."""
    theta = batch.rest_angles + rng.uniform(-spread, spread, batch.rest_angles.shape)
    theta = np.clip(theta, batch.joint_min, batch.joint_max)
    pts = ik.forward_planar(theta, batch.segment_lengths)
    a, b = plane_axes(batch.plane_normal, np.broadcast_to([0.0, 0.0, 1.0], (batch.n_legs, 3)))
    end = pts[np.arange(batch.n_legs), batch.n_segments]
    return batch.hip_offset + end[:, :1] * a + end[:, 1:2] * b


@pytest.mark.parametrize("name", CREATURES)
def test_rest_targets_give_the_rest_pose(name: str) -> None:
    batch = LegBatch.stack([getattr(morph, name)()])
    res = ik.solve_legs(batch, batch.hip_offset, _identity(batch.n_legs), batch.rest_foot)
    np.testing.assert_allclose(res.joints, batch.rest_joints, atol=1e-8)
    assert res.error.max() < 1e-8


@given(st.integers(0, 2**31 - 1), st.sampled_from(CREATURES), st.floats(0.05, 0.7))
def test_reachable_targets_are_reached_with_exact_bones_inside_limits(
    seed: int, name: str, spread: float
) -> None:
    rng = np.random.default_rng(seed)
    batch = LegBatch.stack([getattr(morph, name)()] * 6)
    target = _reachable_targets(batch, rng, spread)
    res = ik.solve_legs(batch, batch.hip_offset, _identity(batch.n_legs), target)
    assert np.all(np.isfinite(res.joints))
    assert res.error.max() < 1e-4 * batch.leg_length.max()
    assert bone_length_error(res.joints[None], batch.segment_lengths, batch.n_segments).max() < 1e-9
    angles = joint_angles(
        res.joints[None], res.plane_normal[None], np.array([0.0, 0.0, 1.0]), batch.n_segments
    )
    assert joint_limit_excess(angles, batch.joint_min, batch.joint_max).max() < 1e-9
    # every joint lies in the leg plane, which contains the target
    rel = res.joints - batch.hip_offset[:, None, :]
    assert np.abs(np.einsum("nkj,nj->nk", rel, res.plane_normal)).max() < 1e-9
    assert np.abs(np.einsum("nj,nj->n", target - batch.hip_offset, res.plane_normal)).max() < 1e-9


def test_out_of_reach_target_straightens_the_leg_toward_it() -> None:
    batch = LegBatch.stack([morph.quadruped()])
    far = batch.hip_offset + np.array([0.1, 0.0, -2.0])
    res = ik.solve_legs(batch, batch.hip_offset, _identity(4), far)
    dist = np.linalg.norm(far - batch.hip_offset, axis=1)
    np.testing.assert_allclose(res.error, dist - batch.leg_length, atol=1e-6)
    end = res.joints[np.arange(4), batch.n_segments]
    direction = (end - batch.hip_offset) / batch.leg_length[:, None]
    np.testing.assert_allclose(direction, (far - batch.hip_offset) / dist[:, None], atol=1e-6)


def test_too_close_target_is_finite_and_bones_stay_exact() -> None:
    batch = LegBatch.stack([morph.spider(), morph.biped()])
    res = ik.solve_legs(batch, batch.hip_offset, _identity(batch.n_legs), batch.hip_offset + 1e-9)
    assert np.all(np.isfinite(res.joints))
    assert np.all(np.isfinite(res.error))
    assert bone_length_error(res.joints[None], batch.segment_lengths, batch.n_segments).max() < 1e-9


def test_biped_knees_bend_forward_over_a_whole_stride() -> None:
    batch = LegBatch.stack([morph.biped()])
    knees = []
    for dx in np.linspace(-0.35, 0.35, 15):
        target = batch.rest_foot + np.array([dx, 0.0, 0.05])
        res = ik.solve_legs(batch, batch.hip_offset, _identity(2), target)
        assert res.error.max() < 1e-9
        hip, knee, ankle = res.joints[:, 0], res.joints[:, 1], res.joints[:, 2]
        # knee in front of the hip-ankle line
        line = ankle - hip
        t = np.einsum("ij,ij->i", knee - hip, line) / np.einsum("ij,ij->i", line, line)
        knees.append((knee - (hip + t[:, None] * line))[:, 0])
    assert np.all(np.array(knees) > 0.0)


def test_spider_leg_plane_yaws_with_the_foot_and_stays_vertical() -> None:
    batch = LegBatch.stack([morph.spider()])
    rest_dir = batch.rest_foot - batch.hip_offset
    target = batch.hip_offset + (_rot_z(0.4) @ rest_dir.T).T
    res = ik.solve_legs(batch, batch.hip_offset, _identity(8), target)
    assert res.error.max() < 1e-9
    # vertical plane: the normal is horizontal, and turned by the same yaw
    assert np.abs(res.plane_normal[:, 2]).max() < 1e-9
    turned = (_rot_z(0.4) @ batch.plane_normal.T).T
    np.testing.assert_allclose(res.plane_normal, turned, atol=1e-9)


def test_solution_follows_the_body_rotation_and_position() -> None:
    rng = np.random.default_rng(3)
    batch = LegBatch.stack([morph.hexapod(), morph.pentapod()])
    target_body = _reachable_targets(batch, rng, 0.3)
    rot = _rot_z(1.1) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(0.3), -np.sin(0.3)], [0.0, np.sin(0.3), np.cos(0.3)]]
    )
    pelvis = np.array([3.0, -2.0, 0.7])
    hips = pelvis + batch.hip_offset @ rot.T
    res_body = ik.solve_legs(batch, batch.hip_offset, _identity(batch.n_legs), target_body)
    res_world = ik.solve_legs(
        batch, hips, np.broadcast_to(rot, (batch.n_legs, 3, 3)), pelvis + target_body @ rot.T
    )
    np.testing.assert_allclose(res_world.joints, pelvis + res_body.joints @ rot.T, atol=1e-9)
    np.testing.assert_allclose(res_world.plane_normal, res_body.plane_normal @ rot.T, atol=1e-9)


def test_plain_ccd_converges_on_an_unlimited_chain() -> None:
    lengths = np.array([[0.3, 0.3, 0.2]])
    target = np.array([[0.4, -0.3]])
    lo, hi = np.full((1, 3), -np.pi), np.full((1, 3), np.pi)
    theta = ik.solve_ccd(
        target, lengths, np.array([3]), lo, hi, np.array([[0.0, 0.5, 0.5]]), max_sweeps=200, tolerance=1e-8
    )
    end = ik.forward_planar(theta, lengths)[0, 3]
    assert np.linalg.norm(end - target[0]) < 1e-7


def test_dls_finishes_where_ccd_stalls_on_a_joint_limit() -> None:
    # a dog's foreleg from its rest pose to a target behind and below: CCD drives the wrist
    # and elbow onto their 0 limits and stops short; the damped least squares with an
    # active set of limits moves the joints together and gets there
    lengths = np.array([[0.22090722034374521, 0.20099751242241778, 0.08062257748298551]])
    lo = np.array([[-3.4067854659899712, 0.0, 0.0]])
    hi = np.array([[0.08387303799868806, 2.792526803190927, 2.792526803190927]])
    rest = np.array([[-1.6614562139956415, 0.19032853969190677, 0.02468634205559983]])
    target = np.array([[-0.07937091302925346, -0.47816132369709585]])
    args = (target, lengths, np.array([3]), lo, hi)
    ccd = ik.solve_ccd(*args, rest, max_sweeps=40)
    ccd_err = np.linalg.norm(ik.forward_planar(ccd, lengths)[0, 3] - target[0])
    dls = ik.solve_dls(*args, ccd, max_iterations=60)
    dls_err = np.linalg.norm(ik.forward_planar(dls, lengths)[0, 3] - target[0])
    assert ccd_err > 1e-2
    assert dls_err < 1e-5
    assert np.all(dls >= lo - 1e-12)
    assert np.all(dls <= hi + 1e-12)


def test_bend_start_depends_on_the_target_only() -> None:
    batch = LegBatch.stack([morph.quadruped()])
    target = batch.rest_foot + np.array([0.08, 0.0, 0.04])
    a = ik.solve_legs(batch, batch.hip_offset, _identity(4), target, init=batch.rest_angles + 0.3)
    b = ik.solve_legs(batch, batch.hip_offset, _identity(4), target, init=batch.rest_angles - 0.2)
    np.testing.assert_allclose(a.joints, b.joints, atol=1e-12)


def test_mask_leaves_unsolved_legs_at_their_initial_angles() -> None:
    batch = LegBatch.stack([morph.spider()])
    target = batch.rest_foot + np.array([0.05, 0.0, 0.02])
    mask = np.arange(8) < 4
    res = ik.solve_legs(batch, batch.hip_offset, _identity(8), target, mask=mask)
    assert res.error[:4].max() < 1e-6
    np.testing.assert_allclose(res.angles[4:], batch.rest_angles[4:])


def _follow(batch: LegBatch, leg: int, path: np.ndarray) -> tuple[np.ndarray, float]:
    """Solve ``leg`` frame by frame along ``path`` ``(F, 3)`` (foot relative to its hip, body
    frame) the way the controller does (last frame's angles and plane in); the other legs
    stand at rest. Returns the bone directions ``(F, k, 3)`` and the worst reach error."""
    n = batch.n_legs
    hip = batch.hip_offset
    angles, normal = batch.rest_angles.copy(), None
    dirs, worst = [], 0.0
    for p in path:
        target = batch.rest_foot.copy()
        target[leg] = hip[leg] + p
        res = ik.solve_legs(batch, hip, _identity(n), target, angles, prev_normal=normal)
        angles, normal = res.angles, res.normal_body
        seg = np.diff(res.joints[leg, : batch.n_segments[leg] + 1], axis=0)
        lengths = batch.segment_lengths[leg, : len(seg)]
        np.testing.assert_allclose(np.linalg.norm(seg, axis=1), lengths, rtol=1e-9)
        dirs.append(seg / np.linalg.norm(seg, axis=1, keepdims=True))
        worst = max(worst, float(res.error[leg]))
    return np.array(dirs), worst


_FOOT = st.tuples(
    st.floats(-np.pi, np.pi), st.floats(0.02, 0.7), st.floats(-0.7, -0.25)
)  # yaw about the hip, horizontal distance and height in leg lengths


@settings(max_examples=25, deadline=None)
@given(
    name=st.sampled_from(["spider", "hexapod"]),
    leg=st.integers(0, 5),
    start=_FOOT,
    end=_FOOT,
    extra_turn=st.floats(-np.pi, np.pi),
)
# the example spider's hind leg: its foot swings in under the hip and out behind it, half a
# turn from its rest direction (the turned rest normal's yaw wraps there)
@example(name="spider", leg=5, start=(2.08, 0.14, -0.42), end=(0.18, 0.19, -0.48), extra_turn=0.0)
# the foot passing a quarter turn from its rest side: the normal's projection is unstable
@example(name="hexapod", leg=4, start=(-2.55, 0.04, -0.35), end=(-0.14, 0.11, -0.55), extra_turn=0.0)
def test_a_foot_moving_by_small_steps_moves_every_bone_by_small_steps(
    name: str, leg: int, start: tuple[float, float, float], end: tuple[float, float, float], extra_turn: float
) -> None:
    """Legs of three and four segments following a foot along a continuous path (steps of at
    most 2 % of the leg's length): bone lengths kept, the foot reached, and no bone turns by
    more than 0.5 rad (29°) from one step to the next, wherever the foot goes around the hip
    (before, a bone could turn up to 150° in one step where the leg plane flipped)."""
    batch = LegBatch.stack([getattr(morph, name)()])
    leg = leg % batch.n_legs
    length = float(batch.leg_length[leg])
    a = np.array(start)
    b = np.array(end) + np.array([extra_turn, 0.0, 0.0])
    span = np.abs(b - a) * np.array([0.7, 1.0, 1.0])  # arc length bound, in leg lengths
    k = max(int(np.ceil(span.sum() / 0.02)), 2)
    c = a + np.linspace(0.0, 1.0, k + 1)[:, None] * (b - a)
    path = length * np.stack([c[:, 1] * np.cos(c[:, 0]), c[:, 1] * np.sin(c[:, 0]), c[:, 2]], axis=1)
    assert np.linalg.norm(np.diff(path, axis=0), axis=1).max() <= 0.021 * length
    dirs, error = _follow(batch, leg, path)
    assert error <= 1e-4 * length
    turn = np.arccos(np.clip(np.sum(dirs[1:] * dirs[:-1], axis=-1), -1.0, 1.0))
    assert turn.max() <= 0.5, f"a bone turns {np.degrees(turn.max()):.1f} deg in one step"


def test_the_plane_comes_back_to_the_target_only_pose() -> None:
    """Followed from another plane, a leg held at one target ends in the pose the target
    alone gives (the continuity does not make poses drift)."""
    batch = LegBatch.stack([morph.spider()])
    target = batch.rest_foot + np.array([0.05, -0.03, 0.02])
    fresh = ik.solve_legs(batch, batch.hip_offset, _identity(8), target)
    flipped = -fresh.normal_body  # type: ignore[operator]
    hip, rot = batch.hip_offset, _identity(8)
    res = ik.solve_legs(batch, hip, rot, target, batch.rest_angles, prev_normal=flipped)
    for _ in range(30):
        res = ik.solve_legs(batch, hip, rot, target, res.angles, prev_normal=res.normal_body)
    np.testing.assert_allclose(res.joints, fresh.joints, atol=1e-9)
