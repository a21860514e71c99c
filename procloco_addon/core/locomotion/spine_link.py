# SPDX-License-Identifier: GPL-3.0-or-later
"""The link between the controller and ``core.locomotion.spine`` (thesis §4.2, §4.4): every loop over
the spine groups lives here.

A character whose morphology has a spine and which is given ``SpineParams`` walks on its
virtual pelvis nodes instead of one rigid pelvis. ``SpineLink`` holds the pelvis nodes of
every character (one per rigid character, ``K`` per spine) and the groups of characters
stepped together through the spine functions (one shared model and settings); the functions
below are the controller's steps for them: set-up (``build_link``, ``start``), steps 1-2
(``advance``), the feedback shift (``shift``), step 3 (``guides``), step 4 with the reach
pull and its release (``pose``), where each leg's node will be when its foot lands
(``landing_refs``) and the read-outs (``joints``, ``bone_rotations``).
Characters without a spine never reach this module's loops.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..geometry import rotate_xy, vector_norm, wrap_angle
from .morphology import LegBatch
from .pelvis import Body
from .spine import (
    SpineModel,
    SpineParams,
    SpinePlan,
    SpinePose,
    SpineState,
    build_spine,
    hip_positions,
    leg_frames,
    node_pitch,
    plan_spine,
    pose_rows,
    pose_with_rows,
    refit,
    repeat_for_reach,
    terrain_guides,
    visual_yaw,
)
from .types import BoolArray, ControllerParams, FloatArray, IntArray, StepControls


@dataclass(eq=False)
class SpineGroup:
    """Characters stepped together through the spine functions: one shared ``SpineModel``
    and ``SpineParams``. ``chars (g,)``; ``legs (g, L)`` flat leg rows; ``nodes (g, K)`` flat
    pelvis-node rows; ``plan``/``pose``: the last steps 1-2 and step 4; ``height``,
    ``pitch (g, K)``: each node's filtered preferred height and pitch (deviation from rest);
    ``reach_shift (g, K, 3)``: how far the last step 4 moved each node's guide so the legs
    reach their feet (released gradually, see ``ControllerParams.reach_release_time``)."""

    model: SpineModel
    params: SpineParams
    chars: IntArray
    legs: IntArray
    nodes: IntArray
    plan: SpinePlan
    pose: SpinePose | None = None
    height: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    pitch: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    reach_shift: FloatArray | None = None


@dataclass
class SpineLink:
    """Pelvis nodes and spine groups of every character.

    ``params``: each character's ``SpineParams`` or None; ``has_spine (C,)``; ``node_start
    (C + 1,)``: first node row of each character; ``node_char (n_nodes,)``; ``leg_node
    (N,)``: the node each leg hangs from; ``spine_legs``: rows of the legs on a spine;
    ``hips``, ``hips_free (N, 3)``: where the spine puts each hip (after and before step 4's
    reach pull; only spine legs' rows are used); ``leg_rot (N, 3, 3)``: each spine leg's
    frame."""

    params: list[SpineParams | None]
    has_spine: BoolArray
    node_start: IntArray
    n_nodes: int
    node_char: IntArray
    leg_node: IntArray
    spine_legs: IntArray
    max_spine_joints: int
    hips: FloatArray
    hips_free: FloatArray
    leg_rot: FloatArray
    groups: list[SpineGroup]

    @property
    def all_legs(self) -> bool:
        """Every leg hangs from a spine (nothing rigid)."""
        return bool(self.spine_legs.size == self.hips.shape[0])


def build_link(legs: LegBatch, spine: Sequence[SpineParams | None] | None) -> SpineLink:
    """Pelvis nodes (one per rigid character, ``K`` per spine) and the spine groups."""
    c, n, lc = legs.n_chars, legs.n_legs, legs.leg_char
    params: list[SpineParams | None] = list(spine) if spine is not None else [None] * c
    if len(params) != c:
        raise ValueError(f"{len(params)} spine settings for {c} characters")
    has_spine = np.array([sp is not None for sp in params], dtype=bool)
    counts = np.ones(c, dtype=np.int64)
    grouped: dict[tuple[int, SpineParams], list[int]] = {}
    models: dict[int, SpineModel] = {}
    for i, sp in enumerate(params):
        if sp is None:
            continue
        model = legs.morphologies[i].spine
        if model is None:
            raise ValueError(f"character {i} has spine settings but its morphology has no spine")
        counts[i] = model.n_keys
        models[id(model)] = model
        grouped.setdefault((id(model), sp), []).append(i)
    node_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    local = np.where(has_spine[lc], legs.pelvis_node, 0)
    groups: list[SpineGroup] = []
    for (mid, sp), chars in grouped.items():
        model = models[mid]
        ch = np.array(chars, dtype=np.int64)
        start = legs.leg_start
        leg_rows = np.stack([np.arange(start[i], start[i + 1]) for i in chars])
        nodes = node_start[ch][:, None] + np.arange(model.n_keys)[None, :]
        empty = SpinePlan(np.zeros((ch.size, model.n_keys, 2)), np.zeros((ch.size, model.n_keys)),
                          np.zeros((ch.size, model.n_keys)), np.zeros(ch.size), np.zeros(ch.size))
        groups.append(SpineGroup(model, sp, ch, leg_rows, nodes, empty))
    return SpineLink(
        params=params, has_spine=has_spine, node_start=node_start, n_nodes=int(node_start[-1]),
        node_char=np.repeat(np.arange(c), counts), leg_node=(node_start[lc] + local).astype(np.int64),
        spine_legs=np.flatnonzero(has_spine[lc]),
        max_spine_joints=max((m.n_joints for m in models.values()), default=0),
        hips=np.zeros((n, 3)), hips_free=np.zeros((n, 3)), leg_rot=np.zeros((n, 3, 3)), groups=groups,
    )


def start(
    link: SpineLink, height_at: Callable[[FloatArray], FloatArray], body: Body, support: FloatArray,
    height: FloatArray,
) -> FloatArray:
    """Spines at rest where the bodies stand (feet as the body rests on them, ``support (N,
    3)``); returns every node's preferred height ``(n_nodes,)`` (the rigid characters' hull
    heights ``height (C,)`` for theirs)."""
    pref = np.asarray(height, dtype=np.float64)[link.node_char].copy()
    for g in link.groups:
        state = SpineState.at_rest(g.model, body.pos[g.chars, :2], body.yaw[g.chars])
        g.plan = plan_spine(g.model, state, g.params, body.yaw[g.chars], 0.0, 0.0)
        h, env_pitch = terrain_guides(g.model, g.plan, height_at, support[g.legs])
        g.height = h
        g.pitch = node_pitch(g.model, g.plan, h, env_pitch, support[g.legs], g.params)
        pref[g.nodes] = h
    return pref


def body_from_plan(g: SpineGroup, body: Body) -> None:
    """The body frame of spine characters from their anchor node on the ground plane
    (the pelvis the planner windows and the records refer to)."""
    m = g.model
    k = m.anchor_key
    yaw = wrap_angle(g.plan.key_heading[:, k] - m.rest_key_heading[k])
    body.yaw[g.chars] = yaw
    rest = np.broadcast_to(m.key_rest[k, :2], (yaw.size, 2))
    body.pos[g.chars, :2] = g.plan.key_xy[:, k] - rotate_xy(rest, yaw)


def advance(link: SpineLink, body: Body, ctl: StepControls, dt: float) -> None:
    """Steps 1-2 (thesis §4.2.1-4.2.2): the head turns toward the commanded heading and
    moves ``speed * dt``; the other nodes follow on the previous spine. Hips move with
    their node in the ground plane until step 4 places them."""
    for g in link.groups:
        old = g.plan.key_xy
        g.plan = plan_spine(
            g.model, SpineState(old), g.params, ctl.heading[g.chars], ctl.speed[g.chars] * dt, dt
        )
        moved = g.plan.key_xy - old
        link.hips[g.legs, :2] += moved[:, g.model.leg_key]
        link.hips_free[g.legs, :2] += moved[:, g.model.leg_key]
        body_from_plan(g, body)


def shift(link: SpineLink, move: FloatArray) -> None:
    """Move every spine's nodes and hips by its character's ground-plane ``move (C, 2)``
    (the feet-error feedback)."""
    for g in link.groups:
        d = move[g.chars]
        g.plan.key_xy[...] += d[:, None, :]
        link.hips[g.legs, :2] += d[:, None, :]
        link.hips_free[g.legs, :2] += d[:, None, :]


def guides(
    link: SpineLink, height_at: Callable[[FloatArray], FloatArray], rigid_height: FloatArray,
    support: FloatArray, alpha: FloatArray,
) -> FloatArray:
    """Step 3 (thesis §4.2.3): each node's preferred height (its hull slice plus its rest
    height) and pitch (environment and feet ``support (N, 3)``), low-pass filtered by
    ``alpha (C,)`` like the rigid pelvis. Returns every node's preferred height
    ``(n_nodes,)`` (rigid characters: their filtered hull height ``rigid_height (C,)``)."""
    pref = rigid_height[link.node_char].copy()
    for g in link.groups:
        feet = support[g.legs]
        height, env_pitch = terrain_guides(g.model, g.plan, height_at, feet)
        a = alpha[g.chars][:, None]
        g.height = g.height + a * (height - g.height)
        pitch = node_pitch(g.model, g.plan, g.height, env_pitch, feet, g.params)
        g.pitch = g.pitch + a * (pitch - g.pitch)
        pref[g.nodes] = g.height
    return pref


@dataclass(frozen=True)
class PoseInputs:
    """What step 4 of the spines reads from the feet and the rig (all ``(N, ...)``): where
    the feet are (``foot``), which swing and where they land (``swinging``, ``target``), how
    far each swing is (``swing_u``), and each leg's ``guard_reach`` and ``foot_lift``; and
    every character's ``body_thickness (C,)``."""

    foot: FloatArray
    swinging: BoolArray
    target: FloatArray
    swing_u: FloatArray
    guard_reach: FloatArray
    foot_lift: FloatArray
    body_thickness: FloatArray


