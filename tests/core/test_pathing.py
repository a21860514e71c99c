# SPDX-License-Identifier: GPL-3.0-or-later
"""Wavefront, supercover line of sight, 2D curves and 3D foot trajectories (thesis §3.4.2)."""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core.hull import upper_hull
from procloco_addon.core.world.pathing import (
    MOVE_LENGTH,
    MOVES,
    FootTrajectory,
    PathContext,
    PathParams,
    _hull_knots_increasing,
    _linspace,
    _segment_clear,
    build_path,
    clearance_profile,
    descend,
    height_profile,
    lift_each,
    line_of_sight_reduce,
    octile_field,
    points_at_each,
    region_frame,
    region_masks,
    search_region,
    segments_clear,
    segments_clear_each,
    supercover_cells,
    trajectory_valid,
    turning_each,
    wavefront,
    wavefront_each,
)
from procloco_addon.core.world.terrain import (
    ROLE_AVOID,
    ROLE_STEP_OVER,
    Boxes,
    Environment,
    Heightmap,
    WindowGrids,
    WindowParams,
    foot_kernel,
)
from tests.core import reference_pathing
from tests.core.cross_path import assert_close

PARAMS = WindowParams(n_cells=40, cell=0.07, foot_half_extents=(0.03, 0.03))


def flat(z: float = 0.0) -> Heightmap:
    return Heightmap(np.full((13, 13), z), np.array([-3.0, -3.0]), 0.5)


def crates(rows: list[tuple[float, float, float, float, float, int]]) -> Boxes:
    """(x, y, sx, sy, height, role) rows, yaw 0, static, on z = 0."""
    a = np.array(rows, dtype=float).reshape(-1, 6)
    n = a.shape[0]
    return Boxes(np.column_stack([a[:, :2], np.zeros(n)]), a[:, 2:5], np.zeros(n), a[:, 5].astype(int),
                 np.zeros(n, dtype=bool))


def reference_distances(free: np.ndarray, source: tuple[int, int]) -> np.ndarray:
    """Plain Dijkstra over the same moves (8 neighbours, no corner cutting)."""
    h, w = free.shape
    dist = np.full((h, w), np.inf)
    dist[source] = 0.0
    heap = [(0.0, source)]
    while heap:
        d, (r, c) = heapq.heappop(heap)
        if d > dist[r, c]:
            continue
        for (dr, dc), length in zip(MOVES, MOVE_LENGTH, strict=True):
            rr, cc = r + dr, c + dc
            if not (0 <= rr < h and 0 <= cc < w) or not free[rr, cc]:
                continue
            if dr and dc and not (free[r + dr, c] and free[r, c + dc]):
                continue
            if d + length < dist[rr, cc] - 1e-12:
                dist[rr, cc] = d + length
                heapq.heappush(heap, (d + length, (rr, cc)))
    return dist


@given(st.integers(0, 100_000), st.floats(0.0, 0.45))
def test_wavefront_equals_dijkstra_and_descends_along_legal_moves(seed: int, density: float) -> None:
    rng = np.random.default_rng(seed)
    free = rng.random((14, 17)) > density
    source = (int(rng.integers(14)), int(rng.integers(17)))
    free[source] = True
    field = wavefront(free, source)
    ref = reference_distances(free, source)
    assert np.array_equal(np.isinf(field.dist), np.isinf(ref))
    assert np.allclose(field.dist[np.isfinite(ref)], ref[np.isfinite(ref)])
    for cell in np.argwhere(np.isfinite(ref))[:20]:
        path = descend(field, (int(cell[0]), int(cell[1])))
        assert tuple(path[0]) == tuple(cell)
        assert tuple(path[-1]) == source
        steps = np.diff(path, axis=0)
        assert np.all(np.abs(steps).max(axis=1) == 1)
        assert np.all(free[path[:, 0], path[:, 1]])
        diag = np.all(steps != 0, axis=1)
        side_a = free[path[:-1, 0][diag] + steps[diag, 0], path[:-1, 1][diag]]
        side_b = free[path[:-1, 0][diag], path[:-1, 1][diag] + steps[diag, 1]]
        assert np.all(side_a & side_b)  # never cuts a forbidden corner
        length = np.sum(np.where(diag, math.sqrt(2.0), 1.0))
        assert length == pytest.approx(ref[tuple(cell)])  # the descent is a shortest path
    blocked_cell = np.argwhere(~free)
    if blocked_cell.size:
        assert descend(field, tuple(blocked_cell[0])).shape == (0, 2)


