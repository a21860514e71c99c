# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/actions.py: bulk keyframe writing, rotation modes, Action memory; on 4.2 and 5.x.

Written keys are checked by evaluating the pose through the depsgraph (``frame_set``),
not by reading back the F-curves.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest
from mathutils import Quaternion

from procloco_addon.blender import actions
from tests.blender.pose_eval import pose_matrices

pytestmark = pytest.mark.blender

MODES = ["QUATERNION", "XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", "AXIS_ANGLE"]


def _armature(name: str = "Rig", n_bones: int = 1) -> Any:
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    parent = None
    for i in range(n_bones):
        eb = arm.edit_bones.new(f"B{i}")
        eb.head = (0.0, 0.0, float(i))
        eb.tail = (0.0, 0.0, float(i + 1))
        eb.roll = 0.3 * i
        eb.parent = parent
        parent = eb
    bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def _smooth_quats(n_frames: int, seed: int, turns: float = 1.3) -> np.ndarray:
    """A smooth quaternion path that sweeps more than a full turn (so branches must be chosen)."""
    rng = np.random.default_rng(seed)
    axis0, axis1 = rng.normal(size=(2, 3))
    t = np.linspace(0.0, 1.0, n_frames)[:, None]
    axis = (1 - t) * axis0 + t * axis1
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = 2.0 * np.pi * turns * t[:, 0] + 0.2
    return np.column_stack([np.cos(angle / 2), np.sin(angle / 2)[:, None] * axis])


def _user_action(obj: Any, name: str = "UserWalk") -> Any:
    """An Action made the ordinary way (keyframe_insert), as a user would."""
    obj.location = (1.0, 2.0, 3.0)
    obj.keyframe_insert("location", frame=1)
    obj.location = (4.0, 5.0, 6.0)
    obj.keyframe_insert("location", frame=10)
    action = obj.animation_data.action
    action.name = name
    return action


def test_new_action_is_unique_and_never_reuses_existing(empty_scene: Any) -> None:
    obj = _armature()
    existing = bpy.data.actions.new("Rig ProcLoco")
    first = actions.new_action(obj)
    second = actions.new_action(obj)
    assert first != existing
    assert second not in (existing, first)
    assert first.name.startswith("Rig ProcLoco.")
    assert second.name.startswith("Rig ProcLoco.")
    assert actions.is_generated(first)
    assert not actions.is_generated(existing)


@pytest.mark.parametrize("mode", MODES)
def test_rotations_written_in_each_rotation_mode_evaluate_to_the_input(empty_scene: Any, mode: str) -> None:
    obj = _armature(n_bones=2)
    for pb in obj.pose.bones:
        pb.rotation_mode = mode
    n = 40
    frames = np.arange(1, n + 1)
    quats = np.stack([_smooth_quats(n, 1), _smooth_quats(n, 2, turns=-0.8)], axis=1)
    locs = np.stack([np.linspace([0, 0, 0], [1, -2, 0.5], n), np.zeros((n, 3))], axis=1)
    action = actions.new_action(obj)
    written = actions.write_pose_bone_transforms(action, obj, frames, ["B0", "B1"], quats, locs)
    actions.assign_generated_action(obj, action)
    n_rot = 4 if mode in {"QUATERNION", "AXIS_ANGLE"} else 3
    assert written == 2 * (3 + n_rot)

    scene = bpy.context.scene
    for f in (0, 7, 21, n - 1):
        scene.frame_set(int(frames[f]))
        for b, name in enumerate(["B0", "B1"]):
            basis = obj.pose.bones[name].matrix_basis
            got = basis.to_quaternion()
            want = Quaternion(quats[f, b])
            assert abs(abs(got.dot(want)) - 1.0) < 1e-5, (mode, f, name)
            assert np.allclose(basis.to_translation(), locs[f, b], atol=1e-5)

    # Continuity: no channel jumps between consecutive frames (no 2π wraps, no sign flips).
    props = {"QUATERNION": "rotation_quaternion", "AXIS_ANGLE": "rotation_axis_angle"}
    prop = props.get(mode, "rotation_euler")
    for idx in range(n_rot):
        got_curve = actions.read_channel(action, obj, f'pose.bones["B0"].{prop}', idx)
        assert got_curve is not None
        assert np.max(np.abs(np.diff(got_curve[1]))) < 1.5  # a wrap or flip would jump by ≥ π


