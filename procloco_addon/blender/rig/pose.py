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
from .rest import _UP, _unit, affine_inverse, nearest_rotation


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


def _sole_reach(rel: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, ...]:
    """For the sole points ``rel`` ``(F, P, 3)`` of feet (relative to each end-effector; foot
    ``j``'s points from ``starts[j]`` to the next start): each foot's forward direction ``d``
    ``(F, J, 2)``, each point's forward reach along its foot's ``a`` ``(F, P)``, which points
    are far enough ahead to limit the pitch, ``ahead`` ``(F, P)`` (points just ahead of the
    ankle and behind it never do: :data:`NEAR_SHARE`), and each point's distance from the
    end-effector in the foot's vertical plane and its angle below the forward direction
    there, ``(F, P)`` each (what :func:`_foot_pitch` reads of the sole, found once for its
    passes)."""
    d = np.add.reduceat(rel[..., :2], starts, axis=1)
    d_norm = np.linalg.norm(d, axis=-1, keepdims=True)
    d = np.divide(d, d_norm, out=np.zeros_like(d), where=d_norm > 1e-12)
    foot = np.repeat(np.arange(starts.size), np.diff(np.append(starts, rel.shape[1])))
    a = np.einsum("fpi,fpi->fp", rel[..., :2], d[:, foot])  # forward reach of each point
    reach = np.maximum.reduceat(a, starts, axis=1)
    b = rel[..., 2]
    return d, a, a > NEAR_SHARE * np.maximum(reach, 1e-12)[:, foot], np.hypot(a, b), np.arctan2(b, a)


