# SPDX-License-Identifier: GPL-3.0-or-later
"""Crowds: Generate Locomotion on many selected rigs at once, through the real operator.

Every rig is read and checked before anything is written; the rigs that can walk together
step in one core simulation (``locomotion.crowd``). The motion is checked on the posed rigs,
evaluated frame by frame through the depsgraph (``pose_eval``), with the thresholds of a rig
generated alone (``test_generate.check_thresholds``).
"""

from __future__ import annotations

import math
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender.locomotion import crowd, generate
from tests.blender.pose_eval import leg_joints
from tests.blender.scene_state import snapshot
from tests.blender.spy import spy
from tests.blender.test_generate import _measure_on, check_thresholds, modal_double
from tools.examples import creatures

pytestmark = pytest.mark.blender

FRAMES = 60


def _ground(size: float = 16.0) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, 0.0))
    obj = bpy.context.active_object
    obj.name = "Ground"
    return obj


def _place(scene: Any, kind: str, name: str, xy: tuple[float, float], scale: float = 1.0,
           yaw: float = 0.0) -> Any:
    obj = creatures.BUILDERS[kind](scene, name=name, location=(xy[0], xy[1], 0.0), scale=scale)
    obj.rotation_euler = (0.0, 0.0, yaw)
    obj.procloco.use_scene_range = False
    obj.procloco.frame_start, obj.procloco.frame_end = 1, FRAMES
    return obj


def _select(rigs: list[Any]) -> None:
    bpy.context.view_layer.update()  # (objects linked since the last update are in its list)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in rigs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = rigs[0]
    bpy.context.view_layer.update()


def _simulated(rigs: list[Any]) -> list[generate.Job]:
    """The jobs of a Generate of ``rigs`` (the same inputs as the operator's), simulated,
    to read what was simulated (the swing flags and the needle the gait is judged by)."""
    jobs = crowd.read_all(bpy.context, rigs)
    groups = crowd.batches(jobs)
    for _ in crowd.read_terrain(bpy.context, groups):
        pass
    for _ in crowd.simulate(groups):
        pass
    return jobs


def _all_poses(rigs: list[Any], frames: list[int]) -> np.ndarray:
    """Every pose bone's world matrix of every rig at each frame ``(F, bones, 4, 4)``, one
    evaluation of the scene per frame."""
    scene = bpy.context.scene
    out = []
    for frame in frames:
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        mats = []
        for obj in rigs:
            ev = obj.evaluated_get(depsgraph)
            world = np.array(ev.matrix_world, dtype=np.float64)
            mats += [world @ np.array(pb.matrix, dtype=np.float64) for pb in ev.pose.bones]
        out.append(mats)
    return np.array(out)


def _measured(obj: Any, job: generate.Job, rigs: list[Any], ground: Any) -> dict[str, Any]:
    """``test_generate._measure_on`` of one rig of a batch, the other rigs' Actions taken
    off meanwhile (evaluating every rig of the batch at each frame would only cost time)."""
    others = [(o, o.animation_data.action) for o in rigs if o is not obj]
    try:
        for o, _action in others:
            o.animation_data.action = None
        return _measure_on(obj, job, [ground], [])
    finally:
        for o, action in others:
            o.animation_data.action = action


# ---------------------------------------------------------------------------------------
# Rigs see each other


