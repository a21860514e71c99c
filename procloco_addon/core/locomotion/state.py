# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-foot state, as one explicit structure: a ``Phase`` per foot and the plan of its swing.

Between two steps every foot is in exactly one phase:

- ``PLANTED``: on the ground, locked where it stands;
- ``SWING``: in the air on its gait swing, following ``SwingPlan.traj``;
- ``FORCED``: in the air on a forced step (its support went, it was left behind, or its
  landing spot was taken), timed by ``forced_elapsed`` / ``forced_duration`` instead of the
  gait;
- ``STUCK``: in its gait's swing sector but on the ground, because its plan failed (it is
  planted like any other foot and steps when its support goes or it is left behind).

Within a step the controller works on three boolean arrays unpacked from the phases
(``FootState.flags``: swinging, forced, failed) and packs them back at its end
(``FootState.set_flags``); the only combinations a step leaves are the four phases above.

Also here: the foot's swing plan (trajectory samples, what was under them when planned,
the commands it was planned for) and the bookkeeping of its current step
(``forced_behind``, ``dodged``, ``restarts``, ``retry``, ``blocked``, ``swing_u``).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..geometry import clip
from .types import BoolArray, FloatArray, IntArray


class Phase(IntEnum):
    """What a foot is doing between two steps (see the module docstring)."""

    PLANTED = 0
    SWING = 1
    FORCED = 2
    STUCK = 3


# (plain ints: an enum member compared with an array is converted at every comparison)
_SWING, _FORCED, _STUCK = int(Phase.SWING), int(Phase.FORCED), int(Phase.STUCK)


@dataclass
class SwingPlan:
    """The plan of every foot's current (or last) swing, ``k + 1`` samples each.

    ``traj (N, k + 1, 3)``: trajectory samples at uniform swing parameters from ``u0 (N,)``
    (the swing progress at which it was planned) to 1; ``target (N, 3)``: the footprint;
    ``support (N,)``: the exact surface height under it; ``ground (N, k + 1)``,
    ``forbidden (N, k + 1)``: what was under each sample when it was planned (moving
    obstacles are judged against it); ``heading``, ``speed (N,)``, ``spacing (N, 2)``: the
    commands it was planned for (a swing is re-planned when they change)."""

    traj: FloatArray
    u0: FloatArray
    target: FloatArray
    support: FloatArray
    ground: FloatArray
    forbidden: BoolArray
    heading: FloatArray
    speed: FloatArray
    spacing: FloatArray


@dataclass
class FootState:
    """Every foot's phase, position and plan ``(N, ...)``.

    ``foot (N, 3)``: where each foot is (on the ground it is planned on); ``support_z (N,)``:
    the surface under a planted foot when it landed; ``preferred (N, 3)``: the last
    preferred footprint; ``plan``: the swing plans. Step bookkeeping: ``forced_behind``: a
    forced step of a foot left behind; ``dodged``: this swing was re-planned for an obstacle
    closing in; ``restarts``: steps started again because the landing spot was taken;
    ``forced_elapsed``, ``forced_duration`` (s) of forced steps; ``swing_u``: swing progress
    this step (1: planted); ``retry``: a foot that started in its swing sector with a failed
    plan, planned again at the next step; ``blocked``: swings a moving obstacle cut this
    step."""

    phase: IntArray
    foot: FloatArray
    support_z: FloatArray
    preferred: FloatArray
    plan: SwingPlan
    forced_behind: BoolArray
    dodged: BoolArray
    restarts: IntArray
    forced_elapsed: FloatArray
    forced_duration: FloatArray
    swing_u: FloatArray
    retry: BoolArray
    blocked: BoolArray

    @property
    def swinging(self) -> BoolArray:
        """``(N,)`` feet in the air (``SWING`` or ``FORCED``)."""
        return np.asarray((self.phase == _SWING) | (self.phase == _FORCED))

    @property
    def forced(self) -> BoolArray:
        """``(N,)`` feet on a forced step."""
        return np.asarray(self.phase == _FORCED)

    @property
    def plan_failed(self) -> BoolArray:
        """``(N,)`` feet down in their swing sector because their plan failed."""
        return np.asarray(self.phase == _STUCK)

    def flags(self) -> tuple[BoolArray, BoolArray, BoolArray]:
        """The phases unpacked into fresh ``(swinging, forced, failed)`` arrays ``(N,)``."""
        return self.swinging, self.forced, self.plan_failed

    def set_flags(self, swinging: BoolArray, forced: BoolArray, failed: BoolArray) -> None:
        """Pack ``(swinging, forced, failed)`` back into phases. Raises ``ValueError`` on a
        combination that is no phase (a bug in the step's rules)."""
        illegal = (failed & (swinging | forced)) | (forced & ~swinging)
        if np.logical_or.reduce(illegal):
            raise ValueError(f"feet {illegal.nonzero()[0].tolist()} in no phase")
        self.phase = phases_of(swinging, forced, failed)


