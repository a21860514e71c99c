# SPDX-License-Identifier: GPL-3.0-or-later
"""World poses to keys: the one place where a pose ProcLoco solved becomes keyable channels.

Generate Locomotion, Bake Secondary Motion and Plan Biped Footsteps all end the same way:
they know where bones should be (armature-space pose matrices of *solved* bones, frame by
frame) and must key channels so that Blender's evaluated rig puts them there. This module
does it, for plain rigs and for control rigs:

- **Free solved bones** (:attr:`.rig.controls.ControlPlan.direct`, a plain FK rig's bones) get the
  ``matrix_basis`` that puts them at their target under their parent's target pose
  (:func:`basis_from_armature`), exactly, without evaluating the rig; when the request
  carries those channels already (Generate solves them so) and the object does not move,
  they are keyed as they are.
- **Controls** (:attr:`.rig.controls.ControlPlan.controls`) are solved *through* Blender: the rig
  is evaluated at every frame, each control is moved by the error of the solved bone it drives
  (``RIGID``: rigidly with it; ``MOVE``: by its head's error only, when it points at
  another bone; ``TURN``: turned like it, rotation only; ``IK``: turned like
  the foot, moved by the end-effector's error; ``POLE``: put on the knee's side of the leg's
  plane), keyed, and the rig is evaluated again,
  until the solved bones are within 0.1 mm (and 0.1 degree) of their targets, or a pass no
  longer helps (two to four passes on generated Rigify rigs; a pass costs one depsgraph
  evaluation per frame). A ``TURN`` control that follows another one of its FK chain
  (:attr:`.rig.controls.ControlKey.follows`) is corrected for its parent's turn in the same
  pass, so a whole FK leg lands in one pass. A pole is turned about the hip-to-end axis
  until the knee lands (by what the knee misses when that is under a quarter turn: a knee on
  the far side is no offset to turn by). Each frame keeps the keys of the pass that placed it
  best (its feet and body first, its knees a hundredth as much): a pass may improve most
  frames and flip a knee in another. Whatever lies between the control and the deform
  bones (foot-roll mechanisms, parent switches) is Blender's own.
- **Switches** (:class:`.rig.controls.Switch`) are keyed at their chosen value (a leg's
  IK/FK switch at IK, or at FK for a leg driven by its FK controls), the IK chains' stretch
  (``ik_stretch``) off included.

The targets are given for the object's world matrix at the first frame (``world0``); when the
object moves (an animated parent, object keys, constraints), each frame's target is carried
into the armature space of that frame, so the bones stay where they were planned *in the
world*.

Shapes: ``frames`` ``(F,)``; ``armature`` ``(F, B, 4, 4)`` for the ``bones`` ``(B,)``.
"""

from __future__ import annotations

from collections.abc import Generator, Iterator, Sequence
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.steps import run_steps, scaled_steps
from . import actions
from .rig.controls import ControlKey, ControlPlan, Switch
from .rig.rest import affine_inverse, affine_inverses, nearest_rotation

__all__ = [
    "PoseRequest",
    "Steps",
    "WriteReport",
    "armature_from_basis",
    "basis_from_armature",
    "evaluate_pose",
    "evaluate_pose_steps",
    "evaluate_poses_steps",
    "object_moves",
    "object_worlds",
    "write_pose",
    "write_pose_steps",
]


#: Stop correcting controls once every solved bone is this close to its target (metres, in
#: units of the rig's scale) and turned by less than ``_TOL_ANGLE`` radians.
_TOL = 1e-4
_TOL_ANGLE = 2e-3
_MAX_PASSES = 5
#: How much less a knee's error (a pole's) counts than a foot's when a frame's best pass is chosen.
_POLE_WEIGHT = 100.0