def _hips_boxes(obj: Any, job: generate.Job, frames: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The posed rig's body box at each frame, from its bones: the box around its hips in
    the frame its hips face (front hips' centre minus hind hips'), as ``(F, 3, 3)``
    world-to-box transforms of the ground plane (rows: x, y, 1) and half sizes ``(F, 2)``."""
    joints = leg_joints(obj, frames, [leg.bones for leg in job.info.legs])
    hips = np.stack([j[:, 0, :2] for j in joints], axis=1)  # (F, L, 2)
    n = hips.shape[1]
    forward = hips[:, : n // 2].mean(axis=1) - hips[:, n - n // 2:].mean(axis=1)
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    left = np.stack([-forward[:, 1], forward[:, 0]], axis=1)
    centre = 0.5 * (hips.min(axis=1) + hips.max(axis=1))
    rel = hips - centre[:, None]
    local = np.stack([np.einsum("fld,fd->fl", rel, forward), np.einsum("fld,fd->fl", rel, left)], axis=-1)
    mid = 0.5 * (local.min(axis=1) + local.max(axis=1))
    half = 0.5 * (local.max(axis=1) - local.min(axis=1))
    to_box = np.zeros((len(frames), 3, 3))
    to_box[:, 0, :2], to_box[:, 1, :2] = forward, left
    to_box[:, 0, 2] = -np.einsum("fd,fd->f", forward, centre) - mid[:, 0]
    to_box[:, 1, 2] = -np.einsum("fd,fd->f", left, centre) - mid[:, 1]
    to_box[:, 2, 2] = 1.0
    return to_box, half


def _feet_in_box(feet: np.ndarray, to_box: np.ndarray, half: np.ndarray) -> np.ndarray:
    """``(F, L)`` how deep each foot ``(F, L, 2)`` is inside the box (m, <= 0 outside)."""
    pts = np.concatenate([feet, np.ones((*feet.shape[:2], 1))], axis=-1)
    local = np.einsum("fij,flj->fli", to_box, pts)[..., :2]
    return np.min(half[:, None] - np.abs(local), axis=-1)


def test_two_rigs_walking_toward_each_other_keep_out_of_each_other_and_pass(empty_scene: Any) -> None:
    ground = _ground()
    frames = list(range(1, 121))
    a = _place(empty_scene, "spider", "SpiderA", (0.05, 1.2), scale=4.0)
    b = _place(empty_scene, "spider", "SpiderB", (-0.05, -1.2), scale=4.0, yaw=math.pi)
    for rig in (a, b):
        rig.procloco.frame_end = frames[-1]
        rig.procloco.speed = 0.45  # 1.3 leg lengths a second: they meet half-way
    # (not copies of each other, so not varied: see _mixed_batch)
    b.procloco.step_height = 0.9 * a.procloco.step_height
    _select([a, b])
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    jobs = _simulated([a, b])
    measured = [_measured(obj, job, [a, b], ground) for obj, job in zip((a, b), jobs, strict=True)]
    feet = {obj.name: m["ends"][..., :2] for obj, m in zip((a, b), measured, strict=True)}
    for me, other, job in ((a, b, jobs[1]), (b, a, jobs[0])):
        to_box, half = _hips_boxes(other, job, frames)
        depth = _feet_in_box(feet[me.name], to_box, half)
        assert float(depth.max()) <= 0.0, f"a foot of {me.name} is {depth.max():.4f} m inside {other.name}"
    # They passed each other: A (walking -Y) ends beyond where B (walking +Y) ends.
    body = [job.result.body[:, 1, 3] for job in jobs if job.result is not None]
    assert body[0][0] > body[1][0]
    assert body[0][-1] < body[1][-1], (body[0][-1], body[1][-1])
    # And they turned aside to do it: at their closest they are more than a body apart.
    xy = [job.result.body[:, :2, 3] for job in jobs if job.result is not None]
    closest = float(np.linalg.norm(xy[0] - xy[1], axis=1).min())
    assert closest > 2.0 * float(np.max(_hips_boxes(a, jobs[0], frames)[1][:, 1])), closest
    # With Avoid Other Rigs off they walk straight on, through each other.
    for rig in (a, b):
        rig.procloco.use_avoid_others = False
    blind = [job.result.body[:, :2, 3] for job in _simulated([a, b]) if job.result is not None]
    assert float(np.linalg.norm(blind[0] - blind[1], axis=1).min()) < 0.15
    # Both within the motion thresholds of a rig alone.
    for m in measured:
        check_thresholds(m)


# ---------------------------------------------------------------------------------------
# A batch of mixed rigs


def _mixed_batch(scene: Any) -> list[Any]:
    """20 rigs: 12 spiders, 5 ants, 2 robots and a wolf, spaced so that they barely meet,
    walking about -Y at their default speeds. The spiders' headings differ by a few degrees,
    so that they are not copies of each other (copies start at other phases: see the copies'
    tests)."""
    rigs = [_place(scene, "spider", f"Spider{k:02d}", (-5.5 + 1.0 * k, 0.0), scale=4.0) for k in range(12)]
    for k, rig in enumerate(rigs):
        rig.procloco.heading = math.radians(2.0 * (k - 5.5))
    rigs += [_place(scene, "ant", f"Ant{k}", (-5.0 + 1.0 * k, 3.0), scale=10.0) for k in range(5)]
    rigs += [_place(scene, "robot", f"Robot{k}", (1.5 + 2.0 * k, 3.5), scale=0.6) for k in range(2)]
    rigs.append(_place(scene, "wolf", "Wolf", (6.5, 1.0), scale=0.6))
    return rigs


def test_a_mixed_batch_meets_the_motion_thresholds_of_each_rig_and_repeats_exactly(empty_scene: Any) -> None:
    ground = _ground()
    rigs = _mixed_batch(empty_scene)
    _select(rigs)
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    actions = [o.animation_data.action for o in rigs]
    assert len({a.name for a in actions}) == len(rigs)  # one Action per rig
    frames = list(range(1, FRAMES + 1))
    first = _all_poses(rigs, frames)
    jobs = _simulated(rigs)  # the same inputs again: what the operator simulated
    for obj, job in zip(rigs, jobs, strict=True):
        m = _measured(obj, job, rigs, ground)
        check_thresholds(m)
        assert m["travel"] > 0.3 * m["scale"], (obj.name, m)  # every rig walked
    # Simulated a second time and written again: the same poses (the same code path, the
    # same seeds).
    generate.write_all(bpy.context, jobs)
    again = _all_poses(rigs, frames)
    assert np.allclose(first, again, rtol=0.0, atol=1e-9)


def test_rigs_of_one_batch_walk_as_they_would_alone(empty_scene: Any) -> None:
    """Two spiders far apart with different headings share one simulation; each walks as
    it does generated on its own (neither is a copy of the other: no variation)."""
    _ground()
    a = _place(empty_scene, "spider", "SpiderA", (-3.0, 0.0), scale=4.0)
    b = _place(empty_scene, "spider", "SpiderB", (3.0, 0.0), scale=4.0)
    b.procloco.heading = math.radians(30.0)
    for rig in (a, b):
        rig.procloco.use_avoid_others = False
    _select([a, b])
    jobs = crowd.read_all(bpy.context, [a, b])
    assert len(crowd.batches(jobs)) == 1
    together = _simulated([a, b])
    for k, rig in enumerate((a, b)):
        alone = _simulated([rig])[0]
        assert (alone.phase, alone.cycle_scale) == (0.0, 1.0)
        ours, theirs = together[k].result, alone.result
        assert ours is not None
        assert theirs is not None
        for name in ("body", "joints", "feet"):
            same = np.allclose(getattr(ours, name), getattr(theirs, name), rtol=0.0, atol=1e-9)
            assert same, (rig.name, name)
        assert np.array_equal(ours.swing, theirs.swing), rig.name


# ---------------------------------------------------------------------------------------
# Bad input in a batch


def test_a_refused_rig_in_a_batch_is_named_and_changes_nothing_on_any_rig(empty_scene: Any) -> None:
    _ground()
    good = [_place(empty_scene, "spider", f"Spider{k}", (-1.0 + 1.0 * k, 0.0), scale=4.0) for k in range(3)]
    arm = bpy.data.armatures.new("Stick")
    stick = bpy.data.objects.new("Stick", arm)
    empty_scene.collection.objects.link(stick)
    bpy.context.view_layer.objects.active = stick
    bpy.ops.object.mode_set(mode="EDIT")
    bone = arm.edit_bones.new("Bone")
    bone.head, bone.tail = (0.0, 2.0, 0.0), (0.0, 2.0, 1.0)
    bpy.ops.object.mode_set(mode="OBJECT")
    _select([*good[:2], stick, good[2]])
    before = snapshot()
    with pytest.raises(RuntimeError, match="'Stick'"):
        bpy.ops.procloco.generate_locomotion()
    assert snapshot() == before
    assert all(o.animation_data is None or o.animation_data.action is None for o in good)


# ---------------------------------------------------------------------------------------
# Copies of one creature


def _foot_heights(obj: Any, frames: list[int]) -> np.ndarray:
    """Each end-effector's height over the ground ``(F, legs)``, from the posed rig."""
    legs = [tuple(chain) for chain in creatures.LEG_CHAINS["spider"]]
    return np.stack([j[:, -1, 2] for j in leg_joints(obj, frames, legs)], axis=1)


def test_linked_duplicates_get_their_own_actions_and_do_not_walk_in_step(empty_scene: Any) -> None:
    _ground()
    first = _place(empty_scene, "spider", "Spider", (-1.0, 0.0), scale=4.0)
    _select([first])
    bpy.ops.object.duplicate(linked=True)
    copy = bpy.context.active_object
    copy.location.x += 2.0
    assert copy.data == first.data  # Alt+D: one armature for both
    user = bpy.data.actions.new("Spider user walk")  # the user's own Action, shared by both
    for rig in (first, copy):
        rig.animation_data_create().action = user
    _select([first, copy])
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    a, b = first.animation_data.action, copy.animation_data.action
    assert a != b
    assert a.name != b.name
    assert user not in (a, b)
    assert "Spider user walk" in bpy.data.actions  # nothing the user made is lost
    frames = list(range(1, FRAMES + 1))
    lift_a = _foot_heights(first, frames)
    lift_b = _foot_heights(copy, frames)
    # Out of step: the feet are not up and down together.
    assert float(np.abs(lift_a - lift_b).max()) > 0.01, "the copies walk in step"
    jobs = _simulated([first, copy])
    assert jobs[0].phase != jobs[1].phase
    assert jobs[0].cycle_scale != jobs[1].cycle_scale
    assert all(0.96 <= job.cycle_scale <= 1.04 for job in jobs)


def test_seed_offset_changes_phase_and_stride_and_zero_alone_changes_nothing(empty_scene: Any) -> None:
    _ground()
    rig = _place(empty_scene, "spider", "Spider", (0.0, 0.0), scale=4.0)
    _select([rig])
    plain = _simulated([rig])[0]
    assert (plain.phase, plain.cycle_scale) == (0.0, 1.0)
    rig.procloco.seed_offset = 3
    varied = _simulated([rig])[0]
    again = _simulated([rig])[0]
    assert (varied.phase, varied.cycle_scale) == (again.phase, again.cycle_scale)  # from the offset alone
    assert varied.phase != 0.0
    assert varied.cycle_scale != 1.0
    assert 0.96 <= varied.cycle_scale <= 1.04
    assert varied.gait.cycle_time == pytest.approx(plain.gait.cycle_time * varied.cycle_scale)
    assert plain.result is not None
    assert varied.result is not None
    assert float(np.abs(varied.result.joints - plain.result.joints).max()) > 1e-3


def test_collection_instances_made_real_each_get_their_own_walk(empty_scene: Any) -> None:
    """A spider in a collection, instanced twice and made real: two rigs of one armature,
    each walks with its own Action, out of step with the other."""
    _ground()
    herd = bpy.data.collections.new("Herd")
    empty_scene.collection.children.link(herd)
    spider = creatures.build_spider(empty_scene, name="Spider", scale=4.0, collection=herd)
    spider.procloco.use_scene_range = False
    spider.procloco.frame_start, spider.procloco.frame_end = 1, FRAMES
    herd.hide_render = False
    empty_scene.view_layers[0].layer_collection.children["Herd"].exclude = True  # only the instances show
    made = []
    for k, x in enumerate((-1.5, 1.5)):
        inst = bpy.data.objects.new(f"HerdInstance{k}", None)
        inst.instance_type = "COLLECTION"
        inst.instance_collection = herd
        inst.location = (x, 0.0, 0.0)
        empty_scene.collection.objects.link(inst)
        _select([inst])
        bpy.ops.object.duplicates_make_real()
        made += [o for o in bpy.context.selected_objects if o.type == "ARMATURE"]
    assert len(made) == 2
    assert made[0].data == made[1].data  # both instances' rigs share the armature
    _select(made)
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    a, b = (o.animation_data.action for o in made)
    assert a != b
    assert a.name != b.name
    frames = list(range(1, FRAMES + 1))
    heights = [_foot_heights(o, frames) for o in made]
    assert float(np.abs(heights[0] - heights[1]).max()) > 0.01, "the copies walk in step"


def test_batch_command_generates_every_rig_and_no_avoid_switches_avoidance_off(empty_scene: Any) -> None:
    from procloco_addon.blender import cli

    _ground()
    rigs = [_place(empty_scene, "spider", f"Spider{k}", (-0.6 + 1.2 * k, 0.0), scale=4.0) for k in range(2)]
    for rig in rigs:
        rig.procloco.frame_end = 12
    assert cli.main(["generate", "--all"]) == 0
    assert all(rig.procloco.use_avoid_others for rig in rigs)
    first = [rig.animation_data.action.name for rig in rigs]
    assert len(set(first)) == 2
    assert cli.main(["generate", "--rigs", "Spider0,Spider1", "--no-avoid"]) == 0
    assert not any(rig.procloco.use_avoid_others for rig in rigs)  # saved on the rigs, as every override
    assert all(rig.animation_data.action is not None for rig in rigs)


def test_escape_midway_through_a_batch_changes_nothing(empty_scene: Any) -> None:
    """The modal path with two rigs in one simulation: Esc during the simulation leaves the
    scene exactly as it was; left to run, the same loop writes both Actions."""
    from types import SimpleNamespace

    from procloco_addon.blender.locomotion.ops import PROCLOCO_OT_generate_locomotion as Op

    _ground()
    rigs = [_place(empty_scene, "spider", f"Spider{k}", (-0.6 + 1.2 * k, 0.0), scale=4.0) for k in range(2)]
    for rig in rigs:
        rig.procloco.frame_end = 24
    _select(rigs)
    before = snapshot()
    me, context = modal_double()
    assert me._prepare(context)
    assert len(me._rigs) == 2
    me._steps = me._run(context, True)
    timer = SimpleNamespace(type="TIMER")
    for _ in range(6):  # (the terrain, then frames of the one simulation)
        assert Op.modal(me, context, timer) == {"RUNNING_MODAL"}
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert snapshot() == before
    assert me._prepare(context)
    me._steps = me._run(context, True)
    results = [Op.modal(me, context, timer) for _ in range(200)]
    assert results.count({"FINISHED"}) == 1
    assert all(rig.animation_data.action.name.startswith(f"{rig.name} ProcLoco") for rig in rigs)


def test_copies_of_a_rig_read_together_are_detected_once(empty_scene: Any,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Detection is a matter of a rig's shape: copies standing elsewhere (one on a table)
    share the legs found for the first; a rig of another shape (a spider, a wolf with a
    shorter hind leg) is detected on its own, and gets the legs it gets alone."""
    from procloco_addon.blender import rig
    from procloco_addon.blender.rig import read

    _ground()
    wolves = [_place(empty_scene, "wolf", f"Wolf{k}", (3.0 * k, 0.0)) for k in range(3)]
    wolves[2].location.z = 0.8
    odd = _place(empty_scene, "wolf", "Odd", (0.0, 4.0))
    spider = _place(empty_scene, "spider", "Spider", (3.0, 4.0))
    bpy.context.view_layer.objects.active = odd
    bpy.ops.object.mode_set(mode="EDIT")
    shin = odd.data.edit_bones["shin.L"]
    shin.head.z += 0.05  # a shorter thigh: another shape (its legs are found the same way)
    bpy.ops.object.mode_set(mode="OBJECT")
    rigs = [*wolves, odd, spider]
    bpy.context.view_layer.update()
    alone = {o.name: rig.detect_legs(o) for o in rigs}
    calls = spy(monkeypatch, read, "find_legs", lambda rest, constrained, name: name)
    with rig.reading_once():
        together = {o.name: rig.detect_legs(o) for o in rigs}
    assert calls == ["Wolf0", "Odd", "Spider"]
    assert together == alone
    jobs = crowd.read_all(bpy.context, rigs)  # Generate's reading: one block for every rig
    assert calls[3:] == ["Wolf0", "Odd", "Spider"]
    assert [list(j.info.legs) for j in jobs] == [alone[o.name] for o in rigs]


def test_copies_of_a_rig_read_together_are_read_once_and_placed(empty_scene: Any,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """A copy of a rig read in the same Generate (the same bones, pose, constraints, skins and
    weights; only its object moved) is the first one's reading moved to where it stands: the
    same as its own reading but for the last bits. A copy posed otherwise, or whose skin is
    weighted otherwise, is read on its own."""
    from procloco_addon.blender import rig
    from procloco_addon.blender.rig import read

    _ground()
    wolves = [_place(empty_scene, "wolf", f"Wolf{k}", (3.0 * k, 0.0)) for k in range(4)]
    wolves[1].location.z = 0.4  # (on a table: a copy all the same)
    wolves[2].pose.bones["spine"].rotation_quaternion = (0.9, 0.1, 0.0, 0.0)  # its tail tip posed
    skin = next(o for o in bpy.data.objects if o.type == "MESH" and o.name.startswith("Wolf3"))
    group = skin.vertex_groups["toe.L"]
    group.remove([v.index for v in skin.data.vertices if any(g.group == group.index for g in v.groups)])
    bpy.context.view_layer.update()
    alone = {o.name: rig.read_rig(o) for o in wolves}
    calls = spy(monkeypatch, read, "_read_rig", lambda obj, *_: obj.name)
    with rig.reading_once():
        together = {o.name: rig.read_rig(o) for o in wolves}
        # What is made from a reading is shared by its copies (but what to key only on a plain
        # rig: see the copies with a constraint below).
        first, copy = together["Wolf0"], together["Wolf1"]
        assert rig.shared(copy, ("x",), object, plain=True) is rig.shared(first, ("x",), object, plain=True)
        assert rig.shared(together["Wolf2"], ("x",), object) is not rig.shared(first, ("x",), object)
    assert calls == ["Wolf0", "Wolf2", "Wolf3"]  # Wolf1 placed from Wolf0
    constrained = [_place(empty_scene, "wolf", f"Held{k}", (3.0 * k, 5.0)) for k in range(2)]
    for obj in constrained:
        obj.pose.bones["spine"].constraints.new("LIMIT_ROTATION")
    bpy.context.view_layer.update()
    with rig.reading_once():
        held = [rig.read_rig(o) for o in constrained]
        assert calls[3:] == ["Held0"]  # a copy all the same
        assert rig.shared(held[1], ("x",), object) is rig.shared(held[0], ("x",), object)
        assert rig.shared(held[1], ("x",), object, plain=True) is not rig.shared(held[0], ("x",), object,
                                                                                  plain=True)
    for name, info in together.items():
        mine = alone[name]
        assert info.object_name == name
        assert info.legs == mine.legs
        np.testing.assert_array_equal(info.world, mine.world)
        pairs = [(info.contact, mine.contact), (info.body.origin, mine.body.origin),
                 *zip(info.joints, mine.joints, strict=True),
                 *zip(info.foot_points, mine.foot_points, strict=True)]
        for a, b in pairs:
            np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)
    assert not np.allclose(together["Wolf3"].foot_points[2], together["Wolf0"].foot_points[2]
                           + together["Wolf3"].world[:3, 3] - together["Wolf0"].world[:3, 3], atol=1e-6)


def test_reading_a_herd_shows_its_progress_and_stops_on_escape(empty_scene: Any) -> None:
    """The rigs are read in the modal steps, one a step: the progress bar moves while a herd
    is read, and Esc then leaves everything as it was (nothing is read ahead of the steps)."""
    from types import SimpleNamespace

    from procloco_addon.blender.locomotion.ops import PROCLOCO_OT_generate_locomotion as Op
    from procloco_addon.blender.rig import read

    _ground()
    rigs = [_place(empty_scene, "spider", f"Spider{k}", (-1.2 + 1.2 * k, 0.0), scale=4.0) for k in range(3)]
    _select(rigs)
    before = snapshot()
    me, context = modal_double()
    assert me._prepare(context)
    assert me._jobs == []  # nothing read yet
    me._steps = me._run(context, True)
    shown = [next(me._steps) for _ in range(2)]
    assert [text for text, _f in shown] == ["reading the rigs"] * 2
    assert [f for _t, f in shown] == pytest.approx([0.05 / 3, 0.1 / 3])
    assert read._read_once is not None  # in the middle of the reading
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert read._read_once is None  # its block closed: nothing kept from it
    assert snapshot() == before
