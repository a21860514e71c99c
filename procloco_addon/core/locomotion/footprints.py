# SPDX-License-Identifier: GPL-3.0-or-later
"""Footprint planning: the best couple (footprint, trajectory) for every swinging foot of a
step (thesis §3.5, §3.7, Appendix E).

:func:`plan_footsteps` is the planner the character controller calls, once per step, for
every foot that starts (or restarts) a swing; each :class:`FootRequest` is one foot and gets
one :class:`Couple`. For each foot:

1. **Candidates** (§3.5.1): positions around the preferred footprint on the preferred
   footprint's own sub-cell lattice (so the preferred footprint itself is a candidate, exactly),
   within ``candidate_radius``. Never candidates: cells inside or next to avoided obstacles and
   other feet (the obstacle map, enlarged by the foot shape), cells without any surface, cells
   the leg cannot reach from its hip, or too far above/below the foot.
2. **Target score** in [0, 1] (§3.5.1), the product of four criteria:
   distance to the preferred footprint ``1 - d / fixed_distance``; free neighbours ``n / 8``
   (a neighbour is not free if forbidden or if the ground there differs by more than
   ``edge_height``); ``edge_score`` (0.8) on an obstacle's rim (a neighbour lower by more than
   ``edge_height``); 0 if the leg would cross another leg (hip→footprint crosses another
   hip→foot).
3. **Height slices** (§3.5.2, Figure 3.25): for slice levels ``z_foot + k * slice_size``
   every cell higher than the level is forbidden, so paths walk around it and over everything
   lower; the last pass has no slice and goes over everything. ``slice_size=None``: only that
   last pass. Levels stop at the leg's reach above the foot and at the highest surface in the
   search rectangle; levels forbidding the same cells are merged.
4. **Best couple with partial scores** (Appendix E): targets by decreasing score; the search
   stops at the first target whose score cannot beat the best couple (path scores are at most
   1); a couple's 2D score bounds its 3D score, so the 3D trajectory is only built when the 2D
   bound beats the best couple. A target in plain sight at some slice is not tried again at
   higher slices (the same straight couple). The result equals the exhaustive search's (ties
   go to the earlier couple in the same order), which ``exhaustive=True`` runs for checking.
   Path scores (:mod:`.pathing`): straightness × ``1 / (1 + turning / 2π)`` in 2D, times a
   climbing factor in 3D (the square of a clean arc's length bound over the length).
5. **LOD** (§3.7): ``max_couples_after_first`` limits the couples evaluated once a valid
   couple exists (0: stop at the first valid couple); ``slice_size`` (None = no slices).

One wavefront per slice, grown from the foot, serves every target (the distance to all
candidates at once); ``shared_wavefront=False`` grows one per (target, slice) as the thesis
does, for comparison. Nothing ever raises for an unreachable target nor returns NaN: a failed
plan is a :class:`Couple` with ``ok=False`` and a ``message``.

**How the feet are searched together.** The search boxes of all feet are stacked into
``(n, H, W)`` arrays (:class:`_Batch`: each foot's box at the top-left of its slice, blocked
past its own size), and every step of the search that does not depend on the others runs
once for all of them: the other feet's cells, foot kernels, obstacle maps of each slice (one
dilation per distinct kernel), candidate scores (:func:`_score_all`), slice levels
(:func:`_levels_all`). Then the search goes in rounds (:func:`_run`): each foot's search is a
:class:`_Search` (its next target and slice, its :class:`_Best` couple so far, its counts)
that :func:`_next_couple` advances over the couples needing no array work and stops at what
it needs next (:class:`_Next`: the maps of a slice, a couple evaluated, or the end); a round
evaluates the next couple of every foot still searching (its line of sight, its straight
plan, the wavefronts its couple needs, the 3D trajectories) in a few vectorised calls, and
:func:`_after_couple` books each. Numpy's cost per call, not its arithmetic, is what a plan
costs, so a step's plans cost a few rounds of calls instead of a few hundred calls per foot.
The last one or two feet of a search finish alone (:func:`_search_alone`: a round for one
foot costs more than its couples), and a batch of one foot is searched the same way.

The tests keep a one-foot planner written out plainly (``tests/core/reference_planner.py``)
and compare the two: the same decisions (success, footprint cell and target, slice, every
count) exactly, the floats to a few ulps (numpy may group a reduction differently for arrays
of another length or alignment).
"""

from __future__ import annotations

import enum
import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..geometry import column_pair, planar_length
from ..world.pathing import (
    DistanceField,
    FootTrajectory,
    Path2D,
    PathContext,
    PathParams,
    Region,
    RegionFrame,
    lift_each,
    path_score_2d,
    region_frame,
    region_masks,
    segments_clear_each,
    turning_each,
    vertical_factor,
    wavefront_each,
)
from ..world.terrain import (
    _VOID_BELOW,
    NO_SURFACE,
    WindowGrids,
    _overlaps,
    _rect_offsets,
    dilate_each,
    foot_kernels,
    raster_boxes,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]

_NEIGHBOURS = np.array([(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)])


@dataclass(frozen=True)
class PlannerParams:
    """The planner settings of a character (what the user's settings and the character's LOD
    choose; one object per character, shared by all its feet). Lengths in metres.

    ``step_height``: clearance of the swing above what it passes over.
    ``slice_size``: height slices for "around or over" (None: no slices, go over everything).
    ``leg_reach``: how far a footprint may be from the hip (horizontal; a request's own
    ``leg_reach`` replaces it), the default ``max_height_change`` and the search rectangle's
    width (half ``max(candidate_radius, reach / 2)`` unless the search switches say).
    ``candidate_radius``: candidates within this distance of the preferred footprint.
    ``fixed_distance``: distance at which the distance criterion reaches 0.
    ``max_couples_after_first``: LOD budget (None: full search; 0: first valid couple).
    ``edge_height``: a height step larger than this between neighbour cells is an edge.
    ``edge_score``: the criterion's value on an obstacle rim (thesis: 0.8).
    ``max_height_change``: footprints further than this above/below the foot are never
    candidates (None: the reach).
    ``tension``: of the 2D cardinal curve.
    ``leg_clearance_score``: the factor of a footprint whose leg line does not clear the
    ground (:class:`LegGeometry` ``leg_length``; a fifth criterion of §3.5.1: taken only when
    nothing better is left, e.g. with an obstacle under the body).
    """

    step_height: float = 0.1
    slice_size: float | None = 0.1
    leg_reach: float = 0.6
    candidate_radius: float = 0.2
    fixed_distance: float = 0.3
    max_couples_after_first: int | None = None
    edge_height: float = 0.04
    edge_score: float = 0.8
    max_height_change: float | None = None
    tension: float = 0.5
    leg_clearance_score: float = 0.2

    def __post_init__(self) -> None:
        if self.slice_size is not None and not self.slice_size > 0.0:
            raise ValueError("slice_size must be positive or None")
        if not (self.leg_reach > 0.0 and self.fixed_distance > 0.0 and self.candidate_radius >= 0.0):
            raise ValueError("leg_reach and fixed_distance must be positive, candidate_radius >= 0")
        if self.max_couples_after_first is not None and self.max_couples_after_first < 0:
            raise ValueError("max_couples_after_first must be >= 0 or None")


@dataclass(frozen=True)
class LegGeometry:
    """What the planner needs of one leg and its foot, computed once per rig (one object per
    leg, shared by all its plans). Lengths in metres.

    ``foot_half_extents``: the foot's ground box (forward, left half sizes): what it keeps
    clear of obstacles, holes and other feet. ``sole_half_extents``: the part of the foot that
    stands, a box about its point (None: the foot box): another foot may not land on it, and
    the foot lands at the highest ground under it (within the foot box). A foot whose toes
    reach far from its end-effector has a large foot box but stands on a small sole: two such
    feet may stand closer than two foot boxes, as long as neither's box covers the other's
    sole, and on a slope such a foot stands on the ground under its sole, not on the ground
    its box reaches up the slope.

    Checks that need the hip's height (the request's ``hip_z``; skipped without it):
    ``reach_3d``: largest distance from the hip to a footprint in 3D (None: only the
    horizontal reach), with the request's ``reach_sweep`` added to the horizontal distance
    and the hip allowed to sink its ``reach_sink`` toward a footprint below it.
    ``leg_length``: the straight line from a footprint up to the hip should pass over the
    elevation map (a lower leg beside a crate would otherwise run through it), raised by
    ``leg_arch`` times the half-height a two-segment leg of that length bends over that
    distance (legs whose knees rise above the hip-foot line; 0 for the others); a footprint
    whose line does not is scored :attr:`PlannerParams.leg_clearance_score` times lower;
    None: no such check. ``max_straddle``: a footprint whose foot box reaches ground more
    than this above the ground at its own point hangs over a height step, it is never a
    candidate (None: no check).
    """

    foot_half_extents: tuple[float, float] = (0.03, 0.03)
    sole_half_extents: tuple[float, float] | None = None
    reach_3d: float | None = None
    leg_length: float | None = None
    leg_arch: float = 0.0
    max_straddle: float | None = None


