# SPDX-License-Identifier: GPL-3.0-or-later
"""Numbers that say whether a generated walk is right ("What done means for the motion").

Every function takes plain arrays (frames first), so the same checks run on the core's
simulation result and on poses evaluated in Blender. Shapes: ``F`` frames, ``L`` legs,
``s`` the longest leg's segment count.

Thresholds (``DESIGN.md``):

- stance feet do not slide: ``MAX_STANCE_SLIDE`` (2 mm) over a stance;
- no penetration below the terrain or into avoided obstacles beyond ``MAX_PENETRATION``
  (5 mm), feet and swing trajectories alike;
- bone lengths: relative error below ``MAX_BONE_LENGTH_ERROR`` (1e-4); joint limits kept;
- reachable footprints reached: IK error at most ``MAX_REACH_ERROR`` (1 cm);
- the gait is the one in the circles: lift-off and touch-down within ``MAX_PHASE_ERROR_FRAMES``
  (one frame) of the sector's start and finish;
- no leg stretched beyond its length (``MAX_EXTENSION`` = 1);
- no pops: no bone of a planted foot turns by more than ``MAX_PLANTED_TURN`` (5°) in one
  frame, and no leg bone by more than ``MAX_BONE_TURN`` (60°) (:func:`bone_turn_per_frame`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .locomotion.morphology import chain_angles

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

MAX_STANCE_SLIDE = 0.002
MAX_PENETRATION = 0.005
MAX_BONE_LENGTH_ERROR = 1e-4
MAX_JOINT_LIMIT_EXCESS = 1e-6
MAX_REACH_ERROR = 0.01
MAX_PHASE_ERROR_FRAMES = 1.0
MAX_EXTENSION = 1.0 + 1e-6
MAX_PLANTED_TURN = float(np.radians(5.0))
MAX_BONE_TURN = float(np.radians(60.0))


def stance_runs(contact: BoolArray) -> tuple[IntArray, IntArray, IntArray]:
    """Maximal runs of ``True`` per column of ``contact (F, L)``.

    Returns ``(leg, first, last)`` arrays, one entry per run (``last`` inclusive).
    """
    c = np.asarray(contact, dtype=bool)
    n_frames, n_legs = c.shape
    padded = np.zeros((n_frames + 2, n_legs), dtype=np.int8)
    padded[1:-1] = c
    edges = np.diff(padded, axis=0)
    start_f, start_l = np.nonzero(edges == 1)
    end_f, end_l = np.nonzero(edges == -1)
    # order both by leg, then frame, so starts and ends pair up
    so = np.lexsort((start_f, start_l))
    eo = np.lexsort((end_f, end_l))
    return start_l[so].astype(np.int64), start_f[so].astype(np.int64), (end_f[eo] - 1).astype(np.int64)


def stance_displacement(foot: FloatArray, contact: BoolArray) -> FloatArray:
    """World displacement of each planted foot from where its stance began: ``(F, L)``
    (0 while the foot swings).

    ``foot (F, L, 3)`` end-effector positions, ``contact (F, L)`` True while planted.
    """
    f = np.asarray(foot, dtype=np.float64)
    c = np.asarray(contact, dtype=bool)
    out = np.zeros(f.shape[:2])
    if not c.any():
        return out
    leg, first, _ = stance_runs(c)
    # position at the start of the run each planted frame belongs to
    frames, legs = np.nonzero(c)
    order = np.lexsort((frames, legs))
    frames, legs = frames[order], legs[order]
    run_of = np.searchsorted(leg * c.shape[0] + first, legs * c.shape[0] + frames, side="right") - 1
    anchor = f[first[run_of], legs]
    out[frames, legs] = np.linalg.norm(f[frames, legs] - anchor, axis=1)
    return out


def stance_sliding(foot: FloatArray, contact: BoolArray) -> FloatArray:
    """Largest world displacement of each planted foot from where it touched down: ``(L,)``.

    ``foot (F, L, 3)`` end-effector positions, ``contact (F, L)`` True while planted
    (:func:`stance_displacement` at its worst frame).
    """
    return np.asarray(stance_displacement(foot, contact).max(axis=0, initial=0.0))


def penetration_depth(points: FloatArray, height_at: Callable[[FloatArray], FloatArray]) -> FloatArray:
    """How far each point ``(..., 3)`` is below the highest surface under it: ``(...)``,
    positive when below. ``height_at(xy (n, 2)) -> (n,)`` is the surface (e.g.
    ``Environment.height_at``; points over nothing get a very low surface and never count)."""
    p = np.asarray(points, dtype=np.float64)
    flat = p.reshape(-1, 3)
    surface = np.asarray(height_at(flat[:, :2]), dtype=np.float64)
    return (surface - flat[:, 2]).reshape(p.shape[:-1])


def box_intrusion(points: FloatArray, center: FloatArray, size: FloatArray, yaw: FloatArray) -> FloatArray:
    """Depth of each point ``(n, 3)`` inside upright boxes (bottom-face ``center (b, 3)``,
    full ``size (b, 3)``, ``yaw (b,)``): the distance to the nearest face, 0 outside: ``(n,)``."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(center) == 0 or p.shape[0] == 0:
        return np.zeros(p.shape[0])
    rel = p[:, None, :] - center[None, :, :]
    c = np.cos(yaw)[None, :]
    s = np.sin(yaw)[None, :]
    lx = c * rel[..., 0] + s * rel[..., 1]
    ly = -s * rel[..., 0] + c * rel[..., 1]
    half = 0.5 * size[None, :, :]
    depth = np.minimum.reduce(
        [half[..., 0] - np.abs(lx), half[..., 1] - np.abs(ly), rel[..., 2], size[None, :, 2] - rel[..., 2]]
    )
    return np.asarray(np.maximum(depth, 0.0).max(axis=1))


