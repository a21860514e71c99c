# SPDX-License-Identifier: GPL-3.0-or-later
"""Rigs users bring (``rig_fixtures``) in scenes harsher than the gently bumpy ground of
``test_rig_fixtures``, as animators make them: hills, slopes, a step in the way. Each test
walks the rigs that once failed there, with Detect Legs' defaults, and measures the posed
rig as ``test_rig_fixtures`` does (``check_motion``)."""

from __future__ import annotations

import math
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import rig
from procloco_addon.blender.rig import controls, pose
from tests.blender.rig_fixtures import FIXTURES
from tests.blender.test_generate import _action_bytes
from tests.blender.test_rig_fixtures import FRAMES, check_motion, grid_under, walk

pytestmark = pytest.mark.blender


def test_mmd_feet_follow_the_toe_ik_on_hills(empty_scene: Any) -> None:
    """An MMD model's ankle is aimed by a one-bone IK at its toe IK bone (左つま先ＩＫ, a
    child of the leg IK 左足ＩＫ), and its knee IK has no pole. On hills of 6 % of its height
    the toe IK once stayed level with the leg IK (its soles 12.9 mm in the ground where the
    walk pitched them to it) and the knee swung about the leg (a planted foot turned 6.4° in
    one frame): now the toe IK is carried with the solved foot, the leg IK turns with it, and
    the legs are keyed at their solved pose, which Blender's IK starts from."""
    obj = FIXTURES["mmd"].build(empty_scene, "mmd")
    job, m = walk(obj, bumps=0.06)
    check_motion(m, "mmd")
    keyed = set(job.keyed_bones)
    assert {"左つま先ＩＫ", "右つま先ＩＫ", "左足", "右ひざ"} <= keyed, keyed


def _bend(obj: Any, name: str, angle: float) -> None:
    pb = obj.pose.bones[name]
    pb.rotation_mode = "QUATERNION"
    pb.rotation_quaternion = (math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0)


def test_legs_under_a_posed_pelvis_walk_from_where_they_hang(empty_scene: Any) -> None:
    """Character Creator's legs hang from CC_Base_Pelvis, a bone between the body bone
    (CC_Base_Hip) and the thighs that the walk does not key. Posed 10° (the animator's
    pose, kept under the walk), the legs were read where they hang but turned from their
    unposed rest: the feet slid 61 mm."""
    obj = FIXTURES["cc4"].build(empty_scene, "cc4")
    _bend(obj, "CC_Base_Pelvis", math.radians(10.0))
    bpy.context.view_layer.update()
    job, m = walk(obj)
    check_motion(m, "cc4")
    assert set(job.info.rest_posed) >= {"CC_Base_L_Thigh", "CC_Base_R_Calf"}, sorted(job.info.rest_posed)


def test_an_idle_in_the_nla_moves_no_planted_foot(empty_scene: Any) -> None:
    """The animator's idle (every bone keyed, the pelvis bending 10° over the frames) is in
    the NLA under the walk: the pelvis the legs hang from is keyed in the walk's Action at
    the pose the walk was read in, so the idle no longer carries the planted feet along (they
    slid 94 mm). The idle and its track are left as they were."""
    obj = FIXTURES["cc4"].build(empty_scene, "cc4")
    for pb in obj.pose.bones:
        pb.keyframe_insert("rotation_quaternion", frame=1)
    _bend(obj, "CC_Base_Pelvis", math.radians(10.0))
    obj.pose.bones["CC_Base_Pelvis"].keyframe_insert("rotation_quaternion", frame=FRAMES)
    idle = obj.animation_data.action
    obj.animation_data.nla_tracks.new().strips.new("Idle", 1, idle)
    obj.animation_data.action = None
    bpy.context.scene.frame_set(1)
    before = _action_bytes(idle, obj)
    job, m = walk(obj)
    check_motion(m, "cc4")
    assert "CC_Base_Pelvis" in job.kept_bones, job.kept_bones
    assert obj.animation_data.action is not idle
    assert [s.action for t in obj.animation_data.nla_tracks for s in t.strips] == [idle]
    assert _action_bytes(idle, obj) == before


