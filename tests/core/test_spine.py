# SPDX-License-Identifier: GPL-3.0-or-later
"""Flexible spine (thesis §4.2) and visual yaw (§4.4)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields

import numpy as np
import pytest

from procloco_addon.core.locomotion.spine import (
    SpineBatch,
    SpineModel,
    SpineParams,
    SpinePlan,
    SpineState,
    _limit_joints,
    build_spine,
    finish_spine,
    frame_from_yaw_pitch,
    ground_guides,
    hip_positions,
    leg_frames,
    node_pitch,
    plan_spine,
    repeat_for_reach,
    spine_step,
    terrain_guides,
    visual_yaw,
    wrap_angle,
)
from procloco_addon.core.world.terrain import NO_SURFACE, ROLE_GROUND, Boxes, Environment, Heightmap
from tests.core.cross_path import assert_close

DT = 1 / 30


def quadruped(arched: bool = False, **kwargs: object) -> SpineModel:
    """A dog-sized spine: head, neck, shoulders, three back joints, hips (7 joints, 3 key
    nodes); front and hind legs 0.5 m long under their girdles."""
    xs = [0.6, 0.45, 0.3, 0.15, 0.0, -0.15, -0.3]
    joints = np.array([[x, 0.0, 0.0] for x in xs])
    joints[0, 2] = 0.1  # head carried higher
    if arched:
        joints[3:6, 2] = [0.03, 0.05, 0.03]
    hips = np.array([[0.3, 0.1, 0.0], [0.3, -0.1, 0.0], [-0.3, 0.1, 0.0], [-0.3, -0.1, 0.0]])
    feet = hips + np.array([0.0, 0.0, -0.5])
    return SpineModel.from_legs(joints, hips, feet, **kwargs)  # type: ignore[arg-type]


def hexapod_like() -> SpineModel:
    """A long body with four key nodes (head + three girdles), like the thesis's figure 4.10."""
    xs = np.linspace(0.9, -0.6, 11)
    joints = np.stack([xs, np.zeros(11), np.zeros(11)], axis=1)
    girdles = [0.6, 0.0, -0.6]
    hips = np.array([[x, s * 0.08, 0.0] for x in girdles for s in (1.0, -1.0)])
    feet = hips + np.array([0.0, 0.0, -0.3]) + np.array([0.0, 1.0, 0.0]) * np.sign(hips[:, 1:2]) * 0.2
    return SpineModel.from_legs(joints, hips, feet)


def lizard() -> SpineModel:
    """Thesis figure 4.15: three key nodes (head, shoulders, hips), 9 spine joints, sprawled
    legs whose feet rest out to the side."""
    xs = np.linspace(0.3, -0.2, 9)
    joints = np.stack([xs, np.zeros(9), np.zeros(9)], axis=1)
    hips = np.array([[xs[3], 0.03, 0.0], [xs[3], -0.03, 0.0], [xs[8], 0.03, 0.0], [xs[8], -0.03, 0.0]])
    feet = hips + np.array([[0.0, 0.08, -0.05], [0.0, -0.08, -0.05], [0.0, 0.08, -0.05], [0.0, -0.08, -0.05]])
    return SpineModel.from_legs(joints, hips, feet)


def flat(xy: np.ndarray) -> np.ndarray:
    return np.zeros(xy.shape[:-1])


def rest_world(model: SpineModel, origin: np.ndarray, heading: float, lift: float) -> np.ndarray:
    c, s = np.cos(heading), np.sin(heading)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return model.joint_rest @ rot.T + np.array([origin[0], origin[1], lift])


