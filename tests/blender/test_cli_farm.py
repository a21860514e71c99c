# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/cli.py: the options of the batch command that render-farm job templates use
(``--rigs`` as one list, ``--no-bake-secondary``, ``--save`` into a new folder)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import pytest

from procloco_addon.blender import cli
from tests.blender.scene_state import snapshot
from tools.examples import creatures

pytestmark = pytest.mark.blender


@pytest.fixture
def two_rigs(tmp_path: Path, empty_scene: Any) -> Path:
    """A saved file with the robot and the lizard over frames 1-6; returns its path."""
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    creatures.build_robot(empty_scene)
    creatures.build_lizard(empty_scene, location=(1.5, 0.0, 0.0))
    empty_scene.frame_start, empty_scene.frame_end = 1, 6
    source = tmp_path / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(source))
    return source


def _actions() -> dict[str, str | None]:
    return {o.name: (o.animation_data.action.name if o.animation_data and o.animation_data.action else None)
            for o in bpy.data.objects if o.type == "ARMATURE"}


def test_rigs_as_one_list_and_save_into_a_new_folder(two_rigs: Path, tmp_path: Path) -> None:
    before = two_rigs.read_bytes()
    saved = tmp_path / "new" / "folder" / "generated.blend"
    assert cli.main(["generate", "--rigs", " Lizard ", "--no-bake-secondary", "--save", str(saved)]) == 0
    assert _actions() == {"Robot": None, "Lizard": "Lizard ProcLoco"}
    assert bpy.data.actions.get("Lizard Secondary") is None  # --no-bake-secondary: no bake
    assert saved.is_file()
    assert two_rigs.read_bytes() == before  # the opened file is left as it was
    bpy.ops.wm.open_mainfile(filepath=str(two_rigs))
    assert cli.main(["generate", "--rigs", "*", "--bake-secondary"]) == 0
    assert _actions() == {"Robot": "Robot ProcLoco", "Lizard": "Lizard Secondary"}
    bpy.ops.wm.open_mainfile(filepath=str(two_rigs))
    assert cli.main(["generate", "--rigs", "Robot,Lizard"]) == 0
    assert _actions() == {"Robot": "Robot ProcLoco", "Lizard": "Lizard ProcLoco"}


def test_rigs_list_with_an_unknown_name_changes_nothing(two_rigs: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    before = snapshot()
    assert cli.main(["generate", "--rigs", "Robot,Nobody"]) == 1
    assert "no armature named 'Nobody'" in capsys.readouterr().err
    assert cli.main(["generate", "--rigs", " , "]) == 1
    assert "--rigs A,B" in capsys.readouterr().err
    assert snapshot() == before
    # bake-secondary with '*' is --all: rigs without chains are skipped, not refused.
    assert cli.main(["bake-secondary", "--rigs", "*"]) == 0
    assert "Robot: no chain for secondary motion, not baked" in capsys.readouterr().out
