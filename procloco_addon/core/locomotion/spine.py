# SPDX-License-Identifier: GPL-3.0-or-later
"""Flexible spine: virtual pelvis nodes joined by a spine curve (thesis §4.2, §4.4).

A quadruped or a lizard does not turn like a plank. Its body is split into *virtual pelvis
nodes* ("key nodes" here): the head node, which carries no legs, then one node per girdle
(shoulders, hips, ...), each carrying the legs attached to it. The real spine joints of the
rig lie on a chain from the head node to the back node. Every step runs the thesis's four
steps, vectorised over ``C`` characters stepped together as one :class:`SpineBatch`: their
spines share one structure (joints, key nodes, the legs on them), each with its own rest
geometry (:class:`SpineModel`: a rig's size and proportions) and settings
(:class:`SpineParams`), so a herd of wolves of different sizes costs the array operations of
one.

1. **Orientation** (§4.2.1, :func:`plan_spine`): the head turns toward the wanted heading
   (at most ``turn_rate``). The turn is absorbed front to back: each key node bends as far as
   its yaw limit allows and passes the rest on; when every node is at its limit the whole
   spine rotates about the node just behind the head.
2. **Advancing** (§4.2.2): the head moves forward by the step's distance; every other key node
   is put back on the previous spine (the support), at its own chord length from the node in
   front, so the body follows the head's path. Bends beyond the limits are clamped and the
   back node's bend relaxes exponentially over ``relax_time``.
3. **Elevation and pitch** (§4.2.3): each key node gets a height (the upper hull of the
   ground under its part of the body plus its rest height; :func:`terrain_guides`, to which
   the controller adds the pseudo-physics) and a pitch: the environment pitch averaged with
   the pitch its feet induce (:func:`node_pitch`). The visual yaw of §4.4 (the lizard) turns
   each node's tangent by the mean angle of its feet away from their rest directions
   (:func:`visual_yaw`).
4. **Final 3D spine** (§4.2.4, :func:`build_spine`): a Hermite curve (``core.hermite``)
   through the 3D key nodes along their tangents is sampled at the bones' lengths; each bone
   turns from its rest direction by the turn of the curve over its own stretch, and the joint
   chain is rebuilt from the anchor node with the exact bone lengths, every joint within its
   yaw/pitch limits. When the legs cannot reach their footprints, :func:`refit` and
   :func:`repeat_for_reach` run step 4 again on guides moved to where the legs can hold them
   (with the tangents of the first build: only the guides move).

:func:`spine_step` chains the four steps. Shapes: ``C`` characters, ``K`` key nodes (head
first), ``J`` spine joints (head first), ``L`` legs. Angles in radians; a heading is the
angle of the forward axis from world +X, counter-clockwise; pitch is positive nose up. The
body frame is x forward, y left, z up; rest positions are in it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields

import numpy as np
import numpy.typing as npt

from ..geometry import vector_norm, wrap_angle, z_rotations
from ..hermite import HERMITE_MATRIX, hermite_basis
from ..hull import upper_hull_eval
from ..world.terrain import NO_SURFACE

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: A terrain height query: world ``xy`` ``(n, 2)`` -> ground height ``(n,)``, such as
#: ``core.world.terrain.Environment.height_at``; heights at or below ``NO_SURFACE / 2`` are holes.
HeightFn = Callable[[FloatArray], FloatArray]

_CURVE_SAMPLES = 25  # dense samples per key segment for arc-length lookups
_CURVE_S = np.linspace(0.0, 1.0, _CURVE_SAMPLES)
_CURVE_BASIS = hermite_basis(_CURVE_S)  # (m, 4), the same for every curve
_CURVE_STEP = float(_CURVE_S[1] - _CURVE_S[0])
_CURVE_STEP_BASIS = _CURVE_BASIS[1:] - _CURVE_BASIS[:-1]  # (m - 1, 4): from one sample to the next
_POWERS = np.array([3.0, 2.0, 1.0, 0.0])  # s³, s², s, 1
#: ``(i - 1) * _CURVE_STEP`` at ``i`` (from 1): the parameter of the dense sample before sample ``i``
_CURVE_S_BEFORE = np.concatenate([[0.0], np.arange(_CURVE_SAMPLES - 1) * _CURVE_STEP])
_ONES3 = np.ones(3)  # a product with it sums the x, y, z of vectors (in that order)
_EPS = 1e-12
_TWO_PI = 2.0 * np.pi
DEFAULT_JOINT_YAW_LIMIT = float(np.radians(25.0))
DEFAULT_JOINT_PITCH_LIMIT = float(np.radians(20.0))

# A step of a spine character is a few hundred array operations on arrays of a handful of
# elements, where each call costs more than its arithmetic: the helpers below do what the
# numpy conveniences do (np.clip, wrap_angle, np.concatenate of pads, np.linspace) with
# fewer calls, and everything that depends on the rest pose alone is computed once per
# batch (SpineBatch).


def _wrap(a: FloatArray) -> FloatArray:
    """``wrap_angle`` of a float array (the same arithmetic, without its conversions)."""
    return np.asarray(np.mod(a + np.pi, _TWO_PI) - np.pi)


def _clamp(a: FloatArray, lo: npt.ArrayLike, hi: npt.ArrayLike) -> FloatArray:
    """``np.clip`` without its dispatch (the bounds broadcast against ``a``)."""
    return np.asarray(np.minimum(np.maximum(a, lo), hi))


def _turn_xy(v: FloatArray, angle: FloatArray) -> FloatArray:
    """2-vectors ``v (..., 2)`` turned by ``angle`` (broadcast against ``v[..., 0]``),
    written out (a 2x2 rotation's products and sums, in the order a matrix product takes)."""
    c, s = np.cos(angle), np.sin(angle)
    x, y = v[..., 0], v[..., 1]
    turned_x = c * x - s * y
    out = np.empty((*turned_x.shape, 2))
    out[..., 0] = turned_x
    out[..., 1] = s * x + c * y
    return out


def _rotate_about(points: FloatArray, centre: FloatArray, angle: FloatArray) -> FloatArray:
    """Rotate ``points`` ``(C, n, 2)`` about ``centre`` ``(C, 2)`` by ``angle`` ``(C,)``
    (:func:`_turn_xy`'s arithmetic, each coordinate written into the result)."""
    rel = points - centre[:, None, :]
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    x, y = rel[..., 0], rel[..., 1]
    out = np.empty_like(rel)
    turned_x, turned_y = out[..., 0], out[..., 1]
    np.multiply(c, x, out=turned_x)
    turned_x -= s * y
    np.multiply(s, x, out=turned_y)
    turned_y += c * y
    out += centre[:, None, :]
    return out


def _segment_angles(key_xy: FloatArray) -> FloatArray:
    """Forward direction of each key segment ``(C, K - 1)``: from node ``i + 1`` to node ``i``."""
    d = key_xy[:, :-1, :] - key_xy[:, 1:, :]
    return np.arctan2(d[..., 1], d[..., 0])


def _bend_at(key_xy: FloatArray, i: int) -> FloatArray:
    """The bend ``(C,)`` at inner key node ``i``: the turn from the segment behind it to the
    one in front (positive to the left), from those two segments alone."""
    d = key_xy[:, i - 1:i + 1, :] - key_xy[:, i:i + 2, :]
    a = np.arctan2(d[..., 1], d[..., 0])
    return _wrap(a[:, 0] - a[:, 1])


def _headings_and_bends(seg_angle: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Heading ``(C, K)`` and bend ``(C, K)`` of every key node from its segments' angles.

    The bend is the turn from the segment behind to the one in front (positive to the left;
    zero at the head and the back node). The heading is the bisector of the node's two
    segments; the two end nodes turn from their segment by half the next node's bend, as on
    a circular arc through three nodes, so a bent spine has no kink in its tangents at the
    ends."""
    c, n_seg = seg_angle.shape
    inner = _wrap(seg_angle[:, :-1] - seg_angle[:, 1:])  # (C, K - 2)
    bend = np.zeros((c, n_seg + 1))
    bend[:, 1:-1] = inner
    half = 0.5 * inner
    heading = np.empty((c, n_seg + 1))
    heading[:, 1:-1] = seg_angle[:, 1:] + half
    if n_seg > 1:
        heading[:, 0] = seg_angle[:, 0] + half[:, 0]
        heading[:, -1] = seg_angle[:, -1] - half[:, -1]
    else:
        heading[:, 0] = seg_angle[:, 0]
        heading[:, -1] = seg_angle[:, -1]
    return _wrap(heading), bend


# The rotations are written element by element into one array (not stacked from rows): a
# character's step builds a few thousand of them and the stacking was a tenth of its time.
_rz = z_rotations


def _ry(angle: FloatArray) -> FloatArray:
    """Rotations ``(..., 3, 3)`` about Y by ``angle`` ``(...)``."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((*np.shape(angle), 3, 3))
    out[..., 0, 0] = c
    out[..., 0, 2] = s
    out[..., 1, 1] = 1.0
    out[..., 2, 0] = -s
    out[..., 2, 2] = c
    return out


def frame_from_yaw_pitch(yaw: npt.ArrayLike, pitch: npt.ArrayLike) -> FloatArray:
    """Body-to-world rotations ``(..., 3, 3)``: heading ``yaw`` then nose-up ``pitch``
    (``Rz(yaw) @ Ry(-pitch)`` written out: its products with the zeros vanish)."""
    y = np.asarray(yaw, dtype=np.float64)
    p = np.asarray(pitch, dtype=np.float64)
    cy, sy = np.cos(y), np.sin(y)
    cp, sp = np.cos(p), np.sin(p)
    shape = y.shape if y.shape == p.shape else np.broadcast_shapes(y.shape, p.shape)
    out = np.empty((*shape, 3, 3))
    out[..., 0, 0] = cy * cp
    out[..., 0, 1] = -sy
    out[..., 0, 2] = -cy * sp
    out[..., 1, 0] = sy * cp
    out[..., 1, 1] = cy
    out[..., 1, 2] = -sy * sp
    out[..., 2, 0] = sp
    out[..., 2, 1] = 0.0
    out[..., 2, 2] = cp
    return out


def _direction(yaw: FloatArray, pitch: FloatArray) -> FloatArray:
    """Unit vectors ``(..., 3)`` at heading ``yaw`` and elevation ``pitch`` (same shapes)."""
    cp = np.cos(pitch)
    out = np.empty((*np.shape(pitch), 3))
    out[..., 0] = cp * np.cos(yaw)
    out[..., 1] = cp * np.sin(yaw)
    out[..., 2] = np.sin(pitch)
    return out


def _as_shape(a: npt.ArrayLike, shape: tuple[int, ...]) -> FloatArray:
    """``a`` as float64 broadcast to ``shape`` (itself when it already is: no broadcast_to)."""
    arr = np.asarray(a, dtype=np.float64)
    return arr if arr.shape == shape else np.broadcast_to(arr, shape)


def _yaw_pitch(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    return np.arctan2(v[..., 1], v[..., 0]), np.arctan2(v[..., 2], np.hypot(v[..., 0], v[..., 1]))


_UNIT_SAMPLES: dict[int, FloatArray] = {}


def _unit_samples(n: int) -> FloatArray:
    """``np.linspace(0, 1, n)``, made once per ``n``."""
    u = _UNIT_SAMPLES.get(n)
    if u is None:
        u = _UNIT_SAMPLES[n] = np.linspace(0.0, 1.0, n)
    return u


# ----------------------------------------------------------------------------- the model


@dataclass(frozen=True, eq=False)
class SpineModel:
    """A rig's spine in its rest pose (body frame); characters step through the spine
    functions as a :class:`SpineBatch` of these (with their settings).

    - ``joint_rest``: ``(J, 3)`` spine joints from the head (0) to the back node (J - 1).
    - ``key_joint``: ``(K,)`` the joints that are virtual pelvis nodes, increasing, starting at
      0 (the head node) and ending at ``J - 1`` (the back node).
    - ``leg_key``: ``(L,)`` the key node each leg hangs from (never 0: the head has no legs).
    - ``hip_rest``, ``foot_rest``: ``(L, 3)`` rest hip and foot positions.
    - ``node_yaw_limit``: ``(K,)`` how far each key node may bend sideways (head and back
      entries unused).
    - ``joint_yaw_limit``, ``joint_pitch_limit``: ``(J,)`` how far the turn between the two
      bones at each joint may move away from its rest value (end entries unused).
    - ``anchor_key``: the key node whose final position is exactly its guide; the chain is
      rebuilt from there in both directions (normally the rig's root, the hips).
    - ``slice_margin``: how far past the head and the back node the ground is sampled.
    - ``leg_bone``: ``(L,)`` optional: the spine bone each leg's hip rides with (bone ``b``
      joins joints ``b`` and ``b + 1``; the hip turns with its rotation about joint ``b + 1``,
      the bone's end toward the back, as a rig's child bone turns with its parent); ``-1``
      (the default) makes the hip ride with the frame of its key node instead.

    Derived (filled in by the constructor): ``bone_length`` ``(J - 1,)``, ``bone_dir``
    ``(J - 1, 3)`` (unit, head to back), ``key_chord`` ``(K - 1,)`` horizontal distances
    between key nodes, ``key_rest_height`` ``(K,)`` rest height of each node above its
    feet (above all feet for the head), ``rest_key_pitch`` ``(K,)``, the rest curve samples,
    ``rest_unturn`` ``(J - 1, 3, 3)`` the rotation taking each bone's rest chord direction to
    the x axis, ``joint_at_start``/``joint_at_end`` ``(J,)`` joints at fraction 0 / 1 of
    their key segment, ``leg_key_joint`` ``(L,)`` the joint of each leg's key node,
    ``any_leg_on_bone``, ``hip_pivot_offset`` ``(L, 3)`` each hip from the joint it turns
    about (step 4's per-call constants, computed once).
    """

    joint_rest: FloatArray
    key_joint: IntArray
    leg_key: IntArray
    hip_rest: FloatArray
    foot_rest: FloatArray
    node_yaw_limit: FloatArray
    joint_yaw_limit: FloatArray
    joint_pitch_limit: FloatArray
    anchor_key: int
    slice_margin: float
    leg_bone: IntArray | None = None
    bone_length: FloatArray = field(init=False)
    bone_dir: FloatArray = field(init=False)
    key_chord: FloatArray = field(init=False)
    key_rest_height: FloatArray = field(init=False)
    rest_key_pitch: FloatArray = field(init=False)
    rest_key_heading: FloatArray = field(init=False)
    joint_segment: IntArray = field(init=False)
    joint_fraction: FloatArray = field(init=False)
    rest_chord_yaw: FloatArray = field(init=False)
    rest_chord_pitch: FloatArray = field(init=False)
    leg_pivot: IntArray = field(init=False)
    leg_on_bone: npt.NDArray[np.bool_] = field(init=False)
    leg_bone_row: IntArray = field(init=False)
    rest_unturn: FloatArray = field(init=False)
    leg_key_joint: IntArray = field(init=False)
    any_leg_on_bone: bool = field(init=False)
    hip_pivot_offset: FloatArray = field(init=False)
    joint_at_start: npt.NDArray[np.bool_] = field(init=False)
    joint_at_end: npt.NDArray[np.bool_] = field(init=False)

    @property
    def n_joints(self) -> int:
        return int(self.joint_rest.shape[0])

    @property
    def n_keys(self) -> int:
        return int(self.key_joint.shape[0])

    @property
    def n_legs(self) -> int:
        return int(self.leg_key.shape[0])

    @property
    def key_rest(self) -> FloatArray:
        """``(K, 3)`` rest positions of the key nodes."""
        return self.joint_rest[self.key_joint]

    @property
    def structure(self) -> tuple[object, ...]:
        """What spines stepped together in one :class:`SpineBatch` must share: the key
        joints (so the joint count), the key node each leg hangs from, the bone each leg
        rides with, the anchor node. Sizes, proportions and limits may differ."""
        return (tuple(self.key_joint.tolist()), tuple(self.leg_key.tolist()),
                tuple(np.asarray(self.leg_bone).tolist()), self.anchor_key)

    def __post_init__(self) -> None:
        joints = np.asarray(self.joint_rest, dtype=np.float64)
        key = np.asarray(self.key_joint, dtype=np.int64)
        leg_key = np.asarray(self.leg_key, dtype=np.int64).reshape(-1)
        n_j, n_k, n_l = joints.shape[0], key.shape[0], leg_key.shape[0]
        if joints.ndim != 2 or joints.shape[1] != 3 or n_j < 2 or not np.all(np.isfinite(joints)):
            raise ValueError("joint_rest must be a finite (J >= 2, 3) array")
        if n_k < 2 or key[0] != 0 or key[-1] != n_j - 1 or np.any(np.diff(key) <= 0):
            raise ValueError("key_joint must increase from 0 (the head) to J - 1 (the back node)")
        if n_l and (leg_key.min() < 1 or leg_key.max() >= n_k):
            raise ValueError("every leg must hang from a key node other than the head (1 .. K - 1)")
        bone = np.diff(joints, axis=0)
        length = np.linalg.norm(bone, axis=1)
        if np.any(length < 1e-9):
            raise ValueError(f"spine bone {int(np.argmax(length < 1e-9))} has zero length")
        chord = np.linalg.norm(np.diff(joints[key, :2], axis=0), axis=1)
        if np.any(chord < 1e-6):
            raise ValueError("key nodes must be apart horizontally")
        if not 0 <= self.anchor_key < n_k:
            raise ValueError(f"anchor_key must be in 0 .. {n_k - 1}")

        def per(name: str, value: npt.ArrayLike, n: int) -> FloatArray:
            arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()
            if np.any(arr < 0.0) or not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} must be finite and >= 0")
            return arr

        set_ = object.__setattr__
        carrier = (np.full(n_l, -1, dtype=np.int64) if self.leg_bone is None
                   else np.asarray(self.leg_bone, dtype=np.int64).reshape(-1).copy())
        if carrier.shape != (n_l,) or np.any(carrier < -1) or np.any(carrier >= n_j - 1):
            raise ValueError(f"leg_bone must hold one bone index in -1 .. {n_j - 2} per leg")
        set_(self, "joint_rest", joints)
        set_(self, "key_joint", key)
        set_(self, "leg_key", leg_key)
        set_(self, "leg_bone", carrier)
        set_(self, "leg_pivot", np.where(carrier >= 0, carrier + 1, key[leg_key]).astype(np.int64))
        set_(self, "leg_on_bone", carrier >= 0)
        set_(self, "leg_bone_row", np.maximum(carrier, 0))
        set_(self, "leg_key_joint", key[leg_key])
        set_(self, "any_leg_on_bone", bool(np.any(carrier >= 0)))
        set_(self, "hip_rest", np.asarray(self.hip_rest, dtype=np.float64).reshape(n_l, 3))
        set_(self, "hip_pivot_offset", self.hip_rest - joints[self.leg_pivot])
        set_(self, "foot_rest", np.asarray(self.foot_rest, dtype=np.float64).reshape(n_l, 3))
        set_(self, "node_yaw_limit", per("node_yaw_limit", self.node_yaw_limit, n_k))
        set_(self, "joint_yaw_limit", per("joint_yaw_limit", self.joint_yaw_limit, n_j))
        set_(self, "joint_pitch_limit", per("joint_pitch_limit", self.joint_pitch_limit, n_j))
        set_(self, "bone_length", length)
        set_(self, "bone_dir", bone / length[:, None])
        set_(self, "key_chord", chord)

        key_pos = joints[key]
        feet_z = self.foot_rest[:, 2]
        all_feet = float(feet_z.mean()) if n_l else float(joints[:, 2].min())
        ground = np.array([feet_z[leg_key == k].mean() if np.any(leg_key == k) else all_feet
                           for k in range(n_k)])
        set_(self, "key_rest_height", key_pos[:, 2] - ground)

        # Rest tangent of every key node: central difference of its neighbours (ends: chord).
        seg_angle = _segment_angles(key_pos[None, :, :2])
        set_(self, "rest_key_heading", _headings_and_bends(seg_angle)[0][0])
        fwd = np.empty((n_k, 3))
        fwd[0] = key_pos[0] - key_pos[1]
        fwd[-1] = key_pos[-2] - key_pos[-1]
        fwd[1:-1] = key_pos[:-2] - key_pos[2:]
        set_(self, "rest_key_pitch", np.arctan2(fwd[:, 2], np.hypot(fwd[:, 0], fwd[:, 1])))

        # Where each joint sits on the key curve: its key segment and the fraction of that
        # segment's bone length before it (key joints at fraction 0, the back node at 1).
        seg = np.searchsorted(key, np.arange(n_j), side="right") - 1
        seg = np.minimum(seg, n_k - 2)
        cum = np.concatenate([[0.0], np.cumsum(length)])
        start, end = cum[key[seg]], cum[key[seg + 1]]
        set_(self, "joint_segment", seg.astype(np.int64))
        set_(self, "joint_fraction", (cum - start) / (end - start))
        set_(self, "joint_at_start", self.joint_fraction <= 0.0)
        set_(self, "joint_at_end", self.joint_fraction >= 1.0)

        ends = self.joint_at_start | self.joint_at_end
        rest_samples = _sample_curve(
            key_pos[None], -_direction(self.rest_key_heading[None], self.rest_key_pitch[None]),
            self.joint_segment, self.joint_fraction, ends, self.joint_at_end[ends].astype(np.float64),
        )[0]
        rest_yaw, rest_pitch = _yaw_pitch(np.diff(rest_samples, axis=0))
        set_(self, "rest_chord_yaw", rest_yaw)
        set_(self, "rest_chord_pitch", rest_pitch)
        # Each bone's rest direction turned back to the x axis, the constant right half of
        # step 4's bone rotations: (J - 1, 3, 3).
        set_(self, "rest_unturn", _ry(rest_pitch) @ _rz(-rest_yaw))

    # ------------------------------------------------------------------ construction
    @classmethod
    def build(
        cls,
        joint_rest: npt.ArrayLike,
        key_joint: npt.ArrayLike,
        leg_key: npt.ArrayLike,
        hip_rest: npt.ArrayLike,
        foot_rest: npt.ArrayLike,
        *,
        joint_yaw_limit: npt.ArrayLike = DEFAULT_JOINT_YAW_LIMIT,
        joint_pitch_limit: npt.ArrayLike = DEFAULT_JOINT_PITCH_LIMIT,
        node_yaw_limit: npt.ArrayLike | None = None,
        anchor_key: int | None = None,
        slice_margin: float | None = None,
        leg_bone: npt.ArrayLike | None = None,
    ) -> SpineModel:
        """A spine model with defaults derived from the rest pose.

        ``node_yaw_limit`` defaults to half the summed joint yaw limits of the joints between
        the node's two neighbours (at most 90 degrees): a node's bend is shared by the bones
        around it. ``anchor_key`` defaults to the key node with the most legs (the back-most
        on a tie). ``slice_margin`` defaults to half the mean distance between key nodes.
        """
        joints = np.asarray(joint_rest, dtype=np.float64)
        key = np.asarray(key_joint, dtype=np.int64)
        legs = np.asarray(leg_key, dtype=np.int64).reshape(-1)
        n_j, n_k = joints.shape[0], key.shape[0]
        yaw_lim = np.broadcast_to(np.asarray(joint_yaw_limit, dtype=np.float64), (n_j,))
        if node_yaw_limit is None:
            node_lim = np.zeros(n_k)
            for i in range(1, n_k - 1):
                node_lim[i] = min(0.5 * float(yaw_lim[key[i - 1] + 1: key[i + 1]].sum()), 0.5 * np.pi)
        else:
            node_lim = np.broadcast_to(np.asarray(node_yaw_limit, dtype=np.float64), (n_k,)).copy()
        if anchor_key is None:
            counts = np.bincount(legs, minlength=n_k) if legs.size else np.zeros(n_k, dtype=np.int64)
            anchor_key = int(n_k - 1 - np.argmax(counts[::-1]))
        if slice_margin is None:
            key_xy = joints[key, :2]
            slice_margin = 0.5 * float(np.linalg.norm(np.diff(key_xy, axis=0), axis=1).mean())
        return cls(
            joint_rest=joints,
            key_joint=key,
            leg_key=legs,
            hip_rest=np.asarray(hip_rest, dtype=np.float64),
            foot_rest=np.asarray(foot_rest, dtype=np.float64),
            node_yaw_limit=node_lim,
            joint_yaw_limit=yaw_lim,
            joint_pitch_limit=np.broadcast_to(np.asarray(joint_pitch_limit, dtype=np.float64), (n_j,)),
            anchor_key=int(anchor_key),
            slice_margin=float(slice_margin),
            leg_bone=None if leg_bone is None else np.asarray(leg_bone, dtype=np.int64),
        )

    @classmethod
    def from_legs(
        cls,
        joint_rest: npt.ArrayLike,
        hip_rest: npt.ArrayLike,
        foot_rest: npt.ArrayLike,
        *,
        joint_yaw_limit: float = DEFAULT_JOINT_YAW_LIMIT,
        joint_pitch_limit: float = DEFAULT_JOINT_PITCH_LIMIT,
        anchor_key: int | None = None,
    ) -> SpineModel:
        """A spine model whose key nodes are found from the legs: each leg hangs from the
        spine joint nearest its hip; those joints plus the head (joint 0) are the key nodes.
        The chain is cut after the back-most of them (what lies behind is a tail, animated
        by the pendulums).
        """
        joints = np.asarray(joint_rest, dtype=np.float64)
        hips = np.asarray(hip_rest, dtype=np.float64).reshape(-1, 3)
        nearest = np.argmin(np.linalg.norm(hips[:, None, :] - joints[None, :, :], axis=2), axis=1)
        if np.any(nearest == 0):
            raise ValueError("the spine chain must reach past the front legs to the head: "
                             "a leg hangs from the first spine joint")
        used = np.unique(nearest)
        key = np.concatenate([[0], used]).astype(np.int64)
        leg_key = np.searchsorted(key, nearest).astype(np.int64)
        return cls.build(joints[: int(used.max()) + 1], key, leg_key, hips, foot_rest,
                         joint_yaw_limit=joint_yaw_limit, joint_pitch_limit=joint_pitch_limit,
                         anchor_key=anchor_key)


@dataclass(frozen=True)
class SpineParams:
    """Settings of the spine effect (the user's "Flexible spine" and "Visual yaw" switches).

    - ``flexible``: False turns the body as one rigid piece about its origin (no spine).
    - ``turn_rate``: the head's fastest turn, rad/s.
    - ``relax_time``: time constant (s) of the back node's bend relaxing toward straight.
    - ``foot_pitch_weight``: weight of the feet's induced pitch against the environment pitch
      (0.5 is the thesis's plain average of the two).
    - ``visual_yaw``, ``visual_yaw_gain``, ``max_visual_yaw``: the lizard effect of §4.4.
    """

    flexible: bool = True
    turn_rate: float = np.radians(120.0)
    relax_time: float = 0.6
    foot_pitch_weight: float = 0.5
    visual_yaw: bool = False
    visual_yaw_gain: float = 1.0
    max_visual_yaw: float = np.radians(35.0)

    def __post_init__(self) -> None:
        if self.turn_rate <= 0.0 or self.relax_time <= 0.0:
            raise ValueError("turn_rate and relax_time must be positive")
        if not 0.0 <= self.foot_pitch_weight <= 1.0:
            raise ValueError("foot_pitch_weight must be in [0, 1]")


#: SpineBatch fields with one row per character (the rest of them are the shared structure).
_PER_CHARACTER = (
    "joint_rest", "key_rest", "foot_rest", "anchor_rest", "anchor_rest_xy", "key_chord",
    "key_chord_sq", "key_chord_sum", "node_yaw_limit", "joint_yaw_limit", "joint_pitch_limit",
    "key_rest_height", "rest_key_pitch", "rest_key_heading",
    "rest_head_angle", "joint_fraction", "rest_chord_yaw", "rest_chord_pitch", "rest_unturn",
    "bone_dir", "bone_length", "hip_pivot_offset", "slice_margin", "rest_foot_ahead",
    "rest_foot_depth", "rest_foot_yaw", "yaw_weight", "yaw_weight_sum", "yaw_has", "turn_rate",
    "relax_time", "foot_pitch_weight", "foot_pitch_nodes", "visual_yaw", "visual_yaw_gain",
    "max_visual_yaw", "bone_vector",
)
#: SpineBatch fields ``(2, B, ...)``: one row per character on their second axis.
_PER_CHARACTER_PAIRS = ("rest_chord_turn", "turn_limit")


@dataclass(frozen=True, eq=False)
class SpineBatch:
    """The spines of characters stepped together: one structure, each character's own rest
    geometry and settings. Every spine function takes one.

    Made from one :class:`SpineModel` and :class:`SpineParams` per character (``models``,
    ``params``; :meth:`of` for one model and settings that any number of characters share).
    The models must have the same :attr:`SpineModel.structure` (key joints, the key node and
    bone of each leg, the anchor node) and the settings the same ``flexible``; sizes,
    proportions, limits and the other settings may differ per character.

    Shared (from the structure): ``n_joints``, ``n_keys``, ``n_legs``, ``key_joint (K,)``,
    ``leg_key (L,)``, ``anchor_key``, ``anchor_joint``, ``flexible``, and step 4's index
    arrays (``joint_segment (J,)``, ``curve_ends``/``curve_end_value``: the joints at their
    key segment's ends, ``leg_pivot``, ``leg_key_joint``, ``leg_bone_row``, ``leg_on_bone
    (L,)``, ``pad_index``), ``membership (L, K)`` (which node each leg hangs from; and
    ``membership_t`` its transpose),
    ``leg_count (K,)``, ``has_legs (K,)``, ``node_legs (K, M)``: the legs of each node (``M``
    the most legs of any node; ``node_leg_valid (K, M)`` marks the ones that are there).

    Per character, one row each (``B`` rows: the number of characters, or 1 for a batch made
    by :meth:`of`, which broadcasts over any number): every float array of the models
    (``joint_rest (B, J, 3)``, ``bone_length (B, J - 1)``, ``rest_unturn (B, J - 1, 3, 3)``,
    ...), constants of steps 3-4 computed from the rest pose once (``rest_foot_ahead``,
    ``rest_foot_depth``, ``rest_foot_yaw (B, L)``: each foot's rest place seen from its node,
    ``yaw_weight (B, L, K)``, step 4's ``bone_vector (B, J - 1, 3, 1)``: each bone at rest,
    ...), and the settings as arrays (``turn_rate``, ``relax_time``, ``foot_pitch_weight``,
    ``visual_yaw``, ``visual_yaw_gain``, ``max_visual_yaw (B,)``). Two pairs hold a row per
    character on their second axis: ``rest_chord_turn (2, B, J - 1)`` (the rest chords' yaw
    and pitch) and ``turn_limit (2, B, J - 2)`` (the inner joints' yaw and pitch limits).
    """

    models: tuple[SpineModel, ...]
    params: tuple[SpineParams, ...]
    n_joints: int = field(init=False)
    n_keys: int = field(init=False)
    n_legs: int = field(init=False)
    key_joint: IntArray = field(init=False)
    leg_key: IntArray = field(init=False)
    anchor_key: int = field(init=False)
    anchor_joint: int = field(init=False)
    flexible: bool = field(init=False)
    joint_segment: IntArray = field(init=False)
    curve_ends: BoolArray = field(init=False)
    curve_end_value: FloatArray = field(init=False)
    leg_pivot: IntArray = field(init=False)
    leg_key_joint: IntArray = field(init=False)
    leg_bone_row: IntArray = field(init=False)
    leg_on_bone: BoolArray = field(init=False)
    any_leg_on_bone: bool = field(init=False)
    all_legs_on_bone: bool = field(init=False)
    pad_index: IntArray = field(init=False)
    others: IntArray = field(init=False)
    membership: FloatArray = field(init=False)
    membership_t: FloatArray = field(init=False)
    leg_count: FloatArray = field(init=False)
    has_legs: BoolArray = field(init=False)
    node_legs: IntArray = field(init=False)
    node_leg_valid: BoolArray = field(init=False)
    any_visual_yaw: bool = field(init=False)
    all_visual_yaw: bool = field(init=False)
    any_foot_pitch: bool = field(init=False)
    joint_rest: FloatArray = field(init=False)
    key_rest: FloatArray = field(init=False)
    foot_rest: FloatArray = field(init=False)
    anchor_rest: FloatArray = field(init=False)
    anchor_rest_xy: FloatArray = field(init=False)
    key_chord: FloatArray = field(init=False)
    key_chord_sq: FloatArray = field(init=False)
    key_chord_sum: FloatArray = field(init=False)
    node_yaw_limit: FloatArray = field(init=False)
    joint_yaw_limit: FloatArray = field(init=False)
    joint_pitch_limit: FloatArray = field(init=False)
    key_rest_height: FloatArray = field(init=False)
    rest_key_pitch: FloatArray = field(init=False)
    rest_key_heading: FloatArray = field(init=False)
    rest_head_angle: FloatArray = field(init=False)
    joint_fraction: FloatArray = field(init=False)
    rest_chord_yaw: FloatArray = field(init=False)
    rest_chord_pitch: FloatArray = field(init=False)
    rest_unturn: FloatArray = field(init=False)
    bone_dir: FloatArray = field(init=False)
    bone_length: FloatArray = field(init=False)
    bone_vector: FloatArray = field(init=False)
    rest_chord_turn: FloatArray = field(init=False)
    turn_limit: FloatArray = field(init=False)
    hip_pivot_offset: FloatArray = field(init=False)
    slice_margin: FloatArray = field(init=False)
    rest_foot_ahead: FloatArray = field(init=False)
    rest_foot_depth: FloatArray = field(init=False)
    rest_foot_yaw: FloatArray = field(init=False)
    yaw_weight: FloatArray = field(init=False)
    yaw_weight_sum: FloatArray = field(init=False)
    yaw_has: BoolArray = field(init=False)
    turn_rate: FloatArray = field(init=False)
    relax_time: FloatArray = field(init=False)
    foot_pitch_weight: FloatArray = field(init=False)
    foot_pitch_nodes: BoolArray = field(init=False)
    visual_yaw: BoolArray = field(init=False)
    visual_yaw_gain: FloatArray = field(init=False)
    max_visual_yaw: FloatArray = field(init=False)

    @classmethod
    def of(cls, model: SpineModel, params: SpineParams | None = None) -> SpineBatch:
        """One model and settings for any number of characters."""
        return cls((model,), (params if params is not None else SpineParams(),))

    @classmethod
    def stack(cls, models: Sequence[SpineModel], params: Sequence[SpineParams]) -> SpineBatch:
        """One model and settings per character."""
        return cls(tuple(models), tuple(params))

    @property
    def n_rows(self) -> int:
        """``B``: rows of the per-character arrays (1 broadcasts over any number)."""
        return len(self.models)

    def __post_init__(self) -> None:
        models, params = self.models, self.params
        if not models or len(models) != len(params):
            raise ValueError(f"{len(models)} spine models for {len(params)} settings (one each, at least "
                             "one)")
        first = models[0]
        for i, m in enumerate(models[1:], 1):
            if m.structure != first.structure:
                raise ValueError(f"spine {i} has another structure than spine 0 (key joints, legs' nodes and "
                                 "bones, anchor): such spines are stepped in separate batches")
        if len({p.flexible for p in params}) != 1:
            raise ValueError("flexible and rigid spines are stepped in separate batches")
        set_ = object.__setattr__
        n_j, n_k, n_l = first.n_joints, first.n_keys, first.n_legs
        key, leg_key = first.key_joint, first.leg_key
        set_(self, "n_joints", n_j)
        set_(self, "n_keys", n_k)
        set_(self, "n_legs", n_l)
        set_(self, "key_joint", key)
        set_(self, "leg_key", leg_key)
        set_(self, "anchor_key", int(first.anchor_key))
        set_(self, "anchor_joint", int(key[first.anchor_key]))
        set_(self, "flexible", bool(params[0].flexible))
        set_(self, "joint_segment", first.joint_segment)
        ends = first.joint_at_start | first.joint_at_end
        set_(self, "curve_ends", ends)
        set_(self, "curve_end_value", first.joint_at_end[ends].astype(np.float64))
        set_(self, "leg_pivot", first.leg_pivot)
        set_(self, "leg_key_joint", first.leg_key_joint)
        set_(self, "leg_bone_row", first.leg_bone_row)
        set_(self, "leg_on_bone", first.leg_on_bone)
        set_(self, "any_leg_on_bone", bool(first.leg_on_bone.any()))
        set_(self, "all_legs_on_bone", bool(first.leg_on_bone.all()))
        # each joint's two bones (one at the ends): the mean turn of a joint's frame
        set_(self, "pad_index", np.array([0, *range(n_j - 1), n_j - 2], dtype=np.intp))
        set_(self, "others", np.array([0, *range(2, n_k)], dtype=np.intp))
        member = (leg_key[:, None] == np.arange(n_k)[None, :]).astype(np.float64)
        count = member.sum(axis=0)
        set_(self, "membership", member)
        set_(self, "membership_t", np.ascontiguousarray(member.T))
        set_(self, "leg_count", np.maximum(count, _EPS))
        set_(self, "has_legs", count > _EPS)
        most = int(count.max()) if n_l else 0
        node_legs = np.zeros((n_k, most), dtype=np.intp)
        node_leg_valid = np.zeros((n_k, most), dtype=bool)
        for k in range(n_k):
            mine = np.flatnonzero(leg_key == k)
            node_legs[k, :mine.size] = mine
            node_leg_valid[k, :mine.size] = True
        set_(self, "node_legs", node_legs)
        set_(self, "node_leg_valid", node_leg_valid)

        def rows(values: Sequence[npt.ArrayLike]) -> FloatArray:
            return np.stack([np.asarray(v, dtype=np.float64) for v in values])

        aj = self.anchor_joint
        set_(self, "joint_rest", rows([m.joint_rest for m in models]))
        set_(self, "key_rest", rows([m.key_rest for m in models]))
        set_(self, "foot_rest", rows([m.foot_rest for m in models]))
        set_(self, "anchor_rest", rows([m.joint_rest[aj] for m in models]))
        set_(self, "anchor_rest_xy", rows([m.key_rest[first.anchor_key, :2] for m in models]))
        set_(self, "key_chord", rows([m.key_chord for m in models]))
        set_(self, "key_chord_sq", rows([m.key_chord * m.key_chord for m in models]))
        set_(self, "key_chord_sum", rows([float(m.key_chord.sum()) for m in models]))
        for name in ("node_yaw_limit", "joint_yaw_limit", "joint_pitch_limit", "key_rest_height",
                     "rest_key_pitch", "rest_key_heading", "joint_fraction", "rest_chord_yaw",
                     "rest_chord_pitch", "rest_unturn", "bone_dir", "bone_length", "hip_pivot_offset"):
            set_(self, name, rows([getattr(m, name) for m in models]))
        set_(self, "rest_head_angle", rows([_segment_angles(m.key_rest[None, :, :2])[0, 0] for m in models]))
        set_(self, "slice_margin", rows([m.slice_margin for m in models]))
        # step 4's bones at rest as column vectors, the rest chords' (yaw, pitch) and the
        # joints' (yaw, pitch) limits between two bones, each (2, B, ...)
        set_(self, "bone_vector", (self.bone_dir * self.bone_length[..., None])[..., None])
        set_(self, "rest_chord_turn", np.stack([self.rest_chord_yaw, self.rest_chord_pitch]))
        set_(self, "turn_limit",
             np.stack([self.joint_yaw_limit[:, 1:n_j - 1], self.joint_pitch_limit[:, 1:n_j - 1]]))

        # Steps 3's feet at rest, seen from their node (node_pitch, visual_yaw).
        ahead, depth, yaw, weight = [], [], [], []
        for m in models:
            rest_rel = m.foot_rest - m.key_rest[leg_key]
            rest_heading = m.rest_key_heading[leg_key]
            ahead.append(rest_rel[:, 0] * np.cos(rest_heading) + rest_rel[:, 1] * np.sin(rest_heading))
            depth.append(-rest_rel[:, 2])
            flat = m.foot_rest[:, :2] - m.key_rest[leg_key, :2]
            yaw.append(np.arctan2(flat[:, 1], flat[:, 0]) - rest_heading)
            # feet right under their node have no direction to speak of: weigh by rest distance
            weight.append(member * np.linalg.norm(flat, axis=1)[:, None])
        set_(self, "rest_foot_ahead", rows(ahead))
        set_(self, "rest_foot_depth", rows(depth))
        set_(self, "rest_foot_yaw", rows(yaw))
        set_(self, "yaw_weight", rows(weight))
        wsum = self.yaw_weight.sum(axis=1)  # (B, K)
        set_(self, "yaw_weight_sum", np.maximum(wsum, _EPS))
        set_(self, "yaw_has", wsum > _EPS)

        set_(self, "turn_rate", rows([p.turn_rate for p in params]))
        set_(self, "relax_time", rows([p.relax_time for p in params]))
        set_(self, "foot_pitch_weight", rows([p.foot_pitch_weight for p in params]))
        set_(self, "foot_pitch_nodes", self.has_legs[None, :] & (self.foot_pitch_weight[:, None] != 0.0))
        set_(self, "any_foot_pitch", bool(np.any(self.foot_pitch_weight != 0.0)))
        set_(self, "visual_yaw", np.array([p.visual_yaw for p in params], dtype=bool))
        set_(self, "any_visual_yaw", bool(self.visual_yaw.any()))
        set_(self, "all_visual_yaw", bool(self.visual_yaw.all()))
        set_(self, "visual_yaw_gain", rows([p.visual_yaw_gain for p in params]))
        set_(self, "max_visual_yaw", rows([p.max_visual_yaw for p in params]))

    def take(self, rows: IntArray) -> SpineBatch:
        """The batch of characters ``rows`` only (itself when its rows broadcast)."""
        if self.n_rows == 1:
            return self
        out = object.__new__(SpineBatch)
        for f in fields(SpineBatch):
            object.__setattr__(out, f.name, getattr(self, f.name))
        pick = rows.tolist()
        object.__setattr__(out, "models", tuple(self.models[i] for i in pick))
        object.__setattr__(out, "params", tuple(self.params[i] for i in pick))
        for name in _PER_CHARACTER:
            object.__setattr__(out, name, getattr(self, name)[rows])
        for name in _PER_CHARACTER_PAIRS:
            object.__setattr__(out, name, getattr(self, name)[:, rows])
        return out


@dataclass(frozen=True)
class SpineState:
    """The spine carried from one step to the next: key node positions ``(C, K, 2)`` in the
    world xy plane (the guides of steps 1-2, not the drawn spine of step 4)."""

    key_xy: FloatArray

    @property
    def n_chars(self) -> int:
        return int(self.key_xy.shape[0])

    @classmethod
    def at_rest(cls, spines: SpineBatch | SpineModel, origin_xy: npt.ArrayLike,
                heading: npt.ArrayLike) -> SpineState:
        """Characters standing in their rest pose: body origins ``(C, 2)``, headings ``(C,)``
        (the rest pose of a batch's rows, or of one model for all)."""
        origin = np.atleast_2d(np.asarray(origin_xy, dtype=np.float64))
        head = _as_shape(heading, origin.shape[:1])
        rest = spines.key_rest[..., :2]  # (B, K, 2) or (K, 2)
        return cls(origin[:, None, :] + _turn_xy(rest, head[:, None]))


@dataclass(frozen=True)
class SpinePlan:
    """Steps 1-2: the key nodes on the ground plane.

    ``key_xy`` ``(C, K, 2)``; ``key_heading`` ``(C, K)`` each node's heading (the bisector of
    its segments; the end nodes as on an arc, see ``_headings_and_bends``), the frame its legs'
    footprints are planned in; ``bend`` ``(C, K)`` each node's sideways bend (0 at the ends);
    ``distance`` ``(C,)`` the distance the head moved; ``steer_heading`` ``(C,)`` the head
    segment's direction, the heading the user steers (what ``desired_heading`` is compared to).
    """

    key_xy: FloatArray
    key_heading: FloatArray
    bend: FloatArray
    distance: FloatArray
    steer_heading: FloatArray


@dataclass(eq=False)
class SpinePose:
    """Step 4: the drawn spine of every character (not changed in place once made: not
    frozen only because a frozen dataclass's construction costs a few microseconds, and
    a step builds about three).

    - ``joints``: ``(C, J, 3)`` world positions of the spine joints (head first).
    - ``bone_rotation``: ``(C, J - 1, 3, 3)`` rotation taking each bone from its rest
      (body-frame) direction to the world.
    - ``joint_frame``: ``(C, J, 3, 3)`` body-to-world rotation at each joint (mean of its
      bones' turn); :meth:`key_frames` gives them at the key nodes.
    - ``guide_xyz``: ``(C, K, 3)`` the key node guides the curve went through;
      ``key_yaw``/``key_pitch`` ``(C, K)`` the tangents' heading (with visual yaw) and the
      nodes' pitch (deviation from rest, nose up); ``tangent`` ``(C, K, 3)`` the curve's unit
      tangents at the key nodes, pointing from the head to the back (what :func:`refit`
      builds on).
    - ``yaw_dev``/``pitch_dev``: ``(C, J - 1)`` each bone's turn from rest (yaw about world up,
      pitch in its vertical plane, sign of the bone's rest direction), after the limits.
    """

    joints: FloatArray
    bone_rotation: FloatArray
    joint_frame: FloatArray
    guide_xyz: FloatArray
    key_yaw: FloatArray
    key_pitch: FloatArray
    tangent: FloatArray
    yaw_dev: FloatArray
    pitch_dev: FloatArray

    def key_positions(self, spines: SpineBatch | SpineModel) -> FloatArray:
        """``(C, K, 3)`` final positions of the key nodes."""
        return self.joints.take(spines.key_joint, axis=1)

    def key_frames(self, spines: SpineBatch | SpineModel) -> FloatArray:
        """``(C, K, 3, 3)`` final body-to-world rotations of the key nodes."""
        return self.joint_frame.take(spines.key_joint, axis=1)


# ------------------------------------------------------------------------ steps 1 and 2


def plan_spine(
    spines: SpineBatch,
    state: SpineState,
    desired_heading: npt.ArrayLike,
    distance: npt.ArrayLike,
    dt: float,
) -> SpinePlan:
    """Steps 1 and 2 (thesis §4.2.1-4.2.2): turn from the head, then advance on the support.

    ``desired_heading``, ``distance`` (>= 0, metres the head moves this step): ``(C,)`` or
    scalars. Returns the new key nodes; store ``SpineState(plan.key_xy)`` for the next step.
    """
    xy = np.array(state.key_xy, dtype=np.float64, copy=True)
    c, k = xy.shape[0], xy.shape[1]
    want = _as_shape(desired_heading, (c,))
    dist = np.maximum(_as_shape(distance, (c,)), 0.0)
    seg = _segment_angles(xy)
    max_turn = spines.turn_rate * float(dt)
    turn = _clamp(_wrap(want - seg[:, 0]), -max_turn, max_turn)

    if not spines.flexible:
        xy = _rigid_move(spines, xy, turn, dist)
    else:
        xy = _turn_from_head(spines, xy, turn)
        # Standing still leaves the nodes exactly where they are (no round-off creep).
        moving = dist > 0.0
        if moving.all():
            xy = _advance_on_support(spines, xy, dist)
        elif moving.any():
            xy = np.where(moving[:, None, None], _advance_on_support(spines, xy, dist), xy)
        xy = _clamp_bends(spines, xy)
        if k >= 3:
            # The back node relaxes its bend toward straight (thesis §4.2.2, in green in
            # figure 4.13), exponentially with the relax time.
            keep = np.exp(-float(dt) / spines.relax_time)
            xy[:, k - 1:] = _rotate_about(xy[:, k - 1:], xy[:, k - 2], _bend_at(xy, k - 2) * (1.0 - keep))

    seg = _segment_angles(xy)
    heading, bend = _headings_and_bends(seg)
    return SpinePlan(key_xy=xy, key_heading=heading, bend=bend, distance=dist, steer_heading=seg[:, 0].copy())


def _turn_from_head(spines: SpineBatch, xy: FloatArray, turn: FloatArray) -> FloatArray:
    """Thesis §4.2.1: each inner node takes what its limit allows, front to back; the rest
    rotates the whole spine about the node just behind the head."""
    k = xy.shape[1]
    remaining = turn
    for i in range(1, k - 1):
        bend = _bend_at(xy, i)
        limit = spines.node_yaw_limit[:, i]
        # Only moves that do not push the bend further past its limit are allowed.
        share = _clamp(remaining, np.minimum(-limit - bend, 0.0), np.maximum(limit - bend, 0.0))
        xy[:, :i] = _rotate_about(xy[:, :i], xy[:, i], share)
        remaining = remaining - share
    others = spines.others
    xy[:, others] = _rotate_about(xy.take(others, axis=1), xy[:, 1], remaining)
    return xy


def _advance_on_support(spines: SpineBatch, xy: FloatArray, dist: FloatArray) -> FloatArray:
    """Thesis §4.2.2: the head moves ahead; every following node is put on the previous
    spine (continued straight behind the back node) at its chord length from the node in
    front."""
    c, k = xy.shape[0], xy.shape[1]
    # the new head ahead of the old one, and a point far beyond the back node (each end's
    # direction and distance in one array: (C, 2 ends, ...))
    end_dir = xy[:, _END_NODES] - xy[:, _END_NEIGHBOURS]
    end_dir /= np.sqrt((end_dir * end_dir) @ _ONES2)[..., None]
    how_far = np.empty((c, 2))
    how_far[:, 0] = dist
    np.add(dist, spines.key_chord_sum, out=how_far[:, 1])
    how_far[:, 1] += 1.0
    support = np.empty((c, k + 2, 2))  # the new head, the old spine, far beyond the back node
    support[:, 1:-1] = xy
    end_dir *= how_far[..., None]
    support[:, _SUPPORT_ENDS] = xy[:, _END_NODES] + end_dir
    a = support[:, :-1]  # segment starts (C, S, 2)
    d = support[:, 1:] - a
    dd = (d * d) @ _ONES2  # (the products summed in the order np.einsum takes)
    usable = dd > _EPS
    four_dd = 4.0 * dd
    two_dd = np.maximum(dd, _EPS)
    two_dd *= 2.0
    seg_idx = _unit_index(k + 1)
    out = np.empty_like(xy)
    out[:, 0] = support[:, 0]
    rows = _unit_index(c)
    g = t = rows  # (the first node is looked for on every segment from its start)
    seg_rows = _row_offsets(c, 1, k + 1)[:, 0]  # where each row's segments start in d's flattening
    flat_d = d.reshape(-1, 2)
    flat_support = support.reshape(-1, 2)  # (a row of support is one longer than of d)
    for i in range(1, k):
        f = a - out[:, i - 1, None, :]
        b = (f * d) @ _ONES2
        b *= 2.0
        cc = (f * f) @ _ONES2
        cc -= spines.key_chord_sq[:, i - 1, None]
        disc = b * b - four_dd * cc
        root = np.sqrt(np.maximum(disc, 0.0))
        root -= b
        root /= two_dd
        ok = usable & (disc >= 0.0) & (root <= 1.0 + 1e-12)
        if i == 1:  # from the head: every segment, from its start
            ok &= root >= -1e-12
        else:  # the segment the last node is on, from where it is; the ones after it
            on = seg_idx == g[:, None]
            t_min = np.where(on, t[:, None], 0.0)
            t_min -= 1e-12
            ok &= (seg_idx >= g[:, None]) & (root >= t_min)
        g = ok.argmax(axis=1)  # the long last segment always qualifies
        # (each row's segment g gathered through the flat arrays: take of a flat index is
        # several times faster than indexing with two index arrays)
        at = g + seg_rows
        t = np.minimum(np.maximum(root.take(at), 0.0), 1.0)
        out[:, i] = flat_support.take(at + rows, axis=0) + t[:, None] * flat_d.take(at, axis=0)
    return out


#: The end nodes of a spine (the head, the back node), their neighbours, and where the
#: points ahead of and behind them go in :func:`_advance_on_support`'s support polyline.
_END_NODES = np.array([0, -1])
_END_NEIGHBOURS = np.array([1, -2])
_SUPPORT_ENDS = np.array([0, -1])
_ONES2 = np.ones(2)
_INDEX: dict[int, IntArray] = {}


def _unit_index(n: int) -> IntArray:
    """``np.arange(n)``, made once per ``n``."""
    out = _INDEX.get(n)
    if out is None:
        out = _INDEX[n] = np.arange(n)
    return out


def _clamp_bends(spines: SpineBatch, xy: FloatArray) -> FloatArray:
    """Bring every inner node's bend back within its limit, front to back, by turning the
    part of the spine behind it."""
    k = xy.shape[1]
    for i in range(1, k - 1):
        bend = _bend_at(xy, i)
        limit = spines.node_yaw_limit[:, i]
        excess = bend - _clamp(bend, -limit, limit)
        if (excess != 0.0).any():
            # Turning the rear part by +x changes this bend by -x.
            xy[:, i + 1:] = _rotate_about(xy[:, i + 1:], xy[:, i], excess)
    return xy


def _rigid_move(spines: SpineBatch, xy: FloatArray, turn: FloatArray, dist: FloatArray) -> FloatArray:
    """No spine: the rest-shaped body turns about its origin and moves along its heading."""
    rest = spines.key_rest[..., :2]  # (B, K, 2)
    heading = _segment_angles(xy)[:, 0] - spines.rest_head_angle
    # The body origin implied by the anchor node (the body is rigid, any node would do).
    anchor = spines.anchor_key
    origin = xy[:, anchor] - _turn_xy(rest[:, anchor], heading)
    heading = heading + turn
    origin = origin + dist[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    return origin[:, None, :] + _turn_xy(rest, heading[:, None])


# ------------------------------------------------------------------------------- step 3


def feet_ahead(spines: SpineBatch, plan: SpinePlan, foot_world: FloatArray) -> FloatArray:
    """``(C, L)`` how far each foot ``foot_world (C, L, 3)`` is ahead of its key node along
    the node's heading (what :func:`terrain_guides` and :func:`node_pitch` measure the feet
    by; give it to them when both run on the same plan and feet)."""
    leg = spines.leg_key
    heading = plan.key_heading.take(leg, axis=1)
    rel_xy = foot_world[..., :2] - plan.key_xy.take(leg, axis=1)
    return np.asarray(rel_xy[..., 0] * np.cos(heading) + rel_xy[..., 1] * np.sin(heading))


def terrain_guides(
    spines: SpineBatch,
    plan: SpinePlan,
    height_at: HeightFn,
    foot_world: npt.ArrayLike | None = None,
    samples_per_node: int = 12,
    ahead: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Each key node's preferred height and environment pitch (thesis §4.2.3, figure 4.14).

    The ground is sampled along the spine's own (curved) path, from ``slice_margin`` before
    the head to ``slice_margin`` behind the back node. Each node owns the stretch from
    half-way to the node in front to half-way to the node behind; the upper convex hull of
    that stretch's ground (and of the feet hanging from the node, ``foot_world`` ``(C, L, 3)``)
    under the node gives its ground height and slope (a node whose whole stretch is over a
    hole uses the ground under the whole body). Returns ``(height, pitch)``, each
    ``(C, K)``: ground height plus the node's rest height, and the slope angle (nose up).
    The controller adds the pseudo-physics offset to ``height`` before :func:`finish_spine`.
    ``ahead``: :func:`feet_ahead` of these feet, when the caller has it already.
    """
    xy = plan.key_xy
    c, k = xy.shape[0], xy.shape[1]
    n = max(2, int(samples_per_node))
    d = xy[:, 1:] - xy[:, :-1]  # (C, K - 1, 2)
    arc = np.zeros((c, k))  # arc length of each node from the head
    np.sqrt(np.add.reduce(d * d, axis=-1)).cumsum(axis=1, out=arc[:, 1:])
    margin = spines.slice_margin
    # node i's stretch: from bounds[i] (half-way to the node in front) to bounds[i + 1]
    bounds = np.empty((c, k + 1))
    bounds[:, 0] = arc[:, 0] - margin
    np.add(arc[:, :-1], arc[:, 1:], out=bounds[:, 1:k])
    bounds[:, 1:k] *= 0.5
    bounds[:, k] = arc[:, -1] + margin
    lo = bounds[:, :-1]
    n_l = spines.n_legs
    with_feet = foot_world is not None and n_l > 0
    own = spines.node_legs  # (K, M): each node's row gets a column per leg of its own
    width = n + (own.shape[1] if with_feet else 0)
    x = np.empty((c, k, width))
    z = np.empty((c, k, width))
    valid = np.empty((c, k, width), dtype=bool)
    s = x[..., :n]
    np.add(lo[..., None], (bounds[:, 1:] - lo)[..., None] * _unit_samples(n), out=s)  # (C, K, n)
    z[..., :n] = np.asarray(height_at(_polyline_at(xy, d, arc, s).reshape(-1, 2)),
                            dtype=np.float64).reshape(c, k, n)
    np.greater(z[..., :n], 0.5 * NO_SURFACE, out=valid[..., :n])
    if with_feet:
        feet = np.asarray(foot_world, dtype=np.float64).reshape(c, n_l, 3)
        if ahead is None:
            ahead = feet_ahead(spines, plan, feet)
        # arc length grows from the head to the back: a foot ahead of its node comes before it
        fx = arc.take(spines.leg_key, axis=1) - ahead  # (C, L)
        x[..., n:] = fx.take(own, axis=1)
        z[..., n:] = feet[..., 2].take(own, axis=1)
        valid[..., n:] = spines.node_leg_valid
    lost = ~np.logical_or.reduce(valid[..., :n], axis=2)  # (C, K)
    if np.count_nonzero(lost):
        # A node over a hole (nothing under its stretch) uses the ground under the whole body.
        whole = np.broadcast_to(valid[..., :n].reshape(c, 1, -1), (c, k, k * n))
        x = np.concatenate([x, np.broadcast_to(s.reshape(c, 1, -1), whole.shape)], axis=2)
        z = np.concatenate([z, np.broadcast_to(z[..., :n].reshape(c, 1, -1), whole.shape)], axis=2)
        valid = np.concatenate([valid, whole & lost[..., None]], axis=2)
    nothing = ~np.logical_or.reduce(valid, axis=2, keepdims=True)
    if np.count_nonzero(nothing):
        # No ground and no feet at all: a flat floor at 0 keeps the numbers finite.
        x = np.concatenate([x, arc[..., None]], axis=2)
        z = np.concatenate([z, np.zeros((c, k, 1))], axis=2)
        valid = np.concatenate([valid, nothing], axis=2)
    ground, slope = upper_hull_eval(x, z, arc[..., None], valid)
    # The slope is along the spine from head to back; nose up means the ground rises forward.
    return ground[..., 0] + spines.key_rest_height, -np.arctan(slope[..., 0])


def _polyline_at(xy: FloatArray, d: FloatArray, arc: FloatArray, s: FloatArray) -> FloatArray:
    """Points at arc lengths ``s`` ``(C, K, n)`` along the key polyline ``xy (C, K, 2)``
    (segments ``d (C, K - 1, 2)``, nodes' arc lengths ``arc (C, K)``; continued straight past
    both ends): ``(C, K, n, 2)``."""
    c, k = xy.shape[0], xy.shape[1]
    flat = s.reshape(c, -1)
    # each segment's start, direction, start's arc length and length, looked up per point
    table = np.empty((c, k - 1, 6))
    table[..., 0:2] = xy[:, :-1]
    table[..., 2:4] = d
    table[..., 4] = arc[:, :-1]
    np.subtract(arc[:, 1:], arc[:, :-1], out=table[..., 5])
    seg = np.add.reduce(flat[..., None] >= arc[:, None, 1:-1], axis=-1)  # (C, m): in 0 .. K - 2
    at = table[np.arange(c)[:, None], seg]  # (C, m, 6)
    f = (flat - at[..., 4]) / np.maximum(at[..., 5], _EPS)
    return (at[..., 0:2] + f[..., None] * at[..., 2:4]).reshape(*s.shape, 2)


def node_pitch(
    spines: SpineBatch,
    plan: SpinePlan,
    node_z: npt.ArrayLike,
    env_pitch: npt.ArrayLike,
    foot_world: npt.ArrayLike | None,
    ahead: FloatArray | None = None,
) -> FloatArray:
    """Each key node's pitch ``(C, K)`` (thesis §4.2.3): environment pitch averaged with the
    pitch its feet induce (``ahead``: :func:`feet_ahead` of ``foot_world``, when the caller
    has it already).

    A foot's induced pitch is the angle of the perpendicular to the node-to-foot vector in
    the node's vertical plane, pointing forward: a foot ahead of (or higher than) its place
    lifts the nose. It is measured against the foot's rest place laid on the environment's
    slope under the node, so a foot standing where it would stand at rest on that slope
    induces exactly the environment pitch. The node's pitch is
    ``(1 - w) * env + w * mean(induced)`` with ``w = foot_pitch_weight``. Nodes without legs
    (the head) keep the environment pitch.
    """
    env = np.asarray(env_pitch, dtype=np.float64)
    if foot_world is None or spines.n_legs == 0 or not spines.any_foot_pitch:
        return env.copy()
    c, k = plan.key_xy.shape[:2]
    env = _as_shape(env, (c, k))
    feet = np.asarray(foot_world, dtype=np.float64).reshape(c, spines.n_legs, 3)
    z = _as_shape(node_z, (c, k))
    leg = spines.leg_key
    if ahead is None:
        ahead = feet_ahead(spines, plan, feet)
    below = z.take(leg, axis=1) - feet[..., 2]
    rest_ahead = spines.rest_foot_ahead
    # The rest place on the sloped ground: further below the node behind it, less ahead.
    ref_below = spines.rest_foot_depth - rest_ahead * np.tan(env.take(leg, axis=1))
    change = _wrap(np.arctan2(ahead, below) - np.arctan2(rest_ahead, ref_below))  # (C, L)
    mean_change = (change @ spines.membership) / spines.leg_count
    # (1 - w) env + w (env + change) = env + w change
    return np.where(spines.foot_pitch_nodes, env + spines.foot_pitch_weight[:, None] * mean_change, env)


def visual_yaw(spines: SpineBatch, plan: SpinePlan, foot_world: npt.ArrayLike) -> FloatArray:
    """The lizard's visual yaw of each key node's tangent ``(C, K)`` (thesis §4.4).

    Every foot's yaw is the angle, seen from above, between the direction from its node to
    the foot now and the direction to its rest place (in the node's current frame); a node
    turns by the mean of its feet's yaws (times ``visual_yaw_gain``, clamped to
    ``max_visual_yaw``; the feet weighed by their rest distance from the node: a foot right
    under it has no direction to speak of). Nodes without feet do not turn. Computed for
    every character; the callers add it where ``SpineParams.visual_yaw`` is on.
    """
    c, k = plan.key_xy.shape[:2]
    if spines.n_legs == 0:
        return np.zeros((c, k))
    feet = np.asarray(foot_world, dtype=np.float64).reshape(c, spines.n_legs, 3)
    leg = spines.leg_key
    rel = feet[..., :2] - plan.key_xy.take(leg, axis=1)
    now = np.arctan2(rel[..., 1], rel[..., 0]) - plan.key_heading.take(leg, axis=1)
    turned = (_wrap(now - spines.rest_foot_yaw)[:, None, :] @ spines.yaw_weight)[:, 0]  # (C, K)
    mean = np.where(spines.yaw_has, turned / spines.yaw_weight_sum, 0.0)
    limit = spines.max_visual_yaw[:, None]
    return _clamp(spines.visual_yaw_gain[:, None] * mean, -limit, limit)


def _with_visual_yaw(spines: SpineBatch, plan: SpinePlan, foot_world: npt.ArrayLike) -> FloatArray:
    """Each key node's tangent heading ``(C, K)``: its heading plus, for the characters with
    ``visual_yaw`` on, :func:`visual_yaw`."""
    turn = visual_yaw(spines, plan, foot_world)
    if not spines.all_visual_yaw:
        turn = np.where(spines.visual_yaw[:, None], turn, 0.0)
    return np.asarray(plan.key_heading + turn)


# ------------------------------------------------------------------------------- step 4


def _sample_curve(
    key_xyz: FloatArray, tangent: FloatArray, segment: IntArray, fraction: FloatArray,
    ends: BoolArray, end_value: FloatArray,
) -> FloatArray:
    """Points ``(C, J, 3)`` on the Hermite curve through the key nodes ``(C, K, 3)`` along
    their unit ``tangent`` ``(C, K, 3)`` (from the head toward the back) at the joints' arc
    fractions: joint ``j`` at ``fraction[..., j]`` of the arc of key segment ``segment[j]``;
    the joints ``ends`` at the parameters ``end_value`` exactly (0 or 1: the key nodes).

    Each segment's arc length is tabulated at ``_CURVE_SAMPLES`` parameters (the chords
    between them, from one product with the basis's differences) and a joint's parameter
    interpolated linearly between the two samples around its arc length."""
    c, k = key_xyz.shape[:2]
    m = _CURVE_SAMPLES
    n_j = segment.shape[0]
    pair = _segment_pairs(k)  # (K - 1, 2): each key segment's two nodes
    ctrl = np.empty((c, k - 1, 4, 3))  # P1, P2, T1, T2 of each key segment
    ends_xyz = ctrl[:, :, 0:2]
    ends_xyz[...] = key_xyz.take(pair, axis=1)
    d = key_xyz[:, 1:] - key_xyz[:, :-1]
    chord = np.sqrt((d * d) @ _ONES3)  # (C, K - 1)
    np.multiply(tangent.take(pair, axis=1), chord[..., None, None], out=ctrl[:, :, 2:4])
    step = _CURVE_STEP_BASIS @ ctrl  # (C, K - 1, m - 1, 3): between consecutive dense samples
    table = np.zeros((c, k - 1, m))  # arc length at each dense sample
    step *= step
    np.add.accumulate(np.sqrt(step @ _ONES3), axis=2, out=table[:, :, 1:])
    tab = table.take(segment, axis=1)  # (C, J, m)
    target = fraction * tab[..., m - 1]
    # the first sample at or past the target (a fraction is at most 1: never past the end)
    idx = np.add.reduce(tab < target[..., None], axis=-1)
    np.maximum(idx, 1, out=idx)
    flat = tab.reshape(-1)
    at = idx + _row_offsets(c, n_j, m)
    l1 = flat[at]
    l0 = flat[at - 1]
    frac = target - l0
    frac /= np.maximum(l1 - l0, _EPS)
    np.maximum(frac, 0.0, out=frac)
    np.minimum(frac, 1.0, out=frac)
    frac *= _CURVE_STEP
    param = _CURVE_S_BEFORE[idx]
    param += frac
    # Exact ends: key joints sit on their key node.
    param[:, ends] = end_value
    basis = (param[..., None] ** _POWERS) @ HERMITE_MATRIX  # (C, J, 4): hermite_basis
    return np.asarray((basis[:, :, None, :] @ ctrl.take(segment, axis=1))[:, :, 0])


_ROW_OFFSETS: dict[tuple[int, int, int], IntArray] = {}


def _row_offsets(c: int, n: int, m: int) -> IntArray:
    """``(np.arange(c * n) * m).reshape(c, n)``, made once per ``(c, n, m)``: where each row
    of a ``(c, n, m)`` array starts in its flattening."""
    out = _ROW_OFFSETS.get((c, n, m))
    if out is None:
        out = _ROW_OFFSETS[(c, n, m)] = (np.arange(c * n, dtype=np.intp) * m).reshape(c, n)
    return out


_SEGMENT_PAIRS: dict[int, IntArray] = {}


def _segment_pairs(k: int) -> IntArray:
    """``(k - 1, 2)``: the two key nodes of each of ``k`` nodes' segments, made once per ``k``."""
    out = _SEGMENT_PAIRS.get(k)
    if out is None:
        out = _SEGMENT_PAIRS[k] = np.stack([np.arange(k - 1), np.arange(1, k)], axis=1).astype(np.intp)
    return out


def build_spine(
    spines: SpineBatch,
    key_xyz: npt.ArrayLike,
    key_yaw: npt.ArrayLike,
    key_pitch: npt.ArrayLike,
    tangent: FloatArray | None = None,
) -> SpinePose:
    """Step 4 (thesis §4.2.4): the final spine from key node guides.

    ``key_xyz`` ``(C, K, 3)`` guide positions; ``key_yaw`` ``(C, K)`` tangent headings
    (node heading plus any visual yaw); ``key_pitch`` ``(C, K)`` node pitch, nose up, as a
    deviation from the rest pose (0 keeps the rest posture); ``tangent``: the unit tangents
    ``(C, K, 3)`` those give (``SpinePose.tangent``), when the caller has them already. Bone
    lengths are exact: the chain is rebuilt from the anchor node with each bone's rest
    direction turned by the curve's turn over that bone, each joint's turn limited to its
    yaw and pitch limits.
    """
    guide = np.asarray(key_xyz, dtype=np.float64)
    yaw = _as_shape(key_yaw, guide.shape[:2])
    pitch = _as_shape(key_pitch, guide.shape[:2])
    if tangent is None:
        tangent = -_direction(yaw, spines.rest_key_pitch + pitch)  # the curve runs from the head to the back
    return _build(spines, guide.copy(), np.array(yaw, copy=True), np.array(pitch, copy=True), tangent)


def build_fresh(
    spines: SpineBatch, key_xyz: FloatArray, key_yaw: FloatArray, key_pitch: FloatArray
) -> SpinePose:
    """:func:`build_spine` on ``(C, K, 3)``, ``(C, K)`` and ``(C, K)`` float arrays the pose may
    hold as they are (the caller will not change them in place)."""
    tangent = -_direction(key_yaw, spines.rest_key_pitch + key_pitch)
    return _build(spines, key_xyz, key_yaw, key_pitch, tangent)


def _build(spines: SpineBatch, guide: FloatArray, yaw: FloatArray, pitch: FloatArray, tangent: FloatArray
           ) -> SpinePose:
    """:func:`build_spine` on arrays the pose may keep as they are (nobody changes them)."""
    c = guide.shape[0]
    n_j = spines.n_joints
    n_b = n_j - 1
    samples = _sample_curve(guide, tangent, spines.joint_segment, spines.joint_fraction, spines.curve_ends,
                            spines.curve_end_value)
    # each bone's turn from rest (yaw, pitch) = (dev[0], dev[1]), each (C, J - 1)
    chord = samples[:, 1:] - samples[:, :-1]
    cx, cy = chord[..., 0], chord[..., 1]
    dev = np.empty((2, c, n_b))
    np.arctan2(cy, cx, out=dev[0])
    np.arctan2(chord[..., 2], np.hypot(cx, cy), out=dev[1])
    dev -= spines.rest_chord_turn
    _wrap_in_place(dev[0])
    # Mostly no joint is at its limit (then every turn stays as it is): one test for both.
    within = np.abs(dev[:, :, 1:] - dev[:, :, :-1]) < spines.turn_limit
    if n_b >= 2 and np.count_nonzero(within) < within.size:
        dev[0], dev[1] = _limit_joints(spines, dev[0], dev[1])

    # Joint frames: the mean turn of the bones on either side (one bone at the ends). For a
    # bone pointing backward, a positive pitch deviation lowers the nose. Bones and joints
    # are turned in one call: (C, J - 1) bone angles, then (C, J) joint angles, yaw then pitch.
    turn = np.empty((2, c, n_b + n_j))
    np.add(spines.rest_chord_turn, dev, out=turn[:, :, :n_b])
    pad = dev.take(spines.pad_index, axis=2)  # (2, C, J + 1)
    half = pad[:, :, 1:] - pad[:, :, :-1]
    _wrap_in_place(half[0])
    half *= 0.5
    np.add(pad[:, :, :-1], half, out=turn[:, :, n_b:])
    np.negative(turn[1, :, n_b:], out=turn[1, :, n_b:])
    turned = _frames(turn)  # (C, 2 J - 1, 3, 3)
    # Rz(yaw) Ry(-pitch) of the turned chord after the rest chord's inverse (rest_unturn)
    rotation = turned[:, :n_b] @ spines.rest_unturn
    bone_world = (rotation @ spines.bone_vector)[..., 0]  # (C, J - 1, 3)

    aj = spines.anchor_joint
    anchor = guide[:, spines.anchor_key]
    joints = np.empty((c, n_j, 3))
    joints[:, aj] = anchor
    if aj < n_j - 1:
        np.add(anchor[:, None], bone_world[:, aj:].cumsum(axis=1), out=joints[:, aj + 1:])
    if aj > 0:
        np.subtract(anchor[:, None], bone_world[:, aj - 1::-1].cumsum(axis=1)[:, ::-1], out=joints[:, :aj])
    return SpinePose(
        joints=joints,
        bone_rotation=rotation,
        joint_frame=turned[:, n_b:],
        guide_xyz=guide,
        key_yaw=yaw,
        key_pitch=pitch,
        tangent=tangent,
        yaw_dev=dev[0],
        pitch_dev=dev[1],
    )


def _wrap_in_place(a: FloatArray) -> None:
    """``a = _wrap(a)``, in place."""
    a += np.pi
    np.mod(a, _TWO_PI, out=a)
    a -= np.pi


#: Entries of ``Rz(yaw) @ Ry(-pitch)`` (``frame_from_yaw_pitch``) in :func:`_frames`' table
#: of cos/sin of yaw and pitch and their products, and their signs.
_FRAME_ENTRIES = np.array([4, 2, 5, 6, 0, 7, 3, 8, 1])
_FRAME_SIGNS = np.array([1.0, -1.0, -1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0])


def _frames(turn: FloatArray) -> FloatArray:
    """``frame_from_yaw_pitch(turn[0], turn[1])`` for ``turn (2, C, n)``: ``(C, n, 3, 3)``,
    from one table of the cosines, sines and their products."""
    c, n = turn.shape[1], turn.shape[2]
    table = np.empty((9, c, n))  # cy, cp, sy, sp, cy cp, cy sp, sy cp, sy sp, 0
    np.cos(turn, out=table[0:2])
    np.sin(turn, out=table[2:4])
    np.multiply(table[0:4:2, None], table[None, 1:4:2], out=table[4:8].reshape(2, 2, c, n))
    table[8] = 0.0
    # (the entries taken along the table's first axis, then turned: the same strided layout
    # as indexing the turned table, which the bone rotations' matrix products depend on)
    out = table.reshape(9, c * n).take(_FRAME_ENTRIES, axis=0).T
    out *= _FRAME_SIGNS
    return out.reshape(c, n, 3, 3)


def _limit_joints(
    spines: SpineBatch | SpineModel, yaw_dev: FloatArray, pitch_dev: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Limit the change of turn at every joint, working outward from the anchor joint.
    ``yaw_dev``, ``pitch_dev`` ``(C, J - 1)`` are not changed."""
    n_b = yaw_dev.shape[1]
    yls = np.asarray(spines.joint_yaw_limit)  # (B, J) or (J,)
    pls = np.asarray(spines.joint_pitch_limit)
    # Mostly no joint is at its limit: then every turn stays as it is (the walk below would
    # only add rounding), found with a few array operations instead of a loop over bones.
    if n_b < 2 or (
        (np.abs(yaw_dev[:, 1:] - yaw_dev[:, :-1]) < yls[..., 1:n_b]).all()
        and (np.abs(pitch_dev[:, 1:] - pitch_dev[:, :-1]) < pls[..., 1:n_b]).all()
    ):
        return yaw_dev, pitch_dev
    yaw = yaw_dev.copy()
    pitch = pitch_dev.copy()
    anchor_joint = int(spines.key_joint[spines.anchor_key])
    # Bones behind the anchor keep the first one's turn as reference; so do bones ahead.
    ref_back = min(anchor_joint, n_b - 1)
    for b in range(ref_back + 1, n_b):  # joint b joins bone b - 1 and bone b
        yl, pl = yls[..., b], pls[..., b]
        yaw[:, b] = yaw[:, b - 1] + _clamp(_wrap(yaw[:, b] - yaw[:, b - 1]), -yl, yl)
        pitch[:, b] = pitch[:, b - 1] + _clamp(pitch[:, b] - pitch[:, b - 1], -pl, pl)
    for b in range(ref_back - 1, -1, -1):  # joint b + 1 joins bone b and bone b + 1
        yl, pl = yls[..., b + 1], pls[..., b + 1]
        yaw[:, b] = yaw[:, b + 1] + _clamp(_wrap(yaw[:, b] - yaw[:, b + 1]), -yl, yl)
        pitch[:, b] = pitch[:, b + 1] + _clamp(pitch[:, b] - pitch[:, b + 1], -pl, pl)
    return yaw, pitch


def finish_spine(
    spines: SpineBatch,
    plan: SpinePlan,
    node_z: npt.ArrayLike,
    env_pitch: npt.ArrayLike,
    foot_world: npt.ArrayLike | None = None,
) -> SpinePose:
    """Steps 3 and 4 from a plan: node heights ``(C, K)`` (hull height plus rest height plus
    the pseudo-physics offset), environment pitch ``(C, K)``, current feet ``(C, L, 3)``."""
    c, k = plan.key_xy.shape[:2]
    z = _as_shape(node_z, (c, k))
    env = _as_shape(env_pitch, (c, k))
    pitch = node_pitch(spines, plan, z, env, foot_world)
    yaw = plan.key_heading.copy()
    if spines.any_visual_yaw and foot_world is not None:
        yaw = _with_visual_yaw(spines, plan, foot_world)
    guide = np.empty((c, k, 3))
    guide[..., :2] = plan.key_xy
    guide[..., 2] = z
    return build_spine(spines, guide, yaw, pitch)


def refit(spines: SpineBatch, pose: SpinePose, key_xyz: npt.ArrayLike, *, keep: bool = False) -> SpinePose:
    """Step 4 again on new guides ``(C, K, 3)`` with the same tangents (thesis §4.2.4: when
    the leg IK cannot reach, the spine is rebuilt on the closest positions it can hold).
    ``keep``: the new pose may hold ``key_xyz`` itself (the caller made it for it and will
    not change it), else it holds a copy."""
    guide = np.asarray(key_xyz, dtype=np.float64)
    return _build(spines, guide if keep else guide.copy(), pose.key_yaw, pose.key_pitch, pose.tangent)


def leg_frames(spines: SpineBatch, pose: SpinePose) -> FloatArray:
    """Body-to-world rotation each leg hangs from ``(C, L, 3, 3)``: its carrier bone's
    rotation (``SpineModel.leg_bone``), else the frame of its key node."""
    if spines.all_legs_on_bone:
        return np.asarray(pose.bone_rotation.take(spines.leg_bone_row, axis=1))
    key_frames = pose.joint_frame.take(spines.leg_key_joint, axis=1)
    if not spines.any_leg_on_bone:
        return np.asarray(key_frames)
    bone_frames = pose.bone_rotation.take(spines.leg_bone_row, axis=1)
    return np.asarray(np.where(spines.leg_on_bone[None, :, None, None], bone_frames, key_frames))


def hip_positions(spines: SpineBatch, pose: SpinePose, frames: FloatArray | None = None) -> FloatArray:
    """World hip positions ``(C, L, 3)``: each hip rides with its carrier bone (turning about
    the bone's back joint) or, without one, with the frame of its key node (``frames``: the
    pose's :func:`leg_frames` ``(C, L, 3, 3)`` when the caller has them already)."""
    if frames is None:
        frames = leg_frames(spines, pose)
    turned = np.matmul(frames, spines.hip_pivot_offset[..., None])[..., 0]
    return pose.joints.take(spines.leg_pivot, axis=1) + turned


def repeat_for_reach(
    spines: SpineBatch,
    pose: SpinePose,
    foot_world: npt.ArrayLike,
    leg_reach: npt.ArrayLike,
    iterations: int = 3,
    slack: float = 0.995,
    max_shift: npt.ArrayLike = np.inf,
    hips: FloatArray | None = None,
) -> SpinePose:
    """Repeat step 4 until every hip is within ``leg_reach`` of its foot.

    A hip too far from its foot is pulled toward it, to ``slack * leg_reach`` (a little
    inside, so that the rebuilt curve, which does not move every hip by exactly its pull,
    settles in few repeats); each key node's guide
    moves by the pulls of its legs averaged with their excesses as weights (one stretched
    leg moves its node by its whole excess, two stretched the same way do not add up), and
    the spine is rebuilt (:func:`refit`); at most ``iterations`` times. This is
    the hook of thesis §4.2.4 with reach as the legs' ability; a controller whose IK knows
    better (joint limits) can compute its own guides and call :func:`refit`.
    ``foot_world`` ``(C, L, 3)``, ``leg_reach`` ``(L,)`` or ``(C, L)``; no guide moves further than
    ``max_shift`` (a scalar or ``(C,)``) from where it was (a foot beyond help is the
    controller's to step). ``hips`` ``(C, L, 3)``: ``hip_positions(spines, pose)`` when the
    caller has them already.
    """
    return reach_repeats(spines, pose, foot_world, leg_reach, iterations, slack, max_shift, hips)[0]


def reach_repeats(
    spines: SpineBatch,
    pose: SpinePose,
    foot_world: npt.ArrayLike,
    leg_reach: npt.ArrayLike,
    iterations: int = 3,
    slack: float = 0.995,
    max_shift: npt.ArrayLike = np.inf,
    hips: FloatArray | None = None,
) -> tuple[SpinePose, FloatArray | None]:
    """:func:`repeat_for_reach`, and the hips ``(C, L, 3)`` of the pose it returns when it
    measured them on that pose for every character (else None)."""
    if spines.n_legs == 0:
        return pose, hips
    feet = np.asarray(foot_world, dtype=np.float64)
    n_chars = pose.joints.shape[0]
    reach_all = np.asarray(leg_reach, dtype=np.float64)
    if reach_all.shape != (n_chars, spines.n_legs):
        reach_all = np.broadcast_to(reach_all if reach_all.ndim == 2 else reach_all[None, :],
                                    (n_chars, spines.n_legs))
    cap_all = np.asarray(max_shift, dtype=np.float64)
    if cap_all.ndim:
        cap_all = cap_all.reshape(-1, 1, 1)
    member = spines.membership
    start = pose.guide_xyz
    # (what the legs are measured against, made once for every repeat)
    limit_all = reach_all + 1e-12
    aim_all = slack * reach_all
    # The characters still stretched (only they are rebuilt): None while that is all of them.
    rows: IntArray | None = None
    sub_spines = spines
    last_hips: FloatArray | None = None
    for i in range(max(0, int(iterations))):
        sub = pose if rows is None else pose_rows(pose, rows)
        hip = hips if i == 0 and hips is not None else hip_positions(sub_spines, sub)
        last_hips = hip if rows is None else None
        to_foot = (feet if rows is None else feet[rows]) - hip
        dist = vector_norm(to_foot)
        stretched = np.logical_or.reduce(dist > (limit_all if rows is None else limit_all[rows]), axis=1)
        n_stretched = np.count_nonzero(stretched)
        if not n_stretched:
            break
        excess = np.maximum(dist - (aim_all if rows is None else aim_all[rows]), 0.0)
        if rows is None and n_stretched == stretched.size:
            cap = cap_all
            base = start
        else:
            rows = (np.arange(n_chars) if rows is None else rows)[stretched]
            to_foot, dist, excess = to_foot[stretched], dist[stretched], excess[stretched]
            sub = pose_rows(pose, rows)
            sub_spines = spines.take(rows)
            cap = cap_all[rows] if cap_all.ndim else cap_all
            base = start[rows]
        pull = to_foot * (excess * excess / np.maximum(dist, _EPS))[..., None]
        weight = excess @ member  # (c, K)
        shift = (spines.membership_t @ pull) / np.maximum(weight, _EPS)[..., None]  # (c, K, 3)
        moved = sub.guide_xyz + shift - base
        size = vector_norm(moved, keepdims=True)
        moved *= np.minimum(1.0, cap / np.maximum(size, _EPS))
        new = refit(sub_spines, sub, base + moved, keep=True)
        pose = new if rows is None else pose_with_rows(pose, rows, new)
        last_hips = None
    return pose, last_hips


def pose_rows(pose: SpinePose, rows: IntArray) -> SpinePose:
    """The poses of characters ``rows`` (increasing, without repeats) only: ``pose`` itself
    when that is every character (poses are not changed in place)."""
    if rows.size == pose.joints.shape[0]:
        return pose
    return SpinePose(*(getattr(pose, f.name)[rows] for f in fields(SpinePose)))


def pose_with_rows(pose: SpinePose, rows: IntArray, sub: SpinePose) -> SpinePose:
    """``pose`` with the characters ``rows`` replaced by ``sub``."""
    if rows.size == pose.joints.shape[0]:
        return sub
    out = []
    for f in fields(SpinePose):
        arr = np.array(getattr(pose, f.name), copy=True)
        arr[rows] = getattr(sub, f.name)
        out.append(arr)
    return SpinePose(*out)


# ------------------------------------------------------------------------- one full step

#: ``(plan) -> (node_z, env_pitch)``, each ``(C, K)``: how the controller elevates the nodes.
GuideFn = Callable[[SpinePlan], tuple[FloatArray, FloatArray]]


def spine_step(
    spines: SpineBatch,
    state: SpineState,
    desired_heading: npt.ArrayLike,
    distance: npt.ArrayLike,
    dt: float,
    guides: GuideFn,
    foot_world: npt.ArrayLike | None = None,
) -> tuple[SpineState, SpinePlan, SpinePose]:
    """All four steps for ``C`` characters: plan on the ground, elevate with ``guides``
    (e.g. :func:`terrain_guides` plus the pseudo-physics), pitch, visual yaw, final curve.
    Returns the state for the next step, the plan (node headings for the feet) and the pose.
    """
    plan = plan_spine(spines, state, desired_heading, distance, dt)
    node_z, env_pitch = guides(plan)
    pose = finish_spine(spines, plan, node_z, env_pitch, foot_world)
    return SpineState(plan.key_xy), plan, pose


def ground_guides(
    spines: SpineBatch, height_at: HeightFn, foot_world: npt.ArrayLike | None = None
) -> GuideFn:
    """A :data:`GuideFn` from a terrain height query alone (no pseudo-physics)."""

    def guides(plan: SpinePlan) -> tuple[FloatArray, FloatArray]:
        return terrain_guides(spines, plan, height_at, foot_world)

    return guides


__all__ = [
    "GuideFn",
    "HeightFn",
    "SpineBatch",
    "SpineModel",
    "SpineParams",
    "SpinePlan",
    "SpinePose",
    "SpineState",
    "build_fresh",
    "build_spine",
    "feet_ahead",
    "finish_spine",
    "frame_from_yaw_pitch",
    "ground_guides",
    "hip_positions",
    "leg_frames",
    "node_pitch",
    "plan_spine",
    "pose_rows",
    "pose_with_rows",
    "reach_repeats",
    "refit",
    "repeat_for_reach",
    "spine_step",
    "terrain_guides",
    "visual_yaw",
    "wrap_angle",
]
