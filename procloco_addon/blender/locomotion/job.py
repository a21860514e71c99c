# SPDX-License-Identifier: GPL-3.0-or-later
"""What one rig's Generate Locomotion carries from stage to stage (``generate``: read, then
``simulation``: run the core, then ``generate``: write), in a module of its own so those
two import it and not each other.

- :class:`Job`: everything read from Blender for one rig, then its results;
- :class:`GaitChange`: one of the rig's Gait Changes mapped onto its legs;
- :class:`RigTracks`: the per-frame tracks the rig is written from, a thin view of one
  character of the core's ``sim.SimResult``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...core.locomotion import autogait
from ...core.locomotion import gait as core_gait
from ...core.locomotion.morphology import Morphology
from ...core.locomotion.sim import SimResult
from .. import rig, scene_terrain
from ..rig import controls

__all__ = ["SETTINGS", "GaitChange", "Job", "RigTracks", "settings_values"]


@dataclass(frozen=True)
class GaitChange:
    """A change of gait (and of speed, unless None) that begins at ``frame_index`` of the
    job's frames and takes ``transition_time`` seconds."""

    frame_index: int
    gait: core_gait.Gait
    transition_time: float
    speed: float | None
    name: str


@dataclass
class Job:
    """Everything one rig's generation needs, read from Blender by :func:`prepare`."""

    obj_name: str
    info: rig.RigInfo
    morphology: Morphology
    terrain: scene_terrain.SceneTerrain | None  # None until read_terrain
    gait: core_gait.Gait
    frames: np.ndarray  # (F,) scene frames
    dt: float  # seconds per frame
    speed: float  # m/s
    heading: float  # world yaw of the walk direction (radians from +X)
    turn_rate: float  # rad/s
    path: np.ndarray | None  # (n, 3) world polyline or None
    step_height: float
    spacing: float
    foot_offset: np.ndarray  # (n_legs, 2) body-frame offsets of the preferred footprints
    seed: int
    use_pelvis_physics: bool
    use_progression: bool
    use_gait_randomizer: bool
    # changes of gait and speed over the frames (GaitChange), in frame order
    gait_changes: tuple[GaitChange, ...] = ()
    # Gait: Auto (core.locomotion.autogait): the gait, stride and cycle follow the speed; None: the
    # gait circles and the Gait Changes' gaits
    auto_gait: autogait.AutoGaitParams | None = None
    # Auto's choice held at one speed (Make Cycle): the walk keeps ``gait`` but Auto's
    # physics (real gravity) and planning window, as Generate would at that speed
    held_auto: autogait.AutoGaitParams | None = None
    # What the Action is ("": a walk; "Cycle": Make Cycle's loop), in its name after
    # "ProcLoco" and on it (ACTION_KIND): a new one supersedes only an earlier one of its kind
    action_kind: str = ""
    # flexible spine (thesis §4.2, §4.4); used when the rig has one (morphology.spine)
    use_visual_yaw: bool = False
    spine_turn_rate: float = float(np.radians(120.0))  # rad/s
    spine_relax_time: float = 0.6  # s
    visual_yaw_gain: float = 1.0
    # Bones only an earlier generation (or bake) keyed, which this one does not drive: keyed
    # at rest so the new Action alone decides the pose (see stale_bones).
    held_bones: tuple[str, ...] = ()
    # Bones the solved bones hang from (a pelvis between the body bone and the hips, a leg
    # IK's parent) that the rig's own Action or NLA animates: keyed at the pose the walk was
    # read in, so the walk's legs hang from what they were solved for (see kept_bones).
    kept_bones: tuple[str, ...] = ()
    # What gets keyed: the solved bones themselves, or the controls that drive them.
    plan: controls.ControlPlan | None = None
    # Whether something may pull the keyed bones off the plan (drivers, limits): then the
    # evaluated feet are measured after writing.
    check_after: bool = False
    warnings: list[str] = field(default_factory=list)
    keyed_bones: tuple[str, ...] = ()
    result: RigTracks | None = None
    # While the simulation runs: the results of its first n frames.
    partial: Callable[[int], RigTracks] | None = None
    timings: dict[str, float] = field(default_factory=dict)
    # What read_terrain reads: the terrain objects' names and the lift of the surfaces.
    terrain_objects: tuple[str, ...] = ()
    lift: float = 0.0
    # What Key Reduction did when it is on (keys.reduce.Reduction), else None.
    key_reduction: Any = None
    # Crowds (several rigs in one simulation, see .crowd): the rig's feet and path keep clear
    # of the other rigs' bodies; its Seed Offset; the needle's start phase (cycles) and the
    # factor on its cycle times a crowd gives it (0 and 1: as generated alone).
    use_avoid_others: bool = True
    seed_offset: int = 0
    phase: float = 0.0
    cycle_scale: float = 1.0


