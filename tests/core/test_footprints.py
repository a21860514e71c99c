# SPDX-License-Identifier: GPL-3.0-or-later
"""Footprint planning: candidate scores, slices, the best-couple search and its LOD
(thesis §3.5, §3.7, Appendix E)."""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core.locomotion.footprints import (
    Couple,
    plan_footsteps,
)
from procloco_addon.core.world.pathing import clearance_profile, wavefront
from procloco_addon.core.world.terrain import (
    ROLE_AVOID,
    ROLE_STEP_OVER,
    Boxes,
    Environment,
    Heightmap,
    WindowGrids,
    WindowParams,
    dilate,
    foot_kernel,
)
from tests.core.cross_path import assert_close
from tests.core.reference_planner import FlatSettings, legs_cross, plan_footstep

WP = WindowParams(n_cells=40, cell=0.07, foot_half_extents=(0.03, 0.03))
P = FlatSettings(step_height=0.1, slice_size=0.1, leg_reach=0.6, candidate_radius=0.2, fixed_distance=0.3,
                 foot_half_extents=(0.03, 0.03))
NO_LEGS = np.zeros((0, 2))
START = np.array([0.0, 0.0, 0.0])
HIP = np.array([0.2, 0.25])


def flat() -> Heightmap:
    return Heightmap(np.zeros((13, 13)), np.array([-3.0, -3.0]), 0.5)


def crates(rows: list[tuple[float, float, float, float, float, int]]) -> Boxes:
    """(x, y, sx, sy, height, role) rows, yaw 0, static, on z = 0."""
    a = np.array(rows, dtype=float).reshape(-1, 6)
    n = a.shape[0]
    return Boxes(np.column_stack([a[:, :2], np.zeros(n)]), a[:, 2:5], np.zeros(n), a[:, 5].astype(int),
                 np.zeros(n, dtype=bool))


def window(rows: list[tuple[float, float, float, float, float, int]] | None = None) -> WindowGrids:
    return Environment(flat(), crates(rows) if rows else None).window(np.array([0.2, 0.0]), WP)


def plan_one(grids: WindowGrids, foot_start: np.ndarray, preferred_xy: np.ndarray, hip_xy: np.ndarray,
             other_hips_xy: np.ndarray, other_feet_xy: np.ndarray, params: FlatSettings,
             foot_yaw: float = 0.0, hip_z: float | None = None) -> Couple:
    """The product planner (:func:`plan_footsteps`) asked for one foot."""
    rq = params.request(grids, foot_start, preferred_xy, hip_xy, other_hips_xy, other_feet_xy, foot_yaw,
                        hip_z)
    return plan_footsteps([rq])[0]


def plan(w: WindowGrids, preferred: tuple[float, float], params: FlatSettings = P,
         start: np.ndarray = START, hip: np.ndarray = HIP, other_hips: np.ndarray = NO_LEGS,
         other_feet: np.ndarray = NO_LEGS, yaw: float = 0.0) -> Couple:
    return plan_one(w, start, np.array(preferred), hip, other_hips, other_feet, params, yaw)


def check_couple(w: WindowGrids, c: Couple, params: FlatSettings, start: np.ndarray,
                 preferred: np.ndarray, hip: np.ndarray, other_feet: np.ndarray = NO_LEGS,
                 yaw: float = 0.0) -> None:
    """Invariants of every valid couple (foot box ``params.foot_half_extents`` at ``yaw``)."""
    assert c.ok
    assert c.trajectory is not None
    assert np.all(np.isfinite(c.footprint))
    assert 0.0 < c.score <= 1.0
    assert c.score == pytest.approx(c.target_score * c.path_score)
    # The footprint: not forbidden, not a dilation-only cell, near the preferred one, in reach.
    rc = tuple(w.cell_of(c.footprint[:2]))
    forbidden, dilated_only = w.obstacle_map(foot_half_extents=params.foot_half_extents, foot_yaw=yaw)
    assert not forbidden[rc]
    assert not dilated_only[rc]
    assert np.linalg.norm(c.footprint[:2] - preferred) <= params.candidate_radius + 1e-9
    assert np.linalg.norm(c.footprint[:2] - hip) <= params.leg_reach + 1e-9
    assert c.footprint[2] >= w.elevation[rc] - 1e-9
    # The trajectory: from the foot to the footprint, outside forbidden cells (apart from the
    # foot's own lift-off cells) and above the elevation map plus the clearance.
    pts = c.trajectory.points
    assert np.all(np.isfinite(pts))
    assert np.allclose(pts[0], start)
    assert np.allclose(pts[-1], c.footprint)
    core, dilated = w.obstacle_map(level=c.slice_level, foot_half_extents=params.foot_half_extents,
                                   foot_yaw=yaw)
    cells = w.cell_of(pts[:, :2])
    start_rc = w.cell_of(start[:2])
    kernel = foot_kernel(w.cell, params.foot_half_extents, yaw)
    liftoff = {tuple(start_rc + k) for k in kernel.tolist()}
    if w.avoid[tuple(start_rc)]:  # standing on an avoided obstacle: may cross it to leave
        escape = wavefront(dilate(w.avoid, kernel), (int(start_rc[0]), int(start_rc[1])))
        liftoff |= {tuple(x) for x in np.argwhere(np.isfinite(escape.dist)).tolist()}
    away = np.array([tuple(x) not in liftoff for x in cells.tolist()])
    assert not np.any(((core | dilated)[cells[:, 0], cells[:, 1]]) & away)
    if other_feet.shape[0]:
        feet_cells = {tuple(x) for x in w.cell_of(other_feet).tolist()}
        assert not any(tuple(x) in feet_cells for x in cells[away].tolist())
    s = c.trajectory.arc_2d
    chords = np.sum(np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1))
    assert chords * (1 - 1e-3) <= s[-1] <= 1.25 * chords + 1e-9  # the arc over its samples' chords
    assert np.all(np.diff(s) >= 0.0)
    ramp = min(max(params.step_height, 2 * w.cell), 0.5 * s[-1]) if s[-1] > 0 else 0.0
    clearance = clearance_profile(s, s[-1], params.step_height, ramp)
    ground = w.elevation[cells[:, 0], cells[:, 1]]
    in_start = np.all(cells == start_rc, axis=1)
    required = np.where(in_start, np.minimum(ground, start[2]), ground + clearance)
    assert np.all(pts[1:-1, 2] >= required[1:-1] - 1e-9)


