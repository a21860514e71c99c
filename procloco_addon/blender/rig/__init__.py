# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading an armature: legs, body, spine, and the core morphology; writing poses back.

One job per module: :mod:`.names` (bone names as hints), :mod:`.rest` (rest geometry as
arrays), :mod:`.detect` (leg detection on those arrays), :mod:`.spine` (the spine chain),
:mod:`.info` (:class:`RigInfo`), :mod:`.read` (reading an armature with ``bpy``),
:mod:`.morphology` (the core morphology), :mod:`.pose` (poses back to bones) and
:mod:`.controls` (on a control rig, the controls that drive the solved bones: imported on
its own). Only :mod:`.read` and :mod:`.controls` import ``bpy``; the names of :mod:`.read`
load on first use, so the numpy modules import without Blender. Names with a leading
underscore are private to this package.

A **leg** is the bone chain from its *hip* bone down to its *end-effector* bone (thesis
§3.1: "the name of each leg hip joint and the name of its end-effector, e.g. the joint
before the foot"). Bones after the end-effector that lie flat on the ground (a human's
foot and toes, a wolf's paw), and a last bone under a tenth of the leg low by the ground
however steep (a hoof), are the leg's *foot*: they keep their rest orientation (turned with
the body's heading) instead of being solved by the IK.

Detection (:func:`detect_legs`, :func:`.detect.find_legs`) works in two passes:

1. **Names.** Bone names are split into tokens (``DEF-``/``ORG-``/``mixamorig:`` prefixes
   dropped, camelCase and separators split) and a side (``.L/.R``, ``_l/_r``,
   ``Left/Right``...). Runs of parent-to-child bones whose names hold a leg word (``thigh``,
   ``shin``, ``foot``, ``coxa``, ``femur``, ``tibia``, ``tarsus``, ``upper_arm``, ``Leg3``...)
   on one side form candidate chains. Bones whose names mark controls or helpers (``ik``,
   ``pole``, ``target``, ``heel``, ``MCH``...) never join a chain.
2. **Topology**, when names find fewer than two legs: every unbranched chain of bones that
   ends at a leaf, hangs from a branching bone and reaches down to the ground.

Either way a candidate is a leg only if it has at least two bones, its lowest point is
near the ground (the lowest contact of all candidates), it reaches down from its hip and its
hip stands with the others' (at least a third of the highest hip's height above the ground).
A leaf bone parented to the root beside each foot (an IK target) is a one-bone chain and
is never a leg; an IK bone with its toe bone there (MMD's leg IK, ``CTRL_foot > CTRL_toe``)
has its hip at the ankle and is not one either. A bone named as a helper that the next bone
of its chain hangs from (Genesis' ``lThighBend > lThighTwist > lShin``) is a segment of the
leg, not a helper. A chain on the midline hanging from behind every paired leg, reaching
further back and longer than the legs (or of more bones) is a tail lying on the ground, not
a leg, whatever its bones are called. Where two chains or more stand on the ground, a chain
whose lowest point (its bones and those below its end) stays 5 % of their length above it,
as high as another such chain, hangs and is not a leg either: a scorpion's pincer arms
(``ClawArm1.L > ... > Claw.L``) or a crab's claws held just above the floor, a kangaroo's
forelegs (a paw raised alone in the rest pose stays a leg).

The **body bone** (:attr:`RigInfo.body_bone`) is the legs' common ancestor, or the highest
plain bone above it (not a root, control or mechanism bone, not driven by a constraint, well
above the ground): Character Creator hangs the legs from ``CC_Base_Pelvis`` and the upper
body from ``CC_Base_Hip`` above it, and moving the pelvis alone would leave the upper body
behind. A connected bone cannot move: its parent carries the body then, a root included.

Geometry is read in **world space** from the armature's rest pose placed by the object's
world matrix, so scaled, rotated and moved rigs work (a uniform object scale is required:
non-uniform scale shears bone rotations). Everything the core sees is in the creature's
body frame (x forward, y left, z up) whose origin is the centroid of the hips.

The **spine** (:attr:`RigInfo.spine`) is the chain of bones from the body bone (the hips)
forward through the bones the legs hang from to the head: at each bone the chain goes on to
the child on the body's midline that carries the most legs, then, past the last girdle, to
the child that continues it forward. Each leg hangs from the nearest spine bone above its
hip. When the legs hang from two or more spine bones (quadrupeds, lizards) and
``read_rig(..., spine=True)``, :class:`SpineLayout` maps the chain to the core's flexible
spine (``core.locomotion.spine``): its joints, its virtual pelvis nodes (the head, one per girdle, the
back girdle at the hips' head) and which bone carries each leg.

:func:`solve_pose` converts per-frame core results (body frame and joint positions in the
world, and with a spine its bones' rotations) into pose-bone ``matrix_basis`` rotations and
the body bone's location, keeping each leg's knee plane and adding no twist;
:mod:`.actions` writes them in each bone's rotation mode.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .detect import LegChain
from .info import BodyInfo, RigInfo, SpineLayout
from .morphology import FOOT_EXTENT_SHARE, morphology_of
from .names import HELPER_WORDS, LEG_WORDS, split_name
from .pose import (
    GroundFn,
    PoseInputs,
    PoseTracks,
    _bend_normal,
    _frames,
    matrix_to_quaternion,
    solve_pose,
    solve_pose_steps,
    solve_poses_steps,
)
from .rest import RigError, _unit, uniform_scale

if TYPE_CHECKING:
    from .read import ReadCache, detect_legs, facing_source, leg_from_bones, read_rig, reading_once, shared

__all__ = [
    "FOOT_EXTENT_SHARE",
    "HELPER_WORDS",
    "LEG_WORDS",
    "BodyInfo",
    "GroundFn",
    "LegChain",
    "PoseInputs",
    "PoseTracks",
    "ReadCache",
    "RigError",
    "RigInfo",
    "SpineLayout",
    "_bend_normal",
    "_frames",
    "_unit",
    "detect_legs",
    "facing_source",
    "leg_from_bones",
    "matrix_to_quaternion",
    "morphology_of",
    "read_rig",
    "reading_once",
    "shared",
    "solve_pose",
    "solve_pose_steps",
    "solve_poses_steps",
    "split_name",
    "uniform_scale",
]

_READ = frozenset({"ReadCache", "detect_legs", "facing_source", "leg_from_bones", "read_rig", "reading_once",
                   "shared"})


def __getattr__(name: str) -> Any:
    # The bpy-reading names load on first use: the numpy modules import without Blender.
    if name in _READ:
        from . import read

        return getattr(read, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
