# SPDX-License-Identifier: GPL-3.0-or-later
"""Animation clips of a biped, their roles and their foot contacts.

A clip is what the animator gives the planner: per frame the *root* (the character's ground
frame: a position and a yaw, carrying the clip's travel), the pelvis position in that frame,
and every joint's local rotation on a :class:`~.skeleton.Skeleton`. Each clip has a role tag
(walk forward, walk left, run right, jump, ...) and per-frame foot contacts, either given or
detected from the feet's speed and height (:func:`detect_contacts`).

Clips the planner chains (walk, run and jump roles) must be in *normal form*: they start at
a right-foot touchdown and end at the next one (one stride), as in the thesis' navigation
graph where an edge maps one right footprint to the next (§3.2). :func:`extract_cycle`
cuts such a stride out of a longer recording. ``START`` begins standing and ends at a
right-foot touchdown; ``STOP`` begins at a right-foot touchdown and ends standing.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

from . import quat
from .skeleton import Skeleton, foot_points, forward_kinematics, to_world

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


class ClipRole(StrEnum):
    """What a clip does; the planner picks clips by role."""

    IDLE = "IDLE"
    START = "START"
    STOP = "STOP"
    WALK_FORWARD = "WALK_FORWARD"
    WALK_LEFT = "WALK_LEFT"
    WALK_LEFT_WIDE = "WALK_LEFT_WIDE"
    WALK_RIGHT = "WALK_RIGHT"
    WALK_RIGHT_WIDE = "WALK_RIGHT_WIDE"
    RUN_FORWARD = "RUN_FORWARD"
    RUN_LEFT = "RUN_LEFT"
    RUN_RIGHT = "RUN_RIGHT"
    JUMP = "JUMP"

    @property
    def family(self) -> str:
        """``"walk"``, ``"run"``, ``"jump"``, ``"start"``, ``"stop"`` or ``"idle"``."""
        return self.value.split("_")[0].lower()

    @property
    def is_locomotion(self) -> bool:
        """Walk, run and jump clips: the edges of the footprint graph."""
        return self.family in ("walk", "run", "jump")

    @property
    def is_running(self) -> bool:
        """The character runs at the clip's ends (the speed blend parameter s = 1, §3.7.2)."""
        return self.family in ("run", "jump")


@dataclass(frozen=True)
class Clip:
    """One animation clip.

    ``root_pos (n, 3)`` and ``root_yaw (n,)``: the ground frame of the character per frame;
    ``pelvis_pos (n, 3)``: the pelvis in that frame; ``joint_rot (n, J, 4)``: local joint
    rotations (see :mod:`.skeleton`); ``contacts (n, 2)``: left/right foot on the ground, or
    ``None`` to detect them. ``dt`` is the time between frames in seconds.
    """

    name: str
    role: ClipRole
    dt: float
    root_pos: FloatArray
    root_yaw: FloatArray
    pelvis_pos: FloatArray
    joint_rot: FloatArray
    contacts: BoolArray | None = None

    def __post_init__(self) -> None:
        n = len(self.root_yaw)
        if n < 3:
            raise ValueError(f"clip {self.name!r} needs at least 3 frames")
        if not self.dt > 0.0:
            raise ValueError(f"clip {self.name!r}: dt must be positive")
        if self.root_pos.shape != (n, 3) or self.pelvis_pos.shape != (n, 3) or self.joint_rot.shape[0] != n:
            raise ValueError(f"clip {self.name!r}: per-frame arrays must all have {n} frames")
        if self.contacts is not None and np.asarray(self.contacts).shape != (n, 2):
            raise ValueError(f"clip {self.name!r}: contacts must be ({n}, 2)")

    @property
    def n_frames(self) -> int:
        return len(self.root_yaw)

    @property
    def duration(self) -> float:
        return (self.n_frames - 1) * self.dt

    def foot_points_world(self, skeleton: Skeleton) -> FloatArray:
        """Heel and toe of both feet in the clip's world, ``(n, 2, 2, 3)``."""
        pos, _ = forward_kinematics(skeleton, self.joint_rot, self.pelvis_pos)
        return to_world(self.root_pos, self.root_yaw, foot_points(skeleton, pos))