def test_free_space_field_has_a_closed_form() -> None:
    free = np.ones((9, 12), dtype=bool)
    a = wavefront(free, (3, 4))
    b = octile_field((9, 12), (3, 4))
    assert np.allclose(a.dist, b.dist)
    path = descend(b, (8, 11))
    assert len(path) == 8  # max(|dr|, |dc|) + 1 cells


@given(st.tuples(*[st.floats(-1.0, 9.0, allow_nan=False)] * 4))
def test_supercover_holds_every_cell_the_segment_touches_and_no_other(seg: tuple[float, ...]) -> None:
    a = np.array(seg[:2])
    b = np.array(seg[2:])
    cells = {tuple(c) for c in supercover_cells(a, b).tolist()}
    t = np.linspace(0.0, 1.0, 4001)
    dense = a + t[:, None] * (b - a)
    for p in np.unique(np.rint(dense).astype(int), axis=0).tolist():
        assert tuple(p) in cells
    # Every reported cell's square comes within a hair of the segment.
    tol = 0.5 + np.linalg.norm(b - a) / 4000 + 1e-6
    for r, c in cells:
        assert np.min(np.max(np.abs(dense - np.array([r, c])), axis=1)) <= tol


def test_supercover_through_a_corner_takes_the_four_cells_and_blocks_corner_cutting() -> None:
    cells = {tuple(c) for c in supercover_cells(np.array([0.0, 0.0]), np.array([1.0, 1.0])).tolist()}
    assert {(0, 0), (1, 1), (0, 1), (1, 0)} <= cells
    blocked = np.zeros((3, 3), dtype=bool)
    blocked[0, 1] = True
    assert not segments_clear(blocked, np.array([0.0, 0.0]), np.array([[1.0, 1.0]]))[0]
    assert segments_clear(blocked, np.array([0.0, 0.0]), np.array([[2.0, 0.0]]))[0]
    # Outside the grid counts as blocked.
    assert not segments_clear(blocked, np.array([0.0, 0.0]), np.array([[2.0, 3.0]]))[0]


@given(st.integers(0, 100_000))
def test_line_of_sight_keeps_few_cells_that_all_see_each_other(seed: int) -> None:
    rng = np.random.default_rng(seed)
    free = rng.random((20, 20)) > 0.25
    free[0, 0] = free[19, 19] = True
    field = wavefront(free, (0, 0))
    if not np.isfinite(field.dist[19, 19]):
        return
    naive = descend(field, (19, 19)).astype(float)
    keep = line_of_sight_reduce(~free, naive)
    assert keep[0] == 0
    assert keep[-1] == naive.shape[0] - 1
    kept = naive[keep]
    for p, q in itertools.pairwise(kept):
        assert segments_clear(~free, p, q[None, :])[0]
    assert len(keep) <= len(naive)
    assert len(line_of_sight_reduce(np.zeros((20, 20), dtype=bool), naive)) == 2


def figure_325_window() -> WindowGrids:
    """Two crates on the way from (0, 0) to (1, 0): a wide one 15 cm high at x = 0.35 and a
    narrow one 25 cm high at x = 0.7."""
    env = Environment(flat(), crates([(0.35, 0.0, 0.1, 0.6, 0.15, ROLE_STEP_OVER),
                                      (0.70, 0.0, 0.1, 0.2, 0.25, ROLE_STEP_OVER)]))
    return env.window(np.array([0.5, 0.0]), PARAMS)


