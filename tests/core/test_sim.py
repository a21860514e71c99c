# SPDX-License-Identifier: GPL-3.0-or-later
"""The system loop: creatures on the terrains of the issue, judged by ``metrics``."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.locomotion import morphology as morph
from procloco_addon.core.locomotion.footprints import PlannerParams
from procloco_addon.core.locomotion.gait import find_gait_preset
from procloco_addon.core.locomotion.scaling import scaled_params
from procloco_addon.core.locomotion.sim import (
    Controls,
    Effects,
    GaitChange,
    PathFollower,
    SimResult,
    Simulation,
    SpeedRamp,
    check_motion,
    speed_schedule,
)
from procloco_addon.core.locomotion.spine import SpineParams, wrap_angle
from procloco_addon.core.locomotion.types import ControllerParams
from procloco_addon.core.world.terrain import (
    ROLE_AVOID,
    ROLE_GROUND,
    ROLE_STEP_OVER,
    Boxes,
    Environment,
    Heightmap,
)


def flat(size: float = 8.0) -> Environment:
    n = int(size / 0.05)
    return Environment(Heightmap(np.zeros((n, n)), np.array([-size / 2, -size / 2]), 0.05))


def slope(grade: float) -> Environment:
    """Flat for x < 0, then rising ``grade`` metres per metre along +x."""
    x = np.arange(-3.0, 8.0, 0.05)
    y = np.arange(-3.0, 3.0, 0.05)
    gx, gy = np.meshgrid(x, y)
    return Environment(
        Heightmap(grade * np.maximum(gx, 0.0) + 0.01 * np.sin(2.0 * gy), np.array([x[0], y[0]]), 0.05)
    )


def stairs(
    rise: float = 0.08, run: float = 0.35, n: int = 6, x0: float = 0.8, end: float = 8.0
) -> Environment:
    """A flight of ``n`` steps starting at ``x0`` up to a plateau (boxes of role ground)."""
    base = Heightmap(np.zeros((120, 240)), np.array([-3.0, -3.0]), 0.05)
    starts = x0 + run * np.arange(n)
    center = np.column_stack([(starts + end) / 2, np.zeros(n), np.zeros(n)])
    size = np.column_stack([end - starts, np.full(n, 3.0), rise * (np.arange(n) + 1)])
    return Environment(base, Boxes(center, size, np.zeros(n), np.full(n, ROLE_GROUND), np.zeros(n, bool)))


def bumpy_with_crates() -> tuple[Environment, np.ndarray]:
    """A heightmap with a low crate to step on, a tall crate to walk around, a moving low
    crate and another static one. Returns the environment and the boxes' start centres."""
    x = np.arange(-3.0, 6.0, 0.05)
    y = np.arange(-3.0, 3.0, 0.05)
    gx, gy = np.meshgrid(x, y)
    heights = 0.06 * np.sin(gx * 1.3) * np.cos(gy * 1.1) + 0.03 * np.sin(2.7 * gx + 0.5)
    hm = Heightmap(heights, np.array([x[0], y[0]]), 0.05)
    centers = np.array([[0.8, 0.3, 0.0], [1.5, -0.35, 0.0], [2.2, 0.0, 0.0], [1.2, -1.0, 0.0]])
    centers[:, 2] = hm.sample(centers[:, :2]) - 0.01
    boxes = Boxes(
        centers,
        np.array([[0.25, 0.25, 0.06], [0.2, 0.2, 0.3], [0.3, 0.2, 0.05], [0.2, 0.2, 0.05]]),
        np.array([0.3, 0.0, 0.5, 0.0]),
        np.array([ROLE_STEP_OVER, ROLE_AVOID, ROLE_STEP_OVER, ROLE_STEP_OVER]),
        np.array([False, False, True, False]),
    )
    return Environment(hm, boxes), centers


def _assert_motion_ok(res: SimResult, env: Environment, settle: float = 0.0) -> None:
    report = check_motion(res, env, settle=settle)
    assert report.passed, report.failures()
    assert report.phase is not None
    assert report.phase.n_events > 0


def test_spider_on_flat_ground_walks_cleanly_and_periodically() -> None:
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    env = flat()
    # one cycle of travel (0.21 m) is a whole number of planning cells, so the windows repeat
    sim = Simulation(
        env,
        [m],
        gait,
        controls=Controls(speed=0.3, heading=0.0, step_height=0.05),
        params=ControllerParams(window_cell=0.035),
    )
    res = sim.run(90)
    _assert_motion_ok(res, sim.env)
    # it went where it was sent, at the speed asked
    np.testing.assert_allclose(res.pelvis_position[-1, 0, :2], [0.3 * 90 / 30, 0.0], atol=1e-9)
    # flat, straight, effects off: constant height and attitude
    assert np.ptp(res.pelvis_position[:, 0, 2]) < 1e-9
    assert np.abs(res.pitch).max() < 1e-9
    assert np.abs(res.roll).max() < 1e-9
    # periodic: one cycle later every footprint and contact repeats, moved by one cycle of
    # travel; the swing curves repeat to a few millimetres (the planner's grid paths)
    cycle = round(0.7 * 30)
    shift = np.array([0.3 * 0.7, 0.0, 0.0])
    np.testing.assert_allclose(res.footprint[cycle:], res.footprint[:-cycle] + shift, atol=1e-9)
    assert np.array_equal(res.contact[cycle:], res.contact[:-cycle])
    np.testing.assert_allclose(res.foot[cycle:], res.foot[:-cycle] + shift, atol=0.005)
    # every foot lifted as often as the circles say, and its swing reached the step height
    lifts = (res.contact[:-1] & ~res.contact[1:]).sum(axis=0)
    assert np.all(lifts >= 4)
    assert res.end_effector[..., 2].max(axis=0).min() == pytest.approx(0.05, abs=0.005)


