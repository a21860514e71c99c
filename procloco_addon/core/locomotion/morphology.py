# SPDX-License-Identifier: GPL-3.0-or-later
"""Legs and body of a legged character, as plain arrays (thesis §3.1, figure 3.4).

Everything here is in the character's *body frame*: x forward, y left, z up, origin at the
pelvis (the point the controller moves). A leg is a planar chain of segments hanging from
its hip joint; legs of one character may have different segment counts, so per-leg arrays
are padded to the longest leg and ``n_segments`` says how many entries are real.

Joint model (see ``ik``): the leg moves in a *leg plane* that contains the hip and the foot
target; the plane turns about the body's up axis with the foot (hip yaw) for splayed legs
(spiders, insects) and keeps its rest orientation for legs that stand under their hip
(mammals, birds, humans). Inside the plane, joint 0 is the hip pitch (the first segment's
angle, counter-clockwise about the plane normal from the plane's horizontal axis) and
joints 1.. are hinges (the angle of a segment relative to the previous one). Angles are
limited per joint by ``joint_min``/``joint_max``.

``Morphology`` describes one character. ``LegBatch`` stacks many characters' legs into one
flat leg axis (``leg_char`` says whose leg each row is) so that the IK, the gait and the
pelvis physics run over every leg of every character with one set of numpy calls.

A character may also have a flexible spine (thesis §4.2, ``core.locomotion.spine``): its body is then
split into *virtual pelvis nodes* — the head node, which carries no legs, and one node per
girdle — joined by the spine's joints. :meth:`Morphology.with_spine` adds one; each leg's
``pelvis_node`` is then the key node it hangs from.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from ..geometry import cross, vector_norm
from .spine import DEFAULT_JOINT_PITCH_LIMIT, DEFAULT_JOINT_YAW_LIMIT, SpineModel

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

_UP = np.array([0.0, 0.0, 1.0])


class MorphologyError(ValueError):
    """Raised for a morphology that cannot be animated (zero-length bones, bad shapes...)."""


def _unit(v: FloatArray, fallback: FloatArray | None = None) -> FloatArray:
    """Normalise the last axis; rows shorter than 1e-12 take ``fallback`` (or stay zero)."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    out = np.divide(v, norm, out=np.zeros_like(v, dtype=np.float64), where=norm > 1e-12)
    if fallback is not None:
        small = norm[..., 0] <= 1e-12
        out[small] = np.broadcast_to(fallback, out.shape)[small]
    return out


def leg_labels(n_legs: int, midline: Sequence[int] = ()) -> tuple[str, ...]:
    """Conventional labels front to back, left before right: ``L1, R1, L2, R2, ...``.

    ``midline`` lists 1-based row numbers that hold a single leg on the midline (labelled
    ``M<row>``), e.g. a star-shaped pentapod with one front leg is ``leg_labels(5, (1,))``
    -> ``M1, L2, R2, L3, R3``.
    """
    labels: list[str] = []
    row = 1
    while len(labels) < n_legs:
        if row in midline:
            labels.append(f"M{row}")
        else:
            labels.append(f"L{row}")
            if len(labels) < n_legs:
                labels.append(f"R{row}")
        row += 1
    return tuple(labels)


