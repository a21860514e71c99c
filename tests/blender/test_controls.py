# SPDX-License-Identifier: GPL-3.0-or-later
"""Control rigs: ProcLoco keys the controls the animator moves, and the deform bones walk.

Generated Rigify rigs (``bpy.ops.pose.rigify_generate()``, built once per module and reloaded
from a temporary .blend), an Auto-Rig Pro-style rig built here, a rig under an animated empty,
and plain rigs with a driver or a Limit Rotation constraint. Every motion figure is measured on
the evaluated **deform** bones against ray casts into the ground, never on the keys written.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import actions
from procloco_addon.blender.locomotion import generate
from procloco_addon.core import metrics
from tests.blender.pose_eval import bone_heads_tails, pose_matrices, ray_heights_over_time
from tools.examples import creatures

pytestmark = pytest.mark.blender

_MECHANISM = ("ORG-", "MCH-", "DEF-")


@pytest.fixture(scope="module")
def rigify_files(tmp_path_factory: Any, procloco_registered: Any) -> dict[str, str]:
    """Generated Rigify wolf, human, cat and bird, each saved once to a temporary .blend."""
    import addon_utils

    addon_utils.enable("rigify", default_set=True)
    folder = tmp_path_factory.mktemp("rigify")
    out = {}
    for kind in ("wolf", "human", "cat", "bird"):
        bpy.ops.wm.read_homefile(use_empty=True)
        getattr(bpy.ops.object, f"armature_{kind}_metarig_add")()
        bpy.ops.pose.rigify_generate()
        path = Path(folder) / f"{kind}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(path), copy=True)
        out[kind] = str(path)
    return out


def _select_only(obj: Any) -> None:
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def _ground(size: float = 30.0) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, 0.0))
    obj = bpy.context.active_object
    obj.name = "Ground"
    return obj


def _open_rig(path: str) -> tuple[Any, Any]:
    bpy.ops.wm.open_mainfile(filepath=path)
    ground = _ground()
    rig = bpy.data.objects["rig"]
    _select_only(rig)
    return rig, ground


def _run(obj: Any, frames: int = 48, speed: float | None = None) -> generate.Job:
    _select_only(obj)
    s = obj.procloco
    s.use_scene_range = False
    s.frame_start, s.frame_end = 1, frames
    if speed is not None:
        s.speed = speed
    job = generate.prepare(bpy.context, obj)
    for _ in generate.simulate(job):
        pass
    generate.write(bpy.context, job)
    return job


_TRANSFORMS = ("location", "rotation_quaternion", "rotation_euler", "rotation_axis_angle", "scale")


def _keyed_bones(obj: Any) -> set[str]:
    """The bones whose transform channels the generated Action keys."""
    out = set()
    for ch in actions.channels_of(obj.animation_data.action, obj):
        if ch.data_path.startswith('pose.bones["') and ch.data_path.endswith(_TRANSFORMS):
            out.add(ch.data_path.split('"')[1])
    return out


def _stretch_keys(obj: Any) -> dict[str, float]:
    """Bone -> the ``ik_stretch`` the generated Action keys it to."""
    action = obj.animation_data.action
    return {ch.data_path.split('"')[1]: float(actions.read_channel(action, obj, ch.data_path, 0)[1][0])  # type: ignore[index]
            for ch in actions.channels_of(action, obj) if ch.data_path.endswith(".ik_stretch")}


def _prop_keys(obj: Any) -> dict[tuple[str, str], float]:
    out = {}
    action = obj.animation_data.action
    for ch in actions.channels_of(action, obj):
        if ch.data_path.startswith('pose.bones["') and ch.data_path.endswith('"]'):
            parts = ch.data_path.split('"')
            out[(parts[1], parts[3])] = float(actions.read_channel(action, obj, ch.data_path, ch.index)[1][0])  # type: ignore[index]
    return out


def _measure(obj: Any, job: generate.Job, feet: list[str], probes: list[str], pelvis: str,
             ground: Any, knees: list[str] | None = None) -> dict[str, float]:
    """Slide of the deform feet (their heads) over each stance, penetration of the deform foot
    bones' heads and tails under the ground (ray casts), travel of the deform pelvis, and how
    far the deform knees (heads of ``knees``) are from the planned ones."""
    frames = [int(f) for f in job.frames]
    knee_error = 0.0
    if knees:
        knee_heads, _kt = bone_heads_tails(obj, frames, knees)
        knee_error = float(np.linalg.norm(knee_heads - job.result.joints[:, :, 1], axis=-1).max())
    heads, _tails = bone_heads_tails(obj, frames, feet)
    ph, pt = bone_heads_tails(obj, frames, probes)
    pts = np.concatenate([ph, pt], axis=1)
    under = ray_heights_over_time(frames, pts[..., :2], [ground])
    pelvis_head, _pt = bone_heads_tails(obj, frames, [pelvis])
    fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base
    return {
        "slide": float(metrics.stance_sliding(heads, ~job.result.swing).max()),
        "penetration": float(np.max(under - pts[..., 2])),
        "travel": float(np.linalg.norm(pelvis_head[-1, 0, :2] - pelvis_head[0, 0, :2])),
        "asked": float(job.speed) * (len(frames) - 1) / fps,
        "reach": float(np.linalg.norm(heads - job.result.feet, axis=-1).max()),
        "knee": knee_error,
    }


def _check_motion(m: dict[str, float]) -> None:
    assert m["slide"] <= 0.002, m
    assert m["penetration"] <= 0.005, m
    assert 0.75 * m["asked"] <= m["travel"] <= 1.25 * m["asked"], m


# ---------------------------------------------------------------------------------------
# Generated Rigify rigs

def _fk(names: str, sides: str = "LR") -> set[str]:
    """``"thigh_fk shin_fk"`` -> ``{"thigh_fk.L", "shin_fk.L", "thigh_fk.R", "shin_fk.R"}``."""
    return {f"{n}.{s}" for n in names.split() for s in sides}


_RIGIFY = {
    # kind: (feet deform bones, probe bones, pelvis deform bone, controls, switch bones, knees)
    # The quadrupeds' legs are Rigify's three-bone paws: their IK chain does not place every
    # leg bone (the paw follows a target a stretchy helper chain places), so Drive Legs: Auto
    # walks them on their FK controls.
    "wolf": (["DEF-front_toe.L", "DEF-front_toe.R", "DEF-toe.L", "DEF-toe.R"],
             ["DEF-front_toe.L", "DEF-front_toe.R", "DEF-toe.L", "DEF-toe.R", "DEF-foot.L", "DEF-foot.R"],
             "DEF-spine.004",
             {"torso"} | _fk("front_thigh_fk front_shin_fk front_foot_fk front_toe")
             | _fk("thigh_fk shin_fk foot_fk toe"),
             ["front_thigh_parent.L", "front_thigh_parent.R", "thigh_parent.L", "thigh_parent.R"],
             ["DEF-front_shin.L", "DEF-front_shin.R", "DEF-shin.L", "DEF-shin.R"]),
    "human": (["DEF-foot.L", "DEF-foot.R"], ["DEF-foot.L", "DEF-foot.R", "DEF-toe.L", "DEF-toe.R"],
              "DEF-spine",
              {"torso", "foot_ik.L", "foot_ik.R", "thigh_ik_target.L", "thigh_ik_target.R"},
              ["thigh_parent.L", "thigh_parent.R"],
              ["DEF-shin.L", "DEF-shin.R"]),
    # The cat's paws: Rigify's three-bone IK legs, whose toes (its metarig's palms and toes
    # do not meet tail to head) once made the whole rig's tails count as meaningless.
    "cat": (["DEF-f_toe.L", "DEF-f_toe.R", "DEF-r_toe.L", "DEF-r_toe.R"],
            ["DEF-f_toe.L", "DEF-f_toe.R", "DEF-r_toe.L", "DEF-r_toe.R"],
            "DEF-spine.001",
            {"torso"} | _fk("upper_arm_fk forearm_fk hand_fk f_toe thigh_fk shin_fk foot_fk r_toe"),
            ["upper_arm_parent.L", "upper_arm_parent.R", "thigh_parent.L", "thigh_parent.R"],
            ["DEF-forearm.L", "DEF-forearm.R", "DEF-shin.L", "DEF-shin.R"]),
}


@pytest.mark.parametrize("kind", ["wolf", "human", "cat"])
def test_generated_rigify_rig_walks_on_its_controls(rigify_files: dict[str, str], kind: str) -> None:
    rig, ground = _open_rig(rigify_files[kind])
    feet, probes, pelvis, wanted, switch_bones, knees = _RIGIFY[kind]
    fk = kind != "human"
    # The animator left the legs in the other mode: the result must not depend on it.
    for b in switch_bones:
        rig.pose.bones[b]["IK_FK"] = 0.0 if fk else 1.0
    assert rig.procloco.drive_legs == "AUTO"
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    listed = {item.label: item.controls for item in rig.procloco.legs}
    for text in listed.values():
        if fk:
            assert text.startswith("FK "), listed
            assert "IK_FK = 1" in text, listed
            assert "pole" not in text, listed
        else:
            assert text.startswith("IK "), listed
            assert "pole " in text, listed
            assert "IK_FK = 0" in text, listed
    job = _run(rig, speed={"wolf": 0.6, "human": 0.8, "cat": 0.3}[kind])
    keyed = _keyed_bones(rig)
    assert wanted <= keyed, keyed
    assert not [b for b in keyed if b.startswith(_MECHANISM)], keyed
    switches = _prop_keys(rig)
    for b in switch_bones:
        assert switches[(b, "IK_FK")] == (1.0 if fk else 0.0)
        if fk:  # the pole switch is the animator's: not keyed
            assert (b, "pole_vector") not in switches, switches
        else:
            assert switches[(b, "pole_vector")] == 1.0
    if fk:
        assert not [b for b in keyed if "_ik" in b], keyed  # no IK control, pole or stretch
        assert not _stretch_keys(rig)
    assert not job.warnings, job.warnings
    m = _measure(rig, job, feet, probes, pelvis, ground, knees)
    if kind != "human":  # the quadrupeds' flexible spine, keyed on Rigify's spine tweaks
        spine = list(job.info.spine[::-1])  # the core's bones, head first
        assert len(spine) >= 5, job.info.spine
        assert {b.replace("ORG-spine", "tweak_spine") for b in spine[2:-1]} <= keyed, keyed
        frames = [int(f) for f in job.frames]
        heads, tails = bone_heads_tails(rig, frames, [b.replace("ORG-", "DEF-") for b in spine])
        assert job.result.spine_joints is not None
        assert np.linalg.norm(heads - job.result.spine_joints[:, 1:], axis=-1).max() < 1e-3
        way = (tails - heads) / np.linalg.norm(tails - heads, axis=-1, keepdims=True)
        bend = np.degrees(np.arccos(np.clip(np.sum(way[:, 1] * way[:, -1], axis=-1), -1.0, 1.0)))
        assert np.ptp(bend) > 3.0, "the spine flexes as it walks"
    _check_motion(m)
    assert m["reach"] <= 0.01, m
    # The poles put the human's knees on the side the walk bends them (Rigify's own IK bends
    # them a little its own way); the FK controls put every knee where it was solved.
    assert m["knee"] <= (0.001 if fk else 0.03), m


def test_secondary_motion_swings_the_generated_wolf_tail_controls(rigify_files: dict[str, str]) -> None:
    from procloco_addon.blender.secondary import bake
    from tests.blender.pose_eval import pose_matrices

    rig, _ground_obj = _open_rig(rigify_files["wolf"])
    _run(rig, frames=24)
    found = bake.suggest_chains(rig)
    assert not [b for s in found for b in s.bones if b.startswith(_MECHANISM)], found
    tail = next(s for s in found if s.root == "spine.003")
    assert tail.bones == ("spine.003", "spine.002", "spine.001", "spine")
    assert len(found) <= 3, found  # the tail and one control per ear, not 16 one-bone chains
    chains = rig.procloco_secondary.chains
    chains.clear()
    item = chains.add()
    item.name, item.root, item.tip = tail.label, tail.root, tail.tip
    frames = list(range(1, 25))
    before = pose_matrices(rig, frames, list(tail.bones))
    job = bake.prepare(bpy.context, rig)
    for _ in bake.sample(bpy.context, job):
        pass
    _quats, planned = bake.simulate(job)
    bake.write(bpy.context, job)
    assert not job.warnings, job.warnings
    after = pose_matrices(rig, frames, list(tail.bones))

    def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        ya = a[..., :3, 1] / np.linalg.norm(a[..., :3, 1], axis=-1, keepdims=True)
        yb = b[..., :3, 1] / np.linalg.norm(b[..., :3, 1], axis=-1, keepdims=True)
        return np.degrees(np.arccos(np.clip(np.sum(ya * yb, axis=-1), -1.0, 1.0)))

    assert angle(after, before).max() > 0.5, "the tail swings"
    # The constrained controls (each copies its parent's rotation) land where the pendulums say.
    assert angle(after, planned).max() < 0.05
    keyed = _keyed_bones(rig)
    assert set(tail.bones) <= keyed
    assert not [b for b in keyed if b.startswith(_MECHANISM)], keyed


@pytest.mark.parametrize(("kind", "switch"), [("human", "thigh_parent.L"), ("wolf", "front_thigh_parent.L")])
def test_clear_gives_back_the_rigify_rig_as_it_was(rigify_files: dict[str, str], kind: str,
                                                   switch: str) -> None:
    # The human walks on its IK controls (IK_FK keyed 0), the wolf on its FK controls (1).
    rig, _ground_obj = _open_rig(rigify_files[kind])
    rig.pose.bones[switch]["IK_FK"] = 0.4
    foot = "foot_ik.R" if kind == "human" else "front_foot_fk.R"
    rig.pose.bones[foot].location = (0.0, 0.05, 0.02)
    rig.pose.bones[foot].rotation_quaternion = (0.99, 0.1, 0.0, 0.0)
    bpy.context.view_layer.update()

    def state() -> tuple[Any, ...]:
        bpy.context.view_layer.update()
        props = [(pb.name, k, float(pb[k])) for pb in rig.pose.bones for k in pb.keys()  # noqa: SIM118 (an ID property group)
                 if isinstance(pb[k], (int, float, bool))]
        basis = np.array([np.array(pb.matrix_basis) for pb in rig.pose.bones])
        deform = np.array([np.array(pb.matrix) for pb in rig.evaluated_get(
            bpy.context.evaluated_depsgraph_get()).pose.bones if pb.name.startswith("DEF-")])
        stretch = [(pb.name, round(pb.ik_stretch, 6)) for pb in rig.pose.bones]
        return props, basis, deform, stretch

    before = state()
    _run(rig, frames=12)
    assert _prop_keys(rig)[(switch, "IK_FK")] == (0.0 if kind == "human" else 1.0)
    assert bpy.ops.procloco.clear_generated_action() == {"FINISHED"}
    after = state()
    assert after[0] == before[0]
    assert np.allclose(after[1], before[1], atol=1e-6)
    assert np.allclose(after[2], before[2], atol=1e-5)
    assert after[3] == before[3]  # the IK chains stretch again


def test_drive_legs_chooses_the_ik_or_the_fk_controls(rigify_files: dict[str, str]) -> None:
    from procloco_addon.blender.locomotion.panel import PROCLOCO_PT_rig_legs
    from tests.blender.ui_recorder import draw_panel

    # The human walks on its FK controls when asked: every deform bone exactly as solved, its
    # feet too (through its IK controls Rigify's foot roll stretches DEF-foot by 0.02 %).
    rig, ground = _open_rig(rigify_files["human"])
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    ui = draw_panel(PROCLOCO_PT_rig_legs, bpy.context)
    assert ui.has_prop("drive_legs", rig.procloco)
    assert "Detect Legs again" not in ui.texts()
    rig.procloco.drive_legs = "FK"
    stale = draw_panel(PROCLOCO_PT_rig_legs, bpy.context).texts()
    assert "Detect Legs again to list the controls this keys" in stale
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    assert [leg.controls for leg in rig.procloco.legs] == [
        f"FK thigh_fk.{s}, shin_fk.{s}, foot_fk.{s}, IK_FK = 1 on thigh_parent.{s}" for s in "LR"]
    job = _run(rig, speed=0.8)
    keyed = _keyed_bones(rig)
    assert {"torso"} | _fk("thigh_fk shin_fk foot_fk") <= keyed, keyed
    assert not keyed & {"foot_ik.L", "foot_ik.R", "thigh_ik_target.L", "thigh_ik_target.R"}, keyed
    assert not _stretch_keys(rig)
    assert not job.warnings, job.warnings
    frames = [int(f) for f in job.frames]
    names = [n for s in "LR" for n in (f"DEF-thigh.{s}", f"DEF-thigh.{s}.001", f"DEF-shin.{s}",
                                        f"DEF-shin.{s}.001", f"DEF-foot.{s}", f"DEF-toe.{s}")]
    mats = pose_matrices(rig, frames, names)
    rest = np.array([np.array(rig.matrix_world @ rig.data.bones[n].matrix_local) for n in names])
    stretch = np.linalg.norm(mats[..., :3, 1], axis=-1) / np.linalg.norm(rest[:, :3, 1], axis=-1)
    assert np.abs(stretch - 1.0).max() < 1e-4
    m = _measure(rig, job, ["DEF-foot.L", "DEF-foot.R"], ["DEF-foot.L", "DEF-foot.R"], "DEF-spine", ground,
                 ["DEF-shin.L", "DEF-shin.R"])
    _check_motion(m)
    assert m["reach"] <= 0.001, m
    assert m["knee"] <= 0.001, m

    # The wolf's paws on their IK controls when asked (they squash and may flip: README).
    rig, _ground = _open_rig(rigify_files["wolf"])
    rig.procloco.drive_legs = "IK"
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    for leg in rig.procloco.legs:
        assert leg.controls.startswith("IK "), leg.controls
        assert "IK_FK = 0" in leg.controls, leg.controls


@pytest.mark.parametrize("kind", ["human", "bird"])
def test_generated_rigify_legs_keep_their_length_and_bend_their_way(rigify_files: dict[str, str],
                                                                      kind: str) -> None:
    # Blender's IK shortens a stretchy chain's bones when that reaches the target with less
    # bending: Rigify's IK chains stretch (ik_stretch 0.1), so the human's deform thigh and
    # shin were up to 2.5 % short while it walked. And a pass of the control solve could flip
    # a knee to the other side for a frame (the bird's, 4 cm of its 7 cm leg).
    rig, _ground = _open_rig(rigify_files[kind])
    job = _run(rig, speed={"human": 0.8, "bird": 0.1}[kind])
    stretch = _stretch_keys(rig)
    assert stretch
    assert set(stretch.values()) == {0.0}, stretch
    assert all(b.startswith(("MCH-", "thigh_ik")) for b in stretch), stretch
    frames = [int(f) for f in job.frames]
    for side in "LR":
        names = [f"DEF-thigh.{side}", f"DEF-shin.{side}", f"DEF-foot.{side}"]
        heads, _tails = bone_heads_tails(rig, frames, names)
        rest = np.array([rig.matrix_world @ rig.data.bones[n].head_local for n in names])
        for a, b in ((0, 1), (1, 2)):
            length = np.linalg.norm(heads[:, b] - heads[:, a], axis=-1)
            assert np.abs(length / np.linalg.norm(rest[b] - rest[a]) - 1.0).max() < 1e-4, (side, a)
        k = [leg.label[0] for leg in job.info.legs].index(side)
        want = job.result.joints[:, k]
        bend = np.cross(heads[:, 1] - heads[:, 0], heads[:, 2] - heads[:, 1])
        planned = np.cross(want[:, 1] - want[:, 0], want[:, 2] - want[:, 1])
        assert (np.sum(bend * planned, axis=-1) > 0.0).all(), side  # the knee on the planned side
        assert np.linalg.norm(heads[:, 1] - want[:, 1], axis=-1).max() < 0.01 * float(job.info.leg_length[k])


# ---------------------------------------------------------------------------------------
# An Auto-Rig Pro-style rig


def _arp_rig(scene: Any) -> Any:
    """A biped named and wired like Auto-Rig Pro: ``c_traj`` > ``c_root_master.x`` > ``root.x``;
    per leg deform ``thigh/leg/foot`` copying an FK chain (``c_thigh_fk`` ...) or an IK chain
    (``thigh_ik``, ``leg_ik`` with IK to ``c_foot_ik`` and pole ``c_leg_pole``), switched by
    ``ik_fk_switch`` on ``c_foot_ik`` (0 IK, 1 FK). Mechanism and deform bones sit in hidden
    bone collections."""
    arm = bpy.data.armatures.new("ARP")
    obj = bpy.data.objects.new("ARP", arm)
    scene.collection.objects.link(obj)
    _select_only(obj)
    bpy.ops.object.mode_set(mode="EDIT")
    eb = arm.edit_bones

    def bone(name: str, head: tuple[float, float, float], tail: tuple[float, float, float],
             parent: str | None = None) -> Any:
        b = eb.new(name)
        b.head, b.tail = head, tail
        if parent:
            b.parent = eb[parent]
        return b

    bone("c_traj", (0, 0, 0), (0, 0.3, 0))
    bone("c_root_master.x", (0, 0, 0.95), (0, 0.2, 0.95), "c_traj")
    bone("root.x", (0, 0, 0.95), (0, 0, 1.1), "c_root_master.x")
    for side, x in (("l", 0.1), ("r", -0.1)):
        hip, knee, ankle, toe = (x, 0.0, 0.9), (x, -0.03, 0.5), (x, 0.0, 0.1), (x, -0.14, 0.02)
        for kind, prefix in (("fk", "c_"), ("ik", "")):
            suffix = f"_{kind}.{side}"
            bone(f"{prefix}thigh{suffix}", hip, knee, "root.x")
            bone(f"{prefix}leg{suffix}", knee, ankle, f"{prefix}thigh{suffix}").use_connect = True
        bone(f"c_foot_fk.{side}", ankle, toe, f"c_leg_fk.{side}")
        bone(f"c_foot_ik.{side}", ankle, toe, "c_traj")
        bone(f"foot_ik.{side}", ankle, toe, f"c_foot_ik.{side}")
        bone(f"c_leg_pole.{side}", (x, -0.5, 0.5), (x, -0.6, 0.5), "c_traj")
        bone(f"thigh.{side}", hip, knee, "root.x")
        bone(f"leg.{side}", knee, ankle, f"thigh.{side}").use_connect = True
        bone(f"foot.{side}", ankle, toe, f"leg.{side}").use_connect = True
    bpy.ops.object.mode_set(mode="OBJECT")
    hidden = arm.collections.new("mch")
    visible = arm.collections.new("controls")
    for b in arm.bones:
        (visible if b.name.startswith("c_") else hidden).assign(b)
    hidden.is_visible = False
    pbones = obj.pose.bones
    for side in ("l", "r"):
        switch = pbones[f"c_foot_ik.{side}"]
        switch["ik_fk_switch"] = 1.0  # the animator left it in FK
        for deform, fk, ik in (("thigh", "c_thigh_fk", "thigh_ik"), ("leg", "c_leg_fk", "leg_ik"),
                               ("foot", "c_foot_fk", "foot_ik")):
            pb = pbones[f"{deform}.{side}"]
            c_fk = pb.constraints.new("COPY_TRANSFORMS")
            c_fk.target, c_fk.subtarget = obj, f"{fk}.{side}"
            c_ik = pb.constraints.new("COPY_TRANSFORMS")
            c_ik.target, c_ik.subtarget = obj, f"{ik}.{side}"
            fc = c_ik.driver_add("influence")
            var = fc.driver.variables.new()
            var.name, var.type = "switch", "SINGLE_PROP"
            var.targets[0].id = obj
            var.targets[0].data_path = f'pose.bones["c_foot_ik.{side}"]["ik_fk_switch"]'
            fc.driver.expression = "1 - switch"
        ik = pbones[f"leg_ik.{side}"].constraints.new("IK")
        ik.target, ik.subtarget, ik.chain_count = obj, f"c_foot_ik.{side}", 2
        ik.pole_target, ik.pole_subtarget = obj, f"c_leg_pole.{side}"
        # The pole angle that keeps the rest pose (depends on the bones' rolls).
        best = None
        for angle in (0.0, 90.0, -90.0, 180.0):
            ik.pole_angle = math.radians(angle)
            bpy.context.view_layer.update()
            knee = pbones[f"leg_ik.{side}"].matrix.to_translation()
            err = (knee - arm.bones[f"leg_ik.{side}"].head_local).length
            if best is None or err < best[0]:
                best = (err, angle)
        assert best is not None
        ik.pole_angle = math.radians(best[1])
    bpy.context.view_layer.update()
    return obj


def test_auto_rig_pro_style_rig_walks_on_its_controls(empty_scene: Any) -> None:
    ground = _ground()
    rig = _arp_rig(empty_scene)
    job = _run(rig, speed=0.8)
    keyed = _keyed_bones(rig)
    assert {"c_root_master.x", "c_foot_ik.l", "c_foot_ik.r", "c_leg_pole.l", "c_leg_pole.r"} <= keyed, keyed
    assert all(b.startswith("c_") for b in keyed), keyed
    assert "c_traj" not in keyed
    assert _prop_keys(rig) == {("c_foot_ik.l", "ik_fk_switch"): 0.0, ("c_foot_ik.r", "ik_fk_switch"): 0.0}
    assert not job.warnings, job.warnings
    m = _measure(rig, job, ["foot.l", "foot.r"], ["foot.l", "foot.r"], "root.x", ground, ["leg.l", "leg.r"])
    _check_motion(m)
    assert m["knee"] <= 0.01, m


# ---------------------------------------------------------------------------------------
# Parents, drivers and limits on plain rigs


def test_rig_under_an_animated_empty_keeps_its_feet_planted_in_the_world(empty_scene: Any) -> None:
    ground = _ground()
    wolf = creatures.build_wolf(empty_scene)
    carrier = bpy.data.objects.new("Platform", None)
    empty_scene.collection.objects.link(carrier)
    carrier.location = (0.0, 0.0, 0.0)
    carrier.keyframe_insert("location", frame=1)
    carrier.location = (0.4, 0.3, 0.0)
    carrier.keyframe_insert("location", frame=48)
    wolf.parent = carrier
    bpy.context.view_layer.update()
    job = _run(wolf)
    feet = [job.info.legs[k].bones[-1] for k in range(len(job.info.legs))]
    frames = [int(f) for f in job.frames]
    _heads, tails = bone_heads_tails(wolf, frames, feet)
    assert float(metrics.stance_sliding(tails, ~job.result.swing).max()) <= 0.002
    assert float(np.linalg.norm(tails - job.result.feet, axis=-1).max()) <= 0.01
    del ground


def test_a_driver_and_a_limit_rotation_are_named_and_their_effect_reported(empty_scene: Any) -> None:
    _ground()
    wolf = creatures.build_wolf(empty_scene)
    plain = _run(wolf, frames=24)
    assert not plain.warnings, plain.warnings
    thigh = wolf.pose.bones["thigh.L"]
    channel = "rotation_quaternion" if thigh.rotation_mode == "QUATERNION" else "rotation_euler"
    fc = thigh.driver_add(channel, 1)
    fc.driver.type = "AVERAGE"
    var = fc.driver.variables.new()
    var.type = "SINGLE_PROP"
    var.targets[0].id = wolf
    var.targets[0].data_path = "location.z"  # 0 here: the thigh is held still
    limit = wolf.pose.bones["front_shin.R"].constraints.new("LIMIT_ROTATION")
    limit.use_limit_x = limit.use_limit_y = limit.use_limit_z = True
    limit.owner_space = "LOCAL"
    job = _run(wolf, frames=24)
    text = "\n".join(job.warnings)
    assert "bone 'thigh.L': a driver on rotation_" in text, text
    assert "bone 'front_shin.R': a Limit Rotation constraint" in text, text
    assert "evaluated feet are off the plan" in text, text
    assert "leg R1" in text, text
    assert "leg L2" in text, text


def test_fk_only_control_rig_keys_its_fk_controls(empty_scene: Any) -> None:
    # The Auto-Rig Pro-style rig switched to FK for good: the deform legs copy only the FK
    # chain (the IK copies are removed), so the FK controls are what moves them.
    ground = _ground()
    rig = _arp_rig(empty_scene)
    for side in ("l", "r"):
        for deform in ("thigh", "leg", "foot"):
            pb = rig.pose.bones[f"{deform}.{side}"]
            ik_copy = next(c for c in pb.constraints if c.subtarget.endswith(f"_ik.{side}"))
            pb.driver_remove(f'constraints["{ik_copy.name}"].influence')
            pb.constraints.remove(ik_copy)
        del rig.pose.bones[f"c_foot_ik.{side}"]["ik_fk_switch"]
    bpy.context.view_layer.update()
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    assert [leg.controls for leg in rig.procloco.legs] == [
        f"FK c_thigh_fk.{s}, c_leg_fk.{s}, c_foot_fk.{s}" for s in ("l", "r")]
    job = _run(rig, speed=0.8)
    keyed = _keyed_bones(rig)
    fk = {f"c_{b}_fk.{s}" for b in ("thigh", "leg") for s in ("l", "r")}
    assert fk | {"c_root_master.x"} <= keyed, keyed
    assert not keyed & {"c_foot_ik.l", "c_foot_ik.r", "c_leg_pole.l", "c_leg_pole.r"}, keyed
    assert all(b.startswith("c_") for b in keyed), keyed
    assert not job.warnings, job.warnings
    m = _measure(rig, job, ["foot.l", "foot.r"], ["foot.l", "foot.r"], "root.x", ground, ["leg.l", "leg.r"])
    _check_motion(m)
    assert m["reach"] <= 0.01, m
    assert m["knee"] <= 0.01, m


def test_generated_rigify_wolf_under_an_animated_empty_keeps_its_feet_planted(
    rigify_files: dict[str, str],
) -> None:
    rig, ground = _open_rig(rigify_files["wolf"])
    carrier = bpy.data.objects.new("Platform", None)
    bpy.context.scene.collection.objects.link(carrier)
    carrier.keyframe_insert("location", frame=1)
    carrier.location = (0.4, 0.3, 0.0)
    carrier.keyframe_insert("location", frame=48)
    rig.parent = carrier
    bpy.context.view_layer.update()
    feet, probes, pelvis, wanted, _switches, _knees = _RIGIFY["wolf"]
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    job = _run(rig, speed=0.6)
    assert wanted <= _keyed_bones(rig)
    assert not job.warnings, job.warnings
    m = _measure(rig, job, feet, probes, pelvis, ground)
    _check_motion(m)  # planted in the world: the platform's 0.5 m are not in the slide
    assert m["reach"] <= 0.01, m


def test_plan_biped_footsteps_walks_the_generated_rigify_human_on_its_controls(
    rigify_files: dict[str, str],
) -> None:
    from procloco_addon.blender.biped import ops as biped_ops
    from procloco_addon.core.biped.planner import stance_slide
    from tests.blender.test_biped import _held_points

    rig, _ground_obj = _open_rig(rigify_files["human"])
    rig.pose.bones["thigh_parent.L"]["IK_FK"] = 1.0  # left in FK by the animator
    assert bpy.ops.procloco.make_biped_clips() == {"FINISHED"}
    goal = bpy.data.objects.new("Goal", None)
    bpy.context.scene.collection.objects.link(goal)
    goal.location = (1.2, -7.0, 0.0)
    rig.procloco_biped.goal = goal
    _select_only(rig)
    job = biped_ops.prepare(bpy.context, rig)
    biped_ops.run(job)
    assert job.error is None, job.error
    biped_ops.finish(bpy.context, job)
    keyed = _keyed_bones(rig)
    assert {"torso", "foot_ik.L", "foot_ik.R", "thigh_ik_target.L", "thigh_ik_target.R"} <= keyed, keyed
    assert not [b for b in keyed if b.startswith(_MECHANISM)], keyed
    assert _prop_keys(rig)[("thigh_parent.L", "IK_FK")] == 0.0
    motion = job.result
    assert motion is not None
    frames = job.start_frame + np.arange(motion.n_frames)
    # The planner's heel and toe points ride on the ORG foot bones; the deform feet follow them.
    pts = _held_points(rig, job.brig, frames)
    org, _t = bone_heads_tails(rig, list(frames), ["ORG-foot.L", "ORG-foot.R", "ORG-toe.L", "ORG-toe.R"])
    deform, _t = bone_heads_tails(rig, list(frames), ["DEF-foot.L", "DEF-foot.R", "DEF-toe.L", "DEF-toe.R"])
    assert np.abs(org - deform).max() < 1e-4
    assert np.nanmax(stance_slide(pts, motion.ik.ik_point, motion.contact)) <= 0.002
    f, s = np.nonzero(motion.ik.ik_point >= 0)
    assert np.abs(pts[f, s, motion.ik.ik_point[f, s]][:, 2]).max() < 0.005
    assert np.linalg.norm(pts[-1].mean(axis=(0, 1))[:2] - np.array([1.2, -7.0])) < 0.10
