# SPDX-License-Identifier: GPL-3.0-or-later
"""Misuse and faults: no traceback reaches the user, a refusal changes nothing, nothing of the
user's is lost (NaN settings and terrain, tweak mode among several rigs, the batch command's
bad options, Clear giving the pose back, clear messages)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import actions, cli
from procloco_addon.blender.locomotion import generate
from tests.blender.scene_state import snapshot
from tools.examples import creatures

pytestmark = pytest.mark.blender


def _ground(size: float = 6.0, name: str = "Ground", z: float = 0.0) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, z))
    obj = bpy.context.active_object
    obj.name = name
    return obj


def _select(*objs: Any) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]


def _short_range(obj: Any, start: int = 1, end: int = 8) -> None:
    obj.procloco.use_scene_range = False
    obj.procloco.frame_start = start
    obj.procloco.frame_end = end


@pytest.fixture
def robot(empty_scene: Any) -> Any:
    _ground()
    obj = creatures.build_robot(empty_scene)
    _select(obj)
    _short_range(obj)
    return obj


def _refused(op: Any, match: str) -> None:
    """``op`` is refused with a message matching ``match`` (no traceback) and changes nothing."""
    before = snapshot()
    with pytest.raises(RuntimeError, match=match) as info:
        op()
    assert "Traceback" not in str(info.value), str(info.value)
    assert snapshot() == before


# ---------------------------------------------------------------------------------------
# 1. No traceback: NaN settings and terrain, the batch command


@pytest.mark.parametrize("name", ["speed", "step_height", "heading", "turn_rate", "cycle_time"])
def test_a_nan_setting_is_refused_up_front_by_name(robot: Any, name: str) -> None:
    setattr(robot.procloco, name, float("nan"))
    label = robot.procloco.bl_rna.properties[name].name
    _refused(bpy.ops.procloco.generate_locomotion, f"{label} of 'Robot' is not a number")


def test_a_nan_leg_setting_is_refused_by_leg(robot: Any) -> None:
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    robot.procloco.legs[1].swing_start = float("nan")
    _refused(bpy.ops.procloco.generate_locomotion, "Swing Start of leg .* of 'Robot' is not a number")


def test_terrain_with_non_finite_vertices_is_used_without_them(empty_scene: Any) -> None:
    verts = [(-3.0, -3.0, 0.0), (3.0, -3.0, 0.0), (3.0, 3.0, 0.0), (-3.0, 3.0, 0.0),
             (5.0, 5.0, 0.0), (6.0, 5.0, 0.0), (5.0, 6.0, 0.0)]
    mesh = bpy.data.meshes.new("Broken")
    mesh.from_pydata(verts, [], [(0, 1, 2, 3), (4, 5, 6)])
    mesh.vertices[5].co = (float("nan"), 5.0, 0.0)
    mesh.vertices[6].co = (float("inf"), 6.0, 0.0)
    ground = bpy.data.objects.new("Broken", mesh)
    empty_scene.collection.objects.link(ground)
    obj = creatures.build_robot(empty_scene)
    _select(obj)
    _short_range(obj)
    job = generate.prepare(bpy.context, obj)
    assert any("'Broken'" in w and "not finite" in w for w in job.warnings), job.warnings
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    assert actions.generated_action(obj) is not None


@pytest.mark.parametrize("argv", [
    ["--speed", "nan"], ["--speed", "inf"], ["--step-height", "nan"], ["--heading", "nan"],
    ["--heading", "inf"], ["--seed", "99999999999"], ["--seed", "-1"], ["--speed", "-1"],
    ["--step-height", "-0.1"], ["--resolution", "0", "0"], ["--frame-step", "0"],
])
def test_batch_command_refuses_bad_options_with_a_status(robot: Any, argv: list[str],
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    before = snapshot()
    status = cli.main(["generate", "--rig", "Robot", *argv])
    assert status == 2
    err = capsys.readouterr().err
    assert "error:" in err, err
    assert argv[0] in err, err
    assert "Traceback" not in err, err
    assert snapshot() == before


def test_batch_help_returns_zero(empty_scene: Any, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["--help"]) == 0
    assert "generate" in capsys.readouterr().out
    assert cli.main(["generate", "--help"]) == 0


def test_batch_command_turns_any_failure_into_a_status(robot: Any, monkeypatch: pytest.MonkeyPatch,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    def broken(*_args: Any, **_kwargs: Any) -> Any:
        raise ZeroDivisionError("a fault nobody foresaw")

    monkeypatch.setattr(generate, "generate", broken)
    before = snapshot()
    assert cli.main(["generate", "--rig", "Robot", "--speed", "0.2"]) == 1
    assert "a fault nobody foresaw" in capsys.readouterr().err
    assert snapshot() == before


def test_an_unforeseen_fault_in_an_operator_is_reported_not_raised(robot: Any,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    from procloco_addon.blender.locomotion import simulation

    def broken(_jobs: Any) -> Any:
        raise ZeroDivisionError("a fault nobody foresaw")
        yield 0.0

    # the one loop every Generate runs (a single rig's ``run`` too): all rigs of a batch
    monkeypatch.setattr(simulation, "run_all", broken)
    _refused(bpy.ops.procloco.generate_locomotion, "a fault nobody foresaw")


# ---------------------------------------------------------------------------------------
# 2. Clear gives the rig back


def test_clear_gives_back_the_pose_of_every_bone_it_keyed(empty_scene: Any) -> None:
    _ground()
    wolf = creatures.build_wolf(empty_scene)
    _select(wolf)
    _short_range(wolf)
    # A hand-posed, unkeyed neck and hind leg.
    for name, angle in (("spine.006", 0.3), ("thigh.L", -0.4)):
        pb = wolf.pose.bones[name]
        pb.rotation_mode = "QUATERNION"
        pb.rotation_quaternion = (np.cos(angle / 2), np.sin(angle / 2), 0.0, 0.0)
    wolf.pose.bones["spine.004"].location = (0.0, 0.01, 0.02)
    before = snapshot()
    for _ in range(2):  # a re-generation still goes back to the pose the user had
        assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
        bpy.context.scene.frame_set(5)
    assert snapshot()["per_object"]["Wolf"]["pose"] != before["per_object"]["Wolf"]["pose"]
    assert bpy.ops.procloco.clear_generated_action() == {"FINISHED"}
    bpy.context.scene.frame_set(before["frame"][0])
    assert snapshot() == before


# ---------------------------------------------------------------------------------------
# 3. All or nothing over the selected rigs


def test_a_rig_in_nla_tweak_mode_among_selected_rigs_changes_nothing(robot: Any) -> None:
    other = creatures.build_robot(bpy.context.scene, name="Robot2", location=(1.0, 0.0, 0.0))
    _short_range(other)
    user = bpy.data.actions.new("Robot2 walk")
    other.animation_data_create()
    other.animation_data.action = user
    other.keyframe_insert("location", frame=1)
    track = other.animation_data.nla_tracks.new()
    track.strips.new("walk", 1, user)
    other.animation_data.action = None
    track.strips[0].select = True
    other.animation_data.use_tweak_mode = True
    assert other.animation_data.use_tweak_mode
    _select(robot, other)
    _refused(bpy.ops.procloco.generate_locomotion, "'Robot2' is in NLA tweak mode")


def test_a_write_failing_on_the_second_rig_takes_back_the_first(robot: Any,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    other = creatures.build_robot(bpy.context.scene, name="Robot2", location=(1.0, 0.0, 0.0))
    _short_range(other)
    _select(robot, other)
    real = actions.assign_generated_action

    def fail_on_second(obj: Any, action: Any, **kwargs: Any) -> None:
        if obj.name == "Robot2":
            raise actions.ActionError("cannot write Robot2")
        real(obj, action, **kwargs)

    monkeypatch.setattr(actions, "assign_generated_action", fail_on_second)
    _refused(bpy.ops.procloco.generate_locomotion, "cannot write Robot2")


# ---------------------------------------------------------------------------------------
# 6. A refusal leaves the settings as they were


def test_a_refused_bake_does_not_leave_the_suggested_chains(empty_scene: Any) -> None:
    _ground()
    wolf = creatures.build_wolf(empty_scene)
    _select(wolf)
    _short_range(wolf, 5, 5)
    assert not len(wolf.procloco_secondary.chains)
    _refused(bpy.ops.procloco.bake_secondary_motion, r"is one frame \(5\): baking needs")


@pytest.mark.parametrize("which", [["--rig", "Robot"], ["--all"]])
def test_a_failed_batch_generate_leaves_the_settings_as_they_were(
    empty_scene: Any, which: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    obj = creatures.build_robot(empty_scene)  # no ground anywhere
    creatures.build_robot(empty_scene, name="Robot2", location=(1.0, 0.0, 0.0))
    before = snapshot()
    status = cli.main(["generate", *which, "--frames", "3", "9", "--speed", "0.7", "--step-height", "0.02",
                       "--seed", "5", "--no-spine", "--bake-secondary", "--gait", "pentapod_robot"])
    assert status == 1
    assert "No ground mesh found" in capsys.readouterr().err
    assert snapshot() == before
    assert obj.procloco.speed != pytest.approx(0.7)


# ---------------------------------------------------------------------------------------
# 9. Messages that say what is wrong


def test_a_one_frame_range_is_named_as_such(robot: Any) -> None:
    _short_range(robot, 4, 4)
    _refused(bpy.ops.procloco.generate_locomotion, r"one frame \(4\)")


def test_a_nan_rig_location_is_named(robot: Any) -> None:
    robot.location.x = float("nan")
    _refused(bpy.ops.procloco.generate_locomotion, "placement of 'Robot' is not finite")


def test_a_hidden_ground_is_named(robot: Any) -> None:
    bpy.data.objects["Ground"].hide_set(True)
    _refused(bpy.ops.procloco.generate_locomotion, "'Ground' is hidden")


def test_a_rig_far_above_the_ground_is_refused(empty_scene: Any) -> None:
    _ground(size=400.0, z=-100.0)
    obj = creatures.build_robot(empty_scene)
    _select(obj)
    _short_range(obj)
    _refused(bpy.ops.procloco.generate_locomotion, "'Robot' stands 100.* above the ground")


# ---------------------------------------------------------------------------------------
# 10. Minor


def test_generating_again_supersedes_the_earlier_generation(robot: Any) -> None:
    for _ in range(3):
        assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    made = [a for a in bpy.data.actions if actions.is_generated(a)]
    assert [a.name for a in made] == ["Robot ProcLoco"]
    # A take the animator protected is kept.
    made[0].use_fake_user = True
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    assert len([a for a in bpy.data.actions if actions.is_generated(a)]) == 2
    assert bpy.ops.procloco.clear_generated_action() == {"FINISHED"}
    assert [a.name for a in bpy.data.actions if actions.is_generated(a)] == ["Robot ProcLoco"]


def test_save_creates_missing_folders(robot: Any, tmp_path: Path) -> None:
    path = tmp_path / "new" / "folder" / "walk.blend"
    assert cli.main(["generate", "--rig", "Robot", "--save", str(path)]) == 0
    assert path.exists()


def test_numbers_on_the_command_line_are_used_as_given_or_refused(robot: Any) -> None:
    assert cli.main(["generate", "--rig", "Robot", "--speed", "0.25", "--step-height", "0.03"]) == 0
    assert robot.procloco.speed == pytest.approx(0.25)
    assert robot.procloco.step_height == pytest.approx(0.03)


# ---------------------------------------------------------------------------------------
# 8. Biped goals


@pytest.fixture(scope="module")
def human_file(tmp_path_factory: pytest.TempPathFactory, procloco_registered: Any) -> Path:
    """A floor, a Rigify human with its example clips and a wall, saved once for the module."""
    from tests.blender.test_biped import _human, _plane

    bpy.ops.wm.read_homefile(use_empty=True)
    _plane("Floor", (6.0, 16.0), (0.0, -6.0, 0.0))
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(2.0, -6.0, 1.0))
    bpy.context.active_object.name = "Wall"
    bpy.context.active_object.scale = (0.2, 4.0, 2.0)
    _human()
    path = tmp_path_factory.mktemp("biped") / "human.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


@pytest.mark.parametrize(("where", "match"), [
    ((1.0, -7.0, 5.0), "'Goal' is 5 m above the walkable surface"),
    ((2.0, -6.0, 1.0), "'Goal' is 1 m below the walkable surface"),  # in the wall, under its top
    ((30.0, 0.0, 0.0), "'Goal' is not on a walkable surface"),
    ((0.05, 0.0, 0.0), "'Goal' is where 'metarig' already stands"),
])
def test_a_biped_goal_off_the_walkable_surface_or_at_the_start_is_refused(
    human_file: Path, where: tuple[float, float, float], match: str
) -> None:
    from tests.blender.test_biped import _goal

    bpy.ops.wm.open_mainfile(filepath=str(human_file))
    rig = bpy.data.objects["metarig"]
    rig.procloco_biped.goal = _goal(where)
    _select(rig)
    _refused(bpy.ops.procloco.plan_biped_footsteps, match)


def test_a_nan_biped_setting_is_refused_by_name(human_file: Path) -> None:
    from tests.blender.test_biped import _goal

    bpy.ops.wm.open_mainfile(filepath=str(human_file))
    rig = bpy.data.objects["metarig"]
    rig.procloco_biped.goal = _goal((1.2, -7.0, 0.0))
    rig.procloco_biped.crossfade = float("nan")
    _select(rig)
    _refused(bpy.ops.procloco.plan_biped_footsteps, "Cross-fade of 'metarig' is not a number")


# ---------------------------------------------------------------------------------------
# 4. Animated terrain: work and memory follow what changes


def _grid_ground(subdivisions: int = 60) -> Any:
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=subdivisions, y_subdivisions=subdivisions, size=8.0)
    ground = bpy.context.active_object
    ground.name = "Ground"
    return ground


def test_a_rigidly_moving_ground_is_read_once_and_placed_per_frame(empty_scene: Any) -> None:
    ground = _grid_ground()
    ground.keyframe_insert("location", frame=1)
    ground.location.z = 0.001
    ground.keyframe_insert("location", frame=8)
    obj = creatures.build_robot(empty_scene)
    _select(obj)
    _short_range(obj)
    job = generate.prepare(bpy.context, obj)
    terrain = job.terrain
    assert terrain is not None
    assert terrain.dynamic_index == (0,)
    motion = terrain.motion[0]
    assert motion.vertices is None  # no per-frame copy of the mesh
    assert motion.relative is not None
    assert motion.relative.shape == (8, 4, 4)
    probe = np.array([[0.3, -0.2]])
    first = terrain.environment.height_at(probe)[0]
    terrain.apply_frame(7)
    assert terrain.environment.height_at(probe)[0] - first == pytest.approx(0.001, abs=1e-6)
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}


def test_a_deforming_ground_beyond_the_memory_budget_is_refused(empty_scene: Any,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    from procloco_addon.blender import scene_terrain

    ground = _grid_ground()
    wave = ground.modifiers.new("Wave", "WAVE")
    wave.height = 0.01
    obj = creatures.build_robot(empty_scene)
    _select(obj)
    _short_range(obj, 1, 40)
    monkeypatch.setattr(scene_terrain, "DEFORM_BUDGET_BYTES", 1 << 16)
    _refused(bpy.ops.procloco.generate_locomotion, "'Ground' deforms .* Shorten the frame range")


def test_escape_while_the_terrain_is_read_changes_nothing(empty_scene: Any) -> None:
    from types import SimpleNamespace

    from procloco_addon.blender.locomotion.ops import PROCLOCO_OT_generate_locomotion as Op
    from tests.blender.test_modal import _context_for, _drive_modal

    ground = _grid_ground()
    ground.keyframe_insert("location", frame=1)
    ground.location.x = 0.5
    ground.keyframe_insert("location", frame=30)
    obj = creatures.build_robot(empty_scene)
    _select(obj)
    _short_range(obj, 1, 30)
    empty_scene.frame_set(1)
    before = snapshot()
    context = _context_for(empty_scene)
    me = _drive_modal(Op, context, 3, _jobs=[])
    assert all(job.terrain is None for job in me._jobs)  # still reading the terrain
    assert empty_scene.frame_current != before["frame"][0]  # playing the range
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert snapshot() == before


def _run_until(me: Any, text: str, fraction: float) -> list[tuple[str, float]]:
    """Drive a modal operator stand-in's steps until one says ``text`` at ``fraction`` or more."""
    seen = []
    for step in me._steps:
        seen.append(step)
        if step[0] == text and step[1] >= fraction:
            break
    return seen


