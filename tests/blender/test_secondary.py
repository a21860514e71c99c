# SPDX-License-Identifier: GPL-3.0-or-later
"""Secondary motion: chain suggestion and Bake Secondary Motion, through the real operators.

Results are checked on the evaluated rig (depsgraph, world matrices), never by reading back
the keys that were written.
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import actions
from procloco_addon.blender.secondary import bake
from procloco_addon.blender.secondary.panel import PROCLOCO_PT_secondary
from tests.blender.pose_eval import pose_matrices
from tests.blender.scene_state import snapshot
from tests.blender.ui_recorder import draw_panel
from tools.examples import creatures

pytestmark = pytest.mark.blender

TAIL = tuple(f"Tail.{i:03d}" for i in range(1, 9))


def _select_only(obj: Any) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def _frames(scene: Any, start: int, end: int, fps: int = 24) -> list[int]:
    scene.render.fps, scene.render.fps_base = fps, 1.0
    scene.frame_start, scene.frame_end = start, end
    return list(range(start, end + 1))


def _lizard(scene: Any) -> Any:
    lizard = creatures.build_lizard(scene)
    _select_only(lizard)
    return lizard


def _key_object_path(obj: Any, fps: int, seconds: float, step_s: float = 0.25) -> None:
    """Keys on the object's location in seconds: a run that starts, bobs and stops."""
    for t in np.arange(0.0, seconds + 1e-9, step_s):
        x = 0.6 * (t - np.sin(2.0 * t) / 2.0) if t < 2.0 else 0.6 * (2.0 - np.sin(4.0) / 2.0)
        obj.location = (x, 0.05 * np.sin(3.0 * t), 0.04 * np.sin(2 * np.pi * 1.5 * t))
        obj.keyframe_insert("location", frame=1 + round(t * fps))


def _bone_dirs(mats: np.ndarray) -> np.ndarray:
    return mats[..., :3, 1] / np.linalg.norm(mats[..., :3, 1], axis=-1, keepdims=True)


# ---------------------------------------------------------------------------------------
# Suggest Chains


@pytest.mark.parametrize("kind", ["spider", "ant", "lizard", "wolf", "robot", "human"])
def test_suggested_chains_are_the_creatures_appendages(empty_scene: Any, kind: str) -> None:
    obj = getattr(creatures, f"build_{kind}")(empty_scene)
    found = {s.bones for s in bake.suggest_chains(obj)}
    expected = set(creatures.APPENDAGES[kind])
    if kind == "wolf":  # the Rigify wolf's ears are chains too
        expected |= {tuple(f"ear.{s}" + (f".{i:03d}" if i else "") for i in range(5)) for s in "LR"}
    assert found == expected


def test_suggest_operator_fills_the_list_and_keeps_edited_chains(empty_scene: Any) -> None:
    wolf = creatures.build_wolf(empty_scene)
    _select_only(wolf)
    assert bpy.ops.procloco.suggest_secondary_chains() == {"FINISHED"}
    chains = wolf.procloco_secondary.chains
    assert [(c.root, c.tip) for c in chains] == [("spine.003", "spine"), ("ear.L", "ear.L.004"),
                                                 ("ear.R", "ear.R.004")]
    chains[0].settling_time = 1.3
    chains[1].enabled = False
    assert bpy.ops.procloco.suggest_secondary_chains() == {"FINISHED"}
    assert len(chains) == 3
    assert chains[0].settling_time == pytest.approx(1.3)
    assert not chains[1].enabled


def test_suggested_chains_start_with_settings_that_suit_them(empty_scene: Any) -> None:
    ant = creatures.build_ant(empty_scene)
    bake.suggest_into_settings(ant)
    chains = ant.procloco_secondary.chains
    springs = {c.root: (round(c.settling_time, 3), round(c.damping, 3)) for c in chains}
    assert springs == {"Antenna1.L": (0.45, 0.35), "Antenna1.R": (0.45, 0.35), "Petiole": (0.3, 0.8)}


# ---------------------------------------------------------------------------------------
# Bake Secondary Motion


