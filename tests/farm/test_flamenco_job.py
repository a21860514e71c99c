# SPDX-License-Identifier: GPL-3.0-or-later
"""farm/flamenco/procloco_locomotion.js: the Flamenco job type, compiled by a Node.js
stand-in for the Manager's job compiler (tests/farm/flamenco_harness.js), and the
generate task it writes run through the real batch command on examples.blend."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.farm.generated_file import rigs_in

ROOT = Path(__file__).resolve().parents[2]
JOB_TYPE = ROOT / "farm" / "flamenco" / "procloco_locomotion.js"
HARNESS = Path(__file__).with_name("flamenco_harness.js")
FAKE_BLENDER = Path(__file__).with_name("fake_blender.py")
NODE = shutil.which("node")

pytestmark = pytest.mark.skipif(NODE is None, reason="Node.js (node) is not installed: the Flamenco "
                                "job type is JavaScript and its tests compile it with node")

OUT = "/farm/renders/shot/2026-01-02_030405"
BLEND = "/farm/jobs/shot.flamenco.blend"


def _run_harness(request: dict[str, Any]) -> dict[str, Any]:
    assert NODE is not None
    env = dict(os.environ, TZ="UTC")  # formatTimestampLocal() formats in local time
    result = subprocess.run([NODE, str(HARNESS)], input=json.dumps(request), capture_output=True,
                            text=True, timeout=60, env=env, check=False)
    assert result.returncode == 0, result.stderr
    answer: dict[str, Any] = json.loads(result.stdout)
    return answer


def _settings(**changes: Any) -> dict[str, Any]:
    """Settings as Flamenco's Blender add-on submits them (evaluated from the scene)."""
    settings: dict[str, Any] = {
        "frames": "1-10", "chunk_size": 3, "rigs": "", "bake_secondary": False, "speed": 0.0,
        "seed": -1, "procloco_args": "", "render_output_root": "/farm/renders",
        "add_path_components": 0, "render_output_path": "/farm/renders/shot/{timestamp}/######",
        "make_video": True, "blendfile": BLEND, "fps": 24.0, "format": "PNG",
        "image_file_extension": ".png",
    }
    settings.update(changes)
    return settings


def compile_jobs(*settings: dict[str, Any]) -> list[dict[str, Any]]:
    answer = _run_harness({"script": str(JOB_TYPE), "jobs": [{"settings": s} for s in settings]})
    jobs: list[dict[str, Any]] = answer["jobs"]
    return jobs


def _tasks(job: dict[str, Any]) -> dict[str, dict[str, Any]]:
    assert "error" not in job, job["error"]
    return {t["name"]: t for t in job["tasks"]}


def _render_frames(job: dict[str, Any]) -> list[str]:
    """The --render-frame argument of each render task, in task order."""
    out = []
    for task in job["tasks"]:
        if task["name"].startswith("render-"):
            args = task["commands"][0]["parameters"]["args"]
            out.append(args[args.index("--render-frame") + 1])
    return out


# ---------------------------------------------------------------------------------------
# The harness's frameChunker is Flamenco's


def test_harness_frame_chunker_matches_flamenco() -> None:
    """Chunks that Flamenco's own job compiler documents and tests (its frameChunker tests and
    Simple Blender Render's chunking); the job type relies on the same function."""
    cases = [
        (("1-10", 3), ["1-3", "4-6", "7-9", "10"]),
        (("1..10,20..25,40,3..8", 4), ["1-4", "5-8", "9,10,20,21", "22-25", "40"]),
        (("1-10,20-25,40", 4), ["1-4", "5-8", "9,10,20,21", "22-25", "40"]),
        ((" 1  .. 10,\t20..25\n,40   ", 4), ["1-4", "5-8", "9,10,20,21", "22-25", "40"]),
        (("47", 4), ["47"]),
        (("1-3", 3), ["1-3"]),
    ]
    bad = [["   ", 4], [" 1 10", 4], ["1-3", 0]]
    answer = _run_harness({"chunks": [list(args) for args, _ in cases] + bad})
    assert [c.get("chunks") for c in answer["chunks"][:len(cases)]] == [want for _, want in cases]
    empty, spaced, zero = answer["chunks"][len(cases):]
    assert "empty range" in empty["error"]
    assert "1 10" in spaced["error"]
    assert "chunk size" in zero["error"]


# ---------------------------------------------------------------------------------------
# The job type's definition


