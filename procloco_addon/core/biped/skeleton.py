# SPDX-License-Identifier: GPL-3.0-or-later
"""The biped skeleton: joints, rest offsets, legs, and forward kinematics.

Conventions (the whole biped package uses them):

* Joint ``0`` is the pelvis, the only joint without a parent. Parents come before their
  children, so one pass over the joints in index order is a valid forward-kinematics order.
* The rest pose has every joint rotation equal to the identity. ``offsets[j]`` is the rest
  position of joint ``j`` relative to its parent, in the parent's (rest) frame, which in the
  rest pose is the character frame: **x forward, y left, z up**.
* A pose is ``joint_rot (..., J, 4)``: each joint's rotation relative to its parent
  (quaternions ``w, x, y, z``), plus ``pelvis_pos (..., 3)``: where the pelvis joint is in
  the *character frame*, the ground frame that carries the root motion (position on the
  ground and yaw). The Blender shell converts its bones' own rest frames to this convention.
* Each leg names five joints: ``hip`` (thigh head), ``knee`` (shin head), ``ankle`` (foot
  head), and two contact points under the foot, ``heel`` and ``toe``, which must be
  descendants of the ankle (leaf joints are fine). ``knee`` is a child of ``hip`` and
  ``ankle`` a child of ``knee``: the two-segment leg of the thesis' IK (§3.8.2).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from . import quat

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

LEFT = 0
RIGHT = 1


@dataclass(frozen=True)
class LegJoints:
    """Joint indices of one leg."""

    hip: int
    knee: int
    ankle: int
    heel: int
    toe: int


@dataclass(frozen=True)
class Skeleton:
    """Joint hierarchy of a biped; see the module docstring for the conventions."""

    names: tuple[str, ...]
    parents: IntArray
    offsets: FloatArray
    left: LegJoints
    right: LegJoints
    thigh_length: FloatArray = field(init=False)
    shin_length: FloatArray = field(init=False)

    def __post_init__(self) -> None:
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=float)
        n = len(self.names)
        if parents.shape != (n,) or offsets.shape != (n, 3):
            raise ValueError(f"parents must be ({n},) and offsets ({n}, 3)")
        if n == 0 or parents[0] != -1:
            raise ValueError("joint 0 must be the pelvis, the only joint without a parent")
        if np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n)):
            raise ValueError("every joint but the pelvis needs a parent listed before it")
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        lengths = []
        for side, leg in (("left", self.left), ("right", self.right)):
            if parents[leg.knee] != leg.hip or parents[leg.ankle] != leg.knee:
                raise ValueError(f"{side} leg: the knee must be a child of the hip and the ankle of the knee")
            for point in (leg.heel, leg.toe):
                if not self.is_descendant(point, leg.ankle):
                    raise ValueError(f"{side} leg: heel and toe must be descendants of the ankle")
            thigh = float(np.linalg.norm(offsets[leg.knee]))
            shin = float(np.linalg.norm(offsets[leg.ankle]))
            if thigh < 1e-6 or shin < 1e-6:
                raise ValueError(f"{side} leg has a zero-length bone")
            lengths.append((thigh, shin))
        object.__setattr__(self, "thigh_length", np.array([lengths[0][0], lengths[1][0]]))
        object.__setattr__(self, "shin_length", np.array([lengths[0][1], lengths[1][1]]))

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def leg(self, side: int) -> LegJoints:
        return self.left if side == LEFT else self.right

    def is_descendant(self, joint: int, ancestor: int) -> bool:
        j = joint
        while j >= 0:
            if j == ancestor:
                return True
            j = int(self.parents[j])
        return False

    def index(self, name: str) -> int:
        return self.names.index(name)


def forward_kinematics(
    skeleton: Skeleton, joint_rot: FloatArray, pelvis_pos: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Joint positions and rotations in the character frame.

    ``joint_rot`` is ``(..., J, 4)`` (local rotations), ``pelvis_pos`` ``(..., 3)``.
    Returns ``(pos (..., J, 3), rot (..., J, 4))``; vectorised over all leading axes, one
    short loop over joints.
    """
    n = skeleton.n_joints
    lead = joint_rot.shape[:-2]
    pos = np.empty((*lead, n, 3))
    rot = np.empty((*lead, n, 4))
    pos[..., 0, :] = pelvis_pos
    rot[..., 0, :] = joint_rot[..., 0, :]
    parents = skeleton.parents
    offsets = skeleton.offsets
    for j in range(1, n):
        p = parents[j]
        pos[..., j, :] = pos[..., p, :] + quat.rotate(rot[..., p, :], np.broadcast_to(offsets[j], (*lead, 3)))
        rot[..., j, :] = quat.mul(rot[..., p, :], joint_rot[..., j, :])
    return pos, rot


def foot_points(skeleton: Skeleton, joint_pos: FloatArray) -> FloatArray:
    """Heel and toe positions of both feet: ``(..., 2 feet [L, R], 2 points [heel, toe], 3)``."""
    idx = np.array([[skeleton.left.heel, skeleton.left.toe], [skeleton.right.heel, skeleton.right.toe]])
    return joint_pos[..., idx, :]


def to_world(root_pos: FloatArray, root_yaw: FloatArray, local: FloatArray) -> FloatArray:
    """Character-frame points ``(F, ..., 3)`` to the world, given the root ``(F, 3)`` and yaw ``(F,)``."""
    extra = local.ndim - 2
    yaw = root_yaw.reshape(root_yaw.shape + (1,) * extra)
    pos = root_pos.reshape(root_pos.shape[:1] + (1,) * extra + (3,))
    return pos + quat.rot2(yaw, local)