def test_generate_writes_with_progress_and_escape_while_writing_changes_nothing(empty_scene: Any) -> None:
    """Writing is the last tenth of Generate's progress, in steps (pose solving bone by
    bone, then keying); Esc there, with the new Action already keyed and assigned and the
    rig evaluated in its walk, deletes it and gives the rig back its Action and pose (a
    hand-posed, unkeyed leg included); run through, the same steps write the walk."""
    from types import SimpleNamespace

    from procloco_addon.blender.locomotion.ops import PROCLOCO_OT_generate_locomotion as Op
    from tests.blender.test_modal import _context_for, _drive_modal

    _ground(20.0)
    wolf = creatures.build_wolf(empty_scene)
    _select(wolf)
    _short_range(wolf, 1, 12)
    wolf.pose.bones["thigh.L"].rotation_mode = "XYZ"
    wolf.pose.bones["thigh.L"].rotation_euler = (0.3, 0.0, 0.1)  # posed by hand, not keyed
    empty_scene.frame_set(1)
    before = snapshot()
    context = _context_for(empty_scene)
    me = _drive_modal(Op, context, 0, _jobs=[], _made=None)
    seen = _run_until(me, "writing the Actions", 0.954)  # keyed and assigned: 0.955
    writing = [f for text, f in seen if text == "writing the Actions"]
    assert len(writing) >= 10, writing  # a step per leg and per bone, then the keys
    assert writing == sorted(writing)
    assert writing[0] >= 0.9
    assert writing[-1] < 1.0
    assert actions.generated_action(wolf) is not None  # keyed and assigned already
    empty_scene.frame_set(6)  # the UI redraws the rig in its new walk between two ticks
    assert snapshot()["per_object"][wolf.name]["pose"] != before["per_object"][wolf.name]["pose"]
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert snapshot() == before
    # The same steps run through write the walk.
    me = _drive_modal(Op, context, 0, _jobs=[], _made=None)
    assert [text for text, _f in me._steps][-1] == "writing the Actions"
    assert me._finish(context) == {"FINISHED"}
    assert actions.generated_action(wolf) is not None