def test_job_type_settings_are_well_formed() -> None:
    answer = _run_harness({"script": str(JOB_TYPE)})
    assert answer["hasCompileJob"]
    job_type = answer["jobType"]
    assert job_type["label"] == "ProcLoco Locomotion"
    settings = job_type["settings"]
    keys = [s["key"] for s in settings]
    assert len(keys) == len(set(keys))
    for s in settings:
        assert s["type"] in ("string", "int32", "float", "bool"), s
        assert s.get("visible", "visible") in ("visible", "submission", "web", "hidden"), s
        assert s.get("subtype") in (None, "file_path", "dir_path", "file_name", "hashed_file_path"), s
        if "default" in s:
            kind = {"string": str, "int32": int, "float": (int, float), "bool": bool}[s["type"]]
            assert isinstance(s["default"], kind), s
    by_key = {s["key"]: s for s in settings}
    # What the Blender add-on fills in from the scene, and what the user chooses.
    assert by_key["frames"]["eval"] == "f'{C.scene.frame_start}-{C.scene.frame_end}'"
    assert by_key["blendfile"]["required"]
    for key in ("chunk_size", "rigs", "bake_secondary", "speed", "seed", "procloco_args",
                "render_output_root", "make_video"):
        assert by_key[key]["visible"] == "submission", key


# ---------------------------------------------------------------------------------------
# Task graphs


def test_task_graph_of_a_shot() -> None:
    (job,) = compile_jobs(_settings(rigs="Wolf, Spider", seed=4, speed=1.25, bake_secondary=True,
                                    procloco_args="--heading -30 --spine"))
    tasks = _tasks(job)
    assert list(tasks) == ["generate-locomotion", "render-1-3", "render-4-6", "render-7-9", "render-10",
                           "preview-video"]
    generated = f"{OUT}/shot-procloco.blend"
    assert tasks["generate-locomotion"] == {
        "name": "generate-locomotion", "type": "blender", "dependencies": [],
        "commands": [{"name": "blender-render", "parameters": {
            "exe": "{blender}", "exeArgs": "{blenderArgs}", "argsBefore": [], "blendfile": BLEND,
            "args": ["--command", "procloco", "generate", "--rig", "Wolf", "--rig", "Spider",
                     "--frames", "1", "10", "--bake-secondary", "--speed", "1.25", "--seed", "4",
                     "--heading", "-30", "--spine", "--save", generated]}}],
    }
    assert tasks["render-4-6"] == {
        "name": "render-4-6", "type": "blender", "dependencies": ["generate-locomotion"],
        "commands": [{"name": "blender-render", "parameters": {
            "exe": "{blender}", "exeArgs": "{blenderArgs}", "argsBefore": [], "blendfile": generated,
            "args": ["--render-output", f"{OUT}/######", "--render-format", "PNG",
                     "--render-frame", "4..6"]}}],
    }
    assert _render_frames(job) == ["1..3", "4..6", "7..9", "10"]
    for name in ("render-1-3", "render-7-9", "render-10"):
        assert tasks[name]["dependencies"] == ["generate-locomotion"]
        assert tasks[name]["commands"][0]["parameters"]["blendfile"] == generated
    video = tasks["preview-video"]
    assert video["type"] == "ffmpeg"
    assert video["dependencies"] == ["render-1-3", "render-4-6", "render-7-9", "render-10"]
    params = video["commands"][0]["parameters"]
    assert (video["commands"][0]["name"], params["fps"], params["inputGlob"], params["outputFile"]) == (
        "frames-to-video", 24, f"{OUT}/*.png", f"{OUT}/shot-1-10.mp4")
    # The job shows the output path it really used.
    assert job["settings"]["render_output_path"] == f"{OUT}/######"


def test_frame_ranges_and_chunks() -> None:
    jobs = compile_jobs(
        _settings(frames="1..10", chunk_size=3),   # Blender's notation
        _settings(frames="7", chunk_size=3),       # a single frame
        _settings(frames="1-10", chunk_size=4),    # does not divide evenly
        _settings(frames="1-5", chunk_size=2),     # two-frame chunks are lists, as in Flamenco
        _settings(frames=" 3 - 6 ", chunk_size=50),  # one chunk for everything
        _settings(frames="0-2", chunk_size=1),
    )
    assert _render_frames(jobs[0]) == ["1..3", "4..6", "7..9", "10"]
    assert _render_frames(jobs[1]) == ["7"]
    assert _render_frames(jobs[2]) == ["1..4", "5..8", "9,10"]
    assert _render_frames(jobs[3]) == ["1,2", "3,4", "5"]
    assert _render_frames(jobs[4]) == ["3..6"]
    assert _render_frames(jobs[5]) == ["0", "1", "2"]
    # The simulation always covers the whole range, in one task.
    for job, (first, last) in zip(jobs, [(1, 10), (7, 7), (1, 10), (1, 5), (3, 6), (0, 2)], strict=True):
        args = _tasks(job)["generate-locomotion"]["commands"][0]["parameters"]["args"]
        assert args[args.index("--frames") + 1:args.index("--frames") + 3] == [str(first), str(last)]
    assert list(_tasks(jobs[1])) == ["generate-locomotion", "render-7", "preview-video"]
    assert _tasks(jobs[1])["preview-video"]["commands"][0]["parameters"]["outputFile"] == f"{OUT}/shot-7.mp4"


