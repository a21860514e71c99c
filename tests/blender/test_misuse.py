# SPDX-License-Identifier: GPL-3.0-or-later
"""Randomized misuse of Generate Locomotion and Clear: settings (NaN, infinite, huge,
negative and sane values), frame ranges and rig placements drawn by hypothesis.

Whatever is drawn: no exception escapes the operator (a refusal is a message, never a
traceback); a refusal changes nothing (full scene snapshot: every property group, every
Action's keys, poses, placements); an accepted run meets the motion thresholds and Clear
gives the rig back as it was.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

from procloco_addon.blender.locomotion import generate
from tests.blender.scene_state import snapshot
from tools.examples import creatures

pytestmark = pytest.mark.blender

_BAD = [math.nan, math.inf, -math.inf, 1e30, -1e30, -1.0]


def _rarely(good: st.SearchStrategy[Any], bad: st.SearchStrategy[Any], odds: int = 12
            ) -> st.SearchStrategy[Any]:
    """``good`` most of the time, ``bad`` about once in ``odds`` draws."""
    return st.integers(0, odds - 1).flatmap(lambda k: bad if k == 0 else good)


def _value(low: float, high: float) -> st.SearchStrategy[float]:
    """A sane value in ``[low, high]`` most of the time, else a bad one."""
    return _rarely(st.floats(low, high), st.sampled_from(_BAD))


#: Sane values; speed and step height in leg lengths (per second), scaled to the rig.
_SETTINGS = {
    "speed": _value(0.0, 2.0),
    "step_height": _value(0.0, 0.4),
    "heading": _value(-7.0, 7.0),
    "turn_rate": _value(-1.0, 1.0),
    "cycle_time": _value(0.5, 2.0),
    "spacing": _value(0.6, 1.4),
    "spine_turn_rate": _value(0.5, 4.0),
    "visual_yaw_gain": _value(0.0, 2.0),
}


#: The example robot's mean leg length (m).
_ROBOT_LEG = 0.66


@pytest.fixture(scope="module")
def robot_file(tmp_path_factory: pytest.TempPathFactory, procloco_registered: Any) -> Path:
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=2000.0)
    bpy.context.active_object.name = "Ground"
    robot = creatures.build_robot(bpy.context.scene)
    robot.procloco.use_scene_range = False
    path = tmp_path_factory.mktemp("misuse") / "robot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def _select(obj: Any) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


@settings(max_examples=max(6, settings.default.max_examples // 5))
@given(
    values=st.fixed_dictionaries({k: st.none() | v for k, v in _SETTINGS.items()}),
    frames=st.tuples(st.integers(-3, 4), _rarely(st.integers(4, 10), st.integers(-4, 0), 6)).map(
        lambda p: (p[0], p[0] + p[1])),
    location=_rarely(st.tuples(*[st.floats(-5.0, 5.0)] * 2), st.sampled_from([(math.nan, 0.0), (1e9, 0.0)])),
    yaw=st.floats(-math.pi, math.pi),
    # (A uniform object scale scales the rig's own speed and step height too: the same rig at
    # another size).
    scale=_rarely(st.sampled_from([(1.0, 1.0, 1.0), (0.05, 0.05, 0.05), (20.0, 20.0, 20.0)]),
                  st.sampled_from([(1.0, 2.0, 1.0), (0.0, 0.0, 0.0), (-1.0, -1.0, -1.0)]), 6),
)
def test_misuse_never_raises_and_a_refusal_changes_nothing(
    robot_file: Path, values: dict[str, float | None], frames: tuple[int, int],
    location: tuple[float, float], yaw: float, scale: tuple[float, float, float],
) -> None:
    from tests.blender.test_generate import _measure_on

    bpy.ops.wm.open_mainfile(filepath=str(robot_file))
    robot = bpy.data.objects["Robot"]
    s = robot.procloco
    leg = _ROBOT_LEG * abs(scale[0])
    if scale[0] > 0.0:  # the rig's own lengths scale with it (a 0.45 m/s walk is slow on a 13 m leg)
        s.speed *= scale[0]
        s.step_height *= scale[0]
    for name, value in values.items():
        if value is not None:
            if name in {"speed", "step_height"} and math.isfinite(value) and abs(value) < 1e3:
                value *= leg
            setattr(s, name, value)  # Blender clamps to the property's hard range; NaN passes
    s.frame_start, s.frame_end = frames
    robot.location = (*location, 0.0)
    robot.rotation_euler = (0.0, 0.0, yaw)
    robot.scale = scale
    _select(robot)
    bpy.context.scene.frame_set(1)
    before = snapshot()
    refusal = ""
    try:
        result = bpy.ops.procloco.generate_locomotion()
    except RuntimeError as err:  # a refusal: reported, never a traceback, nothing changed
        refusal = str(err)
    if refusal:
        assert "Traceback" not in refusal, refusal
        assert snapshot() == before
        event(f"refused: {refusal.split(':')[1].strip()[:40]}")
        return
    event("accepted")
    assert result == {"FINISHED"}
    # Accepted: the motion meets the thresholds (scaled with a scaled rig) ...
    ground = bpy.data.objects["Ground"]
    job = generate.prepare(bpy.context, robot)
    for _fraction in generate.simulate(job):
        pass
    m = _measure_on(robot, job, [ground], [])
    size = scale[0] if scale[0] > 0.0 else 1.0  # the thresholds to the rig's size
    assert m["slide"] <= 0.002 * size, m
    assert m["penetration"] <= 0.005 * size, m
    assert m["bone"] < 1e-4, m
    assert m["reach"] <= 0.01 * size, m
    assert m["extension"] <= 1.0 + 1e-6, m
    # ... and Clear gives the rig back as it was.
    assert bpy.ops.procloco.clear_generated_action() == {"FINISHED"}
    bpy.context.scene.frame_set(1)
    after = snapshot()
    assert after["per_object"]["Robot"] == before["per_object"]["Robot"]
    assert np.isfinite(m["travel"])
