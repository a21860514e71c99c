# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading an armature (bpy): its rest arrays, detected or user-chosen legs, and
:func:`read_rig`, everything one generation needs in one :class:`RigInfo`."""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Callable, Collection, Iterator, Sequence
from contextlib import contextmanager
from typing import TypeVar, cast

import bpy
import numpy as np

from .detect import LegChain, _control_bones, _forward_axis, _label_legs, find_legs, forward_of, leg_between
from .info import BodyInfo, RigInfo
from .rest import (
    _UP,
    RigError,
    _apply,
    _chain_points,
    _common_ancestor,
    _descendants,
    _length,
    _Rest,
    affine_inverse,
    skeleton_view,
    sole_points,
    uniform_scale,
    with_leaf_ends,
)
from .spine import _spine_chain, _spine_layout

_T = TypeVar("_T")


def _object_world(obj: bpy.types.Object) -> np.ndarray:
    return np.array(obj.matrix_world, dtype=np.float64)


# Rest arrays and skin points already read inside a reading_once() block, by object name.
_read_once: dict[str, tuple[_Rest, dict[str, np.ndarray]]] | None = None
# Legs detected inside a reading_once() block, by the rig's shape (see _shape_key).
_detected_once: dict[tuple[object, ...], list[LegChain]] = {}
# Inside a reading_once() block: the meshes each armature deforms (by the armature's name),
# found in one pass over the file's objects, and the vertices weighted mostly to each vertex
# group of a mesh (by the mesh datablock and its groups): linked duplicates share their skin.
_skins_once: dict[str, list[bpy.types.Object]] | None = None
_MembersKey = tuple[int, tuple[tuple[int, str], ...]]
_members_once: dict[_MembersKey, dict[str, np.ndarray]] = {}
# The ReadCache of the reading_once() block (None: nothing is kept beyond the block), and
# the digest of each rig read in the block (see ReadCache).
_cache_once: ReadCache | None = None
_digests_once: dict[str, bytes] = {}
# Inside a reading_once() block: the rigs read by their shape (see read_rig), their copies
# placed from them.
_copies_once: dict[tuple[object, ...], RigInfo] = {}
# Inside a reading_once() block: each reading's copy key (by the id of its RigInfo, kept in
# _copies_once or by its job), whether the rig is plain (no constraint, no driver), and what
# readers derive from a reading and share with its copies (shared()).
_copy_keys_once: dict[int, tuple[tuple[object, ...], bool]] = {}
_shared_once: dict[tuple[object, ...], object] = {}
_plain_once: dict[str, bool] = {}


class ReadCache:
    """Rigs read before, reused while what they were read from stays the same: Live Preview
    reads its rig again after each edit of a setting, when the rig itself rarely changed.

    An entry is found by a digest of everything reading a rig takes from Blender in bulk (the
    object's placement, its bones at rest and as posed now, their constraints, the placement,
    vertices and vertex groups of its skins) and by the reading's own arguments. Vertex
    weights come vertex by vertex and are not in the digest: :meth:`forget_meshes` drops what
    was read from the skins once a mesh was edited (Live Preview calls it from its depsgraph
    handler, which sees a weight painted, or a vertex moved, as an update of the mesh).
    Used through :func:`reading_once`."""

    def __init__(self) -> None:
        self.rest: dict[str, tuple[bytes, tuple[_Rest, dict[str, np.ndarray]]]] = {}
        self.infos: dict[str, tuple[tuple[object, ...], RigInfo]] = {}
        self.members: dict[_MembersKey, dict[str, np.ndarray]] = {}
        self.shared: dict[tuple[object, ...], object] = {}

    def forget_meshes(self) -> None:
        """A mesh was edited: read the skins (and so the rigs) again."""
        self.clear()

    def clear(self) -> None:
        self.rest.clear()
        self.infos.clear()
        self.members.clear()
        self.shared.clear()


@contextmanager
def reading_once(cache: ReadCache | None = None) -> Iterator[None]:
    """Inside the block each rig's rest arrays (bones and skin) are read once, however many
    legs and readers ask for them, copies of one rig are detected once, and a skin mesh that
    several rigs share is read once: for a reader that changes nothing in between
    (Generate's settings check reads them once per leg, then for the rig; Generate on many
    rigs reads them all in one block). With ``cache`` (on the outermost block), what is read
    is kept there, and a rig found unchanged there is not read again."""
    global _read_once, _skins_once, _cache_once, _members_once
    outer = _read_once
    if outer is None:
        _read_once = {}
        if cache is not None:
            _cache_once = cache
            _members_once = cache.members
    try:
        yield
    finally:
        if outer is None:
            _read_once = None
            _skins_once = None
            _cache_once = None
            _detected_once.clear()
            _digests_once.clear()
            _copies_once.clear()
            _copy_keys_once.clear()
            _shared_once.clear()
            _plain_once.clear()
            _members_once = {}


def _digest(obj: bpy.types.Object) -> bytes:
    """What reading ``obj`` takes from Blender, but its current pose (:func:`_pose_digest`)
    and the skins' vertex weights, as a digest (see :class:`ReadCache`); once per
    :func:`reading_once` block."""
    h = hashlib.blake2b(_shape_digest(obj), digest_size=16)
    h.update(np.array(obj.matrix_world, dtype=np.float64)[:3, 3].tobytes())
    # (which meshes: their weights are not in the digest)
    h.update(repr([(m.name, m.data.name, m.data.as_pointer()) for m in _skins(obj)]).encode())
    return h.digest()


def _shape_digest(obj: bpy.types.Object) -> bytes:
    """:func:`_digest` but where the rig stands: its bones, constraints, the turn and scale of
    its object, its skins' vertices, groups and placement relative to it, as a digest; once
    per :func:`reading_once` block."""
    if obj.name in _digests_once:
        return _digests_once[obj.name]
    h = hashlib.blake2b(digest_size=16)
    world = np.array(obj.matrix_world, dtype=np.float64)
    h.update(world[:3, :3].tobytes())
    bones = obj.data.bones
    n = len(bones)
    h.update(repr([(b.name, b.parent.name if b.parent else None, b.use_connect) for b in bones]).encode())
    for prop, size in (("matrix_local", 16), ("head_local", 3), ("tail_local", 3)):
        buf = np.empty(n * size, dtype=np.float32)
        bones.foreach_get(prop, buf)
        h.update(buf.tobytes())
    pbones = obj.pose.bones
    constraints = [(pb.name, [(c.type, c.enabled, round(float(c.influence), 9),
                               getattr(getattr(c, "target", None), "name", None),
                               getattr(c, "subtarget", None), getattr(c, "use_tail", None))
                              for c in pb.constraints])
                   for pb in pbones if len(pb.constraints)]
    drivers = [adt for adt in (obj.animation_data, obj.data.animation_data)
               if adt is not None and len(adt.drivers)]
    _plain_once[obj.name] = not constraints and not drivers
    h.update(repr([pb.name for pb in pbones]).encode() + repr(constraints).encode())
    for mesh_obj in _skins(obj):
        mesh = mesh_obj.data
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        h.update(repr([g.name for g in mesh_obj.vertex_groups]).encode())
        placed = np.array(mesh_obj.matrix_world, dtype=np.float64)
        placed[:3, 3] -= world[:3, 3]
        h.update(placed.tobytes() + co.tobytes())
    _digests_once[obj.name] = out = h.digest()
    return out


def _weights_digest(obj: bpy.types.Object) -> bytes:
    """The vertices weighted to each bone in ``obj``'s skins (:func:`_members`), as a digest."""
    h = hashlib.blake2b(digest_size=16)
    names = {b.name for b in obj.data.bones}
    for mesh_obj in _skins(obj):
        groups = {g.index: g.name for g in mesh_obj.vertex_groups if g.name in names}
        for name, idx in _members(mesh_obj.data, groups).items() if groups else ():
            h.update(name.encode() + b"\0" + idx.tobytes())
    return h.digest()