def test_same_inputs_give_identical_arrays() -> None:
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    env, _ = bumpy_with_crates()

    def run(seed: int) -> SimResult:
        sim = Simulation(
            env,
            [m, m],
            gait,
            start_xy=[[0.0, 0.0], [0.0, -1.6]],
            phase="random",
            seed=seed,
            controls=Controls(speed=0.3, heading=0.0, step_height=0.05),
        )
        return sim.run(40)

    a, b, c = run(7), run(7), run(8)
    for name in ("pelvis_position", "pelvis_rotation", "joints", "contact", "footprint", "needle"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert not np.array_equal(a.needle, c.needle)


def test_each_end_effector_stands_its_foot_lift_above_the_ground() -> None:
    """A rig's end-effectors of different heights above their soles (``foot_lift``): planted,
    each stands its own lift above the ground its foot is planned on, the IK targets too; a
    lift of zero walks exactly as none."""
    from dataclasses import replace

    env = flat()
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    controls = Controls(speed=0.3, heading=0.0, step_height=0.05)
    lift = np.where(np.arange(m.n_legs) % 2 == 0, 0.0, 0.03)

    def run(mm: morph.Morphology) -> SimResult:
        return Simulation(env, [mm], gait, controls=controls).run(40)

    lifted = run(replace(m, foot_lift=lift))
    planted = lifted.contact
    heights = np.broadcast_to(lift, planted.shape)[planted]
    np.testing.assert_allclose(lifted.end_effector[..., 2][planted], heights, atol=1e-4)
    np.testing.assert_allclose(lifted.foot[..., 2][planted], heights, atol=1e-12)
    assert check_motion(lifted, env).passed
    plain, zero = run(m), run(replace(m, foot_lift=np.zeros(m.n_legs)))
    for name in ("pelvis_position", "joints", "foot", "contact"):
        assert np.array_equal(getattr(plain, name), getattr(zero, name)), name
    assert not np.array_equal(plain.joints, lifted.joints)


def test_spider_on_a_heightmap_with_static_and_moving_crates() -> None:
    env, centers = bumpy_with_crates()
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    sim = Simulation(env, [m], gait, controls=Controls(speed=0.3, heading=0.0, step_height=0.05))

    def move(s: Simulation) -> None:
        t = s.time
        env.move_boxes(
            np.array([2]), np.array([[2.2, 0.4 * np.sin(0.8 * t), centers[2, 2]]]), np.array([0.5 + 0.3 * t])
        )

    res = sim.run(300, on_step=move)
    _assert_motion_ok(res, env)
    assert res.pelvis_position[-1, 0, 0] == pytest.approx(3.0, abs=0.05)
    # the body followed the terrain: pelvis height over the hull moves with the bumps
    assert np.ptp(res.pelvis_position[:, 0, 2]) > 0.05
    # feet stood on the low crate (its top), never inside the tall one
    planted = res.contact[1:] & ~res.contact[:-1]
    landed = res.footprint[1:][planted]
    low = env.boxes
    on_low = (np.abs(landed[:, 0] - 0.8) < 0.1) & (np.abs(landed[:, 1] - 0.3) < 0.1)
    assert np.any(on_low)
    np.testing.assert_allclose(landed[on_low, 2], low.center[0, 2] + 0.06, atol=1e-6)
    assert res.stats["n_failed"].sum() == 0


def test_pentapod_robot_goes_uphill() -> None:
    m = morph.pentapod()
    gait = find_gait_preset("pentapod_robot").gait(m.labels)
    grade = 0.25
    env = slope(grade)
    sim = Simulation(env, [m], gait, controls=Controls(speed=0.2, heading=0.0, step_height=0.05))
    res = sim.run(240)
    _assert_motion_ok(res, env)
    x = res.pelvis_position[:, 0, 0]
    z = res.pelvis_position[:, 0, 2]
    on_slope = x > 0.6
    assert on_slope.sum() > 40
    # the pelvis climbs with the slope, body thickness above it, and pitches nose up with it
    np.testing.assert_allclose(z[on_slope] - grade * x[on_slope], m.body_thickness, atol=0.03)
    np.testing.assert_allclose(res.pitch[on_slope, 0], np.arctan(grade), atol=0.05)


def test_quadruped_climbs_stairs() -> None:
    m = morph.quadruped()
    gait = find_gait_preset("quadruped_walk").gait(m.labels)
    rise = 0.08
    env = stairs(rise=rise)
    sim = Simulation(env, [m], gait, controls=Controls(speed=0.5, heading=0.0, step_height=0.08))
    res = sim.run(300)
    _assert_motion_ok(res, env)
    # from the ground to the plateau six steps up
    assert res.pelvis_position[-1, 0, 2] == pytest.approx(6 * rise + m.body_thickness, abs=0.02)
    # every footprint is on a step's top, not on an edge halfway
    planted = res.contact[1:] & ~res.contact[:-1]
    z = res.footprint[1:][planted][:, 2]
    np.testing.assert_allclose(z / rise, np.round(z / rise), atol=1e-6)
    assert len(np.unique(np.round(z / rise))) == 7


def test_biped_on_flat_ground() -> None:
    m = morph.biped()
    preset = find_gait_preset("biped_walk")
    gait = preset.gait(m.labels)
    env = flat()
    speed = preset.speed * float(m.leg_length.mean()) * 0.8
    sim = Simulation(env, [m], gait, controls=Controls(speed=speed, heading=0.0, step_height=0.07))
    res = sim.run(120)
    _assert_motion_ok(res, env)
    # feet alternate: never both in the air
    assert not np.any((~res.contact).all(axis=1))


def test_a_run_resumed_from_a_snapshot_walks_as_the_run_straight_through() -> None:
    """Simulation.snapshot / resume (Live Preview's kept states): a state taken at a frame and
    resumed with the same inputs gives the run straight through, frame for frame (same code);
    the snapshot holds no recorded frames and the run it was taken of goes on unchanged; a
    resume with a gait change after the snapshot's frame walks that change from there."""
    m = morph.quadruped()
    walk = find_gait_preset("quadruped_walk").gait(m.labels)
    trot = find_gait_preset("quadruped_trot").gait(m.labels)
    env, _ = bumpy_with_crates()
    controls = Controls(speed=0.4, heading=0.2, step_height=0.06)
    whole = Simulation(env, [m], walk, controls=controls).run(59)  # (60 frames)

    sim = Simulation(env, [m], walk, controls=controls)
    for _ in range(24):
        sim.step()
    kept = sim.snapshot({id(env): env})
    assert kept.n_frames == 0
    assert sim.n_frames == 25
    for _ in range(35):
        sim.step()
    assert np.array_equal(sim.result().joints, whole.joints)  # the run goes on as it would
    again = kept.resume({id(env): env}, sim, 25, controls, [])
    for _ in range(35):
        again.step()
    res = again.result()
    for name in ("pelvis_position", "joints", "contact", "footprint", "needle"):
        assert np.array_equal(getattr(res, name), getattr(whole, name)), name
    assert again.env is env  # (shared through the memo, not copied)

    change = [GaitChange(1.5, trot, transition_time=0.5)]
    changed = kept.resume({id(env): env}, sim, 25, controls, change)
    for _ in range(35):
        changed.step()
    res = changed.result()
    assert np.array_equal(res.joints[:37], whole.joints[:37])  # (the change starts at 1.5 s)
    assert not np.array_equal(res.needle[-10:], whole.needle[-10:])


def test_gait_transitions_walk_trot_gallop_without_popping() -> None:
    m = morph.quadruped()
    walk = find_gait_preset("quadruped_walk").gait(m.labels)
    trot = find_gait_preset("quadruped_trot").gait(m.labels)
    gallop = find_gait_preset("quadruped_rotary_gallop").gait(m.labels)
    env = flat(20.0)
    changes = [GaitChange(2.0, trot, transition_time=1.0), GaitChange(5.0, gallop, transition_time=1.0)]

    def controls(t: float) -> Controls:
        speed = 0.4 if t < 2.0 else (0.6 if t < 5.0 else 0.9)
        return Controls(speed=speed, heading=0.0, step_height=0.06)

    sim = Simulation(env, [m], walk, controls=controls, gait_changes=changes)
    res = sim.run(300)
    _assert_motion_ok(res, env)
    # no foot pops: a foot moves at most a plausible swing speed in one frame
    step = np.linalg.norm(np.diff(res.foot, axis=0), axis=2)
    assert step.max() < 0.1
    # after each transition (plus one cycle), the disks are the target gait's
    frame = round(4.5 * 30)
    np.testing.assert_allclose(res.disk_start[frame], trot.swing_start)
    np.testing.assert_allclose(res.disk_duration[frame], trot.swing_duration)
    np.testing.assert_allclose(res.disk_start[-1], gallop.swing_start)
    # and the measured lift-offs follow them: the gallop's rotary footfall order in the last second
    lifts = res.contact[:-1] & ~res.contact[1:]
    tail = lifts[-30:]
    frames, legs = np.nonzero(tail)
    needle = res.needle[-30:, 0][frames]
    errors = np.mod(needle - gallop.swing_start[legs] + 0.5, 1.0) - 0.5
    assert np.abs(errors).max() <= res.phase_step[-1, 0] + 1e-9


def test_pelvis_physics_off_is_flat_and_on_bounces_periodically() -> None:
    m = morph.hexapod()
    gait = find_gait_preset("hexapod_tetrapod").gait(m.labels)
    env = flat()
    heights = {}
    for on in (False, True):
        ctl = Controls(speed=0.15, heading=0.0, step_height=0.03, pelvis_physics=on)
        sim = Simulation(env, [m], gait, controls=ctl, dt=1.0 / 40.0)  # a cycle is 30 frames
        res = sim.run(160)
        _assert_motion_ok(res, env)
        heights[on] = res.pelvis_position[:, 0, 2]
    assert np.ptp(heights[False]) < 1e-9
    bounce = heights[True][40:]  # after the running mean of the offset has settled
    assert np.ptp(bounce) > 0.003
    # centred on the height the body has without physics
    assert bounce.mean() == pytest.approx(heights[False][0], abs=0.002)
    # three swing groups a third of a cycle apart: the bounce repeats every third of a cycle
    third = round(gait.cycle_time * 40 / 3)
    assert np.abs(bounce[third:] - bounce[:-third]).max() < 0.1 * np.ptp(bounce)


def test_following_a_polyline_path_and_stopping_at_its_end() -> None:
    m = morph.hexapod()
    gait = find_gait_preset("hexapod_tripod").gait(m.labels)
    env = flat()
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.6, 0.6], [1.6, 1.4]])
    sim = Simulation(env, [m], gait, controls=Controls(speed=0.3, path=[path], step_height=0.03))
    res = sim.run(330)
    _assert_motion_ok(res, env)
    xy = res.pelvis_position[:, 0, :2]
    # close to the path all along (distance to the nearest segment)
    a, b = path[:-1], path[1:]
    ab = b - a
    t = np.clip(np.einsum("fsk,sk->fs", xy[:, None, :] - a[None], ab) / np.einsum("sk,sk->s", ab, ab), 0, 1)
    dist = np.linalg.norm(a[None] + t[..., None] * ab[None] - xy[:, None, :], axis=2).min(axis=1)
    assert dist.max() < 0.15
    # it arrived and stopped
    np.testing.assert_allclose(xy[-1], path[-1], atol=0.12)
    assert np.linalg.norm(xy[-1] - xy[-15]) < 1e-6
    assert res.yaw[-1, 0] == pytest.approx(np.pi / 2, abs=0.15)


