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
from tests.blender.scene_state import snapshot
from tools.examples import creatures

pytestmark = pytest.mark.blender


@pytest.fixture
def robot_scene(empty_scene: Any) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    robot = creatures.build_robot(empty_scene)
    empty_scene.frame_start, empty_scene.frame_end = 1, 10
    return robot


def _image(path: Path) -> np.ndarray:
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)


def test_generate_renders_frames_and_a_contact_sheet(robot_scene: Any, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "frames"
    sheet = tmp_path / "sheet.png"
    saved = tmp_path / "walk.blend"
    status = cli.main(["generate", "--rig", "Robot", "--frame-step", "3", "--resolution", "96", "54",
                       "--render", str(out), "--contact-sheet", str(sheet), "--save", str(saved)])
    assert status == 0
    printed = capsys.readouterr().out
    assert "ProcLoco:   Robot: 100%" in printed
    assert "wrote Action 'Robot ProcLoco'" in printed
    files = sorted(out.glob("frame_*.png"))
    assert [f.name for f in files] == ["frame_0001.png", "frame_0004.png", "frame_0007.png", "frame_0010.png"]
    first, last = _image(files[0]), _image(files[-1])
    assert first.shape == (54, 96, 4)
    assert np.abs(first - last).max() > 0.05, "the robot moved between the first and the last frame"
    assert _image(sheet).shape == (54, 4 * 96, 4)  # four tiles in one row
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
    assert "empty or reversed" in capsys.readouterr().err
    assert cli.main(["generate"]) == 1
    assert "--rig NAME" in capsys.readouterr().err
    assert cli.main(["dance"]) == 2
    assert "invalid choice" in capsys.readouterr().err


def test_info_lists_rigs_and_legs(robot_scene: Any, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["info"]) == 0
    assert "Robot: 5 legs (M1: Leg1_thigh > Leg1_foot" in capsys.readouterr().out


def test_the_command_is_registered_with_blender(procloco_registered: Any) -> None:
    if not hasattr(bpy.utils, "register_cli_command"):
        pytest.skip("this Blender has no command-line commands")
    assert cli._handle is not None
    assert cli._execute(["generate", "--rig", "Nobody"]) == 1