def shared(info: RigInfo, what: tuple[object, ...], make: Callable[[], _T], plain: bool = False) -> _T:
    """``make()``, something a reader derives from ``info`` alone (and ``what``, its other
    inputs), made once for ``info`` and the copies of its rig read in the same
    :func:`reading_once` block (:func:`read_rig`), and shared by them (with a
    :class:`ReadCache`, kept there with the reading); made anew outside a block.
    ``plain``: only for copies of a plain rig (no constraint on any bone, no driver), what
    depends on more of the rig than its reading (what to key: its controls)."""
    found = _copy_keys_once.get(id(info))
    if found is None or (plain and not found[1]):
        return make()
    key = (found[0], *what)
    kept = _shared_once if _cache_once is None else _cache_once.shared  # (a ReadCache keeps it)
    if key not in kept:
        kept[key] = make()
    return cast(_T, kept[key])


def _placed(first: RigInfo, obj: bpy.types.Object) -> RigInfo:
    """``first``, read from a copy of ``obj`` standing elsewhere (:func:`read_rig`), moved to
    where ``obj`` stands."""
    world = np.array(obj.matrix_world, dtype=np.float64)
    shift = world[:3, 3] - first.world[:3, 3]
    layout = first.spine_layout
    return dataclasses.replace(
        first, object_name=obj.name, world=world,
        body=BodyInfo(first.body.origin + shift, first.body.forward, first.body.left),
        joints=tuple(j + shift for j in first.joints), contact=first.contact + shift,
        foot_points=tuple(p + shift for p in first.foot_points),
        spine_layout=None if layout is None else dataclasses.replace(layout, joints=layout.joints + shift))


