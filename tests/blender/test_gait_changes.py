# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait changes over the generated frames: Add/Remove Gait Change, the Gait Changes panel
and menu, and what Generate Locomotion makes of them, checked on the evaluated rig."""

from __future__ import annotations

import json
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender.gait import ops as gait_ops
from procloco_addon.blender.gait import panel as gait_panel
from procloco_addon.blender.locomotion import generate
from procloco_addon.core.locomotion import gait as core_gait
from tests.blender.pose_eval import leg_joints
from tests.blender.scene_state import snapshot
from tests.blender.test_gait_presets import SHIPPED, make_rig
from tests.blender.test_generate import _ground, _select_only, _short_range
from tests.blender.ui_recorder import draw_menu, draw_panel
from tools.examples import creatures

pytestmark = pytest.mark.blender

TROT = SHIPPED / "quadruped_trot.json"


@pytest.fixture
def wolf(empty_scene: Any) -> Any:
    _ground(size=30.0)
    obj = creatures.build_wolf(empty_scene)
    _select_only(obj)
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    obj.procloco.gait_mode = "CIRCLES"  # the gait changes' gaits (Auto would use only their speeds)
    return obj


def _moving_feet(obj: Any, frames: list[int]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Per frame step, which feet moved more than 1 mm (swinging), and the feet's mean
    position per frame, from the evaluated pose."""
    job = generate.prepare(bpy.context, obj)
    joints = leg_joints(obj, frames, [leg.bones for leg in job.info.legs])
    ends = np.stack([j[:, -1] for j in joints], axis=1)
    moving = np.linalg.norm(np.diff(ends, axis=0), axis=2) > 1e-3
    return moving, ends.mean(axis=1), [leg.label for leg in job.info.legs]


def test_a_walk_changes_into_a_trot_and_its_speed_at_the_frame_given(wolf: Any) -> None:
    scene = bpy.context.scene
    _short_range(wolf, 1, 160)
    scene.frame_set(60)
    assert bpy.ops.procloco.add_gait_change(filepath=str(TROT)) == {"FINISHED"}
    change = wolf.procloco.gait_changes[0]
    assert (change.name, change.frame) == ("Quadruped trot", 60)
    trot = core_gait.load_gait_preset(TROT)
    assert change.transition_time == pytest.approx(0.5 * trot.cycle_time)
    walk_speed, trot_speed = wolf.procloco.speed, change.speed
    assert trot_speed > 1.2 * walk_speed  # the preset's speed, scaled to the wolf's legs
    circles = [(leg.swing_start, leg.swing_duration) for leg in wolf.procloco.legs]
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    # the gait circles are the walk the creature starts with: untouched
    assert [(leg.swing_start, leg.swing_duration) for leg in wolf.procloco.legs] == circles

    fps = scene.render.fps / scene.render.fps_base
    moving, centre, labels = _moving_feet(wolf, list(range(1, 161)))
    l1, r1, l2, r2 = (labels.index(k) for k in ("L1", "R1", "L2", "R2"))

    def diagonal_agreement(a: int, b: int) -> float:
        m = moving[a:b]
        return float(np.mean(np.r_[m[:, l1] == m[:, r2], m[:, r1] == m[:, l2]]))

    # Walking, diagonal feet lift at different times; trotting, together.
    assert diagonal_agreement(5, 55) < 0.7
    assert diagonal_agreement(100, 158) > 0.95
    speed = np.linalg.norm(np.diff(centre[:, :2], axis=0), axis=1) * fps
    assert speed[10:55].mean() == pytest.approx(walk_speed, rel=0.1)
    assert speed[110:158].mean() == pytest.approx(trot_speed, rel=0.1)


def test_a_change_at_the_first_frame_is_the_gait_the_walk_starts_with(wolf: Any) -> None:
    _short_range(wolf, 1, 60)
    bpy.context.scene.frame_set(1)
    assert bpy.ops.procloco.add_gait_change(filepath=str(TROT)) == {"FINISHED"}
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    moving, _, labels = _moving_feet(wolf, list(range(1, 61)))
    l1, r2 = labels.index("L1"), labels.index("R2")
    assert float(np.mean(moving[5:, l1] == moving[5:, r2])) > 0.95