def pose(
    link: SpineLink, body: Body, p: ControllerParams, at: PoseInputs, node_z: FloatArray,
    physics_on: BoolArray, dt: float,
) -> None:
    """Step 4 (thesis §4.2.4): the spine curve through the nodes at ``node_z
    (n_nodes,)`` (nodes without legs keep their guide), turned by the visual yaw (§4.4),
    repeated on guides pulled toward the feet while a leg cannot reach; then the hips,
    leg frames and body frame of every spine character."""
    for g in link.groups:
        m = g.model
        has_legs = np.bincount(m.leg_key, minlength=m.n_keys) > 0
        z = np.where(physics_on[g.chars][:, None] & has_legs[None, :], node_z[g.nodes], g.height)
        yaw = g.plan.key_heading
        if g.params.visual_yaw:
            yaw = yaw + visual_yaw(m, g.plan, at.foot[g.legs], g.params)
        guide = np.concatenate([g.plan.key_xy, z[..., None]], axis=-1)
        pose = build_spine(m, guide, yaw, g.pitch)
        hips_free = hip_positions(m, pose)
        link.hips_free[g.legs] = hips_free
        # bounded like the rigid pelvis's guard: a foot beyond help steps early instead
        max_shift = p.guard_max_drop * float(at.body_thickness[g.chars[0]])
        free = pose
        reach = spine_reach(g, at, p.swing_reach_slack)
        # a swinging foot pulls as if it were already down at its landing height (within
        # its growing reach), so the body is as low as that foot needs when it lands
        feet = at.foot[g.legs].copy()
        swing = at.swinging[g.legs]
        feet[swing, 2] = np.minimum(feet[swing, 2], at.target[g.legs][swing, 2])
        feet[..., 2] += at.foot_lift[g.legs]
        pose = repeat_for_reach(m, pose, feet, reach, iterations=6, max_shift=max_shift, hips=hips_free)
        pose, g.reach_shift = release_pull(g, free, pose, feet, reach, dt, p.reach_release_time)
        g.pose = pose
        frames = leg_frames(m, pose)
        link.hips[g.legs] = hip_positions(m, pose, frames)
        link.leg_rot[g.legs] = frames
        aj = int(m.key_joint[m.anchor_key])
        frame = pose.joint_frame[:, aj]
        body.pos[g.chars] = pose.joints[:, aj] - np.einsum("cij,j->ci", frame, m.joint_rest[aj])
        body.yaw[g.chars] = np.arctan2(frame[:, 1, 0], frame[:, 0, 0])
        body.pitch[g.chars] = np.arctan2(frame[:, 2, 0], np.hypot(frame[:, 0, 0], frame[:, 1, 0]))
        body.roll[g.chars] = 0.0
        body.height_target[g.chars] = body.pos[g.chars, 2]


