# SPDX-License-Identifier: GPL-3.0-or-later
"""Environment, rasterisation and per-character window grids (thesis §3.4.1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from procloco_addon.core.world import terrain
from procloco_addon.core.world.terrain import (
    NO_SURFACE,
    ROLE_AVOID,
    ROLE_GROUND,
    ROLE_STEP_OVER,
    Boxes,
    Environment,
    Heightmap,
    TriangleSoup,
    WindowParams,
    dilate,
    dilate_each,
    foot_kernel,
    foot_kernels,
    raster_boxes,
    raster_triangles,
)
from tests.core.cross_path import assert_close

SMALL = WindowParams(n_cells=30, cell=0.07, foot_half_extents=(0.03, 0.03))


def flat(size: float = 6.0, z: float = 0.0) -> Heightmap:
    n = int(size / 0.5) + 1
    return Heightmap(np.full((n, n), z), np.array([-size / 2, -size / 2]), 0.5)


def boxes(rows: list[tuple[float, float, float, float, float, float, int, bool]]) -> Boxes:
    """(x, y, sx, sy, sz, yaw, role, dynamic) rows, standing on z = 0."""
    a = np.array([r[:6] for r in rows], dtype=float).reshape(-1, 6)
    return Boxes(np.column_stack([a[:, :2], np.zeros(len(rows))]), a[:, 2:5], a[:, 5],
                 np.array([r[6] for r in rows], dtype=int), np.array([r[7] for r in rows], dtype=bool))


def random_env(seed: int, n_boxes: int = 25, dynamic: bool = True) -> Environment:
    rng = np.random.default_rng(seed)
    hm = Heightmap(rng.normal(size=(21, 21)) * 0.05, np.array([-2.5, -2.5]), 0.25)
    xy = rng.uniform(-1.5, 1.5, (n_boxes, 2))
    b = Boxes(np.column_stack([xy, rng.uniform(-0.05, 0.05, n_boxes)]),
              np.column_stack([rng.uniform(0.05, 0.5, (n_boxes, 2)), rng.uniform(0.02, 0.4, n_boxes)]),
              rng.uniform(-np.pi, np.pi, n_boxes), rng.choice([ROLE_STEP_OVER, ROLE_AVOID], n_boxes),
              (rng.random(n_boxes) < 0.5) & dynamic)
    ramp_v = np.array([[0.2, -1.0, 0.1], [1.2, -1.0, 0.3], [0.2, -0.2, 0.5]])
    ramp = TriangleSoup(ramp_v, np.array([[0, 1, 2]]), ROLE_STEP_OVER)
    return Environment(hm, b, [ramp], tile_cells=16)


def test_heightmap_is_bilinear_and_ends_at_its_border() -> None:
    xs = np.arange(5) * 0.5
    gx, gy = np.meshgrid(xs, np.arange(4) * 0.5)
    hm = Heightmap(0.3 * gx - 0.2 * gy + 1.0, np.zeros(2), 0.5)
    rng = np.random.default_rng(0)
    p = rng.uniform([0, 0], [2.0, 1.5], (200, 2))
    assert np.allclose(hm.sample(p), 0.3 * p[:, 0] - 0.2 * p[:, 1] + 1.0)  # exact on a plane
    assert np.all(hm.sample(np.array([[-0.1, 0.5], [0.5, 1.6], [2.1, 0.0]])) == NO_SURFACE)
    with pytest.raises(ValueError, match="finite"):
        Heightmap(np.array([[0.0, np.nan], [0.0, 0.0]]), np.zeros(2), 0.5)


@given(st.integers(0, 10_000))
def test_window_elevation_is_the_highest_surface_in_each_cell(seed: int) -> None:
    env = random_env(seed)
    rng = np.random.default_rng(seed + 1)
    centre = rng.uniform(-0.8, 0.8, 2)
    w = env.window(centre, SMALL)
    # Points anywhere in the window: the cell holds at least their height (conservative).
    lo = w.origin - 0.5 * w.cell
    pts = rng.uniform(lo, lo + np.array(w.shape[::-1]) * w.cell, (3000, 2))
    assert np.all(env.height_at(pts) <= w.elevation_at(pts) + 1e-9)
    # Avoided boxes are forbidden cells; every point inside one lies in a forbidden cell.
    inside_avoid = env.forbidden_at(pts)
    rc = w.cell_of(pts[inside_avoid])
    assert np.all(w.avoid[rc[:, 0], rc[:, 1]])


def test_terrain_cells_hold_exactly_the_highest_point_of_the_bilinear_surface() -> None:
    rng = np.random.default_rng(2)
    for hm_cell in (0.25, 0.05):  # coarser and finer than the window cells
        hm = Heightmap(rng.normal(size=(41, 41)) * 0.05, np.array([-1.0, -1.0]), hm_cell)
        w = Environment(hm).window(np.array([0.1, 0.2]), WindowParams(n_cells=12))
        ny, nx = w.shape
        s = np.linspace(-0.5, 0.5, 41) * w.cell
        ox, oy = np.meshgrid(s, s)
        centres = w.xy_of(*np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij"))
        pts = centres[:, :, None, :] + np.column_stack([ox.ravel(), oy.ravel()])[None, None]
        dense_max = hm.sample(pts).max(axis=2)
        assert np.all(w.elevation >= dense_max - 1e-12)
        assert np.all(w.elevation - dense_max <= 0.05)  # samples 1/40 cell apart: close to exact
        assert np.mean(w.elevation - dense_max) < 2e-3


@given(st.integers(0, 10_000))
def test_cached_tiles_and_moving_rasters_equal_a_fresh_rasterisation(seed: int) -> None:
    env = random_env(seed)
    rng = np.random.default_rng(seed)
    dyn = np.nonzero(env.boxes.dynamic)[0]
    for step in range(3):
        centres = rng.uniform(-1.0, 1.0, (3, 2))
        for w in env.windows(centres, SMALL):
            elev, avoid = env.rasterise(w.origin, w.cell, w.shape)
            assert np.allclose(w.elevation, elev, rtol=0.0, atol=1e-12)
            assert np.array_equal(w.avoid, avoid)
        if dyn.size:
            b = env.boxes
            env.move_boxes(dyn, b.center[dyn] + np.array([0.1, -0.05, 0.0]) * (step + 1), b.yaw[dyn] + 0.3)


@given(st.integers(0, 10_000))
@settings(max_examples=15, deadline=None)
def test_moving_rasters_kept_over_many_moves_of_some_boxes_equal_a_fresh_rasterisation(seed: int) -> None:
    """Boxes moved a few at a time keep rasters made at different calls (several batches of
    the kept rasters, the oldest forgotten once no box reads them), read for windows of two
    cell sizes in one call."""
    env = random_env(seed, n_boxes=40)
    rng = np.random.default_rng(seed)
    dyn = np.nonzero(env.boxes.dynamic)[0]
    coarse = WindowParams(n_cells=24, cell=0.1, foot_half_extents=(0.03, 0.03))
    for step in range(8):
        centres = rng.uniform(-1.0, 1.0, (4, 2))
        for w in env.windows(centres, [SMALL, coarse, SMALL, coarse]):
            elev, avoid = env.rasterise(w.origin, w.cell, w.shape)
            assert np.allclose(w.elevation, elev, rtol=0.0, atol=1e-12)
            assert np.array_equal(w.avoid, avoid)
        some = dyn[rng.random(dyn.size) < 0.3]
        if some.size:
            b = env.boxes
            shift = np.array([0.07, -0.04, 0.0]) * (step + 1)
            env.move_boxes(some, b.center[some] + shift, b.yaw[some] + 0.2)


def test_static_tiles_are_rasterised_once_and_moving_boxes_only_when_they_moved() -> None:
    env = Environment(flat(), boxes([(0.3, 0.0, 0.2, 0.2, 0.1, 0.0, ROLE_STEP_OVER, False),
                                     (-0.3, 0.0, 0.2, 0.2, 0.2, 0.0, ROLE_AVOID, True),
                                     (2.5, 2.5, 0.2, 0.2, 0.2, 0.0, ROLE_AVOID, True)]), tile_cells=32)
    env.window(np.zeros(2), SMALL)
    tiles = env.stats["tiles_rasterised"]
    assert env.stats["moving_rasterised"] == 1  # the far moving box is not near this window
    env.window(np.array([0.05, 0.02]), SMALL)
    assert env.stats["tiles_rasterised"] == tiles
    assert env.stats["moving_rasterised"] == 1  # nothing moved: reused
    b = env.boxes
    env.move_boxes(np.array([1]), np.array([[-0.5, 0.2, 0.0]]), np.array([0.4]))
    w = env.window(np.zeros(2), SMALL)
    assert env.stats["moving_rasterised"] == 2
    assert env.stats["tiles_rasterised"] == tiles
    # The box left its old cells and occupies its new ones.
    assert not w.avoid[tuple(w.cell_of(np.array([-0.3, -0.08])))]
    assert w.avoid[tuple(w.cell_of(np.array([-0.5, 0.2])))]
    assert w.elevation[tuple(w.cell_of(np.array([-0.5, 0.2])))] == pytest.approx(0.2)
    with pytest.raises(ValueError, match="dynamic"):
        env.move_boxes(np.array([0]), b.center[:1], b.yaw[:1])


def test_a_window_over_meshes_fills_a_ring_of_blocks_beyond_it() -> None:
    """Static meshes are rasterised block by block: a window that needs new blocks takes the
    blocks around it too, so a window moved by a block needs none; its grids are what a fresh
    rasterisation gives (to its rounding)."""
    rng = np.random.default_rng(5)
    env = Environment(None, None, [_grid_mesh(rng, 12, -3.0, 3.0)])
    params = terrain.WindowParams(n_cells=24, cell=0.05)
    step = env.block_cells * params.cell
    env.window(np.zeros(2), params)
    tiles = env.stats["tiles_rasterised"]
    for dx, dy in ((step, 0.0), (-step, step), (0.0, -step)):
        w = env.window(np.array([dx, dy]), params)
        assert env.stats["tiles_rasterised"] == tiles
        elev, avoid = env.rasterise(w.origin, w.cell, w.shape)  # (its own grid: other roundings)
        assert_close(w.elevation, elev, "elevation")
        assert np.array_equal(w.avoid, avoid)
    env.window(np.array([3.0 * step, 0.0]), params)
    assert env.stats["tiles_rasterised"] > tiles


def test_box_cells_are_exactly_the_cells_the_rotated_box_overlaps() -> None:
    env = Environment(None, boxes([(0.1, -0.05, 0.5, 0.12, 0.3, 0.6, ROLE_AVOID, False)]))
    w = env.window(np.zeros(2), SMALL)
    # Dense samples of each cell; a cell overlaps the box iff one of its samples is inside.
    ny, nx = w.shape
    s = (np.arange(15) + 0.5) / 15 - 0.5
    ox, oy = np.meshgrid(s, s)
    offs = np.column_stack([ox.ravel(), oy.ravel()]) * w.cell
    centres = w.xy_of(*np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij"))
    pts = (centres[:, :, None, :] + offs[None, None, :, :]).reshape(-1, 2)
    hit = env.forbidden_at(pts).reshape(ny, nx, -1).any(axis=2)
    assert np.array_equal(w.avoid, hit)
    assert np.all(w.elevation[w.avoid] == pytest.approx(0.3))
    assert np.all(w.elevation[~w.avoid] == NO_SURFACE)  # no terrain at all: void
    assert np.array_equal(w.void, ~w.avoid)


def test_step_over_raises_the_elevation_but_is_not_forbidden() -> None:
    env = Environment(flat(), boxes([(0.0, 0.0, 0.3, 0.3, 0.15, 0.0, ROLE_STEP_OVER, False)]))
    w = env.window(np.zeros(2), SMALL)
    centre = tuple(w.cell_of(np.zeros(2)))
    assert w.elevation[centre] == pytest.approx(0.15)
    assert not w.avoid.any()
    assert not w.dilated.any()
    # A slice below the crate's top forbids it (walk around); one above does not.
    core_low, dil_low = w.obstacle_map(level=0.1)
    core_high, _ = w.obstacle_map(level=0.2)
    assert core_low[centre]
    assert not core_high.any()
    assert dil_low.any()
    assert not (dil_low & core_low).any()


def test_dilation_is_kept_apart_and_follows_the_foot_shape() -> None:
    env = Environment(flat(), boxes([(0.0, 0.0, 0.05, 0.05, 0.3, 0.0, ROLE_AVOID, False)]))
    w = env.window(np.zeros(2), SMALL)
    assert np.count_nonzero(w.forbidden) == 1
    assert np.count_nonzero(w.dilated) == 8  # a small foot anywhere in its cell: one ring
    assert not (w.forbidden & w.dilated).any()
    # A long foot along x, then turned 90°: the dilation turns with it.
    _, along_x = w.obstacle_map(foot_half_extents=(0.12, 0.02), foot_yaw=0.0)
    _, along_y = w.obstacle_map(foot_half_extents=(0.12, 0.02), foot_yaw=np.pi / 2)
    rows_x, cols_x = np.nonzero(along_x)
    rows_y, cols_y = np.nonzero(along_y)
    assert np.ptp(cols_x) > np.ptp(rows_x)
    assert np.ptp(rows_y) > np.ptp(cols_y)
    assert np.array_equal(along_x, along_y.T)  # square window centred on the box
    # Other feet as extra forbidden cells.
    extra = np.zeros(w.shape, dtype=bool)
    extra[3, 4] = True
    core, dil = w.obstacle_map(extra=extra)
    assert core[3, 4]
    assert dil[3, 5]


def test_foot_kernel_covers_the_foot_anywhere_in_its_cell() -> None:
    cell = 0.07
    for half, yaw in (((0.03, 0.03), 0.0), ((0.1, 0.02), 0.7), ((0.0, 0.0), 0.0)):
        k = foot_kernel(cell, half, yaw)
        ks = {tuple(v) for v in k.tolist()}
        rng = np.random.default_rng(3)
        c, s = np.cos(yaw), np.sin(yaw)
        for _ in range(300):
            centre = rng.uniform(-0.5, 0.5, 2) * cell  # anywhere in cell (0, 0)
            u, v = rng.uniform(-1, 1, 2) * np.asarray(half)
            p = centre + np.array([c * u - s * v, s * u + c * v])
            cell_rc = (int(np.rint(p[1] / cell)), int(np.rint(p[0] / cell)))
            assert cell_rc in ks
    # Dilation equals the union of shifted copies.
    mask = np.zeros((9, 9), dtype=bool)
    mask[4, 4] = True
    grown = dilate(mask, foot_kernel(cell, (0.1, 0.02), 0.0))
    assert grown[4, 2]
    assert grown[4, 6]
    assert not grown[2, 4]


def test_triangle_soups_ground_gaps_and_moving_meshes() -> None:
    # A sloped ground quad over x in [-1, 0], nothing over x > 0 (a gap).
    v = np.array([[-1.0, -1.0, 0.0], [0.0, -1.0, 0.2], [0.0, 1.0, 0.2], [-1.0, 1.0, 0.0]])
    ground = TriangleSoup(v, np.array([[0, 1, 2], [0, 2, 3]]), ROLE_GROUND)
    lid_v = np.array([[-0.6, -0.1, 0.5], [-0.4, -0.1, 0.5], [-0.5, 0.1, 0.5]])
    lid = TriangleSoup(lid_v, np.array([[0, 1, 2]]), ROLE_AVOID, dynamic=True)
    env = Environment(None, None, [ground, lid])
    w = env.window(np.array([-0.3, 0.0]), SMALL)
    rng = np.random.default_rng(5)
    pts = rng.uniform([-0.95, -0.9], [-0.05, 0.9], (2000, 2))
    h = env.height_at(pts)
    e = w.elevation_at(pts)
    assert np.all(h <= e + 1e-9)
    rc = w.cell_of(pts)
    ground_only = ~w.avoid[rc[:, 0], rc[:, 1]]
    assert np.all((e - h)[ground_only] <= 0.2 * w.cell + 1e-9)  # slope 0.2 across at most a cell
    gap = w.elevation_at(np.array([[0.3, 0.0]]))[0]
    assert gap == NO_SURFACE
    assert w.avoid[tuple(w.cell_of(np.array([-0.5, 0.0])))]
    # Moving the lid moves its forbidden cells.
    env.set_soup_vertices(1, lid.vertices + np.array([0.0, 0.5, 0.0]))
    w2 = env.window(np.array([-0.3, 0.0]), SMALL)
    assert not w2.avoid[tuple(w2.cell_of(np.array([-0.5, 0.0])))]
    assert w2.avoid[tuple(w2.cell_of(np.array([-0.5, 0.5])))]
    assert env.forbidden_at(np.array([[-0.5, 0.5], [-0.5, 0.0]])).tolist() == [True, False]
    with pytest.raises(ValueError, match="dynamic"):
        env.set_soup_vertices(0, v)


def test_a_crowd_of_windows_over_meshes_fills_no_ring_of_blocks() -> None:
    """In a call of more windows than ``_FILL_AHEAD_WINDOWS`` (a crowd's), each window takes
    only the blocks it covers: moved by a block, it needs new ones; its grids are the same
    as the ring's fills give, bit for bit."""
    rng = np.random.default_rng(5)
    mesh = _grid_mesh(rng, 12, -3.0, 3.0)
    params = terrain.WindowParams(n_cells=24, cell=0.05)
    m = terrain._FILL_AHEAD_WINDOWS + 1
    centres = np.column_stack([np.linspace(-1.5, 1.5, m), np.zeros(m)])
    crowd, ringed = Environment(None, None, [mesh]), Environment(None, None, [mesh])
    step = crowd.block_cells * params.cell
    crowd.windows(centres, params)
    for c in centres:
        ringed.window(c, params)
    tiles = crowd.stats["tiles_rasterised"]
    moved = centres + np.array([0.0, step])
    wanted = [ringed.window(c, params) for c in moved]
    for got, want in zip(crowd.windows(moved, params), wanted, strict=True):
        assert np.array_equal(got.elevation, want.elevation)
        assert np.array_equal(got.avoid, want.avoid)
    assert crowd.stats["tiles_rasterised"] > tiles


def test_windows_batch_equals_single_windows_and_snaps_to_the_lattice() -> None:
    env = random_env(11)
    centres = np.array([[0.0, 0.0], [0.33, -0.41], [1.2, 0.9]])
    batch = env.windows(centres, SMALL)
    for c, w in zip(centres, batch, strict=True):
        single = env.window(c, SMALL)
        assert_close(w.elevation, single.elevation, "elevation")
        assert np.array_equal(single.avoid, w.avoid)
        mid = w.xy_of(np.array(SMALL.n_cells // 2), np.array(SMALL.n_cells // 2))
        assert np.all(np.abs(mid - c) <= 0.5 * SMALL.cell + 1e-12)
        assert np.allclose(np.round(w.origin / SMALL.cell) * SMALL.cell, w.origin)


def test_bad_inputs_are_refused() -> None:
    with pytest.raises(ValueError, match="role"):
        Boxes(np.zeros((1, 3)), np.ones((1, 3)), np.zeros(1), np.array([7]), np.zeros(1, dtype=bool))
    with pytest.raises(ValueError, match="range"):
        TriangleSoup(np.zeros((3, 3)), np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match="n_cells"):
        WindowParams(n_cells=2)


@given(st.integers(0, 100_000))
def test_foot_kernels_of_many_feet_equal_one_at_a_time(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 6
    cell = rng.choice([0.05, 0.07, 0.1], n)
    hx, hy = rng.uniform(0.0, 0.15, n), rng.uniform(0.0, 0.08, n)
    yaw = rng.uniform(-np.pi, np.pi, n)
    for anywhere in (True, False):
        offsets, member = foot_kernels(cell, hx, hy, yaw, anywhere)
        for i in range(n):
            one = foot_kernel(float(cell[i]), (float(hx[i]), float(hy[i])), float(yaw[i]), anywhere)
            assert {tuple(c) for c in offsets[member[i]].tolist()} == {tuple(c) for c in one.tolist()}


@given(st.integers(0, 100_000))
def test_dilating_many_masks_each_with_its_kernel_equals_one_at_a_time(seed: int) -> None:
    rng = np.random.default_rng(seed)
    masks = rng.random((5, 9, 11)) < 0.1
    offsets, member = foot_kernels(np.full(5, 0.07), np.array([0.03, 0.03, 0.1, 0.0, 0.06]), np.full(5, 0.03),
                                   rng.uniform(-np.pi, np.pi, 5), True)
    got = dilate_each(masks, offsets, member)
    for i in range(5):
        assert np.array_equal(got[i], dilate(masks[i], offsets[member[i]]))
    # One kernel for a stack: each mask dilated alone.
    stacked = dilate(masks, foot_kernel(0.07, (0.1, 0.02), 0.4))
    one = foot_kernel(0.07, (0.1, 0.02), 0.4)
    assert all(np.array_equal(stacked[i], dilate(masks[i], one)) for i in range(5))


@given(st.integers(0, 100_000))
def test_dilation_equals_the_union_of_shifted_copies(seed: int) -> None:
    """The flat, bordered shifts of ``dilate`` against the definition: a cell is set when
    any cell it is reached from by a kernel offset is set (offsets past the grid included)."""
    rng = np.random.default_rng(seed)
    masks = rng.random((3, int(rng.integers(1, 9)), int(rng.integers(1, 9)))) < 0.15
    h, w = masks.shape[1:]
    rect = rng.random() < 0.5
    if rect:  # a full rectangle: the row-then-column passes
        a, b = (int(v) for v in rng.integers(0, 4, 2))
        ii, jj = np.meshgrid(np.arange(-a, a + 1), np.arange(-b, b + 1), indexing="ij")
        offsets = np.stack([ii.ravel(), jj.ravel()], axis=1)
    else:
        offsets = rng.integers(-10, 11, (int(rng.integers(1, 12)), 2))
    want = masks.copy()
    for di, dj in offsets.tolist():
        for r in range(h):
            for c in range(w):
                if 0 <= r - di < h and 0 <= c - dj < w:
                    want[:, r, c] |= masks[:, r - di, c - dj]
    assert np.array_equal(dilate(masks, offsets.astype(np.intp)), want)


def test_boxes_rasterised_each_on_its_own_grid_equal_one_grid_at_a_time() -> None:
    rng = np.random.default_rng(4)
    n = 12
    origin = rng.uniform(-1.0, 1.0, (n, 2))
    cell = rng.choice([0.05, 0.07], n)
    ny, nx = rng.integers(10, 30, n), rng.integers(10, 30, n)
    centre = origin + rng.uniform(-0.2, 1.2, (n, 2))
    hx, hy, yaw = rng.uniform(0.02, 0.3, n), rng.uniform(0.02, 0.3, n), rng.uniform(-np.pi, np.pi, n)
    box, row, col = raster_boxes(origin, cell, (ny, nx), centre, hx, hy, yaw)
    assert box.size
    for i in range(n):
        one = slice(i, i + 1)
        grid = (int(ny[i]), int(nx[i]))
        _, r, c = raster_boxes(origin[i], float(cell[i]), grid, centre[one], hx[one], hy[one], yaw[one])
        assert sorted(zip(row[box == i].tolist(), col[box == i].tolist(), strict=True)) == sorted(
            zip(r.tolist(), c.tolist(), strict=True))


def test_windows_with_their_own_params_equal_one_call_per_params() -> None:
    env = random_env(5)
    centres = np.array([[0.0, 0.0], [0.4, -0.3], [-0.9, 0.6], [1.1, 1.0]])
    params = [SMALL, WindowParams(n_cells=30, cell=0.07, foot_half_extents=(0.05, 0.02), foot_yaw=0.7),
              WindowParams(n_cells=24, cell=0.05), SMALL]
    batch = env.windows(centres, params)
    for c, prm, w in zip(centres, params, batch, strict=True):
        single = Environment(env.heightmap, env.boxes, env.soups, tile_cells=16).window(c, prm)
        assert_close(w.elevation, single.elevation, "elevation")
        assert np.array_equal(single.avoid, w.avoid)
        assert_close(w.origin, single.origin, "origin")
        assert (w.foot_half_extents, w.foot_yaw) == (prm.foot_half_extents, prm.foot_yaw)
    with pytest.raises(ValueError, match="one WindowParams per centre"):
        env.windows(centres, params[:2])


def test_point_queries_see_boxes_that_moved_even_for_the_same_points() -> None:
    env = Environment(flat(), boxes([(2.0, 2.0, 0.2, 0.2, 0.3, 0.0, ROLE_AVOID, True)]))
    xy = np.array([[0.0, 0.0], [0.5, 0.5]])
    assert env.height_at(xy).tolist() == [0.0, 0.0]
    assert env.forbidden_at(xy).tolist() == [False, False]
    env.move_boxes(np.array([0]), np.array([[0.5, 0.5, 0.0]]), np.array([0.3]))
    assert env.height_at(xy).tolist() == [0.0, pytest.approx(0.3)]  # the same array, asked again
    assert env.forbidden_at(xy).tolist() == [False, True]
    xy[0] = [0.55, 0.45]  # the same array object, other points
    assert env.forbidden_at(xy).tolist() == [True, True]


@given(st.lists(st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(-0.2, 0.2)),
                min_size=1, max_size=4))
def test_move_soup_is_the_same_as_setting_the_shifted_vertices(
    offsets: list[tuple[float, float, float]],
) -> None:
    rng = np.random.default_rng(3)
    n = 9
    xs = np.linspace(-0.5, 0.5, n)
    gx, gy = np.meshgrid(xs, xs)
    verts = np.column_stack([gx.ravel(), gy.ravel(), 0.05 * rng.random(n * n)])
    cells = [(i, j) for i in range(n - 1) for j in range(n - 1)]
    faces = np.array([(i * n + j, i * n + j + 1, (i + 1) * n + j + 1) for i, j in cells]
                     + [(i * n + j, (i + 1) * n + j + 1, (i + 1) * n + j) for i, j in cells])
    moved = Environment(soups=[TriangleSoup(verts, faces, ROLE_STEP_OVER, True)])
    reset = Environment(soups=[TriangleSoup(verts, faces, ROLE_STEP_OVER, True)])
    probes = rng.uniform(-0.8, 0.8, (200, 2))
    for off in [*offsets, (*offsets[0][:2], 0.1)]:  # the last one only lifts
        moved.move_soup(0, off)
        reset.set_soup_vertices(0, verts + np.array(off))
        assert np.allclose(moved.height_at(probes), reset.height_at(probes), atol=1e-12)
        for a, b in zip(moved.windows(probes[:3], SMALL), reset.windows(probes[:3], SMALL), strict=True):
            assert np.allclose(a.elevation, b.elevation, atol=1e-12)
            assert np.array_equal(a.forbidden, b.forbidden)
        assert np.allclose(moved.soups[0].vertices, verts + np.array(off))


def _raster_triangles_per_pair(
    origin: np.ndarray, cell: float, shape: tuple[int, int], tris: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The separating-axis cell test written per (triangle, cell) pair, one pair at a time:
    the reference for ``raster_triangles``' batched edges. Returns the (tri, row, col) hits."""
    hits = []
    for t, tri in enumerate(tris):
        fx = (tri[:, 0] - origin[0]) / cell
        fy = (tri[:, 1] - origin[1]) / cell
        rows = range(max(0, int(np.ceil(fy.min() - 0.5))),
                     min(shape[0] - 1, int(np.floor(fy.max() + 0.5))) + 1)
        cols = range(max(0, int(np.ceil(fx.min() - 0.5))),
                     min(shape[1] - 1, int(np.floor(fx.max() + 0.5))) + 1)
        for row in rows:
            for col in cols:
                ok = True
                for a in range(3):
                    b = (a + 1) % 3
                    nxa, nya = -(fy[b] - fy[a]), fx[b] - fx[a]
                    proj = fx * nxa + fy * nya
                    centre = col * nxa + row * nya
                    reach = 0.5 * (abs(nxa) + abs(nya))
                    ok &= bool(proj.max() >= centre - reach - 1e-12)
                    ok &= bool(proj.min() <= centre + reach + 1e-12)
                if ok:
                    hits.append((t, row, col))
    arr = np.array(sorted(hits), dtype=np.intp).reshape(-1, 3)
    return arr[:, 0], arr[:, 1], arr[:, 2]


@given(st.integers(0, 2**32 - 1))
def test_raster_triangles_finds_the_cells_of_the_per_pair_test(seed: int) -> None:
    rng = np.random.default_rng(seed)
    tris = rng.uniform([-0.3, -0.3, 0.0], [0.6, 0.6, 0.4], (6, 3, 3))
    tris[0, :, :2] = tris[0, 0, :2] + rng.uniform(-0.02, 0.02, (3, 2))  # smaller than a cell
    origin, cell, shape = np.array([0.0, 0.0]), 0.07, (9, 8)
    tri, row, col, z = raster_triangles(origin, cell, shape, tris)
    want = _raster_triangles_per_pair(origin, cell, shape, tris)
    order = np.lexsort((col, row, tri))
    for got, ref, name in zip((tri, row, col), want, ("tri", "row", "col"), strict=True):
        assert got[order].tolist() == ref.tolist(), name
    # never below the triangle's plane inside the cell, never above its top vertex
    assert np.all(z <= tris[tri, :, 2].max(axis=1) + 1e-12)


def _height_brute_force(soups: list[TriangleSoup], xy: np.ndarray) -> np.ndarray:
    """Highest triangle over each point, triangle by triangle (barycentric test)."""
    out = np.full(xy.shape[0], NO_SURFACE)
    for soup in soups:
        for f in soup.faces:
            a, b, c = soup.vertices[f]
            e1, e2 = b[:2] - a[:2], c[:2] - a[:2]
            den = e1[0] * e2[1] - e1[1] * e2[0]
            if abs(den) <= 1e-15:
                continue
            p = xy - a[:2]
            u = (p[:, 0] * e2[1] - p[:, 1] * e2[0]) / den
            v = (e1[0] * p[:, 1] - e1[1] * p[:, 0]) / den
            inside = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1.0 + 1e-9)
            z = a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2])
            out = np.where(inside, np.maximum(out, z), out)
    return out


def test_point_queries_over_many_static_soups_and_a_moving_one_equal_triangle_by_triangle() -> None:
    rng = np.random.default_rng(3)
    # a ground of 2 x 2 m in small triangles, five crates (one avoided) and a moving lid
    n = 9
    xs = np.linspace(-1.0, 1.0, n)
    gx, gy = np.meshgrid(xs, xs)
    verts = np.column_stack([gx.ravel(), gy.ravel(), 0.05 * np.sin(3.0 * gx.ravel())])
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1) for i in range(n - 1) for j in range(n - 1)]
    faces += [(i * n + j, (i + 1) * n + j + 1, (i + 1) * n + j) for i in range(n - 1) for j in range(n - 1)]
    soups = [TriangleSoup(verts, np.array(faces), ROLE_GROUND)]
    for k in range(5):
        c = rng.uniform(-0.7, 0.7, 2)
        top = rng.uniform(0.1, 0.3)
        quad = np.array([[c[0] - 0.1, c[1] - 0.1, top], [c[0] + 0.1, c[1] - 0.1, top],
                         [c[0] + 0.1, c[1] + 0.1, top], [c[0] - 0.1, c[1] + 0.1, top]])
        role = ROLE_AVOID if k == 0 else ROLE_STEP_OVER
        soups.append(TriangleSoup(quad, np.array([[0, 1, 2], [0, 2, 3]]), role))
    lid = np.array([[0.2, 0.2, 0.5], [0.5, 0.2, 0.5], [0.35, 0.5, 0.5]])
    soups.append(TriangleSoup(lid, np.array([[0, 1, 2]]), ROLE_AVOID, dynamic=True))
    env = Environment(None, None, soups)
    pts = rng.uniform(-1.2, 1.2, (3000, 2))
    assert_close(env.height_at(pts), _height_brute_force(soups, pts), "height")
    forbidden = env.forbidden_at(pts)
    want = ((_height_brute_force([soups[1]], pts) > NO_SURFACE)
            | (_height_brute_force([soups[-1]], pts) > NO_SURFACE))
    assert forbidden.tolist() == want.tolist()
    # the moving lid: its new place counts, its old one no longer
    env.move_soup(len(soups) - 1, np.array([-0.6, -0.6, 0.0]))
    lid_now = TriangleSoup(lid + np.array([-0.6, -0.6, 0.0]), np.array([[0, 1, 2]]), ROLE_AVOID, True)
    moved = [*soups[:-1], lid_now]
    assert_close(env.height_at(pts), _height_brute_force(moved, pts), "height after the move")


