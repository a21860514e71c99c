# SPDX-License-Identifier: GPL-3.0-or-later
"""The watch on moving obstacles (``core.locomotion.obstacles``): a look that skips the rings
no moving thing comes near answers exactly what asking every ring would."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from procloco_addon.core.locomotion.obstacles import Watch, look, swing_planned, watch_reset
from procloco_addon.core.world.terrain import Boxes, Environment
from tests.core.test_terrain import random_env


def _static_twin(env: Environment) -> Environment:
    """The same scene without its moving boxes (the static part alone)."""
    b = env.boxes
    keep = ~b.dynamic
    static = Boxes(b.center[keep], b.size[keep], b.yaw[keep], b.role[keep], b.dynamic[keep])
    return Environment(env.heightmap, static, list(env.soups), tile_cells=16)


@given(st.integers(0, 10_000))
@settings(max_examples=30, deadline=None)
def test_moving_near_finds_every_moving_box_over_a_rectangle(seed: int) -> None:
    env = random_env(seed, n_boxes=40)
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-6.0, 6.0, (60, 2))
    hi = lo + rng.uniform(0.0, 0.6, (60, 2))
    got = env.moving_near(lo, hi)
    b = env.boxes
    corners = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    want = np.zeros(60, dtype=bool)
    for i in np.flatnonzero(b.dynamic):
        c, s = np.cos(b.yaw[i]), np.sin(b.yaw[i])
        pts = corners * b.size[i, :2] @ np.array([[c, s], [-s, c]]) + b.center[i, :2]
        want |= np.all((pts.max(axis=0) >= lo) & (pts.min(axis=0) <= hi), axis=1)
    assert np.all(got[want])  # every rectangle a moving box reaches
    assert not np.all(got)
    # and no other (up to the nanometre it may add to the boxes' bounds)
    bigger = np.zeros(60, dtype=bool)
    for i in np.flatnonzero(b.dynamic):
        c, s = np.cos(b.yaw[i]), np.sin(b.yaw[i])
        pts = corners * b.size[i, :2] @ np.array([[c, s], [-s, c]]) + b.center[i, :2]
        bigger |= np.all((pts.max(axis=0) + 1e-6 >= lo) & (pts.min(axis=0) - 1e-6 <= hi), axis=1)
    assert not np.any(got & ~bigger)
    # Where nothing moving reaches a rectangle, its points answer what the static scene does.
    twin = _static_twin(env)
    for i in np.flatnonzero(~got):
        xy = lo[i] + rng.random((8, 2)) * (hi[i] - lo[i])
        assert np.array_equal(env.height_at(xy), twin.height_at(xy))
        assert np.array_equal(env.forbidden_at(xy), twin.forbidden_at(xy))


def _watch(env: Environment, n: int, rng: np.random.Generator) -> Watch:
    ring = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    dirs = np.stack([np.cos(ring), np.sin(ring)], axis=1)
    radius = rng.uniform(0.05, 0.3, n)
    offsets = np.concatenate([radius[:, None, None] * dirs, 0.5 * radius[:, None, None] * dirs], axis=1)
    return Watch(offsets, np.zeros((n, 16)), np.zeros((n, 16), dtype=bool), True, np.zeros((n, 2)),
                 np.ones(n, dtype=bool), np.ones(n, dtype=bool), np.zeros((n, 4)),
                 np.abs(offsets).max(axis=1), np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))


@given(st.integers(0, 10_000))
@settings(max_examples=20, deadline=None)
def test_a_look_that_skips_quiet_rings_answers_what_asking_them_all_does(seed: int) -> None:
    env = random_env(seed, n_boxes=40)
    rng = np.random.default_rng(seed)
    n = 30
    spot = np.column_stack([rng.uniform(-6.0, 6.0, (n, 2)), np.zeros(n)])
    skip, full = _watch(env, n, rng), _watch(env, n, rng)
    full.offsets, full.reach = skip.offsets, skip.reach
    legs = np.arange(n)
    watch_reset(env, skip, legs, spot)
    watch_reset(env, full, legs, spot)
    tol = np.full(n, 0.01)
    dyn = np.flatnonzero(env.boxes.dynamic)
    for _ in range(6):
        b = env.boxes
        env.move_boxes(dyn, b.center[dyn] + np.column_stack([rng.normal(0.0, 0.3, (dyn.size, 2)),
                                                              np.zeros(dyn.size)]), b.yaw[dyn] + 0.2)
        moved = rng.random(n) < 0.2  # some spots move without a reset (a foot pushed out)
        spot[moved, :2] += rng.normal(0.0, 0.1, (int(moved.sum()), 2))
        full.stirred[:] = True  # asks every ring
        for got, want in zip(look(env, skip, legs, spot, tol), look(env, full, legs, spot, tol), strict=True):
            assert np.array_equal(got, want)
        assert np.array_equal(skip.ground, full.ground)
        assert np.array_equal(skip.forbidden, full.forbidden)
    assert not skip.stirred.all()  # some rings were quiet: the skipping was exercised


def test_a_swing_is_near_a_moving_box_over_its_samples_bounds() -> None:
    env = random_env(3, n_boxes=40)
    b = env.boxes
    i = int(np.flatnonzero(b.dynamic)[0])
    through = np.linspace(b.center[i] - [0.4, 0.0, 0.0], b.center[i] + [0.4, 0.0, 0.0], 9)
    far = through + np.array([20.0, 20.0, 0.0])
    watch = _watch(env, 2, np.random.default_rng(0))
    swing_planned(env, watch, np.arange(2), np.stack([through, far]))
    assert watch.swing_stirred.tolist() == [True, False]
    assert np.allclose(watch.swing_box[1], [*(far[0, :2]), *(far[-1, :2])])
