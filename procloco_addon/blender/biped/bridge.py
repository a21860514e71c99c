# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender ⇄ core for the biped planner: rig, clips, walkable surfaces, the written Action.

**Rig.** :func:`biped_rig` turns an armature into the core :class:`~...core.biped.Skeleton`.
The legs are the rig's two legs (detected or set in the Rig & Legs panel; each a thigh
and a shin, then the foot bones); joint 0 is the body bone the legs hang from, and every
bone under it is a joint. Two leaf joints per foot are added: the *heel* (the middle of a
bone named like "heel" in the foot, else under the ankle) and the *toe* (the tip of the
last foot bone), both put on the ground, the points the planner's IK holds (§3.8.3).

Rotations. A core joint rotation is the bone's rotation *in the world*, relative to its
rest, taken relative to its parent's, with the rest pose facing +X (the core's body frame:
x forward, y left, z up). A pose bone's ``matrix_basis`` is relative to its own rest axes;
the two are related by conjugation with the bone's rest matrix and the rig's rest heading
(see :func:`pose_to_core` and :func:`core_to_basis`). Object scale and rotation are
honoured; the object itself is never animated.

**Clips.** :func:`read_clip` plays an Action on the rig (temporarily assigned, NLA off,
everything restored afterwards) and records the pose per frame. The root is the pelvis
projected on the ground and smoothed (as one loop of the motion when a walk or run holds
exactly one stride, so that the stride joins itself without a jump); foot contacts come
from the Action's pose markers (``L down``, ``L up``, ``R down``, ``R up``) when there are
any, else from the feet's speed and height. Walks, runs and jumps are cut to one stride
(right touchdown to right touchdown) unless they already are one.
:func:`write_clip_action` writes a core clip as a new Action (the example clips).

**Surfaces.** :func:`walkable_surface` takes the upward faces (up to ``max_slope``) of the
terrain objects (same choice and roles as Generate Locomotion: ``AVOID`` objects are cut
out, ``IGNORE`` ones skipped) around the start and the goal, rasterised in cells of
2.5 cm for the reference leg, scaled to the rig (2.9 cm for the example human): fine
enough that a foot fits on a 35 cm stair tread with the raster's half-cell slack.

**Result.** :func:`write_motion` writes the planned motion as a new Action through
:mod:`...actions` (never into an existing one) and assigns it, remembering the old one.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import bpy
import numpy as np
from mathutils import Matrix

from ... import core as _core  # noqa: F401  (the core package must import without bpy)
from ...core.biped import quat
from ...core.biped.clip import Clip, ClipRole, detect_contacts, extract_cycle, recorded_clip
from ...core.biped.planner import BipedMotion
from ...core.biped.skeleton import LEFT, RIGHT, LegJoints, Skeleton, foot_points, forward_kinematics
from ...core.biped.surface import WalkableSurface
from .. import actions, pose_writer, rig, scene_terrain
from ..rig import controls

__all__ = [
    "BipedError",
    "BipedRig",
    "biped_rig",
    "contacts_from_markers",
    "core_to_basis",
    "pose_to_core",
    "read_clip",
    "walkable_surface",
    "write_clip_action",
    "write_motion",
]


class BipedError(ValueError):
    """The biped planner cannot run as asked (the message is meant for the user)."""


@dataclass(frozen=True)
class BipedRig:
    """An armature seen as a core biped skeleton.

    ``bones`` are the Blender bones of the first ``len(bones)`` joints (the others are the
    added heel and toe points); ``rest_rot``/``rest_head`` their armature-space rest
    rotations ``(B, 3, 3)`` and heads ``(B, 3)``; ``world``/``world_rot``/``scale`` the
    object's matrix, its rotation and its uniform scale; ``yaw0`` the rest heading of the
    body; ``root0 (3,)`` the rest root (under the hips, on the ground).
    """

    object_name: str
    skeleton: Skeleton
    bones: tuple[str, ...]
    rest_rot: np.ndarray
    rest_head: np.ndarray
    world: np.ndarray
    world_rot: np.ndarray
    scale: float
    yaw0: float
    root0: np.ndarray
    body_parent_pose: np.ndarray | None  # (4, 4) armature pose of the body bone's parent
    body_parent_rest: np.ndarray | None  # (4, 4) its rest (matrix_local)
    step_width: float
    warnings: tuple[str, ...] = ()

    @property
    def n_bones(self) -> int:
        return len(self.bones)


