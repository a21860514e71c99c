# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/rig/: leg detection, world-space morphology, and poses written back to bones.

Poses are checked by evaluating the rig through the depsgraph after the Action is written.
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np
import pytest
from mathutils import Matrix, Quaternion

from procloco_addon.blender import actions, rig
from tests.blender.pose_eval import bone_heads_tails, pose_matrices, skin_vertices
from tests.blender.spy import spy
from tools.examples import creatures

pytestmark = pytest.mark.blender


@pytest.mark.parametrize(
    ("name", "side", "tokens"),
    [
        ("thigh.L", 1, ("thigh",)),
        ("DEF-front_thigh.R", -1, ("front", "thigh")),
        ("DEF-thigh.L.001", 1, ("thigh", "001")),
        ("LeftUpLeg", 1, ("up", "leg")),
        ("mixamorig:RightFoot", -1, ("foot",)),
        ("Leg3_tarsus.R", -1, ("leg", "3", "tarsus")),
        ("l_femur", 1, ("femur",)),
        ("Leg3_thigh", 0, ("leg", "3", "thigh")),
        ("foot_ik.L", 1, ("foot", "ik")),
        ("upper_arm_left", 1, ("upper", "arm")),
    ],
)
def test_split_name(name: str, side: int, tokens: tuple[str, ...]) -> None:
    assert rig.split_name(name) == (side, tokens)


@pytest.mark.parametrize(
    ("bones", "joints"),
    [
        # Auto-Rig Pro: the thigh and the shin each split in a twist and a stretch half.
        (("thigh_twist.l", "thigh_stretch.l", "leg_stretch.l", "leg_twist.l"), [1, 3]),
        (("lThighBend", "lThighTwist", "lShin"), [1]),  # Genesis 8
        # An Auto-Rig Pro dog's hind leg: c_thigh_b.l is a bone of its own (the hip).
        (("c_thigh_b.l", "thigh_twist.l", "thigh_stretch.l", "leg_stretch.l"), [2]),
        (("thigh_twist_dupli_001.l", "thigh_stretch_dupli_001.l", "leg_stretch_dupli_001.l"), [1]),
        # Knees: two limbs, even when both are stretch bones or share a word.
        (("mixamorig:LeftUpLeg", "mixamorig:LeftLeg"), []),
        (("thigh_stretch.l", "leg_stretch.l"), []),
        (("Leg1Base.L", "Leg1Mid.L", "Leg1Fore.L"), []),
    ],
)
def test_split_joints_are_the_joints_inside_one_limb_bone(bones: tuple[str, ...], joints: list[int]) -> None:
    from procloco_addon.blender.rig.names import split_joints

    assert split_joints(bones) == joints


# Expected detection per example creature: label -> (IK bones, foot bones).
EXPECTED = {
    "spider": {f"{s}{n}": (tuple(f"Leg{n}_{seg}.{s}" for seg in ("coxa", "femur", "tibia", "tarsus")), ())
               for n in range(1, 5) for s in "LR"},
    # A five-pointed star: the midline front leg, then two pairs.
    "robot": {label: (chain, ()) for label, chain in zip(("M1", "L2", "R2", "L3", "R3"), creatures.ROBOT_LEGS,
                                                           strict=True)},
    "wolf": {"L1": (("front_thigh.L", "front_shin.L", "front_foot.L"), ("front_toe.L",)),
             "R1": (("front_thigh.R", "front_shin.R", "front_foot.R"), ("front_toe.R",)),
             "L2": (("thigh.L", "shin.L", "foot.L"), ("toe.L",)),
             "R2": (("thigh.R", "shin.R", "foot.R"), ("toe.R",))},
    "human": {"L1": (("thigh.L", "shin.L"), ("foot.L", "toe.L")),
              "R1": (("thigh.R", "shin.R"), ("foot.R", "toe.R"))},
    "lizard": {"L1": (("front_thigh.L", "front_shin.L"), ("front_foot.L",)),
               "R1": (("front_thigh.R", "front_shin.R"), ("front_foot.R",)),
               "L2": (("thigh.L", "shin.L"), ("foot.L",)),
               "R2": (("thigh.R", "shin.R"), ("foot.R",))},
}


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_detects_the_legs_of_the_example_creatures(empty_scene: Any, kind: str) -> None:
    arm = creatures.BUILDERS[kind](empty_scene)
    legs = rig.detect_legs(arm)
    got = {leg.label: (leg.bones, leg.foot) for leg in legs}
    assert got == EXPECTED[kind]
    # Front to back, left before right.
    assert [leg.label for leg in legs] == list(EXPECTED[kind])