@dataclass(frozen=True, eq=False)
class Morphology:
    """One character's legs and body, in its body frame (x forward, y left, z up).

    Attributes (``n`` legs, ``s`` = longest leg's segment count):

    - ``labels``: ``(n,)`` leg names, front to back, left before right (``L1, R1, ...``).
    - ``rest_joints``: ``(n, s + 1, 3)`` rest positions of hip, inner joints and end
      effector; rows past a leg's end repeat its end effector.
    - ``n_segments``: ``(n,)`` segment count of each leg (>= 1).
    - ``segment_lengths``: ``(n, s)`` bone lengths, zero past a leg's end.
    - ``plane_normal``: ``(n, 3)`` rest leg-plane normal; hinge angles turn about it.
    - ``joint_min``, ``joint_max``: ``(n, s)`` limits in radians (joint 0 hip pitch, then
      hinges); padded entries are 0.
    - ``yaw_weight``: ``(n,)`` 1 when the leg plane yaws with the foot (splayed legs), 0 when
      it keeps its rest orientation (legs under the hip).
    - ``pelvis_node``: ``(n,)`` index of the pelvis node the hip belongs to: 0 (the one
      pelvis) without a spine; with one, the spine's key node (1 .. K - 1; node 0 is the head).
    - ``body_box_center``, ``body_box_half``: ``(2,)`` projected body box in the xy plane.
    - ``body_thickness``: height of the pelvis origin above the terrain's upper hull when
      standing (thesis figure 3.8); defaults to the rest height above the feet.
    - ``foot_half_extents``: ``(2,)`` half size of the projected foot shape (x along the foot):
      the box the planner keeps clear of obstacles, holes and other feet.
    - ``sole_half_extents``: ``(2,)`` half size of the part of a foot another foot may not land
      on, about its point (None: the foot box). Smaller than the foot box for feet whose toes
      reach far from the end-effector (``core.locomotion.footprints.PlannerParams``).
    - ``foot_lift``: ``(n,)`` how far each end-effector stands above the ground its foot is
      planned on (None: 0). A rig whose end-effectors stand at different heights above their
      soles walks on ground raised by their mean height, each end-effector this much above it.
    - ``spine``: the flexible spine (``core.locomotion.spine.SpineModel``, in this body frame), or None
      for a rigid body; see :meth:`with_spine`.
    """

    labels: tuple[str, ...]
    rest_joints: FloatArray
    n_segments: IntArray
    segment_lengths: FloatArray
    plane_normal: FloatArray
    joint_min: FloatArray
    joint_max: FloatArray
    yaw_weight: FloatArray
    pelvis_node: IntArray
    body_box_center: FloatArray
    body_box_half: FloatArray
    body_thickness: float
    foot_half_extents: FloatArray
    spine: SpineModel | None = None
    sole_half_extents: FloatArray | None = None
    foot_lift: FloatArray | None = None

    # ------------------------------------------------------------------ derived values
    @property
    def n_legs(self) -> int:
        return len(self.labels)

    @property
    def max_segments(self) -> int:
        return int(self.segment_lengths.shape[1])

    @property
    def hip_offset(self) -> FloatArray:
        """``(n, 3)`` hip joint positions."""
        return self.rest_joints[:, 0, :]

    @property
    def rest_foot(self) -> FloatArray:
        """``(n, 3)`` rest end-effector positions."""
        return self.rest_joints[np.arange(self.n_legs), self.n_segments, :]

    @property
    def leg_length(self) -> FloatArray:
        """``(n,)`` sum of each leg's segment lengths (its full reach)."""
        return self.segment_lengths.sum(axis=1)

    @property
    def rest_angles(self) -> FloatArray:
        """``(n, s)`` joint angles of the rest pose in this module's joint model."""
        return chain_angles(
            self.rest_joints, self.plane_normal, np.broadcast_to(_UP, (self.n_legs, 3)), self.n_segments
        )

    def with_spine(
        self,
        joint_rest: npt.ArrayLike,
        *,
        key_joint: npt.ArrayLike | None = None,
        leg_key: npt.ArrayLike | None = None,
        leg_bone: npt.ArrayLike | None = None,
        joint_yaw_limit: float = DEFAULT_JOINT_YAW_LIMIT,
        joint_pitch_limit: float = DEFAULT_JOINT_PITCH_LIMIT,
        anchor_key: int | None = None,
    ) -> Morphology:
        """This morphology with a flexible spine (thesis §4.2).

        ``joint_rest``: ``(J, 3)`` spine joints in the body frame, from the head (0) to the
        back. Without ``key_joint``/``leg_key`` the virtual pelvis nodes are found from the
        legs (each leg hangs from the spine joint nearest its hip; ``SpineModel.from_legs``);
        otherwise ``key_joint`` ``(K,)`` lists the joints that are nodes (0 first, ``J - 1``
        last) and ``leg_key`` ``(n,)`` the node of each leg. ``leg_bone`` ``(n,)``: the spine
        bone each hip rides with (see ``SpineModel``). Limits are per joint, in radians.
        Raises :class:`MorphologyError` for a spine that cannot carry these legs.
        """
        try:
            if key_joint is None or leg_key is None:
                model = SpineModel.from_legs(
                    joint_rest, self.hip_offset, self.rest_foot, joint_yaw_limit=joint_yaw_limit,
                    joint_pitch_limit=joint_pitch_limit, anchor_key=anchor_key,
                )
            else:
                model = SpineModel.build(
                    joint_rest, key_joint, leg_key, self.hip_offset, self.rest_foot,
                    joint_yaw_limit=joint_yaw_limit, joint_pitch_limit=joint_pitch_limit,
                    anchor_key=anchor_key, leg_bone=leg_bone,
                )
        except ValueError as err:
            raise MorphologyError(f"spine: {err}") from None
        return replace(self, spine=model, pelvis_node=model.leg_key.copy())

    def leg_index(self, label: str) -> int:
        try:
            return self.labels.index(label)
        except ValueError:
            raise MorphologyError(f"no leg labelled {label!r} (legs: {', '.join(self.labels)})") from None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_rest_joints(
        cls,
        rest_joints: Sequence[npt.ArrayLike],
        labels: Sequence[str] | None = None,
        *,
        plane_normal: npt.ArrayLike | None = None,
        joint_min: npt.ArrayLike | None = None,
        joint_max: npt.ArrayLike | None = None,
        yaw_weight: npt.ArrayLike | None = None,
        pelvis_node: npt.ArrayLike | None = None,
        body_box: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        body_thickness: float | None = None,
        foot_half_extents: npt.ArrayLike | None = None,
        hinge_margin: float = np.radians(160.0),
        sole_half_extents: npt.ArrayLike | None = None,
        foot_lift: npt.ArrayLike | None = None,
    ) -> Morphology:
        """Build a morphology from each leg's rest joint chain (hip first, end effector last).

        ``rest_joints[i]`` is a ``(k_i + 1, 3)`` array in the body frame. Missing values are
        derived from the rest pose:

        - ``plane_normal``: from the bend of the chain; a straight leg bends like a knee
          (forward axis crossed with the leg direction), a splayed straight leg in the
          vertical plane through it. A rest chain that is not quite planar is allowed: the
          IK keeps every bone length and poses the leg in its plane.
        - joint limits: the hip pitch may move +-100 degrees around its rest value; every
          hinge keeps the sign of its rest bend (knees never bend backwards) and may open
          up to ``hinge_margin``.
        - ``yaw_weight``: 1 for legs whose rest foot is far from under the hip horizontally
          (more than half the leg's reach), 0 otherwise, with a smooth ramp between.
        - ``body_box``: ``(center (2,), half (2,))``; default the box around the hips.
        - ``body_thickness``: the pelvis height above the mean rest foot height.
        - ``foot_half_extents``: 4 % of the mean leg length, square.
        - ``sole_half_extents``: None (other feet are kept a foot box away).
        - ``foot_lift``: None (every end-effector on the ground).
        """
        chains = [np.asarray(c, dtype=np.float64) for c in rest_joints]
        n = len(chains)
        if n == 0:
            raise MorphologyError("a character needs at least one leg")
        for i, c in enumerate(chains):
            if c.ndim != 2 or c.shape[1] != 3 or c.shape[0] < 2:
                raise MorphologyError(f"leg {i}: rest joints must be a (k + 1, 3) array with k >= 1")
            if not np.all(np.isfinite(c)):
                raise MorphologyError(f"leg {i}: rest joints are not finite")
        labels_t = tuple(labels) if labels is not None else leg_labels(n)
        if len(labels_t) != n:
            raise MorphologyError(f"{len(labels_t)} labels for {n} legs")
        if len(set(labels_t)) != n:
            raise MorphologyError(f"leg labels are not unique: {labels_t}")

        n_seg = np.array([c.shape[0] - 1 for c in chains], dtype=np.int64)
        s = int(n_seg.max())
        joints = np.zeros((n, s + 1, 3))
        for i, c in enumerate(chains):
            joints[i, : c.shape[0]] = c
            joints[i, c.shape[0] :] = c[-1]
        seg = np.linalg.norm(np.diff(joints, axis=1), axis=2)
        for i in range(n):
            lengths = seg[i, : n_seg[i]]
            if np.any(lengths < 1e-9):
                j = int(np.argmax(lengths < 1e-9))
                raise MorphologyError(f"leg {labels_t[i]}: segment {j} has zero length")

        hip = joints[:, 0]
        foot = joints[np.arange(n), n_seg]
        reach = seg.sum(axis=1)
        to_foot = foot - hip
        horizontal = np.linalg.norm(to_foot[:, :2], axis=1)

        if yaw_weight is None:
            ratio = horizontal / reach
            yaw_w = np.clip((ratio - 0.3) / 0.3, 0.0, 1.0)
            yaw_w = yaw_w * yaw_w * (3.0 - 2.0 * yaw_w)
        else:
            yaw_w = np.broadcast_to(np.asarray(yaw_weight, dtype=np.float64), (n,)).copy()

        if plane_normal is None:
            normal = _default_plane_normals(joints, n_seg, yaw_w)
        else:
            normal = _unit(np.broadcast_to(np.asarray(plane_normal, dtype=np.float64), (n, 3)).copy())
            if np.any(np.linalg.norm(normal, axis=1) < 0.5):
                raise MorphologyError("plane normals must be non-zero")
        rest = chain_angles(joints, normal, np.broadcast_to(_UP, (n, 3)), n_seg)
        valid = np.arange(s)[None, :] < n_seg[:, None]
        if joint_min is None or joint_max is None:
            lo, hi = _default_limits(rest, n_seg, hinge_margin)
            if joint_min is not None:
                lo = np.broadcast_to(np.asarray(joint_min, dtype=np.float64), (n, s)).copy()
            if joint_max is not None:
                hi = np.broadcast_to(np.asarray(joint_max, dtype=np.float64), (n, s)).copy()
        else:
            lo = np.broadcast_to(np.asarray(joint_min, dtype=np.float64), (n, s)).copy()
            hi = np.broadcast_to(np.asarray(joint_max, dtype=np.float64), (n, s)).copy()
        lo = np.where(valid, lo, 0.0)
        hi = np.where(valid, hi, 0.0)
        if np.any(hi < lo):
            raise MorphologyError("joint_max is below joint_min for some joint")

        node = (
            np.zeros(n, dtype=np.int64)
            if pelvis_node is None
            else np.broadcast_to(np.asarray(pelvis_node, dtype=np.int64), (n,)).copy()
        )

        if body_box is None:
            lo_xy = hip[:, :2].min(axis=0)
            hi_xy = hip[:, :2].max(axis=0)
            margin = 0.1 * float(reach.mean())
            center = 0.5 * (lo_xy + hi_xy)
            half = 0.5 * (hi_xy - lo_xy) + margin
        else:
            center = np.asarray(body_box[0], dtype=np.float64).reshape(2)
            half = np.abs(np.asarray(body_box[1], dtype=np.float64).reshape(2))
        thickness = float(-foot[:, 2].mean()) if body_thickness is None else float(body_thickness)
        if thickness <= 0.0:
            raise MorphologyError("body thickness (pelvis height above the ground) must be positive")
        foot_half = (
            np.full(2, 0.04 * float(reach.mean()))
            if foot_half_extents is None
            else np.abs(np.asarray(foot_half_extents, dtype=np.float64).reshape(2))
        )

        return cls(
            labels=labels_t,
            rest_joints=joints,
            n_segments=n_seg,
            segment_lengths=np.where(valid, seg, 0.0),
            plane_normal=normal,
            joint_min=lo,
            joint_max=hi,
            yaw_weight=yaw_w,
            pelvis_node=node,
            body_box_center=center,
            body_box_half=half,
            body_thickness=thickness,
            foot_half_extents=foot_half,
            sole_half_extents=None if sole_half_extents is None
            else np.abs(np.asarray(sole_half_extents, dtype=np.float64).reshape(2)),
            foot_lift=None if foot_lift is None else np.asarray(foot_lift, dtype=np.float64).reshape(n),
        )