def detect_contacts(
    points: FloatArray,
    dt: float,
    ground_z: float | None = None,
    height_tol: float = 0.03,
    speed_tol: float = 0.3,
    min_frames: int = 2,
) -> BoolArray:
    """Foot contacts from the motion of the feet's contact points.

    ``points`` is ``(n, 2 feet, P points, 3)`` in the world (heel and toe, say). A foot is on
    the ground in a frame when one of its points is within ``height_tol`` of the ground and
    moves slower than ``speed_tol`` m/s. The ground is ``ground_z``, or the lowest height any
    point of that foot reaches in the clip. Runs shorter than ``min_frames`` (contact or not)
    are merged into their neighbours, which removes flicker. Returns ``(n, 2)`` booleans.
    """
    n = points.shape[0]
    vel = np.gradient(points, dt, axis=0)
    speed = np.linalg.norm(vel, axis=-1)
    z = points[..., 2]
    ground = np.full(2, ground_z) if ground_z is not None else z.min(axis=(0, 2))
    low = z - ground[None, :, None] <= height_tol
    slow = speed <= speed_tol
    contact = np.any(low & slow, axis=-1)
    for foot in range(2):
        contact[:, foot] = _remove_short_runs(contact[:, foot], min_frames)
    assert contact.shape == (n, 2)
    return contact


def _remove_short_runs(flags: BoolArray, min_frames: int) -> BoolArray:
    out = flags.copy()
    if min_frames <= 1:
        return out
    for value in (True, False):
        starts, ends = _runs(out == value)
        for s, e in zip(starts, ends, strict=True):
            if e - s < min_frames and s > 0 and e < len(out):
                out[s:e] = not value
    return out