def _add_ik_targets(arm: Any, legs: list[rig.LegChain], names: str) -> None:
    """A leaf bone beside every foot, parented to the root (like an IK target or control)."""
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    eb = arm.data.edit_bones
    root = next(b for b in eb if b.parent is None)
    for k, leg in enumerate(legs):
        tip = eb[leg.end].tail.copy()
        b = eb.new(names.format(k=k, side=leg.label[0]))
        b.head = tip + type(tip)((0.01, 0.0, 0.0))
        b.tail = b.head + type(tip)((0.0, -0.02, 0.0))
        b.parent = root
    bpy.ops.object.mode_set(mode="OBJECT")


@pytest.mark.parametrize("target_names", ["foot_ik.{side}.{k}", "IK_target_{k}", "Ctrl{k}"])
def test_ik_target_bones_are_not_legs(empty_scene: Any, target_names: str) -> None:
    arm = creatures.build_spider(empty_scene)
    before = rig.detect_legs(arm)
    _add_ik_targets(arm, before, target_names)
    after = rig.detect_legs(arm)
    assert [(leg.label, leg.bones) for leg in after] == [(leg.label, leg.bones) for leg in before]


def test_topology_finds_unnamed_legs_and_skips_ik_targets(empty_scene: Any) -> None:
    arm = creatures.build_robot(empty_scene)
    expected = {leg.label: leg.bones for leg in rig.detect_legs(arm)}
    # Rename every bone to something meaningless; keep a map to check the result.
    renamed = {}
    for i, bone in enumerate(list(arm.data.bones)):
        renamed[f"Bone{i:02d}"] = bone.name
        bone.name = f"Bone{i:02d}"
    new_name = {v: k for k, v in renamed.items()}
    _add_ik_targets(arm, [rig.LegChain((new_name[bones[-1]],), (), 0, "X") for bones in expected.values()],
                    "Helper{k}")
    legs = rig.detect_legs(arm)
    got = sorted(tuple(renamed[b] for b in leg.bones) for leg in legs)
    assert got == sorted(expected.values())


def test_scaled_and_rotated_rig_gives_the_same_morphology(empty_scene: Any) -> None:
    small = creatures.build_wolf(empty_scene, name="Small")
    big = creatures.build_wolf(empty_scene, name="Big", location=(3.0, -2.0, 1.0))
    big.scale = (100.0, 100.0, 100.0)
    big.rotation_euler = (0.0, 0.0, np.pi / 2)
    bpy.context.view_layer.update()
    m_small = rig.morphology_of(rig.read_rig(small))
    info_big = rig.read_rig(big)
    m_big = rig.morphology_of(info_big)
    assert m_big.labels == m_small.labels
    assert np.allclose(m_big.rest_joints, 100.0 * m_small.rest_joints, atol=1e-4)
    assert m_big.body_thickness == pytest.approx(100.0 * m_small.body_thickness, rel=1e-5)
    # Facing -Y turned by 90 degrees about Z is facing +X.
    assert np.allclose(info_big.body.forward, [1.0, 0.0, 0.0], atol=1e-6)


def test_non_uniform_scale_is_refused(empty_scene: Any) -> None:
    arm = creatures.build_robot(empty_scene)
    arm.scale = (1.0, 2.0, 1.0)
    bpy.context.view_layer.update()
    with pytest.raises(rig.RigError, match="non-uniform"):
        rig.read_rig(arm)


def test_bad_user_legs_are_refused(empty_scene: Any) -> None:
    arm = creatures.build_robot(empty_scene)
    with pytest.raises(rig.RigError, match="not an ancestor"):
        rig.leg_from_bones(arm, "Leg2_foot.L", "Leg2_thigh.L")
    with pytest.raises(rig.RigError, match="no bone"):
        rig.leg_from_bones(arm, "Leg2_thigh.L", "Nope")
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    eb = arm.data.edit_bones["Leg2_shin.L"]
    # Blender removes truly zero-length bones on leaving edit mode; a 1e-10 bone stays.
    eb.tail = eb.head + type(eb.head)((0.0, 0.0, 1e-10))
    bpy.ops.object.mode_set(mode="OBJECT")
    if "Leg2_shin.L" in arm.data.bones:
        with pytest.raises(rig.RigError, match=r"zero.length"):
            rig.leg_from_bones(arm, "Leg2_thigh.L", "Leg2_foot.L")
    else:  # Blender 4.2 deletes the bone and reparents its child: a valid two-bone leg
        assert rig.leg_from_bones(arm, "Leg2_thigh.L", "Leg2_foot.L").bones == ("Leg2_thigh.L", "Leg2_foot.L")
    # A user-chosen end-effector before the foot gets the flat bones after it as its foot.
    human = creatures.build_human(empty_scene)
    leg = rig.leg_from_bones(human, "thigh.L", "shin.L")
    assert leg.bones == ("thigh.L", "shin.L")
    assert leg.foot[:1] == ("foot.L",)