def _default_plane_normals(joints: FloatArray, n_seg: IntArray, yaw_w: FloatArray) -> FloatArray:
    """Leg-plane normals from the rest bend, with sensible choices for straight legs."""
    n = joints.shape[0]
    hip = joints[:, 0]
    foot = joints[np.arange(n), n_seg]
    to_foot = foot - hip
    # sum of consecutive-segment cross products: the bend direction of the chain
    seg = np.diff(joints, axis=1)
    bend = np.cross(seg[:, :-1], seg[:, 1:]).sum(axis=1) if seg.shape[1] > 1 else np.zeros((n, 3))
    # straight leg: splayed legs bend in the vertical plane through them, others like a knee
    # in the plane of the forward axis and the leg
    vertical_plane = np.cross(_UP, to_foot)
    knee_plane = np.cross(np.array([1.0, 0.0, 0.0]), to_foot)
    straight = np.where((yaw_w > 0.5)[:, None], vertical_plane, knee_plane)
    normal = np.where(
        (np.linalg.norm(bend, axis=1) > 1e-9 * np.linalg.norm(to_foot, axis=1) ** 2)[:, None], bend, straight
    )
    # the hip-to-foot line must be in the plane: remove any component of the normal along it
    d = _unit(to_foot)
    normal = normal - np.einsum("ij,ij->i", normal, d)[:, None] * d
    return _unit(normal, fallback=np.array([0.0, 1.0, 0.0]))