def test_speed_and_heading_changes_replan_swinging_feet() -> None:
    m = morph.spider()
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(m.labels)
    env = flat()

    def controls(t: float) -> Controls:
        # changes while some feet are early in their swing (needle at 0.71 and 0.14)
        return Controls(speed=0.15 if t < 1.2 else 0.35, heading=0.0 if t < 2.2 else 0.8, step_height=0.05)

    sim = Simulation(env, [m], gait, controls=controls)
    res = sim.run(120)
    _assert_motion_ok(res, env)
    replans = res.stats["n_replans"]
    assert replans[:36].sum() == 0
    assert replans[36:38].sum() > 0  # speed change (thesis sequence 3)
    assert replans[66:68].sum() > 0  # heading change
    assert res.yaw[-1, 0] == pytest.approx(0.8, abs=1e-6)


# ------------------------------------------------------------------ flexible spine (§4.2)


def _heading_of(frames: np.ndarray) -> np.ndarray:
    """Headings of the forward axes of rotations ``(..., 3, 3)``."""
    return np.asarray(np.arctan2(frames[..., 1, 0], frames[..., 0, 0]))


def _quarter_turn(spine: SpineParams | None) -> SimResult:
    """A quadruped walking along +x turns to +y (a 90 degree heading command at t = 1 s)."""
    m = morph.quadruped(spine=True)
    gait = find_gait_preset("quadruped_walk").gait(m.labels)

    def controls(t: float) -> Controls:
        return Controls(speed=0.5, heading=0.0 if t < 1.0 else np.pi / 2, step_height=0.06)

    return Simulation(flat(10.0), [m], gait, controls=controls, spine=spine).run(150)