@dataclass(frozen=True)
class SearchSwitches:
    """Switches of the search itself, for tests and benchmarks (the product runs the
    defaults, whose answers the others check or time).

    ``shared_wavefront``: one wavefront per slice from the foot (True) or one per target and
    slice (False, the thesis's way). ``exhaustive``: evaluate every couple fully (the
    reference the pruned search must equal; ignores the LOD budget). ``max_targets``: cap on
    the number of candidates considered (best first), None for all. ``los_shortcut``: build
    no wavefront for a target in plain sight of the foot (the straight line is what the
    wavefront and line-of-sight steps would give anyway). ``search_half_width``: half width
    of the search rectangle in metres (None: ``max(candidate_radius, reach / 2)``).
    """

    shared_wavefront: bool = True
    exhaustive: bool = False
    max_targets: int | None = None
    los_shortcut: bool = True
    search_half_width: float | None = None


#: The search the product runs.
DEFAULT_SEARCH = SearchSwitches()
#: A leg with the default foot box and none of the checks that need the hip's height.
DEFAULT_LEG = LegGeometry()


@dataclass(frozen=True)
class Couple:
    """The planner's answer for one foot.

    ``ok``: a valid couple was found; ``footprint``: ``(3,)`` world position (the foot's start
    when not ok); ``trajectory``: the 3D swing (None when not ok); ``score`` =
    ``target_score * path_score`` in [0, 1]; ``n_couples``: couples (target, slice) whose 2D
    plan was built; ``n_paths``: 3D trajectories built; ``n_targets``: candidate footprints;
    ``n_wavefronts``: distance fields grown; ``first_valid_couple``: 1-based index of the first
    valid couple among the evaluated ones (0 if none); ``n_couples_after_first``;
    ``slice_level``: the slice of the chosen couple (None = no slice); ``message``: why not ok.
    """

    ok: bool
    footprint: FloatArray
    trajectory: FootTrajectory | None
    score: float
    target_score: float
    path_score: float
    n_couples: int
    n_paths: int
    message: str = ""
    n_targets: int = 0
    n_wavefronts: int = 0
    wavefront_iterations: int = 0
    first_valid_couple: int = 0
    n_couples_after_first: int = 0
    slice_level: float | None = None
    target_index: int = -1


def _fail(start: FloatArray, message: str, **counts: int) -> Couple:
    get = counts.get
    return Couple(False, start.copy(), None, 0.0, 0.0, 0.0, get("n_couples", 0), get("n_paths", 0), message,
                  get("n_targets", 0), get("n_wavefronts", 0), get("wavefront_iterations", 0))


def _legs_cross_each(
    hip_xy: FloatArray, foot_xy: FloatArray, other_hips: tuple[FloatArray, FloatArray],
    other_feet: tuple[FloatArray, FloatArray], valid: BoolArray,
) -> BoolArray:
    """:func:`legs_cross` of ``m`` footprints, each against its own other legs: ``hip_xy``,
    ``foot_xy`` ``(m, 2)``; ``other_hips``, ``other_feet``: their x and y ``(j, m)`` (leg by
    leg: the arithmetic runs along the footprints), of which ``valid`` ``(j, m)`` are real.
    Returns ``(m,)``. The same arithmetic, one coordinate at a time."""
    px, py = hip_xy[:, 0], hip_xy[:, 1]
    rx, ry = foot_xy[:, 0] - px, foot_xy[:, 1] - py
    qx, qy = other_hips
    sx, sy = other_feet[0] - qx, other_feet[1] - qy
    d1: FloatArray = rx * (qy - py) - ry * (qx - px)
    d2: FloatArray = rx * (qy + sy - py) - ry * (qx + sx - px)
    d3: FloatArray = sx * (py - qy) - sy * (px - qx)
    d4: FloatArray = sx * (py + ry - qy) - sy * (px + rx - qx)
    eps = 1e-12
    hit = (((d1 > eps) & (d2 < -eps)) | ((d1 < -eps) & (d2 > eps))) & (
        ((d3 > eps) & (d4 < -eps)) | ((d3 < -eps) & (d4 > eps)))
    return np.logical_or.reduce(hit & valid, axis=0)


#: Samples along the hip-footprint line of the leg clearance check (a leg's length is some
#: fifteen planning cells: one sample per cell or closer).
_LEG_SAMPLES = 16


def _hip_checks(
    xy: FloatArray, z: FloatArray, box_z: FloatArray, centre_z: FloatArray, hip: FloatArray,
    hip_z: FloatArray, settings: FloatArray, windows: _WindowLookup, window_of: IntArray,
) -> tuple[BoolArray, BoolArray]:
    """The checks of footprints ``xy (k, 2)`` landing at ``z (k,)`` (the highest ground under
    their foot boxes ``box_z (k,)``, at their own point ``centre_z (k,)``) that need the hip
    ``hip (k, 2)`` at ``hip_z (k,)`` (:class:`LegGeometry`): which are candidates at all
    (``max_straddle``, ``reach_3d``) and which of those have their leg line clear
    (``leg_length``; True where not checked).
    ``settings`` ``(k, 7)``: per footprint ``max_straddle, reach_3d, reach_sweep,
    reach_sink, leg_length, leg_arch, foot radius`` (``inf``: that check off).
    ``windows``: the elevation maps, ``window_of (k,)``: which of them each footprint plans
    in."""
    straddle, reach, sweep, sink, leg, arch, foot_r = settings.T
    ok = ~(box_z - centre_z > straddle)
    dx = xy[:, 0] - hip[:, 0]
    dy = xy[:, 1] - hip[:, 1]
    dh = np.sqrt(dx * dx + dy * dy) + sweep
    dz = hip_z - z
    dz = np.where(dz > sink, dz - sink, np.where(dz < 0.0, -dz, 0.0))
    ok &= ~(dh * dh + dz * dz > reach * reach)
    clear = np.ones(ok.size, dtype=bool)
    rows = (ok & np.isfinite(leg)).nonzero()[0]
    if rows.size == 0:
        return ok, clear
    # The leg as the straight line from the footprint up to the hip, bowed up by the arch its
    # joints take over it: the ground under it must stay below. Samples ``(S, m)``: sample
    # by sample, the arithmetic runs along the footprints.
    t = ((np.arange(_LEG_SAMPLES) + 0.5) / _LEG_SAMPLES)[:, None]
    fx, fy, fz = xy[:, 0][rows], xy[:, 1][rows], z[rows]
    vx, vy, vz = hip[:, 0][rows] - fx, hip[:, 1][rows] - fy, hip_z[rows] - fz
    flat = np.sqrt(vx * vx + vy * vy)
    chord = np.sqrt(vx * vx + vy * vy + vz * vz)
    bow = arch[rows] * 0.5 * np.sqrt(np.maximum(leg[rows] * leg[rows] - chord * chord, 0.0))
    line = fz + t * vz + (4.0 * t * (1.0 - t)) * bow
    own = t * flat < foot_r[rows]  # under the foot itself
    under = windows.heights(fx + t * vx, fy + t * vy, window_of[rows])
    clear[rows[np.logical_or.reduce((under > line + 1e-9) & ~own, axis=0)]] = False
    return ok, clear


def _hip_settings(leg: LegGeometry, sweep: float, sink: float) -> list[float]:
    """A plan's row of :func:`_hip_checks` settings: its leg's, the plan's ``sweep`` and
    ``sink``."""
    inf = math.inf
    half = leg.foot_half_extents
    return [inf if leg.max_straddle is None else leg.max_straddle,
            inf if leg.reach_3d is None else leg.reach_3d, sweep, sink,
            inf if leg.leg_length is None else leg.leg_length, leg.leg_arch,
            math.hypot(float(half[0]), float(half[1]))]


def _sole(leg: LegGeometry, half: tuple[float, float]) -> tuple[float, float]:
    """The half sizes of the box each other foot is forbidden as: its sole, else a foot box."""
    if leg.sole_half_extents is None:
        return half
    sole = np.asarray(leg.sole_half_extents, dtype=np.float64).reshape(2)
    return float(sole[0]), float(sole[1])


@functools.lru_cache(maxsize=64)
def _disc_offsets(radius_cells: float) -> IntArray:
    """Cell offsets ``(k, 2)`` within ``radius_cells`` of (0, 0)."""
    k = math.ceil(radius_cells) + 1
    di, dj = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
    off = np.stack([di.ravel(), dj.ravel()], axis=1).astype(np.intp)
    off = off[np.hypot(off[:, 0], off[:, 1]) <= radius_cells + 1e-9]
    off.setflags(write=False)
    return off


def _level_list(z0: float, slice_size: float, top: float) -> list[float]:
    levels: list[float] = []
    k = 1
    while z0 + k * slice_size < top and k <= 1000:
        levels.append(z0 + k * slice_size)
        k += 1
    levels.append(math.inf)
    return levels


def _distinct_levels(levels: list[float], above: list[int]) -> list[float]:
    """Drop a level whose forbidden set equals the next one's (same paths twice)."""
    return [lv for i, lv in enumerate(levels) if i == len(levels) - 1 or above[i] != above[i + 1]]


