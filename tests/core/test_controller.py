# SPDX-License-Identifier: GPL-3.0-or-later
"""Character controller: footprints, re-plans, forced steps, feedback, reach guard, LOD."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pytest

from procloco_addon.core.geometry import rotation_matrices
from procloco_addon.core.locomotion import fallback, obstacles, pelvis, reach, spine_link
from procloco_addon.core.locomotion import morphology as morph
from procloco_addon.core.locomotion.controller import Controller
from procloco_addon.core.locomotion.footprints import Couple, FootRequest, plan_footsteps
from procloco_addon.core.locomotion.gait import find_gait_preset
from procloco_addon.core.locomotion.morphology import LegBatch
from procloco_addon.core.locomotion.rig import rate_scale, stroke_limits
from procloco_addon.core.locomotion.sim import Controls, Simulation, check_motion
from procloco_addon.core.locomotion.state import Phase
from procloco_addon.core.locomotion.types import ControllerParams, StepControls
from procloco_addon.core.world.pathing import FootTrajectory
from procloco_addon.core.world.terrain import (
    NO_SURFACE,
    ROLE_AVOID,
    ROLE_STEP_OVER,
    Boxes,
    Environment,
    Heightmap,
)
from tests.core.cross_path import assert_close


def _plan_each_foot_with(monkeypatch: pytest.MonkeyPatch, plan: Callable[[FootRequest], object]) -> None:
    """Make the controller's batched planner answer each foot's request with ``plan``, so a
    test can fail or bend chosen plans."""
    from procloco_addon.core.locomotion import planning as planning_module

    def batched(requests: Sequence[FootRequest]) -> list[object]:
        return [plan(r) for r in requests]

    monkeypatch.setattr(planning_module, "plan_footsteps", batched)

def _flat(half: float = 4.0, boxes: Boxes | None = None) -> Environment:
    n = int(2 * half / 0.05)
    return Environment(Heightmap(np.zeros((n, n)), np.array([-half, -half]), 0.05), boxes)


def _controls(
    legs: LegBatch,
    speed: float = 0.3,
    heading: float = 0.0,
    spacing: np.ndarray | None = None,
    ik: bool = True,
) -> StepControls:
    c = legs.n_chars
    return StepControls(
        speed=np.full(c, speed),
        heading=np.full(c, heading),
        step_height=np.full(c, 0.05),
        spacing=np.zeros((legs.n_legs, 2)) if spacing is None else spacing,
        pelvis_physics=np.zeros(c, dtype=bool),
        ik=np.full(c, ik),
    )


def _spider_controller(env: Environment, **kw: object) -> tuple[Controller, LegBatch]:
    m = morph.spider()
    legs = LegBatch.stack([m])
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    ctrl = Controller(env, legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs), **kw)  # type: ignore[arg-type]
    return ctrl, legs


def test_rotation_convention_yaw_ccw_pitch_nose_up_roll_left_up() -> None:
    r = rotation_matrices(
        np.array([np.pi / 2, 0.0, 0.0]), np.array([0.0, 0.3, 0.0]), np.array([0.0, 0.0, 0.3])
    )
    np.testing.assert_allclose(r[0] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    assert (r[1] @ [1.0, 0.0, 0.0])[2] == pytest.approx(np.sin(0.3))
    assert (r[2] @ [0.0, 1.0, 0.0])[2] == pytest.approx(np.sin(0.3))
    np.testing.assert_allclose(
        r @ np.transpose(r, (0, 2, 1)), np.broadcast_to(np.eye(3), (3, 3, 3)), atol=1e-12
    )


def test_rotation_matrices_are_yaw_then_pitch_then_roll_multiplied() -> None:
    rng = np.random.default_rng(2)
    yaw, pitch, roll = rng.uniform(-np.pi, np.pi, (3, 40))

    def about(axis: int, angle: np.ndarray) -> np.ndarray:
        c, s = np.cos(angle), np.sin(angle)
        i, j = (axis + 1) % 3, (axis + 2) % 3  # right-handed about the axis
        out = np.zeros((angle.size, 3, 3))
        out[:, axis, axis] = 1.0
        out[:, i, i], out[:, i, j], out[:, j, i], out[:, j, j] = c, -s, s, c
        return out

    # nose up is a turn about -y
    want = about(2, yaw) @ about(1, -pitch) @ about(0, roll)
    assert_close(rotation_matrices(yaw, pitch, roll), want, "rotations")


def _mid_stance_offsets(res: object, speed: float) -> dict[int, list[np.ndarray]]:
    """Each stance's foot position relative to the pelvis at mid-stance, per leg."""
    out: dict[int, list[np.ndarray]] = {}
    contact = res.contact  # type: ignore[attr-defined]
    for leg in range(contact.shape[1]):
        col = contact[:, leg].astype(int)
        downs = np.flatnonzero(np.diff(col) == 1) + 1
        ups = np.flatnonzero(np.diff(col) == -1) + 1
        for d in downs:
            later = ups[ups > d]
            if later.size:
                t_mid = 0.5 * (res.time[d] + res.time[later[0]])  # type: ignore[attr-defined]
                out.setdefault(leg, []).append(res.foot[d, leg, :2] - [speed * t_mid, 0.0])  # type: ignore[attr-defined]
    return out


