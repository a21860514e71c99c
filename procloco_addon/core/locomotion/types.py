# SPDX-License-Identifier: GPL-3.0-or-later
"""The locomotion controller's types, in one place: its knobs (``ControllerParams``), a
character's planner level of detail (``PlannerLOD``), one step's commands
(``StepControls``) and one step's statistics (``StepStats``), plus the array aliases and
the two constants the other ``locomotion`` modules share."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ..world.terrain import NO_SURFACE
from .pelvis_physics import PelvisPhysicsParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Heights below this are "no surface here" (a hole in the ground).
VOID = NO_SURFACE * 0.5
#: A change of the needle rate in one step by more than this factor re-makes the pelvis
#: particles' orbit (see ``pelvis.pogo_heights``).
RATE_JUMP = 2.0


@dataclass(frozen=True)
class ControllerParams:
    """Controller knobs. Lengths marked "× leg" are fractions of the character's mean leg
    length; times marked "× cycle" fractions of its gait cycle.

    - ``window_cells``, ``window_cell``: the planning window (thesis: 70 cells of 7 cm);
      ``window_cell=None`` uses 0.13 × leg (7 cm for a half-metre spider leg).
    - ``slice_size``: height slices of the planner in metres (None: no slices);
      ``max_couples_after_first``: the planner's LOD budget (None: full search).
    - ``candidate_radius``, ``fixed_distance`` (× leg): planner search around the preferred
      footprint; ``max_height_change`` (× leg): highest step up or down a footprint may be.
    - ``max_stroke`` (× leg): longest stance sweep before the needle speeds up.
    - ``max_turn_rate``: rad/s.
    - re-planning thresholds: ``replan_heading`` (rad), ``replan_speed`` (relative),
      ``replan_spacing`` (× leg); heading/speed/spacing re-plans only before
      ``replan_until`` of the swing.
    - ``feedback_threshold`` (× leg) and ``feedback_gain`` (offset share worked off per cycle).
    - ``reach_margin``: largest hip-to-foot distance allowed, as a share of the leg length;
      the pelvis sinks to keep it, by at most ``guard_max_drop`` (× body thickness). A
      spine's nodes are pulled toward the feet instead (step 4 repeated), each by at most
      the same distance; ``reach_release_time`` (s): time constant over which a node's pull
      lets go once no leg needs it (the pull itself acts at once); ``swing_reach_slack``: a
      swinging foot pulls only beyond ``1 + swing_reach_slack × (1 - swing progress)`` of the
      reach, so the body follows a foot going down a step as it comes down (the swinging
      foot itself goes to the nearest point its leg reaches meanwhile).
    - ``height_time`` (× cycle): time constant of the pelvis height/pitch/roll filter.
    - ``trajectory_samples``: samples kept of each swing trajectory (constant speed).
    - ``snap_tolerance`` (× step height): a footprint may be lowered by up to this much onto
      the exact surface under its point (the planner's grid height is the highest surface
      under the foot's sole, a box about its point).
    - ``body_samples``: terrain samples under the body box (along, across).
    - ``support_tolerance``: metres the support under a planted foot may move before the
      foot steps again; ``ik_tolerance``: metres within which the leg IK stops.
    - ``watch_distance`` (× leg): a planted foot also steps away when a moving obstacle comes
      within this distance of its foot box (the ground there rose above the foot or became
      forbidden since it landed), before the obstacle reaches it.
    - ``forced_swing``: duration of a forced step as a share of the leg's swing duration.
    - ``clock``: the clock of the per-phase timings in ``StepStats.seconds`` (wall time; a
      benchmark on a shared machine may pass ``time.process_time``).
    - ``max_drop`` (× body thickness), ``step_early_reach`` (share of the leg length): a
      planted foot that would need the pelvis to sink more than ``max_drop`` to stay within
      ``step_early_reach`` of its hip steps early (a forced step) instead, before the leg is
      stretched. Such a step waits while it would leave its character with fewer than
      ``min_planted`` feet down (one less than its legs at most), unless the pelvis would
      have to drop more than ``urgent_drop`` (× body thickness) to keep the foot.
    """

    window_cells: int = 70
    window_cell: float | None = None
    slice_size: float | None = 0.1
    max_couples_after_first: int | None = None
    candidate_radius: float = 0.25
    fixed_distance: float = 0.5
    max_height_change: float = 0.5
    max_stroke: float = 0.9
    max_turn_rate: float = 2.0
    replan_heading: float = 0.15
    replan_speed: float = 0.25
    replan_spacing: float = 0.05
    replan_until: float = 0.6
    feedback_threshold: float = 0.1
    feedback_gain: float = 1.0
    reach_margin: float = 0.97
    height_time: float = 0.25
    trajectory_samples: int = 32
    snap_tolerance: float = 0.5
    body_samples: tuple[int, int] = (5, 3)
    support_tolerance: float = 0.002
    ik_tolerance: float = 1e-5
    watch_distance: float = 0.15
    forced_swing: float = 0.6
    max_drop: float = 0.15
    step_early_reach: float = 0.92
    guard_max_drop: float = 0.5
    reach_release_time: float = 0.2
    swing_reach_slack: float = 0.1
    min_planted: int = 2
    urgent_drop: float = 0.45
    clock: Callable[[], float] = time.perf_counter
    physics: PelvisPhysicsParams = field(default_factory=PelvisPhysicsParams)


@dataclass(frozen=True)
class PlannerLOD:
    """A character's planner level of detail (thesis §3.7): couples evaluated after the first
    valid one (None: full search, 0: stop at the first) and the height-slice size in metres
    (None: no slices, go over everything)."""

    max_couples_after_first: int | None = None
    slice_size: float | None = 0.1


@dataclass(frozen=True)
class StepControls:
    """Commands for one step. ``speed``, ``heading``, ``step_height``: ``(C,)`` (m/s,
    radians from world +X, metres); ``spacing``: ``(N, 2)`` body-frame xy offset of each foot
    from its rest position; ``pelvis_physics``: ``(C,)`` bool; ``ik``: ``(C,)`` bool (False
    skips the IK of a character, e.g. off-screen under LOD)."""

    speed: FloatArray
    heading: FloatArray
    step_height: FloatArray
    spacing: FloatArray
    pelvis_physics: BoolArray
    ik: BoolArray


@dataclass
class StepStats:
    """Planner statistics of one step: plans, failed plans, couples and paths evaluated,
    windows cut, re-plans, forced steps, plans retried without the other feet and slices
    (``n_relaxed``), straight fallback steps (``n_fallback``), swinging feet moved to the
    closest point their leg reaches (``n_bent``); and seconds per phase
    (``maps``, ``planning``, ``ik``, ``physics``, ``spine``, ``rest``)."""

    n_plans: int = 0
    n_failed: int = 0
    n_couples: int = 0
    n_paths: int = 0
    n_windows: int = 0
    n_replans: int = 0
    n_forced: int = 0
    n_relaxed: int = 0
    n_fallback: int = 0
    n_bent: int = 0
    seconds: dict[str, float] = field(default_factory=dict)