def test_flat_ground_takes_the_preferred_footprint_with_a_clean_arc() -> None:
    w = window()
    pref = np.array([0.33, 0.02])
    c = plan(w, tuple(pref))
    check_couple(w, c, P, START, pref, HIP)
    assert np.allclose(c.footprint, [0.33, 0.02, 0.0])  # exactly the preferred point
    assert c.target_score == pytest.approx(1.0)
    assert c.score == pytest.approx(1.0)
    assert c.n_couples == 1  # nothing can beat a perfect couple
    pts = c.trajectory.points if c.trajectory else np.zeros((0, 3))
    direction = pref / np.linalg.norm(pref)
    assert np.allclose(pts[:, 0] * direction[1] - pts[:, 1] * direction[0], 0.0, atol=1e-9)  # straight
    top = int(np.argmax(pts[:, 2]))
    assert np.all(np.diff(pts[: top + 1, 2]) >= -1e-12)
    assert np.all(np.diff(pts[top:, 2]) <= 1e-12)
    assert P.step_height <= pts[top, 2] <= 1.5 * P.step_height


def test_stepping_in_place_lifts_the_foot_and_puts_it_back() -> None:
    w = window()
    c = plan(w, (0.0, 0.0))
    check_couple(w, c, P, START, np.zeros(2), HIP)
    assert np.allclose(c.footprint, START)
    traj = c.trajectory
    assert traj is not None
    assert traj.length == pytest.approx(2 * P.step_height)
    assert np.allclose(traj.point_at(np.array([0.5]))[0], [0.0, 0.0, P.step_height])


def test_preferred_footprint_on_a_crate_edge_moves_to_a_comfortable_one() -> None:
    # Thesis sequence 2: the preferred footprint falls on the rim of a crate.
    w = window([(0.5, 0.0, 0.4, 0.4, 0.12, ROLE_STEP_OVER)])  # crate spans x in [0.3, 0.7]
    pref = np.array([0.31, 0.0])
    c = plan(w, tuple(pref))
    check_couple(w, c, P, START, pref, HIP)
    assert np.linalg.norm(c.footprint[:2] - pref) > 0.5 * w.cell  # not the rim cell
    rc = w.cell_of(c.footprint[:2])
    block = w.elevation[rc[0] - 1 : rc[0] + 2, rc[1] - 1 : rc[1] + 2]
    assert np.ptp(block) <= P.edge_height  # all eight neighbours at the same height: comfortable
    assert c.target_score > 0.5