def test_flat_ground_footprint_is_the_preferred_one_and_feet_pass_under_their_rest_spot() -> None:
    # thesis sequence 1: on free flat ground the planner keeps the controller's footprint
    env = _flat()
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    sim = Simulation(env, [m], gait, controls=Controls(speed=0.3, heading=0.0, step_height=0.05))
    res = sim.run(75)
    assert check_motion(res, env).passed
    planted = res.contact[1:] & ~res.contact[:-1]
    assert planted.sum() > 10
    np.testing.assert_allclose(
        res.footprint[1:][planted][:, :2], res.preferred[1:][planted][:, :2], atol=1e-9
    )
    # at mid-stance each foot is under its rest position (figures 3.6, 3.7)
    for leg, offsets in _mid_stance_offsets(res, 0.3).items():
        np.testing.assert_allclose(
            offsets, np.broadcast_to(m.rest_foot[leg, :2], (len(offsets), 2)), atol=0.3 * 0.5 / 30 + 1e-6
        )


def test_spacing_offsets_move_the_feet() -> None:
    env = _flat()
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    spacing = np.zeros((8, 2))
    spacing[:, 1] = np.where(np.arange(8) % 2 == 0, 0.04, -0.04)  # feet 4 cm wider apart

    def controls(t: float) -> Controls:
        return Controls(speed=0.3, heading=0.0, step_height=0.05, spacing=spacing if t >= 1.0 else None)

    sim = Simulation(env, [m], gait, controls=controls)
    res = sim.run(105)
    assert check_motion(res, env).passed
    late = {leg: np.array(v[-2:]) for leg, v in _mid_stance_offsets(res, 0.3).items()}
    for leg, offsets in late.items():
        # within a planning cell of the asked-for spot (other feet may push a footprint aside)
        np.testing.assert_allclose(
            offsets, np.broadcast_to(m.rest_foot[leg, :2] + spacing[leg], offsets.shape), atol=0.04
        )
    widths = np.array([late[leg][:, 1].mean() for leg in range(8)])
    rest_widths = m.rest_foot[:, 1]
    assert np.all(np.abs(widths) > np.abs(rest_widths) + 0.02)


def test_fast_walking_shortens_the_cycle_instead_of_overstretching() -> None:
    env = _flat(6.0)
    ctrl, legs = _spider_controller(env)
    leg = float(legs.leg_length.mean())
    speed = 1.5  # a 0.55-stance cycle of 0.7 s would sweep 0.58 m, 1.07 leg lengths
    for _ in range(60):
        ctrl.step(1.0 / 30.0, _controls(legs, speed=speed))
    sweep = speed * (1.0 - ctrl.gait.disk_duration.min()) * ctrl.gait.cycle_time[0] / ctrl.gait.rate_scale[0]
    assert ctrl.gait.rate_scale[0] > 1.0
    # the sweep is the longest the legs allow: never more than max_stroke, and for this
    # spider less (neighbouring feet a planning cell apart, see test_stroke_limits_*)
    assert sweep <= ctrl.stroke_limit[0]
    assert sweep == pytest.approx(ctrl.stroke_limit[0], rel=1.0 / 1024.0)
    assert ctrl.stroke_limit[0] <= ControllerParams().max_stroke * leg


def _moving_box_run(box_path: np.ndarray, frames: int) -> tuple[Environment, object]:
    boxes = Boxes(
        np.array([box_path[0]]),
        np.array([[0.3, 0.3, 0.05]]),
        np.zeros(1),
        np.array([ROLE_STEP_OVER]),
        np.array([True]),
    )
    env = _flat(4.0, boxes)
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    sim = Simulation(env, [m], gait, controls=Controls(speed=0.2, heading=0.0, step_height=0.08))

    def move(s: Simulation) -> None:
        k = min(round(s.time * 30), len(box_path) - 1)
        env.move_boxes(np.array([0]), box_path[k][None], np.zeros(1))

    return env, sim.run(frames, on_step=move)


def test_a_crate_sliding_under_a_planted_foot_makes_it_step_onto_a_valid_footprint() -> None:
    # thesis sequence 4: the crate comes from the side and passes under the right feet
    frames = 90
    path = np.column_stack(
        [np.full(frames + 1, 0.15), np.linspace(-1.2, 0.3, frames + 1), np.zeros(frames + 1)]
    )
    env, res = _moving_box_run(path, frames)
    report = check_motion(res, env)  # type: ignore[arg-type]
    assert report.passed, report.failures()
    assert res.forced.any()  # type: ignore[attr-defined]
    assert res.stats["n_forced"].sum() > 0  # type: ignore[attr-defined]


def test_a_crate_moving_into_a_swing_trajectory_triggers_a_replan() -> None:
    # thesis sequences 1 and 2: the crate moves across the path of the swinging feet
    frames = 60
    path = np.column_stack(
        [np.full(frames + 1, 0.55), np.linspace(-1.0, 1.0, frames + 1), np.zeros(frames + 1)]
    )
    env, res = _moving_box_run(path, frames)
    report = check_motion(res, env)  # type: ignore[arg-type]
    assert report.passed, report.failures()
    assert res.stats["n_replans"].sum() > 0  # type: ignore[attr-defined]