@dataclass(frozen=True)
class PoseRequest:
    """What to key: ``armature[f, b]`` is where solved bone ``bones[b]`` should be at
    ``frames[f]`` (armature space for world matrix ``world0``). ``keyed_location[b]``: key the
    free bone's location too (else rotation only). ``legs``: per leg the solved chain (hip to
    end-effector) whose end the ``IK`` and ``POLE`` controls place.

    ``rest_local`` / ``parents`` / ``basis``: every bone's armature rest matrix, parent and
    current ``matrix_basis`` (bones that are not solved keep their pose).

    ``rotations`` ``(F, B, 4)`` and ``locations`` ``(F, B, 3)``: the solved bones'
    ``matrix_basis`` as channels, when the caller solved them so (Generate); then
    ``armature`` may be None (it follows from them, :func:`armature_from_basis`), and free
    bones of a rig that does not move are keyed from them as they are.
    """

    frames: np.ndarray
    bones: tuple[str, ...]
    armature: np.ndarray | None
    keyed_location: np.ndarray
    world0: np.ndarray
    rest_local: dict[str, np.ndarray]
    parents: dict[str, str | None]
    basis: dict[str, np.ndarray]
    legs: tuple[tuple[str, ...], ...] = ()
    # The targets are already in each frame's armature space (sampled from the evaluated rig):
    # they are not carried along a moving object.
    per_frame: bool = False
    # Armature-space poses ``(F, 4, 4)`` of bones that are not solved but that solved bones
    # hang from, as sampled (an animated body); others are taken as currently posed.
    parent_pose: dict[str, np.ndarray] = field(default_factory=dict)
    rotations: np.ndarray | None = None
    locations: np.ndarray | None = None

    def armature_space(self) -> np.ndarray:
        """``armature``, or when not given the pose its channels give."""
        if self.armature is not None:
            return np.asarray(self.armature, dtype=np.float64)
        if self.rotations is None or self.locations is None:
            raise ValueError("a pose request needs its armature-space pose or its channels")
        return armature_from_basis(self.bones, self.rotations, self.locations, self.rest_local, self.parents,
                                   self.basis, self.keyed_location)


@dataclass
class WriteReport:
    """What :func:`write_pose` keyed and how close the evaluated rig came."""

    keyed: list[str] = field(default_factory=list)
    passes: int = 0
    # per leg, the largest distance (m) between the evaluated and the planned end-effector
    leg_error: list[float] = field(default_factory=list)
    body_error: float = 0.0
    # what was keyed for which leg (Key Reduction keeps each leg's contacts on its controls)
    plan: ControlPlan | None = None


def object_moves(obj: bpy.types.Object) -> bool:
    """Whether the object's world matrix may change over time (its own or a parent's
    animation, drivers or constraints)."""
    cur: bpy.types.Object | None = obj
    while cur is not None:
        adt = cur.animation_data
        animated = adt is not None and (adt.action is not None or len(adt.drivers) or len(adt.nla_tracks))
        if animated and (cur is not obj or _animates_object(adt)):
            return True
        if len(cur.constraints):
            return True
        cur = cur.parent
    return False


def _animates_object(adt: bpy.types.AnimData) -> bool:
    """Whether the object's own Action, NLA or drivers touch its transform (not its bones)."""
    paths: list[str] = [d.data_path for d in adt.drivers]
    if adt.action is not None:
        paths += [ch.data_path for ch in _fcurves(adt)]
    if len(adt.nla_tracks):
        return True
    return any(p.split("[")[0] in {"location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle",
                                   "scale", "delta_location", "delta_rotation_euler", "delta_scale"}
               for p in paths)


def _fcurves(adt: bpy.types.AnimData) -> list[actions.Channel]:
    obj_id = adt.id_data
    return actions.channels_of(adt.action, obj_id)


def _frame_loop(frames: Sequence[int]) -> Iterator[int]:
    """Set the scene to each frame in turn (yielding its index); the frame is put back after."""
    scene = bpy.context.scene
    old = scene.frame_current
    try:
        for f, frame in enumerate(frames):
            scene.frame_set(int(frame))
            yield f
    finally:
        scene.frame_set(old)


#: What the stepwise writers yield: the fraction done; their return value is the result.
Steps = Generator[float, None, "WriteReport"]

