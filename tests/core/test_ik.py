# SPDX-License-Identifier: GPL-3.0-or-later
"""Leg IK: reach, exact bone lengths, joint limits, knee side, frames, vectorisation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core import ik
from procloco_addon.core import morphology as morph
from procloco_addon.core.metrics import bone_length_error, joint_angles, joint_limit_excess
from procloco_addon.core.morphology import LegBatch, plane_axes

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
