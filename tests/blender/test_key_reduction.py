# SPDX-License-Identifier: GPL-3.0-or-later
"""Key Reduction through the real operators: the posed rig with the reduced keys against the
posed rig with a key on every frame, both evaluated through the depsgraph.

The example wolf walks three gait cycles; Generate Locomotion and Bake Secondary Motion run
once with every key and once with Key Reduction on (built once for the module).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import actions, cli
from procloco_addon.blender.locomotion import generate
from procloco_addon.core import keyfit
from tests.blender import pose_eval, test_generate
from tools.examples import creatures

pytestmark = pytest.mark.blender

FRAMES = (1, 72)  # three cycles of the wolf's walk at 24 fps
FOOT_TOL = 0.001
ANGLE_TOL = math.radians(0.5)


def _select_only(obj: Any) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def _scene() -> Any:
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=12.0)
    wolf = creatures.build_wolf(bpy.context.scene)
    _select_only(wolf)
    s = wolf.procloco
    s.use_scene_range = False
    s.frame_start, s.frame_end = FRAMES
    # the example wolf's walk (tools/examples/creatures.py)
    s.speed, s.step_height = 0.8, 0.08
    return wolf


def _key_count(obj: Any) -> int:
    return sum(fx.size for _ch, fx, _v in actions.read_channels(obj.animation_data.action, obj))


def _keyed_frames(obj: Any, bone: str) -> list[set[int]]:
    """Per F-curve of ``bone``, the frames it has keys on."""
    prefix = f'pose.bones["{bone}"]'
    return [set(np.round(fx).astype(int).tolist())
            for ch, fx, _v in actions.read_channels(obj.animation_data.action, obj)
            if ch.data_path.startswith(prefix)]


@dataclass
class Walks:
    frames: list[int]
    names: list[str]  # deform bones
    feet: list[str]  # each leg's end-effector and toe
    legs: list[list[str]]
    full: np.ndarray  # (F, B, 4, 4) world, every frame keyed
    reduced: np.ndarray
    keys_full: int
    keys_reduced: int
    report: str
    leg_keys: dict[str, list[set[int]]]
    bake_full: np.ndarray
    bake_reduced: np.ndarray
    bake_keys: tuple[int, int]
    foot_tails: np.ndarray  # (F, legs, 3) world tails of the end-effectors, every frame keyed
    motion: dict[str, Any]  # the design's motion checks measured on the reduced walk


@pytest.fixture(scope="module")
def walks(procloco_registered: Any) -> Walks:
    wolf = _scene()
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    frames = list(range(FRAMES[0], FRAMES[1] + 1))
    legs = [[*creatures.WOLF_LEGS[k]] for k in range(4)]
    legs = [leg[1:] if leg[0].startswith("shoulder") else leg for leg in legs]
    names = [b.name for b in wolf.data.bones if b.use_deform]
    bones = wolf.data.bones
    feet = [b for item in wolf.procloco.legs for b in (item.end, *(c.name for c in bones[item.end].children))]
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    full = pose_eval.pose_matrices(wolf, frames, names)
    keys_full = _key_count(wolf)
    _heads, foot_tails = pose_eval.bone_heads_tails(wolf, frames, [leg[-2] for leg in legs])
    wolf.procloco_keys.use_key_reduction = True
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    reduced = pose_eval.pose_matrices(wolf, frames, names)
    keys_reduced = _key_count(wolf)
    # The design's motion checks on the posed reduced walk (the same walk again, simulated
    # for the plan the checks compare with: same settings, same seed).
    job = generate.prepare(bpy.context, wolf)
    for _fraction in generate.simulate(job):
        pass
    motion = test_generate._measure_on(wolf, job, [bpy.data.objects["Plane"]], [])
    report = f"{wolf.procloco_keys.keys_before} {wolf.procloco_keys.keys_after}"
    leg_keys = {b: _keyed_frames(wolf, b) for leg in legs for b in leg}
    # Bake Secondary Motion (the tail) on the walk, with every key and reduced.
    assert bpy.ops.procloco.suggest_secondary_chains() == {"FINISHED"}
    wolf.procloco_keys.use_key_reduction = False
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    bake_full = pose_eval.pose_matrices(wolf, frames, names)
    bake_keys_full = _key_count(wolf)
    wolf.procloco_keys.use_key_reduction = True
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    bake_reduced = pose_eval.pose_matrices(wolf, frames, names)
    return Walks(frames, names, feet, legs, full, reduced, keys_full, keys_reduced, report, leg_keys,
                 bake_full, bake_reduced, (bake_keys_full, _key_count(wolf)), foot_tails, motion)


def _errors(w: Walks, full: np.ndarray, reduced: np.ndarray) -> tuple[float, float]:
    """Worst foot distance (head and tail) and worst bone turn between two posed runs."""
    lengths = np.array([bpy.data.objects["Wolf"].data.bones[n].length for n in w.names])
    feet = [w.names.index(f) for f in w.feet if f in w.names]

    def tails(m: np.ndarray) -> np.ndarray:
        return m[..., :3, 3] + m[..., :3, 1] * lengths[None, :, None]

    heads = full[:, feet][..., :3, 3] - reduced[:, feet][..., :3, 3]
    dist = max(float(np.linalg.norm(heads, axis=-1).max()),
               float(np.linalg.norm(tails(full)[:, feet] - tails(reduced)[:, feet], axis=-1).max()))
    r0 = full[..., :3, :3] / np.linalg.norm(full[..., :3, :3], axis=-2, keepdims=True)
    r1 = reduced[..., :3, :3] / np.linalg.norm(reduced[..., :3, :3], axis=-2, keepdims=True)
    cos = (np.einsum("...ij,...ij->...", r0, r1) - 1.0) / 2.0
    return dist, float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max())


def test_the_reduced_walk_stays_within_the_tolerances_on_the_posed_rig(walks: Walks) -> None:
    dist, angle = _errors(walks, walks.full, walks.reduced)
    assert dist <= FOOT_TOL
    assert angle <= math.degrees(ANGLE_TOL)
    # not trivially: the reduced curves do differ from the full ones between their keys
    assert dist > 1e-6


def test_the_reduced_walk_passes_the_designs_motion_checks(walks: Walks) -> None:
    # stance slide, penetration, bone lengths, reach, extension, gait phases, no pops
    test_generate.check_thresholds(walks.motion)


def test_the_reduced_walk_has_far_fewer_keys(walks: Walks) -> None:
    # measured: 4.4x on this walk (4.1x on the example wolf of examples.blend, bench_blender)
    assert walks.keys_full >= 4.0 * walks.keys_reduced
    assert walks.report == f"{walks.keys_full} {walks.keys_reduced}"


def test_every_contact_is_a_key_of_its_leg(walks: Walks) -> None:
    # Contacts measured on the posed rig with every frame keyed: a foot is planted while its
    # end-effector's tail stays put from one frame to the next.
    moved = np.linalg.norm(np.diff(walks.foot_tails, axis=0), axis=-1)  # (F - 1, legs)
    checked = 0
    for k, leg in enumerate(walks.legs):
        still = moved[:, k] < 1e-6  # a planted foot is still to the micrometre
        for f in range(1, still.size):
            if still[f] == still[f - 1]:
                continue
            contact = walks.frames[f]  # touches down at frame f, or lifts off after it
            checked += 1
            for bone in leg:
                for keyed in walks.leg_keys[bone]:
                    assert contact in keyed, f"{bone}: contact at frame {contact} is not a key"
    assert checked >= 8  # four legs, at least one step each


def test_the_reduced_bake_stays_within_the_tolerances(walks: Walks) -> None:
    dist, angle = _errors(walks, walks.bake_full, walks.bake_reduced)
    assert dist <= FOOT_TOL
    assert angle <= math.degrees(ANGLE_TOL)
    full, reduced = walks.bake_keys
    assert full >= 4.0 * reduced  # measured 4.6x


@pytest.mark.slow
def test_the_example_wolf_has_4x_fewer_keys_and_passes_the_motion_checks(empty_scene: Any,
                                                                         repo_root: Path) -> None:
    bpy.ops.wm.open_mainfile(filepath=str(repo_root / "examples.blend"))
    wolf = bpy.data.objects["Wolf"]
    _select_only(wolf)
    wolf.procloco_keys.use_key_reduction = True
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    keys = wolf.procloco_keys
    assert keys.within
    assert keys.keys_before >= 4.0 * _key_count(wolf)  # measured 4.1x
    job = generate.prepare(bpy.context, wolf)
    for _fraction in generate.simulate(job):
        pass
    terrain = bpy.data.collections["Terrain"].objects
    solid = [o for o in terrain if o.procloco_role != "IGNORE"]
    avoid = [o for o in terrain if o.procloco_role == "AVOID" and o.animation_data is None]
    m = test_generate._measure_on(wolf, job, solid, avoid)
    test_generate.check_thresholds(m)


def test_blender_plays_the_written_curves_as_the_core_evaluates_them(empty_scene: Any) -> None:
    wolf = creatures.build_wolf(empty_scene)
    action = actions.new_action(wolf)
    actions.assign_action(wolf, action)
    co = np.array([[1.0, 0.0], [5.0, 0.8], [6.0, -0.3], [20.0, 0.1]])
    # uneven handles, one pair overlapping in time (Blender shortens them)
    hl = np.array([[0.0, 0.0], [3.0, 1.2], [5.9, -0.5], [12.0, 0.6]])
    hr = np.array([[4.0, 0.2], [8.0, 0.1], [14.0, 0.0], [21.0, 0.1]])
    channel = actions.Channel('pose.bones["spine.004"].location', 2, "spine.004")
    assert actions.write_bezier_channels(action, wolf, [channel], [(co, hl, hr)]) == 4
    fcurve = next(fc for fc in (action.fcurves if not actions.is_slotted() else
                                action.layers[0].strips[0].channelbag(action.slots[0]).fcurves)
                  if fc.data_path == channel.data_path and fc.array_index == 2)
    x = np.linspace(0.0, 21.0, 211)
    played = np.array([fcurve.evaluate(float(f)) for f in x])
    assert np.abs(played - keyfit.evaluate_bezier(keyfit.BezierCurve(co, hl, hr), x)).max() < 1e-5


def test_the_settings_are_saved_in_the_blend_file(empty_scene: Any, tmp_path: Path) -> None:
    wolf = creatures.build_wolf(empty_scene)
    keys = wolf.procloco_keys
    assert not keys.use_key_reduction
    assert keys.foot_tolerance == pytest.approx(0.001)
    assert keys.angle_tolerance == pytest.approx(math.radians(0.5))
    keys.use_key_reduction = True
    keys.foot_tolerance = 0.002
    keys.angle_tolerance = math.radians(1.0)
    path = tmp_path / "keys.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    keys = bpy.data.objects["Wolf"].procloco_keys
    assert keys.use_key_reduction
    assert keys.foot_tolerance == pytest.approx(0.002)
    assert keys.angle_tolerance == pytest.approx(math.radians(1.0))


def test_the_batch_command_reduces_and_prints_the_key_counts(
    procloco_registered: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    wolf = _scene()
    status = cli.main(["generate", "--rig", "Wolf", "--frames", "1", "30", "--key-reduction",
                       "--foot-tolerance", "0.002", "--angle-tolerance", "1"])
    assert status == 0
    printed = capsys.readouterr().out
    line = next(ln for ln in printed.splitlines() if "Wolf: Key Reduction:" in ln)
    counts = line.split("Key Reduction: ")[1].split(" keys")[0].split(" -> ")
    before, after = (int(n.replace(",", "")) for n in counts)
    assert after < before
    assert _key_count(wolf) == after
    assert wolf.procloco_keys.foot_tolerance == pytest.approx(0.002)
    assert wolf.procloco_keys.angle_tolerance == pytest.approx(math.radians(1.0))


def test_the_reduced_biped_walk_stays_within_the_tolerances(empty_scene: Any) -> None:
    import addon_utils

    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, -6.0, 0.0))
    floor = bpy.context.active_object
    floor.scale = (6.0, 16.0, 1.0)
    bpy.ops.object.transform_apply(scale=True)
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    rig = bpy.context.active_object
    _select_only(rig)
    assert bpy.ops.procloco.make_biped_clips() == {"FINISHED"}
    goal = bpy.data.objects.new("Goal", None)
    bpy.context.scene.collection.objects.link(goal)
    goal.location = (1.2, -4.0, 0.0)
    rig.procloco_biped.goal = goal
    _select_only(rig)
    assert bpy.ops.procloco.plan_biped_footsteps() == {"FINISHED"}
    action = rig.animation_data.action
    first, last = (round(f) for f in action.frame_range)
    frames = list(range(first, last + 1))
    names = [b.name for b in rig.data.bones if b.use_deform]
    full = pose_eval.pose_matrices(rig, frames, names)
    keys_full = _key_count(rig)
    feet = ["foot.L", "foot.R"]
    _heads, foot_tails = pose_eval.bone_heads_tails(rig, frames, feet)
    rig.procloco_keys.use_key_reduction = True
    assert bpy.ops.procloco.plan_biped_footsteps() == {"FINISHED"}
    reduced = pose_eval.pose_matrices(rig, frames, names)
    keys_reduced = _key_count(rig)
    assert keys_full >= 4.0 * keys_reduced  # measured 5.3x
    foot = [names.index(f) for f in feet]
    lengths = np.array([rig.data.bones[f].length for f in feet])
    feet_full, feet_reduced = full[:, foot], reduced[:, foot]
    tails_reduced = feet_reduced[..., :3, 3] + feet_reduced[..., :3, 1] * lengths[None, :, None]
    assert np.linalg.norm(feet_full[..., :3, 3] - feet_reduced[..., :3, 3], axis=-1).max() <= FOOT_TOL
    assert np.linalg.norm(foot_tails - tails_reduced, axis=-1).max() <= FOOT_TOL
    r0 = full[..., :3, :3] / np.linalg.norm(full[..., :3, :3], axis=-2, keepdims=True)
    r1 = reduced[..., :3, :3] / np.linalg.norm(reduced[..., :3, :3], axis=-2, keepdims=True)
    cos = (np.einsum("...ij,...ij->...", r0, r1) - 1.0) / 2.0
    assert np.arccos(np.clip(cos, -1.0, 1.0)).max() <= ANGLE_TOL


def test_the_panel_shows_the_switch_the_tolerances_and_the_last_counts(empty_scene: Any) -> None:
    from procloco_addon.blender.keys.panel import PROCLOCO_PT_key_reduction
    from tests.blender.ui_recorder import draw_panel, draw_panel_header

    wolf = creatures.build_wolf(empty_scene)
    _select_only(wolf)
    header = draw_panel_header(PROCLOCO_PT_key_reduction, bpy.context)
    assert [c.params.get("property") for c in header.walk() if c.method == "prop"] == ["use_key_reduction"]
    ui = draw_panel(PROCLOCO_PT_key_reduction, bpy.context)
    props = [c.params.get("property") for c in ui.walk() if c.method == "prop"]
    assert props == ["foot_tolerance", "angle_tolerance"]
    assert "Keys" not in ui.texts()  # nothing reduced yet
    keys = wolf.procloco_keys
    keys.keys_before, keys.keys_after = 7128, 1605
    keys.foot_error, keys.angle_error = 0.00084, math.radians(0.48)
    ui = draw_panel(PROCLOCO_PT_key_reduction, bpy.context)
    assert "Keys: 7,128 → 1,605 (4.4× fewer)" in ui.labels()
    assert "Feet within 0.84 mm, bones within 0.48°" in ui.labels()


def test_a_reduction_that_cannot_get_within_keeps_every_key(empty_scene: Any) -> None:
    from procloco_addon.blender.keys import reduce

    wolf = creatures.build_wolf(empty_scene)
    action = actions.new_action(wolf)
    actions.assign_generated_action(wolf, action)
    frames = np.arange(1.0, 31.0)
    t = frames / 24.0
    turn = 0.3 * np.sin(2 * np.pi * t) + 0.05 * np.sin(17.0 * t)
    quats = np.stack([np.cos(turn / 2), np.sin(turn / 2), 0 * t, 0 * t], axis=1)[:, None]
    actions.write_pose_bone_transforms(action, wolf, frames, ["thigh.L"], rotations=quats)
    names = ["thigh.L", "shin.L", "foot.L"]
    full = pose_eval.pose_matrices(wolf, frames.astype(int).tolist(), names)
    # one pass and no room at all: it cannot get there, so nothing is lost
    result = reduce.reduce_action(wolf, action, frames, ["foot.L"], foot_tolerance=1e-9,
                                  angle_tolerance=1e-9, max_passes=1)
    assert not result.within
    assert result.keys_after == result.keys_before == _key_count(wolf) == 4 * 30
    assert "kept all 120 keys" in result.describe()
    assert np.abs(pose_eval.pose_matrices(wolf, frames.astype(int).tolist(), names) - full).max() < 1e-6
    # with the default tolerances it reduces, within them
    result = reduce.reduce_action(wolf, action, frames, ["foot.L"])
    assert result.within
    assert result.keys_after < result.keys_before
    moved = pose_eval.pose_matrices(wolf, frames.astype(int).tolist(), names)
    assert np.linalg.norm(moved[:, 2, :3, 3] - full[:, 2, :3, 3], axis=-1).max() <= FOOT_TOL


def test_the_reduction_reports_progress_and_esc_during_it_changes_nothing(empty_scene: Any) -> None:
    wolf = _scene()
    wolf.procloco.frame_end = 36
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    wolf.procloco_keys.use_key_reduction = True
    job = generate.prepare(bpy.context, wolf)
    for _fraction in generate.simulate(job):
        pass
    # a full run: the reduction's passes move the progress on within the last fifth
    steps = generate.write_all_steps(bpy.context, [job])
    fractions = []
    try:
        while True:
            fractions.append(next(steps))
    except StopIteration as done:
        made = done.value
    assert all(a <= b for a, b in itertools.pairwise(fractions))
    assert len([f for f in fractions if 0.8 < f < 1.0]) >= 2
    assert wolf.procloco_keys.keys_after < wolf.procloco_keys.keys_before
    assert wolf.animation_data.action == made[0]
    names = [b.name for b in wolf.data.bones if b.use_deform]
    frames = list(range(1, 37))
    pose_before = pose_eval.pose_matrices(wolf, frames, names)
    n_actions = len(bpy.data.actions)
    # again, and Esc once the reduction has begun (its first step: the full pose evaluated)
    steps = generate.write_all_steps(bpy.context, [job])
    while next(steps) <= 0.8:
        pass
    steps.close()
    assert wolf.animation_data.action == made[0]
    assert len(bpy.data.actions) == n_actions
    assert np.abs(pose_eval.pose_matrices(wolf, frames, names) - pose_before).max() < 1e-6
