# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait presets from the panel: list, apply, save, remove; bad files change nothing.

Runs the real operators on a small armature whose legs were detected by ``rig`` (the
way the Detect Legs button fills ``Object.procloco.legs``). User presets go to the user
scripts folder, which the test session points into a temporary folder.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender.gait import ops, presets
from procloco_addon.core.locomotion import gait as core_gait
from tests.blender.ui_recorder import draw_menu

SHIPPED = core_gait.gait_preset_dir()


def make_rig(scene: Any, n_pairs: int = 2, name: str = "Rig", *, detect: bool = True) -> Any:
    """An armature with a body bone and ``n_pairs`` pairs of two-bone legs (0.25 m thigh
    drop, 0.1·x out, 0.25 m shin), facing −Y, legs filled in ``procloco.legs`` when ``detect``."""
    from procloco_addon.blender import rig

    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    body = arm.edit_bones.new("body")
    body.head, body.tail = (0.0, 0.5, 0.5), (0.0, -0.5, 0.5)
    for row in range(n_pairs):
        y = -0.4 + 0.8 * row / max(n_pairs - 1, 1)
        for side, x in (("L", 0.2), ("R", -0.2)):
            upper = arm.edit_bones.new(f"Leg{row + 1}_upper.{side}")
            upper.head, upper.tail, upper.parent = (x, y, 0.5), (1.5 * x, y, 0.25), body
            lower = arm.edit_bones.new(f"Leg{row + 1}_lower.{side}")
            lower.head, lower.tail, lower.parent = upper.tail, (1.5 * x, y, 0.0), upper
            lower.use_connect = True
    bpy.ops.object.mode_set(mode="OBJECT")
    if detect:
        for leg in rig.detect_legs(obj):
            item = obj.procloco.legs.add()
            item.name = item.label = leg.label
            item.hip, item.end = leg.bones[0], leg.bones[-1]
    return obj


RIG_LEG_LENGTH = math.hypot(0.1, 0.25) + 0.25  # every leg of make_rig


def gait_state(obj: Any) -> dict[str, Any]:
    """Everything a preset sets on the rig, as stored (float32 values, exactly)."""
    s = obj.procloco
    return {
        "start": [leg.swing_start for leg in s.legs],
        "duration": [leg.swing_duration for leg in s.legs],
        "cycle_time": s.cycle_time,
        "speed": s.speed,
        "step_height": s.step_height,
        "gait_preset": s.gait_preset,
    }


@pytest.fixture
def rig(empty_scene: Any) -> Any:
    folder = presets.user_dir()
    if folder is not None and folder.is_dir():
        for path in folder.glob("*.json"):
            path.unlink()
    return make_rig(empty_scene)


def test_shipped_presets_are_listed_with_their_names(rig: Any) -> None:
    ui = draw_menu(ops.PROCLOCO_MT_gait_presets)
    applied = {Path(c.operator_properties["filepath"]).name: c.text
               for c in ui.operator_calls("procloco.apply_gait_preset")}
    for path in core_gait.list_gait_presets():
        assert applied[path.name] == core_gait.load_gait_preset(path).name
    assert not ui.operator_calls("procloco.remove_gait_preset")  # shipped ones cannot be removed
    assert ui.has_operator("procloco.add_gait_preset")


def test_applying_a_preset_sets_the_rig_gait(rig: Any) -> None:
    preset = core_gait.load_gait_preset(SHIPPED / "quadruped_trot.json")
    assert bpy.ops.procloco.apply_gait_preset(filepath=str(preset.path)) == {"FINISHED"}
    s = rig.procloco
    for leg in s.legs:
        i = preset.legs.index(leg.label)  # matched by label, not by order
        assert leg.swing_start == pytest.approx(preset.swing_start[i], abs=1e-6)
        assert leg.swing_duration == pytest.approx(preset.swing_duration[i], abs=1e-6)
    assert s.cycle_time == pytest.approx(preset.cycle_time)
    assert s.gait_preset == preset.name
    # Preset speeds and heights are in leg lengths; the rig's legs are RIG_LEG_LENGTH long.
    assert s.speed == pytest.approx(preset.speed * RIG_LEG_LENGTH, rel=1e-5)
    assert s.step_height == pytest.approx(preset.step_height * RIG_LEG_LENGTH, rel=1e-5)