def test_feet_feedback_moves_the_pelvis_only_when_significant() -> None:
    ctrl, legs = _spider_controller(_flat())
    leg = float(legs.leg_length.mean())
    start = ctrl.pos.copy()
    lengths = ctrl.rig.char_leg_length

    def move(dt: float) -> np.ndarray | None:
        cycle = ctrl.gait.cycle_time
        return pelvis.feedback_move(ctrl.leg_char, ctrl.params, ctrl.feedback, lengths, cycle, dt)

    ctrl.feedback[:] = [0.02 * leg, 0.0]  # below the threshold: ignored
    assert move(0.1) is None
    np.testing.assert_allclose(ctrl.feedback[:, 0], 0.02 * leg)
    ctrl.feedback[:] = [0.0, 0.3 * leg]
    moved = move(0.07)
    share = 0.07 / ctrl.gait.cycle_time[0]
    assert moved is not None
    np.testing.assert_allclose(moved[0], [0.0, 0.3 * leg * share])
    np.testing.assert_allclose(ctrl.pos, start)  # the move is the caller's to apply
    # the part worked off is consumed, so the pelvis does not drift forever
    np.testing.assert_allclose(ctrl.feedback[:, 1], 0.3 * leg * (1.0 - share))


def test_reach_guard_lowers_the_pelvis_to_keep_legs_within_reach() -> None:
    ctrl, _ = _spider_controller(_flat())
    ctrl.foot[0, 2] -= 0.3  # a foot in a hole
    drop = reach.guard_drop(ctrl.rig, ctrl.params, ctrl.hips_world(), ctrl.foot, ctrl.link.spine_legs)
    assert drop[0] > 0.0
    ctrl.pos[:, 2] -= drop
    hips = ctrl.hips_world()
    dist = np.linalg.norm(hips - ctrl.foot, axis=1)
    assert np.all(dist <= ctrl.guard_reach + 1e-9)
    assert dist[0] == pytest.approx(ctrl.guard_reach[0])


def test_a_foot_left_behind_steps_early() -> None:
    ctrl, legs = _spider_controller(_flat())
    planted = 6  # L4, a hind leg standing at the start
    assert not ctrl.swinging[planted]
    ctrl.foot[planted, 0] -= 0.25  # far behind its hip
    left = ctrl.foot[planted].copy()
    hip_before = np.linalg.norm(ctrl.hips_world()[planted] - left)
    ctrl.step(1.0 / 30.0, _controls(legs))
    assert ctrl.forced[planted]
    assert ctrl.swinging[planted]
    # it leaves in the frame it starts: a frame later the stretched leg would miss it
    assert ctrl.foot[planted, 2] > left[2] + 1e-4
    assert np.linalg.norm(ctrl.hips_world()[planted] - ctrl.foot[planted]) < hip_before


def test_no_ground_ahead_fails_plans_cleanly_and_keeps_feet_planted() -> None:
    # the heightmap ends just ahead of the spider: there is nowhere to step
    env = Environment(Heightmap(np.zeros((40, 40)), np.array([-1.2, -1.0]), 0.05))
    ctrl, legs = _spider_controller(env)
    failures = 0
    frames_failed = 0
    for _ in range(50):
        stats = ctrl.step(1.0 / 30.0, _controls(legs, speed=0.5))
        failures += stats.n_failed
        res = ctrl.ik_result
        assert res is not None
        assert np.all(np.isfinite(res.joints))
        # a foot whose plan failed stays on the ground (checked at every step: which feet
        # are between swings at the last step depends on the cycle)
        frames_failed += int(ctrl.plan_failed.any())
        assert np.all(ctrl.foot[ctrl.plan_failed, 2] == 0.0)
        assert not np.any(ctrl.swinging & ctrl.plan_failed)
        # a foot forced to step for lack of anywhere better never lands on nothing
        assert np.all(env.height_at(ctrl.foot[~ctrl.swinging, :2]) > NO_SURFACE / 2)
        assert np.all(env.height_at(ctrl.target[ctrl.swinging, :2]) > NO_SURFACE / 2)
    assert failures > 0
    assert frames_failed > 0


def test_ik_off_keeps_the_previous_angles() -> None:
    ctrl, legs = _spider_controller(_flat())
    before = ctrl.angles.copy()
    for _ in range(5):
        ctrl.step(1.0 / 30.0, _controls(legs, ik=False))
    np.testing.assert_array_equal(ctrl.angles, before)


def test_switching_pelvis_physics_on_does_not_jump() -> None:
    ctrl, legs = _spider_controller(_flat())
    z = []
    for k in range(40):
        ctl = _controls(legs)
        ctl = StepControls(ctl.speed, ctl.heading, ctl.step_height, ctl.spacing, np.full(1, k >= 20), ctl.ik)
        ctrl.step(1.0 / 30.0, ctl)
        z.append(ctrl.pos[0, 2])
    assert np.abs(np.diff(z)).max() < 0.01