@given(st.integers(0, 2**32 - 1))
def test_one_point_queries_over_static_meshes_equal_the_many_point_query(seed: int) -> None:
    """A query of one point over static meshes only (the shell's scenes) takes its own plain
    Python path: each point's height equals that point's height in a query of all of them
    (ground, crates, points outside the meshes, on triangle edges and corners, NaN)."""
    rng = np.random.default_rng(seed)
    soups = [_grid_mesh(rng, int(rng.integers(2, 12)), -1.0, 1.0)]
    for _ in range(int(rng.integers(0, 4))):
        c = rng.uniform(-0.8, 0.8, 2)
        top = float(rng.uniform(0.05, 0.3))
        quad = np.array([[c[0] - 0.1, c[1] - 0.1, top], [c[0] + 0.1, c[1] - 0.1, top],
                         [c[0] + 0.1, c[1] + 0.1, top], [c[0] - 0.1, c[1] + 0.1, top + 0.05]])
        soups.append(TriangleSoup(quad, np.array([[0, 1, 2], [0, 2, 3]]), ROLE_STEP_OVER))
    env = Environment(None, None, soups)
    corners = np.concatenate([s.vertices[:, :2] for s in soups])
    edges = 0.5 * (soups[0].vertices[soups[0].faces[:, 0], :2] + soups[0].vertices[soups[0].faces[:, 1], :2])
    pts = np.concatenate([rng.uniform(-1.3, 1.3, (60, 2)), corners[:40], edges[:40],
                          [[np.nan, 0.0], [0.0, np.inf], [1e9, -1e9]]])
    many = env.height_at(pts)
    one = np.array([env.height_at(q)[0] for q in pts])
    assert_close(one, many, "one point at a time")
    assert ((one > NO_SURFACE) == (many > NO_SURFACE)).all()