def test_bake_writes_a_new_action_and_keeps_the_source(empty_scene: Any) -> None:
    lizard = _lizard(empty_scene)
    frames = _frames(empty_scene, 1, 49)
    _key_object_path(lizard, 24, 2.0)
    hips = lizard.pose.bones["Hips"]
    for f in (1, 25, 49):  # a hand-keyed body bone, kept as it was
        hips.rotation_quaternion = (np.cos(0.1 * f / 49), 0.0, 0.0, np.sin(0.1 * f / 49))
        hips.keyframe_insert("rotation_quaternion", frame=f)
    source = lizard.animation_data.action
    keys_before = {(c.data_path, c.index): actions.read_channel(source, lizard, c.data_path, c.index)
                   for c in actions.channels_of(source, lizard)}
    bones = ["Hips", *TAIL]
    before = pose_matrices(lizard, frames, bones)

    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    baked = lizard.animation_data.action
    assert baked != source
    assert actions.is_generated(baked)
    # The source is untouched, and remembered as the rig's previous Action.
    assert source.name in bpy.data.actions
    for (path, index), (f0, v0) in keys_before.items():
        f1, v1 = actions.read_channel(source, lizard, path, index)
        assert np.array_equal(f0, f1)
        assert np.array_equal(v0, v1)
    assert actions.previous_action(lizard) == (True, source)

    after = pose_matrices(lizard, frames, bones)
    # The body plays as before; the tail swings, keeping its bones' lengths and its root.
    assert np.abs(after[:, 0] - before[:, 0]).max() < 1e-5
    assert np.abs(after[:, 1, :3, 3] - before[:, 1, :3, 3]).max() < 1e-5
    cosine = np.sum(_bone_dirs(after[:, 1:]) * _bone_dirs(before[:, 1:]), -1)
    swing = np.degrees(np.arccos(np.clip(cosine, -1, 1)))
    assert swing.max() > 3.0
    lengths = np.array([lizard.data.bones[b].length for b in TAIL])
    tails = after[:, 1:, :3, 3] + _bone_dirs(after[:, 1:]) * lengths[None, :, None]
    assert np.abs(tails[:, :-1] - after[:, 2:, :3, 3]).max() < 1e-5  # each bone ends where the next starts


def test_no_perturbation_gives_back_the_source_animation(empty_scene: Any) -> None:
    lizard = _lizard(empty_scene)
    frames = _frames(empty_scene, 1, 37)
    # The body stands still; the tail is animated by hand (a wag).
    for f in (1, 10, 19, 28, 37):
        for i, name in enumerate(TAIL[:4]):
            pb = lizard.pose.bones[name]
            angle = 0.25 * np.sin(f / 6.0 + i)
            pb.rotation_quaternion = (np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2))
            pb.keyframe_insert("rotation_quaternion", frame=f)
    before = pose_matrices(lizard, frames, TAIL)
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    after = pose_matrices(lizard, frames, TAIL)
    assert np.abs(after - before).max() < 1e-6