def test_low_crates_are_stepped_over_and_tall_ones_walked_around() -> None:
    pref = np.array([0.4, 0.0])
    # Low crate on the way: under every slice, the foot goes straight over it.
    w = window([(0.2, 0.0, 0.1, 0.3, 0.04, ROLE_STEP_OVER)])
    c = plan(w, tuple(pref))
    check_couple(w, c, P, START, pref, HIP)
    pts = c.trajectory.points if c.trajectory else np.zeros((0, 3))
    above = np.abs(pts[:, 0] - 0.2) <= 0.05
    assert np.allclose(pts[:, 1], 0.0, atol=1e-9)
    assert np.all(pts[above, 2] >= 0.04 + P.step_height - 1e-9)
    # A tall, narrow post on the way: with slices the foot walks around it ...
    w = window([(0.2, 0.0, 0.07, 0.07, 0.35, ROLE_STEP_OVER)])
    c = plan(w, tuple(pref))
    check_couple(w, c, P, START, pref, HIP)
    assert c.slice_level is not None
    pts = c.trajectory.points if c.trajectory else np.zeros((0, 3))
    assert np.all(w.elevation_at(pts[:, :2]) < 0.35)  # never over the post
    assert pts[:, 2].max() < 0.35
    # ... and without slices (the off-screen LOD) it goes over it.
    c = plan(w, tuple(pref), replace(P, slice_size=None))
    check_couple(w, c, P, START, pref, HIP)
    assert c.slice_level is None
    pts = c.trajectory.points if c.trajectory else np.zeros((0, 3))
    assert pts[:, 2].max() >= 0.35 + P.step_height - 1e-9


def random_scene(seed: int) -> tuple[Environment, WindowGrids, np.random.Generator]:
    rng = np.random.default_rng(seed)
    hm = Heightmap(rng.normal(size=(15, 15)) * 0.02, np.array([-2.0, -2.0]), 0.3)
    n = 14
    xy = rng.uniform(-0.4, 0.9, (n, 2))
    b = Boxes(np.column_stack([xy, np.zeros(n)]),
              np.column_stack([rng.uniform(0.05, 0.3, (n, 2)), rng.uniform(0.02, 0.35, n)]),
              rng.uniform(0, np.pi, n), rng.choice([ROLE_STEP_OVER, ROLE_AVOID], n, p=[0.7, 0.3]),
              np.zeros(n, dtype=bool))
    env = Environment(hm, b, tile_cells=48)  # tiles are a cache: small ones for a small window
    return env, env.window(np.array([0.2, 0.0]), WP), rng


def random_foot(env: Environment, w: WindowGrids, rng: np.random.Generator) -> tuple[np.ndarray, ...] | None:
    core, dil = w.obstacle_map()
    for _ in range(20):
        s_xy = rng.uniform(-0.2, 0.2, 2)
        if not (core | dil)[tuple(w.cell_of(s_xy))]:
            start = np.array([s_xy[0], s_xy[1], env.height_at(s_xy[None, :])[0]])
            pref = s_xy + np.array([rng.uniform(0.15, 0.4), rng.uniform(-0.15, 0.15)])
            hip = s_xy + np.array([0.15, 0.3])
            other_hips = np.array([[s_xy[0] + 0.3, s_xy[1] + 0.3], [s_xy[0], s_xy[1] + 0.6]])
            other_feet = other_hips + rng.uniform(-0.3, 0.3, (2, 2)) + np.array([0.0, 0.3])
            return start, pref, hip, other_hips, other_feet
    return None


@given(st.integers(0, 100_000), st.sampled_from([None, 0.08]))
def test_pruned_search_returns_the_exhaustive_best_couple(seed: int, slice_size: float | None) -> None:
    env, w, rng = random_scene(seed)
    foot = random_foot(env, w, rng)
    if foot is None:
        return
    start, pref, hip, oh, of = foot
    # A long foot, turned: the enlargement of obstacles follows its shape and yaw.
    params = replace(P, slice_size=slice_size, foot_half_extents=(0.05, 0.02))
    yaw = float(rng.uniform(-np.pi, np.pi))
    pruned = plan(w, tuple(pref), params, start, hip, oh, of, yaw)
    full = plan(w, tuple(pref), replace(params, exhaustive=True), start, hip, oh, of, yaw)
    assert pruned.ok == full.ok
    if pruned.ok:
        check_couple(w, pruned, params, start, pref, hip, of, yaw)
        assert np.allclose(pruned.footprint, full.footprint)
        assert pruned.score == pytest.approx(full.score, abs=1e-12)
        assert pruned.slice_level == full.slice_level
        assert pruned.n_paths <= full.n_paths
        # One wavefront per (target, slice), grown from the target as in the thesis: as valid.
        # (Shortest grid paths are not unique: descending from the other end may pick another
        # one of them, so its curve and score can differ slightly.)
        thesis = plan(w, tuple(pref), replace(params, shared_wavefront=False), start, hip, oh, of, yaw)
        assert thesis.ok
        check_couple(w, thesis, params, start, pref, hip, of, yaw)
        # The foot box does not overlap an avoided obstacle where it lands.
        c, s = np.cos(yaw), np.sin(yaw)
        u, v = (a.ravel() for a in np.meshgrid(np.linspace(-0.05, 0.05, 7), np.linspace(-0.02, 0.02, 5)))
        box = pruned.footprint[:2] + np.column_stack([c * u - s * v, s * u + c * v])
        assert not env.forbidden_at(box).any()


