# SPDX-License-Identifier: GPL-3.0-or-later
"""The quality panel: figures measured on the posed rig after Generate Locomotion, the
jump-to-worst-frame buttons, red rows above the thresholds, the batch command's line.

Every figure the panel shows is checked against this file's own measurement of the posed
rig (``tests/blender/pose_eval.py``: depsgraph evaluation, ray casts into the ground mesh,
plain loops), never against the core's numbers. The walk's plan (which feet the gait
plants, the targets it set) comes from a simulation run before the operator: the same seed
gives the same walk.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest
from mathutils import Matrix

from procloco_addon.blender import cli
from procloco_addon.blender.locomotion import generate
from procloco_addon.blender.quality import measure
from procloco_addon.blender.quality.ops import PROCLOCO_OT_jump_to_worst_frame
from procloco_addon.blender.quality.panel import PROCLOCO_PT_quality
from tests.blender.pose_eval import bone_heads_tails, leg_joints, ray_heights_over_time
from tests.blender.test_generate import _select_only
from tests.blender.ui_recorder import draw_panel
from tools.examples import creatures

pytestmark = pytest.mark.blender

FRAMES = (1, 36)
KEYS = ("slide", "penetration", "reach", "few_feet_down", "over_stretched")
#: How closely the panel's figures and this file's agree (metres; see the first test).
_TOL = {"slide": 2e-6, "penetration": 5e-5, "reach": 2e-6}


def _scene_with_wolf(ground_size: float = 8.0) -> Any:
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=ground_size)
    bpy.context.active_object.name = "Ground"
    wolf = creatures.build_wolf(bpy.context.scene)
    wolf.procloco.use_scene_range = False
    wolf.procloco.frame_start, wolf.procloco.frame_end = FRAMES
    _select_only(wolf)
    return wolf


def _plan(obj: Any) -> generate.Job:
    """The walk the operator is about to write (simulated, not written)."""
    job = generate.prepare(bpy.context, obj)
    for _ in generate.simulate(job):
        pass
    return job


def _independent(obj: Any, job: generate.Job) -> dict[str, tuple[float, int]]:
    """Each figure as ``(value, worst scene frame)`` from the posed rig, measured here."""
    info = job.info
    res = job.result
    frames = [int(f) for f in job.frames]
    joints = leg_joints(obj, frames, [leg.bones for leg in info.legs])
    ends = np.stack([j[:, -1] for j in joints], axis=1)  # (F, L, 3)
    hips = np.stack([j[:, 0] for j in joints], axis=1)
    n_frames, n_legs = ends.shape[:2]
    planted = ~res.swing
    out: dict[str, tuple[float, int]] = {}
    # Stance slide: distance from where each stance began, stance by stance.
    best = (0.0, frames[0])
    for k in range(n_legs):
        f = 0
        while f < n_frames:
            if not planted[f, k]:
                f += 1
                continue
            start = f
            while f < n_frames and planted[f, k]:
                d = float(np.sqrt(np.sum((ends[f, k] - ends[start, k]) ** 2)))
                if d > best[0]:
                    best = (d, frames[f])
                f += 1
    out["slide"] = best
    # The feet against ray casts into the ground: the end-effector stands its foot height
    # over the ground, the foot bones' heads and tails may touch it.
    foot = [b for leg in info.legs for b in leg.foot]
    fh, ft = bone_heads_tails(obj, frames, foot)
    ground = [bpy.data.objects["Ground"]]
    clearance = np.full((n_frames, n_legs), np.inf)
    depth = np.full((n_frames, n_legs), 0.0)
    col = 0
    for k, leg in enumerate(info.legs):
        points = [ends[:, k]]
        for _ in leg.foot:
            points += [fh[:, col], ft[:, col]]
            col += 1
        pts = np.stack(points, axis=1)  # (F, P, 3)
        heights = ray_heights_over_time(frames, pts[..., :2], ground)
        lift = np.zeros(pts.shape[1])
        lift[0] = info.foot_height[k]
        above = pts[..., 2] - heights - lift[None]
        clearance[:, k] = above.min(axis=1)
        depth[:, k] = np.maximum(-above.min(axis=1), 0.0)
    f, k = np.unravel_index(int(np.argmax(depth)), depth.shape)
    out["penetration"] = (float(depth[f, k]), frames[f])
    length = info.leg_length
    to_target = np.linalg.norm(res.feet - hips, axis=-1)
    miss = np.where(to_target <= length * (1.0 - 1e-6), np.linalg.norm(ends - res.feet, axis=-1), 0.0)
    f, k = np.unravel_index(int(np.argmax(miss)), miss.shape)
    out["reach"] = (float(miss[f, k]), frames[f])
    hanging = np.where(planted & (clearance > 0.005), clearance, -np.inf)
    f, k = np.unravel_index(int(np.argmax(hanging)), hanging.shape)
    out["few_feet_down"] = (float(np.any(hanging > 0.0, axis=1).sum()), frames[f])
    ratio = np.maximum(np.linalg.norm(ends - hips, axis=-1), to_target) / length
    f, k = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    out["over_stretched"] = (float(np.any(ratio > 1.0 + 1e-4, axis=1).sum()), frames[f])
    return out


def _figures(obj: Any) -> dict[str, tuple[float, int]]:
    q = obj.procloco.quality
    return {key: (float(getattr(q, key)), int(getattr(q, f"{key}_frame"))) for key in KEYS}


def _rows(obj: Any) -> dict[str, Any]:
    """The panel's jump button of each figure (recorded call)."""
    ui = draw_panel(PROCLOCO_PT_quality, bpy.context)
    calls = ui.operator_calls(PROCLOCO_OT_jump_to_worst_frame.bl_idname)
    return {c.operator_properties["figure"]: c for c in calls}