def _default_limits(rest: FloatArray, n_seg: IntArray, hinge_margin: float) -> tuple[FloatArray, FloatArray]:
    n, s = rest.shape
    lo = np.zeros((n, s))
    hi = np.zeros((n, s))
    lo[:, 0] = rest[:, 0] - np.radians(100.0)
    hi[:, 0] = rest[:, 0] + np.radians(100.0)
    if s > 1:
        hinge = rest[:, 1:]
        positive = hinge >= 0.0
        lo[:, 1:] = np.where(positive, 0.0, -hinge_margin)
        hi[:, 1:] = np.where(positive, hinge_margin, 0.0)
        # a hinge bent beyond the margin at rest keeps its rest angle reachable
        lo[:, 1:] = np.minimum(lo[:, 1:], hinge)
        hi[:, 1:] = np.maximum(hi[:, 1:], hinge)
    valid = np.arange(s)[None, :] < n_seg[:, None]
    return np.where(valid, lo, 0.0), np.where(valid, hi, 0.0)


def plane_axes(normal: FloatArray, up: FloatArray) -> tuple[FloatArray, FloatArray]:
    """In-plane axes ``(a, b)`` of leg planes: ``b`` is ``up`` projected into the plane,
    ``a = b x normal`` (so ``a x b = normal``). Shapes ``(..., 3)`` (``up`` may be one ``(3,)``).

    A plane whose normal is ``up`` itself (a horizontal leg plane) takes the x axis as ``a``.
    """
    b = up - np.add.reduce(up * normal, axis=-1)[..., None] * normal
    b_norm = vector_norm(b, keepdims=True)
    horizontal_plane = b_norm[..., 0] < 1e-9
    if np.count_nonzero(horizontal_plane):
        alt = cross(normal, np.array([1.0, 0.0, 0.0]))
        b = np.where(horizontal_plane[..., None], alt, b)
        b_norm = vector_norm(b, keepdims=True)
    b = b / b_norm
    a = cross(b, normal)
    return a, b