# ---------------------------------------------------------------------------------------
# Planning many feet at once
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FootRequest:
    """One foot to plan. ``grids``: the character's window (:meth:`~.terrain.Environment.window`);
    ``foot_start``: ``(3,)`` where the foot is now; ``preferred_xy``: ``(2,)`` the
    controller's preferred footprint; ``hip_xy``: ``(2,)`` this leg's hip (at touch-down);
    ``other_hips_xy``, ``other_feet_xy``: ``(k, 2)`` the other legs' hips and feet (their
    feet are forbidden, their legs must not be crossed); ``foot_yaw``: the foot box's yaw;
    ``hip_z``: the hip's height (at touch-down), for the checks that need it (see
    :class:`LegGeometry`; skipped when None).

    ``params``: the character's settings; ``leg``: this leg's geometry; ``search``: the
    search switches. What changes from plan to plan: ``leg_reach``, the horizontal reach
    from the hip for this plan (None: ``params.leg_reach``); ``reach_sweep``, metres added to
    the horizontal distance in the 3D reach check (half the coming stance sweep);
    ``reach_sink``, how far the hip may sink toward a footprint below it in that check."""

    grids: WindowGrids
    foot_start: npt.ArrayLike
    preferred_xy: npt.ArrayLike
    hip_xy: npt.ArrayLike
    other_hips_xy: npt.ArrayLike
    other_feet_xy: npt.ArrayLike
    params: PlannerParams
    foot_yaw: float = 0.0
    hip_z: float | None = None
    leg: LegGeometry = DEFAULT_LEG
    search: SearchSwitches = DEFAULT_SEARCH
    leg_reach: float | None = None
    reach_sweep: float = 0.0
    reach_sink: float = 0.0


_NO_CANDIDATE = ("no candidate footprint: every cell near the preferred footprint is forbidden, "
                 "out of reach, without ground or crosses another leg")
_NO_COUPLE = "no valid couple: no candidate footprint can be reached from the foot"


class _Plan:
    """One request once validated: its numbers as plain Python values, and ``row``, the
    numbers the batch stacks (one :data:`_ROW` row per plan: the batch's arrays are its
    columns, made in one call instead of one list per number)."""

    __slots__ = (
        "cell",
        "frame",
        "grids",
        "half",
        "hip",
        "hip_z",
        "index",
        "leg",
        "o_feet",
        "o_hips",
        "params",
        "pref",
        "reach",
        "row",
        "search",
        "sink",
        "sole",
        "start",
        "start_rc",
        "sweep",
        "yaw",
    )

    def __init__(self, index: int, rq: FootRequest, start: FloatArray, pref: FloatArray, hip: FloatArray,
                 o_hips: FloatArray, o_feet: FloatArray, start_rc: tuple[float, float], frame: RegionFrame,
                 shape: _LegShape, window: tuple[float, float, float, int, int],
                 pref_rc: tuple[float, float]) -> None:
        half, sole, foot_r, straddle, reach_3d, leg_length, arch = shape
        params = rq.params
        cell, ox, oy, ny, nx = window
        self.index = index
        self.sole = sole
        self.grids = rq.grids
        self.params = params
        self.leg = rq.leg
        self.search = rq.search
        self.reach = reach = _reach(rq)
        self.sweep = sweep = float(rq.reach_sweep)
        self.sink = sink = float(rq.reach_sink)
        self.start = start
        self.pref = pref
        self.hip = hip
        self.hip_z = None if rq.hip_z is None else float(rq.hip_z)
        self.o_hips = o_hips
        self.o_feet = o_feet
        self.yaw = yaw = float(rq.foot_yaw)
        self.cell = cell
        self.start_rc = start_rc
        self.frame = frame
        self.half = half
        max_dz = reach if params.max_height_change is None else params.max_height_change
        px, py = pref.tolist()
        hx, hy = hip.tolist()
        self.row = (
            *frame, cell, ox, oy, ny, nx, half[0], half[1], sole[0], sole[1], yaw,
            start_rc[0], start_rc[1], float(start[2]), params.step_height,
            pref_rc[0], pref_rc[1], round(params.candidate_radius / cell, 9), hx, hy, reach + 1e-9, max_dz,
            math.nan if self.hip_z is None else self.hip_z,
            straddle, reach_3d, sweep, sink, leg_length, arch, foot_r,
            params.leg_clearance_score, params.edge_height, px, py, params.fixed_distance, params.edge_score,
            o_hips.shape[0], math.ceil((abs(half[0]) + abs(half[1])) / cell + 1.0),
        )


#: The leg's numbers the planner uses (:func:`_leg_shape`): foot box half sizes, sole half
#: sizes, foot radius and the hip-check settings that do not change from plan to plan.
_LegShape = tuple[tuple[float, float], tuple[float, float], float, float, float, float, float]

#: Columns of :attr:`_Plan.row`: the search rectangle (:data:`RegionFrame`, 11), then these.
_ROW = {name: 11 + i for i, name in enumerate((
    "cell", "ox", "oy", "ny", "nx", "half_x", "half_y", "sole_x", "sole_y", "yaw",
    "start_r", "start_c", "start_z", "step_height",
    "pref_r", "pref_c", "radius", "hip_x", "hip_y", "reach", "max_dz", "hip_z",
    "straddle", "reach_3d", "sweep", "sink", "leg_length", "arch", "foot_r",
    "low", "edge_height", "pref_x", "pref_y", "fixed", "edge_score", "n_other", "land_reach",
))}


def _leg_shape(leg: LegGeometry) -> _LegShape:
    """A leg's :data:`_LegShape`, kept per leg object (a rig's legs are planned again and
    again with the same objects)."""
    hit = _LEG_SHAPES.get(id(leg))
    if hit is not None and hit[0] is leg:
        return hit[1]
    if len(_LEG_SHAPES) > 1024:
        _LEG_SHAPES.clear()
    shape = _leg_shape_of(leg)
    _LEG_SHAPES[id(leg)] = (leg, shape)
    return shape


def _leg_shape_of(leg: LegGeometry) -> _LegShape:
    half_arr = np.asarray(leg.foot_half_extents, dtype=np.float64).reshape(2)
    half = (float(half_arr[0]), float(half_arr[1]))
    inf = math.inf
    return (half, _sole(leg, half), math.hypot(half[0], half[1]),
            inf if leg.max_straddle is None else leg.max_straddle,
            inf if leg.reach_3d is None else leg.reach_3d,
            inf if leg.leg_length is None else leg.leg_length, leg.leg_arch)


#: :func:`_leg_shape`'s cache: the leg object itself (so its id is not reused) and its shape.
_LEG_SHAPES: dict[int, tuple[LegGeometry, _LegShape]] = {}


def _reach(rq: FootRequest) -> float:
    """The horizontal reach of a request's plan."""
    return float(rq.params.leg_reach if rq.leg_reach is None else rq.leg_reach)


def _validate(index: int, rq: FootRequest) -> _Plan | Couple:
    """Checks and the search rectangle of one request; a failed :class:`Couple` if it cannot
    be planned at all."""
    # (reshaped only when not already of their shape: the same arrays)
    start = np.asarray(rq.foot_start, dtype=np.float64)
    if start.shape != (3,):
        start = start.reshape(3)
    pref = np.asarray(rq.preferred_xy, dtype=np.float64)
    if pref.shape != (2,):
        pref = pref.reshape(2)
    hip = np.asarray(rq.hip_xy, dtype=np.float64)
    if hip.shape != (2,):
        hip = hip.reshape(2)
    o_hips = np.asarray(rq.other_hips_xy, dtype=np.float64)
    if o_hips.ndim != 2 or o_hips.shape[1] != 2:
        o_hips = o_hips.reshape(-1, 2)
    o_feet = np.asarray(rq.other_feet_xy, dtype=np.float64)
    if o_feet.ndim != 2 or o_feet.shape[1] != 2:
        o_feet = o_feet.reshape(-1, 2)
    sx, sy, sz = start.tolist()
    px, py = pref.tolist()
    hx, hy = hip.tolist()
    finite = all(map(math.isfinite, (sx, sy, sz, px, py, hx, hy)))
    if rq.hip_z is not None:
        finite = finite and math.isfinite(float(rq.hip_z))
    if finite and (o_hips.size or o_feet.size):
        finite = all(map(math.isfinite, itertools.chain(o_hips.ravel().tolist(), o_feet.ravel().tolist())))
    if not finite:
        return _fail(np.where(np.isfinite(start), start, 0.0), "non-finite input")
    if o_hips.shape != o_feet.shape:
        return _fail(start, "other_hips_xy and other_feet_xy differ in shape")
    grids = rq.grids
    params = rq.params
    cell = float(grids.cell)
    ox, oy = np.asarray(grids.origin, dtype=np.float64).tolist()
    shape = _leg_shape(rq.leg)
    half = shape[0]
    start_rc = ((sy - oy) / cell, (sx - ox) / cell)
    pref_rc = ((py - oy) / cell, (px - ox) / cell)
    ny, nx = grids.elevation.shape
    if not (-0.5 <= start_rc[0] < ny - 0.5 and -0.5 <= start_rc[1] < nx - 0.5):
        return _fail(start, "the foot is outside the window grids")
    half_width = rq.search.search_half_width
    if half_width is None:
        half_width = max(params.candidate_radius, 0.5 * _reach(rq))
    foot_cells = (abs(half[0]) + abs(half[1])) / cell + 1.0
    frame = region_frame((ny, nx), start_rc[0], start_rc[1], pref_rc[0], pref_rc[1],
                         half_width / cell + foot_cells,
                         params.candidate_radius / cell + foot_cells + 1.0, 1.0 + foot_cells)
    if frame is None:
        return _fail(start, _NO_CANDIDATE)
    return _Plan(index, rq, start, pref, hip, o_hips, o_feet, start_rc, frame, shape, (cell, ox, oy, ny, nx),
                 pref_rc)


@dataclass(frozen=True)
class _Best:
    """The best couple of a search so far: its target (position in the foot's order), 3D
    path score, slice level, trajectory and score (target score × path score)."""

    target: int
    path_score: float
    level: float
    trajectory: FootTrajectory
    score: float


