# SPDX-License-Identifier: GPL-3.0-or-later
"""The one-foot footprint planner, kept as a readable reference for the tests.

The product is :func:`procloco_addon.core.locomotion.footprints.plan_footsteps` (the batched search the
controller calls for every foot of a step). This module plans one foot at a time with the
same rules written out plainly, one candidate, one slice, one couple after the other (thesis
§3.5, Appendix E): candidates and their scores (:func:`score_candidates`), slice levels
(:func:`slice_levels`), then the best-couple loop of :func:`plan_footstep`. The tests compare
the two: the same decisions (success, footprint cell, target, slice, every count) exactly,
the floats to the tolerance of :mod:`tests.core.cross_path` (the two paths group their
arithmetic differently).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from procloco_addon.core.geometry import planar_length
from procloco_addon.core.locomotion.footprints import (
    _NEIGHBOURS,
    Couple,
    FootRequest,
    LegGeometry,
    PlannerParams,
    SearchSwitches,
    _disc_offsets,
    _distinct_levels,
    _fail,
    _hip_checks,
    _hip_settings,
    _level_list,
    _reach,
    _sole,
    _WindowLookup,
)
from procloco_addon.core.world.pathing import (
    FootTrajectory,
    PathContext,
    PathParams,
    path_score_2d,
    search_region,
    vertical_factor,
)
from procloco_addon.core.world.terrain import _VOID_BELOW, WindowGrids, _box_overlaps_cells, raster_boxes

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Candidates:
    """Scored candidate footprints: ``xy`` ``(k, 2)``, ``cells`` ``(k, 2)`` region cells,
    ``z`` ``(k,)`` landing heights, ``score`` ``(k,)`` and its criteria ``distance``, ``free``,
    ``edge``, ``crossing`` (each ``(k,)``), sorted best first."""

    xy: FloatArray
    cells: IntArray
    z: FloatArray
    score: FloatArray
    distance: FloatArray
    free: FloatArray
    edge: FloatArray
    crossing: FloatArray


def legs_cross(
    hip_xy: FloatArray, foot_xy: FloatArray, other_hips: FloatArray, other_feet: FloatArray
) -> BoolArray:
    """Whether segment hip→foot ``(k, 2)`` properly crosses any other leg's hip→foot
    ``(j, 2)``; returns ``(k,)``. Touching at an end (shared hips) is not a crossing."""
    if other_hips.shape[0] == 0:
        return np.zeros(foot_xy.shape[0], dtype=bool)
    p = np.broadcast_to(hip_xy, foot_xy.shape)[:, None, :]
    r = (foot_xy - np.broadcast_to(hip_xy, foot_xy.shape))[:, None, :]
    q = other_hips[None, :, :]
    s = (other_feet - other_hips)[None, :, :]

    def cross(a: FloatArray, b: FloatArray) -> FloatArray:
        return np.asarray(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])

    d1 = cross(r, q - p)
    d2 = cross(r, q + s - p)
    d3 = cross(s, p - q)
    d4 = cross(s, p + r - q)
    eps = 1e-12
    hit = (((d1 > eps) & (d2 < -eps)) | ((d1 < -eps) & (d2 > eps))) & (
        ((d3 > eps) & (d4 < -eps)) | ((d3 < -eps) & (d4 > eps)))
    return np.asarray(np.any(hit, axis=1))


def score_candidates(
    ctx: PathContext,
    preferred_xy: FloatArray,
    hip_xy: FloatArray,
    other_hips_xy: FloatArray,
    other_feet_xy: FloatArray,
    rq: FootRequest,
) -> Candidates:
    """Candidate footprints around ``preferred_xy`` with their scores (thesis §3.5.1), for
    the settings, leg and reach of request ``rq`` (the hip's height ``rq.hip_z`` for the
    checks that need it, :class:`LegGeometry`)."""
    params, leg, reach = rq.params, rq.leg, _reach(rq)
    foot_yaw, hip_z = rq.foot_yaw, rq.hip_z
    grids = ctx.grids
    cell = grids.cell
    reg = ctx.region
    pref_rc = grids.rowcol(preferred_xy) - np.array([reg.r0, reg.c0])
    base = np.rint(pref_rc).astype(np.intp)
    sub = pref_rc - base  # the preferred footprint's offset inside its cell (cells)
    off = _disc_offsets(round(params.candidate_radius / cell, 9))
    cells = base[None, :] + off
    h, w = reg.shape
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < h) & (cells[:, 1] >= 0) & (cells[:, 1] < w)
    cells = cells[inside]
    off = off[inside]
    empty = np.zeros(0)
    if cells.shape[0] == 0:
        none = np.zeros((0, 2), dtype=np.intp)
        return Candidates(np.zeros((0, 2)), none, empty, empty, empty, empty, empty, empty)
    core, dilated, _ = ctx.maps(math.inf)
    forbidden = core | dilated
    r, c = cells[:, 0], cells[:, 1]
    elev = ctx.elevation
    ok = reg.mask[r, c] & ~forbidden[r, c] & (elev[r, c] > _VOID_BELOW)
    xy = grids.xy_of(cells[:, 0] + reg.r0 + sub[0], cells[:, 1] + reg.c0 + sub[1])
    to_hip = xy - hip_xy
    ok &= planar_length(to_hip[:, 0], to_hip[:, 1]) <= reach + 1e-9
    # Landing height: the highest surface under the sole (within the foot box) at its exact
    # offset, turned with the foot; the highest under the foot box for the straddle check.
    half = np.asarray(leg.foot_half_extents, dtype=np.float64)
    hx, hy = float(half[0]), float(half[1])
    sole_x, sole_y = _sole(leg, (hx, hy))
    at = (float(foot_yaw), round(float(sub[0]), 9), round(float(sub[1]), 9))
    z = ctx.land_height(cells, _offset_kernel(cell, min(sole_x, hx), min(sole_y, hy), *at))
    box_z = ctx.land_height(cells, _offset_kernel(cell, hx, hy, *at))
    max_dz = reach if params.max_height_change is None else params.max_height_change
    ok &= np.abs(z - ctx.start[2]) <= max_dz
    if hip_z is not None:
        sel = np.flatnonzero(ok)
        m = sel.size
        clear = np.ones(ok.size, dtype=bool)
        ok[sel], clear[sel] = _hip_checks(
            xy[sel], z[sel], box_z[sel], elev[r[sel], c[sel]], np.broadcast_to(hip_xy, (m, 2)),
            np.full(m, float(hip_z)), np.tile(_hip_settings(leg, rq.reach_sweep, rq.reach_sink), (m, 1)),
            _WindowLookup([ctx.grids]), np.zeros(m, dtype=np.intp),
        )
        clearance = np.where(clear[ok], 1.0, params.leg_clearance_score)
    else:
        clearance = np.ones(int(np.count_nonzero(ok)))
    cells, off, xy, z = cells[ok], off[ok], xy[ok], z[ok]
    r, c = cells[:, 0], cells[:, 1]
    # Neighbour criteria on the region, padded as "not free".
    pad_forb = np.ones((h + 2, w + 2), dtype=bool)
    pad_forb[1:-1, 1:-1] = forbidden | (elev < _VOID_BELOW)
    pad_elev = np.full((h + 2, w + 2), -np.inf)
    pad_elev[1:-1, 1:-1] = elev
    here = elev[r, c][:, None]
    nr = r[:, None] + 1 + _NEIGHBOURS[None, :, 0]
    nc = c[:, None] + 1 + _NEIGHBOURS[None, :, 1]
    ne = pad_elev[nr, nc]  # (k, 8)
    free = np.count_nonzero(~pad_forb[nr, nc] & (np.abs(ne - here) <= params.edge_height), axis=1)
    rim = np.any(here - ne > params.edge_height, axis=1)
    to_pref = xy - preferred_xy
    distance = np.clip(1.0 - planar_length(to_pref[:, 0], to_pref[:, 1]) / params.fixed_distance, 0.0, 1.0)
    free_score = free / 8.0
    edge = np.where(rim, params.edge_score, 1.0)
    crossing = np.where(legs_cross(hip_xy, xy, other_hips_xy, other_feet_xy), 0.0, 1.0)
    score = distance * free_score * edge * clearance * crossing
    # Best first; ties: nearer the preferred footprint, then row, then column.
    order = np.lexsort((c, r, np.hypot(off[:, 0], off[:, 1]), -score))
    return Candidates(xy[order], cells[order], z[order], score[order], distance[order], free_score[order],
                      edge[order], crossing[order])


@functools.lru_cache(maxsize=1024)
def _offset_kernel(cell: float, hx: float, hy: float, yaw: float, sub_r: float, sub_c: float) -> IntArray:
    """Cells covered by a foot box whose centre sits ``(sub_r, sub_c)`` cells off its cell's
    centre."""
    reach = math.ceil((abs(hx) + abs(hy)) / cell + 1.0)
    ii, jj = np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1), indexing="ij")
    centres = np.stack([jj.ravel() * cell, ii.ravel() * cell], axis=1)
    centre = np.array([sub_c * cell, sub_r * cell])
    hit = _box_overlaps_cells(centres, cell, centre, hx, hy, yaw)
    off = np.stack([ii.ravel()[hit], jj.ravel()[hit]], axis=1).astype(np.intp)
    if off.shape[0] == 0:
        off = np.zeros((1, 2), dtype=np.intp)
    off.setflags(write=False)
    return off


def _other_feet_mask(
    grids: WindowGrids, feet_xy: FloatArray, half: FloatArray, yaw: float
) -> BoolArray | None:
    if feet_xy.shape[0] == 0:
        return None
    mask = np.zeros(grids.shape, dtype=bool)
    n = feet_xy.shape[0]
    _, r, c = raster_boxes(grids.origin, grids.cell, grids.shape, feet_xy, np.full(n, half[0]),
                           np.full(n, half[1]), np.full(n, yaw))
    mask[r, c] = True
    return mask


def slice_levels(ctx: PathContext, slice_size: float | None, ceiling: float = math.inf) -> list[float]:
    """Slice levels for one plan, lowest first, ending with ``inf`` (no slice).

    Levels are ``z_foot + k * slice_size`` (k >= 1) below the highest surface in the search
    rectangle and below ``ceiling`` (higher slices only add ways over taller things, which the
    last pass already tries); levels that forbid exactly the same cells as the next one are
    dropped.
    """
    if slice_size is None:
        return [math.inf]
    elev = ctx.elevation[ctx.region.mask]
    elev = elev[elev > _VOID_BELOW]
    top = min(float(elev.max()) if elev.size else float(ctx.start[2]), ceiling)
    levels = _level_list(float(ctx.start[2]), slice_size, top)
    above = [int(np.count_nonzero(elev > lv)) for lv in levels]
    return _distinct_levels(levels, above)


def plan_footstep(rq: FootRequest) -> Couple:
    """The best couple (footprint, 3D trajectory) for the one swinging foot of request ``rq``
    (:class:`~procloco_addon.core.locomotion.footprints.FootRequest`). Never raises for an unreachable
    target; never returns NaN.
    """
    grids, foot_start, preferred_xy, hip_xy = rq.grids, rq.foot_start, rq.preferred_xy, rq.hip_xy
    other_hips_xy, other_feet_xy, foot_yaw, hip_z = rq.other_hips_xy, rq.other_feet_xy, rq.foot_yaw, rq.hip_z
    params, leg, search, reach = rq.params, rq.leg, rq.search, _reach(rq)
    start = np.asarray(foot_start, dtype=np.float64).reshape(3)
    pref = np.asarray(preferred_xy, dtype=np.float64).reshape(2)
    hip = np.asarray(hip_xy, dtype=np.float64).reshape(2)
    o_hips = np.asarray(other_hips_xy, dtype=np.float64).reshape(-1, 2)
    o_feet = np.asarray(other_feet_xy, dtype=np.float64).reshape(-1, 2)
    safe_start = np.where(np.isfinite(start), start, 0.0)
    if not (np.all(np.isfinite(start)) and np.all(np.isfinite(pref)) and np.all(np.isfinite(hip))
            and np.all(np.isfinite(o_hips)) and np.all(np.isfinite(o_feet))
            and (hip_z is None or math.isfinite(float(hip_z)))):
        return _fail(safe_start, "non-finite input")
    if o_hips.shape != o_feet.shape:
        return _fail(start, "other_hips_xy and other_feet_xy differ in shape")
    cell = grids.cell
    half = np.asarray(leg.foot_half_extents, dtype=np.float64).reshape(2)
    start_rc = grids.rowcol(start[:2])
    pref_rc = grids.rowcol(pref)
    ny, nx = grids.shape
    if not (-0.5 <= start_rc[0] < ny - 0.5 and -0.5 <= start_rc[1] < nx - 0.5):
        return _fail(start, "the foot is outside the window grids")
    half_width = search.search_half_width
    if half_width is None:
        half_width = max(params.candidate_radius, 0.5 * reach)
    foot_cells = (abs(half[0]) + abs(half[1])) / cell + 1.0
    region = search_region(grids.shape, start_rc, pref_rc, half_width / cell + foot_cells,
                           params.candidate_radius / cell + foot_cells + 1.0, 1.0 + foot_cells)
    extra = _other_feet_mask(grids, o_feet, np.asarray(_sole(leg, (float(half[0]), float(half[1])))),
                             foot_yaw)
    path_params = PathParams(step_height=params.step_height, tension=params.tension,
                             los_shortcut=search.los_shortcut)
    ctx = PathContext(grids, start, region, extra, half, foot_yaw, path_params,
                      per_target=not search.shared_wavefront)
    cand = score_candidates(ctx, pref, hip, o_hips, o_feet, rq)
    valid = cand.score > 0.0
    n_targets = int(np.count_nonzero(valid))
    if n_targets == 0:
        why = ("no candidate footprint: every cell near the preferred footprint is forbidden, "
               "out of reach, without ground or crosses another leg")
        return _fail(start, why)
    order = np.nonzero(valid)[0]
    if search.max_targets is not None:
        order = order[: search.max_targets]
    reach_up = reach if params.max_height_change is None else params.max_height_change
    levels = slice_levels(ctx, params.slice_size, float(start[2]) + reach_up)
    exhaustive = search.exhaustive
    budget = None if exhaustive else params.max_couples_after_first

    best_score = 0.0
    best: tuple[int, float, float, FootTrajectory, float] | None = None
    n_couples = n_paths = after_first = first_valid = 0
    stop = False
    for t in order.tolist():
        t_score = float(cand.score[t])
        if not exhaustive and best is not None and t_score <= best_score:
            break  # Appendix E: no couple with this target can beat the best one
        cell_t = (int(cand.cells[t, 0]), int(cand.cells[t, 1]))
        for level in levels:
            path = ctx.path_2d(level, cell_t, cand.xy[t])
            if path is None:
                continue
            n_couples += 1
            if best is not None:
                after_first += 1
            s2 = path_score_2d(path)
            # Appendix E: build the 3D trajectory only when the 2D bound beats the best couple.
            if exhaustive or best is None or t_score * s2 > best_score:
                traj = ctx.lift(path, float(cand.z[t]))
                n_paths += 1
                s3 = s2 * vertical_factor(traj, params.step_height)
                score = t_score * s3
                if best is None or score > best_score:
                    if best is None:
                        first_valid = n_couples
                    best = (t, s3, level, traj, score)
                    best_score = score
            if budget is not None and best is not None and after_first >= budget:
                stop = True
                break
            if path.in_sight:
                # A straight line clear at this slice is clear at every higher one: the same
                # couple again, which cannot beat itself.
                break
        if stop:
            break

    counts = {"n_couples": n_couples, "n_paths": n_paths, "n_targets": n_targets,
              "n_wavefronts": ctx.n_wavefronts, "wavefront_iterations": ctx.wavefront_iterations}
    if best is None:
        return _fail(start, "no valid couple: no candidate footprint can be reached from the foot", **counts)
    t, s3, level, traj, score = best
    footprint = np.array([cand.xy[t, 0], cand.xy[t, 1], cand.z[t]])
    return Couple(
        ok=True,
        footprint=footprint,
        trajectory=traj,
        score=float(score),
        target_score=float(cand.score[t]),
        path_score=float(s3),
        n_couples=n_couples,
        n_paths=n_paths,
        message="",
        n_targets=n_targets,
        n_wavefronts=ctx.n_wavefronts,
        wavefront_iterations=ctx.wavefront_iterations,
        first_valid_couple=first_valid,
        n_couples_after_first=max(0, n_couples - first_valid),
        slice_level=None if math.isinf(level) else float(level),
        target_index=int(t),
    )



@dataclass(frozen=True)
class FlatSettings:
    """A test's or benchmark's planner set-up in one flat object, so that a scenario reads as
    one ``replace(...)``: every field of :class:`~procloco_addon.core.locomotion.footprints.PlannerParams`,
    :class:`~procloco_addon.core.locomotion.footprints.LegGeometry` and
    :class:`~procloco_addon.core.locomotion.footprints.SearchSwitches`, and a request's per-plan
    ``reach_sweep`` and ``reach_sink``; :meth:`request` splits it into a ``FootRequest``."""

    step_height: float = 0.1
    slice_size: float | None = 0.1
    leg_reach: float = 0.6
    candidate_radius: float = 0.2
    fixed_distance: float = 0.3
    foot_half_extents: tuple[float, float] = (0.03, 0.03)
    sole_half_extents: tuple[float, float] | None = None
    max_couples_after_first: int | None = None
    edge_height: float = 0.04
    edge_score: float = 0.8
    max_height_change: float | None = None
    search_half_width: float | None = None
    tension: float = 0.5
    shared_wavefront: bool = True
    exhaustive: bool = False
    max_targets: int | None = None
    los_shortcut: bool = True
    reach_3d: float | None = None
    reach_sweep: float = 0.0
    reach_sink: float = 0.0
    leg_length: float | None = None
    leg_arch: float = 0.0
    leg_clearance_score: float = 0.2
    max_straddle: float | None = None

    def parts(self) -> tuple[PlannerParams, LegGeometry, SearchSwitches]:
        """The settings, the leg and the search switches."""
        def pick(cls: type) -> dict[str, Any]:
            return {f.name: getattr(self, f.name) for f in fields(cls)}

        return (PlannerParams(**pick(PlannerParams)), LegGeometry(**pick(LegGeometry)),
                SearchSwitches(**pick(SearchSwitches)))

    def request(self, grids: WindowGrids, foot_start: npt.ArrayLike, preferred_xy: npt.ArrayLike,
                hip_xy: npt.ArrayLike, other_hips_xy: npt.ArrayLike, other_feet_xy: npt.ArrayLike,
                foot_yaw: float = 0.0, hip_z: float | None = None) -> FootRequest:
        """The request of one foot with these settings."""
        params, leg, search = self.parts()
        return FootRequest(grids, foot_start, preferred_xy, hip_xy, other_hips_xy, other_feet_xy, params,
                           foot_yaw, hip_z, leg, search, reach_sweep=self.reach_sweep,
                           reach_sink=self.reach_sink)