def test_spine_settings_need_a_spine_and_give_each_girdle_its_pelvis_node() -> None:
    from procloco_addon.core.locomotion.spine import SpineParams

    env = _flat()
    plain, dog = morph.quadruped(), morph.quadruped(spine=True)
    legs = LegBatch.stack([plain, dog, dog])
    gait = find_gait_preset("quadruped_walk").gait(plain.labels)
    start = np.array([[0.0, 0.0], [0.0, 1.5], [0.0, -1.5]])
    with pytest.raises(ValueError, match="character 0 has spine settings but its morphology has no spine"):
        Controller(env, legs, [gait] * 3, start, np.zeros(3), _controls(legs),
                   spine=[SpineParams(), None, None])
    still = _controls(legs, speed=0.0)  # feet at their rest places
    ctrl = Controller(env, legs, [gait] * 3, start, np.zeros(3), still, spine=[None, SpineParams(), None])
    # one node for each rigid body, three (head, shoulders, hips) for the spine
    assert ctrl.n_nodes == 1 + 3 + 1
    assert ctrl.leg_node.tolist() == [0, 0, 0, 0, 2, 2, 3, 3, 4, 4, 4, 4]
    # standing at rest, the spine is the rigid body: same hips, frames and body pose
    up = np.array([0.0, 3.0, 0.0])
    np.testing.assert_allclose(ctrl.hips_world()[4:8], ctrl.hips_world()[8:12] + up, atol=1e-12)
    np.testing.assert_allclose(ctrl.leg_rotations()[4:8], np.broadcast_to(np.eye(3), (4, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(ctrl.pos[1], ctrl.pos[2] + up, atol=1e-12)
    joints = ctrl.spine_joints()
    assert joints.shape == (3, 7, 3)
    np.testing.assert_allclose(joints[1], dog.spine.joint_rest + ctrl.pos[1], atol=1e-12)  # type: ignore[union-attr]
    np.testing.assert_array_equal(joints[0], np.repeat(ctrl.pos[:1], 7, axis=0))


# ---------------------------------------------------------------------------------------
# Robustness at real speeds and near moving obstacles


def _row_of_legs(gap: float, reach_y: float = 0.4) -> LegBatch:
    """Four legs, two per side, their rest feet in a row ``gap`` apart along x."""
    chains = []
    for x in (0.5 * gap, -0.5 * gap):
        for side in (1.0, -1.0):
            hip = np.array([0.3 * x, side * 0.05, 0.0])
            foot = np.array([x, side * reach_y, -0.2])
            chains.append(np.array([hip, 0.5 * (hip + foot) + np.array([0.0, 0.0, 0.12]), foot]))
    return LegBatch.stack([morph.Morphology.from_rest_joints(chains, morph.leg_labels(4))])


def test_stroke_limits_keep_neighbouring_feet_a_clearance_apart() -> None:
    legs = _row_of_legs(gap=0.3)
    far = np.full(4, 10.0)
    clearance = np.array([0.08])
    # the front foot lifts half a stroke behind its rest spot while the hind one lands half a
    # stroke ahead of its own: they meet when the stroke eats the gap less the clearance
    limit = stroke_limits(legs, far, np.zeros(4), clearance, np.array([1.0]))
    assert limit[0] == pytest.approx(0.3 - 0.08, abs=1.0 / 96.0)
    assert limit[0] <= 0.3 - 0.08 + 1e-12
    # feet far apart: only the cap binds
    assert stroke_limits(_row_of_legs(gap=3.0), far, np.zeros(4), clearance, np.array([1.0]))[0] == 1.0


def test_stroke_limits_keep_feet_within_reach_at_both_ends_of_the_sweep() -> None:
    legs = _row_of_legs(gap=0.3)
    rest = legs.rest_foot - legs.hip_offset
    reach = np.full(4, 0.45)
    low = np.full(4, 0.2)
    limit = stroke_limits(legs, reach, low, np.array([0.0]), np.array([10.0]))[0]
    horizontal = np.sqrt(0.45**2 - 0.2**2)
    expected = 2.0 * (np.sqrt(horizontal**2 - rest[:, 1] ** 2) - np.abs(rest[:, 0])).min()
    assert limit == pytest.approx(expected)
    # at that sweep every foot is exactly within reach at its far end
    ends = rest[:, :2] + np.array([[0.5 * limit, 0.0]]) * np.sign(rest[:, :1])
    assert np.hypot(ends[:, 0], ends[:, 1]).max() == pytest.approx(horizontal)


def test_the_needle_starts_at_the_speed_the_stroke_limit_asks_for() -> None:
    # a fast start must not place the feet as if the cycle were the gait's own (too long)
    env = _flat(6.0)
    m = morph.spider()
    legs = LegBatch.stack([m])
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    ctrl = Controller(env, legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs, speed=1.5))
    assert ctrl.gait.rate_scale[0] > 1.0
    hips = ctrl.hips_world()
    assert np.all(np.linalg.norm(ctrl.foot - hips, axis=1) <= ctrl.comfort_reach + 1e-9)


def test_a_rigid_body_turning_fast_shortens_its_steps() -> None:
    ctrl, _ = _spider_controller(_flat())
    speed = np.array([0.2])
    straight = rate_scale(ctrl.rig, ctrl.gait, ctrl.link.has_spine, speed, np.zeros(1))
    turning = rate_scale(ctrl.rig, ctrl.gait, ctrl.link.has_spine, speed, np.array([2.0]))
    # planted feet far from the pelvis sweep sideways in a turn: the cycle runs faster
    assert turning[0] > straight[0] >= 1.0


def test_a_foot_whose_swing_could_not_be_planned_still_steps_when_left_behind(
    monkeypatch: pytest.MonkeyPatch,
) -> None:

    clock = {"t": 0.0}

    def flaky(rq: FootRequest) -> object:
        # every normal plan fails for a while; a foot forced to step (planned without
        # slices) is served
        if 0.5 <= clock["t"] < 1.2 and rq.params.slice_size is not None:
            start = np.asarray(rq.foot_start, dtype=np.float64)
            return Couple(ok=False, footprint=start, trajectory=None, score=0.0, target_score=0.0,
                          path_score=0.0, n_couples=0, n_paths=0, message="test", n_targets=1)
        return plan_footsteps([rq])[0]

    _plan_each_foot_with(monkeypatch, flaky)
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    sim = Simulation(_flat(6.0), [m], gait, controls=Controls(speed=0.5, heading=0.0, step_height=0.05))

    def tick(s: Simulation) -> None:
        clock["t"] = s.time

    res = sim.run(60, on_step=tick)
    assert res.stats["n_failed"].sum() > 0
    assert res.forced.any()
    report = check_motion(res, sim.env)
    # no planted foot dragged along, no leg asked to stretch
    assert report.stance_slide.max() <= 0.002, report.failures()
    assert report.extension.max() <= 1.0 + 1e-6, report.failures()


def _avoided_crate_run(
    path: np.ndarray, frames: int, size: tuple[float, float, float]
) -> tuple[Environment, object]:
    boxes = Boxes(np.array([path[0]]), np.array([size]), np.zeros(1), np.array([ROLE_AVOID]),
                  np.array([True]))
    env = _flat(4.0, boxes)
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    sim = Simulation(env, [m], gait, controls=Controls(speed=0.05, heading=0.0, step_height=0.05))

    def move(s: Simulation) -> None:
        k = min(round((s.time + s.dt) * 30), len(path) - 1)
        env.move_boxes(np.array([0]), path[k][None], np.zeros(1))

    return env, sim.run(frames, on_step=move)


def test_a_tall_crate_sliding_at_planted_feet_makes_them_step_away_before_it_arrives() -> None:
    # an avoided crate, taller than the spider's step, comes from the side at 0.6 m/s and
    # passes where the right feet stand
    frames = 60
    size = (0.2, 0.2, 0.25)
    path = np.column_stack(
        [np.full(frames + 1, 0.1), np.linspace(-1.2, 0.0, frames + 1), np.zeros(frames + 1)]
    )
    env, res = _avoided_crate_run(path, frames, size)
    ends = res.end_effector  # type: ignore[attr-defined]
    # the crate where it stood at each frame: no foot ever inside it
    from procloco_addon.core import metrics as mx

    k = np.minimum(np.round(res.time * 30).astype(int), frames)  # type: ignore[attr-defined]
    box_size = np.array([size])
    inside = [mx.box_intrusion(ends[f], path[k[f]][None], box_size, np.zeros(1)).max() for f in range(len(k))]
    assert max(inside) <= 0.005
    report = check_motion(res, env)  # type: ignore[arg-type]
    assert report.passed, report.failures()
    # nothing was popped onto its top: feet stay on the ground
    assert ends[..., 2].max() < size[2]
    assert res.stats["n_forced"].sum() > 0  # type: ignore[attr-defined]


def test_a_crate_that_lands_on_a_planted_foot_pushes_it_aside_not_onto_its_top() -> None:
    boxes = Boxes(np.array([[0.0, -2.0, 0.0]]), np.array([[0.16, 0.16, 0.25]]), np.zeros(1),
                  np.array([ROLE_AVOID]), np.array([True]))
    env = _flat(4.0, boxes)
    ctrl, legs = _spider_controller(env)
    planted = int(np.flatnonzero(~ctrl.swinging)[0])
    spot = ctrl.foot[planted].copy()
    # too fast to see coming: in one step the crate stands on the foot
    env.move_boxes(np.array([0]), np.array([[spot[0] + 0.03, spot[1], 0.0]]), np.zeros(1))
    ctrl.step(1.0 / 30.0, _controls(legs, speed=0.0))
    foot = ctrl.foot[planted]
    assert foot[2] < 0.05  # stepping away (at most the step height up), not lifted 25 cm onto the crate
    from procloco_addon.core import metrics as mx

    box = env.boxes
    assert mx.box_intrusion(foot[None], box.center, box.size, box.yaw)[0] == 0.0
    assert np.linalg.norm(foot[:2] - spot[:2]) < 0.15  # shoved aside, a short way


def _failed(start: object) -> Couple:
    return Couple(ok=False, footprint=np.asarray(start, dtype=np.float64), trajectory=None, score=0.0,
                  target_score=0.0, path_score=0.0, n_couples=0, n_paths=0, message="test", n_targets=1)


def test_a_foot_that_must_step_goes_around_a_tall_avoided_crate_not_over_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:

    # the planner finds nothing; a hind foot left behind must step, and a crate taller than
    # the spider stands between it and its preferred spot: the straight fallback goes around
    _plan_each_foot_with(monkeypatch, lambda rq: _failed(rq.foot_start))
    m = morph.spider()
    leg = 6  # L4, planted at the start
    rest = m.rest_foot[leg]
    centre = np.array([rest[0] - 0.12, rest[1], 0.0])
    size = np.array([0.06, 0.16, 0.8])
    env = _flat(4.0, Boxes(centre[None], size[None], np.zeros(1), np.array([ROLE_AVOID]), np.array([False])))
    legs = LegBatch.stack([m])
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    ctrl = Controller(env, legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs, speed=0.0))
    assert not ctrl.swinging[leg]
    ctrl.foot[leg, 0] = rest[0] - 0.25  # far behind its hip, the crate in the way
    ctrl.step(1.0 / 30.0, _controls(legs, speed=0.0))
    assert ctrl.forced[leg]
    assert ctrl.swinging[leg]
    from procloco_addon.core import metrics as mx

    swing = ctrl.traj[leg]
    assert mx.box_intrusion(swing, centre[None], size[None], np.zeros(1)).max() == 0.0
    # never higher than the leg can fold: below its hip
    assert swing[:, 2].max() < ctrl.hips_world()[leg, 2]


def test_a_swing_detouring_beyond_the_legs_reach_is_not_taken(monkeypatch: pytest.MonkeyPatch) -> None:

    holder: dict[str, Controller] = {}

    def detour(start: np.ndarray, end: np.ndarray, width: float) -> FootTrajectory:
        """A trajectory swinging 1.5 leg lengths out to the side (a path around an obstacle)."""
        u = np.linspace(0.0, 1.0, 65)
        line = start[None, :] + u[:, None] * (end - start)[None, :]
        return FootTrajectory.from_points(line + np.outer(np.sin(np.pi * u), [0.0, width, 0.03]))

    def detouring(rq: FootRequest) -> Couple:
        couple = plan_footsteps([rq])[0]
        ctrl = holder["ctrl"]
        leg = int(np.argmin(np.linalg.norm(ctrl.foot - np.asarray(rq.foot_start), axis=1)))
        if not couple.ok or ctrl.forced[leg]:
            return couple  # a foot that must move takes what it gets
        start = np.asarray(rq.foot_start, dtype=np.float64)
        wide = detour(start, couple.footprint, 0.8)
        return Couple(ok=True, footprint=couple.footprint, trajectory=wide,
                      score=couple.score, target_score=couple.target_score, path_score=couple.path_score,
                      n_couples=1, n_paths=1)

    m = morph.spider()
    legs = LegBatch.stack([m])
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    ctrl = Controller(_flat(6.0), legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs))
    holder["ctrl"] = ctrl
    _plan_each_foot_with(monkeypatch, detouring)
    failed = 0
    for _ in range(45):
        failed += ctrl.step(1.0 / 30.0, _controls(legs)).n_failed
        # no foot, planted or swinging, is ever asked to be farther than its leg from its hip
        dist = np.linalg.norm(ctrl.foot - ctrl.hips_world(), axis=1)
        assert np.all(dist <= legs.leg_length + 1e-9)
    assert failed > 0  # the detours were refused (the feet stepped when forced instead)