def _idle_in_nla(obj: Any, bone: str) -> Any:
    """An idle in the NLA: every bone of ``bone``'s kind keyed at rest at the first frame,
    ``bone`` bent 10° at the last; the rig at the first frame. Returns the idle."""
    for pb in obj.pose.bones:
        if pb.rotation_mode == "QUATERNION" and not controls.is_mechanism_name(pb.name):
            pb.keyframe_insert("rotation_quaternion", frame=1)
    _bend(obj, bone, math.radians(10.0))
    obj.pose.bones[bone].keyframe_insert("rotation_quaternion", frame=FRAMES)
    idle = obj.animation_data.action
    obj.animation_data.nla_tracks.new().strips.new("Idle", 1, idle)
    obj.animation_data.action = None
    bpy.context.scene.frame_set(1)
    return idle


@pytest.mark.slow
def test_a_rigify_idle_in_the_nla_moves_no_planted_foot(empty_scene: Any) -> None:
    """On the Rigify horse, the front legs' ORG- chains follow the shoulder controls through
    constraints (not as children): an idle in the NLA turning ``shoulder.L`` once carried the
    planted front foot along. The walk keys the controls the legs follow that the idle
    animates at the pose it was read in (the front foot slid 46 mm)."""
    obj = FIXTURES["generated_horse"].build(empty_scene, "generated_horse")
    _idle_in_nla(obj, "shoulder.L")
    job, m = walk(obj)
    check_motion(m, "generated_horse")
    assert "shoulder.L" in job.kept_bones, job.kept_bones


def _side_slope(obj: Any, degrees: float) -> Any:
    """A plane under ``obj`` tilted ``degrees`` about the rig's forward axis (the direction it
    walks): its feet stand on ground that falls away to one side, level along their length."""
    forward = rig.read_rig(obj).body.forward
    left = np.array([-forward[1], forward[0]])
    return grid_under(obj, 12.0, 4, lambda xy: math.tan(math.radians(degrees)) * (xy @ left))


def _spy_rolls(monkeypatch: Any) -> list[np.ndarray | None]:
    """The foot roll turns the pose writer finds (``pose._roll_feet``), call by call."""
    found: list[np.ndarray | None] = []
    roll_feet = pose._roll_feet

    def spy(*args: Any) -> np.ndarray | None:
        found.append(roll_feet(*args))
        return found[-1]

    monkeypatch.setattr(pose, "_roll_feet", spy)
    return found


@pytest.mark.parametrize("name", ["rigify_basic_human", "generated_human"])
def test_feet_roll_with_a_side_slope(empty_scene: Any, monkeypatch: Any, name: str) -> None:
    """Across a 12° side slope (the ground tilted about the walking direction) a human's
    feet roll with the ground under their width as they pitch with it along their length:
    pitched only, the downhill edge of their soles stood 5.7 mm in the ground (now 0.01)."""
    obj = FIXTURES[name].build(empty_scene, name)
    rolls = _spy_rolls(monkeypatch)
    _job, m = walk(obj, ground=_side_slope(obj, 12.0))
    check_motion(m, name)
    # the planted feet rolled about as far as the ground falls across them
    turn = np.concatenate([r for r in rolls if r is not None])
    roll = np.degrees(np.arccos(np.clip(turn[..., 2, 2], -1.0, 1.0)))
    assert 10.0 < float(roll.max()) <= 12.5, float(roll.max())


def test_feet_on_flat_ground_do_not_roll(empty_scene: Any, monkeypatch: Any) -> None:
    """On flat ground no foot rolls: the feet are posed as the pitch alone poses them."""
    obj = FIXTURES["rigify_basic_human"].build(empty_scene, "rigify_basic_human")
    rolls = _spy_rolls(monkeypatch)
    _job, m = walk(obj, ground=_side_slope(obj, 0.0))
    check_motion(m, "rigify_basic_human")
    assert rolls
    assert all(r is None for r in rolls), rolls