# ---------------------------------------------------------------------------------------
# A good walk: the example wolf on flat ground


@pytest.fixture(scope="module")
def walked(procloco_registered: Any) -> dict[str, Any]:
    wolf = _scene_with_wolf()
    job = _plan(wolf)
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    return {"name": wolf.name, "job": job, "mine": _independent(wolf, job)}


def test_panel_figures_match_an_independent_measurement(walked: dict[str, Any]) -> None:
    wolf = bpy.data.objects[walked["name"]]
    q = wolf.procloco.quality
    assert q.measured
    assert measure.is_current(wolf)
    assert (q.frame_start, q.frame_end) == FRAMES
    assert q.action == wolf.animation_data.action.name
    panel, mine = _figures(wolf), walked["mine"]
    for key in ("slide", "penetration", "reach"):
        # The same posed rig read twice: micrometres; the ground is the add-on's rasterised
        # scene against ray casts here, which agree to 3e-5 m. The worst frame of a figure
        # this small is noise and is not compared.
        assert panel[key][0] == pytest.approx(mine[key][0], abs=_TOL[key]), key
        assert panel[key][0] <= measure.LIMITS[key], key
    assert panel["few_feet_down"][0] == mine["few_feet_down"][0] == 0
    assert panel["over_stretched"][0] == mine["over_stretched"][0] == 0
    # a walk that did walk: the feet were planted and the figures are not all zero by default
    assert walked["job"].result.swing.any()
    assert (~walked["job"].result.swing).any()
    assert panel["reach"][0] > 0.0


def test_panel_draws_every_figure_with_its_button(walked: dict[str, Any]) -> None:
    wolf = bpy.data.objects[walked["name"]]
    q = wolf.procloco.quality
    rows = _rows(wolf)
    assert sorted(rows) == sorted(KEYS)
    for key in ("slide", "penetration", "reach"):
        assert rows[key].text == str(getattr(q, f"{key}_frame"))
        assert rows[key].enabled
    for key in ("few_feet_down", "over_stretched"):
        assert not rows[key].enabled, "no frame to jump to"
    ui = draw_panel(PROCLOCO_PT_quality, bpy.context)
    assert not any(c.alert for c in ui.walk()), "nothing above its threshold is drawn red"
    assert "Posed rig, frames 1-36" in ui.texts()


def test_jump_button_sets_the_worst_frame_without_an_undo_step(walked: dict[str, Any]) -> None:
    assert "UNDO" not in PROCLOCO_OT_jump_to_worst_frame.bl_options
    wolf = bpy.data.objects[walked["name"]]
    q = wolf.procloco.quality
    scene = bpy.context.scene
    for key in ("slide", "penetration", "reach"):
        scene.frame_set(FRAMES[1] + 5)
        assert bpy.ops.procloco.jump_to_worst_frame(figure=key) == {"FINISHED"}
        assert scene.frame_current == getattr(q, f"{key}_frame")
    scene.frame_set(3)
    with pytest.raises(RuntimeError, match="No frame has"):
        bpy.ops.procloco.jump_to_worst_frame(figure="few_feet_down")
    assert scene.frame_current == 3