def release_pull(
    g: SpineGroup, free: SpinePose, pulled: SpinePose, feet: FloatArray, reach: FloatArray,
    dt: float, release_time: float,
) -> tuple[SpinePose, FloatArray]:
    """A node pulled toward a stretched leg's foot goes back to its guide over
    ``release_time``, not in one frame when the foot steps (the chest would drop and
    spring back by centimetres per frame); the pull itself acts at once. ``free``: step
    4 without pulls, ``pulled``: with this frame's pulls. Returns the pose and each
    node's guide shift ``(g, K, 3)`` (kept for the next frame)."""
    need = pulled.guide_xyz - free.guide_xyz
    if g.reach_shift is None or g.reach_shift.shape != need.shape or dt <= 0.0:
        return pulled, need
    decayed = g.reach_shift * float(np.exp(-dt / max(release_time, 1e-9)))
    keep = vector_norm(decayed) > vector_norm(need)
    if not keep.any():
        return pulled, need
    trial = np.where(keep[..., None], decayed, need)
    m = g.model
    slow = refit(m, free, free.guide_xyz + trial)
    # kept only where it leaves no leg further from its foot than the pull did
    over = vector_norm(feet - hip_positions(m, slow)) > np.maximum(
        vector_norm(feet - hip_positions(m, pulled)), reach
    ) + 1e-9
    ok = ~over.any(axis=1)
    rows = np.flatnonzero(ok)
    out = pose_with_rows(pulled, rows, pose_rows(slow, rows)) if rows.size else pulled
    return out, np.where(ok[:, None, None], trial, need)


