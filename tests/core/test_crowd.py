# SPDX-License-Identifier: GPL-3.0-or-later
"""Crowds in one simulation: characters of different sizes, each with its own controller
settings (creature-size scaling), stepped together."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from procloco_addon.core import metrics as mx
from procloco_addon.core.locomotion import morphology as morph
from procloco_addon.core.locomotion.gait import find_gait_preset
from procloco_addon.core.locomotion.morphology import Morphology
from procloco_addon.core.locomotion.scaling import scaled_params
from procloco_addon.core.locomotion.sim import Controls, SimResult, Simulation, check_motion, crowd_intrusion
from procloco_addon.core.locomotion.spine import SpineParams
from procloco_addon.core.locomotion.types import ControllerParams
from procloco_addon.core.world.terrain import ROLE_AVOID, Boxes, Environment, Heightmap


def _ground(moving: bool = True) -> Environment:
    """Bumpy ground 16 m square, with (``moving``) an avoided crate sliding across both lanes."""
    x = np.arange(-4.0, 12.0, 0.05)
    y = np.arange(-6.0, 6.0, 0.05)
    gx, gy = np.meshgrid(x, y)
    hm = Heightmap(0.04 * np.sin(gx * 1.1) * np.cos(gy * 0.9), np.array([x[0], y[0]]), 0.05)
    if not moving:
        return Environment(hm)
    boxes = Boxes(np.array([[2.0, 0.0, 0.0]]), np.array([[0.4, 0.4, 0.5]]), np.zeros(1),
                  np.array([ROLE_AVOID]), np.array([True]))
    return Environment(hm, boxes)


def _slide(sim: Simulation) -> None:
    """The crate slides along y through the spider's lane (y = 2) and the wolf's (y = -2)."""
    sim.env.boxes.center[0, :2] = [1.6, 3.0 * np.sin(0.8 * sim.time)]


def _creature(m: Morphology, preset: str) -> tuple[Morphology, object, float, float, ControllerParams]:
    """``m`` with its preset's gait, speed and step height (leg lengths) and its scaled
    controller settings."""
    p = find_gait_preset(preset)
    leg = float(m.leg_length.mean())
    params, _ = scaled_params(leg, p.step_height * leg)
    return m, p.gait(m.labels), p.speed * leg, p.step_height * leg, params


def _run(chars: list[tuple[Morphology, object, float, float, ControllerParams]], start_y: list[float],
         n: int = 48) -> SimResult:
    env = _ground()
    sim = Simulation(
        env, [c[0] for c in chars], [c[1] for c in chars],  # type: ignore[misc]
        start_xy=[[0.0, y] for y in start_y], start_yaw=0.0,
        controls=Controls(speed=[c[2] for c in chars], heading=0.0, step_height=[c[3] for c in chars],
                          pelvis_physics=True),
        params=[c[4] for c in chars], dt=1.0 / 24.0,
    )
    return sim.run(n, on_step=_slide)


def test_each_character_walks_with_its_own_scaled_settings_as_it_would_alone() -> None:
    spider = _creature(morph.spider(0.5), "octopod_alternating_tetrapod")
    wolf = _creature(morph.quadruped(1.45, spine=False), "quadruped_walk")
    sp, wp = spider[4], wolf[4]
    # really different settings: cells, slices, tolerances and gravity all scale
    assert sp.window_cell is not None
    assert wp.window_cell is not None
    assert wp.window_cell > 2.0 * sp.window_cell
    assert wp.physics.gravity > 2.0 * sp.physics.gravity
    both = _run([spider, wolf], [2.0, -2.0])
    alone = [_run([spider], [2.0]), _run([wolf], [-2.0])]
    legs = both.legs.leg_char
    for i, one in enumerate(alone):
        sel = legs == i
        # the same decisions, the same motion (two batchings: floats not bit for bit)
        np.testing.assert_array_equal(both.contact[:, sel], one.contact)
        np.testing.assert_array_equal(both.forced[:, sel], one.forced)
        for name in ("joints", "foot", "footprint"):
            np.testing.assert_allclose(getattr(both, name)[:, sel], getattr(one, name), rtol=0.0, atol=1e-9,
                                       err_msg=name)
        for name in ("pelvis_position", "pelvis_rotation", "needle"):
            np.testing.assert_allclose(getattr(both, name)[:, i], getattr(one, name)[:, 0], rtol=0.0,
                                       atol=1e-9, err_msg=name)
        report = check_motion(both, _ground(), chars=[i])
        assert report.passed, report.failures()


def _wolves(sizes: list[float], spine: list[SpineParams], start_y: list[float],
            n: int = 60) -> tuple[SimResult, int]:
    """Wolves of ``sizes`` (with their scaled settings and their own spine settings) walking
    on the bumpy ground, turning left after a second; the result and how many spine groups
    the simulation stepped them in."""
    wolves = [_creature(morph.quadruped(s, spine=True), "quadruped_walk") for s in sizes]

    def controls(t: float) -> Controls:
        return Controls(speed=[w[2] for w in wolves], heading=0.6 if t > 1.0 else 0.0,
                        step_height=[w[3] for w in wolves], pelvis_physics=True)

    sim = Simulation(_ground(), [w[0] for w in wolves], [w[1] for w in wolves],  # type: ignore[misc]
                     start_xy=[[0.0, y] for y in start_y], start_yaw=0.0, controls=controls,
                     params=[w[4] for w in wolves], spine=spine, dt=1.0 / 24.0)
    return sim.run(n, on_step=_slide), len(sim.controller.spine_groups)


def test_wolves_of_other_sizes_and_spine_settings_share_one_spine_group_and_walk_as_alone() -> None:
    """Copies of a rig in a herd differ in size and settings: their spines are stepped as one
    group (one set of array operations for all), each with its own rest pose and settings,
    and each walks exactly as it does alone."""
    sizes, start_y = [1.2, 1.45, 1.0], [2.0, -2.0, 0.0]
    spine = [SpineParams(), SpineParams(turn_rate=np.radians(80), relax_time=0.3, foot_pitch_weight=0.8),
             SpineParams(visual_yaw=True, max_visual_yaw=np.radians(20))]
    herd, groups = _wolves(sizes, spine, start_y)
    assert groups == 1
    legs = herd.legs.leg_char
    for i in range(3):
        one, alone_groups = _wolves([sizes[i]], [spine[i]], [start_y[i]])
        assert alone_groups == 1
        sel = legs == i
        # the same decisions, the same motion (two batchings: floats not bit for bit)
        np.testing.assert_array_equal(herd.contact[:, sel], one.contact)
        for name in ("joints", "foot", "footprint"):
            np.testing.assert_allclose(getattr(herd, name)[:, sel], getattr(one, name), rtol=0.0, atol=1e-9,
                                       err_msg=name)
        for name in ("pelvis_position", "pelvis_rotation", "spine_joints", "spine_rotation"):
            np.testing.assert_allclose(getattr(herd, name)[:, i], getattr(one, name)[:, 0], rtol=0.0,
                                       atol=1e-9, err_msg=name)


def test_settings_other_than_the_scaled_ones_must_agree() -> None:
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    env = Environment(Heightmap(np.zeros((40, 40)), np.array([-1.0, -1.0]), 0.05))
    a = ControllerParams()
    with pytest.raises(ValueError, match="max_turn_rate"):
        Simulation(env, [m, m], gait, start_xy=[[0, 0], [0, 1]], params=[a, replace(a, max_turn_rate=1.0)])
    with pytest.raises(ValueError, match="physics"):
        Simulation(env, [m, m], gait, start_xy=[[0, 0], [0, 1]],
                   params=[a, replace(a, physics=replace(a.physics, max_substep=0.01))])
    with pytest.raises(ValueError, match="1 controller settings for 2 characters"):
        Simulation(env, [m, m], gait, start_xy=[[0, 0], [0, 1]], params=[a])


# ---------------------------------------------------------------- rigs that see each other


def _flat(half: float = 5.0) -> Environment:
    n = int(2 * half / 0.05)
    return Environment(Heightmap(np.zeros((n, n)), np.array([-half, -half]), 0.05))


def _spider() -> tuple[Morphology, object]:
    m = morph.spider()
    return m, find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)


def _box_overlap(res: SimResult, a: int, b: int) -> float:
    """Largest overlap (m, along the line between them) of two characters' body boxes seen
    as discs of their half widths: > 0 when the bodies run into each other."""
    half = [float(np.min(res.legs.morphologies[i].body_box_half)) for i in (a, b)]
    d = np.linalg.norm(res.pelvis_position[:, a, :2] - res.pelvis_position[:, b, :2], axis=1)
    return float(np.max(half[0] + half[1] - d))


def _planted_gap(res: SimResult) -> float:
    """Smallest distance (m) between two planted feet of different characters at any frame,
    less the larger sole half size: > 0 when no foot stands on another's."""
    legs = res.legs
    sole = max(float(np.max(m.foot_half_extents if m.sole_half_extents is None else m.sole_half_extents))
               for m in legs.morphologies)
    other = legs.leg_char[:, None] != legs.leg_char[None, :]
    gap = np.inf
    for f in range(res.n_frames):
        down = res.contact[f]
        pair = other & down[:, None] & down[None, :]
        if pair.any():
            xy = res.foot[f, :, :2]
            d = np.linalg.norm(xy[:, None] - xy[None], axis=2)
            gap = min(gap, float(d[pair].min()))
    return gap - sole