@dataclass
class _Search:
    """Where one foot's best-couple search stands (Appendix E): the next target (position in
    its order) and slice (position in its levels), the best couple so far and the counts."""

    pos: int = 0
    level_pos: int = 0
    best: _Best | None = None
    best_score: float = 0.0
    n_couples: int = 0
    n_paths: int = 0
    after_first: int = 0
    first_valid: int = 0
    done: bool = False


class _Next(enum.Enum):
    """What a foot's search needs next (:func:`_next_couple`)."""

    MAPS = enum.auto()  # the obstacle maps of its next slice
    EVAL = enum.auto()  # its next couple evaluated (line of sight, 2D plan, maybe 3D)
    END = enum.auto()  # nothing: the search is over


@dataclass(frozen=True)
class _LiftSource:
    """A 2D plan to lift: its ``samples`` ``(m, 2)`` at arc lengths ``arc`` ``(m,)``, its
    ``length``, world ``waypoints`` ``(k, 2)`` and the box cells ``rows``, ``cols`` ``(m,)``
    of the samples (None: not computed yet)."""

    samples: FloatArray
    arc: FloatArray
    length: float
    waypoints: FloatArray
    rows: IntArray | None = None
    cols: IntArray | None = None


@dataclass(frozen=True)
class _StraightPlans:
    """Straight 2D plans of ``m`` couples (:func:`_straight_plans`): ``status`` per plan 1
    (a clean plan), 0 (its samples touch a blocked cell: no plan) or -1 (zero length: plan it
    alone); ``s2`` its 2D score; the samples of the clean and blocked plans one after the
    other, ``samples`` ``(M, 2)`` at arc lengths ``arc`` ``(M,)``, plan ``j`` owning rows
    ``bounds[j]:bounds[j + 1]``, with their box cells ``rows``, ``cols`` ``(M,)``; ``length``
    ``(m,)`` and the world ``waypoints`` ``(m, 2, 2)``."""

    status: list[int]
    s2: list[float]
    samples: FloatArray
    arc: FloatArray
    length: FloatArray
    bounds: list[int]
    rows: IntArray
    cols: IntArray
    waypoints: FloatArray

    def source(self, j: int) -> _LiftSource:
        """Plan ``j`` (a clean one) as a :class:`_LiftSource`."""
        a, b = self.bounds[j], self.bounds[j + 1]
        return _LiftSource(self.samples[a:b], self.arc[a:b], float(self.length[j]), self.waypoints[j],
                           self.rows[a:b], self.cols[a:b])


_Maps = tuple[BoolArray, BoolArray, BoolArray]


@dataclass
class _Cands:
    """The targets (candidates with a positive score) of every plan of a batch, best first
    within each plan, one plan after the other: plan ``k`` owns rows
    ``bounds[k]:bounds[k + 1]``; ``score`` and the cells' rows and columns also as Python lists
    for the search's bookkeeping."""

    xy: FloatArray
    cells: IntArray
    z: FloatArray
    score: FloatArray
    bounds: list[int]
    n_valid: list[int]
    score_list: list[float]
    row_list: list[int]
    col_list: list[int]


class _Foot:
    """One foot in the batch: where its candidates are, its levels, caches and search."""

    __slots__ = (
        "base",
        "budget",
        "ctx",
        "exhaustive",
        "fields",
        "k",
        "levels",
        "maps",
        "n_targets",
        "order",
        "padded",
        "per_target",
        "plan",
        "shortcut",
        "st",
        "start_cell",
        "start_inside",
    )

    def __init__(self, plan: _Plan, k: int, base: int, order: list[int], n_targets: int, levels: list[float],
                 start_cell: tuple[int, int], start_inside: bool) -> None:
        self.plan = plan
        self.k = k
        self.base = base
        self.order = order
        self.n_targets = n_targets
        self.levels = levels
        self.start_cell = start_cell
        self.start_inside = start_inside
        search = plan.search
        self.exhaustive = search.exhaustive
        self.budget = None if search.exhaustive else plan.params.max_couples_after_first
        self.per_target = not search.shared_wavefront
        self.shortcut = search.los_shortcut
        self.st = _Search()
        self.maps: dict[float, _Maps] = {}
        self.fields: dict[tuple[float, int, int], DistanceField] = {}
        self.padded: dict[float, BoolArray] = {}  # blocked maps as (H, W) rows, for batches
        self.ctx: PathContext | None = None