def _pose_spine(
    ctrl: Controller, z: np.ndarray, physics_on: np.ndarray, dt: float, swinging: np.ndarray,
    swing_u: np.ndarray,
) -> None:
    """Step 4 of the spines with the feet ``swinging`` at swing progress ``swing_u``."""
    rig = ctrl.rig
    at = spine_link.PoseInputs(ctrl.foot, swinging, ctrl.target, swing_u, rig.guard_reach, rig.foot_lift,
                               rig.body_thickness)
    spine_link.pose(ctrl.link, ctrl.body, ctrl.params, at, z, physics_on, dt)


@pytest.mark.parametrize("release", [0.2, 1e-6])
def test_a_spine_node_pulled_to_a_stretched_leg_lets_go_over_the_release_time(release: float) -> None:
    from procloco_addon.core.locomotion.spine import SpineParams

    dog = morph.quadruped(spine=True)
    legs = LegBatch.stack([dog])
    gait = find_gait_preset("quadruped_walk").gait(dog.labels)
    ctrl = Controller(_flat(), legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs, speed=0.0),
                      params=ControllerParams(reach_release_time=release), spine=[SpineParams()])
    ctrl.feet.phase[:] = Phase.PLANTED  # every foot planted
    group = ctrl.spine_groups[0]
    z = np.zeros(ctrl.n_nodes)
    z[group.nodes[0]] = group.height[0]
    off = np.zeros(1, dtype=bool)
    dt = 1.0 / 30.0
    reach = ctrl.guard_reach

    def pose_and_check() -> float:
        _pose_spine(ctrl, z, off, dt, ctrl.swinging, ctrl.feet.swing_u)
        assert np.all(np.linalg.norm(ctrl.foot - ctrl.hips_world(), axis=1) <= reach + 1e-6)
        assert group.reach_shift is not None
        return float(np.linalg.norm(group.reach_shift, axis=-1).max())

    assert pose_and_check() == pytest.approx(0.0, abs=1e-12)  # standing at rest: no pull
    rest = ctrl.foot.copy()
    ctrl.foot[0] += [0.3 * legs.leg_length[0], 0.0, -0.1 * legs.leg_length[0]]  # a front foot far ahead
    pulled = pose_and_check()
    assert pulled > 0.02 * legs.leg_length[0]
    ctrl.foot[:] = rest  # the foot has stepped back under its hip: no leg needs the pull now
    kept = pose_and_check()
    # let go over the release time, not at once (a very short release: at once)
    assert kept == pytest.approx(pulled * np.exp(-dt / release), rel=1e-6, abs=1e-9)