def _walk(morphs: list[tuple[Morphology, object]], xy: list[list[float]], heading: list[float], avoid: bool,
          n: int, speed: float = 0.3) -> SimResult:
    sim = Simulation(_flat(), [m for m, _ in morphs], [g for _, g in morphs],  # type: ignore[misc]
                     start_xy=xy, start_yaw=heading,
                     controls=Controls(speed=speed, heading=heading, step_height=0.05),
                     avoid=[avoid] * len(morphs))
    return sim.run(n)


def test_two_spiders_walking_head_on_pass_each_other_and_keep_off_each_other() -> None:
    spider = _spider()
    xy, heading = [[-1.0, 0.0], [1.0, 0.0]], [0.0, np.pi]
    on = _walk([spider, spider], xy, heading, avoid=True, n=230)
    # they pass: from 2 m apart to each a metre past the other, back on its heading
    assert on.pelvis_position[-1, 0, 0] - on.pelvis_position[-1, 1, 0] > 1.0
    np.testing.assert_allclose(np.cos(on.yaw[-1]), [1.0, -1.0], atol=1e-6)
    # no foot ever inside the other's body box; the bodies never touch
    assert crowd_intrusion(on).max() == 0.0
    assert _box_overlap(on, 0, 1) < 0.0
    # and both walk as cleanly as alone
    for i in (0, 1):
        report = check_motion(on, _flat(), chars=[i])
        assert report.passed, report.failures()
    assert on.stats["n_failed"].sum() == 0
    # switched off they walk straight through each other (their bodies overlap)
    off = _walk([spider, spider], xy, heading, avoid=False, n=105)
    assert _box_overlap(off, 0, 1) > 0.1
    assert np.abs(off.pelvis_position[:, :, 1]).max() < 0.01