@given(st.integers(0, 100_000))
def test_lod_budgets_stop_early_and_never_return_an_invalid_couple(seed: int) -> None:
    env, w, rng = random_scene(seed)
    foot = random_foot(env, w, rng)
    if foot is None:
        return
    start, pref, hip, oh, of = foot
    results = {}
    for budget in (0, 1, 3, None):
        params = replace(P, max_couples_after_first=budget)
        c = plan(w, tuple(pref), params, start, hip, oh, of)
        results[budget] = c
        if not c.ok:
            assert c.trajectory is None
            continue
        check_couple(w, c, params, start, pref, hip, of)
        if budget is not None:
            assert c.n_couples_after_first <= budget
    first = results[0]
    if first.ok:
        # Off-screen LOD: stops right at the first valid couple.
        assert first.n_couples == first.first_valid_couple
        assert first.n_couples_after_first == 0
    oks = [results[b].ok for b in (0, 1, 3, None)]
    assert len(set(oks)) == 1  # a valid couple exists or not, whatever the budget
    if all(oks):
        scores = [results[b].score for b in (0, 1, 3, None)]
        # More search is never worse.
        assert all(a <= b + 1e-12 for a, b in itertools.pairwise(scores))


def test_walled_in_foot_gets_a_clear_no_valid_couple() -> None:
    ring = [(0.25 * np.cos(a), 0.25 * np.sin(a), 0.12, 0.12, 0.3, ROLE_AVOID)
            for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
    w = window(ring)
    c = plan(w, (0.45, 0.0))
    assert not c.ok
    assert c.trajectory is None
    assert "no valid couple" in c.message
    assert np.allclose(c.footprint, START)
    assert math.isfinite(c.score)
    assert c.score == 0.0
    assert c.n_couples == 0
    # Nowhere to put the foot at all: a different, equally clear message.
    w2 = window([(0.45, 0.0, 0.8, 0.8, 0.3, ROLE_AVOID)])
    c2 = plan(w2, (0.45, 0.0), replace(P, candidate_radius=0.1))
    assert not c2.ok
    assert "no candidate footprint" in c2.message


def test_a_foot_on_an_avoided_crate_that_moved_under_it_can_step_off() -> None:
    w = window([(0.0, 0.0, 0.3, 0.3, 0.15, ROLE_AVOID)])
    start = np.array([0.0, 0.0, 0.15])  # standing on its top
    pref = np.array([0.4, 0.0])
    c = plan(w, tuple(pref), start=start)
    assert c.ok
    assert c.trajectory is not None
    assert not w.forbidden[tuple(w.cell_of(c.footprint[:2]))]
    assert not w.dilated[tuple(w.cell_of(c.footprint[:2]))]
    pts = c.trajectory.points
    on_crate = w.forbidden[w.cell_of(pts[:, :2])[:, 0], w.cell_of(pts[:, :2])[:, 1]]
    assert np.all(pts[on_crate, 2] >= 0.15 - 1e-9)  # never through the crate
    assert np.all(np.diff(on_crate.astype(int)) <= 0)  # leaves it once, never comes back


def test_bad_numbers_give_a_failed_couple_not_an_exception() -> None:
    w = window()
    c = plan_one(w, np.array([np.nan, 0.0, 0.0]), np.array([0.3, 0.0]), HIP, NO_LEGS, NO_LEGS, P)
    assert not c.ok
    assert np.all(np.isfinite(c.footprint))
    assert "non-finite" in c.message
    far = plan_one(w, np.array([50.0, 0.0, 0.0]), np.array([50.3, 0.0]), HIP, NO_LEGS, NO_LEGS, P)
    assert not far.ok
    assert "outside the window" in far.message


def test_other_feet_are_forbidden_and_legs_do_not_cross() -> None:
    w = window()
    pref = np.array([0.33, 0.0])
    # Another foot stands on the preferred footprint: the foot lands beside it.
    other_foot = np.array([[0.33, 0.0]])
    c = plan(w, tuple(pref), other_hips=np.array([[0.3, -0.3]]), other_feet=other_foot)
    check_couple(w, c, P, START, pref, HIP, other_foot)
    assert np.linalg.norm(c.footprint[:2] - other_foot[0]) >= 2 * 0.03
    # Another leg runs across the line hip -> preferred footprint: that footprint is refused.
    other_hip = np.array([[0.45, 0.2]])
    other = np.array([[0.15, -0.1]])
    assert legs_cross(HIP, pref[None, :], other_hip, other)[0]
    c = plan(w, tuple(pref), other_hips=other_hip, other_feet=other)
    check_couple(w, c, P, START, pref, HIP, other)
    assert not legs_cross(HIP, c.footprint[None, :2], other_hip, other)[0]


def test_a_foot_box_keeps_off_the_other_feet_soles_not_their_whole_boxes() -> None:
    """A foot with long toes (a large box) stands on a small sole: another foot may land with
    its box beside that sole, nearer than two boxes, never with its box over it."""
    w = window()
    pref = np.array([0.35, 0.0])  # a cell centre
    other_foot = np.array([[0.35, 0.28]])  # two boxes (0.2) and a cell or so beside it
    other_hip = np.array([[0.35, 0.4]])
    long_toes = replace(P, foot_half_extents=(0.1, 0.1))
    on_soles = replace(long_toes, sole_half_extents=(0.02, 0.02))
    boxes = plan(w, tuple(pref), long_toes, other_hips=other_hip, other_feet=other_foot)
    soles = plan(w, tuple(pref), on_soles, other_hips=other_hip, other_feet=other_foot)
    # kept two boxes apart, the foot moves off its preferred footprint, away from the other;
    # kept a box and a sole apart, it lands there
    assert boxes.ok
    assert boxes.footprint[1] < -1e-9
    assert soles.ok
    np.testing.assert_allclose(soles.footprint[:2], pref, atol=1e-9)
    assert np.max(np.abs(soles.footprint[:2] - other_foot[0])) >= 0.1 + 0.02
    # the same with the batch planner
    rq = on_soles.request(w, START, pref, HIP, other_hip, other_foot)
    _same_couple(plan_footsteps([rq])[0], soles)


def test_legs_cross_is_a_proper_segment_intersection() -> None:
    hip = np.array([0.0, 0.0])
    feet = np.array([[1.0, 1.0], [1.0, -1.0], [1.0, 0.2]])
    other_hips = np.array([[0.0, 1.0]])
    other_feet = np.array([[1.0, 0.0]])
    assert legs_cross(hip, feet, other_hips, other_feet).tolist() == [True, False, True]
    # Sharing the hip point is not a crossing.
    assert not legs_cross(hip, feet[:1], np.zeros((1, 2)), np.array([[1.0, -1.0]]))[0]
    assert legs_cross(hip, feet, np.zeros((0, 2)), np.zeros((0, 2))).tolist() == [False, False, False]


def _same_couple(a: Couple, b: Couple) -> None:
    """The same answer: every decision exactly, every float to a few ulps (cross_path)."""
    assert a.ok == b.ok
    assert a.message == b.message
    for name in ("n_couples", "n_paths", "n_targets", "n_wavefronts", "wavefront_iterations",
                 "first_valid_couple", "n_couples_after_first", "target_index"):
        assert getattr(a, name) == getattr(b, name), name
    assert (a.slice_level is None) == (b.slice_level is None)
    if a.slice_level is not None:
        assert_close(a.slice_level, b.slice_level, "slice_level")
    assert_close(a.footprint, b.footprint, "footprint")
    for name in ("score", "target_score", "path_score"):
        assert_close(getattr(a, name), getattr(b, name), name)
    if a.trajectory is None or b.trajectory is None:
        assert a.trajectory is None
        assert b.trajectory is None
        return
    for name in ("points", "waypoints", "waypoints_2d", "arc", "arc_2d", "length", "length_2d"):
        assert_close(getattr(a.trajectory, name), getattr(b.trajectory, name), name)


@functools.cache
def _crate_window() -> WindowGrids:
    return window([(0.0, 0.0, 0.3, 0.3, 0.15, ROLE_AVOID)])


#: Planner settings the feet of one batch are given in turn: each LOD of thesis §3.7 and every
#: switch of the search.
BATCH_SETTINGS = [
    P,
    replace(P, max_couples_after_first=0, slice_size=None),
    replace(P, max_couples_after_first=1, slice_size=0.15),
    replace(P, slice_size=0.05, foot_half_extents=(0.05, 0.02)),
    # long toes on a small sole: other feet forbidden as their soles only
    replace(P, foot_half_extents=(0.12, 0.09), sole_half_extents=(0.02, 0.02)),
    replace(P, exhaustive=True, candidate_radius=0.1),
    replace(P, shared_wavefront=False, candidate_radius=0.1),
    replace(P, los_shortcut=False, candidate_radius=0.15),
    replace(P, max_targets=3, candidate_radius=0.3),
    # the checks that need the hip's height (the requests give one)
    replace(P, reach_3d=0.5, reach_sweep=0.05, reach_sink=0.03, leg_length=0.55, leg_arch=0.5,
            max_straddle=0.05),
    # long toes on a small sole with those checks: it lands under its sole, straddles by its box
    replace(P, foot_half_extents=(0.12, 0.09), sole_half_extents=(0.02, 0.04), max_straddle=0.03,
            reach_3d=0.5),
    replace(P, leg_length=0.45, candidate_radius=0.25),
]


@given(st.integers(0, 100_000))
def test_planning_a_batch_of_feet_equals_the_one_foot_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    scenes = [random_scene(seed), random_scene(seed + 1)]
    requests = []
    for i in range(6):
        env, w, _ = scenes[i % 2]
        foot = random_foot(env, w, rng)
        if foot is None:
            continue
        start, pref, hip, oh, of = foot
        params = BATCH_SETTINGS[int(rng.integers(len(BATCH_SETTINGS)))]
        hip_z = float(rng.uniform(0.05, 0.4)) if rng.random() < 0.7 else None
        requests.append(params.request(w, start, pref, hip, oh, of, float(rng.uniform(-np.pi, np.pi)), hip_z))
    env, w, _ = scenes[0]
    # Feet that cannot be planned, and a foot on an avoided crate (it may step off it).
    # A window of another size and cell size in the same batch.
    other = env.window(np.array([0.1, 0.1]), WindowParams(n_cells=31, cell=0.05))
    for grids, start, pref in ((w, [np.nan, 0.0, 0.0], [0.3, 0.0]), (w, [50.0, 0.0, 0.0], [50.3, 0.0]),
                               (_crate_window(), [0.0, 0.0, 0.15], [0.4, 0.0]),
                               (other, [0.0, 0.0, 0.0], [0.3, 0.1])):
        requests.append(P.request(grids, np.array(start), np.array(pref), HIP, NO_LEGS, NO_LEGS))
    order = rng.permutation(len(requests))
    requests = [requests[i] for i in order]
    batched = plan_footsteps(requests)
    assert len(batched) == len(requests)
    for rq, got in zip(requests, batched, strict=True):
        alone = plan_footstep(rq)
        _same_couple(got, alone)
        _same_couple(plan_footsteps([rq])[0], alone)  # a batch of one: the same search
    assert any(c.ok for c in batched)
    assert plan_footsteps([]) == []


def _scaled_plan(scale: float, noise: np.random.Generator | None) -> Couple:
    """A foot in mid-air stepping onto a low crate, in a world ``scale`` times larger, its inputs
    perturbed by float noise (a rig read at another scale through single-precision matrices)."""
    boxes = crates([(0.35 * scale, 0.0, 0.3 * scale, 0.4 * scale, 0.08 * scale, ROLE_STEP_OVER)])
    env = Environment(Heightmap(np.zeros((13, 13)), np.array([-3.0, -3.0]) * scale, 0.5 * scale), boxes)
    half = (0.03 * scale, 0.03 * scale)
    wp = WindowParams(n_cells=40, cell=0.07 * scale, foot_half_extents=half)
    w = env.window(np.array([0.2, 0.0]) * scale, wp)
    params = replace(P, step_height=0.1 * scale, slice_size=0.1 * scale, leg_reach=0.6 * scale,
                     candidate_radius=0.2 * scale, fixed_distance=0.3 * scale,
                     foot_half_extents=half, edge_height=0.04 * scale)

    def jitter(v: list[float]) -> np.ndarray:
        a = np.asarray(v) * scale
        return a if noise is None else a * (1.0 + 1e-8 * noise.standard_normal(a.shape))

    return plan_one(w, jitter([0.02, 0.01, 0.03]), jitter([0.4, 0.02]), jitter([0.2, 0.25]), NO_LEGS,
                         NO_LEGS, params)


def test_a_plan_and_its_hundredfold_copy_with_float_noise_agree() -> None:
    # The clearance profile over flat ground and a crate top has long collinear runs (flat
    # tops, linear ramps): which of their points become waypoints must not hang on rounding.
    ref = _scaled_plan(1.0, None)
    assert ref.ok
    assert ref.trajectory is not None
    assert ref.footprint[2] == pytest.approx(0.08)  # onto the crate
    u = np.linspace(0.0, 1.0, 65)
    want = ref.trajectory.point_at(u)
    rng = np.random.default_rng(7)
    for _ in range(12):
        got = _scaled_plan(100.0, rng)
        assert got.ok
        assert got.trajectory is not None
        assert np.abs(got.trajectory.point_at(u) / 100.0 - want).max() < 1e-6


@pytest.mark.parametrize("crate_y", [-0.2, -0.18])
def test_a_foot_beside_a_tall_avoided_crate_steps_away_without_climbing_it(crate_y: float) -> None:
    # The crate's side is 5 or 3 cm from the foot's centre (at -0.18 it overlaps the foot's
    # cell, as when a moving crate has come at the foot): the foot leaves sideways at its
    # step height, not over the crate's 30 cm top.
    w = window([(0.0, crate_y, 0.3, 0.3, 0.3, ROLE_AVOID)])
    for pref in ((0.3, 0.0), (0.0, 0.25), (-0.25, 0.05)):
        c = plan(w, pref)
        assert c.ok
        assert c.trajectory is not None
        assert c.trajectory.points[:, 2].max() <= 1.1 * P.step_height


def test_a_foot_on_top_of_an_avoided_crate_still_clears_it_on_its_way_off() -> None:
    w = window([(0.0, 0.0, 0.3, 0.3, 0.2, ROLE_AVOID)])
    c = plan(w, (0.35, 0.0), start=np.array([0.0, 0.0, 0.2]))
    assert c.ok
    assert c.trajectory is not None
    on_crate = np.all(np.abs(c.trajectory.points[:, :2]) <= 0.15 + 0.03, axis=1)
    assert np.all(c.trajectory.points[on_crate, 2] >= 0.2 - 1e-9)


def test_a_foot_in_the_air_over_its_footprint_comes_down_without_lifting_again() -> None:
    # A re-plan from mid-air right over the preferred footprint: the foot is not lifted a
    # step height above where it already is (plan after plan it would ratchet upward).
    w = window()
    for z in (0.06, 0.09):
        c = plan(w, (0.0, 0.0), start=np.array([0.0, 0.0, z]))
        assert c.ok
        assert c.trajectory is not None
        assert np.allclose(c.footprint, [0.0, 0.0, 0.0])
        assert c.trajectory.points[:, 2].max() <= 1.1 * P.step_height


def _leg_hits_box(foot: np.ndarray, hip_xy: np.ndarray, hip_z: float, centre: tuple[float, float],
                  half: float, height: float) -> bool:
    """Whether the straight line from a footprint up to the hip runs through an upright box
    (square footprint ``centre`` ± ``half``, from the ground to ``height``)."""
    t = np.linspace(0.0, 1.0, 400)
    pts = foot[None, :] + t[:, None] * (np.r_[hip_xy, hip_z] - foot)[None, :]
    inside = ((np.abs(pts[:, 0] - centre[0]) < half) & (np.abs(pts[:, 1] - centre[1]) < half)
              & (pts[:, 2] < height))
    return bool(inside.any())


def test_a_footprint_whose_leg_would_run_through_a_crate_gives_way_to_a_clear_one() -> None:
    # A 25 cm crate between the hip (30 cm up) and the preferred footprint: without the leg
    # check the foot lands behind the crate with its leg through it.
    hip = np.array([0.2, 0.35])
    w = window([(0.2, 0.2, 0.07, 0.07, 0.25, ROLE_AVOID)])
    params = replace(P, candidate_radius=0.4)
    blind = plan_one(w, START, np.array([0.2, 0.0]), hip, NO_LEGS, NO_LEGS, params, 0.0, 0.3)
    checked = plan_one(w, START, np.array([0.2, 0.0]), hip, NO_LEGS, NO_LEGS,
                            replace(params, leg_length=0.6), 0.0, 0.3)
    assert blind.ok
    assert checked.ok
    assert _leg_hits_box(blind.footprint, hip, 0.3, (0.2, 0.2), 0.035, 0.25)
    assert not _leg_hits_box(checked.footprint, hip, 0.3, (0.2, 0.2), 0.035, 0.25)
    # with nothing clear left, a blocked footprint is still taken, scored lower
    walled = window([(0.2, 0.15, 0.8, 0.06, 0.25, ROLE_AVOID)])
    free = plan_one(walled, START, np.array([0.2, 0.0]), hip, NO_LEGS, NO_LEGS, params, 0.0, 0.3)
    low = plan_one(walled, START, np.array([0.2, 0.0]), hip, NO_LEGS, NO_LEGS,
                        replace(params, leg_length=0.6), 0.0, 0.3)
    assert low.ok
    assert low.target_score == pytest.approx(params.leg_clearance_score * free.target_score)


@pytest.mark.parametrize("hip_z", [0.2, 0.3])
def test_footprints_stay_within_the_legs_3d_reach_of_the_hip(hip_z: float) -> None:
    w = window()
    params = replace(P, reach_3d=0.4, candidate_radius=0.3)
    far = plan_one(w, START, np.array([0.45, 0.0]), HIP, NO_LEGS, NO_LEGS, params)  # no hip height
    assert np.linalg.norm(np.r_[far.footprint[:2] - HIP, far.footprint[2] - hip_z]) > 0.4
    c = plan_one(w, START, np.array([0.45, 0.0]), HIP, NO_LEGS, NO_LEGS, params, 0.0, hip_z)
    assert c.ok
    assert np.linalg.norm(np.r_[c.footprint[:2] - HIP, c.footprint[2] - hip_z]) <= 0.4 + 1e-9
    # a hip too high for any footprint: a clean failure, not a footprint out of reach
    assert not plan_one(w, START, np.array([0.45, 0.0]), HIP, NO_LEGS, NO_LEGS, params, 0.0, 0.45).ok


def test_a_footprint_hanging_over_a_height_step_is_never_a_candidate() -> None:
    from procloco_addon.core.locomotion.footprints import _hip_checks, _WindowLookup

    # Two footprints on the ground (z at their own point 0, their soles landing there), one
    # whose foot box reaches 6 cm higher ground: with max_straddle 1 cm only the first is a
    # candidate.
    xy = np.array([[0.3, 0.0], [0.3, 0.0]])
    box_z = np.array([0.0, 0.06])
    inf = math.inf
    settings = np.tile([0.01, inf, 0.0, 0.0, inf, 0.0, 0.03], (2, 1))
    ok, clear = _hip_checks(xy, np.zeros(2), box_z, np.zeros(2), np.zeros((2, 2)), np.full(2, 0.3), settings,
                            _WindowLookup([window()]), np.zeros(2, dtype=np.intp))
    assert ok.tolist() == [True, False]
    assert clear.all()


def _slope_window(grade: float) -> WindowGrids:
    """A plane rising ``grade`` metres per metre along +x through z = 0 at x = 0."""
    x = -3.0 + 0.5 * np.arange(13)
    ground = Heightmap(np.tile(grade * x, (13, 1)), np.array([-3.0, -3.0]), 0.5)
    return Environment(ground).window(np.array([0.2, 0.0]), WP)


@pytest.mark.parametrize("yaw", [0.0, 0.5 * math.pi])
def test_a_long_footed_leg_on_a_slope_lands_on_the_ground_under_its_sole(yaw: float) -> None:
    # Toes reaching 12 cm from the end-effector (a foot box of 24 cm by 18 cm) on a sole of
    # 4 cm by 1 cm along the foot, up a 1:5 slope: the foot lands at the highest ground under
    # its sole, turned with its yaw, within a cell of the ground under its point; the foot box
    # would set it some 3 cm higher, on the ground its toes reach up the slope. The same
    # footprint for the one-foot reference, and the same with the foot box as sole.
    grade = 0.2
    w = _slope_window(grade)
    long_toes = replace(P, foot_half_extents=(0.12, 0.09), sole_half_extents=(0.04, 0.01), slice_size=None,
                        candidate_radius=0.0)
    start = np.array([0.0, 0.0, 0.0])
    sole_x = 0.04 if yaw == 0.0 else 0.01  # the sole's half size along the slope
    for params, reach_x in ((long_toes, sole_x), (replace(long_toes, sole_half_extents=None), 0.12)):
        c = plan(w, (0.3, 0.0), params, start=start, yaw=yaw)
        assert c.ok
        point = w.elevation[tuple(w.cell_of(c.footprint[:2]))]
        top = grade * (c.footprint[0] + reach_x + 0.5 * w.cell)  # the highest cell the print touches
        assert c.footprint[2] == pytest.approx(top, abs=0.5 * grade * w.cell + 1e-9)
        if params is long_toes:
            assert c.footprint[2] - point <= grade * (reach_x + w.cell) + 1e-9
        rq = params.request(w, start, np.array([0.3, 0.0]), HIP, NO_LEGS, NO_LEGS, yaw)
        _same_couple(c, plan_footstep(rq))


def test_a_long_footed_leg_beside_a_ledge_stands_on_the_ground_its_box_straddling_it() -> None:
    # A 2 cm step-over crate starting 10 cm ahead of the preferred footprint: the foot box
    # (toes reaching 12 cm) reaches its top, the sole does not. The foot lands on the ground
    # (the foot box would set it on the crate's top, 2 cm over the ground under its sole); the
    # straddle check still reads the box: with max_straddle under the crate's height that
    # footprint is never a candidate.
    w = window([(0.3 + 0.1 + 0.5, 0.0, 1.0, 1.0, 0.02, ROLE_STEP_OVER)])
    long_toes = replace(P, foot_half_extents=(0.12, 0.09), sole_half_extents=(0.02, 0.02), slice_size=None,
                        candidate_radius=0.0, max_straddle=0.03)
    pref = np.array([0.3, 0.0])
    rq = long_toes.request(w, START, pref, HIP, NO_LEGS, NO_LEGS, 0.0, 0.3)
    c = plan_footsteps([rq])[0]
    assert c.ok
    assert c.footprint[2] == pytest.approx(0.0, abs=1e-9)
    _same_couple(c, plan_footstep(rq))
    strict = replace(long_toes, max_straddle=0.01).request(w, START, pref, HIP, NO_LEGS, NO_LEGS, 0.0, 0.3)
    assert not plan_footsteps([strict])[0].ok
    assert not plan_footstep(strict).ok