def _over(traj: FootTrajectory, x: float, half: float = 0.05) -> np.ndarray:
    return np.abs(traj.points[:, 0] - x) <= half


@pytest.mark.parametrize(
    ("level", "over_first", "over_second"),
    [(None, True, True), (0.1, False, False), (0.2, True, False), (0.3, True, True)],
)
def test_figure_3_25_slices_go_over_what_is_below_and_around_what_is_above(
    level: float | None, over_first: bool, over_second: bool
) -> None:
    w = figure_325_window()
    traj = build_path(w, np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0]), PathParams(step_height=0.1),
                      level=level, half_width=0.7)
    assert traj is not None
    for x, top, half_y, over in ((0.35, 0.15, 0.3, over_first), (0.70, 0.25, 0.1, over_second)):
        near = _over(traj, x)
        assert near.any()
        crossing_y = np.abs(traj.points[near, 1])
        if over:
            assert crossing_y.min() < half_y  # crosses the crate's footprint ...
            assert traj.points[near, 2].min() >= top + 0.1 - 1e-9  # ... at least a step above it
        else:
            assert crossing_y.min() > half_y + 0.03  # passes beside it, foot included


def _check_trajectory(w: WindowGrids, traj: FootTrajectory, start: np.ndarray, step_height: float,
                      level: float | None = None) -> None:
    pts = traj.points
    assert np.all(np.isfinite(pts))
    assert np.allclose(pts[0], start)
    core, dilated = w.obstacle_map(level=level)
    rc = w.cell_of(pts[:, :2])
    assert np.all(w.inside(rc))
    start_rc = w.cell_of(start[:2])
    liftoff = {tuple(start_rc + k) for k in foot_kernel(w.cell, w.foot_half_extents, 0.0).tolist()}
    outside_liftoff = np.array([tuple(c) not in liftoff for c in rc.tolist()])
    assert not np.any((core | dilated)[rc[:, 0], rc[:, 1]] & outside_liftoff)
    # Above the elevation map plus the clearance (which is 0 at both ends).
    s = traj.arc_2d
    clearance = clearance_profile(s, s[-1], step_height, min(max(step_height, 2 * w.cell), 0.5 * s[-1]))
    ground = w.elevation[rc[:, 0], rc[:, 1]]
    in_start_cell = np.all(rc == start_rc, axis=1)
    required = np.where(in_start_cell, np.minimum(ground, start[2]), ground + clearance)
    assert np.all(pts[1:, 2] >= required[1:] - 1e-9)
    # Constant speed along the curve.
    u = np.linspace(0.0, 1.0, 21)
    p = traj.point_at(u)
    gaps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert np.all(gaps <= traj.length / 20 + 1e-9)
    assert np.sum(gaps) <= traj.length + 1e-9
    assert np.allclose(p[[0, -1]], pts[[0, -1]])


def test_swings_sampled_together_are_each_ones_interpolation() -> None:
    # points_at_each against np.interp coordinate by coordinate on each trajectory alone:
    # trajectories of every length (one point, no length, a repeated point, long ones), at
    # fractions on and between knots and outside [0, 1]
    rng = np.random.default_rng(4)
    trajs = []
    for k in range(40):
        pts = np.cumsum(rng.normal(size=(int(rng.integers(1, 30)), 3)), axis=0)
        if k % 5 == 0 and pts.shape[0] > 3:
            pts[2] = pts[1]
        if k % 7 == 0:
            pts[:] = pts[0]
        trajs.append(FootTrajectory.from_points(pts))
    u = np.concatenate([np.linspace(0.0, 1.0, 17), [-0.5, 1.5, 0.3]])
    got = points_at_each(trajs, u)
    assert got.shape == (40, u.size, 3)
    for traj, g in zip(trajs, got, strict=True):
        s = np.clip(u, 0.0, 1.0) * traj.length
        want = np.stack([np.interp(s, traj.arc, traj.points[:, k]) for k in range(3)], axis=1)
        assert_close(g, want, "points")
        assert_close(traj.point_at(u), want, "point_at")