class _Batch:
    """Stacked arrays of a batch of feet: plan ``k``'s search box at ``[k, :h, :w]`` (past its
    own size: outside the rectangle, no surface, not avoided), and its window's elevation
    around the box with a margin of ``pad`` cells (``-inf`` outside the window) for the foot
    kernels' maxima."""

    def __init__(self, plans: list[_Plan]) -> None:
        n = len(plans)
        self.plans = plans
        self.rows = rows = np.array([p.row for p in plans])
        col = _ROW
        frames = rows[:, :11]
        ints = frames[:, :4].astype(np.intp)
        self.r0 = r0 = ints[:, 0]
        self.c0 = c0 = ints[:, 1]
        self.hh = hh = ints[:, 2]
        self.ww = ww = ints[:, 3]
        H = int(np.maximum.reduce(hh))
        W = int(np.maximum.reduce(ww))
        self.mask = region_masks(frames, H, W)
        self.outside = ~self.mask
        self.cell = rows[:, col["cell"]]
        self.origin = rows[:, col["ox"] : col["oy"] + 1]
        self.ny = rows[:, col["ny"]].astype(np.intp)
        self.nx = rows[:, col["nx"]].astype(np.intp)
        # Foot kernels: swept (the foot anywhere in its cell); the landing ones come with the
        # candidates. The margin holds the widest of them.
        self.half_x = rows[:, col["half_x"]]
        self.half_y = rows[:, col["half_y"]]
        self.sole_x = rows[:, col["sole_x"]]
        self.sole_y = rows[:, col["sole_y"]]
        self.yaw = rows[:, col["yaw"]]
        self.sweep_off, self.sweep_in = _sweep_kernels(rows[:, _KERNEL_COLS])
        land_reach = int(np.maximum.reduce(rows[:, col["land_reach"]]))
        self.pad = R = max(int(np.maximum.reduce(np.abs(self.sweep_off), axis=None)), land_reach)
        Hp, Wp = H + 2 * R, W + 2 * R
        epad = np.full((n, Hp, Wp), -np.inf)
        apad = np.zeros((n, Hp, Wp), dtype=bool)
        avoid = np.zeros((n, H, W), dtype=bool)
        # the elevation in each box, -inf past its own size
        elev = np.full((n, H, W), -np.inf) if n > 1 else np.empty((1, H, W))
        box = ints.tolist()
        for k, p in enumerate(plans):
            g = p.grids
            ny, nx = g.elevation.shape
            rk, ck, h, w = box[k]
            top, left = rk - R, ck - R
            ra, rb, ca, cb = max(top, 0), min(top + Hp, ny), max(left, 0), min(left + Wp, nx)
            epad[k, ra - top : rb - top, ca - left : cb - left] = g.elevation[ra:rb, ca:cb]
            apad[k, ra - top : rb - top, ca - left : cb - left] = g.avoid[ra:rb, ca:cb]
            avoid[k, :h, :w] = g.avoid[rk : rk + h, ck : ck + w]
            elev[k, :h, :w] = epad[k, R : R + h, R : R + w]
        self.epad = epad
        self.elev = elev
        core = avoid.copy()
        # Other feet: forbidden as their soles (or foot boxes), with this foot's yaw; the
        # dilation by this foot's box keeps its whole box off them.
        n_other = rows[:, col["n_other"]].astype(np.intp)
        if np.add.reduce(n_other):
            owner = np.arange(n).repeat(n_other)
            feet = np.concatenate([p.o_feet for p in plans])
            hx = self.sole_x[owner]
            hy = self.sole_y[owner]
            grid = (self.ny[owner], self.nx[owner])
            yaw_o = self.yaw[owner]
            box, fr, fc = raster_boxes(self.origin[owner], self.cell[owner], grid, feet, hx, hy, yaw_o)
            who = owner[box]
            lr = fr - r0[who]
            lc = fc - c0[who]
            ok = (lr >= 0) & (lr < hh[who]) & (lc >= 0) & (lc < ww[who])
            core.reshape(-1)[((who * H + lr) * W + lc)[ok]] = True  # (one flat index)
        self.core = core
        # Lift-off zone: the cells the foot covers where it stands.
        self.start_rc = rows[:, col["start_r"] : col["start_c"] + 1] - ints[:, :2]
        sc = np.rint(self.start_rc).astype(np.intp)
        inside = (sc[:, 0] >= 0) & (sc[:, 0] < hh) & (sc[:, 1] >= 0) & (sc[:, 1] < ww)
        self.start_inside = inside
        lr = sc[:, 0, None] + self.sweep_off[None, :, 0]
        lc = sc[:, 1, None] + self.sweep_off[None, :, 1]
        ok = self.sweep_in & inside[:, None] & (lr >= 0) & (lr < hh[:, None]) & (lc >= 0) & (lc < ww[:, None])
        liftoff = np.zeros((n, H, W), dtype=bool)
        kk, jj = ok.nonzero()
        liftoff.reshape(-1)[(kk * H + lr[kk, jj]) * W + lc[kk, jj]] = True
        at = np.arange(n)
        here = avoid[at, np.where(inside, sc[:, 0], 0), np.where(inside, sc[:, 1], 0)]
        # What swings must clear (pathing.clearance_elevation): avoided cells above the foot
        # plus its step height left out (max_under applies it to the cells it reads).
        self.apad = apad if np.logical_or.reduce(apad, axis=None) else None
        self.above = rows[:, col["start_z"]] + rows[:, col["step_height"]]
        on_avoid = (inside & here).nonzero()[0]
        if on_avoid.size:
            # The foot stands on an avoided obstacle (it moved under the foot): let it leave
            # across that obstacle's cells rather than be stuck there.
            grown = dilate_each(avoid[on_avoid], self.sweep_off, self.sweep_in[on_avoid])
            grown &= self.mask[on_avoid]
            sources = [(int(sc[k, 0]), int(sc[k, 1])) for k in on_avoid.tolist()]
            shapes = [(int(hh[k]), int(ww[k])) for k in on_avoid.tolist()]
            for k, escape in zip(on_avoid.tolist(), wavefront_each(grown, sources, shapes), strict=True):
                h, w = int(hh[k]), int(ww[k])
                liftoff[k, :h, :w] |= np.isfinite(escape.dist)
        self.liftoff = liftoff
        # The obstacle map without slice (thesis §3.4.1 plus the other feet).
        self.grown_inf = dilate_each(core, self.sweep_off, self.sweep_in)

    def max_under(self, plan: IntArray, rows: IntArray, cols: IntArray, kernel: IntArray,
                  member: BoolArray, clearance: bool = False) -> FloatArray:
        """Highest window elevation under kernel cells around box cells ``(rows, cols)``
        ``(p,)`` of plans ``plan`` ``(p,)`` (cells within the box), the kernel of plan ``k``
        being ``kernel[member[k]]``: ``(p,)``; ``-inf`` where no kernel cell is in the window
        (what :meth:`PathContext.kernel_max` gives). ``clearance``: of the elevation a swing
        must clear (:meth:`PathContext.clearance_grid`)."""
        used = np.logical_or.reduce(member, axis=0).nonzero()[0]
        _, hp, wp = self.epad.shape
        R = self.pad
        koff = kernel[used, 0] * wp + kernel[used, 1]
        at = plan * (hp * wp) + (rows + R) * wp + (cols + R)
        # kernel cell by cell ``(k, p)``: each gather and the maximum run along the p cells
        where = koff[:, None] + at
        vals = self.epad.reshape(-1)[where]
        if clearance and self.apad is not None:
            vals = np.where(self.apad.reshape(-1)[where] & (vals > self.above[plan]), NO_SURFACE, vals)
        sel = member[:, used]
        if not np.logical_and.reduce(sel, axis=None):
            vals = np.where(sel.T[:, plan], vals, -np.inf)
        return np.maximum.reduce(vals, axis=0)

    def path_context(self, f: _Foot) -> PathContext:
        """The foot's :class:`PathContext` (made on first use; it shares the foot's caches)."""
        if f.ctx is None:
            k = f.k
            p = f.plan
            h, w = int(self.hh[k]), int(self.ww[k])
            path_params = PathParams(step_height=p.params.step_height, tension=p.params.tension,
                                     los_shortcut=p.search.los_shortcut)
            region = Region(int(self.r0[k]), int(self.c0[k]), self.mask[k, :h, :w])
            f.ctx = PathContext.from_parts(p.grids, p.start, region, path_params, f.per_target,
                                           self.sweep_off[self.sweep_in[k]], (p.half, p.yaw),
                                           self.elev[k, :h, :w], self.core[k, :h, :w], self.start_rc[k],
                                           self.liftoff[k, :h, :w], f.maps, f.fields)
        return f.ctx

    def feet(self, cands: _Cands, levels: list[list[float]]) -> dict[int, _Foot]:
        """The feet with candidates, their maps without slice in."""
        keep = [k for k in range(len(self.plans)) if cands.n_valid[k] > 0]
        if not keep:
            return {}
        if len(keep) == len(self.plans):  # (every plan: no copies of the stacks)
            sel: IntArray | slice = slice(None)
        else:
            sel = np.asarray(keep)
        core = self.core[sel]
        grown = self.grown_inf[sel]
        blocked = (grown | self.outside[sel]) & ~self.liftoff[sel]
        dil = grown & ~core
        sc = np.rint(self.start_rc[sel]).astype(np.intp).tolist()
        inside = self.start_inside[sel].tolist()
        out = {}
        for i, k in enumerate(keep):
            p = self.plans[k]
            n_targets = cands.n_valid[k]
            order = list(range(n_targets))
            if p.search.max_targets is not None:
                order = order[: p.search.max_targets]
            f = _Foot(p, k, cands.bounds[k], order, n_targets, levels[k], (sc[i][0], sc[i][1]), inside[i])
            h, w = int(self.hh[k]), int(self.ww[k])
            f.maps[math.inf] = (core[i, :h, :w], dil[i, :h, :w], blocked[i, :h, :w])
            f.padded[math.inf] = blocked[i]
            out[k] = f
        return out

    def add_maps(self, feet: list[_Foot], levels: list[float]) -> None:
        """The obstacle maps of ``feet`` at slice ``levels`` (one each), all at once."""
        ks = np.array([f.k for f in feet])
        lv = np.array(levels)
        core = self.core[ks] | (self.elev[ks] > lv[:, None, None])
        grown = dilate_each(core, self.sweep_off, self.sweep_in[ks])
        blocked = (grown | self.outside[ks]) & ~self.liftoff[ks]
        dil = grown & ~core
        for i, (f, level) in enumerate(zip(feet, levels, strict=True)):
            h, w = int(self.hh[f.k]), int(self.ww[f.k])
            f.maps[level] = (core[i, :h, :w], dil[i, :h, :w], blocked[i, :h, :w])
            f.padded[level] = blocked[i]

    def blocked_row(self, f: _Foot, level: float) -> BoolArray:
        """The foot's blocked map at ``level`` padded to the batch's box size."""
        row = f.padded.get(level)
        if row is None:  # computed one by one by the context: pad it
            row = np.ones(self.mask.shape[1:], dtype=bool)
            b = f.maps[level][2]
            row[: b.shape[0], : b.shape[1]] = b
            f.padded[level] = row
        return row


def _sweep_kernels(shape: FloatArray) -> tuple[IntArray, BoolArray]:
    """The swept foot kernels (:func:`~.terrain.foot_kernels`) of plans whose ``cell, half_x,
    half_y, yaw`` are the rows of ``shape`` ``(n, 4)``; kept per set of rows (a character
    plans with the same cell, foot and, walking straight, yaw again and again). Read-only
    arrays."""
    key = shape.tobytes()
    hit = _SWEEP_KERNELS.get(key)
    if hit is None:
        if len(_SWEEP_KERNELS) > 256:
            _SWEEP_KERNELS.clear()
        off, member = foot_kernels(shape[:, 0], shape[:, 1], shape[:, 2], shape[:, 3], True)
        member.setflags(write=False)
        hit = _SWEEP_KERNELS[key] = (off, member)
    return hit


#: :func:`_sweep_kernels`' cache, by the bytes of the plans' rows.
_KERNEL_COLS = [_ROW["cell"], _ROW["half_x"], _ROW["half_y"], _ROW["yaw"]]
_SWEEP_KERNELS: dict[bytes, tuple[IntArray, BoolArray]] = {}


def _next_couple(f: _Foot, cands: _Cands) -> tuple[_Next, float]:
    """Advance ``f``'s search over couples that need no batch work (no plan from outside the
    search box, target cell blocked or known unreachable at that slice); returns what the
    next couple needs and at which slice level (0 with :attr:`_Next.END`)."""
    st = f.st
    order = f.order
    levels = f.levels
    scores = cands.score_list
    while True:
        if st.done or st.pos >= len(order):
            return _Next.END, 0.0
        t = f.base + order[st.pos]
        if st.level_pos == 0 and not f.exhaustive and st.best is not None and scores[t] <= st.best_score:
            return _Next.END, 0.0  # Appendix E: no couple with this target can beat the best one
        if st.level_pos >= len(levels) or not f.start_inside:
            st.pos += 1
            st.level_pos = 0
            continue
        level = levels[st.level_pos]
        maps = f.maps.get(level)
        if maps is None:
            return _Next.MAPS, level
        r, c = cands.row_list[t], cands.col_list[t]
        if maps[2][r, c]:
            st.level_pos += 1
            continue
        if not f.per_target:
            fld = f.fields.get((level, f.start_cell[0], f.start_cell[1]))
            if fld is not None and not math.isfinite(fld.dist[r, c]):
                st.level_pos += 1  # known unreachable at this slice
                continue
        return _Next.EVAL, level


def _after_couple(f: _Foot, cands: _Cands, level: float, path_ok: bool, in_sight: bool, s2: float,
                  traj: FootTrajectory | None) -> bool:
    """Book one evaluated couple; ``traj`` is its 3D trajectory if it was built. Returns
    whether the caller must build the trajectory first (then call again with it)."""
    st = f.st
    t = f.order[st.pos]
    t_score = cands.score_list[f.base + t]
    if not path_ok:
        st.level_pos += 1
        return False
    if traj is None and (f.exhaustive or st.best is None or t_score * s2 > st.best_score):
        return True
    st.level_pos += 1
    st.n_couples += 1
    if st.best is not None:
        st.after_first += 1
    if traj is not None:
        st.n_paths += 1
        s3 = s2 * vertical_factor(traj, f.plan.params.step_height)
        score = t_score * s3
        if st.best is None or score > st.best_score:
            if st.best is None:
                st.first_valid = st.n_couples
            st.best = _Best(t, s3, level, traj, score)
            st.best_score = score
    if f.budget is not None and st.best is not None and st.after_first >= f.budget:
        st.done = True
    elif in_sight:
        # A straight line clear at this slice is clear at every higher one: the same couple
        # again, which cannot beat itself.
        st.pos += 1
        st.level_pos = 0
    return False