def test_defaults_animate_every_rig_and_options_stay_off() -> None:
    (plain, exr, no_video, no_fps) = compile_jobs(
        _settings(), _settings(format="OPEN_EXR", image_file_extension=".exr"),
        _settings(make_video=False), _settings(fps=0))
    args = _tasks(plain)["generate-locomotion"]["commands"][0]["parameters"]["args"]
    assert args == ["--command", "procloco", "generate", "--all", "--frames", "1", "10",
                    "--save", f"{OUT}/shot-procloco.blend"]
    assert "preview-video" in _tasks(plain)
    assert _tasks(exr)["render-1-3"]["commands"][0]["parameters"]["args"][3] == "OPEN_EXR"
    for job in (exr, no_video, no_fps):
        assert "preview-video" not in _tasks(job)
    assert any("FFmpeg does not read OPEN_EXR" in line for line in exr["log"])


@pytest.mark.parametrize(("changes", "message"), [
    ({"frames": "1-3,7-9"}, "'1-3,7-9' is not one contiguous range"),
    ({"frames": "10-1"}, "'10-1' is reversed"),
    ({"frames": "1 to 10"}, "'1 to 10' is not a frame range"),
    ({"frames": "-5-10"}, "has a negative frame"),
    ({"frames": ""}, "give the frame range"),
    ({"chunk_size": 0}, "chunk_size: 0 is too small"),
    ({"chunk_size": 2.5}, "chunk_size: '2.5' is not a whole number"),
    ({"blendfile": ""}, "blendfile: no .blend file given"),
    ({"blendfile": "/farm/jobs/shot.ma"}, "'/farm/jobs/shot.ma' is not a .blend file"),
    ({"format": "FFMPEG"}, "The scene renders a movie (FFMPEG)"),
    ({"rigs": "Wolf,,Spider"}, "has an empty name between commas"),
    ({"speed": -1}, "speed: '-1' is not a speed"),
    ({"seed": -3}, "seed: -3 is too small"),
    ({"procloco_args": "--save /tmp/x.blend"}, "--save is set by the job; use the 'render_output_root'"),
    ({"procloco_args": "--speed=2"}, "--speed is set by the job; use the 'speed' setting"),
    ({"procloco_args": "--heading"}, "--heading needs a number, not ''"),
    ({"procloco_args": "--step-height -0.1"}, "--step-height needs a length in metres"),
    ({"procloco_args": "--dance"}, "'--dance' is not one of --heading"),
    ({"procloco_args": "--heading '30"}, "closing quote"),
    ({"render_output_path": ""}, "no output path"),
])
def test_bad_settings_fail_at_compile_time(changes: dict[str, Any], message: str) -> None:
    (job,) = compile_jobs(_settings(**changes))
    assert "tasks" not in job
    assert message in job["error"]


# ---------------------------------------------------------------------------------------
# The generate task, run


@pytest.mark.blender
@pytest.mark.slow
def test_generate_task_runs_the_batch_command_on_examples(tmp_path: Path) -> None:
    """The generate task's exact command line, as a Worker runs it (``{blender}`` and
    ``{blenderArgs}`` are the Manager's defaults ``blender`` and ``-b -y``), on a copy of
    examples.blend: exit 0, a new file with every listed rig's Action, the source untouched."""
    shot = tmp_path / "jobs" / "shot.flamenco.blend"
    shot.parent.mkdir()
    shutil.copyfile(ROOT / "examples.blend", shot)
    before = shot.read_bytes()
    out = tmp_path / "renders" / "shot" / "run"
    (job,) = compile_jobs(_settings(blendfile=str(shot), render_output_path=f"{out}/######", frames="1-4",
                                    rigs="Wolf, Robot", seed=2))
    params = _tasks(job)["generate-locomotion"]["commands"][0]["parameters"]
    assert params["exeArgs"] == "{blenderArgs}"
    argv = ["-b", "-y", *params["argsBefore"], params["blendfile"], *params["args"]]
    result = subprocess.run([sys.executable, str(FAKE_BLENDER), *argv], capture_output=True, text=True,
                            timeout=300, check=False)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "Wolf: wrote Action 'Wolf ProcLoco'" in result.stdout
    generated = out / "shot-procloco.blend"
    assert params["args"][-2:] == ["--save", str(generated)]
    assert shot.read_bytes() == before  # the submitted file is only read
    shown = rigs_in(generated, ["Wolf", "Robot"], frames=(1, 4))
    assert shown == {"Wolf": ("Wolf ProcLoco", 1, 4, 2), "Robot": ("Robot ProcLoco", 1, 4, 2)}