def spine_reach(g: SpineGroup, at: PoseInputs, slack_share: float) -> FloatArray:
    """``(g, L)`` how far each leg of a spine group may reach before it pulls its node
    toward its foot: the guard's reach for a planted foot; for a swinging one (which pulls
    as if already down at its landing height), more the earlier in its swing
    (``slack_share``, ``swing_reach_slack``), so that the body lowers gradually over a swing
    down a step, not all at once as the foot lands."""
    legs = g.legs
    early = 1.0 - at.swing_u[legs]
    slack = np.where(at.swinging[legs], slack_share * early, 0.0)
    return np.asarray(at.guard_reach[legs] * (1.0 + slack))


def landing_refs(
    link: SpineLink, legs_data: LegBatch, legs: IntArray, c_of: IntArray, ctl: StepControls,
    remaining: FloatArray, out: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
) -> None:
    """Where the spine node each spine leg in ``legs (m,)`` (of characters ``c_of (m,)``)
    hangs from will be when its foot lands ``remaining (N,)`` seconds from now, written into
    ``out`` = (ground position ``(m, 2)``, heading ``(m,)``, the node's rest position ``(m,
    3)`` and rest heading ``(m,)``). A node moves along the spine it is on (the nodes follow
    the head's path, thesis §4.2.2) and past the head along the head's own extrapolated
    arc."""
    ref_xy, yaw_land, ref_rest, rest_yaw = out
    for g in link.groups:
        rows = np.flatnonzero(np.isin(c_of, g.chars))
        if rows.size == 0:
            continue
        m, plan = g.model, g.plan
        chars = c_of[rows]
        r = np.searchsorted(g.chars, chars)
        k = m.leg_key[legs[rows] - legs_data.leg_start[chars]]
        xy = plan.key_xy[r]  # (m, K, 2)
        heading = plan.key_heading[r]
        arc = np.concatenate([np.zeros((rows.size, 1)),
                              np.cumsum(vector_norm(xy[:, 1:] - xy[:, :-1]), axis=1)], axis=1)
        speed = ctl.speed[chars]
        dist = speed * remaining[legs[rows]]
        at = np.arange(rows.size)
        s = arc[at, k] - dist
        # on the spine: between node i and node i + 1
        i = np.clip(np.sum(arc[:, 1:-1] < s[:, None], axis=1), 0, m.n_keys - 2)
        span = arc[at, i + 1] - arc[at, i]
        f = np.clip((s - arc[at, i]) / np.maximum(span, 1e-12), 0.0, 1.0)
        on_xy = xy[at, i] + f[:, None] * (xy[at, i + 1] - xy[at, i])
        on_yaw = heading[at, i] + f * wrap_angle(heading[at, i + 1] - heading[at, i])
        # past the head: the head's arc toward the commanded heading
        ahead = np.maximum(-s, 0.0)
        limit = g.params.turn_rate * ahead / np.maximum(speed, 1e-9)
        head_turn = np.clip(wrap_angle(ctl.heading[chars] - plan.steer_heading[r]), -limit, limit)
        mid = heading[:, 0] + 0.5 * head_turn
        past_xy = xy[:, 0] + ahead[:, None] * np.stack([np.cos(mid), np.sin(mid)], axis=1)
        past = s < 0.0
        ref_xy[rows] = np.where(past[:, None], past_xy, on_xy)
        yaw_land[rows] = np.where(past, heading[:, 0] + head_turn, on_yaw)
        ref_rest[rows] = m.key_rest[k]
        rest_yaw[rows] = m.rest_key_heading[k]


def joints(link: SpineLink, pos: FloatArray) -> FloatArray:
    """``(C, J, 3)`` world spine joints (head first) of every character, ``J`` the most
    joints of any spine; rows past a spine's end repeat its last joint, characters
    without a spine hold their pelvis position ``pos (C, 3)``."""
    out = np.repeat(pos[:, None, :], link.max_spine_joints, axis=1)
    for g in link.groups:
        if g.pose is None:
            continue
        j = g.model.n_joints
        out[g.chars, :j] = g.pose.joints
        out[g.chars, j:] = g.pose.joints[:, -1:]
    return out


def bone_rotations(link: SpineLink, n_chars: int) -> FloatArray:
    """``(C, J - 1, 3, 3)`` rotation of every spine bone from its rest (body-frame)
    direction to the world (``SpinePose.bone_rotation``); identity past a spine's end and
    for characters without a spine."""
    out = np.zeros((n_chars, max(link.max_spine_joints - 1, 0), 3, 3))
    out[:] = np.eye(3)
    for g in link.groups:
        if g.pose is not None:
            out[g.chars, : g.model.n_joints - 1] = g.pose.bone_rotation
    return out