def _wait(ctrl: Controller, candidates: np.ndarray, stretch: np.ndarray, airborne: np.ndarray) -> np.ndarray:
    error = None if ctrl.ik_result is None else ctrl.ik_result.error
    return reach.wait_for_support(ctrl.rig, ctrl.params, candidates, stretch, airborne, error)


def test_a_foot_left_behind_waits_while_too_few_feet_would_stay_down() -> None:
    dog = morph.quadruped()
    legs = LegBatch.stack([dog])
    gait = find_gait_preset("quadruped_walk").gait(dog.labels)
    ctrl = Controller(_flat(), legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs, speed=0.0))
    thick = float(ctrl.body_thickness[0])
    mild = np.full(4, 0.2 * thick)  # left behind, but the pelvis can still sink for it
    none_lifted = np.zeros(4, dtype=bool)
    hind = np.array([False, False, True, True])
    # both front feet in the air: a hind foot stepping now would leave one foot down
    swinging = np.array([True, True, False, False])
    assert _wait(ctrl, hind, mild, swinging | none_lifted).tolist() == [False, False, True, True]
    # unless keeping it would need the pelvis to drop too far: it steps, the other waits
    urgent = mild.copy()
    urgent[3] = 0.5 * thick
    assert _wait(ctrl, hind, urgent, swinging | none_lifted).tolist() == [False, False, True, False]
    # one front foot in the air: the more stretched hind foot steps, the other waits
    swinging = np.array([True, False, False, False])
    more = mild.copy()
    more[2] = 0.25 * thick
    assert _wait(ctrl, hind, more, swinging | none_lifted).tolist() == [False, False, False, True]
    # a foot the gait lifts this frame counts as in the air
    lifting = np.array([False, True, False, False])
    assert _wait(ctrl, hind, more, swinging | lifting).tolist() == [False, False, True, True]
    # a biped keeps one foot down (its other one), not two
    human = morph.biped()
    two = LegBatch.stack([human])
    walk = find_gait_preset("biped_walk").gait(human.labels)
    ctrl2 = Controller(_flat(), two, [walk], np.zeros((1, 2)), np.zeros(1), _controls(two, speed=0.0))
    swinging = np.zeros(2, dtype=bool)
    behind, small, still = np.array([True, False]), np.full(2, 0.01), np.zeros(2, dtype=bool)
    assert _wait(ctrl2, behind, small, swinging | still).tolist() == [False, False]
    swinging = np.array([False, True])
    assert _wait(ctrl2, behind, small, swinging | still).tolist() == [True, False]


