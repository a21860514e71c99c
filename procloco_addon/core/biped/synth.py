# SPDX-License-Identifier: GPL-3.0-or-later
"""A small procedural biped clip synthesiser: test clips without motion capture.

The planner needs a clip database; tests, benchmarks and the bundled example must not
depend on motion capture. This module writes clips for a simple human skeleton
(:func:`make_skeleton`) from a few gait parameters:

* walks straight and on arcs of any radius, runs (with the inward lean of a curved run),
  a running jump over a gap, a start from standing, a stop, and idle;
* the feet follow a heel-strike / flat / toe-off roll with the pivot point exactly fixed on
  the ground, swing along a lifted curve, and the legs are solved by the analytic two-bone
  IK with the knee pointing along the foot, so every clip has perfectly planted feet;
* the pelvis bobs, sways, twists and leans; arms and spine counter-swing. The arms swing
  from the shoulder by ``arm_swing`` (±11° walking, as people do; wider running), the
  elbows hang slightly bent (``elbow``) and bend a little more as the arm swings forward
  (``elbow_swing``); the rig's own rest bend of the elbow is taken into account, so a rig
  modelled with bent elbows does not end up bent twice as much.

Every clip is in the normal form of :mod:`.clip` (right touchdown to right touchdown) and
carries its exact foot contacts. :func:`standard_library` returns the full set of roles.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from . import quat
from .clip import Clip, ClipRole
from .skeleton import LEFT, RIGHT, LegJoints, Skeleton, forward_kinematics

FloatArray = NDArray[np.float64]

GRAVITY = 9.81


def make_skeleton(scale: float = 1.0) -> Skeleton:
    """A 22-joint human: pelvis, spine, chest, head, two legs with heel/toe points, two arms.

    Standing height of the pelvis is about ``0.99 * scale`` metres, legs ``0.86 * scale``.
    """
    names = ["pelvis", "spine", "chest", "head"]
    parents = [-1, 0, 1, 2]
    offsets = [(0.0, 0.0, 0.99), (0.0, 0.0, 0.2), (0.0, 0.0, 0.25), (0.0, 0.0, 0.3)]
    legs = {}
    for side, sign, tag in ((LEFT, 1.0, "L"), (RIGHT, -1.0, "R")):
        base = len(names)
        names += [f"thigh.{tag}", f"shin.{tag}", f"foot.{tag}", f"toe.{tag}", f"toe_tip.{tag}", f"heel.{tag}"]
        parents += [0, base, base + 1, base + 2, base + 3, base + 2]
        offsets += [
            (0.0, sign * 0.09, -0.05),
            (0.0, 0.0, -0.44),
            (0.0, 0.0, -0.42),
            (0.13, 0.0, -0.06),
            (0.06, 0.0, -0.02),
            (-0.05, 0.0, -0.08),
        ]
        legs[side] = LegJoints(hip=base, knee=base + 1, ankle=base + 2, heel=base + 5, toe=base + 4)
    for sign, tag in ((1.0, "L"), (-1.0, "R")):
        base = len(names)
        names += [f"upper_arm.{tag}", f"forearm.{tag}", f"hand.{tag}"]
        parents += [2, base, base + 1]
        offsets += [(0.0, sign * 0.18, 0.2), (0.0, 0.0, -0.28), (0.0, 0.0, -0.25)]
    return Skeleton(tuple(names), np.array(parents), np.array(offsets) * scale, legs[LEFT], legs[RIGHT])


@dataclass(frozen=True)
class Gait:
    """Parameters of a synthesised walk or run (lengths in metres, times in seconds).

    ``duty`` is the stance fraction of the stride; ``heel_pitch``/``toe_pitch`` the foot
    angles at touchdown and lift-off (radians), reached over ``heel_phase``/``toe_phase``
    of the stance; ``bob`` the pelvis' vertical amplitude (positive: highest at mid-stance,
    as in walking; negative: lowest, as in running); ``arm_swing`` the shoulder's swing
    amplitude, ``elbow`` the elbow's bend with the arm hanging and ``elbow_swing`` how much
    more it bends at the front of the swing (radians).
    """

    speed: float
    cycle: float
    duty: float
    step_width: float
    step_height: float
    pelvis_height: float
    bob: float
    sway: float
    twist: float
    heel_pitch: float
    toe_pitch: float
    heel_phase: float
    toe_phase: float
    arm_swing: float
    forward_lean: float
    elbow: float = 0.2
    elbow_swing: float = 0.3

    def scaled(self, k: float) -> Gait:
        """The same gait for a body ``k`` times as large (lengths and speeds times ``k``)."""
        return replace(
            self,
            speed=self.speed * k,
            step_width=self.step_width * k,
            step_height=self.step_height * k,
            pelvis_height=self.pelvis_height * k,
            bob=self.bob * k,
            sway=self.sway * k,
        )


#: Leg length (thigh + shin) and standing pelvis height of :func:`make_skeleton` at scale 1,
#: the body the gaits below are written for.
REFERENCE_LEG = 0.86
REFERENCE_STAND = 0.99


def body_scale(skel: Skeleton) -> float:
    """How large ``skel`` is compared with the reference body (ratio of leg lengths)."""
    return float(np.mean(skel.thigh_length + skel.shin_length)) / REFERENCE_LEG


def standing_height(skel: Skeleton) -> float:
    """Height of the pelvis joint above the ground when standing, knees barely bent."""
    return float(skel.offsets[0][2]) - 0.02 * body_scale(skel)


def fit_gait(gait: Gait, skel: Skeleton, step_width: float | None = None) -> Gait:
    """``gait`` (written for the reference body) fitted to ``skel``: scaled by its leg length,
    the pelvis as far below this skeleton's rest height as the reference's below its own,
    and the feet ``step_width`` apart when given."""
    k = body_scale(skel)
    g = gait.scaled(k)
    g = replace(g, pelvis_height=float(skel.offsets[0][2]) - k * (REFERENCE_STAND - gait.pelvis_height))
    return replace(g, step_width=step_width) if step_width is not None else g


WALK = Gait(
    speed=1.2,
    cycle=1.0,
    duty=0.6,
    step_width=0.17,
    step_height=0.06,
    pelvis_height=0.92,
    bob=0.01,
    sway=0.02,
    twist=0.08,
    heel_pitch=0.25,
    toe_pitch=0.45,
    heel_phase=0.15,
    toe_phase=0.3,
    arm_swing=0.2,
    forward_lean=0.03,
    elbow=0.2,
    elbow_swing=0.3,
)
RUN = Gait(
    speed=3.0,
    cycle=0.72,
    duty=0.36,
    step_width=0.12,
    step_height=0.16,
    pelvis_height=0.9,
    bob=-0.025,
    sway=0.01,
    twist=0.12,
    heel_pitch=0.05,
    toe_pitch=0.6,
    heel_phase=0.1,
    toe_phase=0.45,
    arm_swing=0.5,
    forward_lean=0.12,
    elbow=1.35,
    elbow_swing=0.25,
)


@dataclass(frozen=True)
class _Plant:
    """One stance of one foot: time interval, footprint centre on the ground and heading."""

    td: float
    lo: float
    pos: FloatArray
    yaw: float
    heel_pitch: float
    toe_pitch: float
    heel_phase: float
    toe_phase: float
    swing_height: float  # lift of the swing that *leaves* this plant
    swing_ease: float = 1.0  # 1: ease in and out of the swing; 0: constant speed (long flights)


def _foot_geometry(skel: Skeleton, side: int) -> tuple[FloatArray, FloatArray]:
    rest_pos, _ = forward_kinematics(skel, quat.identity((skel.n_joints,)), skel.offsets[0])
    leg = skel.leg(side)
    return rest_pos[leg.heel] - rest_pos[leg.ankle], rest_pos[leg.toe] - rest_pos[leg.ankle]


def _pitch_rot(yaw: float, pitch: float) -> FloatArray:
    return quat.mul(quat.from_yaw(yaw), quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), pitch))


def _stance_pose(p: _Plant, sigma: float, heel: FloatArray, toe: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Ankle position and foot rotation at stance fraction ``sigma`` of plant ``p``."""
    mid = 0.5 * (heel + toe)
    flat_rot = quat.from_yaw(p.yaw)
    ankle_flat = p.pos - quat.rotate(flat_rot, mid)
    if sigma < p.heel_phase and p.heel_pitch > 0.0:
        pitch = -p.heel_pitch * (1.0 - sigma / p.heel_phase) ** 2
        pivot = heel
    elif sigma > 1.0 - p.toe_phase:
        pitch = p.toe_pitch * ((sigma - (1.0 - p.toe_phase)) / p.toe_phase) ** 2
        pivot = toe
    else:
        return ankle_flat, flat_rot
    pivot_world = ankle_flat + quat.rotate(flat_rot, pivot)
    rot = _pitch_rot(p.yaw, pitch)
    return pivot_world - quat.rotate(rot, pivot), rot


