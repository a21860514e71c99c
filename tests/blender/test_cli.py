# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/cli.py: the batch command, called in-process (the bpy module has no ``--command``;
Blender's binary calls the same ``main`` through ``register_cli_command``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import actions, cli
from procloco_addon.blender.cli import image_pixels
from tests.blender.scene_state import snapshot
from tests.blender_free.test_gif import decode as decode_gif
from tools.examples import creatures

pytestmark = pytest.mark.blender


@pytest.fixture
def robot_scene(empty_scene: Any) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    robot = creatures.build_robot(empty_scene)
    empty_scene.frame_start, empty_scene.frame_end = 1, 10
    return robot


def test_generate_renders_frames_and_a_contact_sheet(robot_scene: Any, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "frames"
    sheet = tmp_path / "sheet.png"
    saved = tmp_path / "walk.blend"
    gif = tmp_path / "walk.gif"
    status = cli.main(["generate", "--rig", "Robot", "--frame-step", "3", "--resolution", "96", "54",
                       "--render", str(out), "--contact-sheet", str(sheet), "--gif", str(gif),
                       "--save", str(saved)])
    assert status == 0
    printed = capsys.readouterr().out
    assert "ProcLoco:   Robot: 100%" in printed
    assert "wrote Action 'Robot ProcLoco'" in printed
    files = sorted(out.glob("frame_*.png"))
    assert [f.name for f in files] == ["frame_0001.png", "frame_0004.png", "frame_0007.png", "frame_0010.png"]
    first, last = image_pixels(files[0]), image_pixels(files[-1])
    assert first.shape == (54, 96, 4)
    assert np.abs(first - last).max() > 0.05, "the robot moved between the first and the last frame"
    assert image_pixels(sheet).shape == (54, 4 * 96, 4)  # four tiles in one row
    # The GIF loops the four frames in real time (3 frames at 24 fps each) and shows them.
    shown = decode_gif(gif.read_bytes())
    assert shown["size"] == (96, 54)
    assert shown["loop"]
    assert shown["delays"] == [12] * 4
    for png, frame in zip(files, shown["frames"], strict=True):
        want = np.clip(image_pixels(png)[::-1, :, :3], 0.0, 1.0) * 255.0
        assert np.abs(frame - want).mean() < 6.0
    assert saved.exists()
    assert robot_scene.animation_data.action.name == "Robot ProcLoco"
    # The scene's render settings and camera are left as they were.
    assert bpy.context.scene.camera is None
    assert "ProcLoco Preview" not in bpy.data.objects


def test_settings_are_overridden_from_the_command_line(robot_scene: Any) -> None:
    argv = ["generate", "--rig", "Robot", "--frames", "3", "8", "--speed", "0.2", "--seed", "4"]
    assert cli.main(argv) == 0
    s = robot_scene.procloco
    assert (s.use_scene_range, s.frame_start, s.frame_end) == (False, 3, 8)
    assert s.speed == pytest.approx(0.2)
    assert s.seed == 4
    action = robot_scene.animation_data.action
    keys = actions.read_channel(action, robot_scene, 'pose.bones["Body"].location', 1)
    assert keys is not None
    assert keys[0].tolist() == [3.0, 4.0, 5.0, 6.0, 7.0, 8.0]


def test_bad_rig_name_exits_non_zero_and_changes_nothing(robot_scene: Any,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    before = snapshot()
    assert cli.main(["generate", "--rig", "Nobody"]) == 1
    err = capsys.readouterr().err
    assert "no armature named 'Nobody'" in err
    assert "armatures: Robot" in err
    assert snapshot() == before


def test_failures_and_usage_errors_exit_non_zero(robot_scene: Any,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    robot_scene.procloco.use_scene_range = False
    robot_scene.procloco.frame_start, robot_scene.procloco.frame_end = 10, 2
    assert cli.main(["generate", "--rig", "Robot"]) == 1
    assert "is reversed (10 to 2)" in capsys.readouterr().err
    assert cli.main(["generate"]) == 1
    assert "--rig NAME" in capsys.readouterr().err
    assert cli.main(["dance"]) == 2
    assert "invalid choice" in capsys.readouterr().err


def test_info_lists_rigs_legs_and_chains(robot_scene: Any, capsys: pytest.CaptureFixture[str]) -> None:
    creatures.build_lizard(bpy.context.scene, location=(1.5, 0.0, 0.0))
    assert cli.main(["info"]) == 0
    printed = capsys.readouterr().out
    assert "Robot: 5 legs (M1: Leg1_thigh > Leg1_foot" in printed
    assert "Robot: no tail, antenna or ear chain" in printed
    assert "Lizard: suggested secondary chains Tail.001" in printed


def test_the_command_is_registered_with_blender(procloco_registered: Any) -> None:
    if not hasattr(bpy.utils, "register_cli_command"):
        pytest.skip("this Blender has no command-line commands")
    assert cli._handle is not None
    assert cli._execute(["generate", "--rig", "Nobody"]) == 1


# ---------------------------------------------------------------------------------------
# Secondary motion and the spine switches


@pytest.fixture
def lizard_scene(empty_scene: Any) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    lizard = creatures.build_lizard(empty_scene)
    empty_scene.frame_start, empty_scene.frame_end = 1, 36
    return lizard


def test_generate_then_bake_secondary_swings_the_tail_only(empty_scene: Any,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    from mathutils import Matrix

    from procloco_addon.blender.secondary import bake
    from tests.blender.pose_eval import pose_matrices

    bpy.ops.mesh.primitive_plane_add(size=8.0)
    wolf = creatures.build_wolf(empty_scene)
    empty_scene.frame_start, empty_scene.frame_end = 1, 36
    assert cli.main(["generate", "--rig", "Wolf", "--bake-secondary"]) == 0
    printed = capsys.readouterr().out
    assert "Wolf: suggested chains Tail (spine.003)" in printed
    assert "Wolf: baked" in printed
    baked = wolf.animation_data.action
    assert baked.name == "Wolf Secondary"
    walk = baked[bake.SECONDARY_SOURCE]
    assert walk.name == "Wolf ProcLoco"  # the bake sits on the generated walk, which is kept
    frames = list(range(1, 37))
    bones = ["thigh.L", "front_foot.R", "spine.004", "spine"]  # legs, hips, the tail's tip
    swinging = pose_matrices(wolf, frames, bones)
    actions.assign_action(wolf, walk)
    for pb in wolf.pose.bones:  # the walk does not key the tail: put it back at rest
        pb.matrix_basis = Matrix()
    walking = pose_matrices(wolf, frames, bones)
    # Legs and body walk exactly as generated; the tail's tip lags and swings.
    assert np.abs(swinging[:, :3] - walking[:, :3]).max() < 1e-5
    tip = [m[:, 3, :3, 1] / np.linalg.norm(m[:, 3, :3, 1], axis=-1, keepdims=True)
           for m in (swinging, walking)]
    swing = np.degrees(np.arccos(np.clip(np.sum(tip[0] * tip[1], axis=-1), -1.0, 1.0)))
    assert swing.max() > 0.5  # (exactly 0 without the bake; about 1.7° for this short flat walk)


def test_bake_secondary_command(empty_scene: Any, capsys: pytest.CaptureFixture[str]) -> None:
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    robot = creatures.build_robot(empty_scene)
    ant = creatures.build_ant(empty_scene, location=(1.0, 0.0, 0.0), scale=20.0)
    empty_scene.frame_start, empty_scene.frame_end = 1, 6
    # A named rig without anything to swing is refused, and nothing changes. (Blender 4.2
    # lists a registered property group in the object's keys once it is read: read it first.)
    assert len(robot.procloco_secondary.chains) == 0
    before = snapshot()
    assert cli.main(["bake-secondary", "--rig", "Robot"]) == 1
    assert "'Robot' has no tail, antenna or ear chain" in capsys.readouterr().err
    assert snapshot() == before
    assert len(robot.procloco_secondary.chains) == 0
    # --all bakes every rig that has chains (the ant's antennae, even with no animation) and skips the rest.
    assert cli.main(["bake-secondary", "--all", "--frames", "2", "5"]) == 0
    printed = capsys.readouterr().out
    assert "Robot: no chain for secondary motion, not baked" in printed
    assert "Ant: baked" in printed
    assert robot.animation_data is None or robot.animation_data.action is None
    labels = {c.name for c in ant.procloco_secondary.chains}
    assert any("Antenna" in label for label in labels), labels
    antenna = 'pose.bones["Antenna1.L"].rotation_quaternion'
    keys = actions.read_channel(ant.animation_data.action, ant, antenna, 0)
    assert keys is not None
    assert keys[0].tolist() == [2.0, 3.0, 4.0, 5.0]
    # The bake's options are the generate command's.
    assert cli.main(["bake-secondary", "--rig", "Ant", "--contact-sheet", "x.png"]) == 1
    assert "--contact-sheet and --gif need --render DIR" in capsys.readouterr().err


def test_spine_and_visual_yaw_switches(lizard_scene: Any) -> None:
    from tests.blender.test_generate import _spine_bend

    frames = list(range(1, 37))
    assert cli.main(["generate", "--rig", "Lizard", "--spine", "--visual-yaw"]) == 0
    s = lizard_scene.procloco
    assert s.use_spine
    assert s.use_visual_yaw
    swaying = _spine_bend(lizard_scene, frames, ("Hips", "Chest"))
    assert swaying.max() > 2.0
    # Generated again without the spine: its bones are back at rest (not frozen in the
    # last pose the first walk gave them).
    assert cli.main(["generate", "--rig", "Lizard", "--no-spine"]) == 0
    assert not s.use_spine
    assert s.use_visual_yaw  # left as it was
    rigid = _spine_bend(lizard_scene, frames, ("Hips", "Chest"))
    assert rigid.max() < 0.05  # float32 pose matrices
    assert cli.main(["generate", "--rig", "Lizard", "--no-visual-yaw"]) == 0
    assert not s.use_visual_yaw
