# SPDX-License-Identifier: GPL-3.0-or-later
"""The clip database: every clip analysed once and resampled on a common phase grid.

Playback (§3.4) blends clips by *phase* (normalised time, 0 at the clip's start and 1 at
its end), so that a walk of 1.1 s and a run of 0.7 s stay in step while they are blended.
The database therefore resamples each clip on ``n_samples`` equally spaced phases and stacks
the results into arrays with a leading clip axis, so that one gather samples every clip of
every frame at once.

For each clip it also records what the planner needs to know about it:

* its foot contacts as phase intervals, and the *footprint* each contact leaves (position
  and heading of the foot, relative to the clip's root at phase 0);
* the right footprint at phase 0 (the edge's source in the footprint graph, §3.2) and the
  root's travel over the clip (the *cycle transform*), hence the next right footprint;
* its curvature ``τ`` (turn per metre travelled, positive to the left; §3.7.1) and speed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import quat
from .clip import Clip, ClipRole, contact_runs, detect_contacts
from .skeleton import LEFT, RIGHT, Skeleton, foot_points, forward_kinematics

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class ContactInterval:
    """One contact of one foot within a clip, in phase units.

    ``td``/``lo``: touchdown and lift-off phases; ``lo > 1`` when the stance of a looping clip
    continues into its next stride, ``lo == 1`` when the foot is still planted at the end.
    ``pos``/``yaw``: the footprint it leaves, relative to the clip's root at phase 0.
    """

    side: int
    td: float
    lo: float
    pos: FloatArray
    yaw: float


@dataclass(frozen=True)
class ClipInfo:
    """What the planner knows about one clip (see the module docstring)."""

    index: int
    name: str
    role: ClipRole
    duration: float
    loops: bool
    cycle_pos: FloatArray
    cycle_yaw: float
    intervals: tuple[ContactInterval, ...]
    initial_contact_end: tuple[float, float]
    end_right_pos: FloatArray
    end_right_yaw: float
    curvature: float
    speed: float
    path_length: float

    @property
    def right_start(self) -> ContactInterval:
        """The right footprint the clip starts on (normal form)."""
        for iv in self.intervals:
            if iv.side == RIGHT and iv.td == 0.0:
                return iv
        raise ValueError(f"clip {self.name!r} does not start with the right foot planted")

    @property
    def left_step(self) -> ContactInterval:
        """The left footprint that the clip makes (the one that is not a continuation)."""
        for iv in self.intervals:
            if iv.side == LEFT and iv.td > 0.0:
                return iv
        raise ValueError(f"clip {self.name!r} makes no left footprint")


class ClipDatabase:
    """Analysed clips on a common phase grid; arrays are indexed ``[clip, sample, ...]``.

    ``root_pos (C, S, 3)``, ``root_yaw (C, S)``: root relative to phase 0;
    ``pelvis_pos (C, S, 3)``, ``joint_rot (C, S, J, 4)``: the pose;
    ``points (C, S, 2, 2, 3)``: heel/toe of both feet relative to the root at phase 0;
    ``points_local (C, S, 2, 2, 3)``: the same in the character frame of that sample;
    ``contact (C, S, 2)``: 1.0 where the foot is planted; ``foot_yaw (C, S, 2)``: heading of
    each foot (heel to toe) in the character frame.
    """

    def __init__(self, skeleton: Skeleton, clips: Sequence[Clip], n_samples: int = 65) -> None:
        if not clips:
            raise ValueError("the clip database needs at least one clip")
        self.skeleton = skeleton
        self.clips = list(clips)
        self.n_samples = n_samples
        c = len(clips)
        s = n_samples
        j = skeleton.n_joints
        for clip in clips:
            if clip.joint_rot.shape[1:] != (j, 4):
                raise ValueError(f"clip {clip.name!r} does not match the skeleton ({j} joints)")
        self.phase = np.linspace(0.0, 1.0, s)
        self.root_pos = np.zeros((c, s, 3))
        self.root_yaw = np.zeros((c, s))
        self.pelvis_pos = np.zeros((c, s, 3))
        self.joint_rot = np.zeros((c, s, j, 4))
        self.points = np.zeros((c, s, 2, 2, 3))
        self.points_local = np.zeros((c, s, 2, 2, 3))
        self.contact = np.zeros((c, s, 2))
        self.foot_yaw = np.zeros((c, s, 2))
        self.duration = np.zeros(c)
        self.loops = np.zeros(c, dtype=bool)
        self.cycle_pos = np.zeros((c, 3))
        self.cycle_yaw = np.zeros(c)
        infos = []
        for i, clip in enumerate(clips):
            infos.append(self._analyse(i, clip))
        self.infos: list[ClipInfo] = infos

    # -- analysis -----------------------------------------------------------------------------

    def _analyse(self, i: int, clip: Clip) -> ClipInfo:
        skel = self.skeleton
        n = clip.n_frames
        pos0, yaw0 = clip.root_pos[0], float(clip.root_yaw[0])
        root_pos, root_yaw = quat.relative2(pos0, yaw0, clip.root_pos, clip.root_yaw)
        root_yaw = np.unwrap(root_yaw)
        joint_pos, _ = forward_kinematics(skel, clip.joint_rot, clip.pelvis_pos)
        pts_local = foot_points(skel, joint_pos)
        pts = root_pos[:, None, None, :] + quat.rot2(root_yaw[:, None, None], pts_local)
        contacts = (
            np.asarray(clip.contacts, dtype=bool)
            if clip.contacts is not None
            else detect_contacts(pts, clip.dt)
        )
        loops = clip.role.family in ("walk", "run")
        cyc_pos, cyc_yaw = root_pos[-1].copy(), float(root_yaw[-1])

        def points_at(frame: int) -> FloatArray:
            """Foot points at a frame index that may run past the end (looping clips)."""
            if frame < n:
                return pts[frame]
            p = pts[frame - (n - 1)]
            return cyc_pos + quat.rot2(cyc_yaw, p)

        intervals: list[ContactInterval] = []
        initial_end = [0.0, 0.0]
        last = n - 1
        for side in (LEFT, RIGHT):
            flags = contacts[:, side]
            if loops:
                runs = contact_runs(flags[:last])
                if len(runs) >= 2 and runs[0][0] == 0 and runs[-1][1] == last - 1:
                    first = runs.pop(0)
                    a, b = runs.pop()
                    runs.append((a, last + first[1]))
                if side == RIGHT:
                    # The right touchdown is the clip's start by construction (normal form),
                    # even where detection saw the foot slow down a frame or two early.
                    runs = [(0, b - last) if a > 0.8 * last and b >= last else (a, b) for a, b in runs]
                for _, b in runs:
                    if b > last:
                        initial_end[side] = (b - last) / last
            else:
                runs = contact_runs(flags)
                if side == RIGHT and clip.role.family in ("jump", "start"):
                    # The touchdown on the last frame is the next clip's start, not ours.
                    runs = [(a, b) for a, b in runs if not (b == last and a > 0)]
                if runs and runs[0][0] == 0:
                    initial_end[side] = runs[0][1] / last
            for a, b in runs:
                frames = np.arange(a, b + 1)
                p = np.stack([points_at(int(f)) for f in frames])  # (m, 2 points, 3) per foot below
                foot = p[:, side]
                mid = 0.5 * (foot[:, 0] + foot[:, 1])
                heading = foot[:, 1, :2] - foot[:, 0, :2]
                yaw = float(
                    np.arctan2(
                        np.sin(np.arctan2(heading[:, 1], heading[:, 0])).mean(),
                        np.cos(np.arctan2(heading[:, 1], heading[:, 0])).mean(),
                    )
                )
                fp = np.array([mid[:, 0].mean(), mid[:, 1].mean(), foot[:, :, 2].min(axis=1).mean()])
                intervals.append(ContactInterval(side, a / last, b / last, fp, yaw))
        intervals.sort(key=lambda iv: (iv.td, iv.side))

        # Resample on the phase grid.
        src = np.linspace(0.0, 1.0, n)
        ph = self.phase
        self.root_pos[i] = _interp(ph, src, root_pos)
        self.root_yaw[i] = np.interp(ph, src, root_yaw)
        self.pelvis_pos[i] = _interp(ph, src, clip.pelvis_pos)
        self.joint_rot[i] = _interp_quat(ph, src, clip.joint_rot)
        self.points[i] = _interp(ph, src, pts)
        self.points_local[i] = _interp(ph, src, pts_local)
        self.contact[i] = _interp(ph, src, contacts.astype(float)) >= 0.5
        head = self.points_local[i, :, :, 1, :2] - self.points_local[i, :, :, 0, :2]
        self.foot_yaw[i] = np.unwrap(np.arctan2(head[..., 1], head[..., 0]), axis=0)
        self.duration[i] = clip.duration
        self.loops[i] = loops
        self.cycle_pos[i] = cyc_pos
        self.cycle_yaw[i] = cyc_yaw

        # Where the right foot is at the clip's end: the next stride's right footprint.
        starts = [iv for iv in intervals if iv.side == RIGHT and iv.td == 0.0]
        end_pos: FloatArray
        end_yaw: FloatArray | float
        if loops and starts:
            end_pos, end_yaw = quat.compose2(cyc_pos, cyc_yaw, starts[0].pos, starts[0].yaw)
        elif clip.role.family == "stop" and starts:
            end_pos, end_yaw = starts[0].pos, starts[0].yaw
        else:
            foot = pts[-1, RIGHT]
            head = foot[1, :2] - foot[0, :2]
            end_pos = np.array([*(0.5 * (foot[0, :2] + foot[1, :2])), foot[:, 2].min()])
            end_yaw = float(np.arctan2(head[1], head[0]))
        steps = np.linalg.norm(np.diff(root_pos[:, :2], axis=0), axis=1)
        length = float(steps.sum())
        curvature = cyc_yaw / length if length > 1e-6 else 0.0
        return ClipInfo(
            index=i,
            name=clip.name,
            role=clip.role,
            duration=clip.duration,
            loops=loops,
            cycle_pos=cyc_pos,
            cycle_yaw=cyc_yaw,
            intervals=tuple(intervals),
            initial_contact_end=(initial_end[0], initial_end[1]),
            end_right_pos=np.asarray(end_pos, dtype=float),
            end_right_yaw=float(end_yaw),
            curvature=curvature,
            speed=length / clip.duration,
            path_length=length,
        )

    # -- queries ------------------------------------------------------------------------------

    def by_role(self, *families: str) -> list[ClipInfo]:
        """Clips of the given role families (``"walk"``, ``"run"``, ...)."""
        return [info for info in self.infos if info.role.family in families]

    def first(self, family: str) -> ClipInfo | None:
        found = self.by_role(family)
        return found[0] if found else None

    def sample(self, name: str, clip_idx: IntArray, phase: FloatArray) -> FloatArray:
        """Linear samples of array ``name`` at clip indices and phases in ``[0, 1]``.

        ``clip_idx`` and ``phase`` broadcast together to ``(...)``; the result is
        ``(..., *item_shape)``.
        """
        arr = getattr(self, name)
        f = np.clip(phase, 0.0, 1.0) * (self.n_samples - 1)
        i0 = np.minimum(np.floor(f).astype(np.int64), self.n_samples - 2)
        w = f - i0
        a = arr[clip_idx, i0]
        b = arr[clip_idx, i0 + 1]
        w = w.reshape(w.shape + (1,) * (a.ndim - w.ndim))
        return a + (b - a) * w

    def sample_rot(self, clip_idx: IntArray, phase: FloatArray) -> FloatArray:
        """Joint rotations ``(..., J, 4)`` at clip indices and phases (normalised lerp)."""
        q = self.sample("joint_rot", clip_idx, phase)
        return quat.normalize(q)

    def sample_root(self, clip_idx: IntArray, phase: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Root position ``(..., 3)`` and yaw ``(...)`` at phases in ``[0, 2)``; past 1 a
        looping clip's next stride is the first one moved by the cycle transform."""
        wrap = phase > 1.0
        ph = np.where(wrap, phase - 1.0, phase)
        pos = self.sample("root_pos", clip_idx, ph)
        yaw = self.sample("root_yaw", clip_idx, ph)
        cp = self.cycle_pos[clip_idx]
        cy = self.cycle_yaw[clip_idx]
        pos = np.where(wrap[..., None], cp + quat.rot2(cy, pos), pos)
        yaw = np.where(wrap, yaw + cy, yaw)
        return pos, yaw

    def sample_points(self, clip_idx: IntArray, phase: FloatArray) -> FloatArray:
        """Heel/toe points ``(..., 2, 2, 3)`` relative to the root at phase 0, phases in ``[0, 2)``."""
        wrap = phase > 1.0
        ph = np.where(wrap, phase - 1.0, phase)
        pts = self.sample("points", clip_idx, ph)
        cp = self.cycle_pos[clip_idx][..., None, None, :]
        cy = self.cycle_yaw[clip_idx][..., None, None]
        return np.where(wrap[..., None, None, None], cp + quat.rot2(cy, pts), pts)


def _interp(x: FloatArray, xp: FloatArray, fp: FloatArray) -> FloatArray:
    """``np.interp`` along the first axis of ``fp`` (any trailing shape)."""
    f = np.interp(x, xp, np.arange(len(xp)))
    i0 = np.minimum(np.floor(f).astype(np.int64), len(xp) - 2)
    w = (f - i0).reshape((-1,) + (1,) * (fp.ndim - 1))
    return fp[i0] + (fp[i0 + 1] - fp[i0]) * w


def _interp_quat(x: FloatArray, xp: FloatArray, q: FloatArray) -> FloatArray:
    q = quat.hemisphere(q)
    return quat.normalize(_interp(x, xp, q))