def test_quadruped_turning_90_degrees_bends_its_spine_from_the_head() -> None:
    res = _quarter_turn(SpineParams())
    _assert_motion_ok(res, flat(10.0))
    model = morph.quadruped(spine=True).spine
    assert model is not None
    assert res.spine_n_joints.tolist() == [7]
    joints = res.spine_joints[:, 0]
    bones = np.diff(joints, axis=1)
    # bone lengths exact at every frame
    lengths = np.linalg.norm(bones, axis=2)
    np.testing.assert_allclose(lengths, np.broadcast_to(model.bone_length, lengths.shape), atol=1e-9)
    # every joint within its limits: the turn between two bones moves from its rest value by
    # at most the joint's yaw limit (and pitch limit in the vertical plane)
    yaw = np.arctan2(bones[..., 1], bones[..., 0])
    pitch = np.arctan2(bones[..., 2], np.hypot(bones[..., 0], bones[..., 1]))
    rest_yaw = np.arctan2(model.bone_dir[:, 1], model.bone_dir[:, 0])
    rest_pitch = np.arctan2(model.bone_dir[:, 2], np.hypot(model.bone_dir[:, 0], model.bone_dir[:, 1]))
    joint_yaw = wrap_angle(np.diff(yaw, axis=1) - np.diff(rest_yaw))
    joint_pitch = np.diff(pitch, axis=1) - np.diff(rest_pitch)
    assert np.all(np.abs(joint_yaw) <= model.joint_yaw_limit[1:-1] + 1e-9)
    assert np.all(np.abs(joint_pitch) <= model.joint_pitch_limit[1:-1] + 1e-9)
    assert np.abs(joint_yaw).max() > 0.5 * model.joint_yaw_limit[1]  # and it did bend
    # progressively from the head: while the turn goes on, each bone has turned at least as
    # far as the one behind it
    turned = wrap_angle(yaw - yaw[:1])
    turning = np.flatnonzero((turned[:, 0] > np.radians(10)) & (turned[:, 0] < np.radians(70)))
    assert turning.size > 5
    assert np.all(np.diff(turned[turning], axis=1) <= 1e-9)
    assert np.all(turned[turning, 0] - turned[turning, -1] > np.radians(5))
    # the shoulders lead the hips through the turn, then the body straightens on +y
    lead = wrap_angle(_heading_of(res.leg_frame[:, 0]) - _heading_of(res.leg_frame[:, 2]))
    assert lead.max() > np.radians(20)
    assert abs(lead[-1]) < np.radians(1)
    assert res.yaw[-1, 0] == pytest.approx(np.pi / 2, abs=0.02)
    assert np.abs(turned[-1] - np.pi / 2).max() < np.radians(1)