def _foot_pitch(
    rel: np.ndarray, starts: np.ndarray, end: np.ndarray, heights: np.ndarray, limit: float,
    lift: np.ndarray | None = None, reach: tuple[np.ndarray, ...] | None = None,
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
    d, _a, ahead, radius, angle = _sole_reach(rel, starts) if reach is None else reach
    n_points = rel.shape[1]
    foot = np.repeat(np.arange(starts.size), np.diff(np.append(starts, n_points)))
    # Points just ahead of the ankle are left out: a sole pitched about the ankle swings them
    # back and barely down (the skin under an ankle would forbid any downward pitch).
    ok = ahead & np.isfinite(heights)
    # (the points that count only: the others' heights are not read)
    at = np.flatnonzero(ok)
    row, col = np.divmod(at, n_points)
    c = heights.reshape(-1).take(at) - end[..., 2].reshape(-1).take(row * starts.size + foot.take(col))
    need = np.full(heights.shape, -np.inf)
    need.reshape(-1)[at] = np.arcsin(np.clip(c / np.maximum(radius.reshape(-1).take(at), 1e-12), -1.0, 1.0)) \
        - angle.reshape(-1).take(at)
    theta = np.maximum.reduceat(need, starts, axis=1)
    theta = np.where(np.isfinite(theta), theta, 0.0)
    if lift is not None:
        fade = 0.5 * np.maximum.reduceat(np.where(ok, radius, 0.0), starts, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.clip(1.0 - np.maximum(lift, 0.0) / np.maximum(fade, 1e-12), 0.0, 1.0)
        theta = np.where(theta < 0.0, theta * np.nan_to_num(share, nan=0.0), theta)
    return np.clip(theta, -limit, limit), d


def _foot_roll(
    rel: np.ndarray, starts: np.ndarray, d: np.ndarray, heights: np.ndarray, under: np.ndarray,
    sides: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray:
    """Roll ``(F, J)`` about each foot's forward direction ``d`` ``(F, J, 2)`` (positive lifts
    its left edge) that lays its sole along the ground across its width: the slope from the
    ground under its right edge to the ground under its left, each the mean over that edge's
    sole points (``sides``: :func:`_sole_sides`) of their height ``heights`` ``(F, P)`` above
    the ground ``under`` ``(F, J)`` under the end-effector. 0 where either edge has no ground
    under it or the sole no width, and on flat ground (every height the same: exactly 0)."""
    s, left, right = sides
    n_points = rel.shape[1]
    foot = np.repeat(np.arange(starts.size), np.diff(np.append(starts, n_points)))
    with np.errstate(invalid="ignore"):  # (-inf over nothing on both: nan, left out)
        h = heights - under[:, foot]
    ok = np.isfinite(h)
    h = np.where(ok, h, 0.0)

    def mean(mask: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = np.add.reduceat((mask & ok).astype(np.float64), starts, axis=1)
        total = np.add.reduceat(np.where(mask & ok, v, 0.0), starts, axis=1)
        return np.divide(total, n, out=np.zeros_like(total), where=n > 0), n

    h_l, n_l = mean(left, h)
    h_r, n_r = mean(right, h)
    s_l, _n = mean(left, s)
    s_r, _n = mean(right, s)
    width = s_l - s_r
    good = (n_l > 0) & (n_r > 0) & (width > 1e-12) & (np.abs(d).sum(axis=-1) > 0.0)
    return np.where(good, np.arctan2(h_l - h_r, np.where(good, width, 1.0)), 0.0)


def _sole_sides(rel: np.ndarray, starts: np.ndarray,
                d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each sole point's reach to the left of its foot's long axis ``s`` ``(F, P)`` (``d``
    ``(F, J, 2)``: each foot's forward direction), and which points make the left and the
    right edge of the sole ``(F, P)`` each: those beyond :data:`NEAR_SHARE` of the sole's
    reach to that side (the points along the axis say nothing of the ground across)."""
    n_points = rel.shape[1]
    foot = np.repeat(np.arange(starts.size), np.diff(np.append(starts, n_points)))
    df = d[:, foot]
    s = rel[..., 1] * df[..., 0] - rel[..., 0] * df[..., 1]
    wide_l = np.maximum.reduceat(s, starts, axis=1)[:, foot]
    wide_r = np.maximum.reduceat(-s, starts, axis=1)[:, foot]
    return s, (s > 0.0) & (s > NEAR_SHARE * wide_l), (s < 0.0) & (-s > NEAR_SHARE * wide_r)


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

    Yields the fraction done. :func:`solve_poses_steps` solves many rigs at once.
    """
    rigs = [PoseInputs(info, body_world, tuple(joints_world), ground, spine_rotation, spine_joints,
                       leg_frames, planted)]
    return (yield from solve_poses_steps(rigs, max_foot_pitch))[0]


@dataclass(frozen=True)
class PoseInputs:
    """One rig's simulated tracks for :func:`solve_poses_steps` (each as
    :func:`solve_pose_steps` takes it)."""

    info: RigInfo
    body_world: np.ndarray  # (F, 4, 4)
    joints_world: tuple[np.ndarray, ...]  # per leg (F, k + 1, 3)
    ground: GroundFn | None = None
    spine_rotation: np.ndarray | None = None  # (F, J - 1, 3, 3)
    spine_joints: np.ndarray | None = None  # (F, J, 3)
    leg_frames: np.ndarray | None = None  # (F, L, 3, 3)
    planted: np.ndarray | None = None  # (F, L)


def _shape_of(rig: PoseInputs) -> tuple[object, ...]:
    """What rigs solved together share: their bones, legs, feet, spine and controls, how many
    sole points each foot has, their frame count, their ground (the same function) and which
    of the optional tracks they have."""
    info = rig.info
    order = _hierarchy_order(info, info.driven_bones)
    return (info.legs, info.body_bone, info.spine, info.spine_layout is not None, info.ik_targets,
            info.foot_ik_targets, tuple((n, info.parents[n]) for n in order),
            tuple(p.shape[0] for p in info.foot_points),
            int(np.shape(rig.body_world)[0]), id(rig.ground), rig.leg_frames is None, rig.planted is None)


#: Rigs solved in one pass at most: the arrays of a pass grow with the rigs times the frames,
#: and past a few rigs they no longer stay in the processor's caches (8 wolves of 120 frames
#: solve in 0.8 of the time 8 passes take; 32 in no less).
_GROUP = 8


def solve_poses_steps(rigs: Sequence[PoseInputs], max_foot_pitch: float = np.radians(50.0),
                      ) -> Generator[float, None, list[PoseTracks]]:
    """:func:`solve_pose_steps` for every rig of ``rigs``, in its order: the rigs of one shape
    (the same bones, legs and feet, frame count and ground: copies of a creature) are solved
    together, their arrays stacked along a leading axis of rigs, in one pass of array
    operations for up to :data:`_GROUP` of them (their feet's ground asked together). Each
    rig's pose is its own: the same as solved alone, but for the last bit of a few values.
    Yields the fraction done."""
    groups: dict[tuple[object, ...], list[int]] = {}
    for i, rig in enumerate(rigs):
        groups.setdefault(_shape_of(rig), []).append(i)
    chunks = [idx[s:s + _GROUP] for idx in groups.values() for s in range(0, len(idx), _GROUP)]
    out: list[PoseTracks | None] = [None] * len(rigs)
    done = 0
    for chunk in chunks:
        steps = _solve_group([rigs[i] for i in chunk], max_foot_pitch)
        while True:
            try:
                fraction = next(steps)
            except StopIteration as finished:
                for i, tracks in zip(chunk, finished.value, strict=True):
                    out[i] = tracks
                break
            yield (done + fraction * len(chunk)) / len(rigs)
        done += len(chunk)
    return [t for t in out if t is not None]


def _stacked(arrays: Sequence[np.ndarray]) -> np.ndarray:
    return np.stack([np.asarray(a, dtype=np.float64) for a in arrays])


def _solve_group(rigs: Sequence[PoseInputs], max_foot_pitch: float,
                 ) -> Generator[float, None, list[PoseTracks]]:
    """:func:`solve_poses_steps` for rigs of one shape: every array ``(R, F, ...)``, rig by rig."""
    infos = [rig.info for rig in rigs]
    info = infos[0]  # (the names, legs and hierarchy of every rig of the group)
    n_rigs = len(rigs)
    body_world = _stacked([rig.body_world for rig in rigs])  # (R, F, 4, 4)
    n_frames = body_world.shape[1]
    # Yields the fraction done after each leg and each bone (each step's work grows with the
    # frame count only: a long range shows progress and can stop between two of them).
    order = _hierarchy_order(info, info.driven_bones)  # parents before children
    n_steps = len(info.legs) + len(order) + 1
    done = 0
    body_rest = _stacked([i.body.matrix for i in infos])  # (R, 4, 4)
    delta = body_world @ affine_inverse(body_rest)[:, None]  # (R, F, 4, 4) rest body -> current
    delta_rot = delta[..., :3, :3]
    body_rest_t = np.swapaxes(body_rest[:, :3, :3], -1, -2)  # world rest -> body frame
    n_legs = len(info.legs)
    if rigs[0].leg_frames is None:
        leg_delta = np.broadcast_to(delta_rot[:, :, None], (n_rigs, n_frames, n_legs, 3, 3))
    else:
        leg_delta = _stacked([rig.leg_frames for rig in rigs]) @ body_rest_t[:, None, None]  # type: ignore[misc]
    leg_yaw = _yaw_only(leg_delta)  # (R, F, L, 3, 3)
    planted = None if rigs[0].planted is None else np.stack([np.asarray(rig.planted, dtype=bool)
                                                             for rig in rigs])  # (R, F, L)
    foot_yaw = leg_yaw if planted is None else np.stack(
        [_held_foot_yaw(leg_yaw[r], planted[r]) for r in range(n_rigs)])
    spine_on = info.spine_layout is not None
    if spine_on and any(rig.spine_rotation is None or rig.spine_joints is None for rig in rigs):
        raise ValueError("the rig's spine is driven: give its spine_rotation and spine_joints")
    w = _stacked([i.world for i in infos])  # (R, 4, 4)
    w_rot = w[:, :3, :3] / np.array([i.scale for i in infos])[:, None, None]
    w_inv = affine_inverse(w)

    def per_rig(name: str) -> np.ndarray:
        """Every rig's armature rest matrix of bone ``name`` ``(R, 4, 4)``."""
        return _stacked([i.rest_local[name] for i in infos])

    def posed_rest(name: str) -> np.ndarray:
        """:func:`per_rig` with the pose of the bones above it that are not solved
        (``RigInfo.rest_posed``): where the walk's joints were read."""
        return _stacked([i.rest_posed.get(name, i.rest_local[name]) for i in infos])

    # Desired world rotation (R, F, 3, 3) of every driven bone; world head of the body bone.
    # (of the solved bones only: a rig has many more, a Rigify metarig's face among them)
    rest_rot = {}
    for bone in info.driven_bones:
        m = posed_rest(bone)[:, :3, :3]
        rest_rot[bone] = (w_rot @ (m / np.linalg.norm(m, axis=-2, keepdims=True)))[:, None]  # (R, 1, 3, 3)
    desired: dict[str, np.ndarray] = {}
    desired[info.body_bone] = delta_rot @ rest_rot[info.body_bone]
    body_head_rest = np.einsum("rij,rj->ri", w[:, :3, :3], posed_rest(info.body_bone)[:, :3, 3]) + w[:, :3, 3]
    body_head = np.einsum("rfij,rj->rfi", delta_rot, body_head_rest) + delta[..., :3, 3]
    spine_heads: dict[str, np.ndarray] = {}
    if spine_on:
        spine_joints = _stacked([rig.spine_joints for rig in rigs])  # type: ignore[misc]
        turn = _stacked([rig.spine_rotation for rig in rigs]) @ body_rest_t[:, None, None]  # type: ignore[misc]
        solved = set(info.driven_bones)
        for i, name in enumerate(info.spine[::-1]):  # core bones run from the head back
            desired[name] = turn[:, :, i] @ rest_rot[name]
            if info.parents[name] not in solved:
                # hung from a bone not solved (a generated rig's ORG- spine bone from its
                # tweak control): its head goes to its core joint, not along its parent
                spine_heads[name] = spine_joints[:, :, i + 1]
        body_head = spine_joints[:, :, -1]

    # per leg (R, F, k + 1, 3)
    joints_world = [_stacked([rig.joints_world[k] for rig in rigs]) for k in range(n_legs)]
    for k, leg in enumerate(info.legs):
        cur_j = joints_world[k]
        want = (n_frames, len(leg.bones) + 1, 3)
        if cur_j.shape[1:] != want:
            raise ValueError(f"leg {leg.label}: joints shape {cur_j.shape[1:]}, expected {want}")
        rest_j = _stacked([i.joints[k] for i in infos])  # (R, k + 1, 3)
        n_rest = _bend_normal(rest_j)  # (R, 3)
        for r, one in enumerate(infos):
            length = max(float(np.linalg.norm(np.diff(rest_j[r], axis=0))), 1e-9)
            if np.linalg.norm(n_rest[r]) < 1e-9 * length ** 2:
                # straight rest leg: bend like a knee, about the body's left axis
                n_rest[r] = np.cross(rest_j[r, -1] - rest_j[r, 0], one.body.forward)
        n_rest = _unit(n_rest)
        n_turned = np.einsum("rfij,rj->rfi", leg_delta[:, :, k], n_rest)  # (R, F, 3)
        n_cur = _bend_normal(cur_j)
        size = np.linalg.norm(n_cur, axis=-1)
        scale2 = np.sum(np.diff(cur_j, axis=-2) ** 2, axis=(-2, -1))
        weak = size < 1e-4 * scale2
        n_cur = np.where(weak[..., None], n_turned, _unit(n_cur))
        n_cur = np.stack([_side_of(n_cur[r], n_turned[r]) for r in range(n_rigs)])
        # every bone of the leg at once: (R, k, 3, 3) at rest, (R, F, k, 3, 3) now
        f_rest = np.swapaxes(_frames(np.diff(rest_j, axis=-2), n_rest[:, None]), -1, -2)
        f_cur = _frames(np.diff(cur_j, axis=-2), n_cur[:, :, None])
        for b, name in enumerate(leg.bones):
            desired[name] = f_cur[:, :, b] @ f_rest[:, None, b] @ rest_rot[name]
        if leg.foot:
            desired[leg.foot[0]] = foot_yaw[:, :, k] @ rest_rot[leg.foot[0]]
        done += 1
        yield done / n_steps

    # Bones that IK constraints pull the legs to: placed where the simulated joint is,
    # turned with the body's heading.
    moved_heads: dict[str, np.ndarray] = {**spine_heads, info.body_bone: body_head}
    for k, target in enumerate(info.ik_targets):
        if target is None:
            continue
        bone, joint = target
        desired[bone] = foot_yaw[:, :, k] @ rest_rot[bone]
        moved_heads[bone] = joints_world[k][:, :, joint]
    # Bones that IK constraints aim the feet at: carried with the solved foot (below).
    foot_carried = {t: leg.foot[0] for t, leg in zip(info.foot_ik_targets, info.legs, strict=False)
                    if t is not None}

    ground = rigs[0].ground
    if ground is not None:
        _pitch_feet(infos, joints_world, foot_yaw, desired, ground, max_foot_pitch, planted)
    # A leg's IK target that carries the bone its foot is aimed at (MMD's 左足ＩＫ > 左つま先ＩＫ,
    # connected: the toe IK's head is the leg IK's tail) turns with the whole foot, pitch
    # included (the leg's IK reads only its head).
    aimed_at = info.foot_ik_targets or (None,) * n_legs
    for target, leg, aim in zip(info.ik_targets, info.legs, aimed_at, strict=True):
        if target is not None and target[0] in _ancestors(info, aim):
            foot = leg.foot[0]
            desired[target[0]] = desired[foot] @ np.swapaxes(rest_rot[foot], -1, -2) @ rest_rot[target[0]]
    done += 1
    yield done / n_steps

    bones = info.driven_bones
    # Armature-space pose matrices, parents before children.
    pose: dict[str, np.ndarray] = {}
    basis_out: dict[str, np.ndarray] = {}
    inv_rest = {p: affine_inverse(per_rig(p)) for p in dict.fromkeys(info.parents[n] for n in order)
                if p is not None}
    w_rot_t = np.swapaxes(w_rot, -1, -2)[:, None]  # (R, 1, 3, 3)
    for name in order:
        parent = info.parents[name]
        rest_l = per_rig(name)
        if parent is None:
            base = np.broadcast_to(rest_l[:, None], (n_rigs, n_frames, 4, 4))
        else:
            base = pose[parent] @ (inv_rest[parent] @ rest_l)[:, None]
        if name in foot_carried:
            foot = foot_carried[name]
            goal = pose[foot] @ (affine_inverse(per_rig(foot)) @ rest_l)[:, None]
            basis = affine_inverse(base) @ goal
            basis_out[name] = basis
            pose[name] = goal
        elif name in desired:
            goal = np.empty((n_rigs, n_frames, 4, 4))
            goal[..., :3, :3] = w_rot_t @ desired[name]
            if name in moved_heads:
                goal[..., :3, 3] = np.einsum("rij,rfj->rfi", w_inv[:, :3, :3], moved_heads[name]) \
                    + w_inv[:, None, :3, 3]
            else:
                goal[..., :3, 3] = base[..., :3, 3]  # heads follow their parents
            goal[..., 3, :] = (0.0, 0.0, 0.0, 1.0)
            basis = affine_inverse(base) @ goal
            basis_out[name] = basis
            pose[name] = base @ basis
        else:
            pose[name] = base @ _stacked([i.basis[name] for i in infos])[:, None]
        done += 1
        yield done / n_steps

    basis_all = np.stack([basis_out[b] for b in bones], axis=2)  # (R, F, B, 4, 4)
    rotations = matrix_to_quaternion(nearest_rotation(basis_all[..., :3, :3]))
    locations = basis_all[..., :3, 3]
    keyed = np.array([b in moved_heads or b in foot_carried for b in bones])
    return [PoseTracks(bones, rotations[r], locations[r], keyed) for r in range(n_rigs)]


#: A foot whose end-effector stays this close (a share of the leg's length) to where it
#: stood, its heading unchanged, stands still: a planted foot, held by the IK to a
#: nanometre.
HELD = 1e-9


def _stands_since(ends: np.ndarray, yaw: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """For each rig, frame and foot, the frame it has stood still since ``(R, F, J)`` (its
    own when it moved): the same heading ``yaw`` ``(R, F, J, 3, 3)`` as the frame before and
    its end-effector ``ends`` ``(R, F, J, 3)`` within its rig's ``tol`` ``(R,)`` of where it
    stood then. Frame by frame, every foot of every rig at once."""
    n_rigs, n_frames, n_feet = ends.shape[:3]
    first = np.empty((n_rigs, n_frames, n_feet), dtype=np.int64)
    first[:, 0] = 0
    if n_frames < 2:
        return first
    same = np.all(yaw[:, 1:] == yaw[:, :-1], axis=(-2, -1))  # (R, F - 1, J)
    lanes = ends.reshape(n_rigs * n_frames * n_feet, 3)
    lane = (np.arange(n_rigs)[:, None] * n_frames * n_feet + np.arange(n_feet)[None]).reshape(-1)
    r = np.zeros(n_rigs * n_feet, dtype=np.int64)  # each foot's frame it stands since
    tol_lane = np.repeat(np.asarray(tol, dtype=np.float64), n_feet)
    for f in range(1, n_frames):
        here = lanes.take(lane + f * n_feet, axis=0)
        there = lanes.take(lane + r * n_feet, axis=0)
        stay = same[:, f - 1].reshape(-1) & (np.abs(here - there).max(axis=-1) <= tol_lane)
        r = np.where(stay, r, f)
        first[:, f] = r.reshape(n_rigs, n_feet)
    return first


#: Points asked of the ground at once at most: each point's height is its own, and a point
#: query's work per point grows with the points asked together (their candidate triangles
#: leave the processor's caches): on the bench ground, 0.83 us a point in runs of 1024,
#: 1.09 in runs of 4096, 1.76 in one run of 65536.
_GROUND_RUN = 1024


def _ground_in_runs(ground: GroundFn, frame_index: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """``ground(frame_index, xy)`` ``(n,)``, asked :data:`_GROUND_RUN` points at a time."""
    if xy.shape[0] <= _GROUND_RUN:
        return np.asarray(ground(frame_index, xy), dtype=np.float64)
    return np.concatenate([np.asarray(ground(frame_index[s:s + _GROUND_RUN], xy[s:s + _GROUND_RUN]),
                                      dtype=np.float64) for s in range(0, xy.shape[0], _GROUND_RUN)])


def _pitch_feet(infos: Sequence[RigInfo], joints_world: Sequence[np.ndarray], leg_yaw: np.ndarray,
                desired: dict[str, np.ndarray], ground: GroundFn, limit: float,
                planted: np.ndarray | None = None) -> None:
    """Turn each leg's first foot bone so its sole follows the ground (see :func:`solve_pose`),
    for rigs of one shape (:func:`solve_poses_steps`). ``joints_world``: per leg
    ``(R, F, k + 1, 3)``; ``leg_yaw`` ``(R, F, L, 3, 3)``: the heading turn of each foot
    (:func:`_held_foot_yaw`). Every foot of every rig at once, the rigs' frames one after the
    other: a foot's sole points follow one another, foot after foot. On a ground that does
    not move, a foot that stands still (its heading the same and its end-effector within
    :data:`HELD` of where it stood first, as a planted foot does) keeps the pitch it had
    there: its sole is pitched once per stance, and cannot flicker on an edge it stands on.
    ``planted`` ``(R, F, L)``: the feet the walk plants; their soles are pitched down to the
    ground in full however high their end-effectors stand (a footprint may stand a little
    above the ground under its ankle, the planner's height under its sole where the
    controller did not snap it: only a lifted foot's downward pitch fades)."""
    dynamic = bool(getattr(ground, "dynamic", True))
    info = infos[0]
    legs = [k for k, leg in enumerate(info.legs) if leg.foot and info.foot_points[k].shape[0]]
    if not legs:
        return
    n_rigs, n_frames = leg_yaw.shape[:2]
    n_all = n_rigs * n_frames  # every rig's frames, one rig after the other
    counts = np.array([info.foot_points[k].shape[0] for k in legs])
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    foot = np.repeat(np.arange(len(legs)), counts)  # the foot of each sole point
    ends = np.stack([joints_world[k][:, :, -1] for k in legs], axis=2).reshape(n_all, len(legs), 3)
    yaw = leg_yaw[:, :, legs].reshape(n_all, len(legs), 3, 3)
    rest_points = _stacked([np.concatenate([i.foot_points[k] - i.joints[k][-1] for k in legs])
                            for i in infos])  # (R, P, 3)
    rest_points = np.repeat(rest_points, n_frames, axis=0)  # (R F, P, 3)
    # (R F, P, 3): each point turned with its foot's heading, a rotation about Z (written
    # out: the rotations gathered per point were a tenth of the pitch)
    cos, sin = yaw[:, :, 0, 0][:, foot], yaw[:, :, 1, 0][:, foot]
    rel = np.empty((n_all, foot.size, 3))
    rel[..., 0] = cos * rest_points[..., 0] - sin * rest_points[..., 1]
    rel[..., 1] = sin * rest_points[..., 0] + cos * rest_points[..., 1]
    rel[..., 2] = rest_points[..., 2]
    frame = np.arange(n_all) % n_frames  # each row's frame index in its rig's range
    # (over a moving ground a foot standing still may find other ground under it)
    own_row = np.repeat(np.arange(n_all)[:, None], len(legs), axis=1)
    if dynamic:
        first = own_row
    else:
        tol = np.array([HELD * max(float(np.mean(one.leg_length)), 1e-3) for one in infos])
        since = _stands_since(ends.reshape(n_rigs, n_frames, len(legs), 3),
                              yaw.reshape(n_rigs, n_frames, len(legs), 3, 3), tol)
        first = (since + (np.arange(n_rigs) * n_frames)[:, None, None]).reshape(n_all, len(legs))
    own = first == own_row  # (R F, J) the rows a foot's pitch is found at
    chosen = np.arange(len(legs))[None]
    reach = _sole_reach(rel, starts)
    # Only the sole points ahead of each ankle limit its pitch: the others' heights are not asked.
    asked = reach[2]
    turns = np.broadcast_to(np.eye(3), (n_all, len(legs), 3, 3))
    pitched: np.ndarray | None = None
    angles = np.zeros((n_all, len(legs)))  # each turn's angle (the first: none)
    # How far each end-effector is above where it would stand on the ground under it.
    under = np.full((n_all, len(legs)), np.nan)
    at = np.nonzero(own)
    under[at] = _ground_in_runs(ground, frame[at[0]] if dynamic else np.zeros_like(at[0]), ends[at][:, :2])
    foot_height = np.repeat(_stacked([i.foot_height[legs] for i in infos]), n_frames, axis=0)  # (R F, J)
    lifts = ends[..., 2] - foot_height - under  # (R F, J)
    if planted is not None:
        lifts = np.where(planted[:, :, legs].reshape(n_all, len(legs)), 0.0, lifts)
    # Roll each foot about its long axis to the ground across its sole (once, from where its
    # sole points stand unturned; a standing foot keeps the roll it landed with, a lifted
    # one's fades as its downward pitch does), then pitch the rolled sole.
    rolls = _roll_feet(ground, rel, starts, ends, reach, under, lifts, own, first, frame, dynamic, limit)
    if rolls is not None:
        rel = np.einsum("fpij,fpj->fpi", rolls[:, foot], rel)
        reach = _sole_reach(rel, starts)
        asked = reach[2]
    heights = np.full(asked.shape, -np.inf)
    changed = np.ones((n_all, len(legs)), dtype=bool)
    # Pitching moves the sole points sideways too, onto other ground: a few passes (heights
    # where the pitched points are, the pitch from the rest sole). After the first the pitch
    # only rises: a toe pitched down past an edge onto the higher ground it now stands over
    # is lifted, never pitched down again (a down-and-up swing could end inside the edge).
    axis = np.concatenate([reach[0], np.zeros((n_all, len(legs), 1))], axis=-1)
    axis = np.cross(axis, _UP)
    axis_n = np.linalg.norm(axis, axis=-1, keepdims=True)
    axis = np.divide(axis, axis_n, out=np.zeros_like(axis), where=axis_n > 1e-12)
    for _ in range(3):
        # Heights asked again only where a foot turned since they were read (elsewhere its
        # points stand where they stood).
        ask = asked & (changed & own)[:, foot]
        where = np.flatnonzero(ask)  # (only the points asked are placed)
        at_f, at_p = np.divmod(where, foot.size)
        at_j = foot.take(at_p)
        row = at_f * len(legs) + at_j  # (the rows of each point's foot gathered with take: faster)
        xy = np.reshape(turns, (-1, 3, 3))[:, :2].take(row, axis=0)
        xy = np.einsum("pij,pj->pi", xy, rel.reshape(-1, 3).take(where, axis=0))
        xy += ends.reshape(-1, 3)[:, :2].take(row, axis=0)
        key = frame.take(at_f) if dynamic else np.zeros(at_f.size, dtype=np.int64)
        heights.reshape(-1)[where] = _ground_in_runs(ground, key, xy)
        theta, _d = _foot_pitch(rel, starts, ends, heights, limit, lifts, reach)
        theta = theta[first, chosen]  # a standing foot's from where it began to stand
        if pitched is not None:
            theta = np.maximum(theta, pitched)
        pitched = theta
        angle = np.where(axis_n[..., 0] > 1e-12, theta, 0.0)
        changed = angle != angles
        angles = angle
        turns = _axis_rotation(axis, angle)
    if rolls is not None:
        turns = turns @ rolls
    turns = turns.reshape(n_rigs, n_frames, len(legs), 3, 3)
    for j, k in enumerate(legs):
        name = info.legs[k].foot[0]
        desired[name] = turns[:, :, j] @ desired[name]


def _roll_feet(ground: GroundFn, rel: np.ndarray, starts: np.ndarray, ends: np.ndarray,
               reach: tuple[np.ndarray, ...], under: np.ndarray, lifts: np.ndarray, own: np.ndarray,
               first: np.ndarray, frame: np.ndarray, dynamic: bool, limit: float) -> np.ndarray | None:
    """The roll turns ``(F, J, 3, 3)`` of the feet of :func:`_pitch_feet` (its arrays, rows
    every rig's frames), about each foot's forward direction (:func:`_foot_roll`), within
    ``limit``; None where no foot rolls (flat ground: the feet as the pitch alone sets them).
    Only the edge points of the feet that begin to stand at a row are asked of the ground."""
    n_all, n_feet = own.shape
    n_points = rel.shape[1]
    foot = np.repeat(np.arange(n_feet), np.diff(np.append(starts, n_points)))
    d = reach[0]
    sides = _sole_sides(rel, starts, d)
    where = np.flatnonzero((sides[1] | sides[2]) & own[:, foot])
    if where.size == 0:
        return None
    at_f, at_p = np.divmod(where, n_points)
    xy = rel.reshape(-1, 3)[:, :2].take(where, axis=0) \
        + ends.reshape(-1, 3)[:, :2].take(at_f * n_feet + foot.take(at_p), axis=0)
    key = frame.take(at_f) if dynamic else np.zeros(at_f.size, dtype=np.int64)
    heights = np.full(sides[0].shape, -np.inf)
    heights.reshape(-1)[where] = _ground_in_runs(ground, key, xy)
    roll = _foot_roll(rel, starts, d, heights, np.where(own, under, np.nan), sides)
    # a lifted foot's roll fades out as it rises by half its length (its downward pitch's fade)
    fade = 0.5 * np.maximum.reduceat(np.where(reach[2], reach[3], 0.0), starts, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.clip(1.0 - np.maximum(lifts, 0.0) / np.maximum(fade, 1e-12), 0.0, 1.0)
    roll = np.clip(roll * np.nan_to_num(share, nan=0.0), -limit, limit)
    roll = roll[first, np.arange(n_feet)[None]]  # a standing foot's from where it began to stand
    if not np.any(roll):
        return None
    axis = np.concatenate([d, np.zeros((n_all, n_feet, 1))], axis=-1)
    return _axis_rotation(axis, roll)


def _ancestors(info: RigInfo, name: str | None) -> list[str]:
    """The ancestors of bone ``name`` (none for None), its parent first."""
    out: list[str] = []
    cur = info.parents[name] if name is not None else None
    while cur is not None:
        out.append(cur)
        cur = info.parents[cur]
    return out


def _hierarchy_order(info: RigInfo, bones: Sequence[str]) -> list[str]:
    """``bones`` and all their ancestors, parents first; the bones IK constraints aim the
    feet at (``RigInfo.foot_ik_targets``, carried with the solved feet) and their
    descendants after every other bone."""
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
    targets = {t for t in info.foot_ik_targets if t is not None}
    late = {b for b in needed if targets.intersection([b, *_ancestors(info, b)])} if targets else set()
    return sorted(dict.fromkeys(needed), key=lambda b: (b in late, depth[b]))