@given(st.integers(0, 10_000))
def test_point_queries_over_rotated_boxes_equal_a_box_by_box_test(seed: int) -> None:
    """height_at / forbidden_at over static and moving rotated crates (and the heightmap
    between its samples and at its border) equal testing every box on its own."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 25))
    rows = [(float(rng.uniform(-2.5, 2.5)), float(rng.uniform(-2.5, 2.5)), float(rng.uniform(0.1, 0.8)),
             float(rng.uniform(0.1, 0.8)), float(rng.uniform(0.05, 0.5)), float(rng.uniform(-np.pi, np.pi)),
             int(rng.choice([ROLE_AVOID, ROLE_STEP_OVER, ROLE_GROUND])), bool(rng.random() < 0.4))
            for _ in range(n)]
    hm = Heightmap(rng.uniform(-0.1, 0.1, (13, 13)), np.array([-3.0, -3.0]), 0.5)
    env = Environment(hm, boxes(rows))
    b = boxes(rows)
    xy = rng.uniform(-3.5, 3.5, (int(rng.integers(1, 300)), 2))
    rel = xy[:, None, :] - b.center[None, :, :2]
    cos, sin = np.cos(b.yaw), np.sin(b.yaw)
    u = rel[..., 0] * cos + rel[..., 1] * sin
    v = -rel[..., 0] * sin + rel[..., 1] * cos
    inside = (np.abs(u) <= 0.5 * b.size[:, 0]) & (np.abs(v) <= 0.5 * b.size[:, 1])
    top = np.where(inside, (b.center[:, 2] + b.size[:, 2])[None, :], NO_SURFACE).max(axis=1)
    assert_close(env.height_at(xy), np.maximum(hm.sample(xy), top), "height over the boxes")
    avoided = (inside & (b.role == ROLE_AVOID)[None, :]).any(axis=1)
    assert env.forbidden_at(xy).tolist() == avoided.tolist()
    # the heightmap itself: bilinear inside, nothing outside, its corners its samples
    lo, hi = hm.extent
    corners = np.array([[lo[0], lo[1]], [hi[0], hi[1]], [hi[0] + 0.01, lo[1]]])
    got = hm.sample(corners)
    assert got[0] == hm.heights[0, 0]
    assert got[1] == hm.heights[-1, -1]
    assert got[2] == NO_SURFACE


def _grid_mesh(rng: np.random.Generator, n: int, lo: float, hi: float) -> TriangleSoup:
    """A heightmap-like mesh: an n x n lattice of bumpy vertices in quads cut in two."""
    xs = np.linspace(lo, hi, n) + rng.uniform(-0.01, 0.01)
    gx, gy = np.meshgrid(xs, xs + rng.uniform(-0.3, 0.3))
    gz = 0.03 * np.sin(3.0 * gx) * np.cos(2.0 * gy) + rng.normal(0.0, 0.005, gx.shape)
    a = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    faces = np.concatenate([np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])])
    return TriangleSoup(np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()]), faces, ROLE_GROUND)


@given(st.integers(0, 2**32 - 1))
def test_static_window_grids_are_cut_from_whole_tiles_rasterised_bit_for_bit(seed: int) -> None:
    # The static grids are filled block by block, in batches of rectangles of many tiles and
    # cell sizes; every cell must hold exactly what a rasterisation of its whole tile holds
    # (the tile's origin and arithmetic: what the planner saw when tiles were made whole).
    rng = np.random.default_rng(seed)
    tile = int(rng.choice([16, 20, 48, 128]))
    hm = Heightmap(rng.normal(size=(31, 31)) * 0.05, np.array([-3.1, -2.7]), 0.23) if seed % 3 else None
    nb = int(rng.integers(0, 20))
    xy = rng.uniform(-2.5, 2.5, (nb, 2))
    crates = Boxes(np.column_stack([xy, rng.uniform(-0.05, 0.05, nb)]),
                   np.column_stack([rng.uniform(0.05, 0.5, (nb, 2)), rng.uniform(0.02, 0.4, nb)]),
                   rng.uniform(-np.pi, np.pi, nb), rng.choice([ROLE_STEP_OVER, ROLE_AVOID], nb),
                   np.zeros(nb, dtype=bool))
    lid = rng.uniform(-1.0, 1.0, (8, 3)) * [0.3, 0.3, 0.2] + [*rng.uniform(-1.0, 1.0, 2), 0.2]
    soups = [_grid_mesh(rng, 30, -3.0, 3.0), TriangleSoup(lid, rng.integers(0, 8, (12, 3)), ROLE_AVOID),
             TriangleSoup(np.array([[-5.0, -5.0, 0.1], [5.0, -5.0, 0.0], [0.0, 5.0, 0.4]]),
                          np.array([[0, 1, 2]]), ROLE_STEP_OVER)]
    env = Environment(hm, crates, soups, tile_cells=tile)
    whole: dict[tuple[float, int, int], tuple[np.ndarray, np.ndarray]] = {}
    for _ in range(3):
        m = int(rng.integers(1, 13))  # (more than _FILL_AHEAD_WINDOWS: no ring of blocks)
        params = [WindowParams(n_cells=int(rng.integers(3, 60)), cell=float(rng.choice([0.03, 0.05, 0.071])))
                  for _ in range(m)]
        for w, prm in zip(env.windows(rng.uniform(-2.5, 2.5, (m, 2)), params), params, strict=True):
            n, cell = prm.n_cells, prm.cell
            i0, j0 = (np.rint(w.origin[::-1] / cell)).astype(int)
            for r in range(n):
                for c in (0, n - 1, int(rng.integers(0, n))):
                    ti, tj = (i0 + r) // tile, (j0 + c) // tile
                    if (cell, ti, tj) not in whole:
                        whole[(cell, ti, tj)] = env.rasterise(np.array([tj * tile * cell, ti * tile * cell]),
                                                              cell, (tile, tile))
                    elev, avoid = whole[(cell, ti, tj)]
                    ri, ci = i0 + r - ti * tile, j0 + c - tj * tile
                    assert w.elevation[r, c] == elev[ri, ci]
                    assert w.avoid[r, c] == avoid[ri, ci]


def test_triangles_rasterised_each_on_its_own_grid_part_equal_one_whole_grid_at_a_time(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # Per-triangle grids, parts of grids (first, shape) and batches cut in pieces give the
    # cells and heights of one whole grid at a time, bit for bit.
    monkeypatch.setattr(terrain, "_RASTER_CHUNK", 7)
    rng = np.random.default_rng(6)
    tris = _grid_mesh(rng, 6, -0.4, 0.4)
    tris = tris.vertices[tris.faces]
    k = tris.shape[0]
    origin = rng.uniform(-0.5, -0.3, (k, 2))
    cell = rng.choice([0.05, 0.07], k)
    first = (rng.integers(0, 6, k), rng.integers(0, 6, k))
    shape = (first[0] + rng.integers(3, 12, k), first[1] + rng.integers(3, 12, k))
    tri, row, col, z = raster_triangles(origin, cell, shape, tris, first)
    assert tri.size
    for i in range(k):
        _, r, c, z1 = raster_triangles(origin[i], float(cell[i]), (int(shape[0][i]), int(shape[1][i])),
                                       tris[i : i + 1])
        keep = (r >= first[0][i]) & (c >= first[1][i])
        mine = tri == i
        assert sorted(zip(row[mine].tolist(), col[mine].tolist(), z[mine].tolist(), strict=True)) == sorted(
            zip(r[keep].tolist(), c[keep].tolist(), z1[keep].tolist(), strict=True))


@given(st.integers(0, 2**32 - 1))
def test_rectangle_index_finds_every_item_whose_bounds_overlap(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    lo = rng.uniform(-3.0, 3.0, (n, 2))
    hi = lo + rng.exponential(0.1, (n, 2)) * (1.0 + 20.0 * (rng.random((n, 1)) < 0.05))  # a few wide ones
    qlo = rng.uniform(-4.0, 4.0, (40, 2))
    qhi = qlo + rng.uniform(0.0, 1.5, (40, 2))
    qlo[0], qhi[0] = lo[0], lo[0]  # touching counts
    query, item = terrain._RectIndex(lo, hi).pairs(qlo, qhi)
    want = np.nonzero(np.all((hi[None] >= qlo[:, None]) & (lo[None] <= qhi[:, None]), axis=2))
    assert sorted(zip(query.tolist(), item.tolist(), strict=True)) == sorted(
        zip(want[0].tolist(), want[1].tolist(), strict=True))