def random_window(seed: int) -> tuple[Environment, WindowGrids]:
    rng = np.random.default_rng(seed)
    hm = Heightmap(rng.normal(size=(15, 15)) * 0.03, np.array([-2.0, -2.0]), 0.3)
    n = 12
    xy = rng.uniform(-1.2, 1.2, (n, 2))
    b = Boxes(np.column_stack([xy, np.zeros(n)]),
              np.column_stack([rng.uniform(0.05, 0.4, (n, 2)), rng.uniform(0.02, 0.4, n)]),
              rng.uniform(0, np.pi, n), rng.choice([ROLE_STEP_OVER, ROLE_AVOID], n), np.zeros(n, dtype=bool))
    env = Environment(hm, b)
    return env, env.window(np.zeros(2), PARAMS)


@given(st.integers(0, 100_000), st.sampled_from([None, 0.05, 0.15]))
def test_every_trajectory_avoids_forbidden_cells_and_clears_the_ground(
    seed: int, level: float | None
) -> None:
    env, w = random_window(seed)
    rng = np.random.default_rng(seed + 7)
    core, dilated = w.obstacle_map()
    for _ in range(4):
        s_xy = rng.uniform(-0.8, 0.8, 2)
        if (core | dilated)[tuple(w.cell_of(s_xy))]:
            continue
        start = np.array([s_xy[0], s_xy[1], env.height_at(s_xy[None, :])[0]])
        target = s_xy + rng.uniform(-0.5, 0.5, 2)
        lvl = None if level is None else start[2] + level
        traj = build_path(w, start, target, PathParams(step_height=0.08), level=lvl)
        if traj is None:
            continue
        _check_trajectory(w, traj, start, 0.08, lvl)
        assert np.allclose(traj.points[-1, :2], w.xy_of(*w.cell_of(target)))
        assert traj.length >= np.linalg.norm(traj.points[-1] - traj.points[0]) - 1e-9


def test_flat_ground_gives_a_clean_arc() -> None:
    w = Environment(flat()).window(np.zeros(2), PARAMS)
    traj = build_path(w, np.array([0.0, 0.0, 0.0]), np.array([0.35, 0.0]), PathParams(step_height=0.1))
    assert traj is not None
    pts = traj.points
    assert np.allclose(pts[:, 1], 0.0)  # straight in the ground plane
    assert np.all(np.diff(pts[:, 0]) > 0.0)
    top = int(np.argmax(pts[:, 2]))
    assert np.all(np.diff(pts[: top + 1, 2]) >= -1e-12)  # up ...
    assert np.all(np.diff(pts[top:, 2]) <= 1e-12)  # ... then down: one arc
    assert 0.1 <= pts[top, 2] <= 0.15
    assert pts[0, 2] == 0.0
    assert pts[-1, 2] == 0.0
    assert len(traj.waypoints_2d) == 2


def test_walled_in_target_gives_no_path() -> None:
    ring = [(0.5 + 0.25 * np.cos(a), 0.25 * np.sin(a), 0.12, 0.12, 0.3, ROLE_AVOID)
            for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
    w = Environment(flat(), crates(ring)).window(np.array([0.3, 0.0]), PARAMS)
    assert build_path(w, np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.0])) is None
    # The same ring is stepped over when it may be (a step-over role and no slice).
    low_ring = crates([(*r[:5], ROLE_STEP_OVER) for r in ring])
    w2 = Environment(flat(), low_ring).window(np.array([0.3, 0.0]), PARAMS)
    traj = build_path(w2, np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.0]))
    assert traj is not None
    assert traj.points[:, 2].max() >= 0.4 - 1e-9