def test_a_straight_fallback_step_down_stairs_never_cuts_a_stair_edge() -> None:
    # Stairs going down in +x: 8 cm risers every 12 cm (heightmap cells of 1 cm).
    n = 400
    x = -2.0 + 0.01 * np.arange(n)
    heights = np.broadcast_to(-0.08 * np.floor(np.maximum(x, 0.0) / 0.12), (n, n)).copy()
    env = Environment(Heightmap(heights, np.array([-2.0, -2.0]), 0.01))
    ctrl, legs = _spider_controller(env)
    leg = 0
    u = np.linspace(0.0, 1.0, 7)  # coarse samples: edges fall between them
    checked = 0
    ahead, aside = np.array([0.3, 0.0]), np.array([0.0, 0.05])
    y = float(ctrl.foot[leg, 1])
    for x0 in np.linspace(-0.05, 0.1, 7):
        start = np.array([x0, y, float(env.height_at(np.array([[x0, y]]))[0])])
        hip = ctrl.hips_world()[leg].copy()
        hip[:2] = start[:2] + aside
        hip[2] = start[2] + 0.8 * legs.leg_length[leg]
        got = fallback.straight_step(ctrl.env, ctrl.rig, ctrl.params, leg, start, start[:2] + ahead, u, 0.03,
                                     0.1, hip, hip[:2] + ahead)
        if got is None:
            continue
        samples, _ = got
        # the polyline densely, its vertical ends aside: never below the ground
        t = np.linspace(0.0, 1.0, 60)[:, None]
        dense = (samples[:-1, None, :] * (1.0 - t) + samples[1:, None, :] * t).reshape(-1, 3)
        ground = env.height_at(dense[:, :2])
        ends = samples[[0, -1], :2]
        inner = ~np.isclose(dense[:, None, :2], ends[None, :, :]).all(axis=-1).any(axis=1)
        assert np.all(dense[inner, 2] >= ground[inner] - 1e-9)
        checked += 1
    assert checked >= 4


