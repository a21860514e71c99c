# SPDX-License-Identifier: GPL-3.0-or-later
"""Make Cycle through the real operator: loops checked on the posed rig, in Blender and after
Blender's own glTF exporter and importer (run in a Blender of their own), and every refusal
changing nothing."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import rig
from procloco_addon.blender.cycle import make
from procloco_addon.blender.locomotion import generate, simulation
from procloco_addon.core.locomotion import cycle as core_cycle
from tests.blender import export_cycle
from tests.blender.pose_eval import pose_matrices
from tests.blender.scene_state import snapshot
from tests.blender.test_rig_fixtures import check_motion, measure
from tools.examples import creatures

pytestmark = pytest.mark.blender

#: The loop closes within these on every bone (the issue's bar).
CLOSE_M = 1e-3
CLOSE_DEG = 0.5


def _select_only(obj: Any) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def _ground(size: float, location: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    return bpy.context.active_object


def _add_root(obj: Any) -> None:
    """A bone ``root`` on the ground under the rig, parent of every parentless bone."""
    _select_only(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    edit = obj.data.edit_bones
    tops = [b for b in edit if b.parent is None]
    root = edit.new("root")
    root.head, root.tail = (0.0, 0.0, 0.0), (0.0, 0.3, 0.0)
    for bone in tops:
        bone.parent = root
    bpy.ops.object.mode_set(mode="OBJECT")


def _loop_frames(obj: Any) -> tuple[int, int]:
    """First and last frame of the rig's loop, from its Action's manual frame range."""
    action = obj.animation_data.action
    assert action.use_frame_range
    assert action.use_cyclic
    return round(action.frame_start), round(action.frame_end)


def _gap(a: np.ndarray, b: np.ndarray, offset: np.ndarray | None = None) -> tuple[float, float]:
    """Largest distance (m) between the bones' heads of ``a`` and ``b`` ``(B, 4, 4)`` (``b``
    moved back by ``offset``) and largest angle between their rotations (degrees)."""
    shift = np.zeros(3) if offset is None else offset
    move = float(np.linalg.norm(b[:, :3, 3] - shift - a[:, :3, 3], axis=1).max())
    ra = a[:, :3, :3] / np.linalg.norm(a[:, :3, :1], axis=1, keepdims=True)
    rb = b[:, :3, :3] / np.linalg.norm(b[:, :3, :1], axis=1, keepdims=True)
    # |Ra - Rb| (Frobenius) = 2 sqrt(2) sin(angle / 2): exact near zero, where the arccos of
    # the trace of float32 matrices reads a few hundredths of a degree for equal ones
    chord = np.linalg.norm(rb - ra, axis=(1, 2)) / (2.0 * np.sqrt(2.0))
    return move, float(np.degrees(2.0 * np.arcsin(np.clip(chord, 0.0, 1.0))).max())


def _closes(gap: tuple[float, float], what: str) -> None:
    """The heads within :data:`CLOSE_M` and the rotations within :data:`CLOSE_DEG`."""
    assert gap[0] <= CLOSE_M, (what, gap)
    assert gap[1] <= CLOSE_DEG, (what, gap)


def _walking_job(cj: make.CycleJob) -> generate.Job:
    """The loop's job with the root motion put back on the core's feet and body (the loop was
    written in place on the root bone), for ``measure`` on the walking rig."""
    res = cj.job.result
    n = res.feet.shape[0]
    ramp = np.linspace(0.0, 1.0, n)[:, None] * (cj.cycles * cj.stride)[None]
    body = res.body.copy()
    body[:, :3, 3] += ramp
    walking = dataclasses.replace(res, feet=res.feet + ramp[:, None], body=body)
    return dataclasses.replace(cj.job, result=walking)


@pytest.fixture(scope="module")
def loops(procloco_registered: Any, tmp_path_factory: Any) -> dict[str, Any]:
    """The wolf's loops (in place, 1 cycle, by the operator; on its root bone, 2 cycles) and
    the spider's (in place, 1 cycle), measured on the posed rigs; the root-bone wolf and the
    spider also after a glTF round trip."""
    out: dict[str, Any] = {}
    tmp = Path(tmp_path_factory.mktemp("cycle"))
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    wolf = creatures.build_wolf(scene)
    _add_root(wolf)
    ground = _ground(14.0, (0.0, -5.0, 0.0))
    _select_only(wolf)
    generate.detect_into_settings(wolf)
    bones = [pb.name for pb in wolf.pose.bones]

    # In place, one cycle, through the operator.
    wolf.procloco_cycle.cycles = 1
    assert bpy.ops.procloco.make_cycle() == {"FINISHED"}
    first, last = _loop_frames(wolf)
    mats = pose_matrices(wolf, [first, last, first + 3, last + 3], bones)
    hips = pose_matrices(wolf, list(range(first, last + 1)), ["spine.004"])[:, 0, :3, 3]
    out["in_place"] = {"frames": (first, last), "close": _gap(mats[0], mats[1]),
                       "beyond": _gap(mats[2], mats[3]),
                       "hips_travel": float(np.linalg.norm(hips[:, :2] - hips[0, :2], axis=1).max()),
                       "speed": float(wolf.procloco.speed), "fps": scene.render.fps}

    # On the root bone, two cycles (the operator's steps, to keep the job for the checks).
    wolf.procloco_cycle.root_motion = "ROOT_BONE"
    wolf.procloco_cycle.root_bone = "root"
    wolf.procloco_cycle.cycles = 2
    cj = make.read(bpy.context, wolf)
    for _ in make.simulate_steps(bpy.context, cj):
        pass
    for _ in make.write_steps(bpy.context, [cj]):
        pass
    first, last = _loop_frames(wolf)
    period = cj.period
    frames = [first, first + period, last, last + 3, first + 3]
    mats = pose_matrices(wolf, frames, bones)
    root = bones.index("root")
    out["root_bone"] = {"frames": (first, last), "period": period, "stride": cj.stride.copy(),
                        "root": mats[:, root, :3, 3].copy(),
                        "close": _gap(mats[0], mats[2], 2 * cj.stride),
                        "one_cycle": _gap(mats[0], mats[1], cj.stride),
                        "beyond": _gap(mats[4], mats[3], 2 * cj.stride),
                        "motion": measure(wolf, _walking_job(cj), ground), "closing": cj.closing,
                        "cell": simulation.planning_cell(cj.job, float(np.mean(cj.job.info.leg_length)))}
    wolf_blend = tmp / "wolf.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(wolf_blend), copy=True)
    bpy.ops.wm.open_mainfile(filepath=str(wolf_blend))
    saved = bpy.data.objects["Wolf"].procloco_cycle  # (the file reopened: by name)
    out["saved"] = (saved.cycles, saved.root_motion, saved.root_bone)

    # The spider, in place (its pelvis bounce off: see the README's known limitations).
    bpy.ops.wm.read_homefile(use_empty=True)
    spider = creatures.build_spider(bpy.context.scene)
    _ground(4.0, (-1.5, 0.0, 0.0))
    _select_only(spider)
    generate.detect_into_settings(spider)
    spider.procloco.use_pelvis_physics = False
    assert bpy.ops.procloco.make_cycle() == {"FINISHED"}
    first, last = _loop_frames(spider)
    legs = [rig.leg_from_bones(spider, item.hip, item.end, item.label).bones for item in spider.procloco.legs]
    spider_bones = [pb.name for pb in spider.pose.bones]
    mats = pose_matrices(spider, [first, last, first + 2, last + 2], spider_bones)
    out["spider"] = {"frames": (first, last), "close": _gap(mats[0], mats[1]),
                     "beyond": _gap(mats[2], mats[3]),
                     "legs": len(legs)}
    spider_blend = tmp / "spider.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(spider_blend), copy=True)

    # Blender's own glTF exporter and importer, in a Blender of their own.
    for name, blend in (("wolf", wolf_blend), ("spider", spider_blend)):
        imported = tmp / f"{name}-imported.blend"
        export_cycle.round_trip_in_subprocess(blend, tmp / f"{name}.glb", imported)
        bpy.ops.wm.open_mainfile(filepath=str(imported))
        arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
        action = arm.animation_data.action
        start, end = (round(v) for v in action.frame_range)
        names = [pb.name for pb in arm.pose.bones]
        m = pose_matrices(arm, [start, end], names)
        out[f"{name}_gltf"] = {"frames": (start, end), "mats": m, "names": names}
    bpy.ops.wm.read_homefile(use_empty=True)
    return out


@pytest.mark.slow  # the loops fixture: three loops made and two glTF round trips, once
def test_an_in_place_loop_closes_on_every_bone_and_plays_on(loops: dict[str, Any]) -> None:
    m = loops["in_place"]
    first, last = m["frames"]
    period = last - first
    # the frames of a cycle: the gait's cycle rounded to whole frames (the speed changed to fit)
    assert period >= core_cycle.MIN_PERIOD_FRAMES
    _closes(m["close"], "close")
    # the Cycles modifiers: three frames past the loop is three frames into it
    _closes(m["beyond"], "beyond")
    # in place: the hips stay within a small part of the stride of where they started
    stride = float(np.linalg.norm(loops["root_bone"]["stride"]))
    assert m["hips_travel"] < 0.15 * stride, m
    # the stride is near the walk's: the asked speed over the cycle, within the half frame
    # rounded and the stride rounded to whole planning cells (a cell is 6.5 % of the leg)
    cell = loops["root_bone"]["cell"]
    assert stride / (period / m["fps"]) == pytest.approx(m["speed"], rel=0.5 / period + cell / stride)


@pytest.mark.slow  # the loops fixture: three loops made and two glTF round trips, once
def test_root_motion_on_the_root_bone_is_one_stride_per_cycle(loops: dict[str, Any]) -> None:
    m = loops["root_bone"]
    first, last = m["frames"]
    assert last - first == 2 * m["period"]
    root = m["root"]  # frames: first, first + P, last, last + 3, first + 3
    stride = m["stride"]
    assert np.linalg.norm(root[1] - root[0] - stride) <= 1e-4
    assert np.linalg.norm(root[2] - root[0] - 2 * stride) <= 1e-4
    assert abs(stride[2]) < 1e-9
    assert np.linalg.norm(stride) > 0.1
    # a whole number of the planner's cells (its grids are fixed in the world), measured on
    # the posed root bone (within 0.5 % of a cell: measured 0.12 %, not looked into further)
    cells = np.linalg.norm(root[1] - root[0]) / m["cell"]
    assert abs(cells - round(cells)) < 5e-3
    # the pose one cycle on (and at the loop's end) is the first moved by the strides
    for key in ("one_cycle", "close", "beyond"):
        _closes(m[key], key)
    assert m["closing"] < 5e-3  # the keys changed to close exactly (quaternion parts, metres)


@pytest.mark.slow  # the loops fixture: three loops made and two glTF round trips, once
def test_the_settings_are_saved_in_the_blend(loops: dict[str, Any]) -> None:
    assert loops["saved"] == (2, "ROOT_BONE", "root")


@pytest.mark.slow  # the loops fixture: three loops made and two glTF round trips, once
def test_the_loop_passes_the_motion_checks_on_the_posed_rig(loops: dict[str, Any]) -> None:
    check_motion(loops["root_bone"]["motion"])


@pytest.mark.slow  # the loops fixture: three loops made and two glTF round trips, once
def test_a_spider_loops_too(loops: dict[str, Any]) -> None:
    m = loops["spider"]
    assert m["legs"] == 8
    _closes(m["close"], "close")
    _closes(m["beyond"], "beyond")


@pytest.mark.slow  # the loops fixture: three loops made and two glTF round trips, once
@pytest.mark.parametrize("name", ["wolf", "spider"])
def test_the_loop_closes_after_the_gltf_round_trip(loops: dict[str, Any], name: str) -> None:
    m = loops[f"{name}_gltf"]
    start, end = m["frames"]
    made = loops["root_bone" if name == "wolf" else "spider"]
    assert end - start == made["frames"][1] - made["frames"][0]  # the loop's frames, no more
    offset = None
    if name == "wolf":
        offset = 2 * made["stride"]
        root = m["names"].index("root")
        moved = m["mats"][1, root, :3, 3] - m["mats"][0, root, :3, 3]
        assert np.linalg.norm(moved - offset) <= CLOSE_M  # root motion: stride x cycles
    move, turn = _gap(m["mats"][0], m["mats"][1], offset)
    _closes((move, turn), f"{name} after glTF")


# ---------------------------------------------------------------------------------------
# Refusals: a clear message, nothing changed


@pytest.fixture
def wolf(empty_scene: Any) -> Any:
    obj = creatures.build_wolf(empty_scene)
    _ground(14.0, (0.0, -5.0, 0.0))
    _select_only(obj)
    generate.detect_into_settings(obj)
    return obj


def _bump(wolf: Any) -> None:
    bpy.ops.mesh.primitive_cube_add(size=0.1, location=(0.0, -2.0, 0.0))
    _select_only(wolf)


def _path(wolf: Any) -> None:
    curve = bpy.data.curves.new("Path", "CURVE")
    spline = curve.splines.new("POLY")
    spline.points.add(1)
    spline.points[1].co = (0.0, -3.0, 0.0, 1.0)
    wolf.procloco.path = bpy.data.objects.new("Path", curve)
    bpy.context.scene.collection.objects.link(wolf.procloco.path)


def _moving_crate(wolf: Any) -> None:
    bpy.ops.mesh.primitive_cube_add(size=0.2, location=(3.0, -2.0, 0.1))
    crate = bpy.context.active_object
    crate.keyframe_insert("location", frame=1)
    crate.location.x = 2.0
    crate.keyframe_insert("location", frame=40)
    bpy.context.scene.frame_set(1)
    _select_only(wolf)


def _gait_change(wolf: Any) -> None:
    bpy.context.scene.frame_set(30)
    assert bpy.ops.procloco.add_gait_change() == {"FINISHED"}


REFUSALS: dict[str, tuple[Any, str]] = {
    "path": (_path, "follows a path"),
    "turning": (lambda w: setattr(w.procloco, "turn_rate", 0.3), "it turns"),
    "gait change": (_gait_change, "Gait Changes"),
    "progression": (lambda w: setattr(w.procloco, "use_progression", True), "Burst Progression"),
    "randomizer": (lambda w: setattr(w.procloco, "use_gait_randomizer", True), "Gait Randomizer"),
    "standing": (lambda w: setattr(w.procloco, "speed", 0.0), "speed is 0"),
    "uneven": (_bump, "flat, level ground"),
    "moving": (_moving_crate, "still ground"),
    "no root": (lambda w: setattr(w.procloco_cycle, "root_motion", "ROOT_BONE"), "no bone 'root'"),
    "root with a parent": (lambda w: (setattr(w.procloco_cycle, "root_motion", "ROOT_BONE"),
                                      setattr(w.procloco_cycle, "root_bone", "thigh.L")), "has a parent"),
    "animated root": (lambda w: (setattr(w.procloco_cycle, "root_motion", "ROOT_BONE"),
                                 setattr(w.procloco_cycle, "root_bone", "spine.004")), "ProcLoco animates"),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_make_cycle_refuses_what_cannot_loop(wolf: Any, case: str) -> None:
    setup, match = REFUSALS[case]
    setup(wolf)
    before = snapshot()
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.procloco.make_cycle()
    assert snapshot() == before


def test_the_batch_command_makes_a_loop(wolf: Any) -> None:
    from procloco_addon.blender import cli
    from procloco_addon.blender.gait import rig_gait

    # with the gait circles (a preset), not Auto: the preset's cycle time is stretched
    rig_gait.choose_gait(wolf, "quadruped_walk")
    assert cli.main(["generate", "--rig", wolf.name, "--speed", "0.4", "--cycle", "1"]) == 0
    assert wolf.procloco.gait_mode == "CIRCLES"
    first, last = _loop_frames(wolf)
    bones = [pb.name for pb in wolf.pose.bones]
    mats = pose_matrices(wolf, [first, last], bones)
    _closes(_gap(mats[0], mats[1]), "batch")
    assert wolf.procloco_cycle.cycles == 1
    assert cli.main(["generate", "--rig", wolf.name, "--root-motion", "in-place"]) == 1  # needs --cycle


def test_the_panel_offers_the_settings_and_the_button(wolf: Any) -> None:
    from procloco_addon.blender.cycle.panel import PROCLOCO_PT_make_cycle
    from tests.blender.ui_recorder import draw_panel

    ui = draw_panel(PROCLOCO_PT_make_cycle, bpy.context)
    assert ui.has_prop("cycles", data=wolf.procloco_cycle)
    assert ui.has_prop("root_motion")
    assert not ui.find("prop_search")
    assert ui.operators() == ["procloco.make_cycle"]
    wolf.procloco_cycle.root_motion = "ROOT_BONE"
    assert draw_panel(PROCLOCO_PT_make_cycle, bpy.context).find("prop_search")


def test_a_loop_keeps_the_walk_it_was_made_from_and_replaces_an_earlier_loop(wolf: Any) -> None:
    wolf.procloco.use_scene_range = False
    wolf.procloco.frame_start, wolf.procloco.frame_end = 1, 12
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    walk = wolf.animation_data.action
    assert bpy.ops.procloco.make_cycle() == {"FINISHED"}
    loop = wolf.animation_data.action
    assert loop.name == "Wolf ProcLoco Cycle"
    first, last = _loop_frames(wolf)
    assert walk.name in bpy.data.actions
    assert walk.use_fake_user  # the walk stays, as when any generation replaces another
    names = sorted(a.name for a in bpy.data.actions)
    wolf.procloco_cycle.cycles = 2
    assert bpy.ops.procloco.make_cycle() == {"FINISHED"}
    assert sorted(a.name for a in bpy.data.actions) == names  # the earlier loop superseded
    assert wolf.animation_data.action.name == "Wolf ProcLoco Cycle"
    again = _loop_frames(wolf)
    assert again[1] - again[0] == 2 * (last - first)


def test_escape_midway_leaves_the_scene_unchanged(wolf: Any) -> None:
    from procloco_addon.blender.cycle.ops import PROCLOCO_OT_make_cycle as Op
    from tests.blender.test_modal import _context_for, _drive_modal

    assert bpy.ops.procloco.make_cycle() == {"FINISHED"}  # Esc during a re-make
    before = snapshot()
    context = _context_for(bpy.context.scene)
    me = _drive_modal(Op, context, 40, _jobs=[], _made=[])
    assert Op.modal(me, context, SimpleNamespace(type="ESC")) == {"CANCELLED"}
    assert snapshot() == before