def _pose_digest(obj: bpy.types.Object, at_rest: Collection[str]) -> bytes:
    """The current pose of ``obj``'s bones but those taken ``at_rest`` (a generated Action's,
    posed anew at every frame), as a digest."""
    pbones = obj.pose.bones
    buf = np.empty((len(pbones), 16), dtype=np.float32)
    pbones.foreach_get("matrix_basis", buf.ravel())
    if at_rest:
        buf[[i for i, pb in enumerate(pbones) if pb.name in at_rest]] = 0.0
    return hashlib.blake2b(buf.tobytes(), digest_size=16).digest()


def _rest_of(obj: bpy.types.Object) -> _Rest:
    return _read(obj)[0]


def _read(obj: bpy.types.Object) -> tuple[_Rest, dict[str, np.ndarray]]:
    """``obj``'s rest arrays and its skin points by bone name (see :func:`_skin_points`),
    read once per :func:`reading_once` block (and kept in its :class:`ReadCache`)."""
    if _read_once is not None and obj is not None and obj.name in _read_once:
        return _read_once[obj.name]
    if _cache_once is not None and obj is not None and obj.type == "ARMATURE":
        digest = _digest(obj)
        kept = _cache_once.rest.get(obj.name)
        if kept is not None and kept[0] == digest:
            read = kept[1]
        else:
            read = _read_rest(obj)
            _cache_once.rest[obj.name] = (digest, read)
    else:
        read = _read_rest(obj)
    if _read_once is not None:
        _read_once[obj.name] = read
    return read


def _read_rest(obj: bpy.types.Object) -> tuple[_Rest, dict[str, np.ndarray]]:
    if obj is None or obj.type != "ARMATURE":
        raise RigError("The active object is not an armature: select a rig")
    world = _object_world(obj)
    scale = uniform_scale(world)
    if scale is None:
        raise RigError(f"'{obj.name}' has a non-uniform or mirrored scale: apply its scale first (Ctrl A)")
    bones = obj.data.bones
    names = tuple(b.name for b in bones)
    index = {n: i for i, n in enumerate(names)}
    n = len(names)
    if n == 0:
        raise RigError(f"'{obj.name}' has no bones")
    parent = np.array([index[b.parent.name] if b.parent else -1 for b in bones], dtype=np.int64)
    local = np.empty(n * 16, dtype=np.float32)
    bones.foreach_get("matrix_local", local)
    local_m = local.reshape(n, 4, 4).transpose(0, 2, 1).astype(np.float64)
    head_l = np.empty(n * 3, dtype=np.float32)
    tail_l = np.empty(n * 3, dtype=np.float32)
    bones.foreach_get("head_local", head_l)
    bones.foreach_get("tail_local", tail_l)
    head = _apply(world, head_l.reshape(n, 3).astype(np.float64))
    tail = _apply(world, tail_l.reshape(n, 3).astype(np.float64))
    rest = _Rest(names, index, parent, head, tail, local_m, world, scale)
    # One pass over the skin for every bone: the leaves' far ends here, the feet's soles in
    # read_rig.
    skin = _skin_points(obj, names)
    leaves = {i for i in range(n) if not rest.children(i) and not rest.phantom[i]}
    leaf_skin = {index[k]: v for k, v in skin.items() if index[k] in leaves}
    return (with_leaf_ends(rest, leaf_skin) if leaf_skin else rest), skin


def _skins(obj: bpy.types.Object) -> list[bpy.types.Object]:
    """The meshes deformed by ``obj`` (an Armature modifier on them names it), in the file's
    order; inside a :func:`reading_once` block found for every armature in one pass."""
    global _skins_once
    if _read_once is None:
        return [m for m in bpy.data.objects if m.type == "MESH"
                and any(mod.type == "ARMATURE" and mod.object == obj for mod in m.modifiers)]
    if _skins_once is None:
        _skins_once = {}
        for mesh_obj in bpy.data.objects:
            if mesh_obj.type != "MESH":
                continue
            found = {mod.object.name for mod in mesh_obj.modifiers
                     if mod.type == "ARMATURE" and mod.object is not None}
            for name in found:
                _skins_once.setdefault(name, []).append(mesh_obj)
    return _skins_once.get(obj.name, [])


