# SPDX-License-Identifier: GPL-3.0-or-later
"""Poses back to bones: :func:`solve_pose` turns per-frame core results (world body frames,
joint positions, spine rotations) into pose-bone ``matrix_basis`` channels."""

from __future__ import annotations

from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass

import numpy as np

from ...core.geometry import z_rotations
from ...core.steps import run_steps
from .info import RigInfo
from .rest import _UP, _apply, _unit, affine_inverse, affine_inverses, nearest_rotation


@dataclass(frozen=True)
class PoseTracks:
    """Per-frame ``matrix_basis`` components of the driven bones.

    ``rotations`` ``(F, B, 4)`` quaternions (w, x, y, z); ``locations`` ``(F, B, 3)``;
    ``keyed_location[b]`` says whether bone ``b``'s location should be keyed.
    """

    bones: tuple[str, ...]
    rotations: np.ndarray
    locations: np.ndarray
    keyed_location: np.ndarray


def matrix_to_quaternion(m: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices -> ``(..., 4)`` unit quaternions (w, x, y, z), w >= 0."""
    m = np.asarray(m, dtype=np.float64)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # |w|, |x|, |y|, |z| from the diagonal; signs from the off-diagonal terms relative to
    # the largest component (Shepperd's method, numerically stable for any rotation).
    diag = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    k = np.argmax(diag, axis=-1)
    s21, s02, s10 = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    a01, a02, a12 = m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1]
    rows = np.stack([
        np.stack([diag[..., 0], s21, s02, s10], -1),
        np.stack([s21, diag[..., 1], a01, a02], -1),
        np.stack([s02, a01, diag[..., 2], a12], -1),
        np.stack([s10, a02, a12, diag[..., 3]], -1),
    ], axis=-2)  # row k is proportional to q * q_k
    q = np.take_along_axis(rows, k[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def _frames(direction: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(..., 3, 3)`` with columns (direction, normal made perpendicular, cross)."""
    e1 = _unit(direction)
    e2 = normal - np.sum(normal * e1, axis=-1, keepdims=True) * e1
    e2 = _unit(e2)
    e3 = np.cross(e1, e2)
    return np.stack([e1, e2, e3], axis=-1)


def _bend_normal(joints: np.ndarray) -> np.ndarray:
    """Sum of consecutive segment cross products ``(..., 3)`` for chains ``(..., k + 1, 3)``."""
    seg = np.diff(joints, axis=-2)
    if seg.shape[-2] < 2:
        return np.zeros((*seg.shape[:-2], 3))
    return np.cross(seg[..., :-1, :], seg[..., 1:, :]).sum(axis=-2)


#: Below this |cos| between a leg's bend normal and its turned rest normal the side is taken
#: from the previous frame instead.
_SIDE_CLEAR = 0.5


def _side_of(normal: np.ndarray, turned: np.ndarray) -> np.ndarray:
    """``normal`` ``(F, 3)`` (unit) flipped to face like ``turned`` ``(F, 3)``, the leg's rest
    bend normal turned with its body. Where the two are nearly perpendicular (a splayed leg
    whose foot has swung a quarter turn from its rest direction: the core turns the leg plane
    with the foot) that choice is a coin toss that rolls every bone of the leg by 180° from
    one frame to the next; there the side follows the previous frame's."""
    dots = np.sum(normal * turned, axis=-1)
    out = np.where((dots < 0.0)[:, None], -normal, normal)
    for f in np.flatnonzero(np.abs(dots[1:]) < _SIDE_CLEAR) + 1:
        out[f] = -normal[f] if float(normal[f] @ out[f - 1]) < 0.0 else normal[f]
    return out


def _yaw_only(rot: np.ndarray) -> np.ndarray:
    """The rotation about world Z that turns the x axis like ``rot`` does ``(..., 3, 3)``."""
    x = rot[..., :, 0]
    return z_rotations(np.arctan2(x[..., 1], x[..., 0]))


def _held_foot_yaw(leg_yaw: np.ndarray, planted: np.ndarray) -> np.ndarray:
    """Heading turns ``(F, L, 3, 3)`` of the feet: a planted foot keeps the heading it landed
    with while what its leg hangs from turns (a flexible spine's girdle yaws by several
    degrees a frame, and a foot turning on the ground would grind), and in the next swing
    the difference fades out, so the foot lands with its leg's heading again.

    leg_yaw: ``(F, L, 3, 3)`` yaw-only rotations (:func:`_yaw_only`); planted ``(F, L)``."""
    ang = np.arctan2(leg_yaw[..., 1, 0], leg_yaw[..., 0, 0])  # (F, L)
    out = ang.copy()
    n_frames = ang.shape[0]
    for k in range(ang.shape[1]):
        f = 1
        while f < n_frames:
            if planted[f, k] and planted[f - 1, k]:
                out[f, k] = out[f - 1, k]
                f += 1
                continue
            if not planted[f, k] and planted[f - 1, k]:
                # a swing from f to its landing: the held offset fades to 0 by then
                land = f
                while land < n_frames and not planted[land, k]:
                    land += 1
                offset = np.angle(np.exp(1j * (out[f - 1, k] - ang[f - 1, k])))
                span = land - f + 1
                for i, g in enumerate(range(f, land)):
                    out[g, k] = ang[g, k] + offset * (1.0 - (i + 1) / span)
                f = land + 1 if land < n_frames else land
                continue
            f += 1
    c, s = np.cos(out), np.sin(out)
    held = np.zeros(leg_yaw.shape)
    held[..., 0, 0], held[..., 0, 1] = c, -s
    held[..., 1, 0], held[..., 1, 1] = s, c
    held[..., 2, 2] = 1.0
    return held


#: ``ground(frame_index (n,), xy (n, 2)) -> (n,)`` world surface heights, ``-inf`` over nothing.
GroundFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


#: Sole points ahead of the ankle by less than this share of the foot's forward reach do not limit its pitch.
NEAR_SHARE = 0.3


def _sole_reach(rel: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For the sole points ``rel`` ``(F, P, 3)`` of feet (relative to each end-effector; foot
    ``j``'s points from ``starts[j]`` to the next start): each foot's forward direction ``d``
    ``(F, J, 2)``, each point's forward reach along its foot's ``a`` ``(F, P)``, and which
    points are far enough ahead to limit the pitch, ``ahead`` ``(F, P)`` (points just ahead of
    the ankle and behind it never do: :data:`NEAR_SHARE`)."""
    d = np.add.reduceat(rel[..., :2], starts, axis=1)
    d_norm = np.linalg.norm(d, axis=-1, keepdims=True)
    d = np.divide(d, d_norm, out=np.zeros_like(d), where=d_norm > 1e-12)
    foot = np.repeat(np.arange(starts.size), np.diff(np.append(starts, rel.shape[1])))
    a = np.einsum("fpi,fpi->fp", rel[..., :2], d[:, foot])  # forward reach of each point
    reach = np.maximum.reduceat(a, starts, axis=1)
    return d, a, a > NEAR_SHARE * np.maximum(reach, 1e-12)[:, foot]


def _foot_pitch(
    rel: np.ndarray, starts: np.ndarray, end: np.ndarray, heights: np.ndarray, limit: float,
    lift: np.ndarray | None = None, reach: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pitch ``(F, J)`` about each foot's horizontal cross axis that sets its sole on the
    ground, and each foot's forward direction ``(F, J, 2)``.

    rel: ``(F, P, 3)`` sole points relative to their end-effector ``end`` ``(F, J, 3)`` (foot
    ``j``'s points from ``starts[j]`` on; the foot at its yaw-turned rest orientation);
    heights ``(F, P)`` ground under them. The smallest rotation keeping every forward point
    above the ground: up a slope or onto an edge the toes lift, down a slope they follow it.
    Points behind the end-effector (heels) are left alone. ``lift`` ``(F, J)``: how far each
    end-effector is above where it stands when planted (``inf`` over no ground); the downward
    pitch fades out as the foot rises by half its length, so a lifted foot does not point its
    toes at the ground below (swing, or over a gap). Only the heights of the points ahead
    (:func:`_sole_reach`, ``reach`` when already known) are read.
    """
    d, a, ahead = _sole_reach(rel, starts) if reach is None else reach
    foot = np.repeat(np.arange(starts.size), np.diff(np.append(starts, rel.shape[1])))
    b = rel[..., 2]
    c = heights - end[:, foot, 2]
    radius = np.hypot(a, b)
    # Points just ahead of the ankle are left out: a sole pitched about the ankle swings them
    # back and barely down (the skin under an ankle would forbid any downward pitch).
    ok = ahead & np.isfinite(heights)
    with np.errstate(invalid="ignore"):  # (the heights not read: -inf)
        need = np.arcsin(np.clip(c / np.maximum(radius, 1e-12), -1.0, 1.0)) - np.arctan2(b, a)
    theta = np.maximum.reduceat(np.where(ok, need, -np.inf), starts, axis=1)
    theta = np.where(np.isfinite(theta), theta, 0.0)
    if lift is not None:
        fade = 0.5 * np.maximum.reduceat(np.where(ok, radius, 0.0), starts, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.clip(1.0 - np.maximum(lift, 0.0) / np.maximum(fade, 1e-12), 0.0, 1.0)
        theta = np.where(theta < 0.0, theta * np.nan_to_num(share, nan=0.0), theta)
    return np.clip(theta, -limit, limit), d


def _axis_rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` by ``angle (...)`` about unit ``axis (..., 3)`` (Rodrigues)."""
    k = axis
    kx = np.zeros((*k.shape[:-1], 3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    s = np.sin(angle)[..., None, None]
    c = np.cos(angle)[..., None, None]
    return np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)


def solve_pose(
    info: RigInfo,
    body_world: np.ndarray,
    joints_world: Sequence[np.ndarray],
    ground: GroundFn | None = None,
    max_foot_pitch: float = np.radians(50.0),
    *,
    spine_rotation: np.ndarray | None = None,
    spine_joints: np.ndarray | None = None,
    leg_frames: np.ndarray | None = None,
    planted: np.ndarray | None = None,
) -> PoseTracks:
    """:func:`solve_pose_steps` run through (same arguments and result)."""
    steps = solve_pose_steps(info, body_world, joints_world, ground, max_foot_pitch,
                             spine_rotation=spine_rotation, spine_joints=spine_joints, leg_frames=leg_frames,
                             planted=planted)
    return run_steps(steps)


def solve_pose_steps(
    info: RigInfo,
    body_world: np.ndarray,
    joints_world: Sequence[np.ndarray],
    ground: GroundFn | None = None,
    max_foot_pitch: float = np.radians(50.0),
    *,
    spine_rotation: np.ndarray | None = None,
    spine_joints: np.ndarray | None = None,
    leg_frames: np.ndarray | None = None,
    planted: np.ndarray | None = None,
) -> Generator[float, None, PoseTracks]:
    """Pose-bone channels that put the rig where the core says, frame by frame.

    body_world: ``(F, 4, 4)`` rigid body-to-world transforms (the body frame of
    :class:`BodyInfo` moved by the simulation). joints_world: per leg ``(F, k + 1, 3)``
    world joint positions (hip, inner joints, end-effector), in ``info.legs`` order.

    Each leg bone's rotation maps its rest segment onto the simulated one and its rest
    leg-plane normal onto the simulated plane's normal (no added twist; a straight leg keeps
    the body-turned rest normal). The body bone moves rigidly with the body frame; the first
    foot bone keeps its rest orientation turned by the body's heading and, when ``ground``
    is given (:data:`GroundFn`), pitches about its cross axis so its sole lies on the ground
    (toes lift onto slopes and edges, up to ``max_foot_pitch``).

    With a driven spine (:attr:`RigInfo.spine_layout`), ``spine_rotation`` ``(F, J - 1, 3, 3)``
    (``core.locomotion.spine.SpinePose.bone_rotation``: each core bone's rotation from its rest direction
    in the body frame to the world) turns the spine bones, the body bone's head goes to
    ``spine_joints[:, -1]`` (``(F, J, 3)``), and ``leg_frames`` ``(F, L, 3, 3)`` (body-to-world
    rotation each leg hangs from) turns each leg's rest knee plane and foot instead of the
    body frame.

    ``planted`` ``(F, L)``: feet on the ground; a planted foot keeps the heading it landed
    with (:func:`_held_foot_yaw`) instead of turning with what its leg hangs from.
    """
    body_world = np.asarray(body_world, dtype=np.float64)
    n_frames = body_world.shape[0]
    # Yields the fraction done after each leg and each bone (each step's work grows with the
    # frame count only: a long range shows progress and can stop between two of them).
    order = _hierarchy_order(info, info.driven_bones)  # parents before children
    n_steps = len(info.legs) + len(order) + 1
    done = 0
    delta = body_world @ affine_inverse(info.body.matrix)[None]  # (F, 4, 4) rest body -> current
    delta_rot = delta[:, :3, :3]
    body_rest_t = info.body.matrix[:3, :3].T  # world rest -> body frame
    n_legs = len(info.legs)
    if leg_frames is None:
        leg_delta = np.broadcast_to(delta_rot[:, None], (n_frames, n_legs, 3, 3))
    else:
        leg_delta = np.asarray(leg_frames, dtype=np.float64) @ body_rest_t
    leg_yaw = _yaw_only(leg_delta)
    foot_yaw = leg_yaw if planted is None else _held_foot_yaw(leg_yaw, np.asarray(planted, dtype=bool))
    spine_on = info.spine_layout is not None
    if spine_on and (spine_rotation is None or spine_joints is None):
        raise ValueError("the rig's spine is driven: give its spine_rotation and spine_joints")
    w = info.world
    w_rot = w[:3, :3] / info.scale
    w_inv = affine_inverse(w)

    # Desired world rotation (F, 3, 3) of every driven bone; world head of the body bone.
    # (of the solved bones only: a rig has many more, a Rigify metarig's face among them)
    rest_rot = {n: w_rot @ (m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0))
                for n, m in ((b, info.rest_local[b]) for b in info.driven_bones)}
    desired: dict[str, np.ndarray] = {}
    desired[info.body_bone] = delta_rot @ rest_rot[info.body_bone]
    body_head_rest = _apply(w, info.rest_local[info.body_bone][:3, 3][None])[0]
    body_head = np.einsum("fij,j->fi", delta[:, :3, :3], body_head_rest) + delta[:, :3, 3]
    spine_heads: dict[str, np.ndarray] = {}
    if spine_on:
        assert spine_rotation is not None
        assert spine_joints is not None
        turn = np.asarray(spine_rotation, dtype=np.float64) @ body_rest_t  # world rest -> now
        solved = set(info.driven_bones)
        for i, name in enumerate(info.spine[::-1]):  # core bones run from the head back
            desired[name] = turn[:, i] @ rest_rot[name]
            if info.parents[name] not in solved:
                # hung from a bone not solved (a generated rig's ORG- spine bone from its
                # tweak control): its head goes to its core joint, not along its parent
                spine_heads[name] = np.asarray(spine_joints, dtype=np.float64)[:, i + 1]
        body_head = np.asarray(spine_joints, dtype=np.float64)[:, -1]

    for k, (leg, rest_j, cur_j) in enumerate(zip(info.legs, info.joints, joints_world, strict=True)):
        cur_j = np.asarray(cur_j, dtype=np.float64)
        want = (n_frames, len(leg.bones) + 1, 3)
        if cur_j.shape != want:
            raise ValueError(f"leg {leg.label}: joints shape {cur_j.shape}, expected {want}")
        n_rest = _bend_normal(rest_j)
        if np.linalg.norm(n_rest) < 1e-9 * max(float(np.linalg.norm(np.diff(rest_j, axis=0))), 1e-9) ** 2:
            # straight rest leg: bend like a knee, about the body's left axis
            n_rest = np.cross(rest_j[-1] - rest_j[0], info.body.forward)
        n_rest = _unit(n_rest)
        n_turned = np.einsum("fij,j->fi", leg_delta[:, k], n_rest)
        n_cur = _bend_normal(cur_j)
        size = np.linalg.norm(n_cur, axis=-1)
        scale2 = np.sum(np.diff(cur_j, axis=1) ** 2, axis=(1, 2))
        weak = size < 1e-4 * scale2
        n_cur = _side_of(np.where(weak[:, None], n_turned, _unit(n_cur)), n_turned)
        # every bone of the leg at once: (k, 3, 3) at rest, (F, k, 3, 3) now
        f_rest = np.swapaxes(_frames(np.diff(rest_j, axis=0), n_rest[None]), -1, -2)
        f_cur = _frames(np.diff(cur_j, axis=1), n_cur[:, None])
        for b, name in enumerate(leg.bones):
            desired[name] = f_cur[:, b] @ f_rest[b][None] @ rest_rot[name]
        if leg.foot:
            desired[leg.foot[0]] = foot_yaw[:, k] @ rest_rot[leg.foot[0]]
        done += 1
        yield done / n_steps

    # Bones that IK constraints pull the legs to: placed where the simulated joint is,
    # turned with the body's heading.
    moved_heads: dict[str, np.ndarray] = {**spine_heads, info.body_bone: body_head}
    for k, target in enumerate(info.ik_targets):
        if target is None:
            continue
        bone, joint = target
        desired[bone] = foot_yaw[:, k] @ rest_rot[bone]
        moved_heads[bone] = np.asarray(joints_world[k], dtype=np.float64)[:, joint]

    if ground is not None:
        _pitch_feet(info, joints_world, foot_yaw, rest_rot, desired, ground, max_foot_pitch)
    done += 1
    yield done / n_steps

    bones = info.driven_bones
    # Armature-space pose matrices, parents before children.
    pose: dict[str, np.ndarray] = {}
    basis_out: dict[str, np.ndarray] = {}
    parents = (info.parents[n] for n in order)
    inv_rest = affine_inverses({p: info.rest_local[p] for p in parents if p is not None})
    for name in order:
        parent = info.parents[name]
        rest_l = info.rest_local[name]
        if parent is None:
            base = np.broadcast_to(rest_l, (n_frames, 4, 4))
        else:
            base = pose[parent] @ (inv_rest[parent] @ rest_l)[None]
        if name in desired:
            goal = np.empty((n_frames, 4, 4))
            goal[:, :3, :3] = np.swapaxes(w_rot, 0, 1)[None] @ desired[name]
            if name in moved_heads:
                goal[:, :3, 3] = _apply(w_inv, moved_heads[name])
            else:
                goal[:, :3, 3] = base[:, :3, 3]  # heads follow their parents
            goal[:, 3] = (0.0, 0.0, 0.0, 1.0)
            basis = affine_inverse(base) @ goal
            basis_out[name] = basis
            pose[name] = base @ basis
        else:
            pose[name] = base @ info.basis[name][None]
        done += 1
        yield done / n_steps

    basis_all = np.stack([basis_out[b] for b in bones], axis=1)  # (F, B, 4, 4)
    rotations = matrix_to_quaternion(nearest_rotation(basis_all[..., :3, :3]))
    locations = basis_all[..., :3, 3]
    keyed = np.array([b in moved_heads for b in bones])
    return PoseTracks(bones, rotations, locations, keyed)


#: A foot whose end-effector stays this close (a share of the leg's length) to where it
#: stood, its heading unchanged, stands still: a planted foot, held by the IK to a
#: nanometre.
HELD = 1e-9


def _stands_since(ends: np.ndarray, yaw: np.ndarray, tol: float) -> np.ndarray:
    """For each frame and foot, the frame it has stood still since ``(F, J)`` (its own when
    it moved): the same heading ``yaw`` ``(F, J, 3, 3)`` as the frame before and its
    end-effector ``ends`` ``(F, J, 3)`` within ``tol`` of where it stood then."""
    n_frames, n_feet = ends.shape[:2]
    first = np.repeat(np.arange(n_frames)[:, None], n_feet, axis=1)
    same = np.all(yaw[1:] == yaw[:-1], axis=(-2, -1)).tolist()  # (F - 1, J)
    where = ends.tolist()
    for j in range(n_feet):
        r = 0
        for f in range(1, n_frames):
            here, there = where[f][j], where[r][j]
            if same[f - 1][j] and max(abs(here[0] - there[0]), abs(here[1] - there[1]),
                                      abs(here[2] - there[2])) <= tol:
                first[f, j] = r
            else:
                r = f
    return first


def _pitch_feet(info: RigInfo, joints_world: Sequence[np.ndarray], leg_yaw: np.ndarray,
                rest_rot: dict[str, np.ndarray], desired: dict[str, np.ndarray], ground: GroundFn,
                limit: float) -> None:
    """Turn each leg's first foot bone so its sole follows the ground (see :func:`solve_pose`).
    ``leg_yaw`` ``(F, L, 3, 3)``: the heading turn of each foot (:func:`_held_foot_yaw`). Every
    foot at once: its sole points follow one another, foot after foot. On a ground that does
    not move, a foot that stands still (its heading the same and its end-effector within
    :data:`HELD` of where it stood first, as a planted foot does) keeps the pitch it had
    there: its sole is pitched once per stance, and cannot flicker on an edge it stands on."""
    dynamic = bool(getattr(ground, "dynamic", True))
    legs = [k for k, leg in enumerate(info.legs) if leg.foot and info.foot_points[k].shape[0]]
    if not legs:
        return
    n_frames = leg_yaw.shape[0]
    counts = np.array([info.foot_points[k].shape[0] for k in legs])
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    foot = np.repeat(np.arange(len(legs)), counts)  # the foot of each sole point
    ends = np.stack([np.asarray(joints_world[k], dtype=np.float64)[:, -1] for k in legs], axis=1)  # (F, J, 3)
    rest_points = np.concatenate([info.foot_points[k] - info.joints[k][-1] for k in legs])  # (P, 3)
    # (F, P, 3): each point turned with its foot's heading, a rotation about Z (written out:
    # the rotations gathered per point were a tenth of the pitch)
    cos, sin = leg_yaw[:, legs, 0, 0][:, foot], leg_yaw[:, legs, 1, 0][:, foot]
    rel = np.empty((n_frames, foot.size, 3))
    rel[..., 0] = cos * rest_points[:, 0] - sin * rest_points[:, 1]
    rel[..., 1] = sin * rest_points[:, 0] + cos * rest_points[:, 1]
    rel[..., 2] = rest_points[:, 2]
    # (over a moving ground a foot standing still may find other ground under it)
    first = (np.repeat(np.arange(n_frames)[:, None], len(legs), axis=1) if dynamic else
             _stands_since(ends, leg_yaw[:, legs], HELD * max(float(np.mean(info.leg_length)), 1e-3)))
    own = first == np.arange(n_frames)[:, None]  # (F, J) the frames a foot's pitch is found at
    chosen = np.arange(len(legs))[None]
    reach = _sole_reach(rel, starts)
    # Only the sole points ahead of each ankle limit its pitch: the others' heights are not asked.
    asked = reach[2]
    turns = np.broadcast_to(np.eye(3), (n_frames, len(legs), 3, 3))
    pitched: np.ndarray | None = None
    angles = np.zeros((n_frames, len(legs)))  # each turn's angle (the first: none)
    # How far each end-effector is above where it would stand on the ground under it.
    under = np.full((n_frames, len(legs)), np.nan)
    at = np.nonzero(own)
    under[at] = np.asarray(ground(at[0] if dynamic else np.zeros_like(at[0]), ends[at][:, :2]),
                           dtype=np.float64)
    lifts = ends[..., 2] - info.foot_height[legs][None] - under  # (F, J)
    heights = np.full(asked.shape, -np.inf)
    changed = np.ones((n_frames, len(legs)), dtype=bool)
    # Pitching moves the sole points sideways too, onto other ground: a few passes (heights
    # where the pitched points are, the pitch from the rest sole). After the first the pitch
    # only rises: a toe pitched down past an edge onto the higher ground it now stands over
    # is lifted, never pitched down again (a down-and-up swing could end inside the edge).
    axis = np.concatenate([reach[0], np.zeros((n_frames, len(legs), 1))], axis=-1)
    axis = np.cross(axis, _UP)
    axis_n = np.linalg.norm(axis, axis=-1, keepdims=True)
    axis = np.divide(axis, axis_n, out=np.zeros_like(axis), where=axis_n > 1e-12)
    for _ in range(3):
        # Heights asked again only where a foot turned since they were read (elsewhere its
        # points stand where they stood).
        ask = asked & (changed & own)[:, foot]
        at_f, at_p = np.nonzero(ask)  # (only the points asked are placed)
        at_j = foot[at_p]
        xy = ends[at_f, at_j, :2] + np.einsum("pij,pj->pi", turns[at_f, at_j, :2], rel[at_f, at_p])
        key = at_f if dynamic else np.zeros(at_f.size, dtype=np.int64)
        heights[at_f, at_p] = np.asarray(ground(key, xy), dtype=np.float64)
        theta, _d = _foot_pitch(rel, starts, ends, heights, limit, lifts, reach)
        theta = theta[first, chosen]  # a standing foot's from where it began to stand
        if pitched is not None:
            theta = np.maximum(theta, pitched)
        pitched = theta
        angle = np.where(axis_n[..., 0] > 1e-12, theta, 0.0)
        changed = angle != angles
        angles = angle
        turns = _axis_rotation(axis, angle)
    for j, k in enumerate(legs):
        name = info.legs[k].foot[0]
        desired[name] = turns[:, j] @ desired[name]


def _hierarchy_order(info: RigInfo, bones: Sequence[str]) -> list[str]:
    """``bones`` and all their ancestors, parents first."""
    needed: list[str] = []
    for b in bones:
        chain = []
        cur: str | None = b
        while cur is not None and cur not in needed and cur not in chain:
            chain.append(cur)
            cur = info.parents[cur]
        needed.extend(reversed(chain))
    depth = {}
    for b in needed:
        d = 0
        cur = info.parents[b]
        while cur is not None:
            d += 1
            cur = info.parents[cur]
        depth[b] = d
    return sorted(dict.fromkeys(needed), key=lambda b: depth[b])