#: The rig settings (``obj.procloco``) a :class:`Job` takes as they are, and their types.
SETTINGS: dict[str, type] = {
    "speed": float, "turn_rate": float, "step_height": float, "spacing": float, "seed": int,
    "use_pelvis_physics": bool, "use_progression": bool, "use_gait_randomizer": bool,
    "use_visual_yaw": bool, "spine_turn_rate": float, "spine_relax_time": float, "visual_yaw_gain": float,
    "use_avoid_others": bool, "seed_offset": int,
}


def settings_values(settings: Any) -> dict[str, Any]:
    """The :data:`SETTINGS` of a rig's settings group, as the :class:`Job`'s fields."""
    return {name: kind(getattr(settings, name)) for name, kind in SETTINGS.items()}


@dataclass
class RigTracks:
    """Per-frame tracks of one rig, ``F`` frames: ``body`` ``(F, 4, 4)`` body-to-world
    transforms, ``joints`` ``(F, n_legs, s + 1, 3)`` world joints (hip first), ``swing``
    ``(F, n_legs)`` feet in the air, ``feet`` ``(F, n_legs, 3)`` end-effector targets,
    ``ik_error`` ``(F, n_legs)`` distance from each end-effector to its target; ``needle``
    ``(F,)`` the gait needle's phase and ``phase_rate`` ``(F,)`` its speed in cycles per
    second; ``forced``, ``plan_failed``, ``disk_start``, ``disk_duration`` ``(F, n_legs)``
    (see ``core.locomotion.sim.SimResult``); ``leg_frame`` ``(F, n_legs, 3, 3)`` body-to-world rotation
    of what each leg hangs from; with the flexible spine, ``spine_joints`` ``(F, J, 3)``
    world spine joints (head first) and ``spine_rotation`` ``(F, J - 1, 3, 3)`` each spine
    bone's rotation from its rest direction (None without a spine); ``speed`` ``(F,)`` the
    speed asked of the controller; ``auto_band`` ``(F,)`` Auto's gait index (-1 without).
    Make Cycle builds its loop as one of these; Live Preview slices them frame by frame."""

    body: np.ndarray
    joints: np.ndarray
    swing: np.ndarray
    feet: np.ndarray
    ik_error: np.ndarray
    needle: np.ndarray
    phase_rate: np.ndarray
    forced: np.ndarray
    plan_failed: np.ndarray
    disk_start: np.ndarray
    leg_frame: np.ndarray
    spine_joints: np.ndarray | None = None
    spine_rotation: np.ndarray | None = None
    disk_duration: np.ndarray | None = None
    speed: np.ndarray | None = None
    auto_band: np.ndarray | None = None

    @classmethod
    def of(cls, res: SimResult, char: int = 0) -> RigTracks:
        """The tracks of character ``char`` of a core result."""
        legs = np.flatnonzero(res.legs.leg_char == char)
        body = np.zeros((res.n_frames, 4, 4))
        body[:, :3, :3] = res.pelvis_rotation[:, char]
        body[:, :3, 3] = res.pelvis_position[:, char]
        body[:, 3, 3] = 1.0
        n_spine = int(res.spine_n_joints[char])
        return cls(
            body=body, joints=res.joints[:, legs], swing=~res.contact[:, legs], feet=res.foot[:, legs],
            ik_error=res.ik_error[:, legs], needle=res.needle[:, char], phase_rate=res.phase_rate[:, char],
            forced=res.forced[:, legs], plan_failed=res.plan_failed[:, legs],
            disk_start=res.disk_start[:, legs], leg_frame=res.leg_frame[:, legs],
            spine_joints=res.spine_joints[:, char, :n_spine] if n_spine else None,
            spine_rotation=res.spine_rotation[:, char, :n_spine - 1] if n_spine else None,
            disk_duration=res.disk_duration[:, legs], speed=res.speed[:, char],
            auto_band=res.auto_band[:, char])