def _members(mesh: bpy.types.Mesh, groups: dict[int, str]) -> dict[str, np.ndarray]:
    """The vertices ``(p,)`` of ``mesh`` weighted mostly (>= 0.5) to each of ``groups``
    (vertex group index -> name), in vertex order, for the groups that have any. Blender reads
    vertex weights vertex by vertex only: the one loop over the vertices, shared inside a
    :func:`reading_once` block by the rigs whose skins use the same mesh."""
    key = (mesh.as_pointer(), tuple(sorted(groups.items())))
    if _read_once is not None and key in _members_once:
        return _members_once[key]
    found: dict[int, list[int]] = {g: [] for g in groups}
    get = found.get
    for i, v in enumerate(mesh.vertices):
        for g in v.groups:
            chosen = get(g.group)
            if chosen is not None and g.weight >= 0.5:
                chosen.append(i)
    out = {groups[g]: np.array(idx, dtype=np.int64) for g, idx in found.items() if idx}
    if _read_once is not None:
        _members_once[key] = out
    return out


def _skin_points(obj: bpy.types.Object, bone_names: Sequence[str]) -> dict[str, np.ndarray]:
    """World rest positions ``(p, 3)`` of the skin vertices weighted mostly (>= 0.5) to each
    of ``bone_names``, over the meshes deformed by ``obj`` (Armature modifier)."""
    wanted = set(bone_names)
    out: dict[str, list[np.ndarray]] = {}
    for mesh_obj in _skins(obj):
        groups = {g.index: g.name for g in mesh_obj.vertex_groups if g.name in wanted}
        if not groups:
            continue
        mesh = mesh_obj.data
        members = _members(mesh, groups)
        if not members:
            continue
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        # Only the weighted vertices, placed element-wise: a matrix product of every vertex
        # was a BLAS call whose threads then spun on the other core.
        chosen = np.unique(np.concatenate(list(members.values())))
        world = _apply_each(np.array(mesh_obj.matrix_world, dtype=np.float64),
                            co.reshape(-1, 3)[chosen].astype(np.float64))
        row = np.empty(co.size // 3, dtype=np.int64)
        row[chosen] = np.arange(chosen.size)
        for name, idx in members.items():
            out.setdefault(name, []).append(world[row[idx]])
    merged = {k: v[0] if len(v) == 1 else np.concatenate(v) for k, v in out.items()}
    return {k: v for k, v in merged.items() if len(v) >= 3}


def _apply_each(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Affine ``m`` ``(4, 4)`` applied to points ``p`` ``(n, 3)`` element-wise (no BLAS call)."""
    return (p[:, 0:1] * m[:3, 0] + p[:, 1:2] * m[:3, 1]) + p[:, 2:3] * m[:3, 2] + m[:3, 3]


def _posed_points(rest: _Rest, posed_local: np.ndarray, bone: int, points: np.ndarray,
                  inv_local: np.ndarray, inv_world: np.ndarray) -> np.ndarray:
    """World ``points`` ``(p, 3)`` given at rest, moved with ``bone`` to its armature-space pose
    ``posed_local[bone]`` (the skin follows its bone). ``inv_local``, ``inv_world``: the
    inverses of ``rest.local`` and ``rest.world``."""
    move = rest.world @ posed_local[bone] @ inv_local[bone] @ inv_world
    return _apply(move, points)


_OVERRIDING_CONSTRAINTS = frozenset({
    "IK", "COPY_ROTATION", "COPY_TRANSFORMS", "DAMPED_TRACK", "LOCKED_TRACK", "TRACK_TO", "STRETCH_TO",
    "CHILD_OF", "ARMATURE", "SPLINE_IK", "ACTION", "TRANSFORM", "CLAMP_TO", "FOLLOW_PATH",
})


def detect_legs(obj: bpy.types.Object) -> list[LegChain]:
    """Find the legs of armature ``obj`` (see :func:`.detect.find_legs`).

    Returns legs labelled and ordered front to back, left before right (``L1, R1, L2, ...``;
    a leg on the midline is ``M<row>``). Raises :class:`RigError` when no leg is found.
    """
    rest = _rest_of(obj)
    pbones = obj.pose.bones
    constrained = np.array([any(c.type in _OVERRIDING_CONSTRAINTS for c in pbones[n].constraints)
                            for n in rest.names], dtype=bool)
    if _read_once is None:
        return find_legs(rest, constrained, obj.name)
    key = _shape_key(rest, constrained)
    if key not in _detected_once:
        _detected_once[key] = find_legs(rest, constrained, obj.name)
    return list(_detected_once[key])


def _shape_key(rest: _Rest, constrained: np.ndarray) -> tuple[object, ...]:
    """What detection sees of a rig, wherever it stands: bone names, parents, constraints,
    and its joints relative to the object's origin in world axes, to a nanometre per metre
    of scale. Detection is a matter of the rig's shape (what reaches the ground, which
    bones pair up): copies of one rig, moved, get the legs found for the first (a herd of
    100 wolves is detected once)."""
    origin = rest.world[:3, 3]
    unit = 1e-9 * max(rest.scale, 1e-12)
    where = [np.round((a - origin) / unit).astype(np.int64).tobytes()
             for a in (rest.head, rest.tail, rest.end)]
    return (rest.names, rest.parent.tobytes(), rest.phantom.tobytes(), rest.tails_meaningful,
            constrained.tobytes(), np.round(rest.world[:3, :3] / max(rest.scale, 1e-12), 12).tobytes(),
            rest.local.tobytes(), *where)


def facing_source(obj: bpy.types.Object, legs: Sequence[LegChain]) -> str:
    """What says which way ``obj`` faces with these legs: ``"toes"``, ``"head"``,
    ``"L/R names"`` or ``"object's -Y axis"`` (see :func:`.detect.forward_of`)."""
    return forward_of(_rest_of(obj), legs)[1]


def leg_from_bones(obj: bpy.types.Object, hip: str, end: str, label: str = "") -> LegChain:
    """A leg from user-chosen hip and end-effector bones, validated.

    Raises :class:`RigError` when a bone is missing, the hip is not an ancestor of the end
    (or the end itself), or a bone of the chain has zero length.
    """
    return leg_between(_rest_of(obj), hip, end, label, obj.name)

def read_rig(
    obj: bpy.types.Object, legs: Sequence[LegChain] | None = None, forward_axis: str = "AUTO",
    spine: bool = False, at_rest: Collection[str] = (),
) -> RigInfo:
    """Read ``obj``'s legs (given, else detected), body bone, spine and rest geometry.

    ``spine``: drive the spine chain when the rig has one that carries two girdles or more
    (:attr:`RigInfo.spine_layout`); its bones are then read at rest, like the legs.
    Bones that are not driven keep their current pose (:attr:`RigInfo.basis`), except those
    named in ``at_rest``, which are taken at rest.
    Raises :class:`RigError` for anything that cannot be animated (not an armature, bad
    legs, legs with no common body bone, non-uniform scale).

    Inside a :func:`reading_once` block with a :class:`ReadCache`, a rig read before with the
    same arguments and found unchanged is the one read then (the same object).
    """
    if _read_once is None or obj is None or obj.type != "ARMATURE":
        return _read_rig(obj, legs, forward_axis, spine, at_rest)
    asked = (_pose_digest(obj, at_rest), None if legs is None else tuple(legs), forward_axis, bool(spine),
             tuple(sorted(at_rest)))
    if _cache_once is not None:
        key = (_digest(obj), *asked)
        kept = _cache_once.infos.get(obj.name)
        if kept is not None and kept[0] == key:
            _copy_keys_once[id(kept[1])] = (key, _plain_once[obj.name])  # (what shared() kept too)
            return kept[1]
    # A copy of a rig read in this block (the same bones, pose, constraints, skins and
    # weights; its object only moved): that reading, moved to where it stands.
    copy = (_shape_digest(obj), _weights_digest(obj), *asked)
    first = _copies_once.get(copy)
    info = _read_rig(obj, legs, forward_axis, spine, at_rest) if first is None else _placed(first, obj)
    _copies_once.setdefault(copy, info)
    _copy_keys_once[id(info)] = (copy if _cache_once is None else key, _plain_once[obj.name])
    if _cache_once is not None:
        _cache_once.infos[obj.name] = (key, info)
    return info


def _far_joint(rest: _Rest, leg: LegChain, heads: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The far joint ``(3,)`` of ``leg``'s end-effector, from the posed ``heads`` and far
    joints ``ends`` ``(B, 3)``: its own far joint, or the head of its first foot bone when that
    hangs from it elsewhere among other children. An importer points the tail of a bone with
    several children at one of them (glTF: the first) or between them (FBX: their mean), and
    when most bones have one child the rig's tails pass for joints: Genesis 9's ``l_shin``,
    with ``l_shin_twist1`` and ``l_shin_twist2`` beside ``l_foot``, once ended a fifth of the
    way down the shin."""
    end = rest.index[leg.end]
    if not leg.foot:
        return ends[end]
    foot = rest.index[leg.foot[0]]
    kids = rest.children(end)
    tol = 1e-4 * max(float(np.linalg.norm(rest.head[foot] - rest.head[end])), 1e-12)
    if foot in kids and len(kids) > 1 and np.linalg.norm(rest.end[end] - rest.head[foot]) > tol:
        return heads[foot]
    return ends[end]


def _read_rig(
    obj: bpy.types.Object, legs: Sequence[LegChain] | None, forward_axis: str, spine: bool,
    at_rest: Collection[str],
) -> RigInfo:
    rest, skin = _read(obj)
    if legs is None:
        legs = detect_legs(obj)
    legs = list(legs)
    if not legs:
        raise RigError(f"'{obj.name}' has no enabled legs")
    for leg in legs:
        for b in (*leg.bones, *leg.foot):
            if b not in rest.index:
                raise RigError(f"Leg {leg.label}: '{obj.name}' has no bone '{b}'")
    used = [b for leg in legs for b in leg.bones]
    if len(set(used)) != len(used):
        raise RigError("Two legs share a bone: each bone may belong to one leg only")
    if any(not leg.label for leg in legs) or len({leg.label for leg in legs}) != len(legs):
        legs = _label_legs(rest, [LegChain(leg.bones, leg.foot, leg.side) for leg in legs],
                           _forward_axis(rest, legs, forward_axis))
    forward = _forward_axis(rest, legs, forward_axis)
    left = np.cross(_UP, forward)

    hip_idx = [rest.index[leg.hip] for leg in legs]
    # The body and the spine in the skeleton's hierarchy (a generated rig's ORG- bones as
    # its metarig had them); poses are composed along the real one.
    skel = skeleton_view(rest)
    body_idx = _common_ancestor(skel, hip_idx)
    if body_idx is None:
        raise RigError("The legs do not hang from one body: their hips have no common parent bone")
    # A connected bone cannot be moved (its head is its parent's tail): the body motion goes
    # to the first ancestor that can.
    while obj.data.bones[rest.names[body_idx]].use_connect and rest.parent[body_idx] >= 0:
        body_idx = int(rest.parent[body_idx])
    mean_leg = float(np.mean([_length(_chain_points(rest, [rest.index[b] for b in leg.bones]))
                              for leg in legs]))
    chain = _spine_chain(skel, body_idx, hip_idx, forward, mean_leg)
    carried = spine and _spine_layout(skel, chain, hip_idx, rest.head, rest.end) is not None
    if not carried:
        # The body moves as one from its highest plain bone (CC_Base_Hip, not CC_Base_Pelvis).
        ground = min(float(_chain_points(rest, [rest.index[b] for b in leg.bones])[:, 2].min())
                     for leg in legs)
        body_idx = _carrier(obj, rest, body_idx, ground + 0.25 * mean_leg)

    basis = _current_basis(obj)
    for name in at_rest:
        if name in basis:
            basis[name] = np.eye(4)
    ik_targets = [_ik_target(obj, rest, leg) for leg in legs]
    foot_targets = [_foot_ik_target(obj, rest, leg) for leg in legs]
    driven = {rest.index[b] for leg in legs for b in (*leg.bones, *leg.foot[:1])} | {body_idx}
    if carried:
        driven |= set(chain)
    driven |= {rest.index[t[0]] for t in ik_targets if t is not None}
    driven |= {rest.index[t] for t in foot_targets if t is not None}
    inv_local = affine_inverse(rest.local)
    posed_local = _posed_rest(rest, basis, driven, inv_local)
    # The solved bones under a bone the animator posed: their rest as read (see RigInfo.rest_posed).
    posed = {i for i, n in enumerate(rest.names)
             if i not in driven and not np.array_equal(basis[n], np.eye(4))}
    rest_posed = {rest.names[i]: posed_local[i] for i in sorted(driven)
                  if posed.intersection(rest.ancestors(i))}
    heads = _apply(rest.world, posed_local[:, :3, 3])
    # Each bone's far joint (its tail, or on imported rigs the next bone's head) moves with the bone.
    inv_world = affine_inverse(rest.world)
    end_arm = _apply(inv_world, rest.end)
    end_bone = np.einsum("bij,bj->bi", inv_local[:, :3, :3], end_arm - rest.local[:, :3, 3])
    ends = _apply(rest.world,
                  np.einsum("bij,bj->bi", posed_local[:, :3, :3], end_bone) + posed_local[:, :3, 3])

    foot_bones = [[rest.index[f] for f in leg.foot] for leg in legs]
    foot_bones = [sorted({*fb, *(c for k in fb for c in _descendants(rest, k))}) for fb in foot_bones]
    posed_skin = {k: _posed_points(rest, posed_local, k, skin[rest.names[k]], inv_local, inv_world)
                  for fb in foot_bones for k in fb if rest.names[k] in skin}

    joints = []
    contact = []
    foot_h = []
    foot_ext = []
    foot_pts = []
    for leg, fb in zip(legs, foot_bones, strict=True):
        idx = [rest.index[b] for b in leg.bones]
        pts = np.vstack([heads[idx], _far_joint(rest, leg, heads, ends)[None]])
        joints.append(pts)
        below = [pts[-1]]
        for k in fb:
            below += [heads[k], ends[k]]
        bone_pts = np.array(below)
        # Sole probes: the foot points reaching furthest from the end-effector (toe tips, heel).
        probes = bone_pts[1:]
        if probes.shape[0] > 6:
            far = np.argsort(-np.linalg.norm(probes[:, :2] - pts[-1, :2], axis=1), kind="stable")[:6]
            probes = probes[np.sort(far)]
        # The skin's sole, where the mesh is lower or reaches further than the bones (a heel,
        # a shoe's sole, a hoof's rim): its lowest point and its extremes along and across the body.
        mesh = [posed_skin[k] for k in fb if k in posed_skin]
        if mesh:
            sole = sole_points(np.concatenate(mesh), pts[-1], forward, left)
            below_a = np.vstack([bone_pts, sole])
            probes = np.vstack([probes, sole])
        else:
            below_a = bone_pts
        low = below_a[np.argmin(below_a[:, 2])]
        contact.append(np.array([pts[-1, 0], pts[-1, 1], low[2]]))
        foot_h.append(float(pts[-1, 2] - low[2]))
        # How far the foot reaches from the end-effector, along and across the body.
        rel = below_a[:, :2] - pts[-1, :2]
        foot_ext.append(np.array([np.abs(rel @ forward[:2]).max(), np.abs(rel @ left[:2]).max()]))
        foot_pts.append(probes)
    origin = np.array([j[0] for j in joints]).mean(axis=0)
    body = BodyInfo(origin, forward, left)
    layout = _spine_layout(skel, chain, hip_idx, heads, ends) if carried else None

    warnings = []
    handled = {t[0] for t in ik_targets if t is not None} | {t for t in foot_targets if t is not None}
    for name in sorted(rest.names[i] for i in driven):
        pb = obj.pose.bones[name]
        bad = [c.type for c in pb.constraints
               if c.enabled and c.influence > 0.0 and c.type in _OVERRIDING_CONSTRAINTS
               and not (c.type == "IK" and c.target == obj and c.subtarget in handled)]
        if bad:
            warnings.append(f"bone '{name}' has {', '.join(sorted(set(bad)))} constraints that override the "
                            "generated keys")

    return RigInfo(
        object_name=obj.name,
        legs=tuple(legs),
        body_bone=rest.names[body_idx],
        spine=tuple(rest.names[i] for i in chain),
        body=body,
        joints=tuple(joints),
        contact=np.array(contact),
        foot_height=np.array(foot_h),
        foot_extent=np.array(foot_ext),
        foot_points=tuple(foot_pts),
        ik_targets=tuple(ik_targets),
        foot_ik_targets=tuple(foot_targets),
        rest_posed=rest_posed,
        world=rest.world,
        scale=rest.scale,
        rest_local={n: rest.local[i] for i, n in enumerate(rest.names)},
        parents={n: (rest.names[int(rest.parent[i])] if rest.parent[i] >= 0 else None)
                 for i, n in enumerate(rest.names)},
        basis=basis,
        warnings=tuple(warnings),
        spine_layout=layout,
    )


_SKELETON_COPY = re.compile(r"^(ORG|DEF|MCH)[-_.]")


def _carrier(obj: bpy.types.Object, rest: _Rest, body: int, above: float) -> int:
    """The bone that carries the body: ``body`` (the legs' common ancestor), or the highest of
    its plain ancestors, so no part of the body stays behind when it moves. Character
    Creator's legs hang from ``CC_Base_Pelvis`` and its spine from ``CC_Base_Hip`` above it,
    3ds Max Biped's from ``Bip01 Spine`` under ``Bip01 Pelvis``: moving the pelvis alone
    would leave the upper body (the hips) where they were.

    The climb stops below a bone that is not plain: named as a control or helper (the
    placement root ``root``, ``CC_Base_BoneRoot``, ``c_root_master``), a mechanism or
    deform copy (``ORG-``, ``DEF-``, ``MCH-``), driven by a constraint, or with its head no
    higher than ``above`` (world z: a root at the ground). A body bone that is itself driven
    (a control rig's) is left to the controls that drive it. A connected bone cannot move
    (its head is its parent's tail): its parent carries the body, root or not (FBX's
    importer connects ``CC_Base_Hip`` to ``CC_Base_BoneRoot``, whose tail it points at the
    hip, and the walk once keyed the hip's location, which Blender ignores).
    """
    pbones = obj.pose.bones
    bones = obj.data.bones
    control = _control_bones(rest)

    def plain(i: int) -> bool:
        name = rest.names[i]
        return (not control[i] and not rest.phantom[i] and not _SKELETON_COPY.match(name)
                and not any(c.type in _OVERRIDING_CONSTRAINTS for c in pbones[name].constraints))

    if not plain(body):
        return body
    cur = body
    while True:
        p = int(rest.parent[cur])
        if p < 0 or not plain(p) or float(rest.head[p, 2]) <= above:
            break
        cur = p
    while bones[rest.names[cur]].use_connect and rest.parent[cur] >= 0:
        cur = int(rest.parent[cur])
    return cur


def _ik_target(obj: bpy.types.Object, rest: _Rest, leg: LegChain) -> tuple[str, int] | None:
    """The bone an enabled IK constraint on ``leg`` pulls the chain to, and the index of the
    joint it pulls (the constrained bone's tail, or its head with "Use Tail" off)."""
    chain = set(leg.bones)
    for k, name in enumerate(leg.bones):
        for c in obj.pose.bones[name].constraints:
            if c.type != "IK" or not c.enabled or c.influence <= 0.0 or c.target != obj:
                continue
            target = c.subtarget
            if target not in rest.index or target in chain:
                continue
            # A target that moves with the chain itself would be a dependency cycle.
            if any(rest.names[a] in chain for a in rest.ancestors(rest.index[target])):
                continue
            return target, (k + 1 if c.use_tail else k)
    return None


def _foot_ik_target(obj: bpy.types.Object, rest: _Rest, leg: LegChain) -> str | None:
    """The bone an enabled one-bone IK constraint on the leg's first foot bone aims it at
    (MMD's ``左足首`` at ``左つま先ＩＫ``), when that bone is of this rig and moves neither
    with the leg nor with the foot (that would be a dependency cycle)."""
    if not leg.foot:
        return None
    carried = set(leg.bones) | set(leg.foot)
    for c in obj.pose.bones[leg.foot[0]].constraints:
        if (c.type != "IK" or not c.enabled or c.influence <= 0.0 or c.target != obj or c.chain_count != 1
                or c.subtarget not in rest.index or c.subtarget in carried):
            continue
        if any(rest.names[a] in carried for a in rest.ancestors(rest.index[c.subtarget])):
            continue
        return str(c.subtarget)
    return None


def _current_basis(obj: bpy.types.Object) -> dict[str, np.ndarray]:
    pose = obj.pose
    n = len(pose.bones)
    buf = np.empty(n * 16, dtype=np.float32)
    pose.bones.foreach_get("matrix_basis", buf)
    mats = buf.reshape(n, 4, 4).transpose(0, 2, 1).astype(np.float64)
    return {pb.name: mats[i] for i, pb in enumerate(pose.bones)}


def _posed_rest(rest: _Rest, basis: dict[str, np.ndarray], driven: set[int],
                inv_local: np.ndarray) -> np.ndarray:
    """Armature-space matrices of every bone with driven bones at rest and the others as
    currently posed (their pose persists under the generated Action). ``(B, 4, 4)``.
    ``inv_local``: the inverses of ``rest.local``."""
    n = len(rest.names)
    out = np.empty((n, 4, 4))
    done = np.zeros(n, dtype=bool)

    def solve(i: int) -> np.ndarray:
        if done[i]:
            return out[i]
        b = np.eye(4) if i in driven else basis[rest.names[i]]
        p = int(rest.parent[i])
        if p < 0:
            out[i] = rest.local[i] @ b
        else:
            out[i] = solve(p) @ inv_local[p] @ rest.local[i] @ b
        done[i] = True
        return out[i]

    for i in range(n):
        solve(i)
    return out