def _straight_plans(
    batch: _Batch, ks: IntArray, start_rc: FloatArray, end_rc: FloatArray, blocked: BoolArray
) -> _StraightPlans:
    """Straight 2D plans from ``start_rc`` to ``end_rc`` ``(m, 2)`` (box cells) of plans
    ``ks``, checked against ``blocked`` ``(m, H, W)`` (what :meth:`PathContext.plan_2d` does
    for a target in sight)."""
    cl = batch.cell[ks]
    org = batch.origin[ks]
    r0 = batch.r0[ks]
    c0 = batch.c0[ks]
    w0x = org[:, 0] + (start_rc[:, 1] + c0) * cl
    w0y = org[:, 1] + (start_rc[:, 0] + r0) * cl
    w1x = org[:, 0] + (end_rc[:, 1] + c0) * cl
    w1y = org[:, 1] + (end_rc[:, 0] + r0) * cl
    dx = w1x - w0x
    dy = w1y - w0y
    length = planar_length(dx, dy)
    moving = length > 1e-9
    spacing = _PATH_DEFAULTS.sample_spacing * cl
    counts = np.where(moving, np.maximum(2, np.ceil(length / spacing).astype(np.intp) + 1), 1)
    bounds = np.concatenate([[0], counts.cumsum()])
    m = ks.size
    owner = np.arange(m).repeat(counts)
    i = np.arange(bounds[-1]) - bounds[:-1][owner]
    safe = np.where(moving, length, 1.0)
    arc = i * (length / np.maximum(counts - 1, 1))[owner]
    arc[bounds[1:] - 1] = length
    frac = arc / safe[owner]
    sx = w0x[owner] + dx[owner] * frac
    sy = w0y[owner] + dy[owner] * frac
    rows = np.rint((sy - org[:, 1][owner]) / cl[owner] - r0[owner]).astype(np.intp)
    cols = np.rint((sx - org[:, 0][owner]) / cl[owner] - c0[owner]).astype(np.intp)
    hh = batch.hh[ks][owner]
    ww = batch.ww[ks][owner]
    inside = (rows >= 0) & (rows < hh) & (cols >= 0) & (cols < ww)
    bad = ~inside
    _, H, W = blocked.shape
    bad[inside] = blocked.reshape(-1)[((owner * H + rows) * W + cols)[inside]]
    clean = ~np.logical_or.reduceat(bad, bounds[:-1])
    samples = column_pair(sx, sy)
    bl = bounds.tolist()
    turning = turning_each(samples, bl)
    good = moving & clean
    status = np.where(moving, np.where(clean, 1, 0), -1).tolist()
    # straightness_score of every clean plan, element-wise (the same IEEE operations as on
    # Python floats): direct distance over length, times 1 / (1 + turning / 2 pi)
    first = bounds[:-1]
    last = bounds[1:] - 1
    direct = planar_length(sx[last] - sx[first], sy[last] - sy[first])
    ratio = np.minimum(direct / np.where(good, length, 1.0), 1.0)
    s2 = np.where(good, ratio / (1.0 + np.asarray(turning) / (2.0 * math.pi)), 0.0).tolist()
    way = np.concatenate((w0x[:, None], w0y[:, None], w1x[:, None], w1y[:, None]), axis=1).reshape(m, 2, 2)
    return _StraightPlans(status, s2, samples, arc, length, bl, rows, cols, way)


def _run(batch: _Batch, feet: list[_Foot], cands: _Cands) -> None:
    """The best-couple search of every foot (thesis §3.5.2, Appendix E), in rounds: each
    round evaluates the next couple of every foot still searching, the batchable parts
    (obstacle maps, line of sight, straight plans, wavefronts, 3D trajectories) for all of
    them at once. Each foot sees exactly the sequence of couples of its own search."""
    active = feet
    while active:
        if len(active) <= _ALONE:
            # A round for a foot or two costs more than going on with them one by one.
            for f in active:
                _search_alone(batch, f, cands)
            return
        evals: list[tuple[_Foot, float]] = []
        pending = active
        while pending:
            need: list[tuple[_Foot, float]] = []
            for f in pending:
                kind, level = _next_couple(f, cands)
                if kind is _Next.MAPS:
                    need.append((f, level))
                elif kind is _Next.EVAL:
                    evals.append((f, level))
            if need:
                batch.add_maps([f for f, _ in need], [lv for _, lv in need])
            pending = [f for f, _ in need]
        if not evals:
            return
        m = len(evals)
        ks = np.array([f.k for f, _ in evals])
        tgt = [f.base + f.order[f.st.pos] for f, _ in evals]
        t_xy = cands.xy[tgt]
        t_cell = [(cands.row_list[t], cands.col_list[t]) for t in tgt]
        cl = batch.cell[ks]
        org = batch.origin[ks]
        end_rc = column_pair((t_xy[:, 1] - org[:, 1]) / cl - batch.r0[ks],
                             (t_xy[:, 0] - org[:, 0]) / cl - batch.c0[ks])
        blocked = np.array([batch.blocked_row(f, level) for f, level in evals])  # (np.stack's copy)
        start_rc = batch.start_rc[ks]
        shape = column_pair(batch.hh[ks], batch.ww[ks])
        sight = segments_clear_each(blocked, np.arange(m), shape, start_rc, end_rc).tolist()
        # Plans: straight ones together, the others one by one (after their wavefronts).
        paths: list[Path2D | None] = [None] * m
        s2: list[float] = [0.0] * m
        straight_i = [i for i in range(m) if sight[i] and evals[i][0].shortcut]
        lift_src: dict[int, _LiftSource] = {}
        if straight_i:
            si = np.asarray(straight_i)
            straight = _straight_plans(batch, ks[si], start_rc[si], end_rc[si], blocked[si])
            for j, i in enumerate(straight_i):
                if straight.status[j] == 1:
                    s2[i] = straight.s2[j]
                    lift_src[i] = straight.source(j)
                elif straight.status[j] == -1:
                    f, level = evals[i]
                    paths[i] = batch.path_context(f).plan_2d(level, t_cell[i], end_rc[i], True)
        others = [i for i in range(m) if not (sight[i] and evals[i][0].shortcut)]
        if others:
            _fields_for(batch, [(evals[i][0], evals[i][1], t_cell[i]) for i in others])
            for i in others:
                f, level = evals[i]
                paths[i] = batch.path_context(f).plan_2d(level, t_cell[i], end_rc[i], bool(sight[i]))
        for i in range(m):
            path = paths[i]
            if path is not None:
                s2[i] = path_score_2d(path)
                if path.length > 1e-9:
                    lift_src[i] = _LiftSource(path.samples, path.arc, float(path.length), path.waypoints)
        # Book every couple; build the 3D trajectories the search asks for, all at once.
        made = [i in lift_src or paths[i] is not None for i in range(m)]
        lifts = [i for i, (f, level) in enumerate(evals)
                 if _after_couple(f, cands, level, made[i], sight[i], s2[i], None)]
        if lifts:
            target_z = cands.z[tgt].tolist()
            for i, traj in zip(lifts, _lift_all(batch, evals, lifts, lift_src, paths, target_z), strict=True):
                f, level = evals[i]
                _after_couple(f, cands, level, True, sight[i], s2[i], traj)
        active = [f for f, _ in evals]


#: Feet still searching below which the rounds stop and each goes on alone.
_ALONE = 2


def _search_alone(batch: _Batch, f: _Foot, cands: _Cands) -> None:
    """The rest of one foot's search with its path context alone (the same couples, maps,
    wavefronts and trajectories as the rounds would give it)."""
    ctx = batch.path_context(f)
    while True:
        kind, level = _next_couple(f, cands)
        if kind is _Next.END:
            return
        if kind is _Next.MAPS:
            ctx.maps(level)
            continue
        t = f.base + f.order[f.st.pos]
        path = ctx.path_2d(level, (cands.row_list[t], cands.col_list[t]), cands.xy[t])
        if path is None:
            _after_couple(f, cands, level, False, False, 0.0, None)
            continue
        s2 = path_score_2d(path)
        if _after_couple(f, cands, level, True, path.in_sight, s2, None):
            traj = ctx.lift(path, float(cands.z[t]))
            _after_couple(f, cands, level, True, path.in_sight, s2, traj)


def _fields_for(batch: _Batch, items: list[tuple[_Foot, float, tuple[int, int]]]) -> None:
    """Grow the wavefronts that :meth:`PathContext.plan_2d` will ask for, all at once."""
    todo: list[tuple[_Foot, float, tuple[int, int]]] = []
    for f, level, t_cell in items:
        src = t_cell if f.per_target else f.start_cell
        if (level, src[0], src[1]) in f.fields:
            continue
        if not np.logical_or.reduce(f.maps[level][2], axis=None):
            batch.path_context(f).field(level, src)  # closed form
            continue
        todo.append((f, level, src))
    if not todo:
        return
    free = ~np.array([batch.blocked_row(f, level) for f, level, _ in todo])  # (np.stack's copy)
    shapes = [(int(batch.hh[f.k]), int(batch.ww[f.k])) for f, _, _ in todo]
    fields = wavefront_each(free, [src for _, _, src in todo], shapes)
    for (f, level, src), fld in zip(todo, fields, strict=True):
        ctx = batch.path_context(f)
        f.fields[(level, src[0], src[1])] = fld
        ctx.n_wavefronts += 1
        ctx.wavefront_iterations += fld.iterations