def test_same_motion_at_24_and_60_fps(empty_scene: Any) -> None:
    poses = {}
    for fps in (24, 60):
        bpy.ops.wm.read_homefile(use_empty=True)
        scene = bpy.context.scene
        lizard = _lizard(scene)
        frames = _frames(scene, 1, 1 + 2 * fps, fps)
        _key_object_path(lizard, fps, 2.0)
        assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
        shared = frames[:: fps // 12]  # every 1/12 s
        poses[fps] = pose_matrices(lizard, shared, TAIL)
    d24, d60 = _bone_dirs(poses[24]), _bone_dirs(poses[60])
    angle = np.arccos(np.clip(np.sum(d24 * d60, -1), -1.0, 1.0))
    swing = np.abs(poses[60][..., :3, 3] - poses[60][:1, :, :3, 3]).max()
    assert swing > 0.1  # the rig really moved
    assert angle.max() < 0.02  # radians
    assert np.abs(poses[24][..., :3, 3] - poses[60][..., :3, 3]).max() < 5e-3


def test_a_body_swaying_in_yaw_bakes_the_same_swing_at_24_and_60_fps(empty_scene: Any) -> None:
    """The object sways ±15° in yaw, the same motion in seconds at both frame rates (a driver):
    the tail lags behind it alike (the turn is interpolated between frames, the springs run at
    their own rate)."""
    poses, rest = {}, {}
    for fps in (24, 60):
        bpy.ops.wm.read_homefile(use_empty=True)
        scene = bpy.context.scene
        lizard = _lizard(scene)
        frames = _frames(scene, 1, 1 + 2 * fps, fps)
        yaw = lizard.driver_add("rotation_euler", 2).driver
        yaw.type = "SCRIPTED"
        t = f"((frame - 1) / {fps})"
        yaw.expression = f"radians(15) * sin(2 * pi * 1.2 * {t}) * min({t}, 1)"
        shared = frames[:: fps // 12]  # every 1/12 s
        rest[fps] = pose_matrices(lizard, shared, TAIL)
        assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
        poses[fps] = pose_matrices(lizard, shared, TAIL)
    cosine = np.sum(_bone_dirs(poses[60]) * _bone_dirs(rest[60]), -1)
    swing = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    d24, d60 = _bone_dirs(poses[24]), _bone_dirs(poses[60])
    angle = np.degrees(np.arccos(np.clip(np.sum(d24 * d60, -1), -1.0, 1.0)))
    assert swing.max() > 5.0  # the tail swings
    assert angle.max() < 0.3  # degrees


def test_rig_without_animation_data_hangs_its_tail_with_gravity(empty_scene: Any) -> None:
    lizard = _lizard(empty_scene)
    frames = _frames(empty_scene, 1, 48)
    assert lizard.animation_data is None
    chain_settings = lizard.procloco_secondary
    assert bpy.ops.procloco.suggest_secondary_chains() == {"FINISHED"}
    chain_settings.chains[0].rest_direction = "GRAVITY"
    chain_settings.chains[0].settling_time = 0.8
    chain_settings.chains[0].damping = 1.0
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    mats = pose_matrices(lizard, frames, TAIL)
    down = -_bone_dirs(mats)[..., 2]  # cosine to straight down
    assert np.all(down[-1] > 0.97)
    assert np.all(down[0] < 0.9)
    assert actions.previous_action(lizard) == (True, None)


def test_chain_of_one_bone_swings_with_the_body(empty_scene: Any) -> None:
    spider = creatures.build_spider(empty_scene)
    _select_only(spider)
    frames = _frames(empty_scene, 1, 49)
    _key_object_path(spider, 24, 2.0)
    settings = spider.procloco_secondary
    item = settings.chains.add()
    item.name, item.root, item.tip = "Abdomen", "Abdomen", "Abdomen"
    item.damping = 0.3
    before = pose_matrices(spider, frames, ["Abdomen"])
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    after = pose_matrices(spider, frames, ["Abdomen"])
    assert np.abs(after[..., :3, 3] - before[..., :3, 3]).max() < 1e-5  # anchored
    assert np.abs(_bone_dirs(after) - _bone_dirs(before)).max() > 0.02


def test_baking_again_replaces_the_secondary_motion(empty_scene: Any) -> None:
    lizard = _lizard(empty_scene)
    frames = _frames(empty_scene, 1, 37)
    _key_object_path(lizard, 24, 1.5)
    source = lizard.animation_data.action
    keys_before = {(c.data_path, c.index): actions.read_channel(source, lizard, c.data_path, c.index)
                   for c in actions.channels_of(source, lizard)}
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    first_name = lizard.animation_data.action.name
    first = pose_matrices(lizard, frames, TAIL)
    for _ in range(3):
        assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    latest = lizard.animation_data.action
    # Baked on the source again, not on the earlier bake: same settings, same motion.
    assert np.abs(pose_matrices(lizard, frames, TAIL) - first).max() < 1e-6
    assert actions.previous_action(lizard) == (True, source)
    # Each bake superseded the one before: one bake is left, under the first one's name, and
    # nothing was given a fake user to clutter the file.
    assert {a.name for a in bpy.data.actions} == {source.name, first_name}
    assert latest.name == first_name
    assert not any(a.use_fake_user for a in bpy.data.actions)
    # The user's Action is untouched.
    for (path, index), (f0, v0) in keys_before.items():
        f1, v1 = actions.read_channel(source, lizard, path, index)
        assert np.array_equal(f0, f1)
        assert np.array_equal(v0, v1)


@pytest.mark.parametrize("kept_by", ["fake_user", "nla", "other_object"])
def test_a_bake_something_else_uses_survives_a_rebake(empty_scene: Any, kept_by: str) -> None:
    lizard = _lizard(empty_scene)
    _frames(empty_scene, 1, 25)
    _key_object_path(lizard, 24, 1.0)
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    first = lizard.animation_data.action
    if kept_by == "fake_user":
        first.use_fake_user = True  # the animator keeps this take
    elif kept_by == "nla":
        actions.push_to_nla(lizard, first)
    else:
        twin = creatures.build_lizard(empty_scene, name="Twin")
        actions.assign_action(twin, first)
        _select_only(lizard)
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    second = lizard.animation_data.action
    assert second != first
    assert first.name in bpy.data.actions
    assert first.use_fake_user  # kept, and reachable even if the strip or the twin goes
    assert second.name != first.name


def test_assign_generated_action_replaces_only_its_own_unused_actions(empty_scene: Any) -> None:
    """The helper itself: ``replace=True`` deletes the object's current Action only when ProcLoco
    generated it and nothing else uses it; the user's own Action is remembered, never deleted."""
    lizard = _lizard(empty_scene)
    own = bpy.data.actions.new("Hand keyed")
    actions.assign_action(lizard, own)
    take1 = actions.new_action(lizard, suffix="Take")
    actions.assign_generated_action(lizard, take1, replace=True)
    assert "Hand keyed" in bpy.data.actions
    assert not own.use_fake_user
    assert actions.previous_action(lizard) == (True, own)
    take2 = actions.new_action(lizard, suffix="Take")
    assert take2.name == f"{lizard.name} Take.001"
    actions.assign_generated_action(lizard, take2, replace=True)
    assert take2.name == f"{lizard.name} Take"  # took over the superseded take's name
    assert {a.name for a in bpy.data.actions} == {"Hand keyed", f"{lizard.name} Take"}
    # Without replace, a superseded generated Action is kept with a fake user, as before.
    take3 = actions.new_action(lizard, suffix="Take")
    actions.assign_generated_action(lizard, take3)
    assert take2.name in bpy.data.actions
    assert take2.use_fake_user
    assert actions.previous_action(lizard) == (True, own)


def test_bake_layers_on_a_generated_action(empty_scene: Any) -> None:
    lizard = _lizard(empty_scene)
    frames = _frames(empty_scene, 1, 25)
    walk = actions.new_action(lizard)
    locations = np.zeros((len(frames), 1, 3))
    locations[:, 0, 1] = 0.1 * np.sin(np.arange(len(frames)) / 4.0)  # the hips shuffle back and forth
    actions.write_pose_bone_transforms(walk, lizard, np.array(frames, float), ["Hips"], locations=locations)
    actions.assign_generated_action(lizard, walk)
    walking = pose_matrices(lizard, frames, ["Hips", "Tail.008"])
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    baked = lizard.animation_data.action
    assert baked != walk
    assert walk.use_fake_user  # the generated walk stays reachable
    assert actions.previous_action(lizard) == (True, None)  # Clear goes back to no Action
    after = pose_matrices(lizard, frames, ["Hips", "Tail.008"])
    assert np.abs(walking[:, 0, :3, 3] - walking[0, 0, :3, 3]).max() > 0.05  # the walk moves the hips
    assert np.abs(after[:, 0] - walking[:, 0]).max() < 1e-5  # and still does
    assert np.abs(after[:, 1] - walking[:, 1]).max() > 1e-3  # the tail tip swings
    # Baking again supersedes the bake, never the walk it was baked on.
    baked_name = baked.name
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    assert {a.name for a in bpy.data.actions} == {walk.name, baked_name}
    assert lizard.animation_data.action[bake.SECONDARY_SOURCE] == walk


def test_a_lizard_walking_with_visual_yaw_swings_its_tail_behind_its_hips(empty_scene: Any) -> None:
    """Generate Locomotion with visual yaw sways the lizard's hips (and the tail they carry) by
    about ±9° at each step; baking secondary motion lets the tail lag behind that sway."""
    _frames(empty_scene, 1, 72)
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    lizard = _lizard(empty_scene)
    lizard.procloco.use_visual_yaw = True
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    frames = list(range(1, 73))
    bones = ["Hips", *TAIL]
    walking = pose_matrices(lizard, frames, bones)
    hips_yaw = np.degrees(np.arctan2(walking[:, 0, 1, 1], walking[:, 0, 0, 1]))
    assert np.ptp(hips_yaw[24:]) > 10.0  # the hips really sway
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    baked = pose_matrices(lizard, frames, bones)
    lengths = np.array([lizard.data.bones[b].length for b in TAIL])

    def tip_from_root(mats: np.ndarray) -> np.ndarray:
        tips = mats[:, -1, :3, 3] + _bone_dirs(mats[:, -1]) * lengths[-1]
        return tips - mats[:, 1, :3, 3]

    a, b = tip_from_root(walking), tip_from_root(baked)
    cosine = np.sum(a * b, -1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
    swing = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    assert swing.max() > 5.0  # several degrees (a rigidly carried tail: under 1.1°)
    # The hips play as generated; the tail stays attached and keeps its bones' lengths.
    assert np.abs(baked[:, 0] - walking[:, 0]).max() < 1e-5
    assert np.abs(baked[:, 1, :3, 3] - walking[:, 1, :3, 3]).max() < 1e-5
    ends = baked[:, 1:, :3, 3] + _bone_dirs(baked[:, 1:]) * lengths[None, :, None]
    assert np.abs(ends[:, :-1] - baked[:, 2:, :3, 3]).max() < 1e-5


# ---------------------------------------------------------------------------------------
# Refusals and cancelling change nothing


def _bad(obj: Any, how: str, scene: Any) -> str:
    settings = obj.procloco_secondary
    bpy.ops.procloco.suggest_secondary_chains()
    chain = settings.chains[0]
    if how == "reversed":  # the rig's own range (the scene's cannot be reversed)
        obj.procloco.use_scene_range = False
        obj.procloco.frame_start, obj.procloco.frame_end = 20, 10
        return "is reversed \\(20 to 10\\)"
    if how == "not_ancestor":
        chain.root, chain.tip = "Tail.004", "Tail.002"
        return "not an ancestor"
    if how == "missing":
        chain.tip = "Nope"
        return "has no bone 'Nope'"
    if how == "twice":
        extra = settings.chains.add()
        extra.root, extra.tip = "Tail.003", "Tail.005"
        return "in two chains"
    if how == "disabled":
        for c in settings.chains:
            c.enabled = False
        return "disabled"
    raise AssertionError(how)


@pytest.mark.parametrize("how", ["reversed", "not_ancestor", "missing", "twice", "disabled"])
def test_bad_input_is_refused_and_changes_nothing(empty_scene: Any, how: str) -> None:
    lizard = _lizard(empty_scene)
    _frames(empty_scene, 1, 24)
    _key_object_path(lizard, 24, 1.0)
    message = _bad(lizard, how, empty_scene)
    before = snapshot()
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.procloco.bake_secondary_motion()
    assert snapshot() == before


def test_zero_length_bone_is_refused(empty_scene: Any) -> None:
    arm = bpy.data.armatures.new("Whip")
    obj = bpy.data.objects.new("Whip", arm)
    empty_scene.collection.objects.link(obj)
    _select_only(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    handle = arm.edit_bones.new("Handle")
    handle.head, handle.tail = (0, 0, 1), (0, 0, 0.5)
    dot = arm.edit_bones.new("Dot")  # 20 µm: as good as zero next to a 0.5 m handle
    dot.head, dot.tail = (0, 0, 0.5), (0, 0, 0.49998)
    dot.parent = handle
    bpy.ops.object.mode_set(mode="OBJECT")
    chain = obj.procloco_secondary.chains.add()
    chain.root, chain.tip = "Handle", "Dot"
    before = snapshot()
    with pytest.raises(RuntimeError, match="bone 'Dot' has zero length"):
        bpy.ops.procloco.bake_secondary_motion()
    assert snapshot() == before


def test_not_an_armature_is_refused_by_poll(empty_scene: Any) -> None:
    bpy.ops.mesh.primitive_cube_add()
    assert not bpy.ops.procloco.bake_secondary_motion.poll()
    with pytest.raises(RuntimeError, match="Select an armature"):
        bpy.ops.procloco.bake_secondary_motion()


@pytest.mark.parametrize("rebake", [False, True])
def test_cancel_midway_leaves_the_scene_unchanged(empty_scene: Any, rebake: bool) -> None:
    lizard = _lizard(empty_scene)
    _frames(empty_scene, 1, 30)
    _key_object_path(lizard, 24, 1.2)
    empty_scene.frame_set(7)
    if rebake:  # the rig's Action is set aside while its source is played
        assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    bake.suggest_into_settings(lizard)
    before = snapshot()
    job = bake.prepare(bpy.context, lizard)
    steps = bake.sample(bpy.context, job)
    for _ in range(10):
        next(steps)
    assert empty_scene.frame_current != 7
    steps.close()  # what Esc does in the modal operator
    bake.cancel(bpy.context, job)
    assert snapshot() == before


# ---------------------------------------------------------------------------------------
# Panel


def test_panel_shows_the_chain_settings_and_the_bake_button(empty_scene: Any) -> None:
    wolf = creatures.build_wolf(empty_scene)
    _select_only(wolf)
    ui = draw_panel(PROCLOCO_PT_secondary, bpy.context)
    assert ui.has_operator("procloco.suggest_secondary_chains")
    assert "No chains yet: suggest them, or add one" in ui.texts()
    bake.suggest_into_settings(wolf)
    ui = draw_panel(PROCLOCO_PT_secondary, bpy.context)
    for prop in ("settling_time", "damping", "rest_direction", "influence", "root", "tip", "use_reaction"):
        assert ui.has_prop(prop), prop
    assert ui.has_operator("procloco.bake_secondary_motion")
    assert ui.has_operator("procloco.add_secondary_chain")
    assert ui.has_operator("procloco.remove_secondary_chain")