def bone_length_error(joints: FloatArray, segment_lengths: FloatArray, n_segments: IntArray) -> FloatArray:
    """Largest relative bone-length error of each leg over all frames: ``(L,)``.

    ``joints (F, L, s + 1, 3)``, ``segment_lengths (L, s)``, ``n_segments (L,)``.
    """
    j = np.asarray(joints, dtype=np.float64)
    lengths = np.linalg.norm(np.diff(j, axis=2), axis=3)
    valid = np.arange(segment_lengths.shape[1])[None, :] < n_segments[:, None]
    ref = np.where(valid, segment_lengths, 1.0)
    rel = np.where(valid[None], np.abs(lengths - segment_lengths[None]) / ref[None], 0.0)
    return np.asarray(rel.max(axis=(0, 2)))


def joint_angles(
    joints: FloatArray, plane_normal: FloatArray, up: FloatArray, n_segments: IntArray
) -> FloatArray:
    """Joint angles ``(F, L, s)`` of posed legs (``morphology`` joint model) from joint
    positions ``(F, L, s + 1, 3)``, leg-plane normals ``(F, L, 3)`` and the body's up axis
    ``(F, L, 3)`` (or anything broadcastable)."""
    j = np.asarray(joints, dtype=np.float64)
    n_frames, n_legs = j.shape[:2]
    normal = np.broadcast_to(plane_normal, (n_frames, n_legs, 3)).reshape(-1, 3)
    upv = np.broadcast_to(up, (n_frames, n_legs, 3)).reshape(-1, 3)
    nseg = np.broadcast_to(n_segments, (n_frames, n_legs)).reshape(-1)
    ang = chain_angles(j.reshape(n_frames * n_legs, j.shape[2], 3), normal, upv, nseg)
    return ang.reshape(n_frames, n_legs, -1)


def joint_limit_excess(angles: FloatArray, joint_min: FloatArray, joint_max: FloatArray) -> FloatArray:
    """Largest amount (radians) by which each leg's joints leave their limits: ``(L,)``.

    ``angles (F, L, s)``; limits ``(L, s)``. Angles are compared on the 2π-turn closest to
    the limits' middle.
    """
    a = np.asarray(angles, dtype=np.float64)
    mid = 0.5 * (joint_min + joint_max)
    wrapped = np.mod(a - mid[None] + np.pi, 2.0 * np.pi) - np.pi + mid[None]
    excess = np.maximum(joint_min[None] - wrapped, wrapped - joint_max[None])
    return np.asarray(np.maximum(excess, 0.0).max(axis=(0, 2)))


