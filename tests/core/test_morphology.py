# SPDX-License-Identifier: GPL-3.0-or-later
"""Morphology: legs of any count and segment count, derived values, validation, batching."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.locomotion import morphology as morph
from procloco_addon.core.locomotion.morphology import LegBatch, Morphology, MorphologyError

CREATURES = ["spider", "hexapod", "pentapod", "quadruped", "biped"]


def _mixed() -> Morphology:
    """One two-segment leg and one four-segment leg."""
    short = np.array([[0.0, 0.1, 0.0], [0.1, 0.2, -0.1], [0.1, 0.3, -0.3]])
    long = np.array(
        [[0.0, -0.1, 0.0], [0.05, -0.2, 0.05], [0.1, -0.3, 0.0], [0.12, -0.35, -0.15], [0.12, -0.4, -0.3]]
    )
    return Morphology.from_rest_joints([short, long], ["L1", "R1"])


def test_segments_are_padded_and_counted() -> None:
    m = _mixed()
    assert m.n_segments.tolist() == [2, 4]
    assert m.segment_lengths.shape == (2, 4)
    assert np.all(m.segment_lengths[0, 2:] == 0.0)
    # padded joints repeat the end effector
    np.testing.assert_allclose(m.rest_joints[0, 3], m.rest_joints[0, 2])
    np.testing.assert_allclose(m.rest_joints[0, 4], m.rest_joints[0, 2])
    np.testing.assert_allclose(m.rest_foot[1], [0.12, -0.4, -0.3])
    seg = np.linalg.norm(np.diff(m.rest_joints[1], axis=0), axis=1)
    np.testing.assert_allclose(m.segment_lengths[1], seg)
    np.testing.assert_allclose(m.leg_length, m.segment_lengths.sum(axis=1))


def test_zero_length_bone_is_refused_with_its_leg() -> None:
    bad = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.1, 0.0, -0.2]])
    good = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, -0.1], [0.1, 0.0, -0.2]])
    with pytest.raises(MorphologyError, match=r"R1.*segment 0.*zero length"):
        Morphology.from_rest_joints([good, bad], ["L1", "R1"])


@pytest.mark.parametrize(
    ("labels", "message"),
    [(["L1"], "1 labels for 2 legs"), (["L1", "L1"], "not unique")],
)
def test_bad_labels_are_refused(labels: list[str], message: str) -> None:
    leg = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, -0.1], [0.1, 0.0, -0.2]])
    with pytest.raises(MorphologyError, match=message):
        Morphology.from_rest_joints([leg, leg + 0.1], labels)


def test_no_legs_and_bad_shapes_are_refused() -> None:
    with pytest.raises(MorphologyError, match="at least one leg"):
        Morphology.from_rest_joints([])
    with pytest.raises(MorphologyError, match=r"\(k \+ 1, 3\)"):
        Morphology.from_rest_joints([np.zeros((1, 3))])


@pytest.mark.parametrize("name", CREATURES)
def test_default_limits_hold_the_rest_pose_and_keep_knee_sides(name: str) -> None:
    m = getattr(morph, name)()
    rest = m.rest_angles
    valid = np.arange(m.max_segments)[None, :] < m.n_segments[:, None]
    assert np.all(rest[valid] >= m.joint_min[valid] - 1e-12)
    assert np.all(rest[valid] <= m.joint_max[valid] + 1e-12)
    # every hinge may bend one way only: its range does not straddle zero
    hinge_lo, hinge_hi = m.joint_min[:, 1:], m.joint_max[:, 1:]
    hinge_valid = valid[:, 1:]
    assert np.all((hinge_lo[hinge_valid] >= 0.0) | (hinge_hi[hinge_valid] <= 0.0))
    # the rest feet stand on the ground plane at -body_thickness on average
    assert m.body_thickness == pytest.approx(-m.rest_foot[:, 2].mean())


def test_yaw_weight_separates_splayed_legs_from_legs_under_the_hip() -> None:
    assert np.all(morph.spider().yaw_weight == 1.0)
    assert np.all(morph.quadruped().yaw_weight == 0.0)
    assert np.all(morph.biped().yaw_weight == 0.0)


def test_plane_normal_is_perpendicular_to_every_rest_segment() -> None:
    for name in CREATURES:
        m = getattr(morph, name)()
        seg = np.diff(m.rest_joints, axis=1)
        dots = np.einsum("nkj,nj->nk", seg, m.plane_normal)
        np.testing.assert_allclose(dots, 0.0, atol=1e-12)


def test_straight_rest_leg_bends_like_a_knee() -> None:
    leg_l = np.array([[0.0, 0.1, 0.0], [0.0, 0.1, -0.4], [0.0, 0.1, -0.8]])
    m = Morphology.from_rest_joints([leg_l, leg_l * [1, -1, 1]], ["L1", "R1"])
    # plane of the forward axis and the leg: the normal is lateral
    np.testing.assert_allclose(np.abs(m.plane_normal[:, 1]), 1.0)


def test_leg_labels_front_to_back_left_first() -> None:
    assert morph.leg_labels(4) == ("L1", "R1", "L2", "R2")
    assert morph.leg_labels(5, midline=(1,)) == ("M1", "L2", "R2", "L3", "R3")
    assert morph.leg_labels(3, midline=(2,)) == ("L1", "R1", "M2")
    assert morph.pentapod().labels == ("M1", "L2", "R2", "L3", "R3")


def test_leg_batch_stacks_characters_with_different_legs() -> None:
    spider, biped, mixed = morph.spider(), morph.biped(), _mixed()
    batch = LegBatch.stack([spider, biped, mixed])
    assert batch.n_chars == 3
    assert batch.n_legs == 8 + 2 + 2
    assert batch.max_segments == 4
    assert batch.leg_char.tolist() == [0] * 8 + [1] * 2 + [2] * 2
    assert batch.leg_slice(1) == slice(8, 10)
    np.testing.assert_allclose(batch.segment_lengths[8:10, :2], biped.segment_lengths)
    assert np.all(batch.segment_lengths[:10, 3] == 0.0)
    # padded joint rows repeat each leg's end effector
    np.testing.assert_allclose(batch.rest_joints[:8, 4], spider.rest_foot)
    np.testing.assert_allclose(
        batch.rest_foot, np.concatenate([spider.rest_foot, biped.rest_foot, mixed.rest_foot])
    )


def test_unknown_leg_label_lookup_names_the_legs() -> None:
    with pytest.raises(MorphologyError, match="L1, R1"):
        morph.biped().leg_index("L9")
    assert morph.biped().leg_index("R1") == 1


def test_with_spine_makes_the_legs_hang_from_virtual_pelvis_nodes() -> None:
    plain = morph.quadruped()
    assert plain.spine is None
    assert plain.pelvis_node.tolist() == [0, 0, 0, 0]
    dog = morph.quadruped(spine=True)
    assert dog.spine is not None
    # head, shoulders, hips (thesis §4.4: three pelvis nodes, about seven spine joints)
    assert dog.spine.n_keys == 3
    assert dog.spine.n_joints == 7
    assert dog.pelvis_node.tolist() == [1, 1, 2, 2] == dog.spine.leg_key.tolist()
    np.testing.assert_allclose(dog.spine.hip_rest, dog.hip_offset)
    np.testing.assert_allclose(dog.spine.foot_rest, dog.rest_foot)
    # the legs themselves are unchanged
    np.testing.assert_allclose(dog.rest_joints, plain.rest_joints)
    lizard = morph.lizard()
    assert lizard.spine is not None
    assert (lizard.spine.n_keys, lizard.spine.n_joints) == (3, 9)  # thesis figure 4.15
    assert morph.lizard(spine=False).spine is None
    # explicit key nodes and carrier bones
    joints = dog.spine.joint_rest
    carried = plain.with_spine(joints, key_joint=[0, 2, 6], leg_key=[1, 1, 2, 2], leg_bone=[2, 2, 5, 5],
                               joint_yaw_limit=0.2)
    assert carried.spine is not None
    assert carried.spine.leg_bone.tolist() == [2, 2, 5, 5]
    np.testing.assert_allclose(carried.spine.joint_yaw_limit, 0.2)
    assert LegBatch.stack([plain, carried]).pelvis_node.tolist() == [0, 0, 0, 0, 1, 1, 2, 2]


def test_a_spine_that_cannot_carry_the_legs_is_refused() -> None:
    dog = morph.quadruped()
    short = np.array([[0.3, 0.0, 0.0], [0.0, 0.0, 0.0], [-0.3, 0.0, 0.0]])  # no head before the shoulders
    with pytest.raises(MorphologyError, match=r"spine: .*head"):
        dog.with_spine(short)
    with pytest.raises(MorphologyError, match="spine: "):
        dog.with_spine(short, key_joint=[0, 2], leg_key=[0, 0, 1, 1])