def test_without_the_spine_the_quadruped_turns_rigidly() -> None:
    res = _quarter_turn(None)
    assert res.spine_n_joints.tolist() == [0]
    assert res.yaw[-1, 0] == pytest.approx(np.pi / 2, abs=1e-6)
    # every leg hangs from the one pelvis: same frame, and the hips keep their rest layout
    np.testing.assert_array_equal(res.leg_frame, res.pelvis_rotation[:, res.leg_char])
    m = res.legs.morphologies[0]
    hips_body = np.einsum("fji,fnj->fni", res.pelvis_rotation[:, 0], res.hips - res.pelvis_position[:, :1])
    np.testing.assert_allclose(hips_body, np.broadcast_to(m.hip_offset, hips_body.shape), atol=1e-12)


def test_spine_stays_above_the_stairs_and_pitches_with_the_slope() -> None:
    m = morph.quadruped(spine=True)
    gait = find_gait_preset("quadruped_walk").gait(m.labels)
    rise = 0.08
    env = stairs(rise=rise)
    res = Simulation(env, [m], gait, controls=Controls(speed=0.5, heading=0.0, step_height=0.08),
                     spine=SpineParams()).run(300)
    _assert_motion_ok(res, env)
    joints = res.spine_joints[:, 0]
    ground = env.height_at(joints[..., :2].reshape(-1, 2)).reshape(joints.shape[:2])
    assert (joints[..., 2] - ground).min() > 0.6 * m.body_thickness
    # the hips (the anchor node, the rig's root) end up on the plateau
    assert joints[-1, -1, 2] == pytest.approx(6 * rise + m.body_thickness, abs=0.02)

    grade = 0.25
    env = slope(grade)
    res = Simulation(env, [m], gait, controls=Controls(speed=0.5, heading=0.0, step_height=0.06),
                     spine=SpineParams()).run(240)
    _assert_motion_ok(res, env)
    joints = res.spine_joints[:, 0]
    on_slope = joints[:, -1, 0] > 0.3  # the whole spine is on the slope
    assert on_slope.sum() > 60
    # both girdles pitch with the slope (their legs' frames), the hips ride a body thickness
    # above it (less the lag of the height filter: a quarter cycle of a 0.125 m/s climb)
    frames = res.leg_frame[on_slope][..., 0]  # forward axes (n, legs, 3)
    girdle_pitch = np.arctan2(frames[..., 2], np.hypot(frames[..., 0], frames[..., 1]))
    assert girdle_pitch.mean(axis=0) == pytest.approx(np.full(4, np.arctan(grade)), abs=np.radians(3))
    hips = joints[on_slope, -1]
    above = hips[:, 2] - grade * hips[:, 0]
    assert np.median(above) == pytest.approx(m.body_thickness - 0.25 * 0.5 * grade, abs=0.005)
    assert np.abs(above - m.body_thickness).max() < 0.05


def test_each_spine_node_bounces_on_its_own_legs() -> None:
    """Pseudo-physics per pelvis node (thesis §4.2.3): off, the hips ride level on flat ground;
    on, the shoulders and the hips bounce, each with its own pair of legs."""
    m = morph.quadruped(spine=True)
    gait = find_gait_preset("quadruped_walk").gait(m.labels)
    env = flat()
    z = {}
    for on in (False, True):
        ctl = Controls(speed=0.4, heading=0.0, step_height=0.05, pelvis_physics=on)
        res = Simulation(env, [m], gait, controls=ctl, spine=SpineParams(foot_pitch_weight=0.0)).run(120)
        _assert_motion_ok(res, env)
        z[on] = res.spine_joints[30:, 0][:, [2, 6], 2]  # shoulders and hips (key joints)
    assert np.ptp(z[False][:, 1]) < 1e-9
    assert np.ptp(z[True], axis=0).min() > 0.003
    assert z[True][:, 1].mean() == pytest.approx(z[False][0, 1], abs=0.003)
    # the two nodes do not move as one: their bounces are out of step
    bounce = z[True] - z[True].mean(axis=0)
    assert np.abs(bounce[:, 0] - bounce[:, 1]).max() > 0.002