def test_a_swinging_foot_pulls_its_node_down_to_its_landing_height_as_it_comes_down() -> None:
    from procloco_addon.core.locomotion.spine import SpineParams

    dog = morph.quadruped(spine=True)
    legs = LegBatch.stack([dog])
    gait = find_gait_preset("quadruped_walk").gait(dog.labels)
    ctrl = Controller(_flat(), legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs, speed=0.0),
                      params=ControllerParams(reach_release_time=1e-6), spine=[SpineParams()])
    ctrl.feet.phase[:] = Phase.PLANTED
    group = ctrl.spine_groups[0]
    z = np.zeros(ctrl.n_nodes)
    z[group.nodes[0]] = group.height[0]
    off = np.zeros(1, dtype=bool)
    hip = ctrl.hips_world()[0].copy()
    reach = float(ctrl.guard_reach[0])
    slack = ctrl.params.swing_reach_slack
    # leg 0 swings down a step: its landing is so low that, straight under where the foot is
    # now, it lies just beyond the leg's reach (within the slack)
    swinging = ctrl.swinging
    swinging[0] = True
    swing_u = np.ones(ctrl.n_legs)
    ctrl.foot[0, :2] = hip[:2] + np.array([0.2 * reach, 0.0])
    ctrl.foot[0, 2] = hip[2] - 0.5 * reach
    low = hip[2] - np.sqrt((reach * (1.0 + 0.5 * slack)) ** 2 - (0.2 * reach) ** 2)
    ctrl.target[0] = [ctrl.foot[0, 0] + 0.05, ctrl.foot[0, 1], low]

    def pull_at(progress: float) -> float:
        swing_u[0] = progress
        _pose_spine(ctrl, z, off, 1.0 / 30.0, swinging, swing_u)
        assert group.reach_shift is not None
        return float(np.linalg.norm(group.reach_shift, axis=-1).max())

    assert pull_at(0.0) == pytest.approx(0.0, abs=1e-12)  # just lifted: no pull yet
    mid, late = pull_at(0.6), pull_at(1.0)
    assert 0.0 < mid < late  # more as the foot comes down
    hip_now = ctrl.hips_world()[0]
    down_here = np.array([ctrl.foot[0, 0], ctrl.foot[0, 1], low])
    assert np.linalg.norm(down_here - hip_now) <= reach + 1e-6  # the landing height is in reach


def _gap_env(x0: float, x1: float) -> Environment:
    """Flat ground with a hole (no surface) across the whole width for ``x0 <= x < x1``."""
    n = 300
    heights = np.zeros((n, n))
    x = -5.0 + 0.02 * np.arange(n) + 0.01
    heights[:, (x >= x0) & (x < x1)] = NO_SURFACE
    return Environment(Heightmap(heights, np.array([-5.0, -5.0]), 0.02))


def test_a_footprint_hanging_over_a_hole_moves_onto_the_ground_its_foot_reaches() -> None:
    env = _gap_env(0.0, 0.3)
    ctrl, _ = _spider_controller(env)
    half = float(np.max(ctrl.foot_half[0]))
    shift = obstacles.onto_support(env, ctrl.rig, np.array([0.01, 0.0]), 0)
    assert shift is not None
    assert shift[0] < 0.0
    assert np.linalg.norm(shift) <= 2.5 * half + 1e-9
    assert env.height_at(np.array([[0.01 + shift[0], shift[1]]]))[0] > NO_SURFACE / 2
    # mid-gap: nothing in reach
    assert obstacles.onto_support(env, ctrl.rig, np.array([0.15, 0.0]), 0) is None


def test_walking_over_a_gap_never_plants_a_foot_over_the_hole() -> None:
    dog = morph.quadruped()
    legs = LegBatch.stack([dog])
    gait = find_gait_preset("quadruped_walk").gait(dog.labels)
    for x0 in np.linspace(0.4, 0.8, 9):  # the gap at several places along the strides
        env = _gap_env(float(x0), float(x0) + 0.12)
        ctrl = Controller(env, legs, [gait], np.zeros((1, 2)), np.zeros(1), _controls(legs, speed=0.4))
        crossed = False
        for _ in range(120):
            ctrl.step(1.0 / 30.0, _controls(legs, speed=0.4))
            planted = ~ctrl.swinging
            assert np.all(env.height_at(ctrl.foot[planted, :2]) > NO_SURFACE / 2)
            crossed |= bool(np.all(ctrl.foot[:, 0] > x0 + 0.12))
        assert crossed