def reach_distance(
    end_effector: FloatArray, target: FloatArray, reachable: BoolArray | None = None
) -> FloatArray:
    """End-effector to target distance at each frame, 0 where the target was out of reach:
    ``(F, L)``. ``end_effector``, ``target``: ``(F, L, 3)``; ``reachable (F, L)``."""
    d = np.linalg.norm(np.asarray(end_effector) - np.asarray(target), axis=2)
    if reachable is not None:
        d = np.where(reachable, d, 0.0)
    return np.asarray(d)


def reach_error(
    end_effector: FloatArray, target: FloatArray, reachable: BoolArray | None = None
) -> FloatArray:
    """Largest end-effector to target distance per leg over the frames where the target was
    reachable: ``(L,)``. ``end_effector``, ``target``: ``(F, L, 3)``; ``reachable (F, L)``."""
    return np.asarray(reach_distance(end_effector, target, reachable).max(axis=0))


def extension_ratio(hip: FloatArray, end_effector: FloatArray, leg_length: FloatArray) -> FloatArray:
    """Hip-to-end-effector distance over leg length at each frame: ``(F, L)``.
    ``hip``, ``end_effector``: ``(F, L, 3)``; ``leg_length (L,)``."""
    d = np.linalg.norm(np.asarray(end_effector) - np.asarray(hip), axis=2)
    return np.asarray(d / np.asarray(leg_length)[None, :])


def extension(hip: FloatArray, end_effector: FloatArray, leg_length: FloatArray) -> FloatArray:
    """Largest hip-to-end-effector distance over leg length, per leg: ``(L,)``
    (1 is a fully straight leg; more means the leg would have to stretch)."""
    return np.asarray(extension_ratio(hip, end_effector, leg_length).max(axis=0))


def target_extension(hip: FloatArray, target: FloatArray, leg_length: FloatArray) -> FloatArray:
    """Like ``extension`` but for the targets the legs were asked to reach: ``(L,)``.

    An IK with exact bone lengths never *shows* a stretched leg (``extension`` stays <= 1);
    a target beyond the leg's length is where the motion asked for one."""
    return extension(hip, target, leg_length)


@dataclass(frozen=True)
class PhaseErrors:
    """Gait-phase check: signed errors in frames of every lift-off and touch-down found.

    ``lift_leg``/``lift_frame``/``lift_error`` and ``land_leg``/``land_frame``/``land_error``
    list the events; ``max_abs`` is the largest error magnitude (0 when there are none).
    """

    lift_leg: IntArray
    lift_frame: IntArray
    lift_error: FloatArray
    land_leg: IntArray
    land_frame: IntArray
    land_error: FloatArray

    @property
    def max_abs(self) -> float:
        errs = np.concatenate([self.lift_error, self.land_error])
        return float(np.abs(errs).max()) if errs.size else 0.0

    @property
    def n_events(self) -> int:
        return int(self.lift_error.size + self.land_error.size)


def swing_phase_errors(
    contact: BoolArray,
    needle: FloatArray,
    phase_step: FloatArray | float,
    swing_start: FloatArray,
    swing_duration: FloatArray,
    ignore: BoolArray | None = None,
    first_frame: int = 1,
) -> PhaseErrors:
    """Measured lift-off/touch-down phases against the gait circles.

    ``contact (F, L)``; ``needle (F,)`` or ``(F, L)`` the needle phase at each frame;
    ``phase_step`` the phase the needle moves per frame (scalar, ``(F,)`` or ``(F, L)``);
    ``swing_start``/``swing_duration`` the sectors, ``(L,)`` or per frame ``(F, L)``;
    ``ignore (F, L)`` marks frames whose events must not be judged (forced re-plans).

    A lift-off is the first frame without contact after contact; its error is the needle's
    distance past the sector's start, in frames (0 <= e < 1 for a lift at the first frame
    inside the sector). A touch-down is compared with the sector's finish the same way.
    """
    c = np.asarray(contact, dtype=bool)
    n_frames, n_legs = c.shape
    nd = np.broadcast_to(np.asarray(needle, dtype=np.float64).reshape(n_frames, -1), (n_frames, n_legs))
    stp = np.broadcast_to(
        np.asarray(phase_step, dtype=np.float64).reshape(-1, 1)
        if np.ndim(phase_step) == 1
        else np.asarray(phase_step, dtype=np.float64),
        (n_frames, n_legs),
    )
    start = np.broadcast_to(swing_start, (n_frames, n_legs))
    dur = np.broadcast_to(swing_duration, (n_frames, n_legs))
    skip = np.zeros_like(c) if ignore is None else np.asarray(ignore, dtype=bool)
    prev = c[:-1]
    now = c[1:]
    lift_f, lift_l = np.nonzero(prev & ~now)
    land_f, land_l = np.nonzero(~prev & now)
    lift_f = lift_f + 1
    land_f = land_f + 1

    def err(frames: IntArray, legs: IntArray, boundary: FloatArray) -> FloatArray:
        e = np.mod(nd[frames, legs] - boundary[frames, legs] + 0.5, 1.0) - 0.5
        e = np.where(np.abs(e) < 1e-9, 0.0, e)  # float round-off at the boundary itself
        return np.asarray(e / np.maximum(stp[frames, legs], 1e-12))

    keep_lift = (lift_f >= first_frame) & ~skip[lift_f, lift_l]
    keep_land = (land_f >= first_frame) & ~skip[land_f, land_l]
    lift_f, lift_l = lift_f[keep_lift], lift_l[keep_lift]
    land_f, land_l = land_f[keep_land], land_l[keep_land]
    finish = np.mod(start + dur, 1.0)
    return PhaseErrors(
        lift_leg=lift_l.astype(np.int64),
        lift_frame=lift_f.astype(np.int64),
        lift_error=err(lift_f, lift_l, start),
        land_leg=land_l.astype(np.int64),
        land_frame=land_f.astype(np.int64),
        land_error=err(land_f, land_l, finish),
    )