def test_a_spider_and_a_wolf_crossing_at_right_angles_let_each_other_pass() -> None:
    wolf_m = morph.quadruped(1.0, spine=True)
    wolf = (wolf_m, find_gait_preset("quadruped_walk").gait(wolf_m.labels))
    spider = _spider()
    # both would reach the origin at about the same time
    xy, heading = [[-1.4, 0.0], [0.0, -1.6]], [0.0, 0.5 * np.pi]
    on = _walk([spider, wolf], xy, heading, avoid=True, n=300, speed=0.35)
    assert crowd_intrusion(on).max() == 0.0
    # one gives way to the other, both go on past the crossing, back on their headings
    assert on.pelvis_position[-1, 0, 0] > 0.3
    assert on.pelvis_position[-1, 1, 1] > 1.0
    np.testing.assert_allclose(on.yaw[-1], heading, atol=1e-6)
    d = np.linalg.norm(on.pelvis_position[:, 0, :2] - on.pelvis_position[:, 1, :2], axis=1)
    assert d.min() > 0.6
    for i in (0, 1):
        report = check_motion(on, _flat(), chars=[i])
        assert report.passed, report.failures()
    off = _walk([spider, wolf], xy, heading, avoid=False, n=135, speed=0.35)
    assert _box_overlap(off, 0, 1) > 0.0
    assert np.linalg.norm(off.pelvis_position[:, 0, :2] - off.pelvis_position[:, 1, :2], axis=1).min() < 0.3


@settings(max_examples=3, deadline=None)
@given(st.integers(2, 5), st.integers(0, 2 ** 16))
def test_random_small_crowds_keep_their_feet_off_each_other(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    ant = morph.hexapod(0.8)
    kinds = [_spider(), (ant, find_gait_preset("hexapod_tripod").gait(ant.labels))]
    morphs = [kinds[int(k)] for k in rng.integers(0, 2, n)]
    # on a ring of 1.3 m, facing roughly across it
    ang = 2.0 * np.pi * (np.arange(n) + rng.uniform(-0.2, 0.2, n)) / n
    xy = (1.3 * np.column_stack([np.cos(ang), np.sin(ang)])).tolist()
    heading = (ang + np.pi + rng.uniform(-0.6, 0.6, n)).tolist()
    res = _walk(morphs, xy, heading, avoid=True, n=60)
    assert np.isfinite(res.joints).all()
    assert crowd_intrusion(res).max() == 0.0
    assert _planted_gap(res) > 0.0
    legs = res.legs
    assert mx.bone_length_error(res.joints, legs.segment_lengths, legs.n_segments).max() < 1e-6