def _rz(yaw: float | np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack((np.stack((c, -s, z), -1), np.stack((s, c, z), -1), np.stack((z, z, o), -1)), -2)


def _orthonormal(m: np.ndarray) -> np.ndarray:
    """Rotation part of ``(..., 3, 3)`` matrices (columns normalised: bones do not shear)."""
    return m / np.linalg.norm(m, axis=-2, keepdims=True)


def biped_rig(obj: bpy.types.Object) -> BipedRig:
    """Read ``obj`` as a biped (see the module docstring). Raises :class:`BipedError`."""
    if obj is None or obj.type != "ARMATURE":
        raise BipedError("The active object is not an armature: select the biped rig")
    settings = obj.procloco
    try:
        from ..locomotion.generate import settings_legs, stale_bones

        legs = settings_legs(obj)
        # Bones an earlier ProcLoco Action poses are read at rest, as Generate reads them: a
        # second plan must not start from the pose the first one left on the rig.
        info = rig.read_rig(obj, legs, settings.forward_axis, at_rest=stale_bones(obj))
    except rig.RigError as err:
        raise BipedError(str(err)) from err
    if len(info.legs) != 2:
        raise BipedError(f"'{obj.name}' has {len(info.legs)} legs: the biped planner needs exactly two")
    lefts = [i for i, leg in enumerate(info.legs) if leg.label.upper().startswith("L")]
    rights = [i for i, leg in enumerate(info.legs) if leg.label.upper().startswith("R")]
    if len(lefts) != 1 or len(rights) != 1:
        raise BipedError("The biped planner needs one left and one right leg (labels L… and R…)")
    for leg in info.legs:
        if len(leg.bones) != 2:
            raise BipedError(
                f"Leg {leg.label} has {len(leg.bones)} bones from hip to end-effector: the biped "
                "planner needs a thigh and a shin (set the end-effector to the shin)"
            )
        if not leg.foot:
            raise BipedError(f"Leg {leg.label} has no foot bone after its shin")

    bones = obj.data.bones
    names = [b.name for b in bones]
    index = {n: i for i, n in enumerate(names)}
    body = info.body_bone
    # The body bone and everything under it, parents first.
    order: list[str] = []
    stack = [body]
    while stack:
        name = stack.pop(0)
        order.append(name)
        stack = [c.name for c in bones[name].children] + stack
    j_of = {n: j for j, n in enumerate(order)}
    nb = len(order)
    local = np.array([np.array(bones[n].matrix_local, dtype=np.float64) for n in order])
    rest_rot = _orthonormal(local[:, :3, :3])
    rest_head = local[:, :3, 3]
    world = np.array(obj.matrix_world, dtype=np.float64)
    scale = float(info.scale)
    world_rot = world[:3, :3] / scale
    head_w = rest_head @ world[:3, :3].T + world[:3, 3]
    fwd = info.body.forward
    yaw0 = float(np.arctan2(fwd[1], fwd[0]))
    # Rest geometry only (never the current pose, so that planning twice gives the same walk):
    # each foot's lowest rest point, the hips' centroid.
    tail_w = np.array([np.array(bones[n].tail_local) for n in order]) @ world[:3, :3].T + world[:3, 3]
    foot_ground = []
    for leg in info.legs:
        sub = [j_of[b.name] for f in leg.foot if f in j_of for b in _subtree(bones[f])]
        foot_ground.append(float(min(head_w[sub, 2].min(), tail_w[sub, 2].min())) if sub else 0.0)
    ground = float(min(foot_ground))
    hips = np.array([head_w[j_of[leg.bones[0]]] for leg in info.legs])
    root0 = np.array([hips[:, 0].mean(), hips[:, 1].mean(), ground])
    to_body = _rz(-yaw0)

    parents = [-1] + [j_of[bones[n].parent.name] for n in order[1:]]
    offsets = [to_body @ (head_w[0] - root0)]
    offsets += [to_body @ (head_w[j] - head_w[parents[j]]) for j in range(1, nb)]
    joint_names = list(order)
    leg_joints = {}
    for side, i in ((LEFT, lefts[0]), (RIGHT, rights[0])):
        leg = info.legs[i]
        g = foot_ground[i]
        foot = [j_of[b] for b in leg.foot if b in j_of]
        if not foot:
            raise BipedError(f"Leg {leg.label}: its foot bones are not under the body bone '{body}'")
        ankle = foot[0]
        # Heel: a bone named like "heel" under the foot, else under the ankle, on the ground.
        heel_bone = None
        for n in order:
            if "heel" in n.lower() and index[n] in _descendant_indices(bones, leg.foot[0], index):
                heel_bone = n
                break
        if heel_bone is not None:
            b = bones[heel_bone]
            mid = 0.5 * (np.array(b.head_local) + np.array(b.tail_local))
            heel_w = world[:3, :3] @ mid + world[:3, 3]
            heel_parent = j_of[heel_bone]
        else:
            heel_w = head_w[ankle].copy()
            heel_parent = ankle
        heel_w[2] = g
        tip_bone = foot[-1]
        tip_w = world[:3, :3] @ np.array(bones[order[tip_bone]].tail_local) + world[:3, 3]
        tip_w[2] = g
        tag = "L" if side == LEFT else "R"
        joint_names += [f"ProcLoco heel {tag}", f"ProcLoco toe {tag}"]
        parents += [heel_parent, tip_bone]
        offsets += [to_body @ (heel_w - head_w[heel_parent]), to_body @ (tip_w - head_w[tip_bone])]
        heel_j, toe_j = len(joint_names) - 2, len(joint_names) - 1
        hip, knee = j_of[leg.bones[0]], j_of[leg.bones[1]]
        if parents[knee] != hip or parents[ankle] != knee:
            raise BipedError(
                f"Leg {leg.label}: the shin must be a child of the thigh and the foot of the shin"
            )
        leg_joints[side] = LegJoints(hip=hip, knee=knee, ankle=ankle, heel=heel_j, toe=toe_j)
    try:
        skel = Skeleton(
            tuple(joint_names), np.array(parents), np.array(offsets), leg_joints[LEFT], leg_joints[RIGHT]
        )
    except ValueError as err:
        raise BipedError(f"'{obj.name}': {err}") from err
    ankles = [head_w[j_of[info.legs[i].foot[0]]] for i in (lefts[0], rights[0])]
    width = float(abs((ankles[0] - ankles[1]) @ info.body.left))
    parent_pose = parent_rest = None
    body_parent = bones[body].parent
    if body_parent is not None:
        parent_pose = np.array(obj.pose.bones[body_parent.name].matrix, dtype=np.float64)
        parent_rest = np.array(body_parent.matrix_local, dtype=np.float64)
    return BipedRig(
        obj.name,
        skel,
        tuple(order),
        rest_rot,
        rest_head,
        world,
        world_rot,
        scale,
        yaw0,
        root0,
        parent_pose,
        parent_rest,
        max(width, 0.05 * scale),
        tuple(info.warnings),
    )


def _subtree(bone: bpy.types.Bone) -> list[bpy.types.Bone]:
    out = [bone]
    for child in bone.children:
        out.extend(_subtree(child))
    return out


def _descendant_indices(bones: bpy.types.ArmatureBones, name: str, index: dict[str, int]) -> set[int]:
    out: set[int] = set()
    stack = [bones[name]]
    while stack:
        b = stack.pop()
        out.add(index[b.name])
        stack.extend(b.children)
    return out


# ---------------------------------------------------------------------------------------
# Pose conversions


def pose_to_core(brig: BipedRig, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Armature-space pose matrices ``(F, B, 4, 4)`` of the rig's joints → the joints' world
    rotations in the core convention ``E (F, J, 4)`` (see the module docstring) and the
    pelvis' world position ``(F, 3)``."""
    skel = brig.skeleton
    rot = _orthonormal(pose[..., :3, :3])
    delta_arm = rot @ np.swapaxes(brig.rest_rot, -1, -2)
    d = brig.world_rot @ delta_arm @ brig.world_rot.T
    e = d @ _rz(brig.yaw0)
    n_frames = pose.shape[0]
    e_all = np.empty((n_frames, skel.n_joints, 3, 3))
    e_all[:, : brig.n_bones] = e
    for j in range(brig.n_bones, skel.n_joints):
        e_all[:, j] = e_all[:, skel.parents[j]]
    pelvis = pose[:, 0, :3, 3] @ brig.world[:3, :3].T + brig.world[:3, 3]
    return quat.from_matrix(e_all), pelvis


def core_locals(brig: BipedRig, e: np.ndarray) -> np.ndarray:
    """Local core joint rotations ``(F, J, 4)`` from world ones ``E (F, J, 4)`` (joint 0 kept
    as it is: the caller takes it relative to the root)."""
    par = brig.skeleton.parents.copy()
    par[0] = 0
    local = quat.mul(quat.conj(e[:, par]), e)
    local[:, 0] = e[:, 0]
    return local


def core_to_basis(
    brig: BipedRig, root_pos: np.ndarray, root_yaw: np.ndarray, pelvis_pos: np.ndarray, joint_rot: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A core motion → pose-bone ``matrix_basis`` rotations ``(F, B, 4)`` of the rig's joint
    bones and the body bone's location ``(F, 3)``."""
    skel = brig.skeleton
    _, g = forward_kinematics(skel, joint_rot, pelvis_pos)
    e = quat.mul(quat.from_yaw(root_yaw)[:, None, :], g[:, : brig.n_bones])
    d = quat.to_matrix(e) @ _rz(-brig.yaw0)
    delta = brig.world_rot.T @ d @ brig.world_rot  # armature-space deltas (F, B, 3, 3)
    par = skel.parents[: brig.n_bones].copy()
    parent_delta = delta[:, np.maximum(par, 0)]
    if brig.body_parent_pose is not None and brig.body_parent_rest is not None:
        pd = _orthonormal(brig.body_parent_pose[:3, :3]) @ _orthonormal(brig.body_parent_rest[:3, :3]).T
    else:
        pd = np.eye(3)
    parent_delta[:, 0] = pd
    local = np.swapaxes(parent_delta, -1, -2) @ delta
    basis = np.swapaxes(brig.rest_rot, -1, -2) @ local @ brig.rest_rot
    rotations = quat.from_matrix(basis)
    # Body bone location: its head must land on the planned pelvis.
    pelvis_w = root_pos + quat.rot2(root_yaw, pelvis_pos)
    inv_world = np.linalg.inv(brig.world)
    pelvis_a = pelvis_w @ inv_world[:3, :3].T + inv_world[:3, 3]
    rest = np.eye(4)
    rest[:3, :3] = brig.rest_rot[0]
    rest[:3, 3] = brig.rest_head[0]
    if brig.body_parent_pose is not None and brig.body_parent_rest is not None:
        a = brig.body_parent_pose @ np.linalg.inv(brig.body_parent_rest) @ rest
    else:
        a = rest
    location = (pelvis_a - a[:3, 3]) @ np.linalg.inv(a[:3, :3]).T
    return rotations, location


def keyed_bones(obj: bpy.types.Object, brig: BipedRig, rotations: np.ndarray) -> list[int]:
    """Joint bones worth keying: those the motion turns away from their rest in some frame,
    those posed away from rest now (so that they come back), and the body bone."""
    moving = np.abs(np.abs(rotations[..., 0]) - 1.0).max(axis=0) > 1e-9
    keep = [0]
    for b in range(1, brig.n_bones):
        if moving[b]:
            keep.append(b)
            continue
        q = obj.pose.bones[brig.bones[b]].matrix_basis.to_quaternion()
        if abs(abs(q.w) - 1.0) > 1e-9:
            keep.append(b)
    return keep


def _write_pose(
    action: bpy.types.Action,
    obj: bpy.types.Object,
    brig: BipedRig,
    frames: np.ndarray,
    rotations: np.ndarray,
    location: np.ndarray,
    *,
    assign: bool = True,
) -> pose_writer.WriteReport:
    """Key the motion through :mod:`..pose_writer` (and assign ``action``): the joint bones
    themselves on a plain rig, the controls that drive them on a control rig (the legs' IK
    controls, poles and switches, the body's root control). ``assign=False`` (clips, which are
    not assigned): on a control rig the clip is assigned only while its controls are solved."""
    bones = obj.data.bones
    rest = {b.name: np.array(b.matrix_local, dtype=np.float64) for b in bones}
    parents = {b.name: (b.parent.name if b.parent else None) for b in bones}
    basis = {pb.name: np.array(pb.matrix_basis, dtype=np.float64) for pb in obj.pose.bones}
    locations = np.zeros((*rotations.shape[:2], 3))
    locations[:, 0] = location
    keyed_location = np.zeros(brig.n_bones, dtype=bool)
    keyed_location[0] = True
    joints = brig.bones[: brig.n_bones]
    armature = pose_writer.armature_from_basis(joints, rotations, locations, rest, parents, basis,
                                               keyed_location)
    skel = brig.skeleton
    legs = [(brig.bones[lj.hip], brig.bones[lj.knee]) for lj in (skel.left, skel.right)]
    feet = [(brig.bones[lj.ankle],) for lj in (skel.left, skel.right)]
    keep = [brig.bones[b] for b in keyed_bones(obj, brig, rotations)]
    plan = controls.plan_controls(obj, list(zip(legs, feet, strict=True)), brig.bones[0])
    if not plan.uses_controls:
        plan = controls.ControlPlan(direct=tuple(keep), controls=(), legs=(), switches=(), uncovered=())
    request = pose_writer.PoseRequest(
        frames=frames, bones=tuple(joints), armature=armature, keyed_location=keyed_location,
        world0=brig.world, rest_local=rest, parents=parents, basis=basis, legs=tuple(legs))
    if assign:
        actions.remember_pose(action, obj, [*plan.keyed_bones], [(s.bone, s.prop) for s in plan.switches])
        return pose_writer.write_pose(action, obj, request, plan)
    if not plan.uses_controls:
        return pose_writer.write_pose(action, obj, request, plan, assign=False)
    adt = obj.animation_data
    prev = adt.action if adt is not None else None
    prev_slot = str(adt.action_slot.identifier) if (adt is not None and actions.is_slotted()
                                                    and adt.action_slot is not None) else ""
    basis_before = [pb.matrix_basis.copy() for pb in obj.pose.bones]
    props_before = {s: s.read(obj) for s in plan.switches}
    try:
        actions.assign_action(obj, action)
        return pose_writer.write_pose(action, obj, request, plan, assign=False)
    finally:
        actions.assign_action(obj, prev, slot_identifier=prev_slot)
        for pb, m in zip(obj.pose.bones, basis_before, strict=True):
            pb.matrix_basis = m
        for switch, value in props_before.items():
            switch.write(obj, value)


# ---------------------------------------------------------------------------------------
# Clips

_MARKER = re.compile(r"^\s*(l|left|r|right)[\s._-]*(down|up|on|off|contact|lift)\s*$", re.IGNORECASE)


def contacts_from_markers(markers: Sequence[tuple[str, int]], frames: np.ndarray) -> np.ndarray | None:
    """Foot contacts ``(n, 2)`` from pose markers ``(name, frame)`` such as ``"L down"`` and
    ``"R up"``; None when no marker names a foot. Before a foot's first marker it is in the
    state opposite to that marker."""
    events: dict[int, list[tuple[int, bool]]] = {LEFT: [], RIGHT: []}
    for name, frame in markers:
        m = _MARKER.match(name)
        if m is None:
            continue
        side = LEFT if m.group(1).lower().startswith("l") else RIGHT
        events[side].append((int(frame), m.group(2).lower() in ("down", "on", "contact")))
    if not events[LEFT] and not events[RIGHT]:
        return None
    out = np.zeros((len(frames), 2), dtype=bool)
    for side in (LEFT, RIGHT):
        ev = sorted(events[side])
        if not ev:
            continue
        state = not ev[0][1]
        k = 0
        for i, f in enumerate(frames):
            while k < len(ev) and ev[k][0] <= f:
                state = ev[k][1]
                k += 1
            out[i, side] = state
    return out


def _pose_matrices(
    context: bpy.types.Context, obj: bpy.types.Object, brig: BipedRig, frames: np.ndarray
) -> np.ndarray:
    """Armature-space pose matrices ``(F, B, 4, 4)`` of the joint bones, evaluated per frame."""
    scene = context.scene
    names = [pb.name for pb in obj.pose.bones]
    idx = np.array([names.index(n) for n in brig.bones])
    buf = np.empty(len(names) * 16, dtype=np.float32)
    out = np.empty((len(frames), brig.n_bones, 4, 4))
    for i, f in enumerate(frames):
        scene.frame_set(int(f))
        ev = obj.evaluated_get(context.evaluated_depsgraph_get())
        ev.pose.bones.foreach_get("matrix", buf)
        out[i] = buf.reshape(-1, 4, 4).transpose(0, 2, 1)[idx]
    return out


def read_clip(
    context: bpy.types.Context,
    obj: bpy.types.Object,
    brig: BipedRig,
    action: bpy.types.Action,
    role: ClipRole,
) -> Clip:
    """The Action as a core clip (see the module docstring). Leaves the rig and the scene as
    they were. Raises :class:`BipedError`."""
    start, end = (round(float(x)) for x in action.frame_range)
    if end - start < 2:
        raise BipedError(f"Clip '{action.name}' is too short ({end - start + 1} frames)")
    frames = np.arange(start, end + 1)
    scene = context.scene
    fps = scene.render.fps / scene.render.fps_base
    adt = obj.animation_data
    had_adt = adt is not None
    prev_action = adt.action if adt is not None else None
    prev_slot = ""
    if adt is not None and actions.is_slotted() and adt.action_slot is not None:
        prev_slot = str(adt.action_slot.identifier)
    prev_nla = adt.use_nla if adt is not None else True
    old_frame = scene.frame_current
    # Bones keep their last evaluated pose when no Action drives them: put the pose back too.
    old_basis = [pb.matrix_basis.copy() for pb in obj.pose.bones]
    try:
        actions.assign_action(obj, action)
        obj.animation_data.use_nla = False
        # Bones the clip does not key are at rest in the clip, whatever the rig's pose was.
        rest = Matrix.Identity(4)
        for pb in obj.pose.bones:
            pb.matrix_basis = rest
        pose = _pose_matrices(context, obj, brig, frames)
    except actions.ActionError as err:
        raise BipedError(str(err)) from err
    finally:
        try:
            actions.assign_action(obj, prev_action, slot_identifier=prev_slot)
        finally:
            if obj.animation_data is not None:
                if had_adt:
                    obj.animation_data.use_nla = prev_nla
                elif prev_action is None and not len(obj.animation_data.nla_tracks):
                    obj.animation_data_clear()
            for pb, m in zip(obj.pose.bones, old_basis, strict=True):
                pb.matrix_basis = m
            scene.frame_set(old_frame)
    e, pelvis_w = pose_to_core(brig, pose)
    local = core_locals(brig, e)
    markers = [(m.name, m.frame) for m in getattr(action, "pose_markers", [])]
    contacts = contacts_from_markers(markers, frames)
    clip = recorded_clip(action.name, role, brig.skeleton, 1.0 / fps, pelvis_w, e[:, 0], local, contacts)
    if contacts is None:
        clip = Clip(
            clip.name,
            role,
            clip.dt,
            clip.root_pos,
            clip.root_yaw,
            clip.pelvis_pos,
            clip.joint_rot,
            detect_contacts(clip.foot_points_world(brig.skeleton), clip.dt),
        )
    if role.family in ("walk", "run", "jump"):
        c = clip.contacts
        assert c is not None
        one_stride = bool(c[0, RIGHT] and c[-1, RIGHT] and not c[:, RIGHT].all())
        if one_stride and role.family in ("walk", "run"):
            # One loop of a walk or run: its root must loop with it (see root_from_pelvis).
            clip = recorded_clip(
                action.name, role, brig.skeleton, clip.dt, pelvis_w, e[:, 0], local, c, periodic=True
            )
        if not one_stride:
            try:
                clip = extract_cycle(clip, brig.skeleton)
            except ValueError as err:
                raise BipedError(f"Clip '{action.name}': {err}") from err
    return clip


def write_clip_action(
    obj: bpy.types.Object, brig: BipedRig, clip: Clip, start_frame: int = 1
) -> bpy.types.Action:
    """A new Action holding ``clip`` on the rig (not assigned), with contact pose markers."""
    world_yaw = clip.root_yaw + brig.yaw0
    root = brig.root0 + quat.rot2(brig.yaw0, clip.root_pos)
    rotations, location = core_to_basis(brig, root, world_yaw, clip.pelvis_pos, clip.joint_rot)
    action = actions.new_action(obj, suffix=clip.name)
    frames = start_frame + np.arange(clip.n_frames, dtype=np.float64)
    try:
        _write_pose(action, obj, brig, frames, rotations, location, assign=False)
    except Exception:
        bpy.data.actions.remove(action)
        raise
    if clip.contacts is not None:
        for side, tag in ((LEFT, "L"), (RIGHT, "R")):
            flags = clip.contacts[:, side]
            changes = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
            for f in [0, *changes.tolist()]:
                state = "down" if flags[f] else "up"
                action.pose_markers.new(f"{tag} {state}").frame = int(frames[f])
    return action


# ---------------------------------------------------------------------------------------
# Surfaces


def walkable_surface(
    context: bpy.types.Context,
    obj: bpy.types.Object,
    brig: BipedRig,
    collection: bpy.types.Collection | None,
    start: np.ndarray,
    goal: np.ndarray,
    max_slope: float,
    margin: float,
) -> WalkableSurface:
    """The walkable surface around ``start`` and ``goal`` (world ``(2+,)``): upward faces of
    the terrain objects, minus what ``AVOID`` objects cover. Raises :class:`BipedError`."""
    objs = scene_terrain.terrain_objects(context, [obj], collection)
    depsgraph = context.evaluated_depsgraph_get()
    walk: list[np.ndarray] = []
    block: list[np.ndarray] = []
    cos_max = float(np.cos(max_slope))
    for ob in objs:
        role = scene_terrain.object_role(ob)
        verts, tris = scene_terrain.read_triangles(ob, depsgraph)
        if len(tris) == 0:
            continue
        t = verts[tris]
        if role == "AVOID":
            block.append(t)
            continue
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        length = np.linalg.norm(n, axis=1)
        up = (length > 1e-12) & (np.abs(n[:, 2]) >= cos_max * np.maximum(length, 1e-12))
        walk.append(t[up])
    if not walk or not sum(len(w) for w in walk):
        raise BipedError("No walkable ground: no mesh with upward faces among the terrain objects")
    span = float(np.linalg.norm(np.asarray(goal)[:2] - np.asarray(start)[:2]))
    pad = 0.5 * span + 10.0 * brig.scale
    lo = np.minimum(start[:2], goal[:2]) - pad
    hi = np.maximum(start[:2], goal[:2]) + pad
    k = float(np.mean(brig.skeleton.thigh_length + brig.skeleton.shin_length)) / 0.86
    try:
        return WalkableSurface.from_triangles(
            np.concatenate(walk),
            cell=0.025 * k,
            margin=margin,
            max_step=0.2 * k,
            blocked=np.concatenate(block) if block else None,
            bounds=(lo[0], lo[1], hi[0], hi[1]),
        )
    except ValueError as err:
        raise BipedError(f"No walkable ground near the character: {err}") from err


# ---------------------------------------------------------------------------------------
# Result


def write_motion(
    obj: bpy.types.Object, brig: BipedRig, motion: BipedMotion, start_frame: int
) -> bpy.types.Action:
    """Write the planned motion as a new Action on ``obj`` (assigned, the old one remembered)."""
    rotations, location = core_to_basis(
        brig, motion.root_pos, motion.root_yaw, motion.pelvis_pos, motion.joint_rot
    )
    action = actions.new_action(obj, suffix="ProcLoco Biped")
    frames = start_frame + np.arange(motion.n_frames, dtype=np.float64)
    adt = obj.animation_data
    before = adt.action if adt is not None else None
    remembered, _previous = actions.previous_action(obj)
    try:
        report = _write_pose(action, obj, brig, frames, rotations, location)
        _reduce_keys(obj, action, brig, motion, frames, report)
    except Exception:
        if obj.animation_data is not None and obj.animation_data.action == action:
            actions.assign_action(obj, before)
            if not remembered:
                actions.forget_previous(obj)
        bpy.data.actions.remove(action)
        raise
    return action


def _reduce_keys(obj: bpy.types.Object, action: bpy.types.Action, brig: BipedRig, motion: BipedMotion,
                 frames: np.ndarray, report: pose_writer.WriteReport) -> None:
    """Key Reduction of the planned walk when the rig has it on (see :mod:`..keys.reduce`):
    each foot's touch-downs and lift-offs stay keys of its leg's bones and controls."""
    from ..keys import reduce

    skel = brig.skeleton
    sides = (skel.left, skel.right)  # the columns LEFT, RIGHT of motion.contact
    chains = [[brig.bones[j] for j in (lj.hip, lj.knee, lj.ankle, lj.toe) if j < len(brig.bones)]
              for lj in sides]
    contacts = reduce.contact_frames(np.asarray(motion.contact) >= 0)
    required: dict[str, np.ndarray] = {}
    for k, names in enumerate(reduce.leg_keyed_bones(report.plan, chains)):
        for name in names:
            required[name] = required.get(name, np.zeros(len(frames), dtype=bool)) | contacts[:, k]
    feet = [brig.bones[lj.ankle] for lj in sides]
    planted = {brig.bones[lj.ankle]: np.asarray(motion.contact)[:, k] >= 0 for k, lj in enumerate(sides)}
    reduce.reduce_if_enabled(obj, action, frames, feet, required, planted)


def heel_toe_world(brig: BipedRig, motion: BipedMotion) -> np.ndarray:
    """Heel and toe of both feet in the world for the planned motion: ``(F, 2, 2, 3)``."""
    jpos, _ = forward_kinematics(brig.skeleton, motion.joint_rot, motion.pelvis_pos)
    pts = foot_points(brig.skeleton, jpos)
    return motion.root_pos[:, None, None, :] + quat.rot2(motion.root_yaw[:, None, None], pts)
