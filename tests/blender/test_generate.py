# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate Locomotion, Detect Legs and Clear Generated Action, through the real operators.

The motion is checked on the posed rig, frame by frame through the depsgraph, against ray
casts into the scene's meshes: independently of the core's own bookkeeping.
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import actions
from procloco_addon.blender.locomotion import generate
from procloco_addon.core import gait as core_gait
from tests.blender.scene_state import snapshot
from tools.examples import creatures

pytestmark = pytest.mark.blender


def _ground(size: float = 6.0, name: str = "Ground") -> Any:
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, 0.0))
    obj = bpy.context.active_object
    obj.name = name
    return obj


def _select_only(obj: Any) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def _short_range(obj: Any, start: int = 1, end: int = 12) -> None:
    obj.procloco.use_scene_range = False
    obj.procloco.frame_start = start
    obj.procloco.frame_end = end


# ---------------------------------------------------------------------------------------
# Detect Legs


def test_detect_legs_fills_the_legs_list_with_a_matching_gait(empty_scene: Any) -> None:
    wolf = creatures.build_wolf(empty_scene)
    _select_only(wolf)
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    legs = wolf.procloco.legs
    assert [(leg.label, leg.hip, leg.end) for leg in legs] == [
        ("L1", "front_thigh.L", "front_foot.L"), ("R1", "front_thigh.R", "front_foot.R"),
        ("L2", "thigh.L", "foot.L"), ("R2", "thigh.R", "foot.R")]
    walk = core_gait.find_gait_preset("quadruped_walk").gait(["L1", "R1", "L2", "R2"])
    assert np.allclose([leg.swing_start for leg in legs], walk.swing_start)
    assert np.allclose([leg.swing_duration for leg in legs], walk.swing_duration)
    assert wolf.procloco.cycle_time == pytest.approx(walk.cycle_time)
    # Detecting again keeps the user's edits of existing legs.
    legs[0].swing_start = 0.33
    legs[2].offset = (0.05, -0.02)
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    assert wolf.procloco.legs[0].swing_start == pytest.approx(0.33)
    assert tuple(wolf.procloco.legs[2].offset) == pytest.approx((0.05, -0.02))