def test_visual_yaw_sways_the_lizard_with_its_feet() -> None:
    m = morph.lizard()
    model = m.spine
    assert model is not None
    gait = find_gait_preset("quadruped_trot").gait(m.labels)
    env = flat()
    sway = {}
    for on in (False, True):
        res = Simulation(env, [m], gait, controls=Controls(speed=0.3, heading=0.0, step_height=0.03),
                         spine=SpineParams(visual_yaw=on)).run(90)
        _assert_motion_ok(res, env)
        bones = np.diff(res.spine_joints[:, 0], axis=1)
        yaw = np.arctan2(bones[..., 1], bones[..., 0])
        sway[on] = np.abs(wrap_angle(yaw - np.pi))  # rest bones point straight back
        joint_yaw = wrap_angle(np.diff(yaw, axis=1))
        assert np.all(np.abs(joint_yaw) <= model.joint_yaw_limit[1:-1] + 1e-9)
    assert sway[False].max() < 1e-9
    assert sway[True].max() > np.radians(3)


def test_spine_nodes_plan_the_rigid_footprints_on_a_straight_walk() -> None:
    """Walking straight the nodes follow the rigid body's path, so feet planned in each node's
    frame (predicted along the spine to touch-down) land where the rigid body plans them."""
    m = morph.quadruped(spine=True)
    gait = find_gait_preset("quadruped_walk").gait(m.labels)
    env = flat()
    ctl = Controls(speed=0.5, heading=0.3, step_height=0.06)
    rigid = Simulation(env, [m], gait, controls=ctl, start_yaw=0.3).run(90)
    level = SpineParams(foot_pitch_weight=0.0)
    spine = Simulation(env, [m], gait, controls=ctl, start_yaw=0.3, spine=level).run(90)
    assert (~rigid.contact).sum() > 20
    np.testing.assert_allclose(spine.footprint, rigid.footprint, atol=1e-9)
    np.testing.assert_allclose(spine.preferred, rigid.preferred, atol=1e-9)


def test_rigid_characters_in_a_crowd_with_spines_are_unchanged_and_runs_repeat() -> None:
    env, _ = bumpy_with_crates()
    dog = morph.quadruped(spine=True)
    gait = find_gait_preset("quadruped_walk").gait(dog.labels)
    ctl = Controls(speed=0.4, heading=0.0, step_height=0.06, pelvis_physics=True)
    alone = Simulation(env, [dog], gait, controls=ctl, start_xy=[[0.0, 0.0]]).run(45)

    def crowd() -> SimResult:
        return Simulation(env, [dog, dog, morph.lizard(2.0)], [gait, gait, gait], controls=ctl,
                          start_xy=[[0.0, 0.0], [0.0, -1.5], [-1.0, 1.2]],
                          spine=[None, SpineParams(), SpineParams(visual_yaw=True)]).run(45)

    a, b = crowd(), crowd()
    assert a.spine_n_joints.tolist() == [0, 7, 9]
    # The crowd steps the first dog in batches with the others, the lone run by itself: the
    # same decisions (which feet are down), the same motion to a nanometre (two code paths:
    # floats are not compared bit for bit, see tests/core/cross_path.py).
    def first(res: SimResult, name: str) -> np.ndarray:
        arr = getattr(res, name)
        return arr[:, :4] if arr.shape[1] == 12 else arr[:, :1]

    np.testing.assert_array_equal(first(a, "contact"), alone.contact)
    for name in ("pelvis_position", "pelvis_rotation", "joints", "foot", "footprint"):
        np.testing.assert_allclose(first(a, name), getattr(alone, name), rtol=0.0, atol=1e-9, err_msg=name)
    # Runs repeat to the last bits that numpy's reductions keep: their SIMD grouping can follow
    # the arrays' memory alignment, which differs between runs (seen once in 700 test runs, on
    # values of 1e-18); Actions are written in float32, where that never shows.
    for name in ("spine_joints", "spine_rotation", "joints", "leg_frame"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0.0, atol=1e-12, err_msg=name)
    report = check_motion(a, env, chars=[1, 2])
    assert report.passed, report.failures()


# ---------------------------------------------------------------------------------------
# At the presets' own speeds


def _preset_run(
    m: morph.Morphology, preset_name: str, env: Environment, seconds: float, heading: object = 0.0,
    fps: float = 24.0,
) -> SimResult:
    """``m`` walking at its gait preset's speed and step height (leg lengths), pelvis physics
    on, as the Blender shell runs it: a step per frame, cells and slices in leg lengths."""
    preset = find_gait_preset(preset_name)
    leg = float(m.leg_length.mean())

    def controls(t: float) -> Controls:
        h = heading(t) if callable(heading) else heading
        return Controls(speed=preset.speed * leg, heading=h, step_height=preset.step_height * leg,
                        pelvis_physics=True)

    params = ControllerParams(window_cell=0.065 * leg, slice_size=0.14 * leg)
    planner = PlannerParams(step_height=preset.step_height * leg, slice_size=0.14 * leg, leg_reach=leg,
                            candidate_radius=params.candidate_radius * leg,
                            fixed_distance=params.fixed_distance * leg, edge_height=0.055 * leg)
    sim = Simulation(env, [m], preset.gait(m.labels), controls=controls, dt=1.0 / fps, params=params,
                     planner=[planner])
    return sim.run(round(seconds * fps))