def _lift_all(
    batch: _Batch, evals: list[tuple[_Foot, float]], lifts: list[int], lift_src: dict[int, _LiftSource],
    paths: list[Path2D | None], target_z: list[float],
) -> list[FootTrajectory]:
    """:meth:`PathContext.lift` of the couples ``lifts`` (indices into ``evals``)."""
    out: dict[int, FootTrajectory] = {}
    many = [i for i in lifts if i in lift_src]
    for i in lifts:
        if i not in lift_src:  # zero length: lift and put down on the spot
            path = paths[i]
            assert path is not None
            out[i] = batch.path_context(evals[i][0]).lift(path, target_z[i])
    if many:
        src = [lift_src[i] for i in many]
        xy = np.concatenate([s.samples for s in src])
        arc = np.concatenate([s.arc for s in src])
        counts = [s.samples.shape[0] for s in src]
        bounds = [0, *itertools.accumulate(counts)]
        ks = np.array([evals[i][0].k for i in many])
        kp = ks.repeat(counts)
        known = [(s.rows, s.cols) for s in src if s.rows is not None and s.cols is not None]
        if len(known) == len(src):
            rows = np.concatenate([r for r, _ in known])
            cols = np.concatenate([c for _, c in known])
        else:
            cl = batch.cell[kp]
            org = batch.origin[kp]
            rows = np.rint((xy[:, 1] - org[:, 1]) / cl - batch.r0[kp]).astype(np.intp)
            cols = np.rint((xy[:, 0] - org[:, 0]) / cl - batch.c0[kp]).astype(np.intp)
        ground = batch.max_under(kp, rows, cols, batch.sweep_off, batch.sweep_in, clearance=True)
        lens, z0, tz, step, ramp, gap, way = [], [], [], [], [], [], []
        for i, s in zip(many, src, strict=True):
            p = evals[i][0].plan
            length = s.length
            lens.append(length)
            z0.append(float(p.start[2]))
            tz.append(target_z[i])
            step.append(p.params.step_height)
            # PathContext.ramp (the default PathParams) and its minimum waypoint gap.
            ramp.append(min(max(p.params.step_height, 2.0 * p.cell), 0.5 * length))
            gap.append(_PATH_DEFAULTS.min_waypoint_gap * p.cell)
            way.append(s.waypoints)
        trajs = lift_each(xy, arc, bounds, ground, lens, z0, tz, step, ramp, gap, way)
        out.update(zip(many, trajs, strict=True))
    return [out[i] for i in lifts]


_PATH_DEFAULTS = PathParams()


def plan_footsteps(requests: Sequence[FootRequest]) -> list[Couple]:
    """The best couple (:class:`Couple`) of every request, one per request in their order, for
    any number of feet (of one or many characters, on one or many windows) at once. Never
    raises for a foot that cannot be planned (non-finite input, a foot outside its window, no
    candidate, no valid couple): its couple has ``ok=False`` and a ``message``.

    The search of each foot is its own sequence of couples (Appendix E), whatever else is in
    the batch; what does not
    depend on the other feet is computed for all of them together: the search rectangles,
    the other feet's cells, the foot kernels, the obstacle maps of every slice, every
    candidate's score, the slice levels, then round after round the next couple of every foot
    still searching (line of sight, straight plans, wavefronts, 3D trajectories). A crowd
    step's plans cost a few hundred numpy calls instead of a few hundred per foot.
    """
    results: list[Couple | None] = [None] * len(requests)
    plans: list[_Plan] = []
    for i, rq in enumerate(requests):
        item = _validate(i, rq)
        if isinstance(item, Couple):
            results[i] = item
        else:
            plans.append(item)
    if plans:
        for p, couple in zip(plans, _plan_batch(plans), strict=True):
            results[p.index] = couple
    return [c for c in results if c is not None]


def _plan_batch(plans: list[_Plan]) -> list[Couple]:
    batch = _Batch(plans)
    cands = _score_all(plans, batch)
    levels = _levels_all(plans, batch.mask, batch.elev)
    feet = batch.feet(cands, levels)
    if feet:
        _run(batch, list(feet.values()), cands)
    out = []
    for k, p in enumerate(plans):
        f = feet.get(k)
        if f is None:
            out.append(_fail(p.start, _NO_CANDIDATE))
            continue
        st = f.st
        n_wf = f.ctx.n_wavefronts if f.ctx is not None else 0
        n_it = f.ctx.wavefront_iterations if f.ctx is not None else 0
        if st.best is None:
            out.append(_fail(p.start, _NO_COUPLE, n_couples=st.n_couples, n_paths=st.n_paths,
                             n_targets=f.n_targets, n_wavefronts=n_wf, wavefront_iterations=n_it))
            continue
        best = st.best
        row = f.base + best.target
        footprint = np.array([cands.xy[row, 0], cands.xy[row, 1], cands.z[row]])
        out.append(Couple(True, footprint, best.trajectory, float(best.score), cands.score_list[row],
                          float(best.path_score), st.n_couples, st.n_paths, "", f.n_targets, n_wf, n_it,
                          st.first_valid, max(0, st.n_couples - st.first_valid),
                          None if math.isinf(best.level) else float(best.level), int(best.target)))
    return out


def _score_all(plans: list[_Plan], batch: _Batch) -> _Cands:
    """Candidate footprints of every plan with their scores (thesis §3.5.1), best first
    within each plan (what :func:`score_candidates` gives each plan)."""
    n = len(plans)
    r0, c0, hh, ww, mask, elev = batch.r0, batch.c0, batch.hh, batch.ww, batch.mask, batch.elev
    forbidden = batch.grown_inf
    rows, col = batch.rows, _ROW
    pref_rc = column_pair(rows[:, col["pref_r"]] - r0, rows[:, col["pref_c"]] - c0)
    base = np.rint(pref_rc).astype(np.intp)
    sub = pref_rc - base  # the preferred footprint's offset inside its cell (cells)
    rad = rows[:, col["radius"]]
    disc = _disc_offsets(float(np.maximum.reduce(rad)))
    member = np.hypot(disc[:, 0], disc[:, 1])[None, :] <= rad[:, None] + 1e-9
    cr = base[:, 0, None] + disc[None, :, 0]
    cc = base[:, 1, None] + disc[None, :, 1]
    member &= (cr >= 0) & (cr < hh[:, None]) & (cc >= 0) & (cc < ww[:, None])
    b, d = member.nonzero()
    r = cr[b, d]
    c = cc[b, d]
    # the stacks read through flat indices (one gather each, not one per axis)
    _, H, W = elev.shape
    at = (b * H + r) * W + c
    here = elev.reshape(-1).take(at)
    ok = mask.reshape(-1).take(at) & ~forbidden.reshape(-1).take(at) & (here > _VOID_BELOW)
    # each plan's numbers at its candidates, in one gather (rows of _CAND_COLS)
    (cl, ox_b, oy_b, hx_b, hy_b, reach_b, z0_b, max_dz_b, low_b, edge_h, pref_x, pref_y, fixed,
     edge_score) = rows.T[_CAND_COLS].take(b, axis=1)
    x = ox_b + (c + c0[b] + sub[:, 1][b]) * cl
    y = oy_b + (r + r0[b] + sub[:, 0][b]) * cl
    hip = rows[:, col["hip_x"] : col["hip_y"] + 1]
    dx = x - hx_b
    dy = y - hy_b
    ok &= planar_length(dx, dy) <= reach_b
    # Landing height: the highest surface under the sole at its exact offset, turned with the
    # foot (thesis §3.4: the foot's bounding box grows the obstacles, the elevations map where
    # the foot stands lifts its path). The foot box of a foot whose toes reach far from its
    # end-effector would set it on ground up a slope that its sole never touches.
    land_off, land_in, box_in = _offset_kernels(batch, sub)
    z = batch.max_under(b, r, c, land_off, land_in)
    ok &= np.abs(z - z0_b) <= max_dz_b
    hip_z = rows[:, col["hip_z"]]
    if not np.logical_and.reduce(np.isnan(hip_z)):
        sel = (ok & ~np.isnan(hip_z)[b]).nonzero()[0]
        owner = b[sel]
        settings = rows[:, col["straddle"] : col["foot_r"] + 1]
        clear = np.ones(ok.size, dtype=bool)
        # what the whole foot box reaches, for the straddle check (the sole's when it is the box)
        box_z = z[sel] if box_in is None else batch.max_under(owner, r[sel], c[sel], land_off, box_in)
        ok[sel], clear[sel] = _hip_checks(
            column_pair(x[sel], y[sel]), z[sel], box_z, here[sel],
            hip[owner], hip_z[owner], settings[owner], _WindowLookup([p.grids for p in plans]), owner,
        )
        clearance = np.where(clear, 1.0, low_b)
    else:
        clearance = np.ones(ok.size)
    keep = ok.nonzero()[0]
    b, d, r, c, x, y, z = b[keep], d[keep], r[keep], c[keep], x[keep], y[keep], z[keep]
    clearance = clearance[keep]
    here = here[keep]
    edge_h, pref_x, pref_y, fixed, edge_score = (v[keep] for v in (edge_h, pref_x, pref_y, fixed, edge_score))
    # Neighbour criteria (8, k), neighbour by neighbour; past the stacked boxes "not free"
    # with no ground (read where they are, not from padded copies of the stacks).
    nr = r + _NEIGHBOURS[:, 0, None]
    nc = c + _NEIGHBOURS[:, 1, None]
    out = (nr < 0) | (nr >= H) | (nc < 0) | (nc >= W)
    at = (b * H + np.where(out, 0, nr)) * W + np.where(out, 0, nc)
    ne = np.where(out, -np.inf, elev.reshape(-1)[at])
    taken = out | forbidden.reshape(-1)[at] | (ne < _VOID_BELOW)
    free = np.add.reduce(~taken & (np.abs(ne - here) <= edge_h), axis=0)
    rim = np.logical_or.reduce(here - ne > edge_h, axis=0)
    ex = x - pref_x
    ey = y - pref_y
    distance = np.minimum(np.maximum(1.0 - planar_length(ex, ey) / fixed, 0.0), 1.0)
    free_score = free / 8.0
    edge = np.where(rim, edge_score, 1.0)
    # Only positive scores are targets: the leg-crossing criterion (0 or 1) is needed for those.
    partial = distance * free_score * edge * clearance
    live = (partial > 0.0).nonzero()[0]
    b, d, r, c = b[live], d[live], r[live], c[live]
    x, y, z, partial = x[live], y[live], z[live], partial[live]
    xy = column_pair(x, y)
    n_other = rows[:, col["n_other"]].astype(np.intp)
    j = int(np.maximum.reduce(n_other, initial=0))
    if j and b.size:
        # each plan's other legs, slot by slot: (j, n) per coordinate
        who = np.arange(n).repeat(n_other)
        slot = np.arange(who.size) - (n_other.cumsum() - n_other).repeat(n_other)
        legs_xy = []
        for part in (np.concatenate([p.o_hips for p in plans]), np.concatenate([p.o_feet for p in plans])):
            for axis in (0, 1):
                grid = np.zeros((j, n))
                grid[slot, who] = part[:, axis]
                legs_xy.append(grid[:, b])
        valid = np.arange(j)[:, None] < n_other[b]
        crosses = _legs_cross_each(hip[b], xy, (legs_xy[0], legs_xy[1]), (legs_xy[2], legs_xy[3]), valid)
    else:
        crosses = np.zeros(b.size, dtype=bool)
    score = partial * np.where(crosses, 0.0, 1.0)
    keep = (score > 0.0).nonzero()[0]
    b, d, r, c, xy, z, score = b[keep], d[keep], r[keep], c[keep], xy[keep], z[keep], score[keep]
    # Best first; ties: nearer the preferred footprint, then row, then column.
    order = np.lexsort((c, r, np.hypot(disc[:, 0][d], disc[:, 1][d]), -score, b))
    b = b[order]
    cells = column_pair(r[order], c[order])
    score = score[order]
    cuts = b.searchsorted(np.arange(n + 1)).tolist()
    n_valid = [cuts[k + 1] - cuts[k] for k in range(n)]
    return _Cands(xy[order], cells, z[order], score, cuts, n_valid, score.tolist(), cells[:, 0].tolist(),
                  cells[:, 1].tolist())