def test_wavefront_from_the_foot_and_from_the_target_agree() -> None:
    rng = np.random.default_rng(9)
    free = rng.random((16, 16)) > 0.3
    free[0, 0] = True
    from_foot = wavefront(free, (0, 0))
    for cell in np.argwhere(np.isfinite(from_foot.dist))[:15]:
        from_target = wavefront(free, (int(cell[0]), int(cell[1])))
        assert from_target.dist[0, 0] == pytest.approx(from_foot.dist[tuple(cell)])


@given(st.integers(0, 100_000))
def test_height_profile_never_dips_below_the_hull(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s = np.sort(rng.uniform(0.0, 1.0, 30))
    z = rng.uniform(0.0, 0.5, 30)
    idx = upper_hull(s, z)
    fine = np.linspace(s[0], s[-1], 500)
    prof = height_profile(s[idx], z[idx], fine)
    chord = np.interp(fine, s[idx], z[idx])
    assert np.all(prof >= chord - 1e-12)
    assert np.allclose(height_profile(s[idx], z[idx], s[idx]), z[idx])


def test_running_swings_are_invalidated_when_an_obstacle_moves_into_them() -> None:
    boxes = Boxes(np.array([[0.3, 1.0, 0.0]]), np.array([[0.1, 0.1, 0.2]]), np.zeros(1),
                  np.array([ROLE_AVOID]), np.array([True]))
    env = Environment(flat(), boxes)
    w = env.window(np.zeros(2), PARAMS)
    start = np.array([0.0, 0.0, 0.0])
    traj = build_path(w, start, np.array([0.42, 0.0]))
    assert traj is not None
    assert trajectory_valid(w, traj)
    # The crate slides across the middle of the path: the swing must be re-planned ...
    env.move_boxes(np.array([0]), np.array([[0.21, 0.0, 0.0]]), np.zeros(1))
    moved = env.window(np.zeros(2), PARAMS)
    assert not trajectory_valid(moved, traj)
    # ... unless the foot is already past it.
    assert trajectory_valid(moved, traj, u_from=0.9)
    # A step-over crate onto the footprint, higher than the planned landing, also invalidates.
    env2 = Environment(flat(), Boxes(np.array([[0.42, 0.0, 0.0]]), np.array([[0.1, 0.1, 0.05]]), np.zeros(1),
                                     np.array([ROLE_STEP_OVER]), np.array([True])))
    assert not trajectory_valid(env2.window(np.zeros(2), PARAMS), traj)
    assert trajectory_valid(env2.window(np.zeros(2), PARAMS), traj, tolerance=0.06)


@given(st.integers(0, 100_000), st.booleans())
def test_one_segment_and_batched_line_of_sight_agree(seed: int, on_lattice: bool) -> None:
    rng = np.random.default_rng(seed)
    blocked = rng.random((12, 12)) < 0.15
    ends = rng.uniform(-1.0, 12.0, (8, 2))
    if on_lattice:  # exact half cells: segments through corners and along cell borders
        ends = np.round(ends * 2.0) / 2.0
    a = ends[0]
    batched = segments_clear(blocked, a, ends[1:])
    single = [segments_clear(blocked, a, e[None, :])[0] for e in ends[1:]]
    assert batched.tolist() == single


@given(st.integers(0, 100_000))
def test_many_wavefronts_at_once_equal_one_at_a_time(seed: int) -> None:
    rng = np.random.default_rng(seed)
    shapes = [(int(rng.integers(3, 15)), int(rng.integers(3, 15))) for _ in range(4)]
    hh = max(h for h, _ in shapes)
    ww = max(w for _, w in shapes)
    free = np.zeros((4, hh, ww), dtype=bool)
    sources = []
    for i, (h, w) in enumerate(shapes):
        free[i, :h, :w] = rng.random((h, w)) > 0.3
        sources.append((int(rng.integers(h)), int(rng.integers(w))))
    for i, got in enumerate(wavefront_each(free, sources, shapes)):
        h, w = shapes[i]
        alone = reference_pathing.wavefront(free[i, :h, :w], sources[i])
        # The same relaxation sweep for sweep: the same parents and reached cells; distances
        # (sums of 1 and √2) to a few ulps.
        assert np.array_equal(np.isinf(got.dist), np.isinf(alone.dist))
        assert_close(got.dist, alone.dist, "dist")
        assert np.array_equal(got.parent, alone.parent)
        assert got.iterations == alone.iterations
        assert got.source == alone.source


@given(st.integers(0, 100_000))
def test_line_of_sight_on_many_grids_equals_one_grid_at_a_time(seed: int) -> None:
    rng = np.random.default_rng(seed)
    blocked = rng.random((3, 12, 12)) < 0.12
    shape = np.array([[12, 12], [9, 12], [12, 7]])
    blocked[1, 9:] = True  # past a grid's own size: outside
    blocked[2, :, 7:] = True
    which = rng.integers(0, 3, 10)
    a = rng.uniform(-1.0, 12.0, (10, 2))
    b = rng.uniform(-1.0, 12.0, (10, 2))
    got = segments_clear_each(blocked, which, shape[which], a, b)
    for i in range(10):
        h, w = shape[which[i]]
        grid = blocked[which[i], :h, :w]
        assert got[i] == segments_clear(grid, a[i], b[i][None, :])[0]
        # the plain-Python walk of line_of_sight_reduce over the same samples
        assert got[i] == _segment_clear(grid, h, w, *a[i].tolist(), *b[i].tolist())


@given(st.integers(0, 100_000))
def test_search_rectangles_at_once_equal_one_at_a_time(seed: int) -> None:
    rng = np.random.default_rng(seed)
    frames, regions = [], []
    for _ in range(5):
        a, b = rng.uniform(-5.0, 45.0, 2), rng.uniform(-5.0, 45.0, 2)
        half, end, back = rng.uniform(1.0, 8.0), rng.uniform(0.0, 5.0), rng.uniform(0.0, 3.0)
        frame = region_frame((40, 40), a[0], a[1], b[0], b[1], half, end, back)
        one = search_region((40, 40), a, b, half, end, back)
        if frame is None:
            assert one.mask.size == 0
            continue
        frames.append(frame)
        regions.append(one)
    if not frames:
        return
    arr = np.array(frames)
    masks = region_masks(arr, int(arr[:, 2].max()), int(arr[:, 3].max()))
    for frame, one, mask in zip(frames, regions, masks, strict=True):
        assert (one.r0, one.c0) == frame[:2]
        assert np.array_equal(mask[: frame[2], : frame[3]], one.mask)
        assert not mask[frame[2] :].any()
        assert not mask[:, frame[3] :].any()


@given(st.integers(0, 100_000))
def test_lifting_many_plans_at_once_equals_lifting_each(seed: int) -> None:
    env, w = random_window(seed)
    rng = np.random.default_rng(seed + 3)
    core, dilated = w.obstacle_map()
    paths, ctxs, tz = [], [], []
    for _ in range(6):
        s_xy = rng.uniform(-0.8, 0.8, 2)
        if (core | dilated)[tuple(w.cell_of(s_xy))]:
            continue
        start = np.array([s_xy[0], s_xy[1], env.height_at(s_xy[None, :])[0]])
        t_rc = np.rint(w.rowcol(s_xy + rng.uniform(-0.5, 0.5, 2)))
        region = search_region(w.shape, w.rowcol(s_xy), t_rc, 0.4 / w.cell, 3.0)
        ctx = PathContext(w, start, region, None, w.foot_half_extents, 0.0, PathParams(step_height=0.08))
        cell = (int(t_rc[0]) - region.r0, int(t_rc[1]) - region.c0)
        if not (0 <= cell[0] < region.shape[0] and 0 <= cell[1] < region.shape[1]):
            continue
        path = ctx.path_2d(float(rng.choice([np.inf, start[2] + 0.1])), cell)
        if path is None or path.length <= 1e-9:
            continue
        paths.append(path)
        ctxs.append(ctx)
        tz.append(float(ctx.land_height(np.array([cell]))[0]))
    if not paths:
        return
    bounds = [0, *itertools.accumulate(p.samples.shape[0] for p in paths)]
    ground = np.concatenate([c._clear_at(p.samples) for c, p in zip(ctxs, paths, strict=True)])
    samples = np.concatenate([p.samples for p in paths])
    ramps = [min(c.ramp, 0.5 * p.length) for c, p in zip(ctxs, paths, strict=True)]
    arcs = np.concatenate([p.arc for p in paths])
    z0 = [float(c.start[2]) for c in ctxs]
    gaps = [c.params.min_waypoint_gap * w.cell for c in ctxs]
    got = lift_each(samples, arcs, bounds, ground, [p.length for p in paths], z0, tz,
                    [c.params.step_height for c in ctxs], ramps, gaps, [p.waypoints for p in paths])
    for c, p, z, traj in zip(ctxs, paths, tz, got, strict=True):
        alone = c.lift(p, z)
        for name in ("points", "waypoints", "waypoints_2d", "arc", "arc_2d", "length"):
            assert_close(getattr(traj, name), getattr(alone, name), name)
    # The turning of every plan too.
    want = [reference_pathing.turning(p.samples) for p in paths]
    assert_close(turning_each(samples, bounds), want, "turning")


@given(st.integers(0, 100_000))
def test_plain_python_hull_waypoints_equal_the_numpy_ones(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 60))
    s = np.sort(rng.uniform(0.0, 1.0, n))
    s = s[np.concatenate([[True], np.diff(s) > 0])]
    # Clearance-like profiles: flat runs and linear ramps (collinear points) plus bumps.
    steps = np.repeat(rng.uniform(0, 0.2, s.size // 3 + 1), 3)[: s.size]
    z = np.minimum(np.minimum(s, s[-1] - s) * 2.0, 0.1) + steps
    gap = float(rng.choice([0.0, 0.02, 0.1]))
    want = reference_pathing.hull_waypoints(s, z, gap).tolist()
    assert _hull_knots_increasing(s.tolist(), z.tolist(), gap) == want
    # the same points among others (many plans' samples one after the other)
    pad = int(rng.integers(0, 5))
    s_all = [-1.0] * pad + s.tolist() + [9.0, 10.0]
    z_all = [5.0] * pad + z.tolist() + [5.0, 5.0]
    assert _hull_knots_increasing(s_all, z_all, gap, pad, pad + s.size) == [pad + k for k in want]


@given(st.integers(0, 100_000))
def test_line_of_sight_reduction_keeps_the_farthest_point_in_sight_of_the_batched_test(seed: int) -> None:
    rng = np.random.default_rng(seed)
    free = rng.random((18, 18)) > 0.3
    free[0, 0] = free[17, 17] = True
    field = wavefront(free, (0, 0))
    if not np.isfinite(field.dist[17, 17]):
        return
    naive = descend(field, (17, 17))[::-1].astype(float)
    pts = np.vstack([rng.uniform(-0.4, 0.4, 2), naive[1:], naive[-1:] + rng.uniform(-0.4, 0.4, 2)])
    # Reference greedy: every later point tested at once with the vectorised supercover test.
    expected = [0]
    i = 0
    while i < len(pts) - 1:
        seen = np.nonzero(segments_clear(~free, pts[i], pts[i + 1 :]))[0]
        i = i + 1 + int(seen[-1]) if seen.size else i + 1
        expected.append(i)
    assert line_of_sight_reduce(~free, pts).tolist() == expected


@given(st.floats(0.0, 50.0), st.integers(2, 300))
def test_straight_plan_arc_lengths_are_numpys_linspace(stop: float, num: int) -> None:
    """A straight plan's samples are spaced as ``np.linspace(0, length, n)`` spaces them
    (``pathing._linspace`` writes out its arithmetic without its set-up)."""
    got = _linspace(stop, num)
    want = np.linspace(0.0, stop, num)
    assert_close(got, want, "linspace")
    assert got[0] == 0.0
    assert got[-1] == stop
    assert got.shape == want.shape