def phases_of(swinging: BoolArray, forced: BoolArray, failed: BoolArray) -> IntArray:
    """``(N,)`` the ``Phase`` of each foot from its flags (see ``FootState.set_flags``)."""
    return np.where(failed, _STUCK, np.where(forced, _FORCED, swinging.astype(np.int64)))


def start_feet(foot: FloatArray, samples: int) -> FootState:
    """Every foot planted at ``foot (N, 3)``, its plan a trajectory of ``samples + 1``
    points standing where it is."""
    n = foot.shape[0]
    plan = SwingPlan(
        traj=np.repeat(foot[:, None, :], samples + 1, axis=1),
        u0=np.zeros(n),
        target=foot.copy(),
        support=foot[:, 2].copy(),
        ground=np.zeros((n, samples + 1)),
        forbidden=np.zeros((n, samples + 1), dtype=bool),
        heading=np.zeros(n),
        speed=np.zeros(n),
        spacing=np.zeros((n, 2)),
    )
    return FootState(
        phase=np.full(n, Phase.PLANTED, dtype=np.int64),
        foot=foot,
        support_z=foot[:, 2].copy(),
        preferred=foot.copy(),
        plan=plan,
        forced_behind=np.zeros(n, dtype=bool),
        dodged=np.zeros(n, dtype=bool),
        restarts=np.zeros(n, dtype=np.int64),
        forced_elapsed=np.zeros(n),
        forced_duration=np.ones(n),
        swing_u=np.ones(n),
        retry=np.zeros(n, dtype=bool),
        blocked=np.zeros(n, dtype=bool),
    )


def support_points(feet: FootState, swinging: BoolArray) -> FloatArray:
    """``(N, 3)`` feet as the body rests on them: planted ones where they stand, swinging
    ones (``swinging (N,)``) where they will land."""
    return np.asarray(np.where(swinging[:, None], feet.plan.target, feet.foot))


def swing_parameter(feet: FootState, progress: FloatArray) -> FloatArray:
    """``(N,)`` each foot's parameter along its trajectory at swing ``progress (N,)``."""
    u0 = feet.plan.u0
    return clip((progress - u0) / np.maximum(1.0 - u0, 1e-9), 0.0, 1.0)


def sample_polyline(samples: FloatArray, u: FloatArray) -> FloatArray:
    """Points at parameters ``u (m,)`` in [0, 1] of polylines ``(m, k + 1, 3)`` sampled at
    uniform parameters (linear interpolation)."""
    k = samples.shape[1] - 1
    x = clip(u, 0.0, 1.0) * k
    i = np.minimum(np.floor(x).astype(np.int64), k - 1)
    f = (x - i)[:, None]
    rows = np.arange(samples.shape[0])
    return np.asarray(samples[rows, i] * (1.0 - f) + samples[rows, i + 1] * f)