def test_spider_at_its_preset_speed_walks_and_turns_with_its_feet_planted() -> None:
    # 1.5 leg lengths per second at the preset's 0.7 s cycle would sweep 0.58 leg lengths,
    # more than the 0.3-0.35 between neighbouring feet and, turning, more than the legs
    # reach: the cycle shortens so that legs neither cross, crowd nor stretch
    m = morph.spider(1.33)
    env = flat(12.0)
    res = _preset_run(m, "octopod_alternating_tetrapod", env, 2.5,
                      heading=lambda t: 0.0 if t < 1.5 else 0.5 * np.pi)
    _assert_motion_ok(res, env)
    assert res.stats["n_failed"].sum() == 0
    leg = float(m.leg_length.mean())
    travel = np.linalg.norm(np.diff(res.pelvis_position[:, 0, :2], axis=0), axis=1).sum()
    assert travel == pytest.approx(1.5 * leg * 2.5, rel=0.02)


def test_rigid_quadruped_turning_90_degrees_at_walking_speed_keeps_its_feet_planted() -> None:
    # an abrupt quarter turn: the planted feet far from the pelvis sweep sideways; the legs
    # step faster and early rather than stretch or drag
    m = morph.quadruped(1.45, spine=False)
    env = flat(12.0)
    res = _preset_run(m, "quadruped_walk", env, 3.0, heading=lambda t: 0.0 if t < 1.0 else 0.5 * np.pi,
                      fps=24.0)
    _assert_motion_ok(res, env)
    assert res.yaw[-1, 0] == pytest.approx(0.5 * np.pi, abs=1e-6)


# ---------------------------------------------------------------- the shell's loop, in the core


def test_speed_schedule_ramps_from_the_speed_it_began_at() -> None:
    speed_at = speed_schedule(1.0, [SpeedRamp(2.0, 1.0, 3.0), SpeedRamp(0.5, 0.0, 0.5)])
    assert speed_at(0.0) == 1.0
    assert speed_at(0.5) == 0.5  # at once
    assert speed_at(2.5) == pytest.approx(1.75)  # halfway from 0.5 to 3
    assert speed_at(9.0) == 3.0


def test_scaled_params_scale_with_the_creature() -> None:
    small, small_plan = scaled_params(0.1, 0.02)
    big, big_plan = scaled_params(10.0, 2.0)
    assert big.window_cell == pytest.approx(100.0 * small.window_cell)
    assert big_plan.slice_size == pytest.approx(100.0 * small_plan.slice_size)
    assert big_plan.edge_height == pytest.approx(100.0 * small_plan.edge_height)
    assert big.support_tolerance == pytest.approx(100.0 * small.support_tolerance)
    # gait circles: gravity scales with the creature; Auto: real gravity
    assert big.physics.gravity == pytest.approx(100.0 * small.physics.gravity)
    assert scaled_params(0.1, 0.02, auto_physics=True)[0].physics.gravity == pytest.approx(9.81)


def test_a_fast_character_looks_farther_along_its_path() -> None:
    # east for 3 m, then north: 1.5 m before the corner a 1 m look-ahead still aims east; at
    # 4 m/s the character looks 2 m on (half a second), past the corner, and turns toward it
    corner = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 3.0]])
    slow = PathFollower(corner, lookahead=1.0, stop_distance=0.5, lookahead_time=0.5)
    fast = PathFollower(corner, lookahead=1.0, stop_distance=0.5, lookahead_time=0.5)
    at = np.array([1.5, 0.0])
    assert slow.command(at, speed=1.0)[0] == pytest.approx(0.0, abs=1e-12)  # 0.5 m < 1 m: one leg
    heading, _ = fast.command(at, speed=4.0)
    assert heading == pytest.approx(np.arctan2(0.5, 1.5), abs=1e-12)


def test_path_progress_never_goes_back_where_a_path_crosses_itself() -> None:
    # a loop through the origin: at the crossing the follower keeps to the part it is on
    loop = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, -1.0], [0.0, -1.0]])
    f = PathFollower(loop, lookahead=0.3, stop_distance=0.2)
    walk = [*([x, 0.0] for x in np.linspace(0.0, 2.0, 21)), *([2.0, y] for y in np.linspace(0.0, 1.0, 11)),
            *([x, 1.0] for x in np.linspace(2.0, 1.0, 11)), *([1.0, y] for y in np.linspace(1.0, 0.1, 10))]
    for xy in walk[:10]:
        f.command(np.array(xy))
    heading, factor = f.command(np.array(walk[10]))
    assert heading == pytest.approx(0.0, abs=1e-9)  # the first time through the crossing: east
    assert factor == 1.0
    for xy in walk[11:]:
        f.command(np.array(xy))
    # back over the crossing point, now heading down the second leg of the loop
    heading, _ = f.command(np.array([1.0, 0.0]))
    assert heading == pytest.approx(-np.pi / 2, abs=1e-9)
    # eases to a stop over the last 0.2 m
    for xy in ([1.0, -0.4], [1.0, -0.8], [0.9, -1.0], [0.6, -1.0], [0.3, -1.0]):
        f.command(np.array(xy))
    _, near_end = f.command(np.array([0.1, -1.0]))
    assert 0.0 < near_end < 1.0
    assert f.command(np.array([0.0, -1.0]))[1] == 0.0