def bone_turn_per_frame(rotation: FloatArray) -> FloatArray:
    """Angle each bone turns from one frame to the next, radians ``(F - 1, B)``.

    rotation: ``(F, B, 3, 3)`` world rotations (any uniform scale is divided out).
    """
    r = np.asarray(rotation, dtype=np.float64)
    r = r / np.linalg.norm(r[..., :, :1], axis=-2, keepdims=True)
    rel = np.einsum("fbji,fbjk->fbik", r[:-1], r[1:])  # R_f^T R_{f+1}
    cos = np.clip(0.5 * (np.trace(rel, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
    out: FloatArray = np.arccos(cos)
    return out


def periodicity_error(series: FloatArray, period_frames: int, start: int = 0) -> float:
    """Largest difference between ``series[f]`` and ``series[f + period_frames]`` from
    ``start`` on (any trailing shape)."""
    s = np.asarray(series, dtype=np.float64)[start:]
    if s.shape[0] <= period_frames:
        raise ValueError("the series is shorter than one period")
    return float(np.abs(s[period_frames:] - s[:-period_frames]).max())


@dataclass(frozen=True)
class MotionReport:
    """All motion numbers of one result and whether each meets its threshold.

    Per-leg arrays are ``(L,)``. ``phase`` is ``None`` when no gait data was given;
    ``avoid_intrusion`` is 0 without avoided boxes.
    """

    stance_slide: FloatArray
    penetration: float
    avoid_intrusion: float
    bone_length_error: FloatArray
    joint_limit_excess: FloatArray
    reach_error: FloatArray
    extension: FloatArray
    phase: PhaseErrors | None = None
    notes: tuple[str, ...] = field(default=())
    #: highest a planted foot hangs above the ground under it (a foot planted where its leg
    #: does not reach, or on a spot its point does not touch); judged like penetration
    hover: float = 0.0
    #: ``(B,)`` largest per-frame turn of each leg and foot bone while its foot is planted,
    #: and at any time (radians; empty when not measured)
    planted_turn: FloatArray = field(default_factory=lambda: np.zeros(0))
    bone_turn: FloatArray = field(default_factory=lambda: np.zeros(0))

    def failures(self) -> list[str]:
        """One line per failed check (empty when everything passes)."""
        out: list[str] = []
        if self.stance_slide.size and self.stance_slide.max() > MAX_STANCE_SLIDE:
            out.append(
                f"stance foot slides {self.stance_slide.max() * 1000:.2f} mm "
                f"(leg {int(self.stance_slide.argmax())}) > {MAX_STANCE_SLIDE * 1000:.0f} mm"
            )
        if self.penetration > MAX_PENETRATION:
            out.append(
                f"foot {self.penetration * 1000:.2f} mm below a surface > {MAX_PENETRATION * 1000:.0f} mm"
            )
        if self.hover > MAX_PENETRATION:
            out.append(f"a planted foot hangs {self.hover * 1000:.2f} mm above the ground > "
                       f"{MAX_PENETRATION * 1000:.0f} mm")
        if self.avoid_intrusion > MAX_PENETRATION:
            out.append(f"foot {self.avoid_intrusion * 1000:.2f} mm inside an avoided obstacle")
        if self.bone_length_error.size and self.bone_length_error.max() > MAX_BONE_LENGTH_ERROR:
            out.append(f"bone length changes by {self.bone_length_error.max():.2e} (relative)")
        if self.joint_limit_excess.size and self.joint_limit_excess.max() > MAX_JOINT_LIMIT_EXCESS:
            out.append(f"joint leaves its limits by {np.degrees(self.joint_limit_excess.max()):.3f} deg")
        if self.reach_error.size and self.reach_error.max() > MAX_REACH_ERROR:
            out.append(
                f"end effector misses a reachable target by {self.reach_error.max() * 100:.2f} cm "
                f"(leg {int(self.reach_error.argmax())})"
            )
        if self.extension.size and self.extension.max() > MAX_EXTENSION:
            out.append(f"leg stretched to {self.extension.max():.4f} of its length")
        if self.phase is not None and self.phase.max_abs > MAX_PHASE_ERROR_FRAMES:
            out.append(f"lift-off/touch-down {self.phase.max_abs:.2f} frames away from the gait circles")
        if self.planted_turn.size and self.planted_turn.max() > MAX_PLANTED_TURN:
            out.append(f"a bone of a planted foot turns {np.degrees(self.planted_turn.max()):.1f} deg "
                       "in one frame")
        if self.bone_turn.size and self.bone_turn.max() > MAX_BONE_TURN:
            out.append(f"a leg bone turns {np.degrees(self.bone_turn.max()):.1f} deg in one frame")
        return out

    @property
    def passed(self) -> bool:
        return not self.failures()

    def summary(self) -> str:
        def top(values: FloatArray, scale: float = 1.0) -> float:
            return float(values.max()) * scale if values.size else 0.0

        lines = [
            f"stance slide max      {top(self.stance_slide, 1000.0):8.3f} mm",
            f"penetration max       {self.penetration * 1000:8.3f} mm",
            f"avoid intrusion max   {self.avoid_intrusion * 1000:8.3f} mm",
            f"planted foot hover    {self.hover * 1000:8.3f} mm",
            f"bone length rel err   {top(self.bone_length_error):8.2e}",
            f"joint limit excess    {top(self.joint_limit_excess, 180.0 / np.pi):8.4f} deg",
            f"reach error max       {top(self.reach_error, 100.0):8.3f} cm",
            f"extension max         {top(self.extension):8.4f} of leg length",
        ]
        if self.bone_turn.size:
            lines.append(f"bone turn per frame   {top(self.bone_turn, 180.0 / np.pi):8.2f} deg "
                         f"(planted foot {top(self.planted_turn, 180.0 / np.pi):.2f} deg)")
        if self.phase is not None:
            lines.append(
                f"phase error max       {self.phase.max_abs:8.3f} frames ({self.phase.n_events} events)"
            )
        lines.extend(self.notes)
        return "\n".join(lines)


#: Frames allowed with fewer feet on the ground than the gait plants, and with a leg
#: stretched beyond its length: none (``MAX_PENETRATION`` says when a foot is down).
MAX_FEW_FEET_FRAMES = 0
MAX_STRETCHED_FRAMES = 0
#: A posed leg is over-stretched beyond this fraction of its length: the bone-length
#: tolerance, since a posed rig is read in single precision (``MAX_EXTENSION``'s 1e-6 is for
#: the core's own double-precision joints, and a rig 10 m from the origin is already
#: 1e-6 m off in single precision).
MAX_POSED_EXTENSION = 1.0 + MAX_BONE_LENGTH_ERROR


@dataclass(frozen=True)
class Worst:
    """One figure of a posed result: its ``value`` (metres, or a number of frames), the
    index of its worst frame ``frame`` and the leg ``leg`` there (both -1 when there is
    none), and the ``limit`` above which it fails."""

    value: float
    frame: int
    leg: int
    limit: float

    @property
    def failed(self) -> bool:
        return self.value > self.limit


def worst_of(values: FloatArray, limit: float) -> Worst:
    """The largest of ``values (F, L)`` with its frame and leg (first one on ties)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return Worst(0.0, -1, -1, limit)
    f, leg = np.unravel_index(int(np.argmax(v)), v.shape)
    return Worst(float(v[f, leg]), int(f), int(leg), limit)


@dataclass(frozen=True)
class PosedQuality:
    """What the quality panel shows for a written result, measured on the posed rig.

    ``slide``, ``penetration``, ``reach``: metres at their worst frame; ``few_feet_down``:
    frames where a foot the gait plants is not on the ground (its lowest point hangs more
    than ``MAX_PENETRATION`` above it), its worst frame the one whose planted foot hangs highest
    (``hover`` metres, ``inf`` over no ground); ``over_stretched``: frames where a leg is, or
    is asked to be, longer than it is, its worst frame the one with the largest ``stretch``
    (hip-to-foot distance over leg length; over-stretched above ``MAX_POSED_EXTENSION``)."""

    slide: Worst
    penetration: Worst
    reach: Worst
    few_feet_down: Worst
    over_stretched: Worst
    stretch: float
    hover: float

    def figures(self) -> tuple[tuple[str, Worst], ...]:
        """``(key, figure)`` in the panel's order."""
        return (("slide", self.slide), ("penetration", self.penetration), ("reach", self.reach),
                ("few_feet_down", self.few_feet_down), ("over_stretched", self.over_stretched))


def posed_quality(
    end_effector: FloatArray,
    hip: FloatArray,
    target: FloatArray,
    contact: BoolArray,
    leg_length: FloatArray,
    probes: FloatArray,
    surface: FloatArray,
    lift: FloatArray,
) -> PosedQuality:
    """The quality panel's figures of a posed result (see :class:`PosedQuality`).

    ``end_effector``, ``hip``, ``target``: ``(F, L, 3)`` world positions of the posed legs'
    ends and hips and of the targets the walk planned; ``contact (F, L)`` the feet the gait
    plants; ``leg_length (L,)``; ``probes (F, L, P, 3)`` points of each foot checked against
    the ground, the end-effector first, ``surface (F, L, P)`` the ground's height under each
    (``-inf`` over nothing) and ``lift (L, P)`` how high each probe stands over the ground
    when the foot is down (an ankle above the sole).
    """
    end = np.asarray(end_effector, dtype=np.float64)
    hips = np.asarray(hip, dtype=np.float64)
    tgt = np.asarray(target, dtype=np.float64)
    c = np.asarray(contact, dtype=bool)
    length = np.asarray(leg_length, dtype=np.float64)
    depth = np.asarray(surface, dtype=np.float64) + np.asarray(lift)[None] - np.asarray(probes)[..., 2]
    deepest = depth.max(axis=2, initial=-np.inf)  # (F, L): the foot's lowest point
    below = np.maximum(deepest, 0.0)
    hover = -deepest  # a foot is down when any of its points is (a sole tilted on a slope)
    lifted = c & ~(hover <= MAX_PENETRATION)  # planted feet off the ground (or over nothing)
    few = lifted.any(axis=1)
    hang = worst_of(np.where(lifted, hover, -np.inf), 0.0)
    reachable = np.linalg.norm(tgt - hips, axis=2) <= length[None, :] * (1.0 - 1e-6)
    ratio = np.maximum(extension_ratio(hips, end, length), extension_ratio(hips, tgt, length))
    longest = worst_of(ratio, MAX_POSED_EXTENSION)
    stretched = (ratio > MAX_POSED_EXTENSION).any(axis=1)
    return PosedQuality(
        slide=worst_of(stance_displacement(end, c), MAX_STANCE_SLIDE),
        penetration=worst_of(below, MAX_PENETRATION),
        reach=worst_of(reach_distance(end, tgt, reachable), MAX_REACH_ERROR),
        few_feet_down=Worst(float(few.sum()), hang.frame if few.any() else -1,
                            hang.leg if few.any() else -1, MAX_FEW_FEET_FRAMES),
        over_stretched=Worst(float(stretched.sum()), longest.frame if stretched.any() else -1,
                             longest.leg if stretched.any() else -1, MAX_STRETCHED_FRAMES),
        stretch=longest.value if longest.frame >= 0 else 0.0,
        hover=max(hang.value, 0.0) if few.any() else 0.0,
    )
