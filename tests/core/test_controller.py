# SPDX-License-Identifier: GPL-3.0-or-later
"""Character controller: footprints, re-plans, forced steps, feedback, reach guard, LOD."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core import morphology as morph
from procloco_addon.core.controller import Controller, ControllerParams, StepControls, rotation_matrices
from procloco_addon.core.gait import find_gait_preset
from procloco_addon.core.morphology import LegBatch
from procloco_addon.core.sim import Controls, Simulation, check_motion
from procloco_addon.core.terrain import ROLE_STEP_OVER, Boxes, Environment, Heightmap


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
    assert sweep == pytest.approx(ControllerParams().max_stroke * leg)


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
    ctrl.feedback[:] = [0.02 * leg, 0.0]  # below the threshold: ignored
    ctrl._apply_feedback(0.1)
    np.testing.assert_allclose(ctrl.pos, start)
    ctrl.feedback[:] = [0.0, 0.3 * leg]
    ctrl._apply_feedback(0.07)
    share = 0.07 / ctrl.gait.cycle_time[0]
    np.testing.assert_allclose(ctrl.pos[0, :2] - start[0, :2], [0.0, 0.3 * leg * share])
    # the part worked off is consumed, so the pelvis does not drift forever
    np.testing.assert_allclose(ctrl.feedback[:, 1], 0.3 * leg * (1.0 - share))


def test_reach_guard_lowers_the_pelvis_to_keep_legs_within_reach() -> None:
    ctrl, _ = _spider_controller(_flat())
    ctrl.foot[0, 2] -= 0.3  # a foot in a hole
    ctrl._reach_guard()
    hips = ctrl.hips_world()
    dist = np.linalg.norm(hips - ctrl.foot, axis=1)
    assert np.all(dist <= ctrl.guard_reach + 1e-9)
    assert dist[0] == pytest.approx(ctrl.guard_reach[0])


def test_a_foot_left_behind_steps_early() -> None:
    ctrl, legs = _spider_controller(_flat())
    planted = 6  # L4, a hind leg standing at the start
    assert not ctrl.swinging[planted]
    ctrl.foot[planted, 0] -= 0.25  # far behind its hip
    ctrl.step(1.0 / 30.0, _controls(legs))
    assert ctrl.forced[planted]
    assert ctrl.swinging[planted]


def test_no_ground_ahead_fails_plans_cleanly_and_keeps_feet_planted() -> None:
    # the heightmap ends just ahead of the spider: there is nowhere to step
    env = Environment(Heightmap(np.zeros((40, 40)), np.array([-1.2, -1.0]), 0.05))
    ctrl, legs = _spider_controller(env)
    failures = 0
    for _ in range(50):
        stats = ctrl.step(1.0 / 30.0, _controls(legs, speed=0.5))
        failures += stats.n_failed
        res = ctrl.ik_result
        assert res is not None
        assert np.all(np.isfinite(res.joints))
    assert failures > 0
    assert ctrl.plan_failed.any()
    # a foot whose plan failed stays on the ground
    assert np.all(ctrl.foot[ctrl.plan_failed, 2] == 0.0)


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
    from procloco_addon.core.spine import SpineParams

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