def test_figures_survive_save_and_reload_then_go_stale_and_clear(walked: dict[str, Any],
                                                                 tmp_path: Path) -> None:
    wolf = bpy.data.objects[walked["name"]]
    before = _figures(wolf)
    path = tmp_path / "walk.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    wolf = bpy.data.objects[walked["name"]]
    assert _figures(wolf) == before
    assert measure.is_current(wolf)
    generated = wolf.animation_data.action
    # Another Action on the rig: the figures are stale, greyed, and the buttons are off.
    wolf.animation_data.action = bpy.data.actions.new("Hand made")
    assert not measure.is_current(wolf)
    _select_only(wolf)
    ui = draw_panel(PROCLOCO_PT_quality, bpy.context)
    assert "Stale: measured on" in ui.texts()
    assert not any(c.enabled for c in ui.operator_calls(PROCLOCO_OT_jump_to_worst_frame.bl_idname))
    assert not PROCLOCO_OT_jump_to_worst_frame.poll(bpy.context)
    # The generated Action back: current again; cleared: the figures are gone.
    wolf.animation_data.action = generated
    if hasattr(generated, "slots"):
        wolf.animation_data.action_slot = generated.slots[0]
    assert measure.is_current(wolf)
    assert bpy.ops.procloco.clear_generated_action() == {"FINISHED"}
    assert not wolf.procloco.quality.measured
    assert "Generate Locomotion to measure" in draw_panel(PROCLOCO_PT_quality, bpy.context).texts()


# ---------------------------------------------------------------------------------------
# Bad setups: the figures go above their thresholds, drawn red


def _limit_z(obj: Any, bone: str, min_z: float) -> None:
    c = obj.pose.bones[bone].constraints.new("LIMIT_LOCATION")
    c.owner_space = "WORLD"
    c.use_min_z = True
    c.min_z = min_z


def _pin_feet_up(wolf: Any, job: generate.Job) -> None:
    """Each leg held 6 cm above its rest place from its hip (Limit Location has no effect on
    a connected bone such as a foot; a hip is not connected): the feet never get down."""
    for leg in job.info.legs:
        assert not wolf.data.bones[leg.bones[0]].use_connect
        head = wolf.matrix_world @ wolf.data.bones[leg.bones[0]].head_local
        _limit_z(wolf, leg.bones[0], head.z + 0.06)


def _raise_body(wolf: Any, job: generate.Job) -> None:
    """The body kept higher than its legs reach."""
    body = job.info.body_bone
    head = wolf.matrix_world @ wolf.data.bones[body].head_local
    _limit_z(wolf, body, head.z + 0.5 * float(job.info.leg_length.mean()))


@pytest.mark.parametrize(("setup", "red"), [(_pin_feet_up, ("few_feet_down", "reach")),
                                             (_raise_body, ("few_feet_down", "over_stretched"))],
                         ids=["feet_pinned_off_the_ground", "body_raised_over_stretched"])
def test_a_bad_setup_shows_its_figures_above_the_thresholds(procloco_registered: Any, setup: Any,
                                                            red: tuple[str, ...]) -> None:
    wolf = _scene_with_wolf()
    job = _plan(wolf)
    setup(wolf, job)
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    panel, mine = _figures(wolf), _independent(wolf, job)
    rows = _rows(wolf)
    for key in red:
        assert panel[key][0] > measure.LIMITS[key], (key, panel[key])
        assert rows[key].alert, f"{key} is drawn red"
        scene = bpy.context.scene
        assert bpy.ops.procloco.jump_to_worst_frame(figure=key) == {"FINISHED"}
        assert scene.frame_current == panel[key][1]
    for key in KEYS:
        if key in ("few_feet_down", "over_stretched"):
            assert panel[key][0] == mine[key][0], (key, panel[key], mine[key])
        else:
            assert panel[key][0] == pytest.approx(mine[key][0], rel=1e-3, abs=_TOL[key]), key
        if panel[key][0] > 1e-3:  # a figure well above noise: its worst frame is the same
            assert panel[key][1] == mine[key][1], (key, panel[key], mine[key])
    assert rows["slide"].alert == (panel["slide"][0] > measure.LIMITS["slide"])