def chain_angles(joints: FloatArray, normal: FloatArray, up: FloatArray, n_segments: IntArray) -> FloatArray:
    """Joint angles ``(n, s)`` of planar chains ``joints: (n, s + 1, 3)`` (hip first).

    Angle 0 is the first segment's direction in the plane (from axis ``a`` toward ``b`` of
    ``plane_axes``), angle j > 0 the turn from segment j - 1 to segment j, in (-pi, pi].
    Padded segments get 0.
    """
    a, b = plane_axes(normal, up)
    seg = np.diff(joints, axis=1)
    ca = np.einsum("nkj,nj->nk", seg, a)
    cb = np.einsum("nkj,nj->nk", seg, b)
    absolute = np.arctan2(cb, ca)
    rel = np.empty_like(absolute)
    rel[:, 0] = absolute[:, 0]
    rel[:, 1:] = np.diff(absolute, axis=1)
    rel[:, 1:] = (rel[:, 1:] + np.pi) % (2.0 * np.pi) - np.pi
    valid = np.arange(seg.shape[1])[None, :] < n_segments[:, None]
    return np.where(valid, rel, 0.0)


def _read_only(a: FloatArray) -> FloatArray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class LegBatch:
    """Legs of many characters on one flat axis of ``N`` legs (the IK/gait/physics axis).

    Per-leg arrays have the same meaning as in ``Morphology`` with a leading ``N`` axis and
    ``s`` = the longest leg of any character. ``leg_char[k]`` is the character of leg ``k``,
    ``leg_slice[c]`` its legs' range (legs of a character are contiguous, in its label order).
    """

    morphologies: tuple[Morphology, ...]
    leg_char: IntArray
    leg_start: IntArray
    rest_joints: FloatArray
    n_segments: IntArray
    segment_lengths: FloatArray
    plane_normal: FloatArray
    joint_min: FloatArray
    joint_max: FloatArray
    yaw_weight: FloatArray
    pelvis_node: IntArray
    rest_angles: FloatArray

    @property
    def n_chars(self) -> int:
        return len(self.morphologies)

    @property
    def n_legs(self) -> int:
        return int(self.leg_char.shape[0])

    @property
    def max_segments(self) -> int:
        return int(self.segment_lengths.shape[1])

    @property
    def hip_offset(self) -> FloatArray:
        return self.rest_joints[:, 0]

    # (the derived arrays below are made once and read only: a step asks for them a few
    # dozen times)
    @functools.cached_property
    def rest_foot(self) -> FloatArray:
        return _read_only(self.rest_joints[np.arange(self.n_legs), self.n_segments])

    @functools.cached_property
    def foot_lift(self) -> FloatArray:
        """``(N,)`` each end-effector's height above the ground its foot is planned on
        (``Morphology.foot_lift``; 0 where a character has none)."""
        return _read_only(np.concatenate([np.zeros(m.n_legs) if m.foot_lift is None else m.foot_lift
                                          for m in self.morphologies]))

    @functools.cached_property
    def leg_length(self) -> FloatArray:
        return _read_only(self.segment_lengths.sum(axis=1))

    def leg_slice(self, char: int) -> slice:
        return slice(int(self.leg_start[char]), int(self.leg_start[char + 1]))

    @classmethod
    def stack(cls, morphologies: Sequence[Morphology]) -> LegBatch:
        morphs = tuple(morphologies)
        if not morphs:
            raise MorphologyError("no characters")
        s = max(m.max_segments for m in morphs)

        def pad(arr: FloatArray, width: int, axis_len: int) -> FloatArray:
            if arr.shape[1] == axis_len:
                return arr
            extra = axis_len - arr.shape[1]
            if arr.ndim == 3:  # joints: repeat the last row
                return np.concatenate([arr, np.repeat(arr[:, -1:], extra, axis=1)], axis=1)
            return np.concatenate([arr, np.zeros((arr.shape[0], extra))], axis=1)

        counts = np.array([m.n_legs for m in morphs], dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return cls(
            morphologies=morphs,
            leg_char=np.repeat(np.arange(len(morphs), dtype=np.int64), counts),
            leg_start=start,
            rest_joints=np.concatenate([pad(m.rest_joints, 3, s + 1) for m in morphs]),
            n_segments=np.concatenate([m.n_segments for m in morphs]),
            segment_lengths=np.concatenate([pad(m.segment_lengths, 2, s) for m in morphs]),
            plane_normal=np.concatenate([m.plane_normal for m in morphs]),
            joint_min=np.concatenate([pad(m.joint_min, 2, s) for m in morphs]),
            joint_max=np.concatenate([pad(m.joint_max, 2, s) for m in morphs]),
            yaw_weight=np.concatenate([m.yaw_weight for m in morphs]),
            pelvis_node=np.concatenate([m.pelvis_node for m in morphs]),
            rest_angles=np.concatenate([pad(m.rest_angles, 2, s) for m in morphs]),
        )


# ---------------------------------------------------------------------- example creatures
def _radial_leg(
    hip: FloatArray, direction_deg: float, lengths: Sequence[float], pitches_deg: Sequence[float]
) -> FloatArray:
    """A leg chain from ``hip`` in the vertical plane at ``direction_deg`` (from +x, ccw),
    each segment pitched ``pitches_deg`` (absolute, up positive)."""
    yaw = np.radians(direction_deg)
    out_dir = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    pts = [np.asarray(hip, dtype=np.float64)]
    for length, pitch in zip(lengths, pitches_deg, strict=True):
        p = np.radians(pitch)
        pts.append(pts[-1] + length * (np.cos(p) * out_dir + np.sin(p) * _UP))
    return np.array(pts)


def spider(scale: float = 1.0) -> Morphology:
    """An eight-legged spider-like creature, three segments per leg (femur, tibia, tarsus).

    Body about ``0.4 * scale`` long; legs about ``0.52 * scale`` long, pelvis
    ``0.18 * scale`` above the ground at rest.
    """
    rows_x = np.array([0.12, 0.04, -0.04, -0.12]) * scale
    angles = [50.0, 75.0, 105.0, 130.0]
    chains = []
    for x, ang in zip(rows_x, angles, strict=True):
        for side in (1.0, -1.0):
            hip = np.array([x, side * 0.06 * scale, 0.0])
            chains.append(
                _radial_leg(hip, side * ang, [0.18 * scale, 0.2 * scale, 0.14 * scale], [35.0, -40.0, -75.0])
            )
    chains = [_drop_to_ground(c, 0.18 * scale) for c in chains]
    return Morphology.from_rest_joints(
        chains,
        leg_labels(8),
        body_box=(np.zeros(2), np.array([0.16, 0.08]) * scale),
        foot_half_extents=np.array([0.015, 0.015]) * scale,
    )


def hexapod(scale: float = 1.0) -> Morphology:
    """A six-legged insect-like creature, three segments per leg (coxa, femur, tibia)."""
    rows_x = np.array([0.1, 0.0, -0.1]) * scale
    angles = [55.0, 90.0, 125.0]
    chains = []
    for x, ang in zip(rows_x, angles, strict=True):
        for side in (1.0, -1.0):
            hip = np.array([x, side * 0.04 * scale, 0.0])
            chains.append(
                _radial_leg(hip, side * ang, [0.05 * scale, 0.12 * scale, 0.14 * scale], [0.0, 30.0, -65.0])
            )
    chains = [_drop_to_ground(c, 0.12 * scale) for c in chains]
    return Morphology.from_rest_joints(
        chains,
        leg_labels(6),
        body_box=(np.zeros(2), np.array([0.15, 0.05]) * scale),
        foot_half_extents=np.array([0.01, 0.01]) * scale,
    )


def pentapod(scale: float = 1.0) -> Morphology:
    """A five-legged star robot (thesis figure 3.37): one front leg ``M1`` on the midline,
    then ``L2, R2, L3, R3``; two segments per leg."""
    angles = [0.0, 72.0, -72.0, 144.0, -144.0]
    chains = []
    for ang in angles:
        yaw = np.radians(ang)
        hip = 0.12 * scale * np.array([np.cos(yaw), np.sin(yaw), 0.0])
        chains.append(_radial_leg(hip, ang, [0.2 * scale, 0.24 * scale], [40.0, -75.0]))
    chains = [_drop_to_ground(c, 0.16 * scale) for c in chains]
    return Morphology.from_rest_joints(
        chains,
        leg_labels(5, midline=(1,)),
        body_box=(np.zeros(2), np.array([0.14, 0.14]) * scale),
        foot_half_extents=np.array([0.02, 0.02]) * scale,
    )


def quadruped(scale: float = 1.0, spine: bool = False) -> Morphology:
    """A dog-like quadruped: front legs three segments (upper arm, forearm, hand), hind legs
    three segments (thigh, shin, tarsus); feet under the hips, knees forward, hocks back.

    ``spine``: with a flexible spine of 7 joints (head and neck carried forward and up,
    shoulders, back, hips): 3 virtual pelvis nodes (head, shoulders, hips), as the thesis's
    wolf (§4.4)."""
    front = [
        np.array([0.3, 0.1, 0.0]),
        np.array([0.24, 0.1, -0.19]),
        np.array([0.3, 0.1, -0.38]),
        np.array([0.31, 0.1, -0.46]),
    ]
    hind = [
        np.array([-0.3, 0.1, 0.0]),
        np.array([-0.22, 0.1, -0.18]),
        np.array([-0.36, 0.1, -0.33]),
        np.array([-0.33, 0.1, -0.46]),
    ]
    front = [p * scale for p in front]
    hind = [p * scale for p in hind]
    mirror = [np.array([1.0, side, 1.0]) for side in (1.0, -1.0)]
    chains = [np.array([p * m for p in leg]) for leg in (front, hind) for m in mirror]
    body = Morphology.from_rest_joints(
        chains,
        leg_labels(4),
        body_box=(np.zeros(2), np.array([0.4, 0.12]) * scale),
        foot_half_extents=np.array([0.03, 0.025]) * scale,
    )
    if not spine:
        return body
    xs = np.array([0.6, 0.45, 0.3, 0.15, 0.0, -0.15, -0.3])
    joints = np.column_stack([xs, np.zeros(7), np.array([0.1, 0.03, 0, 0, 0, 0, 0])]) * scale
    return body.with_spine(joints)


def lizard(scale: float = 1.0, spine: bool = True) -> Morphology:
    """A sprawling lizard (thesis figure 4.15): four legs of three segments reaching out to
    the sides, and (``spine``) a spine of 9 joints with 3 virtual pelvis nodes (head,
    shoulders, hips). About 0.6 × scale long from the snout to the hips."""
    chains = []
    for x, azimuth in ((0.14, 70.0), (-0.14, 105.0)):
        for side in (1.0, -1.0):
            hip = np.array([x, side * 0.04, 0.0]) * scale
            lengths = [0.09 * scale, 0.085 * scale, 0.06 * scale]
            chain = _radial_leg(hip, side * azimuth, lengths, [12.0, -45.0, -80.0])
            chains.append(_drop_to_ground(chain, 0.09 * scale))
    body = Morphology.from_rest_joints(
        chains,
        leg_labels(4),
        body_box=(np.zeros(2), np.array([0.3, 0.06]) * scale),
        foot_half_extents=np.array([0.015, 0.015]) * scale,
    )
    if not spine:
        return body
    xs = np.linspace(0.45, -0.14, 9)
    joints = np.column_stack([xs, np.zeros(9), np.zeros(9)]) * scale
    joints[0, 2] = 0.01 * scale
    return body.with_spine(joints)


def biped(scale: float = 1.0) -> Morphology:
    """A human-like biped: thigh and shin (the end effector is the ankle), knees forward."""
    chains = [
        np.array([[0.0, side * 0.1, 0.0], [0.14, side * 0.1, -0.41], [0.0, side * 0.1, -0.8]]) * scale
        for side in (1.0, -1.0)
    ]
    return Morphology.from_rest_joints(
        chains,
        leg_labels(2),
        body_box=(np.zeros(2), np.array([0.12, 0.16]) * scale),
        foot_half_extents=np.array([0.12, 0.05]) * scale,
    )


def _drop_to_ground(chain: FloatArray, height: float) -> FloatArray:
    """Scale the vertical extent of a chain's last segment so its tip is at z = -height."""
    out = chain.copy()
    dz = -height - out[-1, 2]
    out[-1, 2] += dz
    return out