def _runs(flags: BoolArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Start (inclusive) and end (exclusive) indices of the runs of True."""
    d = np.diff(np.concatenate(([0], flags.astype(np.int8), [0])))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def contact_runs(flags: BoolArray) -> list[tuple[int, int]]:
    """Runs of True as ``(first, last)`` inclusive frame indices."""
    s, e = _runs(np.asarray(flags, dtype=bool))
    return [(int(a), int(b) - 1) for a, b in zip(s, e, strict=True)]


def extract_cycle(clip: Clip, skeleton: Skeleton, role: ClipRole | None = None) -> Clip:
    """The first stride of a recording in normal form: right touchdown to right touchdown.

    The root is re-based so that the first frame is the clip's origin. Raises ``ValueError``
    when the recording holds no complete stride of the right foot.
    """
    contacts = (
        clip.contacts
        if clip.contacts is not None
        else detect_contacts(clip.foot_points_world(skeleton), clip.dt)
    )
    right = np.asarray(contacts[:, 1], dtype=bool)
    touchdowns = np.flatnonzero(right[1:] & ~right[:-1]) + 1
    if len(touchdowns) < 2:
        raise ValueError(f"clip {clip.name!r} holds no complete right-foot stride")
    a, b = int(touchdowns[0]), int(touchdowns[1])
    sl = slice(a, b + 1)
    pos0, yaw0 = clip.root_pos[a], clip.root_yaw[a]
    root_pos, root_yaw = quat.relative2(pos0, yaw0, clip.root_pos[sl], clip.root_yaw[sl])
    root_yaw = np.unwrap(root_yaw)
    return Clip(
        name=clip.name,
        role=role if role is not None else clip.role,
        dt=clip.dt,
        root_pos=root_pos,
        root_yaw=root_yaw,
        pelvis_pos=clip.pelvis_pos[sl].copy(),
        joint_rot=clip.joint_rot[sl].copy(),
        contacts=np.asarray(contacts[sl], dtype=bool).copy(),
    )


def root_from_pelvis(
    pelvis_world: FloatArray,
    pelvis_rot_world: FloatArray,
    dt: float,
    window: float = 0.5,
    periodic: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """A ground root trajectory for a recorded clip that has none.

    The root follows the pelvis projected on the ground, low-passed by a centred moving
    average of ``window`` seconds (which removes the side-to-side sway of a walk), with the
    pelvis' own heading likewise smoothed. Returns ``(root_pos (n, 3), root_yaw (n,))``
    with the root at height 0; :func:`recorded_clip` puts it on the ground under the feet.

    ``periodic``: the recording is one cycle of a looping motion (its last frame is its
    first one moved by the cycle's travel and turn). The average then reaches past the ends
    into the previous and next cycles, so that the root — and every pose taken relative to
    it — ends the cycle exactly as it began it, moved by the cycle. Padding the ends with
    copies of the end frames instead would drag the root at both ends, and the feet of one
    stride would jump at every join of the loop. Otherwise the ends are extended by point
    reflection (``2 p_end - p``), which continues the motion at its end speed: a clip that
    ends walking (a start) keeps its root under the walking pelvis up to its last frame.
    """
    n = len(pelvis_world)
    k = max(1, round(window / dt) | 1)
    pad = k // 2
    yaw = np.unwrap(quat.yaw_of(pelvis_rot_world))
    xy = pelvis_world[:, :2]
    if periodic and n > 2 and pad > 0:
        # The cycle transform maps frame 0's ground pose onto frame n-1's.
        turn = float(yaw[-1] - yaw[0])
        d = min(pad, n - 2)
        before = quat.rot2(-turn, xy[n - 1 - d : n - 1] - xy[-1]) + xy[0]
        after = quat.rot2(turn, xy[1 : d + 1] - xy[0]) + xy[-1]
        xy_p = np.concatenate((before, xy, after))
        yaw_p = np.concatenate((yaw[n - 1 - d : n - 1] - turn, yaw, yaw[1 : d + 1] + turn))
        xy_p = np.pad(xy_p, ((pad - d, pad - d), (0, 0)), mode="reflect", reflect_type="odd")
        yaw_p = np.pad(yaw_p, (pad - d, pad - d), mode="reflect", reflect_type="odd")
    else:
        xy_p = np.pad(xy, ((pad, pad), (0, 0)), mode="reflect", reflect_type="odd")
        yaw_p = np.pad(yaw, (pad, pad), mode="reflect", reflect_type="odd")
    kernel = np.ones(k) / k
    sx = np.convolve(xy_p[:, 0], kernel, mode="valid")
    sy = np.convolve(xy_p[:, 1], kernel, mode="valid")
    syaw = np.convolve(yaw_p, kernel, mode="valid")
    root = np.column_stack((sx[:n], sy[:n], np.zeros(n)))
    return root, syaw[:n]


def recorded_clip(
    name: str,
    role: ClipRole,
    skeleton: Skeleton,
    dt: float,
    pelvis_world: FloatArray,
    joint_rot_world_pelvis: FloatArray,
    joint_rot: FloatArray,
    contacts: BoolArray | None = None,
    periodic: bool = False,
) -> Clip:
    """A clip from a recording in world space (e.g. an Action read from Blender).

    ``pelvis_world (n, 3)`` and ``joint_rot_world_pelvis (n, 4)`` are the pelvis' world
    position and rotation; ``joint_rot (n, J, 4)`` the local rotations of the other joints
    (index 0 is replaced by the pelvis rotation relative to the new root). The root is
    derived with :func:`root_from_pelvis` (``periodic``: the recording is one loop of a
    walk or run), at the height of the lowest foot point.
    """
    root_pos, root_yaw = root_from_pelvis(pelvis_world, joint_rot_world_pelvis, dt, periodic=periodic)
    local_pelvis = quat.rot2(-root_yaw, pelvis_world - root_pos)
    rot = joint_rot.copy()
    rot[:, 0] = quat.mul(quat.from_yaw(-root_yaw), joint_rot_world_pelvis)
    clip = Clip(name, role, dt, root_pos, root_yaw, local_pelvis, rot, contacts)
    ground = float(clip.foot_points_world(skeleton)[..., 2].min())
    root_pos = root_pos.copy()
    root_pos[:, 2] = ground
    local_pelvis = local_pelvis.copy()
    local_pelvis[:, 2] -= ground
    return Clip(name, role, dt, root_pos, root_yaw, local_pelvis, rot, contacts)