def test_save_load_another_load_back_gives_identical_settings(rig: Any) -> None:
    s = rig.procloco
    for leg, start, duration in zip(s.legs, [0.07, 0.61, 0.93, 0.33], [0.31, 0.27, 0.5, 0.44], strict=True):
        leg.swing_start, leg.swing_duration = start, duration
    s.cycle_time, s.speed, s.step_height = 0.83, 1.37, 0.061
    mine = gait_state(rig)

    assert bpy.ops.procloco.add_gait_preset(name="My Odd Trot", source="test") == {"FINISHED"}
    saved = presets.user_dir() / "my_odd_trot.json"
    data = json.loads(saved.read_text())
    assert data["name"] == "My Odd Trot"
    assert data["legs"] == ["L1", "R1", "L2", "R2"]
    assert data["speed"] == pytest.approx(1.37 / RIG_LEG_LENGTH, rel=1e-6)  # stored in leg lengths

    bpy.ops.procloco.apply_gait_preset(filepath=str(SHIPPED / "quadruped_walk.json"))
    assert gait_state(rig) != mine
    assert bpy.ops.procloco.apply_gait_preset(filepath=str(saved)) == {"FINISHED"}
    mine["gait_preset"] = "My Odd Trot"
    assert gait_state(rig) == mine  # exactly the same stored values

    ui = draw_menu(ops.PROCLOCO_MT_gait_presets)
    remove = ui.operator_calls("procloco.remove_gait_preset")
    assert [c.operator_properties["filepath"] for c in remove] == [str(saved)]


BAD_PRESETS = {
    "not_json.json": ("{ this is not json", "not valid JSON"),
    "missing.json": (json.dumps({"format": "procloco.gait/1", "name": "x"}), "missing field"),
    "full_swing.json": (None, "swing_duration"),
    "six_legs.json": ("hexapod", "is for legs"),
}


@pytest.mark.parametrize("name", sorted(BAD_PRESETS))
def test_bad_preset_gives_a_clear_message_and_changes_nothing(rig: Any, tmp_path: Path, name: str) -> None:
    text, message = BAD_PRESETS[name]
    good = json.loads((SHIPPED / "quadruped_trot.json").read_text())
    if text is None:
        good["swing_duration"][2] = 1.0
        text = json.dumps(good)
    elif text == "hexapod":
        text = (SHIPPED / "hexapod_tripod.json").read_text()
    path = tmp_path / name
    path.write_text(text)
    before = gait_state(rig)
    with pytest.raises(RuntimeError, match=message) as error:
        bpy.ops.procloco.apply_gait_preset(filepath=str(path))
    assert "nothing was changed" in str(error.value)
    assert gait_state(rig) == before


def test_saving_an_invalid_gait_is_refused(rig: Any) -> None:
    rig.procloco.legs[1].swing_duration = 0.0
    with pytest.raises(RuntimeError, match="zero or full-cycle swing"):
        bpy.ops.procloco.add_gait_preset(name="Broken")
    folder = presets.user_dir()
    assert folder is None or not any(folder.glob("*.json"))


def test_removing_presets(rig: Any) -> None:
    assert not bpy.ops.procloco.remove_gait_preset.poll()  # nothing of the user's yet
    bpy.ops.procloco.add_gait_preset(name="Keep Me")
    bpy.ops.procloco.add_gait_preset(name="Drop Me")
    folder = presets.user_dir()
    with pytest.raises(RuntimeError, match="shipped presets cannot be removed"):
        bpy.ops.procloco.remove_gait_preset(filepath=str(SHIPPED / "quadruped_trot.json"))
    assert (SHIPPED / "quadruped_trot.json").is_file()
    assert bpy.ops.procloco.remove_gait_preset(filepath=str(folder / "drop_me.json")) == {"FINISHED"}
    assert sorted(p.name for p in folder.glob("*.json")) == ["keep_me.json"]
    with pytest.raises(RuntimeError, match="No gait preset file"):
        bpy.ops.procloco.remove_gait_preset(filepath=str(folder / "drop_me.json"))


def test_operators_explain_why_they_are_disabled(empty_scene: Any) -> None:
    with pytest.raises(RuntimeError, match="Select an armature"):
        bpy.ops.procloco.apply_gait_preset(filepath=str(SHIPPED / "quadruped_trot.json"))
    make_rig(empty_scene, detect=False)
    with pytest.raises(RuntimeError, match="no legs yet"):
        bpy.ops.procloco.add_gait_preset(name="x")


def test_preset_with_other_leg_labels_maps_by_label(rig: Any, tmp_path: Path) -> None:
    data = json.loads((SHIPPED / "quadruped_trot.json").read_text())
    order = np.array([3, 2, 1, 0])  # same legs listed back to front
    for key in ("legs", "swing_start", "swing_duration"):
        data[key] = [data[key][i] for i in order]
    path = tmp_path / "reversed.json"
    path.write_text(json.dumps(data))
    bpy.ops.procloco.apply_gait_preset(filepath=str(SHIPPED / "quadruped_trot.json"))
    expected = gait_state(rig)
    bpy.ops.procloco.apply_gait_preset(filepath=str(SHIPPED / "quadruped_walk.json"))
    bpy.ops.procloco.apply_gait_preset(filepath=str(path))
    got = gait_state(rig)
    assert got["start"] == expected["start"]
    assert got["duration"] == expected["duration"]
