# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/render_chunk.py: ``procloco render --frames A-B``, the render farms' chunk render,
through the batch command in-process."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import cli, render_chunk
from procloco_addon.blender.cli import image_pixels
from tests.blender.scene_state import snapshot
from tools.examples import creatures

pytestmark = pytest.mark.blender


def test_frame_ranges_in_farm_and_blender_notation() -> None:
    parse = render_chunk.parse_frames
    assert parse("1-10") == parse("1..10") == list(range(1, 11))
    assert parse("7") == parse("7-7") == [7]
    assert parse(" 2 .. 4 , 9,3") == [2, 3, 4, 9]
    assert parse("-3..-1") == [-3, -2, -1]
    assert list(render_chunk.frame_runs([1, 2, 3, 7, 9, 10])) == [(1, 3), (7, 7), (9, 10)]
    for bad, message in [("10-1", "reversed"), ("one", "bad frame range"), ("", "bad frame range"),
                         ("1-3-5", "bad frame range"), ("1,,2", "bad frame range")]:
        with pytest.raises(render_chunk.RenderError, match=message):
            parse(bad)


@pytest.fixture
def walking_robot(empty_scene: Any) -> Any:
    """A generated walk of the robot over frames 1-10, a camera, a tiny Workbench render."""
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    creatures.build_robot(empty_scene)
    empty_scene.frame_start, empty_scene.frame_end = 1, 10
    assert cli.main(["generate", "--rig", "Robot"]) == 0
    data = bpy.data.cameras.new("Camera")
    camera = bpy.data.objects.new("Camera", data)
    empty_scene.collection.objects.link(camera)
    camera.location = (0.0, -2.5, 1.0)
    camera.rotation_euler = (1.3, 0.0, 0.0)
    empty_scene.camera = camera
    r = empty_scene.render
    r.engine = "BLENDER_WORKBENCH"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 48, 27, 100
    empty_scene.display.render_aa = "OFF"
    r.filepath = "//scene_output_"
    return empty_scene


def test_render_a_chunk_with_the_scenes_settings(walking_robot: Any, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    scene = walking_robot
    before = (scene.frame_start, scene.frame_end, scene.frame_current, scene.render.filepath,
              scene.render.image_settings.file_format)
    assert cli.main(["render", "--frames", "3-5", "--output", str(tmp_path / "frame_####")]) == 0
    printed = capsys.readouterr().out
    assert "with BLENDER_WORKBENCH" in printed
    assert "rendered 3 frames" in printed
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"frame_{f:04d}.png" for f in (3, 4, 5)]
    first, last = image_pixels(tmp_path / "frame_0003.png"), image_pixels(tmp_path / "frame_0005.png")
    assert first.shape == (27, 48, 4)
    assert np.abs(first - last).max() > 0.02, "the generated walk moves the robot between frames 3 and 5"
    # Frames after the scene's range, in Blender's notation and another format.
    assert cli.main(["render", "--frames", "11..12", "--output", str(tmp_path / "late_##"),
                     "--format", "JPEG"]) == 0
    assert (tmp_path / "late_11.jpg").is_file()
    assert (tmp_path / "late_12.jpg").is_file()
    # The scene is as it was: range, current frame, output path and format.
    assert (scene.frame_start, scene.frame_end, scene.frame_current, scene.render.filepath,
            scene.render.image_settings.file_format) == before


def test_render_uses_the_scenes_engine(walking_robot: Any, tmp_path: Path) -> None:
    scene = walking_robot
    assert cli.main(["render", "--frames", "4", "--output", str(tmp_path / "workbench_####")]) == 0
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.device = "CPU"
    assert cli.main(["render", "--frames", "4", "--output", str(tmp_path / "cycles_####")]) == 0
    assert scene.render.engine == "CYCLES"
    workbench = image_pixels(tmp_path / "workbench_0004.png")
    cycles = image_pixels(tmp_path / "cycles_0004.png")
    assert workbench.shape == cycles.shape
    assert np.abs(workbench - cycles).max() > 0.1, "Cycles and Workbench render the frame differently"


def test_render_refusals_exit_non_zero_and_change_nothing(walking_robot: Any, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "frame_####")
    before = snapshot()
    cases = [
        (["render", "--frames", "5-1", "--output", out], 1, "frame range '5-1' is reversed"),
        (["render", "--frames", "1-2", "--output", out, "--format", "GIF"], 1, "unknown image format 'GIF'"),
        (["render", "--frames", "1-2", "--output", out, "--format", "FFMPEG"], 1,
         "the output format is FFMPEG"),
        (["render", "--frames=-2..1", "--output", out], 1, "negative frames cannot be rendered"),
        (["render", "--output", out], 2, "--frames"),
    ]
    for argv, status, message in cases:
        assert cli.main(argv) == status, argv
        assert message in capsys.readouterr().err
    walking_robot.camera = None
    assert cli.main(["render", "--frames", "1", "--output", out]) == 1
    assert "has no camera to render from" in capsys.readouterr().err
    walking_robot.camera = bpy.data.objects["Camera"]
    assert snapshot() == before
    assert list(tmp_path.iterdir()) == []


def test_render_that_writes_nothing_fails(walking_robot: Any, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the output folder should be")
    assert cli.main(["render", "--frames", "2", "--output", str(blocker / "frame_####")]) == 1
    assert "cannot save" in capsys.readouterr().err