def test_rigs_generated_together_are_each_measured_on_their_own_pose(procloco_registered: Any) -> None:
    """Several rigs are measured in one pass over the frames: each rig's figures are its own
    posed rig's, over its own frame range (one pinned off the ground, one walking well, on
    ranges that overlap only in part)."""
    from procloco_addon.core.steps import run_steps

    wolf = _scene_with_wolf(ground_size=12.0)
    other = creatures.build_wolf(bpy.context.scene, name="Other", location=(0.0, 3.0, 0.0))
    other.procloco.use_scene_range = False
    other.procloco.frame_start, other.procloco.frame_end = 10, 30
    jobs = [_plan(wolf), _plan(other)]
    _pin_feet_up(wolf, jobs[0])
    # written and measured together (Generate's last stage), each walk as planned here
    run_steps(generate.write_all_steps(bpy.context, jobs, measure=True))
    mine = [_independent(o, job) for o, job in zip((wolf, other), jobs, strict=True)]
    for o, job, theirs in zip((wolf, other), jobs, mine, strict=True):
        q = o.procloco.quality
        assert (q.frame_start, q.frame_end) == (int(job.frames[0]), int(job.frames[-1]))
        panel = _figures(o)
        for key in KEYS:
            if key in ("few_feet_down", "over_stretched"):
                assert panel[key][0] == theirs[key][0], (o.name, key, panel[key], theirs[key])
            else:
                assert panel[key][0] == pytest.approx(theirs[key][0], rel=1e-3, abs=_TOL[key]), (o.name, key)
    assert _figures(wolf)["few_feet_down"][0] > measure.LIMITS["few_feet_down"]
    assert _figures(other)["few_feet_down"][0] == 0