def test_detect_legs_refuses_a_rig_without_legs(empty_scene: Any) -> None:
    arm = bpy.data.armatures.new("Stick")
    obj = bpy.data.objects.new("Stick", arm)
    empty_scene.collection.objects.link(obj)
    _select_only(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    b = arm.edit_bones.new("Bone")
    b.head, b.tail = (0, 0, 0), (0, 0, 1)
    bpy.ops.object.mode_set(mode="OBJECT")
    before = snapshot()
    with pytest.raises(RuntimeError, match="No legs found on 'Stick'"):
        bpy.ops.procloco.detect_legs()
    assert snapshot() == before


def test_default_gait_falls_back_to_a_wave() -> None:
    gait = generate.default_gait(["L1", "R1", "L2", "R2", "L3", "R3", "L4"])
    assert gait.n_legs == 7
    # One foot up at a time: never all feet in the air.
    phases = np.linspace(0.0, 1.0, 500, endpoint=False)
    assert int(gait.in_swing(phases).sum(axis=1).max()) == 1


# ---------------------------------------------------------------------------------------
# Bad input: a clear message and nothing changed


@pytest.fixture
def wolf_scene(empty_scene: Any) -> Any:
    _ground()
    wolf = creatures.build_wolf(empty_scene)
    _select_only(wolf)
    _short_range(wolf)
    return wolf


def _refused(match: str) -> None:
    before = snapshot()
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.procloco.generate_locomotion()
    assert snapshot() == before


def test_refuses_a_non_armature(wolf_scene: Any) -> None:
    _select_only(bpy.data.objects["Ground"])
    before = snapshot()
    with pytest.raises(RuntimeError, match="Select an armature"):
        bpy.ops.procloco.generate_locomotion()
    assert snapshot() == before


def test_refuses_a_hip_that_is_not_an_ancestor(wolf_scene: Any) -> None:
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    leg = wolf_scene.procloco.legs[0]
    leg.hip, leg.end = leg.end, leg.hip
    _refused("is not an ancestor of end-effector")


def test_refuses_a_zero_length_segment(wolf_scene: Any) -> None:
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    # spine.003 starts where its parent spine.004 starts: the chain's first segment has no length.
    leg = wolf_scene.procloco.legs[0]
    leg.hip, leg.end = "spine.004", "spine.003"
    _refused("zero.length")


def test_refuses_when_no_ground_mesh(empty_scene: Any) -> None:
    wolf = creatures.build_wolf(empty_scene)
    _select_only(wolf)
    _short_range(wolf)
    _refused("No ground mesh found")


def test_refuses_when_no_ground_under_the_creature(empty_scene: Any) -> None:
    ground = _ground(size=2.0)
    ground.location = (10.0, 0.0, 0.0)
    wolf = creatures.build_wolf(empty_scene)
    _select_only(wolf)
    _short_range(wolf)
    _refused("No ground under 'Wolf'")


def test_refuses_an_empty_path(wolf_scene: Any) -> None:
    curve = bpy.data.curves.new("Empty", "CURVE")
    path = bpy.data.objects.new("EmptyPath", curve)
    bpy.context.scene.collection.objects.link(path)
    wolf_scene.procloco.path = path
    _refused("Path 'EmptyPath' is empty")


@pytest.mark.parametrize(("start", "end"), [(20, 10), (10, 10)])
def test_refuses_an_empty_or_reversed_frame_range(wolf_scene: Any, start: int, end: int) -> None:
    _short_range(wolf_scene, start, end)
    _refused("frame range of 'Wolf' is empty or reversed")


@pytest.mark.parametrize(("duration", "kind"), [(0.0, "zero"), (1.0, "full-cycle")])
def test_refuses_a_zero_or_full_cycle_swing(wolf_scene: Any, duration: float, kind: str) -> None:
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    wolf_scene.procloco.legs[2].swing_duration = duration
    _refused(f"Leg L2 of 'Wolf' has a {kind} swing")


def test_refuses_when_every_leg_is_disabled(wolf_scene: Any) -> None:
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    for leg in wolf_scene.procloco.legs:
        leg.enabled = False
    _refused("Every leg of 'Wolf' is disabled")


def test_one_bad_rig_among_selected_rigs_changes_nothing(wolf_scene: Any) -> None:
    other = creatures.build_robot(bpy.context.scene, name="Robot", location=(2.0, 0.0, 0.0))
    _short_range(other, 30, 5)
    other.select_set(True)
    _refused("frame range of 'Robot' is empty or reversed")


# ---------------------------------------------------------------------------------------
# Clear Generated Action


def test_clear_refuses_a_user_action(wolf_scene: Any) -> None:
    wolf_scene.pose.bones["spine.004"].keyframe_insert("location", frame=1)
    before = snapshot()
    with pytest.raises(RuntimeError, match="not generated by ProcLoco"):
        bpy.ops.procloco.clear_generated_action()
    assert snapshot() == before


def test_clear_restores_the_user_action(wolf_scene: Any) -> None:
    pb = wolf_scene.pose.bones["spine.004"]
    pb.keyframe_insert("location", frame=1)
    user = wolf_scene.animation_data.action
    gen = actions.new_action(wolf_scene)
    actions.write_pose_bone_transforms(gen, wolf_scene, np.array([1.0, 2.0]), ["spine.004"],
                                       locations=np.ones((2, 1, 3)))
    actions.assign_generated_action(wolf_scene, gen)
    assert bpy.ops.procloco.clear_generated_action() == {"FINISHED"}
    assert wolf_scene.animation_data.action == user


# ---------------------------------------------------------------------------------------
# Panels (drawn into a recording layout: a real UILayout cannot exist headless)


def test_rig_and_locomotion_panels(wolf_scene: Any) -> None:
    from procloco_addon.blender.locomotion import panel, ui_list
    from tests.blender.ui_recorder import draw_panel, draw_ui_list_item

    ui = draw_panel(panel.PROCLOCO_PT_rig_legs)
    assert ui.has_operator("procloco.detect_legs")
    assert "detect them to edit" in ui.texts()
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    ui = draw_panel(panel.PROCLOCO_PT_rig_legs)
    assert ui.find("template_list")
    for name in ("hip", "end", "offset", "label"):
        assert ui.has_prop(name), name
    row = draw_ui_list_item(ui_list.PROCLOCO_UL_legs, wolf_scene.procloco, wolf_scene.procloco.legs[0])
    assert "front_thigh.L > front_foot.L" in row.texts()
    ui = draw_panel(panel.PROCLOCO_PT_locomotion)
    for name in ("speed", "heading", "path", "step_height", "spacing", "frame_start", "frame_end", "seed"):
        assert ui.has_prop(name), name


def test_terrain_panel_shows_the_role_of_a_mesh_and_the_collection_of_a_rig(wolf_scene: Any) -> None:
    from procloco_addon.blender.locomotion import panel
    from tests.blender.ui_recorder import draw_panel

    assert draw_panel(panel.PROCLOCO_PT_terrain).has_prop("terrain_collection")
    _select_only(bpy.data.objects["Ground"])
    assert draw_panel(panel.PROCLOCO_PT_terrain).has_prop("procloco_role")
