# SPDX-License-Identifier: GPL-3.0-or-later
"""What the shell knows about one rig: its body frame, spine layout and :class:`RigInfo`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .detect import LegChain
from .rest import _UP


@dataclass(frozen=True)
class BodyInfo:
    """The creature's body frame at rest, in the world."""

    origin: np.ndarray  # (3,) centroid of the hips
    forward: np.ndarray  # (3,) horizontal unit
    left: np.ndarray  # (3,)

    @property
    def matrix(self) -> np.ndarray:
        """``(4, 4)`` body-to-world rigid transform."""
        m = np.eye(4)
        m[:3, 0] = self.forward
        m[:3, 1] = self.left
        m[:3, 2] = _UP
        m[:3, 3] = self.origin
        return m


@dataclass(frozen=True)
class SpineLayout:
    """The rig's spine chain as the core's flexible spine (``core.locomotion.spine.SpineModel``).

    - ``joints``: ``(J, 3)`` world rest joints, head first: the tip of the head bone, then
      the head of every chain bone from the head bone back to the body bone (``J - 1``
      bones). Core bone ``i`` joins joints ``i`` and ``i + 1``: it is chain bone
      ``spine[-1 - i]`` of :attr:`RigInfo.spine`.
    - ``key_joint``: ``(K,)`` the virtual pelvis nodes: 0 (the head), one joint per girdle
      (the end of its bone nearest the legs' hips), ``J - 1`` (the body bone's head, the back
      girdle).
    - ``leg_key``: ``(L,)`` the node each leg belongs to; ``leg_bone``: ``(L,)`` the core
      bone each leg's hip hangs from (its nearest spine ancestor).
    """

    joints: np.ndarray
    key_joint: np.ndarray
    leg_key: np.ndarray
    leg_bone: np.ndarray


@dataclass(frozen=True)
class RigInfo:
    """Everything the shell needs about one armature, read once per generation.

    Arrays are in world space at the generation's first frame unless named ``_local``.
    ``spine`` is the spine chain from the body bone to the head (parent to child; empty when
    the rig has none); ``spine_layout`` is set when the spine drives the body (read with
    ``spine=True`` from a rig whose legs hang from two or more spine bones): its bones are
    then keyed too.
    """

    object_name: str
    legs: tuple[LegChain, ...]
    body_bone: str
    spine: tuple[str, ...]
    body: BodyInfo
    joints: tuple[np.ndarray, ...]  # per leg (k + 1, 3) rest joints (heads, then the end's tail)
    contact: np.ndarray  # (n_legs, 3) lowest point of each foot (ground contact) at rest
    foot_height: np.ndarray  # (n_legs,) height of the end-effector above its contact point
    foot_extent: np.ndarray  # (n_legs, 2) half size of each foot's ground print (forward, left)
    foot_points: tuple[np.ndarray, ...]  # per leg (p, 3) rest points of the foot bones (sole probes)
    # Per leg: (target bone, joint index) when an IK constraint on the leg pulls the chain to
    # a bone of this rig; that bone is keyed so the joint reaches the simulated position.
    ik_targets: tuple[tuple[str, int] | None, ...]
    world: np.ndarray  # (4, 4) object world matrix
    scale: float
    rest_local: dict[str, np.ndarray] = field(repr=False)  # bone -> (4, 4) armature-space rest
    parents: dict[str, str | None] = field(repr=False)
    basis: dict[str, np.ndarray] = field(repr=False)  # bone -> (4, 4) current matrix_basis
    warnings: tuple[str, ...] = ()
    spine_layout: SpineLayout | None = None
    # Per leg: the bone an IK constraint on the leg's first foot bone aims that bone at (MMD's
    # toe IK, ``左つま先ＩＫ``), or None; that bone is carried rigidly with the solved foot
    # and keyed, so the foot keeps the pitch solved for it.
    foot_ik_targets: tuple[str | None, ...] = ()
    # Solved bones under a bone the animator posed (a pelvis between the body bone and the
    # hips): bone -> (4, 4) armature-space rest with that pose (the solved bones at rest).
    # The walk turns them from there, as their joints were read; the others from rest_local.
    rest_posed: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def leg_length(self) -> np.ndarray:
        return np.array([np.linalg.norm(np.diff(j, axis=0), axis=1).sum() for j in self.joints])

    @property
    def driven_bones(self) -> tuple[str, ...]:
        names = [self.body_bone]
        if self.spine_layout is not None:
            names += list(self.spine)
        for leg in self.legs:
            names += list(leg.bones)
            names += list(leg.foot[:1])
        names += [t[0] for t in self.ik_targets if t is not None]
        names += [t for t in self.foot_ik_targets if t is not None]
        return tuple(dict.fromkeys(names))