def test_a_failed_measurement_leaves_the_walk_and_says_so(procloco_registered: Any,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from procloco_addon.blender import actions
    from procloco_addon.core.steps import run_steps

    wolf = _scene_with_wolf()
    wolf.procloco.frame_end = 8
    job = _plan(wolf)

    def broken(*args: Any) -> Any:
        raise RuntimeError("no ground today")

    monkeypatch.setattr(measure, "figures_of", broken)
    made = run_steps(generate.write_all_steps(bpy.context, [job], measure=True))
    assert actions.generated_action(wolf) == made[0]
    assert "could not measure the result: no ground today" in job.warnings
    assert not wolf.procloco.quality.measured


# ---------------------------------------------------------------------------------------
# The batch command


def test_batch_command_prints_the_quality_line_per_rig(empty_scene: Any,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    bpy.ops.mesh.primitive_plane_add(size=10.0)
    rigs = [creatures.build_robot(empty_scene, name=name, location=(x, 0.0, 0.0))
            for name, x in (("Left", -1.5), ("Right", 1.5))]
    empty_scene.frame_start, empty_scene.frame_end = 1, 10
    assert cli.main(["generate", "--rigs", "Left,Right"]) == 0
    printed = capsys.readouterr().out.splitlines()
    for obj in rigs:
        lines = [ln for ln in printed if ln.startswith(f"ProcLoco: {obj.name}: quality on the posed rig")]
        assert lines == [f"ProcLoco: {measure.summary_line(obj)}"]
        q = obj.procloco.quality
        assert q.measured
        assert measure.is_current(obj)
        line = lines[0]
        assert f"stance slide {q.slide * 1000:.2f} mm" in line
        assert f"too few feet down {q.few_feet_down} frame" in line
        assert line.endswith("all within the thresholds")


# ---------------------------------------------------------------------------------------
# Plain rigs posed from their Actions, without the depsgraph


_LEG_BONES = ("shoulder.L", "front_thigh.L", "front_shin.L", "front_foot.L", "front_toe.L",
              "thigh.L", "shin.L", "foot.L", "toe.L", "thigh.R", "shin.R", "foot.R")


def _keyed_metarig() -> Any:
    """Rigify's wolf metarig, turned and moved under a parent, keyed by hand in every way a walk or an
    animator keys it: quaternions, an Euler shoulder (the metarig's own YXZ), an axis-angle
    thigh, Bézier keys on a few frames only (the frames between are curves), a Cycles
    modifier past the last key, location on a free bone and on a connected one (ignored),
    scale on the root, a muted curve, and a bone posed but not keyed."""
    import addon_utils

    bpy.ops.wm.read_homefile(use_empty=True)
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_wolf_metarig_add()
    rig = bpy.context.active_object
    rig.location = (1.5, -2.0, 0.3)
    rig.rotation_euler = (0.0, 0.0, 0.7)
    holder = bpy.data.objects.new("Holder", None)  # the rig parented to a turned, moved empty
    bpy.context.scene.collection.objects.link(holder)
    holder.location = (0.4, 0.2, -0.1)
    holder.rotation_euler = (0.0, 0.0, -0.3)
    rig.parent = holder
    rig.matrix_parent_inverse = Matrix.Translation((0.1, -0.2, 0.05)) @ Matrix.Rotation(0.2, 4, "Z")
    pose = rig.pose.bones
    assert pose["shoulder.L"].rotation_mode == "YXZ"
    assert rig.data.bones["shin.L"].use_connect
    assert not rig.data.bones["thigh.L"].use_connect
    pose["thigh.R"].rotation_mode = "AXIS_ANGLE"
    pose["front_foot.L"].rotation_quaternion = (0.9, 0.3, 0.1, 0.0)  # posed, never keyed
    rng = np.random.default_rng(7)
    for frame in (1, 4, 9):
        pose["shoulder.L"].rotation_euler = rng.uniform(-0.5, 0.5, 3)
        pose["shoulder.L"].keyframe_insert("rotation_euler", frame=frame)
        pose["thigh.R"].rotation_axis_angle = (rng.uniform(-1.0, 1.0), *rng.uniform(-1.0, 1.0, 3))
        pose["thigh.R"].keyframe_insert("rotation_axis_angle", frame=frame)
        for name in ("thigh.L", "shin.L", "foot.L", "front_thigh.L", "front_shin.L"):
            q = rng.normal(size=4)
            pose[name].rotation_quaternion = q / np.linalg.norm(q) * 1.3  # unnormalised on purpose
            pose[name].keyframe_insert("rotation_quaternion", frame=frame)
        for name in ("thigh.L", "shin.L"):
            pose[name].location = rng.uniform(-0.1, 0.1, 3)
            pose[name].keyframe_insert("location", frame=frame)
        pose["spine.004"].scale = rng.uniform(0.8, 1.2, 3)
        pose["spine.004"].keyframe_insert("scale", frame=frame)
        pose["thigh.R"].location = (0.0, 0.0, 5.0)
        pose["thigh.R"].keyframe_insert("location", frame=frame)
    from procloco_addon.blender import actions

    fcurves = actions._fcurve_collection(rig.animation_data.action, rig, create=False)
    for fc in fcurves:
        if fc.data_path.endswith('["thigh.R"].location'):
            fc.mute = True
        if fc.data_path.endswith('["thigh.L"].rotation_quaternion') and fc.array_index == 1:
            fc.modifiers.new("CYCLES")
    pose["thigh.R"].location = (0.0, 0.0, 0.0)
    return rig


def test_a_plain_rig_is_posed_from_its_action_as_the_depsgraph_poses_it(procloco_registered: Any) -> None:
    from procloco_addon.blender.quality import posed
    from tests.blender.pose_eval import pose_matrices

    rig = _keyed_metarig()
    frames = np.arange(1, 15)
    mine = posed.plain_poses(rig, frames, _LEG_BONES)
    assert mine is not None, "a rig with no constraints, drivers or NLA is plain"
    blender = pose_matrices(rig, [int(f) for f in frames], _LEG_BONES)
    # float32 in Blender, float64 here: a few tenths of a micrometre on a metre-sized rig
    assert np.abs(mine - blender).max() < 1e-5
    # and the keys do move the legs: the comparison is not between two rest poses
    assert np.abs(np.diff(blender[..., :3, 3], axis=0)).max() > 0.01


@pytest.mark.parametrize("change", ["constraint", "nla", "driver", "object_keys", "parent_keys",
                                    "rest_position", "inherit_scale"])
def test_anything_else_that_moves_bones_leaves_the_rig_to_the_depsgraph(procloco_registered: Any,
                                                                         change: str) -> None:
    from procloco_addon.blender.quality import posed

    rig = _keyed_metarig()
    if change == "constraint":  # on a bone off the measured legs: an IK could still pull them
        rig.pose.bones["spine.006"].constraints.new("COPY_ROTATION")
    elif change == "nla":
        rig.animation_data.nla_tracks.new()
    elif change == "driver":
        rig.pose.bones["tail.001" if "tail.001" in rig.pose.bones else "spine.003"].driver_add("location", 0)
    elif change == "object_keys":
        rig.keyframe_insert("location", frame=1)
    elif change == "parent_keys":
        rig.parent.keyframe_insert("location", frame=1)
    elif change == "rest_position":
        rig.data.pose_position = "REST"
    else:
        rig.data.bones["shin.L"].inherit_scale = "NONE"
    assert posed.plain_poses(rig, np.arange(1, 5), _LEG_BONES) is None
