# SPDX-License-Identifier: GPL-3.0-or-later
"""The link between the controller and ``core.locomotion.spine`` (thesis §4.2, §4.4): every loop over
the spine groups lives here.

A character whose morphology has a spine and which is given ``SpineParams`` walks on its
virtual pelvis nodes instead of one rigid pelvis. ``SpineLink`` holds the pelvis nodes of
every character (one per rigid character, ``K`` per spine) and the groups of characters
stepped together through the spine functions: every character whose spine has the same
structure (``SpineModel.structure``: key joints, the legs' nodes and bones) and the same
``flexible`` setting is in one group, as one ``SpineBatch`` with each character's own rest
geometry and settings, so many characters cost the array operations of one; the functions
below are the controller's steps for them: set-up (``build_link``, ``start``), steps 1-2
(``advance``), the feedback shift (``shift``), step 3 (``guides``), step 4 with the reach
pull and its release (``pose``), where each leg's node will be when its foot lands
(``landing_refs``) and the read-outs (``joints``, ``bone_rotations``).
Characters without a spine never reach this module's loops.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..geometry import rotate_xy, vector_norm, wrap_angle
from .morphology import LegBatch
from .pelvis import Body
from .spine import (
    SpineBatch,
    SpineModel,
    SpineParams,
    SpinePlan,
    SpinePose,
    SpineState,
    build_fresh,
    feet_ahead,
    hip_positions,
    leg_frames,
    node_pitch,
    plan_spine,
    pose_rows,
    pose_with_rows,
    reach_repeats,
    refit,
    terrain_guides,
    visual_yaw,
)
from .types import BoolArray, ControllerParams, FloatArray, IntArray, StepControls


@dataclass(eq=False)
class SpineGroup:
    """Characters stepped together through the spine functions: ``spines``, one
    ``SpineBatch`` (one structure; each character's own ``SpineModel`` and ``SpineParams``).
    ``chars (g,)``; ``legs (g, L)`` flat leg rows; ``nodes (g, K)`` flat
    pelvis-node rows; ``plan``/``pose``: the last steps 1-2 and step 4; ``height``,
    ``pitch (g, K)``: each node's filtered preferred height and pitch (deviation from rest);
    ``reach_shift (g, K, 3)``: how far the last step 4 moved each node's guide so the legs
    reach their feet (released gradually, see ``ControllerParams.reach_release_time``)."""

    spines: SpineBatch
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
    frame; ``char_group``, ``char_row (C,)``: each character's group (-1 without a spine)
    and its row in it."""

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
    char_group: IntArray
    char_row: IntArray

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
    # one group per spine structure (and rigid or flexible): characters of different sizes,
    # proportions and settings step together
    grouped: dict[tuple[object, ...], list[int]] = {}
    models: list[SpineModel | None] = [None] * c
    for i, sp in enumerate(params):
        if sp is None:
            continue
        model = legs.morphologies[i].spine
        if model is None:
            raise ValueError(f"character {i} has spine settings but its morphology has no spine")
        counts[i] = model.n_keys
        models[i] = model
        grouped.setdefault((model.structure, sp.flexible), []).append(i)
    node_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    local = np.where(has_spine[lc], legs.pelvis_node, 0)
    groups: list[SpineGroup] = []
    char_group = np.full(c, -1, dtype=np.int64)
    char_row = np.zeros(c, dtype=np.int64)
    for chars in grouped.values():
        spines = SpineBatch.stack([m for i in chars if (m := models[i]) is not None],
                                  [sp for i in chars if (sp := params[i]) is not None])
        ch = np.array(chars, dtype=np.int64)
        char_group[ch] = len(groups)
        char_row[ch] = np.arange(ch.size)
        start = legs.leg_start
        leg_rows = np.stack([np.arange(start[i], start[i + 1]) for i in chars])
        k = spines.n_keys
        nodes = node_start[ch][:, None] + np.arange(k)[None, :]
        empty = SpinePlan(np.zeros((ch.size, k, 2)), np.zeros((ch.size, k)), np.zeros((ch.size, k)),
                          np.zeros(ch.size), np.zeros(ch.size))
        groups.append(SpineGroup(spines, ch, leg_rows, nodes, empty))
    return SpineLink(
        params=params, has_spine=has_spine, node_start=node_start, n_nodes=int(node_start[-1]),
        node_char=np.repeat(np.arange(c), counts), leg_node=(node_start[lc] + local).astype(np.int64),
        spine_legs=np.flatnonzero(has_spine[lc]),
        max_spine_joints=max((m.n_joints for m in models if m is not None), default=0),
        hips=np.zeros((n, 3)), hips_free=np.zeros((n, 3)), leg_rot=np.zeros((n, 3, 3)), groups=groups,
        char_group=char_group, char_row=char_row,
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
        state = SpineState.at_rest(g.spines, body.pos[g.chars, :2], body.yaw[g.chars])
        g.plan = plan_spine(g.spines, state, body.yaw[g.chars], 0.0, 0.0)
        h, env_pitch = terrain_guides(g.spines, g.plan, height_at, support[g.legs])
        g.height = h
        g.pitch = node_pitch(g.spines, g.plan, h, env_pitch, support[g.legs])
        pref[g.nodes] = h
    return pref


def body_from_plan(g: SpineGroup, body: Body) -> None:
    """The body frame of spine characters from their anchor node on the ground plane
    (the pelvis the planner windows and the records refer to)."""
    sb = g.spines
    k = sb.anchor_key
    yaw = wrap_angle(g.plan.key_heading[:, k] - sb.rest_key_heading[:, k])
    body.yaw[g.chars] = yaw
    body.pos[g.chars, :2] = g.plan.key_xy[:, k] - rotate_xy(sb.anchor_rest_xy, yaw)


def advance(link: SpineLink, body: Body, ctl: StepControls, dt: float) -> None:
    """Steps 1-2 (thesis §4.2.1-4.2.2): the head turns toward the commanded heading and
    moves ``speed * dt``; the other nodes follow on the previous spine. Hips move with
    their node in the ground plane until step 4 places them."""
    for g in link.groups:
        old = g.plan.key_xy
        g.plan = plan_spine(g.spines, SpineState(old), ctl.heading[g.chars], ctl.speed[g.chars] * dt, dt)
        moved = (g.plan.key_xy - old).take(g.spines.leg_key, axis=1)
        link.hips[g.legs, :2] += moved
        link.hips_free[g.legs, :2] += moved
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
        ahead = feet_ahead(g.spines, g.plan, feet)
        height, env_pitch = terrain_guides(g.spines, g.plan, height_at, feet, ahead=ahead)
        a = alpha[g.chars][:, None]
        g.height = g.height + a * (height - g.height)
        pitch = node_pitch(g.spines, g.plan, g.height, env_pitch, feet, ahead)
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
        sb = g.spines
        c, k = g.nodes.shape
        z = np.where(physics_on[g.chars][:, None] & sb.has_legs, node_z[g.nodes], g.height)
        yaw = g.plan.key_heading
        if sb.any_visual_yaw:
            turn = visual_yaw(sb, g.plan, at.foot[g.legs])
            yaw = yaw + (turn if sb.all_visual_yaw else np.where(sb.visual_yaw[:, None], turn, 0.0))
        guide = np.empty((c, k, 3))
        guide[..., :2] = g.plan.key_xy
        guide[..., 2] = z
        # (build_spine without its copies: the guides are made here, and the plan's headings
        # and the filtered pitch are replaced, not changed in place, from frame to frame)
        pose = build_fresh(sb, guide, yaw, g.pitch)
        hips_free = hip_positions(sb, pose)
        link.hips_free[g.legs] = hips_free
        # bounded like the rigid pelvis's guard: a foot beyond help steps early instead
        max_shift = p.guard_max_drop * at.body_thickness[g.chars]
        free = pose
        reach = spine_reach(g, at, p.swing_reach_slack)
        # a swinging foot pulls as if it were already down at its landing height (within
        # its growing reach), so the body is as low as that foot needs when it lands
        feet = at.foot[g.legs]
        swing = at.swinging[g.legs]
        if np.count_nonzero(swing):
            feet[swing, 2] = np.minimum(feet[swing, 2], at.target[g.legs][swing, 2])
        feet[..., 2] += at.foot_lift[g.legs]
        pose, hips = reach_repeats(sb, pose, feet, reach, iterations=6, max_shift=max_shift, hips=hips_free)
        pose, g.reach_shift, hips = release_pull(g, free, pose, feet, reach, dt, p.reach_release_time, hips)
        g.pose = pose
        frames = leg_frames(sb, pose)
        link.hips[g.legs] = hip_positions(sb, pose, frames) if hips is None else hips
        link.leg_rot[g.legs] = frames
        aj = sb.anchor_joint
        frame = pose.joint_frame[:, aj]
        body.pos[g.chars] = pose.joints[:, aj] - (frame @ sb.anchor_rest[..., None])[..., 0]
        body.yaw[g.chars] = np.arctan2(frame[:, 1, 0], frame[:, 0, 0])
        body.pitch[g.chars] = np.arctan2(frame[:, 2, 0], np.hypot(frame[:, 0, 0], frame[:, 1, 0]))
        body.roll[g.chars] = 0.0
        body.height_target[g.chars] = body.pos[g.chars, 2]


def release_pull(
    g: SpineGroup, free: SpinePose, pulled: SpinePose, feet: FloatArray, reach: FloatArray,
    dt: float, release_time: float, pulled_hips: FloatArray | None = None,
) -> tuple[SpinePose, FloatArray, FloatArray | None]:
    """A node pulled toward a stretched leg's foot goes back to its guide over
    ``release_time``, not in one frame when the foot steps (the chest would drop and
    spring back by centimetres per frame); the pull itself acts at once. ``free``: step
    4 without pulls, ``pulled``: with this frame's pulls (``pulled_hips``: its hips, when
    known). Returns the pose, each node's guide shift ``(g, K, 3)`` (kept for the next
    frame) and the hips of the returned pose when known (else None)."""
    need = pulled.guide_xyz - free.guide_xyz
    if g.reach_shift is None or g.reach_shift.shape != need.shape or dt <= 0.0:
        return pulled, need, pulled_hips
    decayed = g.reach_shift * math.exp(-dt / max(release_time, 1e-9))
    keep = vector_norm(decayed) > vector_norm(need)
    if not np.count_nonzero(keep):
        return pulled, need, pulled_hips
    trial = np.where(keep[..., None], decayed, need)
    sb = g.spines
    slow = refit(sb, free, free.guide_xyz + trial, keep=True)
    slow_hips = hip_positions(sb, slow)
    if pulled_hips is None:
        pulled_hips = hip_positions(sb, pulled)
    # kept only where it leaves no leg further from its foot than the pull did
    over = vector_norm(feet - slow_hips) > np.maximum(vector_norm(feet - pulled_hips), reach) + 1e-9
    ok = ~np.logical_or.reduce(over, axis=1)
    shift = np.where(ok[:, None, None], trial, need)
    n_ok = np.count_nonzero(ok)
    if n_ok == ok.size:
        return slow, shift, slow_hips
    if not n_ok:
        return pulled, shift, pulled_hips
    rows = np.flatnonzero(ok)
    return (pose_with_rows(pulled, rows, pose_rows(slow, rows)), shift,
            np.where(ok[:, None, None], slow_hips, pulled_hips))


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
    group_of = link.char_group[c_of]
    for gi, g in enumerate(link.groups):
        rows = np.flatnonzero(group_of == gi)
        if rows.size == 0:
            continue
        sb, plan = g.spines, g.plan
        chars = c_of[rows]
        r = link.char_row[chars]
        k = sb.leg_key[legs[rows] - legs_data.leg_start[chars]]
        xy = plan.key_xy[r]  # (m, K, 2)
        heading = plan.key_heading[r]
        arc = np.concatenate([np.zeros((rows.size, 1)),
                              np.cumsum(vector_norm(xy[:, 1:] - xy[:, :-1]), axis=1)], axis=1)
        speed = ctl.speed[chars]
        dist = speed * remaining[legs[rows]]
        at = np.arange(rows.size)
        s = arc[at, k] - dist
        # on the spine: between node i and node i + 1
        i = np.clip(np.sum(arc[:, 1:-1] < s[:, None], axis=1), 0, sb.n_keys - 2)
        span = arc[at, i + 1] - arc[at, i]
        f = np.clip((s - arc[at, i]) / np.maximum(span, 1e-12), 0.0, 1.0)
        on_xy = xy[at, i] + f[:, None] * (xy[at, i + 1] - xy[at, i])
        on_yaw = heading[at, i] + f * wrap_angle(heading[at, i + 1] - heading[at, i])
        # past the head: the head's arc toward the commanded heading
        ahead = np.maximum(-s, 0.0)
        limit = sb.turn_rate[r] * ahead / np.maximum(speed, 1e-9)
        head_turn = np.clip(wrap_angle(ctl.heading[chars] - plan.steer_heading[r]), -limit, limit)
        mid = heading[:, 0] + 0.5 * head_turn
        past_xy = xy[:, 0] + ahead[:, None] * np.stack([np.cos(mid), np.sin(mid)], axis=1)
        past = s < 0.0
        ref_xy[rows] = np.where(past[:, None], past_xy, on_xy)
        yaw_land[rows] = np.where(past, heading[:, 0] + head_turn, on_yaw)
        ref_rest[rows] = sb.key_rest[r, k]
        rest_yaw[rows] = sb.rest_key_heading[r, k]


def joints(link: SpineLink, pos: FloatArray) -> FloatArray:
    """``(C, J, 3)`` world spine joints (head first) of every character, ``J`` the most
    joints of any spine; rows past a spine's end repeat its last joint, characters
    without a spine hold their pelvis position ``pos (C, 3)``."""
    full = _all_full(link)
    out = (np.empty((pos.shape[0], link.max_spine_joints, 3)) if full
           else np.repeat(pos[:, None, :], link.max_spine_joints, axis=1))
    for g in link.groups:
        if g.pose is None:
            continue
        j = g.spines.n_joints
        out[g.chars, :j] = g.pose.joints
        out[g.chars, j:] = g.pose.joints[:, -1:]
    return out


def bone_rotations(link: SpineLink, n_chars: int) -> FloatArray:
    """``(C, J - 1, 3, 3)`` rotation of every spine bone from its rest (body-frame)
    direction to the world (``SpinePose.bone_rotation``); identity past a spine's end and
    for characters without a spine."""
    shape = (n_chars, max(link.max_spine_joints - 1, 0), 3, 3)
    if _all_full(link):
        out = np.empty(shape)
    else:
        out = np.zeros(shape)
        out[:] = np.eye(3)
    for g in link.groups:
        if g.pose is not None:
            out[g.chars, : g.spines.n_joints - 1] = g.pose.bone_rotation
    return out


def _all_full(link: SpineLink) -> bool:
    """Every character has a spine of the most joints and a pose: the read-outs above write
    every row of it (nothing to fill in first)."""
    return bool(link.has_spine.all()) and all(
        g.pose is not None and g.spines.n_joints == link.max_spine_joints for g in link.groups)
