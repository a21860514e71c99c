# SPDX-License-Identifier: GPL-3.0-or-later
"""The watch on moving obstacles (``core.locomotion.obstacles``): a look that skips the rings
no moving thing comes near answers exactly what asking every ring would, and a step's looks
in one query answer what each asked alone does."""

from __future__ import annotations

import copy

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from procloco_addon.core.locomotion.obstacles import Watch, look, look_around, swing_planned, watch_reset
from procloco_addon.core.locomotion.state import start_feet
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


@given(st.integers(0, 10_000))
@settings(max_examples=15, deadline=None)
def test_a_steps_looks_in_one_query_answer_what_each_look_alone_does(seed: int) -> None:
    """``look_around``'s one rectangle query and one point query for the landed, swinging and
    planted feet give what each part asked alone gives: the landed feet's watch reset, then
    the swings' checks, then the planted feet's looks (the landed ones among them)."""
    env = random_env(seed, n_boxes=40)
    rng = np.random.default_rng(seed)
    n, k = 24, 10
    foot = np.column_stack([rng.uniform(-6.0, 6.0, (n, 2)), np.zeros(n)])
    feet = start_feet(foot, k)
    swing = rng.random(n) < 0.4
    legs = np.flatnonzero(swing)
    # the swings: straight lines 0.5 m long at 5 cm, planned over what was there then
    step = rng.normal(0.0, 0.5, (legs.size, 2))
    line = foot[legs][:, None, :] + np.linspace(0.0, 1.0, k + 1)[None, :, None] * np.concatenate(
        [step, np.zeros((legs.size, 1))], axis=1)[:, None, :]
    line[..., 2] = 0.05
    feet.plan.traj[legs] = line
    feet.plan.target[legs] = line[:, -1]
    feet.plan.ground[legs] = env.height_at(line[..., :2].reshape(-1, 2)).reshape(legs.size, -1)
    feet.plan.forbidden[legs] = env.forbidden_at(line[..., :2].reshape(-1, 2)).reshape(legs.size, -1)
    feet.plan.support[legs] = feet.plan.ground[legs, -1]
    watch = _watch(env, n, rng)
    watch_reset(env, watch, np.arange(n), np.where(swing[:, None], feet.plan.target, foot))
    swing_planned(env, watch, legs, line)
    dyn = np.flatnonzero(env.boxes.dynamic)
    b = env.boxes
    shift = np.column_stack([rng.normal(0.0, 0.3, (dyn.size, 2)), np.zeros(dyn.size)])
    env.move_boxes(dyn, b.center[dyn] + shift, b.yaw[dyn] + 0.2)
    # some planted feet landed at new spots this step
    landed = np.flatnonzero(~swing & (rng.random(n) < 0.5))
    feet.foot[landed, :2] += rng.normal(0.0, 0.2, (landed.size, 2))
    progress = rng.uniform(0.0, 1.0, n)
    tol = np.full(n, 0.01)
    none = np.zeros(0, dtype=np.intp)
    nobody = np.zeros(n, dtype=bool)
    alone_watch, alone_feet = copy.deepcopy(watch), copy.deepcopy(feet)
    blocked, looked = look_around(env, watch, feet, landed, swing, ~swing, progress, tol)
    watch_reset(env, alone_watch, landed, alone_feet.foot[landed])
    want_blocked, _ = look_around(env, alone_watch, alone_feet, none, swing, nobody, progress, tol)
    want_look = look(env, alone_watch, np.flatnonzero(~swing), alone_feet.foot[~swing], tol)
    assert np.array_equal(blocked, want_blocked)
    assert np.array_equal(looked[0], np.flatnonzero(~swing))
    for got, want in zip(looked[1:], want_look, strict=True):
        assert np.array_equal(got, want)
    assert np.array_equal(feet.dodged, alone_feet.dodged)
    for name in ("ground", "forbidden", "spot", "stirred", "spot_ground", "spot_forbidden", "spot_known"):
        assert np.array_equal(getattr(watch, name), getattr(alone_watch, name)), name
