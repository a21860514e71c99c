# SPDX-License-Identifier: GPL-3.0-or-later
"""farm/openjd/procloco.yaml: the Open Job Description template passes ``openjd check``
and ``openjd run`` executes it on examples.blend: one Generate task, then Render tasks over
chunks of frames, each a ``blender --background FILE --command procloco ...`` process
(Blender's binary stood in for by tests/farm/fake_blender.py, on the bpy module)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.farm.generated_file import rigs_in

ROOT = Path(__file__).resolve().parents[2]
TEMPLATE = ROOT / "farm" / "openjd" / "procloco.yaml"
FAKE_BLENDER = Path(__file__).with_name("fake_blender.py")
EXAMPLE_RIGS = ["Ant", "Human", "Lizard", "Robot", "Spider", "Wolf"]
_POSIX = pytest.mark.skipif(os.name != "posix" or shutil.which("sh") is None,
                            reason="the stand-in blender executables are shell scripts")


def _openjd(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    beside = Path(sys.executable).with_name("openjd")  # the venv's own, when pytest runs from one
    exe = str(beside) if beside.exists() else shutil.which("openjd")
    assert exe, "openjd-cli is missing: it is pinned in tools/requirements.txt"
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=timeout, check=False)


def test_template_passes_openjd_check() -> None:
    result = _openjd("check", str(TEMPLATE))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "passes validation checks" in result.stdout


def test_template_summary_lists_both_steps_and_the_chunks() -> None:
    result = _openjd("summary", str(TEMPLATE), "--output", "json", "-p", "SceneFile=/shots/a.blend",
                     "-p", "OutputDir=/renders/a", "-p", "FrameStart=1", "-p", "FrameEnd=25",
                     "-p", "ChunkSize=10")
    assert result.returncode == 0, result.stdout + result.stderr
    summary = json.loads(result.stdout)
    steps = {step["name"]: step for step in summary["steps"]}
    assert list(steps) == ["Generate", "Render"]
    assert steps["Render"]["dependencies"][0]["step_name"] == "Generate"
    assert steps["Generate"]["total_tasks"] == 1


@pytest.fixture(scope="module")
def small_scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """examples.blend with a tiny render (10 % of 640×360, no anti-aliasing: the template
    renders with the scene's own settings, and Workbench's 8 samples take seconds a frame
    in software GL)."""
    folder = tmp_path_factory.mktemp("openjd_scene")
    scene = folder / "shot.blend"
    code = textwrap.dedent(f"""
        import bpy, os, sys
        bpy.ops.wm.open_mainfile(filepath={str(ROOT / "examples.blend")!r})
        s = bpy.context.scene
        s.render.resolution_percentage = 10
        s.display.render_aa = "OFF"
        bpy.ops.wm.save_as_mainfile(filepath={str(scene)!r})
        sys.stdout.flush()
        os._exit(0)
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                            check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    return scene


@pytest.mark.blender
@pytest.mark.slow
@_POSIX
def test_openjd_run_generates_then_renders_in_chunks(small_scene: Path, tmp_path: Path) -> None:
    blender = tmp_path / "bin" / "blender"
    blender.parent.mkdir()
    blender.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{FAKE_BLENDER}" "$@"\n')
    blender.chmod(0o755)
    out = tmp_path / "out"
    before = small_scene.read_bytes()
    result = _openjd("run", str(TEMPLATE), "--step", "Render", "--run-dependencies",
                     "-p", f"SceneFile={small_scene}", "-p", f"OutputDir={out}",
                     "-p", "FrameStart=1", "-p", "FrameEnd=3", "-p", "ChunkSize=2",
                     "-p", "SecondaryMotion=--bake-secondary", "-p", f"BlenderExecutable={blender}",
                     timeout=600)
    log = result.stdout + result.stderr
    assert result.returncode == 0, log[-4000:]
    assert "All actions completed successfully" in log
    # Two render tasks, one per chunk (the last one a single frame), after one generate task.
    chunks = [line.split("=")[1].strip() for line in log.splitlines() if "Frames(CHUNK[INT]) =" in line]
    assert chunks == ["1-2", "3-3"], log[-4000:]
    assert log.index("ProcLoco: generating") < log.index("ProcLoco: rendering frames 1-2")
    assert "Chunks run: 3" in log
    generated = out / "procloco_generated.blend"
    assert small_scene.read_bytes() == before  # the scene is only read
    rigs = rigs_in(generated, EXAMPLE_RIGS, frames=(1, 3))
    assert set(rigs) == set(EXAMPLE_RIGS)
    for name, (action, start, end, _seed) in rigs.items():
        assert action.startswith(name)  # "<rig> ProcLoco", or "<rig> Secondary" on top of it
        assert (start, end) == (1, 3), name
    assert rigs["Wolf"][0] == "Wolf Secondary"
    frames = sorted(p.name for p in (out / "frames").iterdir())
    assert frames == [f"frame_{f:04d}.png" for f in range(1, 4)]


@_POSIX
def test_openjd_run_stops_when_generation_fails(tmp_path: Path) -> None:
    """A Generate task that exits non-zero fails the job: no Render task runs."""
    blender = tmp_path / "blender"
    blender.write_text("#!/bin/sh\necho \"procloco: error: no armature named 'Nobody'\" >&2\nexit 1\n")
    blender.chmod(0o755)
    result = _openjd("run", str(TEMPLATE), "--step", "Render", "--run-dependencies",
                     "-p", f"SceneFile={tmp_path / 'shot.blend'}", "-p", f"OutputDir={tmp_path / 'out'}",
                     "-p", "Rigs=Nobody", "-p", "FrameEnd=4", "-p", f"BlenderExecutable={blender}")
    log = result.stdout + result.stderr
    assert result.returncode != 0, log
    assert "no armature named 'Nobody'" in log
    assert "Frames(CHUNK[INT])" not in log  # no render task started




@pytest.mark.parametrize(("params", "message"), [
    (["FrameStart=10", "FrameEnd=1"], "descending range"),
    (["ChunkSize=0"], "ChunkSize must be at least 1"),
    (["ChunkSize=151"], "ChunkSize must be at most 150"),
    (["SecondaryMotion=yes"], "SecondaryMotion"),
])
def test_bad_parameters_are_refused_when_the_job_is_made(params: list[str], message: str) -> None:
    args = ["-p", "SceneFile=/shots/a.blend", "-p", "OutputDir=/renders/a"]
    for param in params:
        args += ["-p", param]
    result = _openjd("summary", str(TEMPLATE), *args)
    assert result.returncode != 0
    assert message in result.stdout + result.stderr