def test_current_circles_are_stored_and_the_list_stays_in_frame_order(wolf: Any) -> None:
    scene = bpy.context.scene
    wolf.procloco.legs[0].swing_start = 0.3
    scene.frame_set(80)
    assert bpy.ops.procloco.add_gait_change() == {"FINISHED"}
    scene.frame_set(20)
    assert bpy.ops.procloco.add_gait_change(filepath=str(TROT)) == {"FINISHED"}
    changes = wolf.procloco.gait_changes
    assert [c.frame for c in changes] == [20, 80]
    assert changes[wolf.procloco.active_gait_change_index].frame == 20  # the one just added
    stored = json.loads(changes[1].gait)
    assert stored["swing_start"][stored["legs"].index("L1")] == pytest.approx(0.3)
    assert changes[1].speed == pytest.approx(wolf.procloco.speed)
    # editing the circles afterwards does not change what was stored
    wolf.procloco.legs[0].swing_start = 0.6
    assert json.loads(changes[1].gait) == stored
    wolf.procloco.active_gait_change_index = 0
    assert bpy.ops.procloco.remove_gait_change() == {"FINISHED"}
    assert [c.frame for c in changes] == [80]


def test_a_preset_for_other_legs_is_refused_and_nothing_changes(wolf: Any) -> None:
    before = snapshot()
    with pytest.raises(RuntimeError, match="Cannot change to this gait"):
        bpy.ops.procloco.add_gait_change(filepath=str(SHIPPED / "hexapod_tripod.json"))
    assert snapshot() == before
    assert len(wolf.procloco.gait_changes) == 0


def test_a_damaged_gait_change_is_refused_by_generate_and_nothing_changes(wolf: Any) -> None:
    _short_range(wolf, 1, 12)
    bpy.context.scene.frame_set(5)
    assert bpy.ops.procloco.add_gait_change(filepath=str(TROT)) == {"FINISHED"}
    wolf.procloco.gait_changes[0].gait = "{not json"
    before = snapshot()
    message = r"Gait change 1 of 'Wolf' \(Quadruped trot at frame 5\) cannot be used"
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.procloco.generate_locomotion()
    assert snapshot() == before


def test_a_change_after_the_last_frame_is_left_out_with_a_warning(wolf: Any) -> None:
    _short_range(wolf, 1, 12)
    bpy.context.scene.frame_set(40)
    assert bpy.ops.procloco.add_gait_change(filepath=str(TROT)) == {"FINISHED"}
    job = generate.prepare(bpy.context, wolf)
    assert job.gait_changes == ()
    assert any("after the last frame" in w for w in job.warnings)


def test_gait_changes_panel_and_menu(empty_scene: Any) -> None:
    obj = make_rig(empty_scene, n_pairs=2)
    ui = draw_panel(gait_panel.PROCLOCO_PT_gait_changes)
    assert ui.menus() == ["PROCLOCO_MT_add_gait_change"]
    assert ui.has_operator("procloco.remove_gait_change")
    assert not ui.has_prop("frame")  # nothing selected yet
    menu = draw_menu(gait_ops.PROCLOCO_MT_add_gait_change)
    calls = menu.operator_calls("procloco.add_gait_change")
    assert calls[0].text == "Current Gait Circles"
    assert "Quadruped trot" in [c.text for c in calls]
    assert bpy.ops.procloco.add_gait_change(filepath=str(TROT)) == {"FINISHED"}
    ui = draw_panel(gait_panel.PROCLOCO_PT_gait_changes)
    item = obj.procloco.gait_changes[0]
    for name in ("frame", "transition_time", "use_speed", "speed"):
        assert ui.has_prop(name, data=item), name


def test_the_gait_panel_says_which_change_rules_the_current_frame(empty_scene: Any) -> None:
    make_rig(empty_scene, n_pairs=2)
    empty_scene.frame_set(30)
    assert bpy.ops.procloco.add_gait_change(filepath=str(TROT)) == {"FINISHED"}
    empty_scene.frame_set(10)
    assert not any("From frame" in t for t in draw_panel(gait_panel.PROCLOCO_PT_gait).labels())
    empty_scene.frame_set(45)
    assert "From frame 30: Quadruped trot (Gait Changes)" in draw_panel(gait_panel.PROCLOCO_PT_gait).labels()