def test_escape_while_a_bake_writes_changes_nothing(empty_scene: Any) -> None:
    """Bake Secondary Motion's write step is in steps too; Esc there, over an earlier bake,
    leaves the scene as it was (the earlier bake kept and assigned, the pose as before)."""
    from types import SimpleNamespace

    from procloco_addon.blender.secondary.ops import PROCLOCO_OT_bake_secondary_motion as Op
    from tests.blender.test_modal import _context_for, _drive_modal
    from tests.blender.test_secondary import _frames, _key_object_path, _lizard

    lizard = _lizard(empty_scene)
    _frames(empty_scene, 1, 24)
    _key_object_path(lizard, 24, 1.0)
    assert bpy.ops.procloco.bake_secondary_motion() == {"FINISHED"}
    empty_scene.frame_set(3)
    before = snapshot()
    context = _context_for(empty_scene)
    me = _drive_modal(Op, context, 0, _job=None, _made=None)
    seen = _run_until(me, "writing the Action", 0.0)
    assert seen[-1][0] == "writing the Action"
    assert actions.generated_action(lizard) is not None
    empty_scene.frame_set(9)
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert snapshot() == before


# ---------------------------------------------------------------------------------------
# 5. A long bake simulates in slices: progress, and Esc with nothing written


def test_a_long_bake_simulates_in_slices_and_escape_there_changes_nothing(
    empty_scene: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    from types import SimpleNamespace

    from procloco_addon.blender.secondary import bake
    from procloco_addon.blender.secondary.ops import PROCLOCO_OT_bake_secondary_motion as Op
    from tests.blender.test_modal import TIMER, _context_for
    from tests.blender.test_secondary import _frames, _key_object_path, _lizard

    lizard = _lizard(empty_scene)
    _frames(empty_scene, 1, 72)  # 3 s: 360 pendulum steps at 120 Hz, a report every 50
    monkeypatch.setattr(bake, "SLICE_STEPS", 50)
    _key_object_path(lizard, 24, 3.0)
    assert bpy.ops.procloco.suggest_secondary_chains() == {"FINISHED"}
    empty_scene.frame_set(1)
    before = snapshot()
    # The simulation alone reports its progress in slices and ends as simulate() does.
    job = bake.prepare(bpy.context, lizard)
    for _fraction in bake.sample(bpy.context, job):
        pass
    fractions = list(bake.simulate_steps(job))
    assert len(fractions) >= 5
    assert fractions == sorted(fractions)
    assert 0.0 < fractions[0] < 1.0
    assert job.swung is not None
    # The operator shows "swinging the chains" steps and Esc there leaves the scene as it was.
    context = _context_for(empty_scene)
    me = SimpleNamespace(report=lambda *_a: None, _timer=None, _steps=None, _tick_budget_s=0.0,
                         _cancelled_message="cancelled", _run_errors=Op._run_errors, _job=None)
    for name in ("_prepare", "_run", "_stop", "_abort", "_discard", "_finish"):
        setattr(me, name, getattr(Op, name).__get__(me))
    assert me._prepare(context)
    texts = []
    me._steps = me._run(context, True)
    for text, _fraction in me._steps:
        texts.append(text)
        if text == "swinging the chains":
            break
    assert texts[-1] == "swinging the chains"
    assert me._job.swung is None  # stopped midway through the pendulums
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert Op.modal(me, context, TIMER) == {"PASS_THROUGH"}
    assert snapshot() == before


# ---------------------------------------------------------------------------------------
# 7. Size invariance


@pytest.mark.slow
def test_the_same_rig_at_any_size_walks_the_same_walk_to_scale(empty_scene: Any) -> None:
    """The Rigify wolf built at x0.01 (7 mm legs), x1 and x100 on the same terrain scaled alike,
    with the gait circles and every effect at its default (flexible spine, pelvis physics),
    speeds in leg lengths per second: the walks agree, back
    at unit scale, to 0.1 mm (1.4e-4 leg lengths), and each meets the motion thresholds
    scaled to its size."""
    from tests.blender.test_generate import _generate, _leg_length, _measure, _terrain

    walks = {}
    for scale in (0.01, 1.0, 100.0):
        bpy.ops.wm.read_homefile(use_empty=True)
        wolf = creatures.build_wolf(bpy.context.scene, scale=scale)
        leg = _leg_length(wolf)
        terrain = _terrain(leg)
        wolf.procloco.speed = 0.8 * leg
        wolf.procloco.step_height = 0.25 * leg
        wolf.procloco.gait_mode = "CIRCLES"  # (Auto chooses the gait by Froude number: not to scale)
        assert wolf.procloco.use_spine
        assert wolf.procloco.use_pelvis_physics
        job = _generate(wolf, frames=48)
        m = _measure(wolf, job, terrain)
        size = leg / 0.7325
        assert m["slide"] <= 0.002 * size, m
        assert m["reach"] <= 0.01 * size, m
        assert m["penetration"] <= 0.005 * size, m
        assert m["extension"] <= 1.0 + 1e-6, m
        assert m["travel"] > 1.5 * leg, m
        walks[scale] = (job.result.feet / scale, job.result.body[:, :3, 3] / scale)
    for scale in (0.01, 100.0):
        assert np.abs(walks[scale][0] - walks[1.0][0]).max() < 1e-4, scale
        assert np.abs(walks[scale][1] - walks[1.0][1]).max() < 1e-4, scale


def test_a_rig_scaled_as_an_object_walks_as_the_rig_scaled_in_its_bones(empty_scene: Any) -> None:
    """The example robot scaled x20 and x0.05 as an object (bones untouched) and built at x20
    in its bones, speed and step height scaled alike, turning to a heading 2.1 rad from the
    way it faces: on the evaluated pose, every leg joint relative to the rig's origin is the
    unit robot's scaled, to 1e-4 leg lengths (the evaluated matrices are float32), and each
    meets its reach."""
    from tests.blender.pose_eval import leg_joints
    from tests.blender.test_generate import _measure_on

    frames = list(range(1, 25))
    posed = {}
    for how, scale in (("bones", 1.0), ("object", 20.0), ("object", 0.05), ("bones", 20.0)):
        bpy.ops.wm.read_homefile(use_empty=True)
        ground = _ground(400.0)
        robot = creatures.build_robot(bpy.context.scene, scale=scale if how == "bones" else 1.0)
        robot.location = (1.5 * scale, -0.5 * scale, 0.0)
        s = robot.procloco
        if how == "object":
            robot.scale = (scale, scale, scale)
            s.speed *= scale
            s.step_height *= scale
        s.heading = -2.12
        s.gait_mode = "CIRCLES"  # (Auto chooses the gait by Froude number: not to scale)
        _short_range(robot, frames[0], frames[-1])
        _select(robot)
        empty_scene = bpy.context.scene
        empty_scene.frame_set(1)
        assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
        job = generate.prepare(bpy.context, robot)
        for _fraction in generate.simulate(job):
            pass
        m = _measure_on(robot, job, [ground], [])
        leg = float(job.info.leg_length.mean())
        assert m["reach"] <= 0.01 * leg / 0.66, (how, scale, m)
        joints = leg_joints(robot, frames, [leg.bones for leg in job.info.legs])
        origin = np.array([1.5, -0.5, 0.0]) * scale
        posed[how, scale] = (np.stack(joints) - origin) / scale, leg / scale
    ref, leg = posed["bones", 1.0]
    for key, (joints, _leg) in posed.items():
        assert np.abs(joints - ref).max() < 1e-4 * leg, key


def test_a_slow_walk_turning_to_its_heading_keeps_its_feet_in_reach(robot: Any) -> None:
    """The example robot at 0.1 m/s (0.15 leg lengths/s), asked to head 2.1 rad from the way
    it faces: its feet stay within reach (1 cm) of where the core put them, and the pelvis
    bounces gently. (The turn on the spot speeds its gait up 4.8 times from the first frame;
    the pelvis particles' orbit, made for the slow cycle, flew the body 1.6 m up until it is
    re-made for the new rate.)"""
    from tests.blender.test_generate import _measure_on

    robot.procloco.speed = 0.1
    robot.procloco.heading = -2.12
    _short_range(robot, 1, 24)
    bpy.context.scene.frame_set(1)
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    job = generate.prepare(bpy.context, robot)
    for _fraction in generate.simulate(job):
        pass
    m = _measure_on(robot, job, [bpy.data.objects["Ground"]], [])
    assert m["reach"] <= 0.01, m
    height = job.result.body[:, 2, 3]
    assert float(np.ptp(height)) < 0.05 * float(job.info.leg_length.mean()), height
