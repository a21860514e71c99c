# SPDX-License-Identifier: GPL-3.0-or-later
"""A plain rig's posed bones read from its Action, without the depsgraph.

Measuring a walk reads the evaluated pose of every rig at every frame. Through the depsgraph
that costs a scene evaluation per frame (every animated rig and its skin's Armature
modifier), about 1 ms per rig and frame in a herd. A *plain* rig, one whose bones only
follow their parents and their own channels, poses the same way in a few array operations:
each bone's armature-space pose is its parent's pose, times its rest offset from the parent,
times its ``matrix_basis`` (location, rotation in the bone's rotation mode, scale; a
connected bone's location ignored), Blender's own composition for bones that inherit rotation and scale in
full. The channels are the Action's F-curves at each frame (:func:`.actions.sample_channels`)
where it animates them, the pose bone's own values elsewhere.

:func:`plain_poses` returns None, and the depsgraph is used, for every rig where anything
else could move a measured bone: a constraint or a driver anywhere on it, NLA tracks, an
Action influence below one, an object that moves, the rest position, bones that do not
inherit in full, or an animated property the composition does not know.

Shapes: ``F`` frames, ``n`` bones; matrices ``(F, n, 4, 4)``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import bpy
import numpy as np

from .. import actions, pose_writer
from ..rig.rest import affine_inverse

__all__ = ["plain_poses"]

#: A pose bone's transform channel: the (escaped) bone name and the property.
_CHANNEL = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.(location|rotation_quaternion|rotation_euler|'
                      r"rotation_axis_angle|scale)$")

def _unescape(name: str) -> str:
    return name.replace('\\"', '"').replace("\\\\", "\\")


def _plain_object(obj: bpy.types.Object) -> bool:
    """Whether nothing but the active Action's channels can move ``obj``'s bones or the
    object (its Action's own channels are looked at as they are sampled)."""
    if obj.type != "ARMATURE" or obj.data.pose_position != "POSE" or len(obj.constraints):
        return False
    adt = obj.animation_data
    if adt is not None and (len(adt.drivers) or len(adt.nla_tracks) or adt.use_tweak_mode
                            or adt.action_influence != 1.0 or adt.action_blend_type != "REPLACE"):
        return False
    data_adt = obj.data.animation_data
    if data_adt is not None and (data_adt.action is not None or len(data_adt.drivers)
                                 or len(data_adt.nla_tracks)):
        return False
    if any(len(pb.constraints) for pb in obj.pose.bones):
        return False
    child = obj
    while child.parent is not None:  # parented plainly to objects that do not move
        if child.parent_type != "OBJECT" or pose_writer.object_moves(child.parent):
            return False
        child = child.parent
    return True


def _world(obj: bpy.types.Object) -> np.ndarray:
    """The world matrix of an object that does not move: its own transform (location,
    rotation, scale and their deltas) under its parents' (asking the depsgraph to evaluate
    a herd whose Actions were just assigned costs more than the measurement)."""
    own = np.array(obj.matrix_basis, dtype=np.float64)
    if obj.parent is None:
        return own
    return _world(obj.parent) @ np.array(obj.matrix_parent_inverse, dtype=np.float64) @ own


def _chain_order(bones: bpy.types.ArmatureBones, names: Sequence[str]) -> list[str]:
    """``names`` and their ancestors, each after its parent."""
    order: list[str] = []
    seen: set[str] = set()
    for name in names:
        line = []
        bone = bones[name]
        while bone is not None and bone.name not in seen:
            line.append(bone.name)
            seen.add(bone.name)
            bone = bone.parent
        order.extend(reversed(line))  # the line's first ancestor is seen already (or a root)
    return order


def _quaternion_matrices(q: np.ndarray) -> np.ndarray:
    """``(..., 4)`` quaternions (w, x, y, z), normalised as Blender does -> ``(..., 3, 3)``."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    # (each component contiguous, each product made once, written into one array: the same
    # values as the nine entries' expressions stacked, in a fifth of the time)
    w, x, y, z = np.ascontiguousarray(np.moveaxis(q, -1, 0))
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.empty((*q.shape[:-1], 3, 3))
    m[..., 0, 0] = 1 - 2 * (yy + zz)
    m[..., 0, 1] = 2 * (xy - wz)
    m[..., 0, 2] = 2 * (xz + wy)
    m[..., 1, 0] = 2 * (xy + wz)
    m[..., 1, 1] = 1 - 2 * (xx + zz)
    m[..., 1, 2] = 2 * (yz - wx)
    m[..., 2, 0] = 2 * (xz - wy)
    m[..., 2, 1] = 2 * (yz + wx)
    m[..., 2, 2] = 1 - 2 * (xx + yy)
    return m


def _bulk(collection: bpy.types.bpy_prop_collection, prop: str, width: int) -> np.ndarray:
    """``prop`` of every item of ``collection`` ``(n, width)`` (or ``(n, 4, 4)`` matrices), float64."""
    n = len(collection)
    buf = np.empty(n * width, dtype=np.float32)
    collection.foreach_get(prop, buf)
    if width == 16:  # matrices come column by column
        return buf.reshape(n, 4, 4).transpose(0, 2, 1).astype(np.float64)
    return buf.reshape(n, width).astype(np.float64)


def _axis_turns(axis: str, angle: np.ndarray) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` by ``angle`` ``(...,)`` about the X, Y or Z axis."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((*angle.shape, 3, 3))
    i, j = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[axis]
    k = 3 - i - j
    out[..., k, k] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def _rotation_matrices(mode: str, values: np.ndarray) -> np.ndarray:
    """A pose bone's rotation channels ``(..., 3 or 4)`` in rotation ``mode`` -> ``(..., 3, 3)``:
    an Euler order applies its first axis first; an axis-angle turns about its normalised axis
    (none about a zero axis)."""
    if mode == "QUATERNION":
        return _quaternion_matrices(values)
    if mode == "AXIS_ANGLE":
        axis = values[..., 1:]
        size = np.linalg.norm(axis, axis=-1, keepdims=True)
        k = np.divide(axis, size, out=np.zeros_like(axis), where=size > 0.0)
        cross = np.zeros((*k.shape[:-1], 3, 3))
        cross[..., 0, 1], cross[..., 0, 2] = -k[..., 2], k[..., 1]
        cross[..., 1, 0], cross[..., 1, 2] = k[..., 2], -k[..., 0]
        cross[..., 2, 0], cross[..., 2, 1] = -k[..., 1], k[..., 0]
        angle = np.where(size[..., 0] > 0.0, values[..., 0], 0.0)[..., None, None]
        return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * (cross @ cross)
    out = np.broadcast_to(np.eye(3), (*values.shape[:-1], 3, 3))
    for letter in mode:
        out = _axis_turns(letter, values[..., "XYZ".index(letter)]) @ out
    return out


#: Each rotation mode's channel (its number of values); the Euler orders' is ``rotation_euler``.
_ROTATION_CHANNEL = {"QUATERNION": ("rotation_quaternion", 4), "AXIS_ANGLE": ("rotation_axis_angle", 4)}


def plain_poses(obj: bpy.types.Object, frames: np.ndarray, names: Sequence[str]) -> np.ndarray | None:
    """World matrices ``(F, n, 4, 4)`` of ``obj``'s bones ``names`` at ``frames`` ``(F,)`` as
    the depsgraph would pose them, computed from the rig's Action; None when the rig is not
    plain (see the module doc)."""
    if not _plain_object(obj):
        return None
    bones = obj.data.bones
    order = _chain_order(bones, names)
    for n in order:
        bone = bones[n]
        if (not bone.use_inherit_rotation or bone.inherit_scale != "FULL" or not bone.use_local_location
                or bone.use_relative_parent):
            return None
    frames = np.asarray(frames, dtype=np.int64).reshape(-1)
    n_frames = frames.shape[0]
    wanted = set(order)
    unknown: list[str] = []
    known: dict[str, tuple[str, str]] = {}  # the measured channels' bone and property, by path

    def measured(path: str) -> bool:
        """Whether the channel ``path`` moves a bone of the measured chains (noting, in
        ``unknown``, properties the composition does not know)."""
        found = _CHANNEL.match(path)
        if found is not None:
            bone = _unescape(found.group(1))
            if bone in wanted:
                known[path] = (bone, found.group(2))
                return True
            return False
        if path.startswith('pose.bones["'):  # another property of a pose bone: harmless off the chains
            end = path.find('"]', len('pose.bones["'))
            if end < 0 or _unescape(path[len('pose.bones["'):end]) in wanted:
                unknown.append(path)
        else:
            unknown.append(path)  # an object or custom property: the depsgraph knows what it does
        return False

    adt = obj.animation_data
    action = adt.action if adt is not None else None
    sampled = actions.sample_channels(action, obj, frames, measured) if action is not None else {}
    if unknown:
        return None
    # The chains' bones: each one's own channels, then the Action's where it animates them.
    pose_bones = obj.pose.bones
    column = {pb.name: i for i, pb in enumerate(pose_bones)}
    at = {n: j for j, n in enumerate(order)}
    picked = np.array([column[n] for n in order], dtype=np.int64)
    chan = {prop: np.repeat(_bulk(pose_bones, prop, width)[picked][None], n_frames, axis=0)
            for prop, width in (("location", 3), ("rotation_quaternion", 4), ("rotation_euler", 3),
                                ("rotation_axis_angle", 4), ("scale", 3))}  # (F, n, k)
    animated = np.zeros(len(order), dtype=bool)
    for (path, index), values in sampled.items():
        bone, prop = known[path]
        j = at[bone]
        animated[j] = True
        if prop in chan:
            chan[prop][:, j, index] = values
    # matrix_basis: the pose bone's own, or from its channels where animated (a connected
    # bone's head stays on its parent's tail: its location is not used).
    basis = np.repeat(_bulk(pose_bones, "matrix_basis", 16)[picked][None], n_frames, axis=0)
    modes = [pose_bones[n].rotation_mode for n in order]
    for mode in sorted({modes[j] for j in np.flatnonzero(animated)}):
        moved = np.array([j for j in np.flatnonzero(animated) if modes[j] == mode], dtype=np.int64)
        prop, _width = _ROTATION_CHANNEL.get(mode, ("rotation_euler", 3))
        m = np.zeros((n_frames, moved.size, 4, 4))
        turn = _rotation_matrices(mode, chan[prop][:, moved])
        m[..., :3, :3] = turn * chan["scale"][:, moved, None, :]
        free = np.array([not bones[order[j]].use_connect for j in moved])
        m[..., :3, 3] = chan["location"][:, moved] * free[None, :, None]
        m[..., 3, 3] = 1.0
        basis[:, moved] = m
    # Each bone's rest offset from its parent (its own rest matrix for a root).
    rest_all = _bulk(bones, "matrix_local", 16)
    rest_index = {b.name: i for i, b in enumerate(bones)}
    parents = [bones[n].parent for n in order]
    rest = rest_all[[rest_index[n] for n in order]]
    parent_rest = np.stack([rest_all[rest_index[p.name]] if p is not None else np.eye(4) for p in parents])
    offset = affine_inverse(parent_rest) @ rest
    pose = np.empty((n_frames, len(order), 4, 4))
    for j, parent in enumerate(parents):
        above = offset[j][None] if parent is None else pose[:, at[parent.name]] @ offset[j][None]
        pose[:, j] = above @ basis[:, j]
    return _world(obj)[None, None] @ pose[:, [at[n] for n in names]]
