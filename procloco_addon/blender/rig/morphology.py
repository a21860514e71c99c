# SPDX-License-Identifier: GPL-3.0-or-later
"""The rig as the core's :class:`~procloco_addon.core.locomotion.morphology.Morphology`, in its body frame."""

from __future__ import annotations

import numpy as np

from ...core.locomotion.morphology import Morphology, chain_angles
from ...core.locomotion.spine import DEFAULT_JOINT_PITCH_LIMIT, DEFAULT_JOINT_YAW_LIMIT
from .info import RigInfo
from .names import split_joints
from .rest import RigError, _apply

FOOT_EXTENT_SHARE = 1.0
#: Largest rest bend (radians) of a joint between two halves of one limb bone.
_SPLIT_BEND = float(np.radians(10.0))


def morphology_of(
    info: RigInfo,
    joint_yaw_limit: float = DEFAULT_JOINT_YAW_LIMIT,
    joint_pitch_limit: float = DEFAULT_JOINT_PITCH_LIMIT,
) -> Morphology:
    """The core morphology of the rig, in its body frame (origin at the hips' centroid).

    The end-effectors are the core's feet. A leg whose foot bones hold its end-effector above
    the ground (a human's ankle) is handled by the caller, which raises the terrain the core
    sees by the mean :attr:`RigInfo.foot_height` (see ``locomotion.generate``); each leg's
    ``foot_lift`` is its own foot height's difference from that mean. With a
    :attr:`RigInfo.spine_layout` the morphology has the flexible spine
    (``Morphology.with_spine``) with these per-joint limits (radians). A hinge between two
    halves of one limb bone (``names.split_joints``: a twist and a stretch bone), nearly
    straight at rest, is held at its rest angle.
    """
    to_body = np.linalg.inv(info.body.matrix)
    chains = [_apply(to_body, j) for j in info.joints]
    hips = np.array([c[0] for c in chains])
    ends = np.array([c[-1] for c in chains])
    if float(np.mean(hips[:, 2] - ends[:, 2])) <= 0.0:
        raise RigError("The hips are not above the feet: the rig must stand on its legs in its rest pose")
    lo, hi = hips[:, :2].min(axis=0), hips[:, :2].max(axis=0)
    reach = float(info.leg_length.mean())
    # The footprint the planner keeps clear of obstacles and of the other feet's soles: at
    # least 4 % of the leg, and as far as the foot bones (toes, paw, tarsus) reach from the
    # end-effector (its box is centred on the end-effector), so toes stay out of obstacles.
    foot_half = np.maximum(FOOT_EXTENT_SHARE * info.foot_extent.max(axis=0), 0.04 * reach)
    # The sole another foot may not land on: the end-effector's own print, the box of a foot
    # without foot bones. Keeping other feet a whole foot box away instead would keep them two
    # toe reaches apart: the example ant's tarsi reach 0.37 of its leg, and its hind feet
    # found no footprint beside the middle ones.
    sole_half = np.full(2, 0.04 * reach)
    labels = [leg.label for leg in info.legs]
    common = {
        "body_box": (0.5 * (lo + hi), 0.5 * (hi - lo) + 0.1 * reach),
        "foot_half_extents": foot_half,
        "sole_half_extents": np.minimum(sole_half, foot_half),
        # the terrain is raised by the mean foot height (locomotion.generate): each
        # end-effector stands its own foot height above the ground
        "foot_lift": info.foot_height - float(np.mean(info.foot_height)),
    }
    try:
        morph = Morphology.from_rest_joints(chains, labels, **common)
        # A joint between two halves of one limb bone (twist and stretch bones) keeps its rest
        # angle: the leg bends at its knee, not in the middle of its shin.
        locks = [(k, j) for k, leg in enumerate(info.legs) for j in split_joints(leg.bones)]
        if locks:
            up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), morph.plane_normal.shape)
            rest = chain_angles(morph.rest_joints, morph.plane_normal, up, morph.n_segments)
            j_min, j_max = morph.joint_min.copy(), morph.joint_max.copy()
            for k, j in locks:
                if abs(float(rest[k, j])) <= _SPLIT_BEND:
                    j_min[k, j] = j_max[k, j] = rest[k, j]
            morph = Morphology.from_rest_joints(chains, labels, plane_normal=morph.plane_normal,
                                                joint_min=j_min, joint_max=j_max, **common)
        layout = info.spine_layout
        if layout is not None:
            morph = morph.with_spine(
                _apply(to_body, layout.joints), key_joint=layout.key_joint, leg_key=layout.leg_key,
                leg_bone=layout.leg_bone, joint_yaw_limit=joint_yaw_limit,
                joint_pitch_limit=joint_pitch_limit,
            )
        return morph
    except ValueError as err:
        raise RigError(str(err)) from err