#: Frames evaluated between two progress steps (a step stays well under a tenth of a second).
_FRAMES_PER_STEP = 32


def _object_worlds_steps(obj: bpy.types.Object, frames: np.ndarray) -> Generator[float, None, np.ndarray]:
    out = np.empty((len(frames), 4, 4))
    for f in _frame_loop([int(x) for x in frames]):
        ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        out[f] = np.array(ev.matrix_world, dtype=np.float64)
        if f % _FRAMES_PER_STEP == _FRAMES_PER_STEP - 1:
            yield (f + 1) / len(frames)
    return out


def object_worlds(obj: bpy.types.Object, frames: np.ndarray) -> np.ndarray:
    """The object's evaluated world matrix at each frame ``(F, 4, 4)``."""
    return run_steps(_object_worlds_steps(obj, frames))


def _evaluate_pose_steps(obj: bpy.types.Object, frames: np.ndarray, names: Sequence[str],
                         world: bool = False) -> Generator[float, None, np.ndarray]:
    return (yield from evaluate_poses_steps([obj], [frames], [names], world))[0]


def evaluate_poses_steps(objs: Sequence[bpy.types.Object], frames: Sequence[np.ndarray],
                         names: Sequence[Sequence[str]],
                         world: bool = False) -> Generator[float, None, list[np.ndarray]]:
    """Per object ``objs[k]`` its bones ``names[k]``' evaluated pose matrices
    ``(F_k, n_k, 4, 4)`` at its ``frames[k]``, the scene set to each frame of their union
    once for all of them (a frame change evaluates every animated object of the scene, so
    one pass for all rigs instead of one per rig). ``world``: world matrices (the evaluated
    object's world matrix at each frame applied) instead of armature-space ones. Yields the
    fraction done."""
    index = []
    bufs = []
    for obj, want in zip(objs, names, strict=True):
        all_names = [pb.name for pb in obj.pose.bones]
        where = {n: i for i, n in enumerate(all_names)}
        index.append(np.array([where[n] for n in want], dtype=np.int64))
        bufs.append(np.empty(len(all_names) * 16, dtype=np.float32))
    out = [np.empty((len(f), len(want), 4, 4)) for f, want in zip(frames, names, strict=True)]
    wanted = [np.asarray(f, dtype=np.int64) for f in frames]
    union = np.unique(np.concatenate(wanted)) if wanted else np.zeros(0, dtype=np.int64)
    # per object, the row of each frame of the union it has (-1: not one of its frames)
    rows = []
    for f in wanted:
        row = np.full(len(union), -1, dtype=np.int64)
        row[np.searchsorted(union, f)] = np.arange(len(f))
        rows.append(row)
    step = max(_FRAMES_PER_STEP // max(len(objs), 1), 1)
    for u in _frame_loop([int(x) for x in union]):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for k, obj in enumerate(objs):
            at = int(rows[k][u])
            if at < 0:
                continue
            ev = obj.evaluated_get(depsgraph)
            ev.pose.bones.foreach_get("matrix", bufs[k])
            out[k][at] = bufs[k].reshape(-1, 4, 4).transpose(0, 2, 1)[index[k]]
            if world:
                out[k][at] = np.array(ev.matrix_world, dtype=np.float64) @ out[k][at]
        if u % step == step - 1:
            yield (u + 1) / len(union)
    return out


def evaluate_pose(obj: bpy.types.Object, frames: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """Evaluated armature-space pose matrices ``(F, n, 4, 4)`` of ``names`` at each frame."""
    return run_steps(_evaluate_pose_steps(obj, frames, names))


def evaluate_pose_steps(obj: bpy.types.Object, frames: np.ndarray, names: Sequence[str],
                        world: bool = False) -> Generator[float, None, np.ndarray]:
    """:func:`evaluate_pose` as progress steps; ``world``: world matrices (the evaluated
    object's world matrix at each frame applied) instead of armature-space ones."""
    return _evaluate_pose_steps(obj, frames, names, world)


def _depth(parents: dict[str, str | None], name: str) -> int:
    d = 0
    cur = parents[name]
    while cur is not None:
        d += 1
        cur = parents[cur]
    return d


def basis_from_armature(req: PoseRequest, armature: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """``matrix_basis`` ``(F, n, 4, 4)`` that puts free bones ``names`` (of ``req.bones``) at
    ``armature`` ``(F, B, 4, 4)``, each under its parent's pose: the parent's target when it
    is solved, else its current pose under its own (possibly solved) parents."""
    index = {b: i for i, b in enumerate(req.bones)}
    n_frames = armature.shape[0]
    cache: dict[str, np.ndarray] = {}
    inv_rest = affine_inverses(req.rest_local)

    def pose(name: str) -> np.ndarray:
        if name in index:
            return armature[:, index[name]]
        if name in req.parent_pose:
            return np.broadcast_to(req.parent_pose[name], (n_frames, 4, 4))
        if name not in cache:
            parent = req.parents[name]
            rest = req.rest_local[name]
            if parent is None:
                above: np.ndarray = np.eye(4)[None]
            else:
                above = pose(parent) @ inv_rest[parent]
            cache[name] = np.broadcast_to(above @ (rest @ req.basis[name])[None], (n_frames, 4, 4))
        return cache[name]

    out = np.empty((n_frames, len(names), 4, 4))
    for j, name in enumerate(names):
        parent = req.parents[name]
        rest = req.rest_local[name]
        if parent is None:
            base = np.broadcast_to(rest, (n_frames, 4, 4))
        else:
            base = pose(parent) @ (inv_rest[parent] @ rest)[None]
        out[:, j] = affine_inverse(base) @ armature[:, index[name]]
    return out


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """``(..., 4)`` unit quaternions (w, x, y, z) -> ``(..., 3, 3)`` rotation matrices."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def armature_from_basis(
    bones: Sequence[str], rotations: np.ndarray, locations: np.ndarray, rest_local: dict[str, np.ndarray],
    parents: dict[str, str | None], basis: dict[str, np.ndarray], keyed_location: np.ndarray,
) -> np.ndarray:
    """Armature-space pose ``(F, B, 4, 4)`` of ``bones`` given their ``matrix_basis`` as
    rotations ``(F, B, 4)`` and locations ``(F, B, 3)`` (used where ``keyed_location`` ``(B,)``,
    elsewhere the bone keeps its current location); other bones keep ``basis``."""
    index = {b: i for i, b in enumerate(bones)}
    n_frames = rotations.shape[0]
    own = np.tile(np.eye(4), (n_frames, len(bones), 1, 1))
    own[..., :3, :3] = _quat_matrix(rotations)
    current = np.array([basis[b][:3, 3] for b in bones]).reshape(len(bones), 3)
    keyed = np.asarray(keyed_location, dtype=bool)[None, :, None]
    own[..., :3, 3] = np.where(keyed, locations, current[None])
    cache: dict[str, np.ndarray] = {}
    inv_rest = affine_inverses(rest_local)

    def pose(name: str) -> np.ndarray:
        if name not in cache:
            parent = parents[name]
            b = own[:, index[name]] if name in index else basis[name][None]
            rest = rest_local[name]
            if parent is None:
                cache[name] = rest[None] @ b
            else:
                cache[name] = pose(parent) @ (inv_rest[parent] @ rest)[None] @ b
        return cache[name]

    return np.stack([np.broadcast_to(pose(b), (n_frames, 4, 4)) for b in bones], axis=1)


def _key(action: bpy.types.Action, obj: bpy.types.Object, frames: np.ndarray, names: Sequence[str],
         basis: np.ndarray, location: np.ndarray | Sequence[bool]) -> None:
    """Key rotation (and location where ``location[b]``) of ``basis`` ``(F, n, 4, 4)``."""
    from .rig import matrix_to_quaternion

    if not names:
        return
    quats = matrix_to_quaternion(nearest_rotation(basis[..., :3, :3]))
    _key_channels(action, obj, frames, names, quats, basis[..., :3, 3], location)


def _key_channels(action: bpy.types.Action, obj: bpy.types.Object, frames: np.ndarray, names: Sequence[str],
                  rotations: np.ndarray, locations: np.ndarray,
                  location: np.ndarray | Sequence[bool]) -> None:
    """Key ``rotations`` ``(F, n, 4)`` (and ``locations`` ``(F, n, 3)`` where ``location[b]``)."""
    actions.write_pose_bone_transforms(action, obj, frames, names, rotations=rotations)
    loc = [i for i, k in enumerate(location) if k]
    if loc:
        actions.write_pose_bone_transforms(action, obj, frames, [names[i] for i in loc],
                                           locations=locations[:, loc])


def _key_switches(action: bpy.types.Action, obj: bpy.types.Object, frames: np.ndarray,
                  switches: Sequence[Switch]) -> None:
    if not switches:
        return
    ends = frames[[0, -1]] if frames.size > 1 else frames[:1]
    chans = [actions.Channel(s.data_path, 0, s.bone) for s in switches]
    values = np.tile(np.array([s.value for s in switches], dtype=np.float64), (ends.size, 1))
    actions.write_channels(action, obj, chans, ends, values, interpolation="CONSTANT")


def _leg_frame(joints: np.ndarray) -> np.ndarray:
    """Per frame the leg's frame ``(F, 3, 3)``: hip to end, the bend normal, their cross."""
    hip, knee, end = joints[:, 0], joints[:, 1], joints[:, -1]
    e1 = end - hip
    e1 /= np.maximum(np.linalg.norm(e1, axis=-1, keepdims=True), 1e-12)
    n = np.cross(knee - hip, end - knee)
    n = n - np.sum(n * e1, axis=-1, keepdims=True) * e1
    size = np.linalg.norm(n, axis=-1, keepdims=True)
    # a straight leg keeps the last good normal
    good = size[:, 0] > 1e-9
    if not good.any():
        n = np.cross(e1, np.array([0.0, 0.0, 1.0]))
        size = np.linalg.norm(n, axis=-1, keepdims=True)
        good = size[:, 0] > 1e-12
    n = np.where(good[:, None], n / np.maximum(size, 1e-12), np.nan)
    idx = np.where(good, np.arange(len(n)), 0)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(good))
    idx[: first] = first
    n = n[idx]
    e3 = np.cross(e1, n)
    return np.stack([e1, n, e3], axis=-1)


def _joints(mats: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Chain joints ``(F, k + 1, 3)``: each bone's head, then the last bone's tail."""
    heads = mats[..., :3, 3]
    tail = heads[:, -1] + mats[:, -1, :3, 1] * lengths[-1]
    return np.concatenate([heads, tail[:, None]], axis=1)


def write_pose(
    action: bpy.types.Action, obj: bpy.types.Object, req: PoseRequest, plan: ControlPlan,
    *, assign: bool = True, replace: bool = False, check: bool = False,
    superseded: list[tuple[bpy.types.Action, bpy.types.Action]] | None = None,
) -> WriteReport:
    """:func:`write_pose_steps` run through (same arguments and result)."""
    return run_steps(write_pose_steps(action, obj, req, plan, assign=assign, replace=replace, check=check,
                                      superseded=superseded))


def write_pose_steps(
    action: bpy.types.Action, obj: bpy.types.Object, req: PoseRequest, plan: ControlPlan,
    *, assign: bool = True, replace: bool = False, check: bool = False,
    superseded: list[tuple[bpy.types.Action, bpy.types.Action]] | None = None,
) -> Steps:
    """Key ``req`` on ``obj`` into ``action`` following ``plan`` (see the module doc),
    yielding the fraction done while it evaluates the rig frame by frame (closed early, the
    scene gets its frame back; the caller deletes ``action`` and puts back the assignment).

    ``action`` is assigned to the object (``assign``, through
    :func:`.actions.assign_generated_action` with ``replace`` and ``superseded``) before the
    passes that evaluate it. ``check``: with no controls, still evaluate the rig once and
    report how far each leg's end-effector landed from its target (drivers and limits can
    pull it off).
    """
    report = WriteReport(plan=plan)
    frames = np.asarray(req.frames, dtype=np.float64)
    armature: np.ndarray | None = None
    moves = not req.per_frame and object_moves(obj)
    if moves:
        worlds = yield from scaled_steps(_object_worlds_steps(obj, req.frames), 0.0, 0.1)
        # The plan is in the world: carry it into each frame's armature space.
        armature = (affine_inverse(worlds) @ req.world0[None])[:, None] @ req.armature_space()
    index = {b: i for i, b in enumerate(req.bones)}
    direct = [b for b in req.bones if b in plan.direct]
    controls = list(plan.controls)
    located = [bool(req.keyed_location[index[b]]) for b in direct]
    if direct and req.rotations is not None and req.locations is not None and not moves:
        # the solved channels as they are (their armature-space pose gives them back)
        cols = [index[b] for b in direct]
        _key_channels(action, obj, frames, direct, req.rotations[:, cols], req.locations[:, cols], located)
    elif direct:
        armature = req.armature_space() if armature is None else armature
        _key(action, obj, frames, direct, basis_from_armature(req, armature, direct), located)
    _key_switches(action, obj, frames, plan.switches)
    report.keyed = [*direct, *(c.bone for c in controls)]
    if assign:
        actions.assign_generated_action(obj, action, replace=replace, superseded=superseded)
    yield 0.1
    if controls or (check and req.legs):
        armature = req.armature_space() if armature is None else armature
    if controls:
        assert armature is not None
        yield from _solve_controls(action, obj, frames, armature, req, controls, report, index)
    elif check and req.legs:
        assert armature is not None
        report.leg_error = yield from scaled_steps(_leg_errors(obj, req, armature, index), 0.1, 1.0)
    return report


def _leg_errors(obj: bpy.types.Object, req: PoseRequest, armature: np.ndarray,
                index: dict[str, int]) -> Generator[float, None, list[float]]:
    """Per leg the largest distance (m, armature space) between the evaluated and the planned end."""
    names = list(dict.fromkeys(b for leg in req.legs for b in leg))
    ev = yield from _evaluate_pose_steps(obj, req.frames, names)
    col = {n: i for i, n in enumerate(names)}
    out = []
    for leg in req.legs:
        lengths = np.array([obj.data.bones[b].length for b in leg])
        got = _joints(ev[:, [col[b] for b in leg]], lengths)
        want = _joints(armature[:, [index[b] for b in leg]], lengths)
        out.append(float(np.linalg.norm(got[:, -1] - want[:, -1], axis=-1).max()))
    return out


def _solve_controls(action: bpy.types.Action, obj: bpy.types.Object, frames: np.ndarray, armature: np.ndarray,
                    req: PoseRequest, controls: Sequence[ControlKey], report: WriteReport,
                    index: dict[str, int]) -> Generator[float, None, None]:
    """Key ``controls`` by passes of evaluate-and-correct (see the module doc); yields the
    fraction done, from 0.1 (each pass a share of the rest; one that converges early ends)."""
    ctrl_names = [c.bone for c in controls]
    anchors = list(dict.fromkeys(c.anchor for c in controls))
    leg_ids = sorted({c.leg for c in controls if c.leg >= 0})
    chains = {k: list(req.legs[k]) for k in leg_ids}
    names = list(dict.fromkeys([*ctrl_names, *anchors, *(b for k in leg_ids for b in chains[k])]))
    col = {n: i for i, n in enumerate(names)}
    lengths = {k: np.array([obj.data.bones[b].length for b in chains[k]]) for k in leg_ids}
    want_joints = {k: _joints(armature[:, [index[b] for b in chains[k]]], lengths[k]) for k in leg_ids}
    pole_offset = {c.bone: _pole_offset(req, chains[c.leg], lengths[c.leg], c.bone)
                   for c in controls if c.mode == "POLE"}
    pole_turn = {c.bone: np.zeros(frames.size) for c in controls if c.mode == "POLE"}
    basis = np.stack([np.broadcast_to(req.basis[c], (frames.size, 4, 4)) for c in ctrl_names], axis=1).copy()
    scale = max(float(np.mean([np.sum(v) for v in lengths.values()])) if lengths else 1.0, 1e-9)
    last = worst = np.inf
    stalled = 0
    best_error = np.full(frames.size, np.inf)
    best_basis = basis.copy()
    best_leg_error = np.zeros((frames.size, len(leg_ids)))
    legged = any(c.mode in {"IK", "POLE"} for c in controls)
    located = [c.mode != "TURN" for c in controls]
    for p in range(_MAX_PASSES + 1):
        _key(action, obj, frames, ctrl_names, basis, located)
        share = 0.9 / (_MAX_PASSES + 1)
        ev = yield from scaled_steps(_evaluate_pose_steps(obj, req.frames, names), 0.1 + p * share,
                                0.1 + (p + 1) * share)
        report.passes = p + 1
        got_joints = {k: _joints(ev[:, [col[b] for b in chains[k]]], lengths[k]) for k in leg_ids}
        leg_error = np.stack([np.linalg.norm(got_joints[k][:, -1] - want_joints[k][:, -1], axis=-1)
                              for k in leg_ids], axis=1) if leg_ids else np.zeros((frames.size, 0))
        per_frame = np.stack([_control_error(c, ev, col, armature, index, got_joints, want_joints, scale)
                              / (_POLE_WEIGHT if c.mode == "POLE" else 1.0) for c in controls],
                             axis=1).max(axis=1)
        # Each frame keeps the pass that placed it best: a pass may improve most frames and
        # flip a knee in another (an IK that bends its own way there). The feet and the body
        # come first: a knee counts a hundredth as much (a flipped knee, centimetres off, still
        # loses to a pass whose feet are a tenth of a millimetre further).
        better = per_frame < best_error
        best_error[better] = per_frame[better]
        best_basis[better] = basis[better]
        best_leg_error[better] = leg_error[better]
        report.leg_error = [float(e) for e in best_leg_error.max(axis=0)] if leg_ids else []
        worst = float(best_error.max())
        # Done when close enough, or when passes no longer help (a rig that cannot get there).
        # Legs whose IK bends a little its own way stop improving after two or three passes;
        # chains of controls may get worse before they get better, and run all passes.
        stalled = stalled + 1 if legged and worst > 0.99 * last else 0
        if worst < 1.0 or p == _MAX_PASSES or stalled >= 2:
            if not np.array_equal(best_basis, basis):  # the last pass is not the best everywhere
                _key(action, obj, frames, ctrl_names, best_basis, located)
            break
        last = worst
        turned: dict[str, np.ndarray] = {}  # TURN control -> its world turn this pass (F, 3, 3)
        for j, c in enumerate(controls):
            m = ev[:, col[c.bone]]
            want = m.copy()
            if c.mode == "RIGID":  # carried rigidly with its anchor
                want = armature[:, index[c.anchor]] @ affine_inverse(ev[:, col[c.anchor]]) @ m
            elif c.mode == "MOVE":  # moved by its anchor's head error; its turn is another's
                want[:, :3, 3] += armature[:, index[c.anchor], :3, 3] - ev[:, col[c.anchor], :3, 3]
            elif c.mode == "TURN":  # turned like its anchor; its head follows its parent
                d = nearest_rotation(armature[:, index[c.anchor], :3, :3])
                e = nearest_rotation(ev[:, col[c.anchor], :3, :3])
                want[:, :3, :3] = d @ np.swapaxes(e, -1, -2) @ m[:, :3, :3]
                turned[c.bone] = d @ np.swapaxes(e, -1, -2)
            elif c.mode == "IK":  # turned like its anchor, moved by the end-effector's error
                d = nearest_rotation(armature[:, index[c.anchor], :3, :3])
                e = nearest_rotation(ev[:, col[c.anchor], :3, :3])
                want[:, :3, :3] = d @ np.swapaxes(e, -1, -2) @ m[:, :3, :3]
                want[:, :3, 3] += want_joints[c.leg][:, -1] - got_joints[c.leg][:, -1]
            else:  # POLE: at its rest offset from the knee in the leg's frame, turned about the
                # hip-to-end axis by what the knee still misses
                joints = want_joints[c.leg]
                frame_w = _leg_frame(joints)
                frame_g = _leg_frame(got_joints[c.leg])
                miss = np.arctan2(np.einsum("fi,fi->f", frame_w[..., 1], frame_g[..., 2]),
                                  np.einsum("fi,fi->f", frame_w[..., 1], frame_g[..., 1]))
                # A knee on the far side is no small offset to turn the pole by: the IK did
                # not reach there this pass (a target out of reach, a chain still straight).
                pole_turn[c.bone] = pole_turn[c.bone] + np.where(np.abs(miss) < 0.5 * np.pi, miss, 0.0)
                pole = joints[:, 1] + np.einsum("fij,j->fi", frame_w, pole_offset[c.bone])
                turned_pole = _turn_about(frame_w[..., 0], pole_turn[c.bone], pole - joints[:, 0])
                want[:, :3, 3] = joints[:, 0] + turned_pole
            # The control's matrix is (what its parent and constraints give) @ basis.
            base = m @ affine_inverse(basis[:, j])
            if c.follows in turned:  # its parent turns too this pass: it carries the control along
                base[:, :3, :3] = turned[c.follows] @ base[:, :3, :3]
            basis[:, j] = affine_inverse(base) @ want


def _control_error(c: ControlKey, ev: np.ndarray, col: dict[str, int], armature: np.ndarray,
                   index: dict[str, int], got: dict[int, np.ndarray], want: dict[int, np.ndarray],
                   scale: float) -> np.ndarray:
    """How far what control ``c`` places still is at each frame ``(F,)``, in tolerances
    (under 1: close enough)."""
    tol = _TOL * scale
    if c.mode == "POLE":
        return np.linalg.norm(got[c.leg][:, 1] - want[c.leg][:, 1], axis=-1) / tol
    turn = _angles(armature[:, index[c.anchor], :3, :3], ev[:, col[c.anchor], :3, :3]) / _TOL_ANGLE
    if c.mode == "TURN":
        return turn
    if c.mode == "IK":
        moved = np.linalg.norm(got[c.leg][:, -1] - want[c.leg][:, -1], axis=-1)
    else:
        moved = np.linalg.norm(ev[:, col[c.anchor], :3, 3] - armature[:, index[c.anchor], :3, 3], axis=-1)
        if c.mode == "MOVE":
            return moved / tol
    return np.maximum(moved / tol, turn)


def _turn_about(axis: np.ndarray, angle: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` ``(F, 3)`` turned by ``angle`` ``(F,)`` about unit ``axis`` ``(F, 3)`` (Rodrigues)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=-1, keepdims=True) * (1.0 - c)


def _angles(want: np.ndarray, got: np.ndarray) -> np.ndarray:
    """Angles (radians) ``(F,)`` between rotations ``want`` and ``got`` ``(F, 3, 3)`` (either may
    be scaled: a target a few millionths short, from float32 rest matrices, reads as a 0.2 degree
    turn near ``arccos(1)``)."""
    want = want / np.linalg.norm(want, axis=-2, keepdims=True)
    got = got / np.linalg.norm(got, axis=-2, keepdims=True)
    cos = (np.trace(np.swapaxes(want, -1, -2) @ got, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.asarray(np.arccos(np.clip(cos, -1.0, 1.0)))


def _pole_offset(req: PoseRequest, chain: Sequence[str], lengths: np.ndarray, pole: str) -> np.ndarray:
    """The pole's rest head relative to the knee, in the leg's rest frame ``(3,)``."""
    rest = _joints(np.stack([req.rest_local[b] for b in chain])[None], lengths)
    return _leg_frame(rest)[0].T @ (req.rest_local[pole][:3, 3] - rest[0, 1])