def test_posed_world_matrices_match_mathutils(empty_scene: Any) -> None:
    """pose_eval reads the depsgraph the same way mathutils does (layout of foreach_get)."""
    obj = _armature(n_bones=3)
    obj.location = (1.0, 2.0, 3.0)
    obj.rotation_euler = (0.3, 0.1, 1.2)
    obj.scale = (2.0, 2.0, 2.0)
    obj.pose.bones["B1"].rotation_quaternion = Quaternion((1.0, 0.3, -0.2, 0.5)).normalized()
    mats = pose_matrices(obj, [1], ["B2"])
    bpy.context.view_layer.update()
    want = np.array(obj.matrix_world @ obj.pose.bones["B2"].matrix)
    assert np.allclose(mats[0, 0], want, atol=1e-5)


def test_quaternion_to_euler_matches_blender_for_every_order() -> None:
    rng = np.random.default_rng(5)
    quats = rng.normal(size=(200, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    for order in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        eul = actions.quaternion_to_euler(quats, order)
        for q, e in zip(quats, eul, strict=True):
            want = Quaternion(q).to_matrix()
            from mathutils import Euler

            got = Euler(e, order).to_matrix()
            assert np.allclose(np.array(got), np.array(want), atol=1e-6), order


def test_object_transforms_keyed_in_object_rotation_mode(empty_scene: Any) -> None:
    obj = _armature()
    obj.rotation_mode = "ZXY"
    frames = np.array([1.0, 5.0, 9.0])
    locs = np.array([[0, 0, 0], [1, 0, 0], [2, 1, 0.5]], dtype=float)
    quats = np.array([[1, 0, 0, 0], [np.cos(0.5), 0, 0, np.sin(0.5)], [np.cos(1.0), 0, np.sin(1.0), 0]])
    action = actions.new_action(obj)
    assert actions.write_object_transforms(action, obj, frames, locs, quats) == 6
    actions.assign_generated_action(obj, action)
    bpy.context.scene.frame_set(9)
    assert np.allclose(obj.location, locs[2], atol=1e-6)
    assert abs(abs(obj.matrix_basis.to_quaternion().dot(Quaternion(quats[2]))) - 1) < 1e-6
    # Linear interpolation between the keys.
    bpy.context.scene.frame_set(3)
    assert np.allclose(obj.location, [0.5, 0, 0], atol=1e-6)


def test_user_action_survives_generation_and_is_restored(empty_scene: Any, tmp_path: Path) -> None:
    obj = _armature()
    user = _user_action(obj)
    user_slot = actions._current_slot_identifier(obj)
    keys_before = actions.read_channel(user, obj, "location", 0)

    gen1 = actions.new_action(obj)
    actions.write_object_transforms(gen1, obj, np.array([1.0, 2.0]), np.zeros((2, 3)))
    actions.assign_generated_action(obj, gen1)
    assert obj.animation_data.action == gen1
    assert actions.generated_action(obj) == gen1
    # A second generation replaces the first but still remembers the user's Action.
    gen2 = actions.new_action(obj)
    actions.write_object_transforms(gen2, obj, np.array([1.0, 2.0]), np.ones((2, 3)))
    actions.assign_generated_action(obj, gen2)
    assert gen1.use_fake_user, "a replaced generated Action must stay reachable"
    assert actions.previous_action(obj) == (True, user)

    # The remembered Action survives a save and reload even with no other user.
    path = tmp_path / "kept.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects["Rig"]
    user = bpy.data.actions["UserWalk"]
    gen2_name = obj.animation_data.action.name

    assert actions.clear_generated_action(obj)
    assert obj.animation_data.action == user
    assert actions._current_slot_identifier(obj) == user_slot
    assert gen2_name not in bpy.data.actions, "the cleared generated Action is removed"
    keys_after = actions.read_channel(user, obj, "location", 0)
    assert keys_before is not None
    assert keys_after is not None
    assert np.array_equal(keys_before[1], keys_after[1])
    bpy.context.scene.frame_set(10)
    assert np.allclose(obj.location, (4.0, 5.0, 6.0))
    # Nothing generated any more: clear refuses and changes nothing.
    assert not actions.clear_generated_action(obj)
    assert obj.animation_data.action == user


def test_clear_restores_no_action_when_there_was_none(empty_scene: Any) -> None:
    obj = _armature()
    gen = actions.new_action(obj)
    actions.write_object_transforms(gen, obj, np.array([1.0]), np.ones((1, 3)))
    actions.assign_generated_action(obj, gen)
    assert actions.clear_generated_action(obj)
    assert obj.animation_data.action is None
    assert actions.previous_action(obj) == (False, None)


def test_never_writes_into_a_user_action(empty_scene: Any) -> None:
    obj = _armature()
    user = _user_action(obj)
    before = actions.read_channel(user, obj, "location", 0)
    with pytest.raises(actions.ActionError, match="not made by ProcLoco"):
        actions.write_object_transforms(user, obj, np.array([1.0]), np.zeros((1, 3)))
    after = actions.read_channel(user, obj, "location", 0)
    assert before is not None
    assert after is not None
    assert np.array_equal(before[1], after[1])


def test_rewriting_a_channel_replaces_its_keys(empty_scene: Any) -> None:
    obj = _armature()
    action = actions.new_action(obj)
    actions.write_channels(action, obj, [actions.Channel("location", 2)], np.arange(1.0, 11.0), np.zeros(10))
    actions.write_channels(action, obj, [actions.Channel("location", 2)], np.array([1.0, 3.0]),
                           np.array([[5.0], [6.0]]), interpolation="CONSTANT")
    got = actions.read_channel(action, obj, "location", 2)
    assert got is not None
    assert np.array_equal(got[0], [1.0, 3.0])
    assert np.array_equal(got[1], [5.0, 6.0])
    assert [c.data_path for c in actions.channels_of(action, obj)] == ["location"]
    actions.assign_generated_action(obj, action)
    bpy.context.scene.frame_set(2)
    assert obj.location.z == pytest.approx(5.0)  # constant interpolation holds the first key


def test_bad_values_are_refused(empty_scene: Any) -> None:
    obj = _armature()
    action = actions.new_action(obj)
    loc_x = [actions.Channel("location", 0)]
    with pytest.raises(actions.ActionError):
        actions.write_channels(action, obj, loc_x, np.array([1.0]), np.array([np.nan]))
    with pytest.raises(ValueError, match="increasing"):
        actions.write_channels(action, obj, loc_x, np.array([2.0, 1.0]), np.zeros(2))
    assert actions.channels_of(action, obj) == []


def test_nla_strip_plays_the_action(empty_scene: Any) -> None:
    obj = _armature()
    action = actions.new_action(obj)
    actions.write_object_transforms(action, obj, np.array([5.0, 15.0]), np.array([[0, 0, 0], [10, 0, 0.0]]))
    strip = actions.push_to_nla(obj, action)
    assert strip.frame_start == pytest.approx(5.0)
    bpy.context.scene.frame_set(10)
    assert obj.location.x == pytest.approx(5.0)


def test_tweak_mode_is_refused(empty_scene: Any) -> None:
    obj = _armature()
    user = _user_action(obj)
    actions.push_to_nla(obj, user)
    obj.animation_data.action = None
    obj.animation_data.nla_tracks[0].strips[0].select = True
    obj.animation_data.use_tweak_mode = True
    assert obj.animation_data.use_tweak_mode
    action = actions.new_action(obj)
    with pytest.raises(actions.ActionError, match="tweak mode"):
        actions.assign_generated_action(obj, action)
    assert actions.previous_action(obj) == (False, None)


def test_matrix_helpers_are_consistent() -> None:
    rng = np.random.default_rng(0)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    mats = actions._quat_to_matrix(q)
    for qi, m in zip(q, mats, strict=True):
        assert np.allclose(np.array(Quaternion(qi).to_matrix()), m, atol=1e-12)


def _quat_continuous_by_frame(q: np.ndarray) -> np.ndarray:
    """The frame-by-frame reference: flip a frame that faces away from the one written before."""
    out = q.copy()
    for f in range(1, q.shape[0]):
        flip = np.sum(out[f] * out[f - 1], axis=-1) < 0.0
        out[f] = np.where(flip[..., None], -out[f], out[f])
    return out


@pytest.mark.parametrize("shape", [(1, 4), (2, 4), (300, 4), (300, 5, 4)])
def test_quaternion_signs_are_made_continuous_as_frame_by_frame(shape: tuple[int, ...]) -> None:
    """The one-pass sign continuity (a 10,000-frame write no longer loops per frame) flips
    exactly the frames the frame-by-frame rule does, exact zeros of the dot product included."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=shape)
    if shape[0] > 10:
        q[4:7] = q[3]  # runs of equal frames
        q[8], q[9], q[10] = (1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, -1.0, 0.0, 0.0)  # dot 0
    got = actions._quat_continuous(q)
    assert np.array_equal(got, _quat_continuous_by_frame(q))
    assert np.all(np.sum(got[1:] * got[:-1], axis=-1) >= 0.0)