def _foot_track(
    t: FloatArray, plants: list[_Plant], heel: FloatArray, toe: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Ankle ``(n, 3)``, foot rotation ``(n, 4)`` and contact ``(n,)`` of one foot."""
    n = len(t)
    ankle = np.zeros((n, 3))
    rot = np.zeros((n, 4))
    contact = np.zeros(n, dtype=bool)
    for i, ti in enumerate(t):
        k = next((j for j, p in enumerate(plants) if p.td - 1e-9 <= ti <= p.lo + 1e-9), None)
        if k is not None:
            p = plants[k]
            sigma = (ti - p.td) / max(p.lo - p.td, 1e-9)
            ankle[i], rot[i] = _stance_pose(p, min(max(sigma, 0.0), 1.0), heel, toe)
            contact[i] = True
            continue
        k = next(j for j in range(len(plants) - 1) if plants[j].lo < ti < plants[j + 1].td)
        a, b = plants[k], plants[k + 1]
        s = (ti - a.lo) / (b.td - a.lo)
        a0, _ = _stance_pose(a, 1.0, heel, toe)
        a1, _ = _stance_pose(b, 0.0, heel, toe)
        e = s + a.swing_ease * (s * s * (3.0 - 2.0 * s) - s)
        pos = a0 + (a1 - a0) * e
        pos[2] = a0[2] + (a1[2] - a0[2]) * s + a.swing_height * np.sin(np.pi * s) ** 1.5
        yaw = a.yaw + quat.wrap_angle(b.yaw - a.yaw) * e
        pitch = a.toe_pitch + (-b.heel_pitch - a.toe_pitch) * e
        ankle[i] = pos
        rot[i] = _pitch_rot(float(yaw), float(pitch))
        # Keep heel and toe above the ground plane of the two plants.
        ground = min(a.pos[2], b.pos[2]) + (max(a.pos[2], b.pos[2]) - min(a.pos[2], b.pos[2])) * e
        low = min(quat.rotate(rot[i], heel)[2], quat.rotate(rot[i], toe)[2]) + ankle[i][2]
        if low < ground + 0.005:
            ankle[i][2] += ground + 0.005 - low
    return ankle, rot, contact


def _min_filter_then_mean(x: FloatArray, k: int, periodic: bool) -> FloatArray:
    """Smooth a signal downwards: every output is at most the input (see the drop below)."""
    if k <= 1:
        return x
    pad = k // 2
    xp = np.pad(x, pad, mode="wrap") if periodic else np.pad(x, pad, mode="edge")
    mins = np.lib.stride_tricks.sliding_window_view(xp, k).min(axis=1)
    mp = np.pad(mins, pad, mode="wrap") if periodic else np.pad(mins, pad, mode="edge")
    return np.convolve(mp, np.ones(k) / k, mode="valid")[: len(x)]


def _children(skel: Skeleton, j: int) -> list[int]:
    return [int(c) for c in np.flatnonzero(skel.parents == j)]


def spine_chain(skel: Skeleton) -> list[int]:
    """The joints from the pelvis up to the head: at each joint, the child that reaches
    highest (in the rest pose), leaving out the legs. Empty when the pelvis has no such child."""
    rest, _ = forward_kinematics(skel, quat.identity((skel.n_joints,)), skel.offsets[0])
    legs = {skel.left.hip, skel.right.hip}
    chain: list[int] = []
    j = 0
    while True:
        kids = [c for c in _children(skel, j) if c not in legs and rest[c, 2] >= rest[j, 2] - 1e-9]
        if not kids:
            return chain
        j = max(kids, key=lambda c: rest[c, 2])
        chain.append(j)


def hanging_arms(skel: Skeleton) -> tuple[tuple[int, int], tuple[int, int]]:
    """``(upper, lower)`` joints of the left and right arms when the arms hang down at rest
    (bones named ``upper_arm``/``forearm`` with ``.L``/``.R``); ``-1`` where there is none.
    Arms held out (a T pose) are left alone: a swing about the body's side axis would wave
    them."""
    rest, _ = forward_kinematics(skel, quat.identity((skel.n_joints,)), skel.offsets[0])
    out = []
    for tag in ("L", "R"):
        upper = next((i for i, n in enumerate(skel.names) if n.lower() == f"upper_arm.{tag.lower()}"), -1)
        lower = next((i for i, n in enumerate(skel.names) if n.lower() == f"forearm.{tag.lower()}"), -1)
        if upper >= 0 and lower >= 0 and skel.parents[lower] == upper:
            d = rest[lower] - rest[upper]
            if d[2] < -0.7 * np.linalg.norm(d):
                out.append((upper, lower))
                continue
        out.append((-1, -1))
    return out[0], out[1]


def rest_elbow_bend(skel: Skeleton, forearm: int) -> float:
    """How far (radians, forwards positive) the forearm already points ahead of the upper
    arm in the rest pose, seen from the side; 0 when the forearm has no child to aim at."""
    kids = _children(skel, forearm)
    if not kids:
        return 0.0
    upper_dir = skel.offsets[forearm]
    fore_dir = skel.offsets[kids[0]]
    pitch = np.arctan2(fore_dir[0], -fore_dir[2]) - np.arctan2(upper_dir[0], -upper_dir[2])
    return float(pitch)


def _assemble(
    skel: Skeleton,
    name: str,
    role: ClipRole,
    dt: float,
    t: FloatArray,
    root_xy: FloatArray,
    root_yaw: FloatArray,
    pelvis_z: FloatArray,
    pelvis_y: FloatArray,
    roll: FloatArray,
    twist: FloatArray,
    pitch: FloatArray,
    plants: tuple[list[_Plant], list[_Plant]],
    arm_phase: FloatArray,
    arm_swing: float | FloatArray,
    periodic: bool,
    elbow: float = 0.0,
    elbow_swing: float | FloatArray = 0.0,
) -> Clip:
    """Solve the legs for the given root, pelvis and foot plans and package a clip."""
    n = len(t)
    root_pos = np.column_stack((root_xy, np.zeros(n)))
    ankles, foot_rot, contacts = [], [], []
    for side in (LEFT, RIGHT):
        heel, toe = _foot_geometry(skel, side)
        a, r, c = _foot_track(t, plants[side], heel, toe)
        ankles.append(a)
        foot_rot.append(r)
        contacts.append(c)
    pelvis_rot = quat.mul(
        quat.from_yaw(twist),
        quat.mul(
            quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), roll),
            quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), pitch),
        ),
    )
    thigh = skel.thigh_length
    shin = skel.shin_length

    def hips(pz: FloatArray) -> list[FloatArray]:
        pelvis_local = np.column_stack((np.zeros(n), pelvis_y, pz))
        out = []
        for side in (LEFT, RIGHT):
            hip_local = pelvis_local + quat.rotate(
                pelvis_rot, np.broadcast_to(skel.offsets[skel.leg(side).hip], (n, 3))
            )
            out.append(root_pos + quat.rot2(root_yaw, hip_local))
        return out

    # Lower the pelvis wherever a leg would have to stretch beyond 99 % of its length.
    pz = pelvis_z.copy()
    for _ in range(2):
        hp = hips(pz)
        dz_max = np.full(n, np.inf)
        for side in (LEFT, RIGHT):
            reach = 0.99 * (thigh[side] + shin[side])
            d = ankles[side] - hp[side]
            dh2 = np.sum(d[:, :2] ** 2, axis=1)
            dz_max = np.minimum(
                dz_max, (ankles[side][:, 2] + np.sqrt(np.maximum(reach**2 - dh2, 0.0))) - hp[side][:, 2]
            )
        drop = np.minimum(dz_max - 0.002, 0.0)
        pz = pz + _min_filter_then_mean(drop, max(1, int(0.2 / dt) | 1), periodic)
    hp = hips(pz)

    pelvis_pos = np.column_stack((np.zeros(n), pelvis_y, pz))
    joint_rot = quat.identity((n, skel.n_joints))
    joint_rot[:, 0] = pelvis_rot
    yaw_q = quat.from_yaw(root_yaw)
    inv_yaw = quat.conj(yaw_q)
    down = np.array([0.0, 0.0, -1.0])
    lateral = np.array([0.0, 1.0, 0.0])
    for side in (LEFT, RIGHT):
        leg = skel.leg(side)
        hip = hp[side]
        ankle = ankles[side]
        d = ankle - hip
        dist = np.linalg.norm(d, axis=1)
        l1, l2 = thigh[side], shin[side]
        if np.any(dist > (l1 + l2) * (1 + 1e-6)):
            raise AssertionError(f"{name}: a leg cannot reach its foot")
        e = d / dist[:, None]
        cos_b = np.clip((l1**2 + dist**2 - l2**2) / (2 * l1 * dist), -1.0, 1.0)
        fwd = quat.rotate(foot_rot[side], np.broadcast_to(np.array([1.0, 0.0, 0.0]), (n, 3)))
        pole = fwd - np.sum(fwd * e, axis=1, keepdims=True) * e
        pole /= np.linalg.norm(pole, axis=1, keepdims=True)
        knee = hip + l1 * (cos_b[:, None] * e + np.sqrt(1 - cos_b**2)[:, None] * pole)
        hinge = np.cross(knee - hip, ankle - knee)
        fallback = quat.rotate(foot_rot[side], np.broadcast_to(lateral, (n, 3)))
        bad = np.linalg.norm(hinge, axis=1) < 1e-6
        hinge[bad] = fallback[bad]
        thigh_w = quat.from_two_frames(
            np.broadcast_to(down, (n, 3)), np.broadcast_to(lateral, (n, 3)), knee - hip, hinge
        )
        shin_w = quat.from_two_frames(
            np.broadcast_to(down, (n, 3)), np.broadcast_to(lateral, (n, 3)), ankle - knee, hinge
        )
        # Into the character frame, then local to each parent.
        thigh_c = quat.mul(inv_yaw, thigh_w)
        shin_c = quat.mul(inv_yaw, shin_w)
        foot_c = quat.mul(inv_yaw, foot_rot[side])
        joint_rot[:, leg.hip] = quat.mul(quat.conj(pelvis_rot), thigh_c)
        joint_rot[:, leg.knee] = quat.mul(quat.conj(thigh_c), shin_c)
        joint_rot[:, leg.ankle] = quat.mul(quat.conj(shin_c), foot_c)

    # Spine counter-twist, head stays level; arms swing against the legs.
    y_axis = np.array([0.0, 1.0, 0.0])
    chain = spine_chain(skel)
    for i, j in enumerate(chain[:-1]):
        joint_rot[:, j] = quat.from_yaw(-(0.6 if i == 0 else 0.5 / max(len(chain) - 2, 1)) * twist)
    if chain:
        joint_rot[:, chain[-1]] = quat.mul(
            quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), -0.6 * roll), quat.from_axis_angle(y_axis, -pitch)
        )
    for sign, (upper, lower) in zip((1.0, -1.0), hanging_arms(skel), strict=True):
        if upper < 0:
            continue
        forward = sign * np.sin(arm_phase)  # +1 with this arm at the front of its swing
        joint_rot[:, upper] = quat.from_axis_angle(y_axis, -arm_swing * forward)
        if lower >= 0:
            bend = elbow + elbow_swing * 0.5 * (1.0 + forward) - rest_elbow_bend(skel, lower)
            joint_rot[:, lower] = quat.from_axis_angle(y_axis, -np.broadcast_to(bend, (n,)))
    contact = np.column_stack(contacts).astype(bool)
    return Clip(name, role, dt, root_pos, root_yaw, pelvis_pos, quat.hemisphere(joint_rot), contact)


def _arc(s: FloatArray, curvature: float) -> tuple[FloatArray, FloatArray]:
    """Points ``(n, 2)`` and headings of the arc of given curvature at arc lengths ``s``."""
    if abs(curvature) < 1e-9:
        return np.column_stack((s, np.zeros_like(s))), np.zeros_like(s)
    r = 1.0 / curvature
    a = s * curvature
    return np.column_stack((r * np.sin(a), r * (1.0 - np.cos(a)))), a


def _plant(g: Gait, td: float, lo: float, pos: FloatArray, yaw: float, height: float | None = None) -> _Plant:
    return _Plant(
        td,
        lo,
        np.asarray(pos, dtype=float),
        float(yaw),
        g.heel_pitch,
        g.toe_pitch,
        g.heel_phase,
        g.toe_phase,
        g.step_height if height is None else height,
    )


def _gait_plants(
    g: Gait, curvature: float, cycles: range, t_shift: float = 0.0
) -> tuple[list[_Plant], list[_Plant]]:
    """Footprints of a steady gait along an arc: right stance at [0, duty], left half a stride later."""
    out: tuple[list[_Plant], list[_Plant]] = ([], [])
    T = g.cycle
    for k in cycles:
        for side, start in ((RIGHT, 0.0), (LEFT, 0.5)):
            td = (k + start) * T + t_shift
            lo = td + g.duty * T
            s_mid = g.speed * 0.5 * (td + lo)
            p, yaw = _arc(np.array([s_mid]), curvature)
            lat = (0.5 if side == LEFT else -0.5) * g.step_width
            pos = np.array([p[0, 0] - lat * np.sin(yaw[0]), p[0, 1] + lat * np.cos(yaw[0]), 0.0])
            out[side].append(_plant(g, td, lo, pos, float(yaw[0])))
    return out


def gait_clip(
    skel: Skeleton, gait: Gait, curvature: float, role: ClipRole, name: str | None = None, fps: float = 60.0
) -> Clip:
    """One stride of a steady walk or run along an arc of the given curvature (1/m, + left)."""
    T = gait.cycle
    n = max(3, round(T * fps) + 1)
    t = np.linspace(0.0, T, n)
    xy, yaw = _arc(gait.speed * t, curvature)
    plants = _gait_plants(gait, curvature, range(-1, 3))
    phase = 2 * np.pi * t / T
    # Highest (walk) or lowest (run) at each mid-stance: twice per stride.
    mid = 0.5 * gait.duty
    pelvis_z = np.full(n, gait.pelvis_height) + gait.bob * np.cos(2 * phase - 4 * np.pi * mid)
    sway = gait.sway * np.cos(phase - 2 * np.pi * (mid + 0.25))
    lean = np.arctan(gait.speed**2 * curvature / GRAVITY)
    roll = np.full(n, lean) - 0.5 * sway
    twist = gait.twist * np.cos(phase)
    pitch = np.full(n, gait.forward_lean)
    return _assemble(
        skel,
        name or role.value.lower(),
        role,
        1.0 / fps,
        t,
        xy,
        yaw,
        pelvis_z,
        sway,
        roll,
        twist,
        pitch,
        plants,
        phase,
        gait.arm_swing,
        periodic=True,
        elbow=gait.elbow,
        elbow_swing=gait.elbow_swing,
    )


def jump_clip(
    skel: Skeleton,
    run: Gait = RUN,
    length: float | None = None,
    fps: float = 60.0,
    role: ClipRole = ClipRole.JUMP,
) -> Clip:
    """A running jump: right stance, left take-off stance, a long flight, right landing.

    ``length`` is the distance between the take-off (left) and landing (right) footprints
    (default 2.6 m for the reference body, scaled with the skeleton). Starts and ends at a
    right touchdown at running speed, like a run stride.
    """
    k = body_scale(skel)
    length = 2.6 * k if length is None else length
    T_run = run.cycle
    stance = run.duty * T_run
    v = run.speed
    t_left = 0.5 * T_run
    t_takeoff = t_left + stance
    left_mid = 0.5 * (t_left + t_takeoff)
    # Landing right footprint: ``length`` ahead of the take-off footprint.
    t_land_mid = left_mid + length / v
    T = t_land_mid - 0.5 * stance
    n = max(3, round(T * fps) + 1)
    t = np.linspace(0.0, T, n)
    xy = np.column_stack((v * t, np.zeros(n)))
    yaw = np.zeros(n)
    w = 0.5 * run.step_width
    r0 = _plant(run, 0.0, stance, np.array([v * 0.5 * stance, -w, 0.0]), 0.0)
    r_prev = _plant(run, -T_run, -T_run + stance, np.array([v * (0.5 * stance - T_run), -w, 0.0]), 0.0)
    r_land = _plant(run, T, T + stance, np.array([v * t_land_mid, -w, 0.0]), 0.0)
    r0 = replace(r0, swing_height=0.3 * k, swing_ease=0.0)
    l_prev = _plant(
        run, t_left - T_run, t_left - T_run + stance, np.array([v * (left_mid - T_run), w, 0.0]), 0.0
    )
    l_take = _plant(run, t_left, t_takeoff, np.array([v * left_mid, w, 0.0]), 0.0, height=0.3 * k)
    l_take = replace(l_take, swing_ease=0.0)
    l_next = _plant(
        run,
        T + 0.5 * T_run,
        T + 0.5 * T_run + stance,
        np.array([v * (T + 0.5 * T_run + 0.5 * stance), w, 0.0]),
        0.0,
    )
    plants = ([l_prev, l_take, l_next], [r_prev, r0, r_land])
    # Ballistic pelvis between take-off and landing, crouching into both.
    flight = t_land_mid - 0.5 * stance - t_takeoff
    vz = 0.5 * GRAVITY * flight
    z = np.full(n, run.pelvis_height)
    air = (t > t_takeoff) & (t < T)
    ta = t[air] - t_takeoff
    z[air] += vz * ta - 0.5 * GRAVITY * ta**2
    crouch = k * (
        0.05 * np.exp(-(((t - t_takeoff + 0.1) / 0.08) ** 2)) + 0.04 * np.exp(-(((t - T) / 0.08) ** 2))
    )
    z -= crouch
    phase = 2 * np.pi * np.minimum(t, t_takeoff) / T_run
    pitch = np.full(n, run.forward_lean) + 0.15 * np.exp(-(((t - t_takeoff) / 0.15) ** 2))
    zeros = np.zeros(n)
    return _assemble(
        skel,
        "jump",
        role,
        1.0 / fps,
        t,
        xy,
        yaw,
        z,
        zeros,
        zeros,
        run.twist * np.cos(phase),
        pitch,
        plants,
        phase,
        run.arm_swing,
        periodic=False,
        elbow=run.elbow,
        elbow_swing=run.elbow_swing,
    )


def start_clip(skel: Skeleton, walk: Gait = WALK, fps: float = 60.0) -> Clip:
    """From standing (feet side by side) to a right touchdown at walking speed."""
    T = 1.1
    w = 0.5 * walk.step_width
    step = walk.speed * walk.cycle * 0.5
    lead = walk.speed * 0.5 * walk.duty * walk.cycle  # root is this far behind a fresh right footprint
    x_l0 = 0.55 * step
    x_r1 = x_l0 + step
    n = round(T * fps) + 1
    t = np.linspace(0.0, T, n)
    s = t / T
    x_end = x_r1 - lead
    x = (3 * s**2 - 2 * s**3) * x_end + (s**3 - s**2) * walk.speed * T
    xy = np.column_stack((x, np.zeros(n)))
    yaw = np.zeros(n)
    k = body_scale(skel)
    stand = standing_height(skel)
    l_stand = _plant(walk, -1.0, 0.12, np.array([0.0, w, 0.0]), 0.0, height=0.05 * k)
    l_stand = replace(l_stand, toe_pitch=0.2, toe_phase=0.1)
    l0 = _plant(walk, 0.55, 0.55 + walk.duty * walk.cycle, np.array([x_l0, w, 0.0]), 0.0)
    r_stand = _plant(walk, -1.0, 0.62, np.array([0.0, -w, 0.0]), 0.0)
    r_stand = replace(r_stand, toe_phase=0.18)
    r1 = _plant(walk, T, T + walk.duty * walk.cycle, np.array([x_r1, -w, 0.0]), 0.0)
    ramp = s * s * (3 - 2 * s)
    pelvis_z = stand + (walk.pelvis_height - stand) * ramp
    phase = 2 * np.pi * (t - T) / walk.cycle
    sway = walk.sway * np.sin(np.pi * s) * 0.8
    clip = _assemble(
        skel,
        "start",
        ClipRole.START,
        1.0 / fps,
        t,
        xy,
        yaw,
        pelvis_z,
        sway,
        -0.5 * sway,
        walk.twist * np.cos(phase) * ramp,
        walk.forward_lean * ramp,
        ([l_stand, l0], [r_stand, r1]),
        phase,
        walk.arm_swing * ramp,
        periodic=False,
        elbow=walk.elbow,
        elbow_swing=walk.elbow_swing * ramp,
    )
    contacts = clip.contacts.copy() if clip.contacts is not None else None
    assert contacts is not None
    contacts[0] = True  # both feet planted while standing
    return replace(clip, contacts=contacts)


def stop_clip(skel: Skeleton, walk: Gait = WALK, fps: float = 60.0) -> Clip:
    """From a right touchdown at walking speed to standing with the feet side by side."""
    T = 0.95
    w = 0.5 * walk.step_width
    step = walk.speed * walk.cycle * 0.5
    lead = walk.speed * 0.5 * walk.duty * walk.cycle
    n = round(T * fps) + 1
    t = np.linspace(0.0, T, n)
    s = t / T
    x = (s**3 - 2 * s**2 + s) * walk.speed * T + (3 * s**2 - 2 * s**3) * lead
    xy = np.column_stack((x, np.zeros(n)))
    yaw = np.zeros(n)
    l_lift = (0.5 + walk.duty - 1.0) * walk.cycle
    l_prev = _plant(walk, l_lift - walk.duty * walk.cycle, l_lift, np.array([lead - step, w, 0.0]), 0.0)
    k = body_scale(skel)
    stand = standing_height(skel)
    l_end = _plant(walk, 0.58, T + 1.0, np.array([lead, w, 0.0]), 0.0, height=0.05 * k)
    l_end = replace(l_end, toe_phase=1e-3, toe_pitch=0.0, heel_pitch=0.1)
    r0 = _plant(walk, 0.0, T + 1.0, np.array([lead, -w, 0.0]), 0.0)
    r0 = replace(
        r0,
        toe_phase=1e-3,
        toe_pitch=0.0,
        heel_phase=walk.heel_phase * walk.duty * walk.cycle / (r0.lo - r0.td),
    )
    ramp = 1.0 - s * s * (3 - 2 * s)
    pelvis_z = stand + (walk.pelvis_height - stand) * ramp
    phase = 2 * np.pi * t / walk.cycle
    sway = walk.sway * np.sin(np.pi * s) * 0.8
    return _assemble(
        skel,
        "stop",
        ClipRole.STOP,
        1.0 / fps,
        t,
        xy,
        yaw,
        pelvis_z,
        sway,
        -0.5 * sway,
        walk.twist * np.cos(phase) * ramp,
        walk.forward_lean * ramp,
        ([l_prev, l_end], [r0]),
        phase,
        walk.arm_swing * ramp,
        periodic=False,
        elbow=walk.elbow,
        elbow_swing=walk.elbow_swing * ramp,
    )


def idle_clip(skel: Skeleton, walk: Gait = WALK, duration: float = 2.0, fps: float = 60.0) -> Clip:
    """Standing with both feet planted, breathing: a slow pelvis sway."""
    n = round(duration * fps) + 1
    t = np.linspace(0.0, duration, n)
    w = 0.5 * walk.step_width
    xy = np.zeros((n, 2))
    yaw = np.zeros(n)
    feet = (
        [_plant(walk, -1.0, duration + 1.0, np.array([0.0, w, 0.0]), 0.0)],
        [_plant(walk, -1.0, duration + 1.0, np.array([0.0, -w, 0.0]), 0.0)],
    )
    feet = (
        [replace(feet[0][0], toe_phase=1e-3, toe_pitch=0.0)],
        [replace(feet[1][0], toe_phase=1e-3, toe_pitch=0.0)],
    )
    phase = 2 * np.pi * t / duration
    k = body_scale(skel)
    sway = 0.012 * k * np.sin(phase)
    zeros = np.zeros(n)
    return _assemble(
        skel,
        "idle",
        ClipRole.IDLE,
        1.0 / fps,
        t,
        xy,
        yaw,
        np.full(n, standing_height(skel) - 0.005 * k) + 0.004 * k * np.cos(2 * phase),
        sway,
        -0.3 * sway,
        zeros,
        zeros + 0.01,
        feet,
        zeros,
        0.0,
        periodic=True,
        elbow=walk.elbow,
    )


WALK_RADII = {
    ClipRole.WALK_LEFT: 1.6,
    ClipRole.WALK_LEFT_WIDE: 4.0,
    ClipRole.WALK_FORWARD: np.inf,
    ClipRole.WALK_RIGHT_WIDE: -4.0,
    ClipRole.WALK_RIGHT: -1.6,
}
RUN_RADII = {ClipRole.RUN_LEFT: 4.0, ClipRole.RUN_FORWARD: np.inf, ClipRole.RUN_RIGHT: -4.0}


def standard_library(
    skel: Skeleton,
    fps: float = 60.0,
    run: bool = True,
    jump: bool = True,
    walk_gait: Gait | None = None,
    run_gait: Gait | None = None,
    step_width: float | None = None,
) -> list[Clip]:
    """Every role: start, stop, idle, five walks (radii ±1.6 m, ±4 m, straight), three runs
    (±4 m, straight) and a running jump.

    Gaits default to :data:`WALK` and :data:`RUN` fitted to ``skel`` (:func:`fit_gait`),
    turning radii scale with it too; ``step_width`` sets how far apart the feet walk.
    """
    k = body_scale(skel)
    walk_gait = walk_gait or fit_gait(WALK, skel, step_width)
    run_gait = run_gait or fit_gait(RUN, skel, None if step_width is None else 0.7 * step_width)
    clips = [
        start_clip(skel, walk_gait, fps),
        stop_clip(skel, walk_gait, fps),
        idle_clip(skel, walk_gait, fps=fps),
    ]
    for role, radius in WALK_RADII.items():
        clips.append(gait_clip(skel, walk_gait, 1.0 / (k * radius), role, fps=fps))
    if run:
        for role, radius in RUN_RADII.items():
            clips.append(gait_clip(skel, run_gait, 1.0 / (k * radius), role, fps=fps))
    if jump:
        clips.append(jump_clip(skel, run_gait, fps=fps))
    return clips
