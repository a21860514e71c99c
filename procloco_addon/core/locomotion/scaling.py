# SPDX-License-Identifier: GPL-3.0-or-later
"""Creature-size scaling: the controller's and the planner's constants for a creature of a
given leg length, written once for Generate Locomotion, the benchmarks and the tests.

The core's defaults are tuned for half-metre legs (7 cm planning cells, 10 cm height
slices). Planning cells and height slices scale with the creature instead, so a rig scaled
×100 plans the same steps on a 100 times larger terrain.

The pelvis's pogo stick bounces by about g T² for a cycle of T seconds. With the gait
circles T is the rig's cycle time whatever its size, and a 2 cm wolf would bob by its own
leg length: gravity then scales with the creature (real gravity at ``REFERENCE_LEG``), so a
rig scaled ×0.01 or ×100 bobs the same for its size. With Gait: Auto the cycle follows the
Froude number (T grows as the square root of the size) and real gravity keeps the bounce to
scale (``auto_physics``). The planted feet's support tolerance (2 mm at ``REFERENCE_LEG``)
and the leg IK's (10 µm there) scale with the creature either way.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .autogait import AutoGaitParams
from .footprints import PlannerParams
from .morphology import LegBatch, Morphology
from .pelvis_physics import PelvisPhysicsParams
from .rig import build_rig
from .types import ControllerParams

__all__ = ["GRAVITY", "REFERENCE_LEG", "planning_window", "scaled_params", "stroke_limit"]

#: Leg length (m) at which the simulation's physical constants are the real ones.
REFERENCE_LEG = 0.7325  # the Rigify wolf's
#: Real gravity (m/s²).
GRAVITY = 9.81
#: Planning window: cells across, and the cell size in leg lengths (4.5 legs across).
WINDOW_CELLS = 70
WINDOW_CELL = 0.065
#: Height slices and edge height of the planner, in leg lengths.
SLICE_SIZE = 0.14
EDGE_HEIGHT = 0.055


def planning_window(leg: float, auto: AutoGaitParams | None = None,
                    speeds: Sequence[float] = ()) -> tuple[int, float]:
    """Cells and cell size (m) of the planning window for mean leg length ``leg`` (m): 70
    cells of 0.065 leg; with Gait: Auto (``auto``) grown when the fastest of ``speeds``
    (m/s) would put a landing foot beyond its edge (the window is centred on the pelvis; a
    front foot lands up to about a leg and a half plus a stride ahead of where the pelvis
    was at lift-off). Cells and size grow alike, by the square root of the needed growth, so
    planning stays affordable at a gallop. (The gait circles' walks keep the window they
    were tuned with.)"""
    cells, cell = WINDOW_CELLS, WINDOW_CELL * leg
    if auto is None or not speeds:
        return cells, cell
    v_max = max(speeds)
    half = 1.5 * leg + v_max * float(auto.schedule([v_max])[2][0])
    growth = half / (0.5 * cells * cell)
    if growth <= 1.0:
        return cells, cell
    return int(np.ceil(cells * np.sqrt(growth))), cell * float(np.sqrt(growth))


def scaled_params(leg: float, step_height: float, *, auto_physics: bool = False,
                  window: tuple[int, float] | None = None) -> tuple[ControllerParams, PlannerParams]:
    """The controller and planner settings of a creature whose mean leg is ``leg`` metres,
    stepping ``step_height`` metres high. ``auto_physics``: real gravity (Gait: Auto's
    cycle follows the size); else gravity scales with the creature (see the module
    docstring). ``window``: the planning window's cells and cell size (default
    :func:`planning_window` without Auto)."""
    size = leg / REFERENCE_LEG
    gravity = GRAVITY * (1.0 if auto_physics else size)
    cells, cell = planning_window(leg) if window is None else window
    params = ControllerParams(window_cells=cells, window_cell=cell, slice_size=SLICE_SIZE * leg,
                              support_tolerance=0.002 * size, ik_tolerance=1e-5 * size,
                              physics=PelvisPhysicsParams(gravity=gravity))
    planner = PlannerParams(step_height=step_height, slice_size=SLICE_SIZE * leg, leg_reach=leg,
                            candidate_radius=params.candidate_radius * leg,
                            fixed_distance=params.fixed_distance * leg, edge_height=EDGE_HEIGHT * leg)
    return params, planner


def stroke_limit(morphology: Morphology) -> float:
    """The longest stance sweep (m) the legs of ``morphology`` allow walking straight ahead,
    as the controller finds it with the creature-size settings (``rig.Rig.stroke_limit``,
    the planning window of :func:`planning_window` without Auto): what Gait: Auto's stride
    keeps within (``AutoGaitParams.stroke``)."""
    legs = LegBatch.stack([morphology])
    params, _ = scaled_params(float(legs.leg_length.mean()), 0.0)
    return float(build_rig(legs, params).stroke_limit[0])
