# SPDX-License-Identifier: GPL-3.0-or-later
"""``examples.blend`` end to end: each creature as saved in the committed file, on the first
click, generates its walk (Generate Locomotion) and bakes its secondary motion (Bake
Secondary Motion, where the file lists chains), over the file's whole frame range (1-120).

The motion is measured on the posed rig, frame by frame through the depsgraph, against ray
casts into the example terrain's real meshes, with the thresholds of "What done means for
the motion" (see ``test_generate._measure_on``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender.locomotion import generate
from procloco_addon.blender.locomotion import property_group as locomotion_props
from procloco_addon.blender.quality import measure
from procloco_addon.blender.secondary import bake
from tests.blender.pose_eval import pose_matrices
from tests.blender.test_generate import (
    _measure_on,
    _select_only,
    check_no_pops,
    check_thresholds,
    without_pops,
)
from tools.examples import scene as example_scene

pytestmark = pytest.mark.blender

KINDS = example_scene.CREATURE_NAMES


def _open_examples(repo_root: Path) -> None:
    path = repo_root / "examples.blend"
    if not path.exists():
        pytest.fail("examples.blend is missing: run tools/build_examples.py")
    bpy.ops.wm.open_mainfile(filepath=str(path))


def _unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True))


@pytest.mark.parametrize("kind", KINDS)
def test_example_creature_walks_and_swings_within_the_thresholds(empty_scene: Any, repo_root: Path,
                                                                 kind: str) -> None:
    _open_examples(repo_root)
    scene = bpy.context.scene
    obj = bpy.data.objects[example_scene.CREATURE_NAMES[kind]]
    assert "procloco_pending_settings" not in obj
    expected = (example_scene.FRAME_START, example_scene.FRAME_END)
    assert locomotion_props.frame_range(obj.procloco, scene) == expected
    _select_only(obj)
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    walk = obj.animation_data.action
    assert walk.name == f"{obj.name} ProcLoco"
    # The quality panel's figures (measured on the posed rig; test_quality checks them against
    # an independent measurement) are all within the design's thresholds: the example ant's
    # planted tarsi hung up to 15 mm over its downhill slope for 11 frames before its planted
    # soles were pitched to the ground in full.
    assert not [key for key in measure.LIMITS if measure.failed(obj, key)], measure.summary_line(obj)
    # The same inputs again, to read what the operator simulated (the posed rig must match it:
    # the "reach" measure compares the posed feet with these targets).
    job = generate.prepare(bpy.context, obj)
    for _ in generate.simulate(job):
        pass

    chains = list(obj.procloco_secondary.chains)
    if chains:
        tips = [c.tip for c in chains]
        frames = [int(f) for f in job.frames]
        walking = _unit(pose_matrices(obj, frames, tips)[..., :3, 1])
        assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
        baked = obj.animation_data.action
        assert baked.name == f"{obj.name} Secondary"
        assert baked[bake.SECONDARY_SOURCE] == walk
        swinging = _unit(pose_matrices(obj, frames, tips)[..., :3, 1])
        swing = np.degrees(np.arccos(np.clip(np.sum(walking * swinging, axis=-1), -1.0, 1.0)))
        assert swing.max() > 0.5, f"no chain of the {kind} swings: {swing.max(axis=0)}"

    terrain = bpy.data.collections["Terrain"].objects
    solid = [o for o in terrain if o.procloco_role != "IGNORE"]
    # Static avoided crates are judged from the side too; a crate moving across is judged by
    # its top (it may slide into a planted foot, which then steps away: thesis sequence 4).
    avoid = [o for o in terrain if o.procloco_role == "AVOID" and o.animation_data is None]
    m = _measure_on(obj, job, solid, avoid)
    m.pop("ends")
    check_thresholds(without_pops(m))
    assert m["travel"] > 2.0 * m["scale"], m
    check_no_pops(m, kind)


def test_example_human_walks_over_its_stairs_to_its_goal(empty_scene: Any, repo_root: Path) -> None:
    """Plan Biped Footsteps on the example human, as set up in the file (its clips and goal):
    it climbs its stairs to the goal on the landing, and its feet never sink into the steps."""
    from tests.blender.pose_eval import ray_heights_over_time

    _open_examples(repo_root)
    human = bpy.data.objects[example_scene.CREATURE_NAMES["human"]]
    goal = human.procloco_biped.goal
    assert goal is not None
    _select_only(human)
    assert bpy.ops.procloco.plan_biped_footsteps() == {"FINISHED"}
    action = human.animation_data.action
    start, end = (round(v) for v in action.frame_range)
    frames = list(range(start, end + 1, 2))
    feet = ["foot.L", "toe.L", "foot.R", "toe.R"]
    mats = pose_matrices(human, frames, feet)
    lengths = np.array([human.data.bones[b].length for b in feet])
    heads = mats[..., :3, 3]
    points = np.concatenate([heads, heads + mats[..., :3, 1] * lengths[:, None]], axis=1)
    walkable = [o for o in bpy.data.collections["Terrain"].objects
                if o.get("example_feature") in ("ground", "stairs")]
    under = ray_heights_over_time(frames, points[..., :2], walkable)
    toe_radius = 0.025  # the skin's capsule at the toes; the bones run inside the foot
    assert (under - points[..., 2]).max() <= toe_radius + 0.005
    climbed = points[..., 2].min(axis=1).max()
    assert climbed > 0.5, "the feet never stood on the landing (0.6 m up)"
    hips = pose_matrices(human, [end, min(end, example_scene.FRAME_END)], ["spine"])[:, 0, :3, 3]
    assert np.linalg.norm(hips[0, :2] - np.array(goal.location)[:2]) < 0.5
    # ... and it is there by the example's last frame: the render shows the climb complete.
    assert np.linalg.norm(hips[1, :2] - np.array(goal.location)[:2]) < 0.5


def test_example_ant_walks_from_detect_legs_defaults(empty_scene: Any, repo_root: Path) -> None:
    """The example ant with its own settings cleared (its speed, step height and cycle time
    never set, its legs detected again): Detect Legs' defaults and Gait: Auto walk it over
    the example terrain within the thresholds. Its legs are crowded along its body: the
    default speed is the fastest at which Auto keeps its swing time (the model's 0.8 leg
    lengths a cycle ran the cycle six times a second, each swing a frame or two)."""
    _open_examples(repo_root)
    obj = bpy.data.objects[example_scene.CREATURE_NAMES["ant"]]
    settings = obj.procloco
    for name in ("speed", "step_height", "cycle_time", "gait_mode"):
        settings.property_unset(name)
    settings.legs.clear()
    _select_only(obj)
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    assert settings.gait_mode == "AUTO"
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    job = generate.prepare(bpy.context, obj)
    for _ in generate.simulate(job):
        pass
    assert job.auto_gait is not None
    assert float(settings.speed) == pytest.approx(job.auto_gait.top_speed(), rel=1e-6)
    terrain = bpy.data.collections["Terrain"].objects
    solid = [o for o in terrain if o.procloco_role != "IGNORE"]
    avoid = [o for o in terrain if o.procloco_role == "AVOID" and o.animation_data is None]
    m = _measure_on(obj, job, solid, avoid)
    m.pop("ends")
    check_thresholds(without_pops(m))
    assert m["travel"] > 2.0 * m["scale"], m
    check_no_pops(m)