def test_burst_progression_starts_still_walks_in_bursts_and_repeats_with_its_seed() -> None:
    m = morph.hexapod()
    gait = find_gait_preset("hexapod_tripod").gait(m.labels)

    def run(seed: int) -> SimResult:
        sim = Simulation(flat(), [m], gait, controls=Controls(speed=0.3, step_height=0.03), dt=1.0 / 24.0,
                         seed=seed, effects=[Effects(progression=True, randomize_gait=True,
                                                     cycle_time=gait.cycle_time)])
        return sim.run(60)

    res = run(3)
    assert res.speed[0, 0] == 0.0  # standing still at first
    assert res.speed.min() >= 0.0
    assert res.speed.max() <= 0.3 + 1e-12
    assert (res.speed[1:, 0] < 0.3 - 1e-9).any()
    assert (res.speed[1:, 0] > 0.05).any()
    np.testing.assert_array_equal(run(3).pelvis_position, res.pelvis_position)
    assert not np.array_equal(run(4).speed, res.speed)


def test_result_of_the_first_frames_is_the_start_of_the_whole() -> None:
    m = morph.hexapod()
    gait = find_gait_preset("hexapod_tripod").gait(m.labels)
    sim = Simulation(flat(), [m], gait, controls=Controls(speed=0.3, step_height=0.03))
    sim.run(12)
    first = sim.result(5)
    whole = sim.result()
    assert first.n_frames == 5
    assert whole.n_frames == 13
    np.testing.assert_array_equal(first.joints, whole.joints[:5])
    np.testing.assert_array_equal(first.stats["n_plans"], whole.stats["n_plans"][:5])
    # the vanishing first step leaves the hips within reach of the planted feet
    reach = np.linalg.norm(whole.foot[0] - whole.hips[0], axis=1)
    assert (reach <= m.leg_length * (1.0 + 1e-9)).all()


def _crowded_hexapod() -> morph.Morphology:
    """A beetle whose legs hang 10 cm apart along its body, its hips 20 cm above its feet,
    each leg a short coxa, a femur rising to a high knee and a long tibia down (the Blender
    tests' ``beetle_gltf``): its legs allow a stance sweep of a third of their length."""
    chains = []
    for along in (0.1, 0.0, -0.1):
        for side in (1.0, -1.0):
            out = np.array([0.4 * np.sign(along), side, 0.0]) / np.hypot(1.0, 0.4 * np.sign(along))
            hip = np.array([along, 0.03 * side, 0.0])
            coxa = hip + 0.02 * out
            knee = coxa + 0.06 * out + np.array([0.0, 0.0, 0.06])
            foot = knee + 0.08 * out
            foot[2] = -0.2
            chains.append(np.array([hip, coxa, knee, foot]))
    return morph.Morphology.from_rest_joints(chains, ["L1", "R1", "L2", "R2", "L3", "R3"])


def test_auto_gait_of_crowded_legs_keeps_its_swings_and_lands_its_feet_beside_the_body() -> None:
    from procloco_addon.core.locomotion import autogait
    from procloco_addon.core.locomotion.scaling import stroke_limit

    m = _crowded_hexapod()
    leg = float(m.leg_length.mean())
    hip = autogait.rest_hip_height(m.rest_joints, m.n_segments)
    stroke = stroke_limit(m)
    assert stroke < 0.5 * autogait.SWING_TIME / autogait.DUTY_K * leg  # crowded
    p = autogait.auto_gait_params(m.labels, hip, leg, stroke=stroke)
    assert p is not None
    speed = p.top_speed()  # what Detect Legs gives such a rig
    params, planner = scaled_params(leg, 0.15 * leg, auto_physics=True)

    def walk(auto: autogait.AutoGaitParams) -> Simulation:
        sim = Simulation(flat(), [m], find_gait_preset("hexapod_tripod").gait(m.labels), dt=1.0 / 24.0,
                         controls=Controls(speed=speed, heading=0.0, step_height=0.15 * leg),
                         auto_gait=[auto], params=params, planner=[planner])
        res = sim.run(72)
        _assert_motion_ok(res, sim.env)
        # every foot lands beside the body where its rest pose puts it, none pushed in under
        # its hip by the foot ahead (where the leg folds and its coxa turns over in a frame)
        for k in range(m.n_legs):
            f = np.flatnonzero(~res.contact[:-1, k] & res.contact[1:, k]) + 1
            assert f.size >= 3
            side = (res.foot[f, k, :2] - res.pelvis_position[f, 0, :2])[:, 1]
            np.testing.assert_allclose(np.abs(side), abs(m.rest_foot[k, 1]), atol=0.01)
        return sim

    # the swing keeps its time: the controller does not run the cycle faster than Auto's
    assert walk(p).controller.gait.rate_scale[0] == 1.0
    # (the model's own sweep, twice what the legs allow, ran the whole cycle twice as fast)
    free = autogait.auto_gait_params(m.labels, hip, leg)
    assert free is not None
    sim = Simulation(flat(), [m], find_gait_preset("hexapod_tripod").gait(m.labels), dt=1.0 / 24.0,
                     controls=Controls(speed=speed, heading=0.0, step_height=0.15 * leg), auto_gait=[free],
                     params=params, planner=[planner])
    sim.run(2)
    assert sim.controller.gait.rate_scale[0] > 1.5