def bone_yaw_pitch(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = np.diff(joints, axis=-2)
    return np.arctan2(v[..., 1], v[..., 0]), np.arctan2(v[..., 2], np.hypot(v[..., 0], v[..., 1]))


def run_turn(model: SpineModel, params: SpineParams, heading: float, speed: float, steps: int,
             height_at: Callable[[np.ndarray], np.ndarray] = flat,
             ) -> tuple[list[SpinePlan], list[np.ndarray], list[object]]:
    sb = SpineBatch.of(model, params)
    state = SpineState.at_rest(model, np.zeros((1, 2)), 0.0)
    plans, joints, poses = [], [], []
    for _ in range(steps):
        state, plan, pose = spine_step(sb, state, heading, speed * DT, DT, ground_guides(sb, height_at))
        plans.append(plan)
        joints.append(pose.joints[0])
        poses.append(pose)
    return plans, joints, poses


# ------------------------------------------------------------------------------ model


def test_model_finds_key_nodes_from_the_legs() -> None:
    m = quadruped()
    assert m.key_joint.tolist() == [0, 2, 6]
    assert m.leg_key.tolist() == [1, 1, 2, 2]
    assert m.anchor_key == 2  # the hips: most legs, back-most on a tie
    assert m.key_rest_height == pytest.approx([0.6, 0.5, 0.5])
    assert m.node_yaw_limit[1] == pytest.approx(0.5 * 5 * np.radians(25.0))


def test_bad_spines_are_refused() -> None:
    joints = np.array([[0.5, 0, 0], [0.0, 0, 0], [-0.5, 0, 0]])
    hips = np.array([[0.5, 0.1, 0.0]])
    with pytest.raises(ValueError, match="head"):
        SpineModel.from_legs(joints, hips, hips - [0, 0, 0.4])
    with pytest.raises(ValueError, match="zero length"):
        SpineModel.build(np.array([[0.5, 0, 0], [0.5, 0, 0], [-0.5, 0, 0]]), [0, 2], [1], hips, hips)
    with pytest.raises(ValueError, match="head"):
        SpineModel.build(joints, [0, 2], [0], hips, hips)
    with pytest.raises(ValueError, match="key_joint"):
        SpineModel.build(joints, [0, 1], [1], hips, hips)


# --------------------------------------------------------------------- steps 1, 2 and 4


@pytest.mark.parametrize("arched", [False, True])
def test_walking_straight_keeps_the_rest_pose_exactly(arched: bool) -> None:
    m = quadruped(arched=arched)
    heading = 0.7
    sb = SpineBatch.of(m)
    state = SpineState.at_rest(m, np.array([[1.0, 2.0]]), heading)
    for i in range(20):
        state, plan, pose = spine_step(sb, state, heading, 0.05, DT, ground_guides(sb, flat))
        moved = np.array([1.0, 2.0]) + 0.05 * (i + 1) * np.array([np.cos(heading), np.sin(heading)])
        expected = rest_world(m, moved, heading, lift=0.5)
        assert np.abs(pose.joints[0] - expected).max() < 1e-9
        assert np.abs(plan.bend).max() < 1e-12


def test_turning_90_degrees_bends_progressively_from_the_head() -> None:
    m = quadruped()
    plans, joints, _ = run_turn(m, SpineParams(), heading=np.pi / 2, speed=1.0, steps=90)
    key_heading = np.array([p.key_heading[0] for p in plans])  # (T, K)
    # Head, shoulders and hips pass 45 degrees in that order, each clearly after the other.
    first = [int(np.argmax(key_heading[:, k] > np.pi / 4)) for k in range(3)]
    assert first[0] < first[1] - 2 < first[2] - 4
    # Along the chain, every bone turns past 45 degrees no earlier than the bone in front.
    yaw, _ = bone_yaw_pitch(np.array(joints))  # (T, J - 1); bones point backward
    heading_of_bone = wrap_angle(yaw - np.pi)
    passed = [int(np.argmax(heading_of_bone[:, b] > np.pi / 4)) for b in range(yaw.shape[1])]
    assert passed == sorted(passed)
    assert passed[-1] > passed[0]
    # While turning, the chain is bent: head bone ahead of the hip bone by a clear angle.
    assert (heading_of_bone[:, 0] - heading_of_bone[:, -1]).max() > np.radians(30)
    # In the end the whole body faces the new heading and is straight again.
    assert heading_of_bone[-1] == pytest.approx(np.full(yaw.shape[1], np.pi / 2), abs=np.radians(1.0))


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_turning_keeps_every_joint_within_its_limits_and_bones_exact(side: float) -> None:
    m = quadruped()
    # A sharp U-turn at speed, to the left and to the right: the bends reach their limits.
    plans, joints, _ = run_turn(m, SpineParams(turn_rate=np.radians(720)), heading=side * (np.pi - 1e-3),
                                speed=1.5, steps=60)
    rest_yaw, _ = bone_yaw_pitch(m.joint_rest)
    for plan, j in zip(plans, joints, strict=True):
        assert np.all(np.abs(plan.bend[0]) <= m.node_yaw_limit + 1e-9)
        lengths = np.linalg.norm(np.diff(j, axis=0), axis=1)
        assert np.abs(lengths - m.bone_length).max() < 1e-12
        # Measured on the output: the change of turn at each inner joint, from rest.
        yaw, _ = bone_yaw_pitch(j)
        dev = wrap_angle(yaw - rest_yaw)
        turn = np.abs(wrap_angle(np.diff(dev)))
        assert np.all(turn <= m.joint_yaw_limit[1:-1] + 1e-9)
    # The turn really strained the spine (step 1 bends it up to the limit; advancing on
    # the support then opens it a little before the plan is returned).
    assert max(np.abs(p.bend[0, 1]) for p in plans) > 0.85 * m.node_yaw_limit[1]


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_following_the_head_never_bends_a_node_past_its_limit(side: float) -> None:
    """Advancing on the support carries a bend backward along the body, like a train on its
    track; a node that may bend less than the one in front is brought back to its limit."""
    h = hexapod_like()
    m = SpineModel.build(h.joint_rest, h.key_joint, h.leg_key, h.hip_rest, h.foot_rest,
                         node_yaw_limit=np.radians([0.0, 40.0, 8.0, 0.0]))
    plans, joints, _ = run_turn(m, SpineParams(relax_time=1e9), heading=side * np.pi / 2, speed=1.0, steps=60)
    bends = np.array([p.bend[0] for p in plans])
    assert np.all(np.abs(bends) <= m.node_yaw_limit + 1e-9)
    assert np.abs(bends[:, 2]).max() == pytest.approx(np.radians(8.0))  # the limit did bind
    assert np.all(side * bends >= -1e-9)  # every node bends toward the turn
    for j in joints:
        assert np.abs(np.linalg.norm(np.diff(j, axis=0), axis=1) - m.bone_length).max() < 1e-12


def test_tight_joint_limits_bind_on_the_final_chain() -> None:
    m = quadruped(joint_yaw_limit=np.radians(4.0))
    m = SpineModel.build(m.joint_rest, m.key_joint, m.leg_key, m.hip_rest, m.foot_rest,
                         joint_yaw_limit=np.radians(4.0), node_yaw_limit=np.radians(60.0))
    _, joints, _ = run_turn(m, SpineParams(), heading=np.pi / 2, speed=1.0, steps=30)
    rest_yaw, _ = bone_yaw_pitch(m.joint_rest)
    worst = 0.0
    for j in joints:
        yaw, _ = bone_yaw_pitch(j)
        turn = np.abs(wrap_angle(np.diff(wrap_angle(yaw - rest_yaw))))
        assert np.all(turn <= np.radians(4.0) + 1e-9)
        worst = max(worst, float(turn.max()))
    assert worst == pytest.approx(np.radians(4.0))  # the limit was reached: it did bind


def test_without_the_spine_the_body_turns_rigidly() -> None:
    m = quadruped()
    params = SpineParams(flexible=False)
    plans, joints, _ = run_turn(m, params, heading=np.pi / 2, speed=1.0, steps=60)
    rest_gaps = np.linalg.norm(m.joint_rest[:, None] - m.joint_rest[None], axis=2)
    for plan, j in zip(plans, joints, strict=True):
        assert np.ptp(plan.key_heading[0]) < 1e-12  # every node faces the same way
        assert np.abs(plan.bend).max() < 1e-12
        gaps = np.linalg.norm(j[:, None] - j[None], axis=2)
        assert np.abs(gaps - rest_gaps).max() < 1e-9
    headings = np.array([p.steer_heading[0] for p in plans])
    assert headings == pytest.approx(np.array([p.key_heading[0, 0] for p in plans]))
    # The body turns at the turn rate until it faces the new heading.
    assert np.diff(headings)[:10] == pytest.approx(np.full(10, params.turn_rate * DT))
    assert headings[-1] == pytest.approx(np.pi / 2)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_turning_in_place_saturates_from_the_head_then_rotates_about_the_node_behind_it(side: float) -> None:
    m = hexapod_like()
    assert m.n_keys == 4
    params = SpineParams(turn_rate=np.radians(90), relax_time=1e9)  # step 1 alone
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    lim = m.node_yaw_limit
    bends, node1 = [], []
    for _ in range(80):
        plan = plan_spine(SpineBatch.of(m, params), state, side * (np.pi - 1e-6), 0.0, DT)
        state = SpineState(plan.key_xy)
        bends.append(np.abs(plan.bend[0]))
        node1.append(plan.key_xy[0, 1].copy())
    bends_arr = np.array(bends)
    at_limit = bends_arr[:, 1:3] >= lim[1:3] - 1e-9  # (T, 2)
    full1 = int(np.argmax(at_limit[:, 0]))
    full_all = int(np.argmax(at_limit.all(axis=1)))
    assert 0 < full1 < full_all
    # The node behind the head bends first; the next one only once the first is at its limit.
    assert np.all(bends_arr[:full1, 2] < 1e-12)
    assert bends_arr[full_all, 2] > np.radians(5)
    assert np.all(bends_arr <= lim + 1e-9)
    # Then every node is constrained: the whole spine rotates about the node behind the head.
    pivot = np.array(node1[full_all:])
    assert np.abs(pivot - pivot[0]).max() < 1e-8  # (limits are met to 1e-9 rad)
    seg = plan.key_xy[0, 0] - plan.key_xy[0, 1]
    assert abs(wrap_angle(np.arctan2(seg[1], seg[0]) - side * np.pi)) < 1e-5


def test_back_node_relaxes_over_time() -> None:
    m = quadruped()
    params = SpineParams(turn_rate=np.radians(240), relax_time=0.5)
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    for _ in range(8):  # bend the spine by turning in place
        state = SpineState(plan_spine(SpineBatch.of(m, params), state, np.pi / 2, 0.0, DT).key_xy)
    heading = np.arctan2(*(state.key_xy[0, 0] - state.key_xy[0, 1])[::-1])
    bend0 = abs(plan_spine(SpineBatch.of(m, params), state, heading, 0.0, 0.0).bend[0, 1])
    assert bend0 > np.radians(20)
    # Standing still, facing where the head faces: the back straightens as exp(-t / relax).
    for _ in range(15):
        plan = plan_spine(SpineBatch.of(m, params), state, heading, 0.0, DT)
        state = SpineState(plan.key_xy)
    assert abs(plan.bend[0, 1]) == pytest.approx(bend0 * np.exp(-15 * DT / 0.5), rel=1e-6)


def test_nodes_follow_the_path_of_the_head() -> None:
    """On the support of the previous spine, the girdles walk where the head walked."""
    m = quadruped()
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    params = SpineParams(turn_rate=np.radians(45))
    head_path = [state.key_xy[0, 0].copy()]
    for _ in range(120):
        plan = plan_spine(SpineBatch.of(m, params), state, np.pi / 2, 0.02, DT)
        state = SpineState(plan.key_xy)
        head_path.append(plan.key_xy[0, 0].copy())
    path = np.array(head_path)
    # Distance from the shoulders to the head's polyline stays small (cm), though the
    # shoulders never took a step of their own.
    seg_a, seg_b = path[:-1], path[1:]
    d = seg_b - seg_a
    rel = plan.key_xy[0, 1] - seg_a
    t = np.clip(np.einsum("ij,ij->i", rel, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-18), 0, 1)
    gap = np.linalg.norm(seg_a + t[:, None] * d - plan.key_xy[0, 1], axis=1).min()
    assert gap < 0.01


def test_characters_are_independent_in_a_batch() -> None:
    m = quadruped()
    sb = SpineBatch.of(m)
    origins = np.array([[0.0, 0.0], [3.0, 1.0], [-2.0, 4.0]])
    headings = np.array([0.0, 1.0, -2.0])
    targets = np.array([1.5, -0.5, 2.9])
    speeds = np.array([0.5, 1.0, 0.0])
    batch = SpineState.at_rest(m, origins, headings)
    singles = [SpineState.at_rest(m, origins[i:i + 1], headings[i]) for i in range(3)]
    for _ in range(25):
        batch, _, pose = spine_step(sb, batch, targets, speeds * DT, DT, ground_guides(sb, flat))
        for i in range(3):
            singles[i], _, single_pose = spine_step(sb, singles[i], targets[i], speeds[i] * DT, DT,
                                                    ground_guides(sb, flat))
            assert np.allclose(pose.joints[i], single_pose.joints[0], atol=1e-12)


# ----------------------------------------------------------------------------- step 3


def stairs(rise: float = 0.1, run: float = 0.3, start: float = 1.0, n: int = 12) -> Environment:
    """A flight of steps going up along +x as static crates (each one from its nosing to
    the top of the flight), on a flat heightmap."""
    ground = Heightmap(np.zeros((2, 2)), origin=np.array([-5.0, -5.0]), cell=20.0)
    x0 = start + run * np.arange(n)
    x1 = start + run * n
    centre = np.stack([0.5 * (x0 + x1), np.zeros(n), np.zeros(n)], axis=1)
    size = np.stack([x1 - x0, np.full(n, 4.0), rise * np.arange(1, n + 1)], axis=1)
    boxes = Boxes(centre, size, np.zeros(n), np.full(n, ROLE_GROUND), np.zeros(n, dtype=bool))
    return Environment(heightmap=ground, boxes=boxes)


def test_spine_stays_above_stairs_and_pitches_with_them() -> None:
    m = quadruped()
    env = stairs()
    sb = SpineBatch.of(m)
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    pitches = []
    whole_body_pitch = []
    for _ in range(150):  # 3 m at 0.6 m/s: over the first step and well up the stairs
        state, _, pose = spine_step(sb, state, 0.0, 0.02, DT, ground_guides(sb, env.height_at))
        j = pose.joints[0]
        clearance = j[:, 2] - env.height_at(j[:, :2])
        assert clearance.min() > 0.25  # the body never touches the steps
        hips_x = j[-1, 0]
        if hips_x > 1.0 + m.slice_margin:  # the whole body is over the stairs
            pitches.append(pose.key_pitch[0])
            d = j[0] - j[-1]
            whole_body_pitch.append(np.arctan2(d[2] - 0.1, np.hypot(d[0], d[1])))
    stair_angle = np.arctan2(0.1, 0.3)
    assert len(pitches) > 30
    assert np.mean(pitches) == pytest.approx(stair_angle, abs=np.radians(4))
    assert np.mean(whole_body_pitch) == pytest.approx(stair_angle, abs=np.radians(3))


def test_node_over_a_hole_keeps_the_ground_under_the_body() -> None:
    m = quadruped()
    # Two platforms 0.2 m high with a trench between them (x in -0.02 .. 0.48): nothing there.
    platforms = Boxes(np.array([[-2.02, 0.0, 0.0], [2.48, 0.0, 0.0]]), np.array([[4.0, 4.0, 0.2]] * 2),
                      np.zeros(2), np.full(2, ROLE_GROUND), np.zeros(2, dtype=bool))
    env = Environment(boxes=platforms)
    assert env.height_at(np.array([[0.3, 0.0]]))[0] == NO_SURFACE
    plan = plan_spine(SpineBatch.of(m), SpineState.at_rest(m, np.zeros((1, 2)), 0.0), 0.0, 0.0, DT)
    node_z, pitch = terrain_guides(SpineBatch.of(m), plan, env.height_at)
    # The shoulders' whole stretch is over the trench: they keep the height the rest of the
    # body stands at instead of falling in.
    assert node_z[0] == pytest.approx(0.2 + m.key_rest_height)
    assert pitch[0] == pytest.approx(np.zeros(3))


def test_feet_on_a_crate_raise_their_node() -> None:
    m = quadruped()
    plan = plan_spine(SpineBatch.of(m), SpineState.at_rest(m, np.zeros((1, 2)), 0.0), 0.0, 0.0, DT)
    feet = (m.foot_rest + np.array([0.0, 0.0, 0.5]))[None].copy()
    feet[0, 2:, 2] = 0.3  # both hind feet up on something the slice did not see
    node_z, _ = terrain_guides(SpineBatch.of(m), plan, lambda xy: np.zeros(len(xy)), feet)
    assert node_z[0, 2] == pytest.approx(0.3 + m.key_rest_height[2])
    assert node_z[0, 1] == pytest.approx(m.key_rest_height[1])


def test_ramp_gives_exact_pitch_and_constant_height_above_ground() -> None:
    m = quadruped()
    slope = np.radians(15)

    xs = np.arange(-2.0, 8.01, 0.5)
    terrain = Environment(heightmap=Heightmap(np.tile(np.tan(slope) * xs, (21, 1)),
                                              origin=np.array([-2.0, -5.0]), cell=0.5))

    def ramp(xy: np.ndarray) -> np.ndarray:
        return terrain.height_at(np.reshape(xy, (-1, 2))).reshape(np.shape(xy)[:-1])

    state = SpineState.at_rest(m, np.array([[2.0, 0.0]]), 0.0)
    plan = plan_spine(SpineBatch.of(m), state, 0.0, 0.0, DT)
    node_z, env = terrain_guides(SpineBatch.of(m), plan, ramp)
    assert env[0] == pytest.approx(np.full(3, slope), abs=1e-9)
    assert node_z[0] == pytest.approx(ramp(plan.key_xy[0]) + m.key_rest_height, abs=1e-9)
    pose = finish_spine(SpineBatch.of(m), plan, node_z, env)
    _, pitch = bone_yaw_pitch(pose.joints[0])
    _, rest_pitch = bone_yaw_pitch(m.joint_rest)
    # Bones point backward: a nose-up slope tilts each of them down by the slope. (Near the
    # raised head a little less: node heights are vertical offsets above the ground.)
    assert pitch[2:] - rest_pitch[2:] == pytest.approx(np.full(4, -slope), abs=np.radians(0.5))
    assert pitch[:2] - rest_pitch[:2] == pytest.approx(np.full(2, -slope), abs=np.radians(3.0))
    # Facing downhill, the pitch is negative.
    back = SpineState.at_rest(m, np.array([[2.0, 0.0]]), np.pi)
    _, env_down = terrain_guides(SpineBatch.of(m), plan_spine(SpineBatch.of(m), back, np.pi, 0.0, DT), ramp)
    assert env_down[0] == pytest.approx(np.full(3, -slope), abs=1e-9)


def test_feet_induce_pitch_averaged_with_the_environment() -> None:
    m = quadruped()
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    plan = plan_spine(SpineBatch.of(m), state, 0.0, 0.0, DT)
    node_z = m.key_rest_height[None, :].copy()
    env = np.array([[0.05, 0.05, 0.05]])
    feet = (m.foot_rest + np.array([0.0, 0.0, 0.5]))[None]  # rest feet in the world
    sb = SpineBatch.of(m, SpineParams(foot_pitch_weight=0.5))
    # Feet where they stand at rest on this ground (flat here): they induce the ground's
    # own pitch, so the node keeps the environment pitch.
    assert node_pitch(sb, plan, node_z, env, feet) == pytest.approx(env)
    # Both front feet 0.2 m ahead: each induces atan(0.2 / 0.5) more; averaged half/half.
    ahead = feet.copy()
    ahead[0, :2, 0] += 0.2
    pitch = node_pitch(sb, plan, node_z, env, ahead)
    assert pitch[0, 1] == pytest.approx(0.05 + 0.5 * np.arctan2(0.2, 0.5))
    assert pitch[0, 0] == pytest.approx(0.05)  # the head has no feet
    assert pitch[0, 2] == pytest.approx(0.05)  # hind feet at rest
    # A foot lower than the ground it should stand on lifts the nose less.
    low = feet.copy()
    low[0, 2:, 2] -= 0.1
    assert node_pitch(sb, plan, node_z, env, low)[0, 2] == pytest.approx(0.05)  # right below


def test_splayed_feet_standing_on_a_slope_induce_the_slope() -> None:
    m = hexapod_like()
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    plan = plan_spine(SpineBatch.of(m), state, 0.0, 0.0, DT)
    slope = np.radians(12)
    node_ground = np.tan(slope) * plan.key_xy[0, :, 0]
    node_z = (node_ground + m.key_rest_height)[None]
    feet = m.foot_rest.copy()
    feet[:, 2] = np.tan(slope) * feet[:, 0]  # the feet stand on the slope under the body
    env = np.full((1, 4), slope)
    pitch = node_pitch(SpineBatch.of(m, SpineParams(foot_pitch_weight=1.0)), plan, node_z, env, feet[None])
    assert pitch[0] == pytest.approx(env[0], abs=1e-9)


# ------------------------------------------------------------------------- visual yaw


def test_visual_yaw_turns_the_girdle_toward_the_feet_offsets() -> None:
    m = lizard()
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    plan = plan_spine(SpineBatch.of(m), state, 0.0, 0.0, DT)
    feet = (m.foot_rest + np.array([0.0, 0.0, 0.05]))[None].copy()
    params = SpineParams(visual_yaw=True)
    assert visual_yaw(SpineBatch.of(m, params), plan, feet) == pytest.approx(np.zeros((1, 3)))
    # Left front foot forward, right front foot back: both feet swing clockwise about the
    # shoulders, so the shoulders turn right (negative yaw) by the feet's mean angle.
    feet[0, 0, 0] += 0.04
    feet[0, 1, 0] -= 0.04
    yaw = visual_yaw(SpineBatch.of(m, params), plan, feet)
    one_foot = np.arctan2(0.04, 0.11)
    assert yaw[0, 1] == pytest.approx(-one_foot)
    assert yaw[0, 0] == 0.0
    assert yaw[0, 2] == pytest.approx(0.0)

    node_z = m.key_rest_height[None, :] + 0.0
    on = finish_spine(SpineBatch.of(m, params), plan, node_z, np.zeros((1, 3)), feet)
    off = finish_spine(SpineBatch.of(m, SpineParams(visual_yaw=False)), plan, node_z, np.zeros((1, 3)), feet)
    frames_on = on.key_frames(m)[0]
    frames_off = off.key_frames(m)[0]
    shoulder_yaw_on = np.arctan2(frames_on[1, 1, 0], frames_on[1, 0, 0])
    shoulder_yaw_off = np.arctan2(frames_off[1, 1, 0], frames_off[1, 0, 0])
    assert shoulder_yaw_off == pytest.approx(0.0, abs=1e-12)
    assert shoulder_yaw_on < -0.5 * one_foot
    # The effect is visual: the spine still has its exact bone lengths and the hips stay put.
    lengths = np.linalg.norm(np.diff(on.joints[0], axis=0), axis=1)
    assert np.abs(lengths - m.bone_length).max() < 1e-12
    assert on.key_positions(m)[0, 2] == pytest.approx(off.key_positions(m)[0, 2])


def test_visual_yaw_is_clamped() -> None:
    m = lizard()
    plan = plan_spine(SpineBatch.of(m), SpineState.at_rest(m, np.zeros((1, 2)), 0.0), 0.0, 0.0, DT)
    feet = (m.foot_rest + np.array([0.0, 0.0, 0.05]))[None].copy()
    feet[0, 0, 0] += 0.5
    feet[0, 1, 0] -= 0.5
    clamped = SpineBatch.of(m, SpineParams(visual_yaw=True, max_visual_yaw=np.radians(20)))
    yaw = visual_yaw(clamped, plan, feet)
    assert yaw[0, 1] == pytest.approx(-np.radians(20))


# ------------------------------------------------------------------- reach and hips


def test_hips_ride_with_their_girdle() -> None:
    m = quadruped()
    pose = build_spine(SpineBatch.of(m), np.array([[[0.6, 0.0, 0.6], [0.3, 0.0, 0.5], [-0.3, 0.0, 0.5]]]),
                       np.zeros((1, 3)), np.zeros((1, 3)))
    assert hip_positions(SpineBatch.of(m), pose)[0] == pytest.approx(m.hip_rest + np.array([0.0, 0.0, 0.5]))
    # Turned by 90 degrees about z: the hips turn with it.
    turned = build_spine(SpineBatch.of(m), np.array([[[0.0, 0.6, 0.6], [0.0, 0.3, 0.5], [0.0, -0.3, 0.5]]]),
                         np.full((1, 3), np.pi / 2), np.zeros((1, 3)))
    hips = hip_positions(SpineBatch.of(m), turned)[0]
    expected = np.stack([-m.hip_rest[:, 1], m.hip_rest[:, 0], m.hip_rest[:, 2] + 0.5], axis=1)
    assert hips == pytest.approx(expected)


def test_step_four_is_repeated_until_the_legs_reach() -> None:
    m = quadruped()
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    plan = plan_spine(SpineBatch.of(m), state, 0.0, 0.0, DT)
    pose = finish_spine(SpineBatch.of(m), plan, m.key_rest_height[None, :], np.zeros((1, 3)))
    feet = (m.foot_rest + np.array([0.0, 0.0, 0.5]))[None].copy()
    feet[0, :2, 2] -= 0.15  # the front feet stand in a hole: 0.65 m below the shoulders
    reach = np.full(4, 0.55)
    before = np.linalg.norm(feet[0] - hip_positions(SpineBatch.of(m), pose)[0], axis=1)
    assert before[:2].min() > 0.55
    fixed = repeat_for_reach(SpineBatch.of(m), pose, feet, reach, iterations=6)
    after = np.linalg.norm(feet[0] - hip_positions(SpineBatch.of(m), fixed)[0], axis=1)
    assert after.max() <= 0.55 + 1e-3
    assert fixed.guide_xyz[0, 1, 2] < pose.guide_xyz[0, 1, 2] - 0.05  # the shoulders dropped
    lengths = np.linalg.norm(np.diff(fixed.joints[0], axis=0), axis=1)
    assert np.abs(lengths - m.bone_length).max() < 1e-12


def test_negative_distance_means_standing_still() -> None:
    m = quadruped()
    state = SpineState.at_rest(m, np.zeros((1, 2)), 0.0)
    plan = plan_spine(SpineBatch.of(m), state, 0.0, -1.0, DT)  # negative distance is clamped
    assert plan.key_xy == pytest.approx(state.key_xy)
    assert plan.distance[0] == 0.0


# ------------------------------------------------------------- carrier bones, feet ahead


def test_hips_ride_with_their_carrier_bone_like_a_child_bone() -> None:
    """With ``leg_bone`` set, a hip keeps its rest offset in its carrier bone's frame, about
    the bone's back joint: what a rig does with a leg parented to a spine bone."""
    base = quadruped()
    # front legs carried by bone 2 (joints 2-3), hind legs by bone 5 (joints 5-6)
    m = SpineModel.build(base.joint_rest, base.key_joint, base.leg_key, base.hip_rest, base.foot_rest,
                         leg_bone=[2, 2, 5, 5])
    assert m.leg_pivot.tolist() == [3, 3, 6, 6]
    # a bent spine: the head guide swung to the left and lowered
    pose = build_spine(SpineBatch.of(m), np.array([[[0.55, 0.25, 0.5], [0.3, 0.0, 0.5], [-0.3, 0.0, 0.5]]]),
                       np.array([[0.8, 0.4, 0.0]]), np.array([[0.1, 0.05, 0.0]]))
    hips = hip_positions(SpineBatch.of(m), pose)[0]
    for leg, bone in enumerate([2, 2, 5, 5]):
        rot = pose.bone_rotation[0, bone]
        back = m.leg_pivot[leg]
        expected = pose.joints[0, back] + rot @ (m.hip_rest[leg] - m.joint_rest[back])
        assert hips[leg] == pytest.approx(expected)
        # rigidly attached to the bone: its distances to both ends of the bone are the rest ones
        for joint in (bone, bone + 1):
            assert np.linalg.norm(hips[leg] - pose.joints[0, joint]) == pytest.approx(
                np.linalg.norm(m.hip_rest[leg] - m.joint_rest[joint]))
    frames = leg_frames(SpineBatch.of(m), pose)[0]
    assert frames[0] == pytest.approx(pose.bone_rotation[0, 2])
    assert frames[3] == pytest.approx(pose.bone_rotation[0, 5])
    # the default (no carrier) keeps the key node frames
    assert leg_frames(SpineBatch.of(base), pose)[0, 0] == pytest.approx(pose.key_frames(base)[0, 1])
    with pytest.raises(ValueError, match="leg_bone"):
        SpineModel.build(base.joint_rest, base.key_joint, base.leg_key, base.hip_rest, base.foot_rest,
                         leg_bone=[2, 2, 6, 6])


def test_feet_ahead_of_their_node_on_a_step_lift_its_nose() -> None:
    """A foot standing ahead of its node on something higher tilts that node's hull up at
    the front (the slice runs from the head to the back: ahead is before the node)."""
    m = quadruped()
    plan = plan_spine(SpineBatch.of(m), SpineState.at_rest(m, np.zeros((1, 2)), 0.0), 0.0, 0.0, DT)
    feet = (m.foot_rest + np.array([0.0, 0.0, 0.5]))[None].copy()
    feet[0, :2, :2] += [0.15, 0.0]  # front feet 0.15 m ahead of the shoulders...
    feet[0, :2, 2] = 0.1  # ... up on a step
    _, pitch = terrain_guides(SpineBatch.of(m), plan, flat, feet)
    assert pitch[0, 1] > np.radians(10)  # nose up
    feet[0, :2, :2] -= [0.3, 0.0]  # the same step behind the shoulders: nose down
    _, pitch = terrain_guides(SpineBatch.of(m), plan, flat, feet)
    assert pitch[0, 1] < -np.radians(10)


def test_reach_repeat_moves_a_node_by_its_one_stretched_leg_and_is_bounded() -> None:
    m = quadruped()
    plan = plan_spine(SpineBatch.of(m), SpineState.at_rest(m, np.zeros((1, 2)), 0.0), 0.0, 0.0, DT)
    pose = finish_spine(SpineBatch.of(m), plan, m.key_rest_height[None, :], np.zeros((1, 3)))
    feet = (m.foot_rest + np.array([0.0, 0.0, 0.5]))[None].copy()
    feet[0, 2, 0] -= 0.2  # one hind foot left 0.2 m behind: 0.54 m from its hip
    reach = np.full(4, 0.52)
    fixed = repeat_for_reach(SpineBatch.of(m), pose, feet, reach, iterations=4)
    after = np.linalg.norm(feet[0] - hip_positions(SpineBatch.of(m), fixed)[0], axis=1)
    assert after.max() <= 0.52 + 1e-9
    # bounded: the hips may not move more than max_shift, so the leg stays stretched
    held = repeat_for_reach(SpineBatch.of(m), pose, feet, reach, iterations=4, max_shift=0.005)
    moved = np.linalg.norm(held.guide_xyz - pose.guide_xyz, axis=-1)
    assert moved.max() <= 0.005 + 1e-12
    assert np.linalg.norm(feet[0, 2] - hip_positions(SpineBatch.of(m), held)[0, 2]) > 0.52


def _limit_joints_walk(
    model: SpineModel, yaw_dev: np.ndarray, pitch_dev: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The joint limits walked bone by bone outward from the anchor joint, every time: the
    reference for ``_limit_joints``, which skips the walk when no joint is at its limit."""
    yaw, pitch = yaw_dev.copy(), pitch_dev.copy()
    n_b = yaw.shape[1]
    ref = min(int(model.key_joint[model.anchor_key]), n_b - 1)
    for b in [*range(ref + 1, n_b), *range(ref - 1, -1, -1)]:
        o = b - 1 if b > ref else b + 1
        j = max(b, o)
        yl, pl = model.joint_yaw_limit[j], model.joint_pitch_limit[j]
        yaw[:, b] = yaw[:, o] + np.clip(wrap_angle(yaw[:, b] - yaw[:, o]), -yl, yl)
        pitch[:, b] = pitch[:, o] + np.clip(pitch[:, b] - pitch[:, o], -pl, pl)
    return yaw, pitch


@pytest.mark.parametrize("scale", [0.2, 0.9, 3.0])
def test_joint_limits_equal_the_bone_by_bone_walk(scale: float) -> None:
    model = hexapod_like()
    rng = np.random.default_rng(int(scale * 10))
    n_b = model.n_joints - 1
    limit = float(model.joint_yaw_limit[1])
    yaw = np.cumsum(rng.uniform(-scale, scale, (20, n_b)) * limit, axis=1)
    pitch = np.cumsum(rng.uniform(-scale, scale, (20, n_b)) * float(model.joint_pitch_limit[1]), axis=1)
    got_y, got_p = _limit_joints(model, yaw, pitch)
    want_y, want_p = _limit_joints_walk(model, yaw, pitch)
    assert_close(got_y, want_y, "yaw")
    assert_close(got_p, want_p, "pitch")
    if scale < 0.5:  # within the limits nothing changes
        assert_close(got_y, yaw, "yaw unchanged")


def test_frames_and_bone_rotations_are_the_turns_they_name() -> None:
    rng = np.random.default_rng(4)
    yaw, pitch = rng.uniform(-3.0, 3.0, (2, 10))
    f = frame_from_yaw_pitch(yaw, pitch)
    c, s = np.cos(yaw), np.sin(yaw)
    rz = np.zeros((10, 3, 3))
    rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = c, -s, s, c, 1.0
    cp, sp = np.cos(pitch), np.sin(pitch)
    ry = np.zeros((10, 3, 3))  # nose up: about -y
    ry[:, 0, 0], ry[:, 0, 2], ry[:, 2, 0], ry[:, 2, 2], ry[:, 1, 1] = cp, -sp, sp, cp, 1.0
    assert_close(f, rz @ ry, "frame")
    # each bone's rest chord turned back onto +x by the model's rest_unturn
    model = quadruped(arched=True)
    chord = np.stack([np.cos(model.rest_chord_pitch) * np.cos(model.rest_chord_yaw),
                      np.cos(model.rest_chord_pitch) * np.sin(model.rest_chord_yaw),
                      np.sin(model.rest_chord_pitch)], axis=-1)
    assert_close(np.einsum("bij,bj->bi", model.rest_unturn, chord),
                 np.broadcast_to([1.0, 0.0, 0.0], chord.shape), "unturn")


# ------------------------------------------------------------------ batches of spines


def _scaled(model: SpineModel, scale: float, **kwargs: object) -> SpineModel:
    """``model`` ``scale`` times larger (same structure), with other limits if given."""
    return SpineModel.build(model.joint_rest * scale, model.key_joint, model.leg_key, model.hip_rest * scale,
                            model.foot_rest * scale, leg_bone=model.leg_bone, **kwargs)  # type: ignore[arg-type]


def _wavy(xy: np.ndarray) -> np.ndarray:
    return 0.05 * np.sin(1.7 * xy[..., 0]) * np.cos(1.1 * xy[..., 1])


def test_a_batch_of_different_spines_steps_each_as_it_would_alone() -> None:
    """Spines of one structure but other sizes, limits and settings stepped as one batch (a
    herd of wolves in one simulation) give each character what it gets alone, step by step:
    steps 1-2 while turning, the terrain guides and the feet's pitch, the visual yaw of the
    characters that have it, step 4 and its reach repeats with some characters stretched
    and others not (floats to the cross-path tolerance: the batch is another array shape)."""
    base = quadruped(arched=True)
    models = [base, _scaled(base, 1.3, joint_yaw_limit=np.radians(12.0)),
              _scaled(base, 0.8, node_yaw_limit=0.3)]
    params = [SpineParams(), SpineParams(turn_rate=np.radians(200), relax_time=0.3, foot_pitch_weight=0.8),
              SpineParams(visual_yaw=True, visual_yaw_gain=0.7, turn_rate=np.radians(60))]
    batch = SpineBatch.stack(models, params)
    alone = [SpineBatch.of(m, p) for m, p in zip(models, params, strict=True)]
    assert batch.n_rows == 3
    origins = np.array([[0.0, 0.0], [2.0, 1.0], [-1.5, 2.5]])
    headings = np.array([0.0, 1.0, -2.0])
    targets = np.array([1.6, -0.8, 2.9])
    speeds = np.array([0.6, 1.0, 0.4])
    size = np.array([1.0, 1.3, 0.8])
    reach = np.array([0.56, 10.0, 0.56]) * size  # the first and last get stretched, the middle one never
    state = SpineState.at_rest(batch, origins, headings)
    states = [SpineState.at_rest(a, origins[i:i + 1], headings[i]) for i, a in enumerate(alone)]
    pulls = np.zeros(3, dtype=int)  # steps in which the repeats moved each character's guides
    for step in range(40):
        plan = plan_spine(batch, state, targets, speeds * DT, DT)
        state = SpineState(plan.key_xy)
        free = finish_spine(batch, plan, *terrain_guides(batch, plan, _wavy))
        # feet under the hips, swinging fore and aft: pitch, visual yaw and reach all act
        feet = hip_positions(batch, free)
        feet[..., 2] -= 0.55 * size[:, None]
        feet[..., 0] += 0.12 * size[:, None] * np.sin(0.4 * step + np.arange(4))
        z, env_pitch = terrain_guides(batch, plan, _wavy, feet)
        pitch = node_pitch(batch, plan, z, env_pitch, feet)
        pose = finish_spine(batch, plan, z, env_pitch, feet)
        pulled = repeat_for_reach(batch, pose, feet, reach[:, None] * np.ones(4), iterations=4,
                                  max_shift=np.array([0.05, 0.08, 0.04]))
        moved = np.abs(pulled.guide_xyz - pose.guide_xyz).max(axis=(1, 2)) > 0.0
        pulls += moved
        for i, a in enumerate(alone):
            plan_i = plan_spine(a, states[i], targets[i], speeds[i] * DT, DT)
            states[i] = SpineState(plan_i.key_xy)
            assert_close(plan.key_xy[i], plan_i.key_xy[0], "key_xy")
            assert_close(plan.key_heading[i], plan_i.key_heading[0], "key_heading")
            z_i, env_i = terrain_guides(a, plan_i, _wavy, feet[i:i + 1])
            assert_close(z[i], z_i[0], "height")
            assert_close(env_pitch[i], env_i[0], "env pitch")
            assert_close(pitch[i], node_pitch(a, plan_i, z_i, env_i, feet[i:i + 1])[0], "pitch")
            pose_i = finish_spine(a, plan_i, z_i, env_i, feet[i:i + 1])
            assert_close(pose.joints[i], pose_i.joints[0], "joints")
            assert_close(pose.joint_frame[i], pose_i.joint_frame[0], "frames")
            pulled_i = repeat_for_reach(a, pose_i, feet[i:i + 1], reach[i] * np.ones(4), iterations=4,
                                        max_shift=[0.05, 0.08, 0.04][i])
            assert_close(pulled.joints[i], pulled_i.joints[0], "pulled joints")
            assert_close(hip_positions(batch, pulled)[i], hip_positions(a, pulled_i)[0], "hips")
    # the repeats ran on part of the batch (the characters still stretched), not on all of it
    assert pulls[1] == 0
    assert pulls[[0, 2]].min() > 20
    # the settings did act: the visual yaw turned the third character's nodes only
    assert np.abs(pose.key_yaw[2] - plan.key_heading[2]).max() > 0.01
    assert np.abs(pose.key_yaw[:2] - plan.key_heading[:2]).max() == 0.0


def test_a_batch_needs_one_structure_and_one_kind_of_spine() -> None:
    m = quadruped()
    with pytest.raises(ValueError, match="structure"):
        SpineBatch.stack([m, hexapod_like()], [SpineParams(), SpineParams()])
    with pytest.raises(ValueError, match="flexible and rigid"):
        SpineBatch.stack([m, _scaled(m, 1.2)], [SpineParams(), SpineParams(flexible=False)])
    with pytest.raises(ValueError, match="one each"):
        SpineBatch.stack([m, m], [SpineParams()])
    # sizes, limits and carriers' rows may differ; the structure is what the indices use
    assert _scaled(m, 2.0, joint_pitch_limit=0.1).structure == m.structure


def test_taking_rows_of_a_batch_takes_every_per_character_array() -> None:
    """``SpineBatch.take`` (the characters still stretched in the reach repeats) selects
    every array with a row per character, and only those."""
    m = quadruped()
    models = [_scaled(m, 1.0 + 0.1 * i) for i in range(5)]  # 5 rows: no other axis is 5 long
    batch = SpineBatch.stack(models, [SpineParams(turn_rate=1.0 + i) for i in range(5)])
    rows = np.array([1, 3])
    sub = batch.take(rows)
    for f in fields(SpineBatch):
        value = getattr(batch, f.name)
        if isinstance(value, np.ndarray) and value.shape[:1] == (5,):
            np.testing.assert_array_equal(getattr(sub, f.name), value[rows], err_msg=f.name)
        elif isinstance(value, np.ndarray) and value.shape[:2] == (2, 5):  # (yaw, pitch) pairs of rows
            np.testing.assert_array_equal(getattr(sub, f.name), value[:, rows], err_msg=f.name)
        elif isinstance(value, np.ndarray):
            assert getattr(sub, f.name) is value, f.name
    assert sub.models == (models[1], models[3])
    one = SpineBatch.of(m)
    assert one.take(rows) is one  # one row broadcasts over any characters