#: The columns of :attr:`_Plan.row` that :func:`_score_all` reads at each candidate.
_CAND_COLS = [_ROW[k] for k in ("cell", "ox", "oy", "hip_x", "hip_y", "reach", "start_z", "max_dz", "low",
                                "edge_height", "pref_x", "pref_y", "fixed", "edge_score")]


class _WindowLookup:
    """The elevation of many plans' windows at points (``-inf`` outside a window): read from
    their :attr:`~.terrain.WindowGrids.stack` when they were made together, else from a
    concatenation of their elevations."""

    def __init__(self, grids: list[WindowGrids]) -> None:
        index: dict[int, int] = {}
        uniq: list[WindowGrids] = []
        which = []
        for g in grids:
            k = index.setdefault(id(g), len(uniq))
            if k == len(uniq):
                uniq.append(g)
            which.append(k)
        stack = uniq[0].stack
        if len(uniq) == 1:
            self.flat = uniq[0].elevation.ravel()
            starts = np.zeros(1, dtype=np.intp)
        elif stack is not None and all(g.stack is not None and g.stack[0] is stack[0] for g in uniq):
            self.flat = stack[0].reshape(-1)
            plane = stack[0].shape[1] * stack[0].shape[2]
            starts = np.array([g.stack[1] * plane for g in uniq if g.stack is not None], dtype=np.intp)
        else:
            sizes = [g.elevation.size for g in uniq]
            self.flat = np.concatenate([g.elevation.ravel() for g in uniq])
            starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
        w = np.asarray(which)
        self.start = starts[w]
        self.ox = np.array([float(g.origin[0]) for g in uniq])[w]
        self.oy = np.array([float(g.origin[1]) for g in uniq])[w]
        self.cell = np.array([g.cell for g in uniq])[w]
        self.ny = np.array([g.shape[0] for g in uniq])[w]
        self.nx = np.array([g.shape[1] for g in uniq])[w]

    def heights(self, x: FloatArray, y: FloatArray, plan: IntArray) -> FloatArray:
        """Elevation under points ``(x, y)`` ``(S, m)`` of plans ``plan (m,)`` (point ``[s,
        i]`` of plan ``plan[i]``)."""
        cl = self.cell[plan]
        col = np.rint((x - self.ox[plan]) / cl).astype(np.intp)
        row = np.rint((y - self.oy[plan]) / cl).astype(np.intp)
        ny = self.ny[plan]
        nx = self.nx[plan]
        inside = (row >= 0) & (row < ny) & (col >= 0) & (col < nx)
        at = (self.start[plan] + np.minimum(np.maximum(row, 0), ny - 1) * nx
              + np.minimum(np.maximum(col, 0), nx - 1))
        return np.asarray(np.where(inside, self.flat[at], -np.inf))


def _offset_kernels(batch: _Batch, sub: FloatArray) -> tuple[IntArray, BoolArray, BoolArray | None]:
    """The landing kernels of each plan of ``batch``, a foot whose centre sits ``sub``
    ``(n, 2)`` cells off its cell's centre (sub offsets rounded to 1e-9 cell, as cached):
    the cell offsets, the cells under its sole (its part within the foot box) and those under
    its foot box (None when no plan's sole is smaller), ``(n, k)`` each, turned with its yaw."""
    cell, hx, hy, yaw = batch.cell, batch.half_x, batch.half_y, batch.yaw
    sub_r = np.array([round(v, 9) for v in sub[:, 0].tolist()])
    sub_c = np.array([round(v, 9) for v in sub[:, 1].tolist()])
    reach = int(np.maximum.reduce(batch.rows[:, _ROW["land_reach"]]))
    off = _rect_offsets(reach, reach)
    col = cell[:, None]
    # the cell centres from the foot's centre, x and y apart
    dx = off[None, :, 1] * col - (sub_c * cell)[:, None]
    dy = off[None, :, 0] * col - (sub_r * cell)[:, None]
    cos = np.cos(yaw)[:, None]
    sin = np.sin(yaw)[:, None]
    sole_x, sole_y = batch.sole_x, batch.sole_y
    box = None
    if np.logical_or.reduce((sole_x < hx) | (sole_y < hy)):
        # a sole within the foot box: the foot lands under its sole
        box = _overlaps(dx, dy, col, hx[:, None], hy[:, None], cos, sin)
        hx, hy = np.minimum(sole_x, hx), np.minimum(sole_y, hy)
    member = _overlaps(dx, dy, col, hx[:, None], hy[:, None], cos, sin)
    centre = (2 * reach + 1) * reach + reach
    for m in (member, box):
        if m is None:
            continue
        empty = ~np.logical_or.reduce(m, axis=1)
        if np.logical_or.reduce(empty):
            m[empty, centre] = True
    return off, member, box


def _levels_all(plans: list[_Plan], mask: BoolArray, elev: FloatArray) -> list[list[float]]:
    """Slice levels of every plan (:func:`slice_levels`)."""
    out: list[list[float]] = [[math.inf] for _ in plans]
    sliced = [k for k, p in enumerate(plans) if p.params.slice_size is not None]
    if not sliced:
        return out
    sel = np.asarray(sliced)
    ev_sel = elev[sel]
    valid = mask[sel] & (ev_sel > _VOID_BELOW)
    e = np.where(valid, ev_sel, -np.inf)
    tops = np.maximum.reduce(e, axis=(1, 2)).tolist()
    lists = []
    for i, k in enumerate(sliced):
        p = plans[k]
        z0 = float(p.start[2])
        reach_up = p.reach if p.params.max_height_change is None else p.params.max_height_change
        top = min(tops[i] if tops[i] != -math.inf else z0, z0 + reach_up)
        size = p.params.slice_size
        assert size is not None
        lists.append(_level_list(z0, size, top))
    j = max(len(lv) for lv in lists)
    if j <= 16:
        lv_arr = np.full((sel.size, j), math.inf)
        for i, lv in enumerate(lists):
            lv_arr[i, : len(lv)] = lv
        above = np.add.reduce(e.reshape(sel.size, 1, -1) > lv_arr[:, :, None], axis=2).tolist()
    else:
        above = []
        for i in range(sel.size):
            ev = ev_sel[i][valid[i]]
            above.append([int(np.count_nonzero(ev > lv)) for lv in lists[i]])
    for i, k in enumerate(sliced):
        out[k] = _distinct_levels(lists[i], above[i][: len(lists[i])])
    return out