def test_matrix_to_quaternion_matches_mathutils() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(300, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    mats = np.array([np.array(Quaternion(x).to_matrix()) for x in q])
    got = rig.matrix_to_quaternion(mats)
    dots = np.abs(np.sum(got * q, axis=1))
    assert np.allclose(dots, 1.0, atol=1e-9)


def _fk_truth(arm: Any, info: rig.RigInfo, n_frames: int, seed: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Ground truth poses made by Blender itself: random hinge rotations of every leg bone
    about its leg's plane normal and a moving, turning, pitching body. Returns the body
    frames (F, 4, 4) and per-leg world joints (F, k + 1, 3) read back through the depsgraph."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n_frames)
    yaw = 0.8 * np.sin(2 * np.pi * t)
    pitch = 0.15 * np.sin(4 * np.pi * t)
    body = np.repeat(info.body.matrix[None], n_frames, axis=0)
    for f in range(n_frames):
        rz = np.array(Matrix.Rotation(yaw[f], 3, "Z"))
        ry = np.array(Matrix.Rotation(pitch[f], 3, "Y"))
        body[f, :3, :3] = rz @ info.body.matrix[:3, :3] @ ry
        shift = np.array([0.4 * t[f], 0.1 * t[f], 0.05 * np.sin(3 * t[f])])
        body[f, :3, 3] = info.body.origin + shift * info.scale
    # Truth: drive the body bone and the leg bones by hand-made basis rotations.
    action = actions.new_action(arm, "Truth")
    frames = np.arange(1, n_frames + 1, dtype=float)
    bones: list[str] = []
    quats: list[np.ndarray] = []
    for leg in info.legs:
        for _name in leg.bones:
            axis = rng.normal(size=3) * 0.2 + np.array([1.0, 0.0, 0.0])
            axis /= np.linalg.norm(axis)
            angle = 0.4 * np.sin(2 * np.pi * (t + rng.random()))
            quats.append(np.column_stack([np.cos(angle / 2), np.sin(angle / 2)[:, None] * axis]))
        bones += list(leg.bones)
    actions.write_pose_bone_transforms(action, arm, frames, bones, np.stack(quats, axis=1))
    actions.assign_generated_action(arm, action)
    joints = []
    for leg in info.legs:
        heads, tails = bone_heads_tails(arm, frames.astype(int), list(leg.bones))
        joints.append(np.concatenate([heads, tails[:, -1:]], axis=1))
    # The truth above moves legs relative to a body at rest; now move the body too.
    delta = body @ np.linalg.inv(info.body.matrix)
    joints = [np.einsum("fij,fkj->fki", delta[:, :3, :3], j) + delta[:, None, :3, 3] for j in joints]
    return body, joints


@pytest.mark.parametrize(("kind", "mode"),
                         [("spider", "QUATERNION"), ("wolf", "XYZ"), ("robot", "AXIS_ANGLE")])
def test_solved_pose_reproduces_joint_positions(empty_scene: Any, kind: str, mode: str) -> None:
    arm = creatures.BUILDERS[kind](empty_scene, location=(1.0, 2.0, 0.5))
    arm.scale = (3.0, 3.0, 3.0)
    arm.rotation_euler = (0.0, 0.0, 0.7)
    bpy.context.view_layer.update()
    for pb in arm.pose.bones:
        pb.rotation_mode = mode
    info = rig.read_rig(arm)
    n = 12
    body, joints = _fk_truth(arm, info, n, seed=7)
    tracks = rig.solve_pose(info, body, joints)
    action = actions.new_action(arm)
    actions.write_pose_bone_transforms(action, arm, np.arange(1, n + 1), tracks.bones, tracks.rotations)
    loc_bones = [b for b, k in zip(tracks.bones, tracks.keyed_location, strict=True) if k]
    loc_idx = [tracks.bones.index(b) for b in loc_bones]
    actions.write_pose_bone_transforms(action, arm, np.arange(1, n + 1), loc_bones,
                                       locations=tracks.locations[:, loc_idx])
    actions.assign_generated_action(arm, action)

    frames = list(range(1, n + 1))
    scale = float(info.leg_length.mean())
    for leg, want in zip(info.legs, joints, strict=True):
        heads, tails = bone_heads_tails(arm, frames, list(leg.bones))
        got = np.concatenate([heads, tails[:, -1:]], axis=1)
        err = np.max(np.linalg.norm(got - want, axis=-1))
        assert err < 1e-4 * scale, (leg.label, err)
    # The body bone moves rigidly with the body frame.
    mats = pose_matrices(arm, frames, [info.body_bone])[:, 0]
    delta = body @ np.linalg.inv(info.body.matrix)
    want_mats = delta @ info.world @ info.rest_local[info.body_bone]
    assert np.allclose(mats, want_mats, atol=1e-4 * scale)


def test_planted_foot_keeps_its_heading_while_the_body_turns(empty_scene: Any) -> None:
    """A planted foot does not turn on the ground with the body (the example lizard's girdle
    yaws 6 deg a frame): it keeps the heading it landed with; in its swing it comes round to
    the body's heading, and lands with it."""
    arm = creatures.build_wolf(empty_scene)
    info = rig.read_rig(arm)
    n = 10
    yaw = np.radians(4.0) * np.arange(n)  # the body turns 4 deg a frame about its origin
    body = np.repeat(info.body.matrix[None], n, axis=0)
    for f in range(n):
        body[f, :3, :3] = np.array(Matrix.Rotation(yaw[f], 3, "Z")) @ info.body.matrix[:3, :3]
    delta = body @ np.linalg.inv(info.body.matrix)
    joints = [np.einsum("fij,kj->fki", delta[:, :3, :3], j) + delta[:, None, :3, 3] for j in info.joints]
    planted = np.ones((n, len(info.legs)), dtype=bool)
    planted[5:8] = False  # down for frames 1-5, a swing for 6-8, down again from 9
    tracks = rig.solve_pose(info, body, joints, planted=planted)
    action = actions.new_action(arm)
    actions.write_pose_bone_transforms(action, arm, np.arange(1, n + 1), tracks.bones, tracks.rotations,
                                       tracks.locations)
    actions.assign_generated_action(arm, action)
    frames = list(range(1, n + 1))
    feet = [leg.foot[0] for leg in info.legs if leg.foot]
    assert feet
    rot = pose_matrices(arm, frames, feet)[..., :3, :3]
    rest = np.stack([np.array(arm.matrix_world)[:3, :3] @ np.array(arm.data.bones[b].matrix_local)[:3, :3]
                     for b in feet])
    rest = rest / np.linalg.norm(rest, axis=-2, keepdims=True)

    def turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        cos = (np.trace(np.swapaxes(a, -1, -2) @ b, axis1=-2, axis2=-1) - 1.0) / 2.0
        return np.asarray(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))

    # planted: the heading it landed with (at rest here) on frames 1-5
    assert turn(rot[:5], rest[None]).max() < 0.01
    # it lands with the body's heading (frame 9) and keeps it (frame 10)
    for f in (8, 9):
        want = np.array(Matrix.Rotation(yaw[8], 3, "Z"))[None] @ rest
        assert turn(rot[f], want).max() < 0.01, f
    # and gets there in its swing, a few degrees a frame
    assert turn(rot[1:], rot[:-1]).max() < 20.0


def test_knee_plane_kept_without_twist(empty_scene: Any) -> None:
    """Each leg bone's local axes keep their rest relation to the leg plane: no added twist."""
    arm = creatures.build_wolf(empty_scene)
    info = rig.read_rig(arm)
    n = 6
    body, joints = _fk_truth(arm, info, n, seed=3)
    tracks = rig.solve_pose(info, body, joints)
    action = actions.new_action(arm)
    actions.write_pose_bone_transforms(action, arm, np.arange(1, n + 1), tracks.bones, tracks.rotations,
                                       tracks.locations)
    actions.assign_generated_action(arm, action)
    frames = list(range(1, n + 1))
    for leg, rest_j, cur_j in zip(info.legs, info.joints, joints, strict=True):
        mats = pose_matrices(arm, frames, list(leg.bones))
        n_rest = rig._unit(rig._bend_normal(rest_j))
        n_cur = rig._unit(rig._bend_normal(cur_j))
        # The plane's side is the one facing like the body-turned rest normal.
        turned = np.einsum("fij,j->fi", (body @ np.linalg.inv(info.body.matrix))[:, :3, :3], n_rest)
        n_cur *= np.sign(np.einsum("fi,fi->f", n_cur, turned))[:, None]
        for b, name in enumerate(leg.bones):
            # Twist = angle of the bone's X axis about its own axis, measured from the leg
            # plane's normal (made perpendicular to the bone). It must stay the rest twist.
            rest_m = info.world[:3, :3] @ info.rest_local[name][:3, :3]
            rest_m /= np.linalg.norm(rest_m, axis=0)
            f_rest = rig._frames(rest_m[:, 1], n_rest)
            twist_rest = np.arctan2(rest_m[:, 0] @ f_rest[:, 2], rest_m[:, 0] @ f_rest[:, 1])
            m = mats[:, b, :3, :3] / np.linalg.norm(mats[:, b, :3, :3], axis=1)[:, None, :]
            f_now = rig._frames(m[:, :, 1], n_cur)
            twist_now = np.arctan2(np.einsum("fi,fi->f", m[:, :, 0], f_now[:, :, 2]),
                                   np.einsum("fi,fi->f", m[:, :, 0], f_now[:, :, 1]))
            assert np.allclose(twist_now, twist_rest, atol=1e-4), name


def test_numbered_legs_without_sides_get_sides_from_where_they_are(empty_scene: Any) -> None:
    """``Leg1 > Leg1.001 > Leg1.002``, ..., ``Leg5``: names say "leg" and a number only."""
    arm = creatures.build_robot(empty_scene)
    renamed = {}
    for n, chain in enumerate(creatures.ROBOT_LEGS, start=1):
        for k, name in enumerate(chain):
            new = f"Leg{n}" if k == 0 else f"Leg{n}.{k:03d}"
            arm.data.bones[name].name = new
            renamed[new] = name
    legs = rig.detect_legs(arm)
    got = {leg.label: tuple(renamed[b] for b in leg.bones) for leg in legs}
    assert got == {label: chain for label, (chain, _foot) in EXPECTED["robot"].items()}


# ---------------------------------------------------------------------------------------
# The spine chain (thesis §4.2): read from the rig, written back where the core puts it

SPINES = {
    "wolf": (("spine.004", "spine.005", "spine.006", "spine.007", "spine.008", "spine.009", "spine.010",
              "spine.011"), {"L1": "spine.008", "R1": "spine.008", "L2": "spine.005", "R2": "spine.005"}),
    "lizard": (("Hips", "Spine.001", "Spine.002", "Spine.003", "Spine.004", "Chest", "Neck", "Head"),
               {"L1": "Chest", "R1": "Chest", "L2": "Hips", "R2": "Hips"}),
}


@pytest.mark.parametrize("kind", ["wolf", "lizard"])
def test_spine_chain_runs_from_the_hips_to_the_head_and_carries_the_girdles(
    empty_scene: Any, kind: str
) -> None:
    arm = creatures.BUILDERS[kind](empty_scene)
    chain, carriers = SPINES[kind]
    info = rig.read_rig(arm, spine=True)
    assert info.spine == chain
    assert info.body_bone == chain[0]
    layout = info.spine_layout
    assert layout is not None
    # core bone i is chain bone -1 - i; each leg hangs from its parent spine bone
    carried = {leg.label: chain[-1 - int(b)] for leg, b in zip(info.legs, layout.leg_bone, strict=True)}
    assert carried == carriers
    # nodes: the head tip, the front girdle, the hips' head; front legs on node 1, hind on node 2
    assert layout.key_joint.tolist() == [0, 3, len(chain)]
    assert layout.leg_key.tolist() == [1, 1, 2, 2]
    bones = arm.data.bones
    world = np.array(arm.matrix_world)
    tip, hips = np.array(bones[chain[-1]].tail_local), np.array(bones[chain[0]].head_local)
    assert layout.joints[0] == pytest.approx(world[:3, :3] @ tip + world[:3, 3])
    assert layout.joints[-1] == pytest.approx(world[:3, :3] @ hips + world[:3, 3])
    assert set(chain) <= set(info.driven_bones)
    morph = rig.morphology_of(info, joint_yaw_limit=0.3)
    assert morph.spine is not None
    assert morph.pelvis_node.tolist() == [1, 1, 2, 2]
    assert morph.spine.n_joints == len(chain) + 1
    np.testing.assert_allclose(morph.spine.joint_yaw_limit, 0.3)
    # the same rig read without the spine keeps its spine bones out of the keys
    plain = rig.read_rig(arm)
    assert plain.spine == chain
    assert plain.spine_layout is None
    assert not set(chain[1:]) & set(plain.driven_bones)
    assert rig.morphology_of(plain).spine is None


@pytest.mark.parametrize("kind", ["spider", "ant", "robot", "human"])
def test_rigs_whose_legs_hang_from_one_bone_have_no_spine_to_bend(empty_scene: Any, kind: str) -> None:
    arm = creatures.BUILDERS[kind](empty_scene)
    info = rig.read_rig(arm, spine=True)
    assert info.spine_layout is None
    assert info.spine[0] == info.body_bone
    assert rig.morphology_of(info).spine is None


def test_spine_pose_is_written_where_the_core_puts_it(empty_scene: Any) -> None:
    """Spine bones keyed from the core's bone rotations put every spine joint and every hip
    (legs hang from spine.005 and spine.008) where the core's spine does: a moved, turned,
    scaled wolf, bent sideways and up."""
    from procloco_addon.core.locomotion import spine as core_spine

    arm = creatures.build_wolf(empty_scene, location=(1.0, 2.0, 0.0))
    arm.scale = (2.0, 2.0, 2.0)
    arm.rotation_euler = (0.0, 0.0, 0.7)
    bpy.context.view_layer.update()
    arm.pose.bones["spine.006"].rotation_mode = "XYZ"
    info = rig.read_rig(arm, spine=True)
    morph = rig.morphology_of(info)
    model = morph.spine
    assert model is not None
    n = 6
    t = np.linspace(0.0, 1.0, n)
    heading = 0.3 + 0.8 * t
    rest_keys = model.key_rest
    c, s = np.cos(heading), np.sin(heading)
    # key node guides: the rest layout turned by the heading, the head swung aside and raised
    guides = np.einsum("fij,kj->fki", np.stack([np.stack([c, -s, 0 * c], -1), np.stack([s, c, 0 * c], -1),
                                                np.stack([0 * c, 0 * c, 1 + 0 * c], -1)], -2), rest_keys)
    guides += np.array([3.0, -1.0, 0.2])
    guides[:, 0, :2] += 0.15 * t[:, None] * np.stack([-s, c], axis=1)
    guides[:, 0, 2] += 0.1 * t
    yaw = heading[:, None] + np.array([0.5, 0.25, 0.0])[None] * t[:, None]
    pitch = np.array([0.1, 0.05, -0.05])[None] * t[:, None]
    spines = core_spine.SpineBatch.of(model)
    pose = core_spine.build_spine(spines, guides, yaw, pitch)
    hips = core_spine.hip_positions(spines, pose)
    frames_leg = core_spine.leg_frames(spines, pose)
    to_body = np.linalg.inv(info.body.matrix)
    joints = []
    for k, rest_j in enumerate(info.joints):
        local = rest_j @ to_body[:3, :3].T + to_body[:3, 3]  # the leg at rest, in the body frame
        joints.append(hips[:, k, None] + np.einsum("fij,pj->fpi", frames_leg[:, k], local - local[0]))
    body = np.repeat(info.body.matrix[None], n, axis=0)
    tracks = rig.solve_pose(info, body, joints, spine_rotation=pose.bone_rotation, spine_joints=pose.joints,
                            leg_frames=frames_leg)
    action = actions.new_action(arm)
    frames = np.arange(1, n + 1)
    actions.write_pose_bone_transforms(action, arm, frames, tracks.bones, tracks.rotations, tracks.locations)
    actions.assign_generated_action(arm, action)
    scale = float(info.leg_length.mean())
    chain = list(info.spine[::-1])  # head bone first, as the core's bones
    heads, tails = bone_heads_tails(arm, list(frames), chain)
    got = np.concatenate([tails[:, :1], heads], axis=1)
    assert np.abs(got - pose.joints).max() < 1e-4 * scale
    for leg, want in zip(info.legs, joints, strict=True):
        heads, tails = bone_heads_tails(arm, list(frames), list(leg.bones))
        got = np.concatenate([heads, tails[:, -1:]], axis=1)
        assert np.abs(got - want).max() < 1e-4 * scale, leg.label
    # the spine bent: the head bone turned from the hips' bone by more than 10 degrees
    mats = pose_matrices(arm, [n], [chain[0], chain[-1]])[0]
    y_head, y_hips = mats[0, :3, 1], mats[1, :3, 1]
    turn = np.degrees(np.arctan2(y_head[1], y_head[0]) - np.arctan2(y_hips[1], y_hips[0]))
    assert abs((turn + 180.0) % 360.0 - 180.0) > 10.0
    with pytest.raises(ValueError, match="spine is driven"):
        rig.solve_pose(info, body, joints)


def test_feet_follow_the_ground_they_stand_on_and_not_the_ground_below_them(empty_scene: Any) -> None:
    """The wolf's hind paw (``toe.L``) with its leg at rest over different grounds: flat, a
    slope falling away ahead (toes follow it down), a slope rising (toes lift), the ground a
    leg length below (a foot in the air keeps its rest orientation instead of pointing its
    toes at the ground) and no ground at all (over a gap)."""
    arm = creatures.build_wolf(empty_scene)
    info = rig.read_rig(arm)
    k = [leg.label for leg in info.legs].index("L2")
    end = info.joints[k][-1]
    contact_z = float(info.contact[k, 2])
    forward = info.body.forward[:2]
    leg_length = float(info.leg_length[k])
    slopes = {0: 0.0, 1: np.radians(-20.0), 2: np.radians(15.0)}

    def ground(frame_index: np.ndarray, xy: np.ndarray) -> np.ndarray:
        ahead = np.maximum((xy - end[:2]) @ forward, 0.0)
        z = np.empty(len(xy))
        for f in np.unique(frame_index):
            pick = frame_index == f
            if f in slopes:
                z[pick] = contact_z + np.tan(slopes[int(f)]) * ahead[pick]
            elif f == 3:
                z[pick] = contact_z - leg_length
            else:
                z[pick] = -np.inf
        return z

    ground.dynamic = True  # type: ignore[attr-defined]
    n = 5
    body = np.repeat(info.body.matrix[None], n, axis=0)
    joints = [np.repeat(j[None], n, axis=0) for j in info.joints]
    tracks = rig.solve_pose(info, body, joints, ground=ground)
    action = actions.new_action(arm)
    actions.write_pose_bone_transforms(action, arm, np.arange(1, n + 1), tracks.bones, tracks.rotations,
                                       tracks.locations)
    actions.assign_generated_action(arm, action)
    paw = pose_matrices(arm, list(range(1, n + 1)), ["toe.L"])[:, 0]
    rest = (info.world @ info.rest_local["toe.L"])[:3, 1]
    # The paw stands on its skin: the lowest vertex of the toe's capsule is its sole.
    skin = skin_vertices(creatures.skin_of(arm), list(range(1, n + 1)), ["toe.L"])
    under = np.stack([ground(np.full(skin.shape[1], f), skin[f, :, :2]) for f in range(n)])
    tip = skin[np.arange(n), np.argmin(skin[..., 2] - under, axis=1)]

    def pitch(v: np.ndarray) -> float:  # degrees above the horizontal
        return float(np.degrees(np.arctan2(v[2], np.linalg.norm(v[:2]))))

    tilt = np.array([pitch(v) - pitch(rest) for v in paw[:, :3, 1]])
    # On the ground it stands on, the paw turns until its sole touches it: down the falling
    # slope, up the rising one (less than the slope: the skin under its heel touches too).
    assert abs(tilt[0]) < 0.1
    assert tilt[1] < -5.0, tilt
    assert tilt[2] > 5.0, tilt
    above = tip[:3, 2] - ground(np.arange(3), tip[:3, :2])
    assert np.all(above > -1e-4 * leg_length), above  # never into the ground
    assert np.all(above < 0.006 * leg_length), above  # and down onto it
    # In the air, or over nothing, the paw keeps its rest orientation.
    np.testing.assert_allclose(tilt[3:], 0.0, atol=0.1)


def test_a_standing_foot_keeps_its_pitch_on_an_edge_and_a_moved_one_finds_its_own(empty_scene: Any) -> None:
    """Over ground that does not move, a foot standing still (the IK holds a planted
    end-effector to a nanometre, not to the last bit) is pitched once, where it began to
    stand: with its toe exactly on the edge of a step, end-effectors a tenth of a nanometre
    apart do not flicker its pitch from frame to frame. A foot moved by a millimetre, onto
    the step, is pitched where it is."""
    arm = creatures.build_wolf(empty_scene)
    info = rig.read_rig(arm)
    k = [leg.label for leg in info.legs].index("L2")
    end = info.joints[k][-1]
    forward = info.body.forward[:2] / np.linalg.norm(info.body.forward[:2])
    reach = float(np.max((info.foot_points[k][:, :2] - end[:2]) @ forward))  # the toe tip, ahead
    contact_z = float(info.contact[k, 2])

    def ground(frame_index: np.ndarray, xy: np.ndarray) -> np.ndarray:
        ahead = (xy - end[:2]) @ forward
        return contact_z + np.where(ahead > reach, 0.02, 0.0)  # a 2 cm step at the toe tip

    ground.dynamic = False  # type: ignore[attr-defined]
    n = 6
    body = np.repeat(info.body.matrix[None], n, axis=0)
    joints = [np.repeat(j[None], n, axis=0) for j in info.joints]
    nudge = np.zeros(3)
    nudge[:2] = 1e-10 * forward
    joints[k][1::2, -1] += nudge  # (odd frames: the tip a tenth of a nanometre onto the step)
    tracks = rig.solve_pose(info, body, joints, ground=ground)
    toe = tracks.bones.index(info.legs[k].foot[0])

    def turn(q: np.ndarray, r: np.ndarray) -> np.ndarray:  # degrees between quaternions
        return np.degrees(2.0 * np.arccos(np.clip(np.abs(np.sum(q * r, axis=-1)), 0.0, 1.0)))

    assert np.abs(tracks.rotations[1:, toe] - tracks.rotations[:1, toe]).max() < 1e-8
    alone = rig.solve_pose(info, body[:1], [j[:1] for j in joints], ground=ground)
    assert np.abs(tracks.rotations[0, toe] - alone.rotations[0, toe]).max() < 1e-12
    # (pitched frame by frame, as over a moving ground, the nudged frames do step up)
    ground.dynamic = True  # type: ignore[attr-defined]
    flicker = rig.solve_pose(info, body, joints, ground=ground).rotations[:, toe]
    assert turn(flicker[1::2], flicker[::2]).min() > 1.0
    ground.dynamic = False  # type: ignore[attr-defined]
    # Moved a millimetre forward from frame 3 on, the foot stands on the step's edge: pitched up.
    joints[k][3:, -1] += 1000.0 * 1e-6 * np.append(forward, 0.0)
    moved = rig.solve_pose(info, body, joints, ground=ground).rotations[:, toe]
    assert turn(moved[3], moved[2]) > 1.0
    assert np.abs(moved[4:] - moved[3:4]).max() < 1e-8


def _same_info(a: rig.RigInfo, b: rig.RigInfo) -> bool:
    return (a.legs == b.legs and a.body_bone == b.body_bone
            and all(np.array_equal(x, y) for x, y in zip(a.joints, b.joints, strict=True))
            and all(np.array_equal(x, y) for x, y in zip(a.foot_points, b.foot_points, strict=True))
            and np.array_equal(a.contact, b.contact) and np.array_equal(a.world, b.world)
            and all(np.array_equal(a.basis[n], b.basis[n]) for n in a.basis))


def test_a_read_cache_gives_an_unchanged_rig_back_and_reads_a_changed_one_again(
        empty_scene: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """Live Preview's ReadCache: the rig read before when nothing it was read from changed;
    read again (as a fresh reading gives it) when the rig moved or a bone that is not driven
    was posed; its skins' weights, which are not in the digest, when it is told a mesh was
    edited (forget_meshes)."""
    from procloco_addon.blender.rig import read

    arm = creatures.build_wolf(empty_scene)
    skin = next(o for o in bpy.data.objects if o.type == "MESH")
    cache = rig.ReadCache()
    calls = spy(monkeypatch, read, "_read_rest", lambda obj: obj.name)

    def cached() -> tuple[rig.RigInfo, int]:
        """The reading through the cache, and how many times the rest arrays were read for it."""
        before = len(calls)
        with rig.reading_once(cache):
            info = rig.read_rig(arm, spine=True)
        return info, len(calls) - before

    first, n = cached()
    assert n == 1
    again, n = cached()
    assert again is first
    assert n == 0
    assert _same_info(first, rig.read_rig(arm, spine=True))
    arm.location.x += 0.5  # moved: read again
    bpy.context.view_layer.update()
    moved, n = cached()
    assert moved is not first
    assert n == 1
    assert np.allclose(moved.joints[0] - first.joints[0], [0.5, 0.0, 0.0])
    arm.pose.bones["spine"].rotation_quaternion = (0.9, 0.1, 0.0, 0.0)  # the tail tip: not driven
    bpy.context.view_layer.update()
    posed, n = cached()
    assert posed is not moved
    assert n == 0
    assert _same_info(posed, rig.read_rig(arm, spine=True))
    assert not _same_info(posed, moved)
    # A hind toe's vertices taken out of its group: the weights are not in the digest...
    group = skin.vertex_groups["toe.L"]
    group.remove([v.index for v in skin.data.vertices if any(g.group == group.index for g in v.groups)])
    kept, n = cached()
    assert kept is posed
    assert n == 0
    cache.forget_meshes()  # ... until the cache is told a mesh was edited
    reread, n = cached()
    assert reread is not posed
    assert n == 1
    assert _same_info(reread, rig.read_rig(arm, spine=True))
    assert not _same_info(reread, posed)  # that foot's sole comes from its bones now


def test_rigs_solved_together_get_the_poses_they_get_alone(empty_scene: Any) -> None:
    """solve_poses_steps: two wolves (one turned, both walking their own way, feet pitched on
    a shared ground) and a spider in one call; each rig's channels as solved alone (the wolves
    in one pass: but for the last bit), in the order given."""
    from procloco_addon.core.steps import run_steps

    wolves = [creatures.build_wolf(empty_scene, name=f"Wolf{k}", location=(3.0 * k, 0.0, 0.0))
              for k in range(2)]
    wolves[1].rotation_euler = (0.0, 0.0, 0.4)
    spider = creatures.build_spider(empty_scene, location=(0.0, 4.0, 0.0))
    bpy.context.view_layer.update()

    def ground(frame_index: np.ndarray, xy: np.ndarray) -> np.ndarray:
        return 0.03 * np.sin(3.0 * xy[:, 0]) * np.cos(2.0 * xy[:, 1])  # bumps under the toes

    ground.dynamic = False  # type: ignore[attr-defined]
    n = 10
    t = np.linspace(0.0, 1.0, n)
    inputs = []
    for k, arm in enumerate([wolves[0], spider, wolves[1]]):
        info = rig.read_rig(arm)
        body = np.repeat(info.body.matrix[None], n, axis=0)
        body[:, :3, 3] += np.outer(t, [0.3, 0.1 * k, 0.0])
        move = np.outer(t, [0.3, 0.1 * k, 0.02])[:, None]
        joints = [np.repeat(j[None], n, axis=0) + move for j in info.joints]
        for leg_joints in joints:
            leg_joints[:, 1:-1] += 0.01 * np.sin(7.0 * t + k)[:, None, None]  # the knees move
        planted = np.zeros((n, len(info.legs)), dtype=bool)
        planted[: n // 2, ::2] = True
        inputs.append(rig.PoseInputs(info, body, tuple(joints), ground, planted=planted))
    together = run_steps(rig.solve_poses_steps(inputs))
    for inp, got in zip(inputs, together, strict=True):
        alone = rig.solve_pose(inp.info, inp.body_world, inp.joints_world, ground=ground, planted=inp.planted)
        assert got.bones == alone.bones
        np.testing.assert_allclose(got.rotations, alone.rotations, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(got.locations, alone.locations, rtol=0.0, atol=1e-12)
    feet = [together[0].bones.index(leg.foot[0]) for leg in inputs[0].info.legs]
    assert np.ptp(together[0].rotations[:, feet], axis=0).max() > 1e-3  # the feet were pitched
