# SPDX-License-Identifier: GPL-3.0-or-later
"""Rigs named and built the way users bring them, made by script (no third-party asset).

Each builder returns an armature object standing on ``z = 0`` with a capsule skin (one vertex
group per bone), so Blender's glTF and FBX exporters write it like a game asset. Geometry is
given in creature space: facing -Y, left at +X, Z up, metres. :data:`FIXTURES` lists them by
name with the legs detection must find (:class:`Expected`) or the refusal it must give.

- Humanoids named by Mixamo (T pose and A pose), the Unreal mannequin (facing +Y), Character
  Creator and 3ds Max Biped: arms that do not reach the ground, twist and IK helper bones.
- ``gltf_quadruped``: numbered game names (``b_LeftLeg01_015``), every bone pointing along
  its own +Y with a fixed length (what importers make of a file), the object turned 90°
  about X as a Y-up file arrives.
- ``spider8``: game names ``Leg1Base.L`` ... ``Leg4Fore.R``, jaws, pedipalps and antennae.
- ``root_legs``: four legs ``FrontLeftLeg > FrontLeftShin > FrontLeftToe`` hanging from the
  root bone beside the body, not from the body.
- ``horse``: front legs scapula > humerus > radius > cannon > pastern > hoof.
- ``swapped``: the horse with its L/R names on the wrong sides.
- ``rigify_horse``, ``rigify_bird`` (9 cm legs), ``rigify_basic_human``: Blender's own
  metarigs, which earlier detection got wrong (hoof-only front legs, legs ending at the knee).
- ``generated_wolf``, ``generated_horse``, ``generated_cat``, ``generated_quadruped``,
  ``generated_human``, ``generated_bird``: the control rigs Rigify generates from its metarigs
  (``rigify_generate``): legs of ``ORG-`` bones copying FK and IK chains (the quadrupeds'
  three-bone paws), deform ``DEF-`` bones in B-Bone segments, no skin.
- ``shark``: Rigify's shark metarig (fins only); ``on_side`` / ``upside_down``: the horse
  turned 90° and 180° about its forward axis.
- ``horse_in_holder``: the horse parented to a moved, turned, half-scaled empty;
  ``horse_numbered``: the horse with no names (``Bone``, ``Bone.001``, ...); ``mirrored``:
  the horse mirrored as an object (refused: apply the scale); ``copy_rotation_controls``:
  the horse whose deform leg bones copy the rotation of a control chain beside them.
- ``beetle_gltf``: a sprawling six-legged game beetle, bones ``joint_0`` ... ``joint_19``,
  tails as importers leave them (its legs 10 cm apart along the body).
- ``arp_rig``, ``arp_export``, ``arp_dog``: Auto-Rig Pro's names and wiring (see its
  section): a biped's control rig (controls, FK/IK mechanism, deform bones copying them, no
  skin on controls), its game-engine export (the deform skeleton alone), and a dog's deform
  skeleton with three-bone legs; thighs and shins each split in a twist and a stretch bone.
- Game creatures whose other limbs are the classic traps (their section): a ``scorpion``
  (pincer arms named ``ClawArm1.L`` ... ``Claw.L``, held just above the floor; a tail curled
  over the back), a ``raptor`` (long feet and toes, small arms, a level tail, a long neck),
  a ``centaur`` (a human torso with hanging arms on a horse), a ``mantis`` (raised raptorial
  forelegs), a ``crab`` (legs splayed sideways, claws near the floor), a ``centipede`` (22
  legs on a chain of segments), a ``kangaroo`` (forelegs hanging above the floor, a tail on
  it) and a legless ``snake`` (refused); the scorpion, centaur and kangaroo also unnamed
  and round-tripped.
"""

from __future__ import annotations

import math
import re
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import bpy
import numpy as np
from mathutils import Matrix, Vector

from tools.examples import creatures

Vec = tuple[float, float, float]
#: (name, parent, head, tail) in creature space.
Spec = tuple[str, str | None, Vec, Vec]


@dataclass(frozen=True)
class Expected:
    """What Detect Legs must find: ``label -> (hip, end-effector)``; or a refusal."""

    legs: dict[str, tuple[str, str]] = field(default_factory=dict)
    refusal: str = ""


def _chain(names: Sequence[str], parent: str | None, points: Sequence[Vec]) -> list[Spec]:
    return [(n, parent if i == 0 else names[i - 1], points[i], points[i + 1]) for i, n in enumerate(names)]


def _mirror(specs: Sequence[Spec], rename: Callable[[str], str]) -> list[Spec]:
    def flip(p: Vec) -> Vec:
        return (-p[0], p[1], p[2])

    return [(rename(n), rename(p) if p else None, flip(h), flip(t)) for n, p, h, t in specs]


def _swap(a: str, b: str) -> Callable[[str], str]:
    return lambda name: name.replace(a, b)


# ---------------------------------------------------------------------------------------
# Humanoids


def _humanoid(
    names: dict[str, str],
    rename: Callable[[str], str],
    pose: str = "T",
    root: str | None = None,
    extras: Sequence[Spec] = (),
) -> list[Spec]:
    """A 1.75 m humanoid. ``names`` maps roles to the left side's bone names; ``rename`` makes
    the right side's from them. ``pose``: ``"T"`` (arms level) or ``"A"`` (45° down)."""
    n = names
    hips_parent = root
    bones: list[Spec] = []
    if root is not None:
        bones.append((root, None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.2)))
    bones += _chain(
        [n["hips"], n["spine"], n["chest"], n["neck"], n["head"]],
        hips_parent,
        [
            (0.0, 0.0, 1.0),
            (0.0, 0.0, 1.1),
            (0.0, 0.0, 1.3),
            (0.0, 0.0, 1.5),
            (0.0, 0.0, 1.58),
            (0.0, 0.0, 1.75),
        ],
    )
    # The legs hang from the hips bone, the arms from the chest.
    left = _chain(
        [n["thigh"], n["shin"], n["foot"], n["toe"]],
        n["hips"],
        [(0.1, 0.0, 0.95), (0.1, -0.02, 0.5), (0.1, 0.03, 0.08), (0.1, -0.1, 0.0), (0.1, -0.17, 0.0)],
    )
    c, s = (1.0, 0.0) if pose == "T" else (math.cos(math.radians(45)), math.sin(math.radians(45)))
    sh = (0.17, 0.0, 1.45)

    def along(d: float) -> Vec:
        return (sh[0] + c * d, 0.0, sh[2] - s * d)

    left += _chain([n["shoulder"]], n["chest"], [(0.03, 0.0, 1.45), sh])
    left += _chain(
        [n["upper_arm"], n["forearm"], n["hand"], n["finger"]],
        n["shoulder"],
        [sh, along(0.28), along(0.54), along(0.62), along(0.7)],
    )
    for role, parent in (("thigh_twist", "thigh"), ("calf_twist", "shin")):
        if role in n:
            i = [b[0] for b in left].index(n[parent])
            h, t = np.array(left[i][2]), np.array(left[i][3])
            left.append((n[role], n[parent], tuple(h + 0.3 * (t - h)), tuple(h + 0.5 * (t - h))))
    left += list(extras)
    return bones + left + _mirror(left, rename)


MIXAMO = {
    "hips": "mixamorig:Hips",
    "spine": "mixamorig:Spine",
    "chest": "mixamorig:Spine2",
    "neck": "mixamorig:Neck",
    "head": "mixamorig:Head",
    "thigh": "mixamorig:LeftUpLeg",
    "shin": "mixamorig:LeftLeg",
    "foot": "mixamorig:LeftFoot",
    "toe": "mixamorig:LeftToeBase",
    "shoulder": "mixamorig:LeftShoulder",
    "upper_arm": "mixamorig:LeftArm",
    "forearm": "mixamorig:LeftForeArm",
    "hand": "mixamorig:LeftHand",
    "finger": "mixamorig:LeftHandIndex1",
}
UNREAL = {
    "hips": "pelvis",
    "spine": "spine_01",
    "chest": "spine_03",
    "neck": "neck_01",
    "head": "head",
    "thigh": "thigh_l",
    "shin": "calf_l",
    "foot": "foot_l",
    "toe": "ball_l",
    "shoulder": "clavicle_l",
    "upper_arm": "upperarm_l",
    "forearm": "lowerarm_l",
    "hand": "hand_l",
    "finger": "index_01_l",
    "thigh_twist": "thigh_twist_01_l",
    "calf_twist": "calf_twist_01_l",
}
CC = {
    "hips": "CC_Base_Hip",
    "spine": "CC_Base_Waist",
    "chest": "CC_Base_Spine02",
    "neck": "CC_Base_NeckTwist01",
    "head": "CC_Base_Head",
    "thigh": "CC_Base_L_Thigh",
    "shin": "CC_Base_L_Calf",
    "foot": "CC_Base_L_Foot",
    "toe": "CC_Base_L_ToeBase",
    "shoulder": "CC_Base_L_Clavicle",
    "upper_arm": "CC_Base_L_Upperarm",
    "forearm": "CC_Base_L_Forearm",
    "hand": "CC_Base_L_Hand",
    "finger": "CC_Base_L_Index1",
    "calf_twist": "CC_Base_L_CalfTwist01",
}
BIPED = {
    "hips": "Bip01 Pelvis",
    "spine": "Bip01 Spine",
    "chest": "Bip01 Spine1",
    "neck": "Bip01 Neck",
    "head": "Bip01 Head",
    "thigh": "Bip01 L Thigh",
    "shin": "Bip01 L Calf",
    "foot": "Bip01 L Foot",
    "toe": "Bip01 L Toe0",
    "shoulder": "Bip01 L Clavicle",
    "upper_arm": "Bip01 L UpperArm",
    "forearm": "Bip01 L Forearm",
    "hand": "Bip01 L Hand",
    "finger": "Bip01 L Finger0",
}


def _unreal_bones() -> list[Spec]:
    ik = [
        ("ik_foot_root", "root", (0.0, 0.0, 0.0), (0.0, 0.0, 0.1)),
        ("ik_foot_l", "ik_foot_root", (0.1, 0.03, 0.08), (0.1, 0.13, 0.08)),
        ("ik_foot_r", "ik_foot_root", (-0.1, 0.03, 0.08), (-0.1, 0.13, 0.08)),
    ]
    bones = _humanoid(UNREAL, _swap("_l", "_r"), pose="A", root="root") + ik
    # The mannequin faces +Y: turned half a turn about Z.
    return [(n, p, (-h[0], -h[1], h[2]), (-t[0], -t[1], t[2])) for n, p, h, t in bones]


# ---------------------------------------------------------------------------------------
# Creatures


def _quadruped(
    front: Sequence[str],
    hind: Sequence[str],
    body: dict[str, str],
    rename: Callable[[str], str],
    front_points: Sequence[Vec],
    hind_points: Sequence[Vec],
    front_parent: str,
    hind_parent: str,
    size: float = 1.0,
) -> list[Spec]:
    b = body
    spine = _chain(
        [b["hips"], b["spine"], b["chest"]],
        b.get("root"),
        [(0.0, 0.4, 1.4), (0.0, 0.1, 1.42), (0.0, -0.2, 1.45), (0.0, -0.45, 1.5)],
    )
    spine += _chain(
        [b["neck"], b["head"]], b["chest"], [(0.0, -0.45, 1.5), (0.0, -0.75, 1.75), (0.0, -1.05, 1.6)]
    )
    spine += _chain(
        [b["tail"], b["tail"] + "_end"], b["hips"], [(0.0, 0.4, 1.4), (0.0, 0.7, 1.2), (0.0, 0.9, 0.9)]
    )
    left = _chain(list(front), front_parent, list(front_points)) + _chain(
        list(hind), hind_parent, list(hind_points)
    )
    bones = spine + left + _mirror(left, rename)
    return [(n, p, tuple(size * x for x in h), tuple(size * x for x in t)) for n, p, h, t in bones]  # type: ignore[misc]


HORSE_FRONT = [
    (0.15, -0.35, 1.5),
    (0.17, -0.55, 1.15),
    (0.17, -0.45, 0.9),
    (0.17, -0.47, 0.45),
    (0.17, -0.47, 0.15),
    (0.17, -0.53, 0.06),
    (0.17, -0.6, 0.0),
]
HORSE_HIND = [
    (0.17, 0.45, 1.35),
    (0.2, 0.25, 0.95),
    (0.2, 0.55, 0.6),
    (0.2, 0.55, 0.15),
    (0.2, 0.5, 0.06),
    (0.2, 0.44, 0.0),
]


def _horse_bones(swap_names: bool = False) -> list[Spec]:
    front = ["scapula.L", "humerus.L", "radius.L", "cannon.L", "pastern.L", "hoof.L"]
    hind = ["femur.L", "tibia.L", "metatarsus.L", "hind_pastern.L", "hind_hoof.L"]
    body = {
        "hips": "pelvis",
        "spine": "spine",
        "chest": "chest",
        "neck": "neck",
        "head": "head",
        "tail": "tail",
    }
    bones = _quadruped(front, hind, body, _swap(".L", ".R"), HORSE_FRONT, HORSE_HIND, "chest", "pelvis")
    if swap_names:

        def swapped(name: str) -> str:
            return name.replace(".L", ".X").replace(".R", ".L").replace(".X", ".R")

        bones = [(swapped(n), swapped(p) if p else None, h, t) for n, p, h, t in bones]
    return bones


def _gltf_quadruped_bones() -> list[Spec]:
    body = {
        "root": "b_Root_00",
        "hips": "b_Hips_01",
        "spine": "b_Spine01_02",
        "chest": "b_Spine02_03",
        "neck": "b_Neck_04",
        "head": "b_Head_05",
        "tail": "b_Tail01_019",
    }
    front = ["b_LeftUpperArm_09", "b_LeftForeArm_010", "b_LeftHand_011", "b_LeftFinger_012"]
    hind = ["b_LeftLeg01_015", "b_LeftLeg02_016", "b_LeftFoot01_017", "b_LeftFoot02_018"]
    # A bent front leg (elbow back, wrist forward): nearly straight columns make the IK jump (see README)
    fp = [
        (0.14, -0.3, 1.25),
        (0.15, -0.18, 0.78),
        (0.15, -0.26, 0.24),
        (0.15, -0.34, 0.06),
        (0.15, -0.42, 0.0),
    ]
    hp = [(0.15, 0.4, 1.25), (0.16, 0.2, 0.8), (0.16, 0.45, 0.35), (0.16, 0.4, 0.05), (0.16, 0.32, 0.0)]
    bones = _quadruped(
        front, hind, body, _swap("Left", "Right"), fp, hp, "b_Spine02_03", "b_Hips_01", size=0.5
    )
    root = ("b_Root_00", None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.1))
    return [root, *bones]


def _spider_bones() -> list[Spec]:
    s = 0.3  # body height (m)
    bones: list[Spec] = [
        ("Body", None, (0.0, 0.1 * s, s), (0.0, -0.2 * s, s)),
        ("Abdomen", "Body", (0.0, 0.15 * s, s), (0.0, 0.8 * s, 1.1 * s)),
        ("Head", "Body", (0.0, -0.2 * s, s), (0.0, -0.35 * s, 1.02 * s)),
    ]
    left: list[Spec] = []
    for n, azimuth in enumerate((40.0, 75.0, 110.0, 150.0), start=1):
        a = math.radians(azimuth)
        out = np.array([math.sin(a), -math.cos(a), 0.0])
        hip = np.array([0.0, -0.05 * s, s]) + 0.15 * s * out
        knee = hip + 0.25 * s * out + np.array([0.0, 0.0, 0.1 * s])
        top = knee + 0.6 * s * out + np.array([0.0, 0.0, 0.5 * s])
        foot = top + 0.7 * s * out
        foot[2] = 0.0
        left += _chain(
            [f"Leg{n}Base.L", f"Leg{n}Mid.L", f"Leg{n}Fore.L"],
            "Body",
            [tuple(hip), tuple(knee), tuple(top), tuple(foot)],
        )
    left += _chain(
        ["JawBase.L", "Pincer.L"],
        "Head",
        [(0.03 * s, -0.3 * s, 0.95 * s), (0.05 * s, -0.45 * s, 0.7 * s), (0.04 * s, -0.5 * s, 0.5 * s)],
    )
    left += _chain(
        ["Pedipalp1.L", "Pedipalp2.L"],
        "Body",
        [(0.08 * s, -0.2 * s, 0.95 * s), (0.15 * s, -0.5 * s, 0.8 * s), (0.18 * s, -0.7 * s, 0.45 * s)],
    )
    left += _chain(
        ["Antenna1.L", "Antenna2.L"],
        "Head",
        [(0.03 * s, -0.35 * s, 1.05 * s), (0.1 * s, -0.7 * s, 1.4 * s), (0.15 * s, -1.1 * s, 1.6 * s)],
    )
    return bones + left + _mirror(left, _swap(".L", ".R"))


def _root_legs_bones() -> list[Spec]:
    bones: list[Spec] = [
        ("root", None, (0.0, 0.0, 0.0), (0.0, 0.2, 0.0)),
        ("Body", "root", (0.0, 0.35, 0.5), (0.0, -0.35, 0.5)),
        ("Head", "Body", (0.0, -0.35, 0.5), (0.0, -0.55, 0.6)),
    ]
    left: list[Spec] = []
    for row, y in (("Front", -0.25), ("Back", 0.25)):
        left += _chain(
            [f"{row}LeftLeg", f"{row}LeftShin", f"{row}LeftToe"],
            "root",
            [(0.15, y, 0.48), (0.17, y - 0.02, 0.25), (0.17, y + 0.01, 0.04), (0.17, y - 0.07, 0.0)],
        )
    return bones + left + _mirror(left, _swap("Left", "Right"))


# ---------------------------------------------------------------------------------------
# Rigs as their tools make them (hierarchies as published for each tool)


def _lerp(a: Vec, b: Vec, t: float) -> Vec:
    return (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2]))


def _plus(a: Vec, d: Vec) -> Vec:
    return (a[0] + d[0], a[1] + d[1], a[2] + d[2])


#: A 1.75 m humanoid's left leg: hip, knee, ankle, ball, toe tip (creature space).
_HIP, _KNEE, _ANKLE, _BALL, _TIP = (
    (0.1, 0.0, 0.95),
    (0.1, -0.02, 0.52),
    (0.1, 0.03, 0.08),
    (0.1, -0.1, 0.015),
    (0.1, -0.17, 0.01),
)
_SHOULDER = (0.17, 0.0, 1.45)


def _arm(names: Sequence[str], parent: str, clavicle: str, clavicle_parent: str) -> list[Spec]:
    """A left arm in A pose (45° down): a clavicle, then ``names`` from the shoulder to the hand."""
    c = math.cos(math.radians(45))

    def along(d: float) -> Vec:
        return (_SHOULDER[0] + c * d, 0.0, _SHOULDER[2] - c * d)

    pts = [_SHOULDER, *(along(0.62 * (k + 1) / len(names)) for k in range(len(names)))]
    return [(clavicle, clavicle_parent, (0.03, 0.0, 1.45), _SHOULDER), *_chain(names, clavicle, pts)]


def _spine(names: Sequence[str], parent: str | None, bottom: float = 1.0, top: float = 1.5) -> list[Spec]:
    zs = np.linspace(bottom, top, len(names) + 1)
    return _chain(names, parent, [(0.0, 0.0, float(z)) for z in zs])


def _mixamo_full_bones() -> list[Spec]:
    """Mixamo as it downloads: end bones (``LeftToe_End``, ``HeadTop_End``), eyes, four bones
    per finger."""
    p = "mixamorig:"
    body = _spine([f"{p}Hips", f"{p}Spine", f"{p}Spine1", f"{p}Spine2"], None)
    body += _spine([f"{p}Neck", f"{p}Head"], f"{p}Spine2", 1.5, 1.75)
    body += [
        (f"{p}HeadTop_End", f"{p}Head", (0.0, 0.0, 1.75), (0.0, 0.0, 1.85)),
        (f"{p}LeftEye", f"{p}Head", (0.03, -0.08, 1.65), (0.03, -0.1, 1.65)),
        (f"{p}RightEye", f"{p}Head", (-0.03, -0.08, 1.65), (-0.03, -0.1, 1.65)),
    ]
    left = _chain(
        [f"{p}LeftUpLeg", f"{p}LeftLeg", f"{p}LeftFoot", f"{p}LeftToeBase"],
        f"{p}Hips",
        [_HIP, _KNEE, _ANKLE, _BALL, _TIP],
    )
    left.append((f"{p}LeftToe_End", f"{p}LeftToeBase", _TIP, (0.1, -0.22, 0.01)))
    left += _arm(
        [f"{p}LeftArm", f"{p}LeftForeArm", f"{p}LeftHand"], f"{p}Spine2", f"{p}LeftShoulder", f"{p}Spine2"
    )
    hand = left[-1]
    for k, finger in enumerate(("Thumb", "Index", "Middle", "Ring", "Pinky")):
        start = _plus(hand[3], (0.0, 0.012 * (k - 2), 0.0))
        pts = [_plus(start, (0.018 * j, 0.0, -0.018 * j)) for j in range(5)]
        left += _chain([f"{p}LeftHand{finger}{j}" for j in range(1, 5)], f"{p}LeftHand", pts)
    return body + left + _mirror(left, _swap("Left", "Right"))


def _ue5_bones() -> list[Spec]:
    """The UE5 mannequin (Manny): twist and corrective bones on the legs, ``ik_foot_root`` >
    ``ik_foot_l`` and the hand IK bones under ``root``; it faces +Y."""
    body = [("root", None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.2))]
    body += _spine(["pelvis", "spine_01", "spine_02", "spine_03", "spine_04", "spine_05"], "root")
    body += _spine(["neck_01", "neck_02", "head"], "spine_05", 1.5, 1.75)
    left = _chain(["thigh_l", "calf_l", "foot_l", "ball_l"], "pelvis", [_HIP, _KNEE, _ANKLE, _BALL, _TIP])
    left += [
        ("thigh_twist_01_l", "thigh_l", _lerp(_HIP, _KNEE, 0.3), _lerp(_HIP, _KNEE, 0.5)),
        ("thigh_twist_02_l", "thigh_l", _lerp(_HIP, _KNEE, 0.6), _lerp(_HIP, _KNEE, 0.8)),
        ("thigh_twistCor_01_l", "thigh_twist_01_l", _lerp(_HIP, _KNEE, 0.3), _lerp(_HIP, _KNEE, 0.35)),
        ("thigh_correctiveRoot_l", "thigh_l", _HIP, _lerp(_HIP, _KNEE, 0.1)),
    ]
    for k, d in (
        ("bck", (0.0, 0.08, 0.0)),
        ("fwd", (0.0, -0.08, 0.0)),
        ("out", (0.07, 0.0, 0.0)),
        ("in", (-0.06, 0.0, 0.0)),
    ):
        h = _plus(_lerp(_HIP, _KNEE, 0.1), d)
        left.append((f"thigh_{k}_l", "thigh_correctiveRoot_l", h, _plus(h, (0.0, 0.0, -0.05))))
    left += [
        ("calf_twist_01_l", "calf_l", _lerp(_KNEE, _ANKLE, 0.3), _lerp(_KNEE, _ANKLE, 0.5)),
        ("calf_twist_02_l", "calf_l", _lerp(_KNEE, _ANKLE, 0.6), _lerp(_KNEE, _ANKLE, 0.8)),
        ("calf_correctiveRoot_l", "calf_l", _KNEE, _lerp(_KNEE, _ANKLE, 0.1)),
        (
            "calf_knee_l",
            "calf_correctiveRoot_l",
            _plus(_KNEE, (0.0, -0.06, 0.0)),
            _plus(_KNEE, (0.0, -0.06, -0.04)),
        ),
        (
            "calf_kneeBack_l",
            "calf_correctiveRoot_l",
            _plus(_KNEE, (0.0, 0.06, 0.0)),
            _plus(_KNEE, (0.0, 0.06, -0.04)),
        ),
        ("ankle_bck_l", "foot_l", _plus(_ANKLE, (0.0, 0.05, -0.01)), _plus(_ANKLE, (0.0, 0.07, -0.02))),
        ("ankle_fwd_l", "foot_l", _plus(_ANKLE, (0.0, -0.04, 0.0)), _plus(_ANKLE, (0.0, -0.06, -0.01))),
    ]
    left += _arm(["upperarm_l", "lowerarm_l", "hand_l"], "spine_05", "clavicle_l", "spine_05")
    ik = [
        ("ik_foot_root", "root", (0.0, 0.0, 0.0), (0.0, 0.1, 0.0)),
        ("ik_foot_l", "ik_foot_root", _ANKLE, _plus(_ANKLE, (0.0, 0.1, 0.0))),
        (
            "ik_foot_r",
            "ik_foot_root",
            (-_ANKLE[0], _ANKLE[1], _ANKLE[2]),
            (-_ANKLE[0], _ANKLE[1] + 0.1, _ANKLE[2]),
        ),
        ("ik_hand_root", "root", (0.0, 0.0, 0.0), (0.0, 0.1, 0.0)),
        ("ik_hand_gun", "ik_hand_root", (-0.45, -0.1, 1.0), (-0.45, 0.0, 1.0)),
        ("ik_hand_l", "ik_hand_gun", (0.45, -0.1, 1.0), (0.45, 0.0, 1.0)),
        ("ik_hand_r", "ik_hand_gun", (-0.45, -0.1, 1.0), (-0.45, 0.0, 1.0)),
        ("interaction", "root", (0.0, 0.0, 0.0), (0.0, 0.1, 0.0)),
        ("center_of_mass", "root", (0.0, 0.0, 0.0), (0.0, 0.1, 0.0)),
    ]
    bones = body + left + _mirror(left, lambda n: re.sub(r"_l$", "_r", n)) + ik
    return [(n, p, (-h[0], -h[1], h[2]), (-t[0], -t[1], t[2])) for n, p, h, t in bones]


def _cc4_bones() -> list[Spec]:
    """Character Creator 4: ``CC_Base_BoneRoot`` > ``CC_Base_Hip`` > (``CC_Base_Pelvis`` >
    thighs) and (``CC_Base_Waist`` > spine > arms, head): the legs and the upper body hang
    from two children of the hip bone."""
    p = "CC_Base_"
    body = [
        (f"{p}BoneRoot", None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.2)),
        (f"{p}Hip", f"{p}BoneRoot", (0.0, 0.0, 1.0), (0.0, 0.0, 1.1)),
        (f"{p}Pelvis", f"{p}Hip", (0.0, 0.0, 1.0), (0.0, 0.0, 0.9)),
    ]
    body += _spine([f"{p}Waist", f"{p}Spine01", f"{p}Spine02"], f"{p}Hip")
    body += _spine([f"{p}NeckTwist01", f"{p}NeckTwist02", f"{p}Head"], f"{p}Spine02", 1.5, 1.75)
    body += [
        (f"{p}FacialBone", f"{p}Head", (0.0, -0.02, 1.62), (0.0, -0.05, 1.62)),
        (f"{p}JawRoot", f"{p}FacialBone", (0.0, -0.02, 1.6), (0.0, -0.08, 1.56)),
    ]
    left = _chain(
        [f"{p}L_Thigh", f"{p}L_Calf", f"{p}L_Foot", f"{p}L_ToeBase"],
        f"{p}Pelvis",
        [_HIP, _KNEE, _ANKLE, _BALL, _TIP],
    )
    left += [
        (f"{p}L_ThighTwist01", f"{p}L_Thigh", _HIP, _lerp(_HIP, _KNEE, 0.5)),
        (f"{p}L_ThighTwist02", f"{p}L_Thigh", _lerp(_HIP, _KNEE, 0.5), _KNEE),
        (f"{p}L_CalfTwist01", f"{p}L_Calf", _KNEE, _lerp(_KNEE, _ANKLE, 0.5)),
        (f"{p}L_CalfTwist02", f"{p}L_Calf", _lerp(_KNEE, _ANKLE, 0.5), _ANKLE),
        (f"{p}L_KneeShareBone", f"{p}L_Calf", _KNEE, _plus(_KNEE, (0.0, -0.05, 0.0))),
    ]
    for k, toe in enumerate(("BigToe1", "IndexToe1", "MidToe1", "RingToe1", "PinkyToe1")):
        h = _plus(_BALL, (0.012 * (2 - k), 0.0, 0.0))
        left.append((f"{p}L_{toe}", f"{p}L_ToeBase", h, _plus(h, (0.0, -0.03, -0.003))))
    left += _arm(
        [f"{p}L_Upperarm", f"{p}L_Forearm", f"{p}L_Hand"], f"{p}Spine02", f"{p}L_Clavicle", f"{p}Spine02"
    )
    return body + left + _mirror(left, _swap("_L_", "_R_"))


def _max_biped_bones() -> list[Spec]:
    """3ds Max Biped as its FBX export has it: ``Bip01`` (the centre of mass) > ``Bip01 Pelvis``
    > ``Bip01 Spine`` > the thighs (not the pelvis), ``Bip01 Footsteps`` on the ground under
    ``Bip01``, ``Nub`` end bones, the clavicles under the neck."""
    body = [
        ("Bip01", None, (0.0, 0.0, 1.0), (0.0, -0.1, 1.0)),
        ("Bip01 Footsteps", "Bip01", (0.0, 0.0, 0.0), (0.0, -0.1, 0.0)),
    ]
    body += _spine(
        ["Bip01 Pelvis", "Bip01 Spine", "Bip01 Spine1", "Bip01 Spine2", "Bip01 Neck"], "Bip01", 1.0, 1.55
    )
    body += _spine(["Bip01 Head", "Bip01 HeadNub"], "Bip01 Neck", 1.55, 1.85)
    left = _chain(
        ["Bip01 L Thigh", "Bip01 L Calf", "Bip01 L Foot", "Bip01 L Toe0"],
        "Bip01 Spine",
        [_HIP, _KNEE, _ANKLE, _BALL, _TIP],
    )
    left.append(("Bip01 L Toe0Nub", "Bip01 L Toe0", _TIP, (0.1, -0.2, 0.01)))
    left += _arm(
        ["Bip01 L UpperArm", "Bip01 L Forearm", "Bip01 L Hand"],
        "Bip01 Neck",
        "Bip01 L Clavicle",
        "Bip01 Neck",
    )
    left += _chain(
        ["Bip01 L Finger0", "Bip01 L Finger0Nub"],
        "Bip01 L Hand",
        [left[-1][3], _plus(left[-1][3], (0.02, 0.0, -0.02)), _plus(left[-1][3], (0.04, 0.0, -0.04))],
    )
    return body + left + _mirror(left, _swap(" L ", " R "))


def _genesis8_bones() -> list[Spec]:
    """DAZ Genesis 8: ``hip`` > ``pelvis`` > ``lThighBend`` > ``lThighTwist`` > ``lShin`` >
    ``lFoot`` > ``lMetatarsals`` > ``lToe`` (the thigh in two bones, the shin hanging from
    the twist bone's end); ``hip`` > ``abdomenLower`` > ... the upper body."""
    body = [
        ("hip", None, (0.0, 0.0, 1.0), (0.0, 0.0, 1.05)),
        ("pelvis", "hip", (0.0, 0.0, 1.0), (0.0, 0.0, 0.9)),
    ]
    body += _spine(["abdomenLower", "abdomenUpper", "chestLower", "chestUpper"], "hip")
    body += _spine(["neckLower", "neckUpper", "head"], "chestUpper", 1.5, 1.75)
    left = _chain(
        ["lThighBend", "lThighTwist", "lShin", "lFoot", "lMetatarsals", "lToe"],
        "pelvis",
        [_HIP, _lerp(_HIP, _KNEE, 0.45), _KNEE, _ANKLE, (0.1, -0.05, 0.03), _BALL, _TIP],
    )
    for k, toe in enumerate(("lBigToe", "lSmallToe1", "lSmallToe2", "lSmallToe3", "lSmallToe4")):
        h = _plus(_TIP, (0.01 * (2 - k), 0.01, 0.0))
        left.append((toe, "lToe", h, _plus(h, (0.0, -0.025, -0.002))))
    left += _arm(
        ["lShldrBend", "lShldrTwist", "lForearmBend", "lForearmTwist", "lHand"],
        "chestUpper",
        "lCollar",
        "chestUpper",
    )
    return body + left + _mirror(left, lambda n: "r" + n[1:] if re.match(r"^l[A-Z]", n) else n)


def _mmd_bones(ik_parent: bool) -> list[Spec]:
    """A PMX model as mmd_tools imports it (Japanese names only): 全ての親 > センター >
    グルーブ > 腰 > 下半身 > 左足 > 左ひざ > 左足首 > 左つま先, the upper body from 腰, and the
    leg IK bones 左足ＩＫ > 左つま先ＩＫ under the root (``ik_parent``: under 左足IK親 on the
    ground, as newer models have them)."""
    body: list[Spec] = [
        ("全ての親", None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.1)),
        ("センター", "全ての親", (0.0, 0.0, 0.6), (0.0, 0.0, 0.5)),
        ("グルーブ", "センター", (0.0, 0.0, 0.65), (0.0, 0.0, 0.75)),
        ("腰", "グルーブ", (0.0, 0.02, 0.95), (0.0, 0.0, 1.0)),
        ("下半身", "腰", (0.0, 0.0, 1.0), (0.0, 0.0, 0.9)),
    ]
    body += _spine(["上半身", "上半身2", "首", "頭"], "腰", 1.0, 1.72)
    left = _chain(
        ["左足", "左ひざ", "左足首", "左つま先"], "下半身", [_HIP, _KNEE, _ANKLE, _BALL, (0.1, -0.12, 0.0)]
    )
    left += _chain(
        ["左肩", "左腕", "左ひじ", "左手首"],
        "上半身2",
        [(0.03, 0.0, 1.43), (0.16, 0.0, 1.42), (0.35, 0.0, 1.25), (0.52, 0.0, 1.08), (0.58, 0.0, 1.02)],
    )
    parent = "全ての親"
    if ik_parent:
        left.append(("左足IK親", "全ての親", (_ANKLE[0], _ANKLE[1], 0.0), (_ANKLE[0], _ANKLE[1], 0.05)))
        parent = "左足IK親"
    left += _chain(["左足ＩＫ", "左つま先ＩＫ"], parent, [_ANKLE, _BALL, _plus(_BALL, (0.0, 0.0, -0.05))])
    return body + left + _mirror(left, _swap("左", "右"))


def _mmd(scene: Any, name: str, ik_parent: bool = False) -> Any:
    """:func:`_mmd_bones` with MMD's IK: the knee pulled to 左足ＩＫ (two bones), the ankle to
    左つま先ＩＫ (one)."""
    arm = build(scene, name, _mmd_bones(ik_parent))
    for side in "左右":
        for bone, target, count in (
            (f"{side}ひざ", f"{side}足ＩＫ", 2),
            (f"{side}足首", f"{side}つま先ＩＫ", 1),
        ):
            c = arm.pose.bones[bone].constraints.new("IK")
            c.target, c.subtarget, c.chain_count = arm, target, count
    bpy.context.view_layer.update()
    return arm


def _ik_quadruped_bones() -> list[Spec]:
    """A hand-made quadruped with IK controls named ``CTRL_``: a reverse-foot chain
    ``CTRL_foot.L > CTRL_toe.L`` per foot under ``root``, standing on the ground beside each
    foot, and pole bones."""
    body: list[Spec] = [("root", None, (0.0, 0.0, 0.0), (0.0, 0.4, 0.0))]
    body += _chain(
        ["hips", "spine", "chest"],
        "root",
        [(0.0, 0.35, 0.9), (0.0, 0.1, 0.92), (0.0, -0.15, 0.94), (0.0, -0.35, 0.97)],
    )
    body += _chain(["neck", "head"], "chest", [(0.0, -0.35, 0.97), (0.0, -0.55, 1.15), (0.0, -0.75, 1.1)])
    left = _chain(
        ["upperarm.L", "forearm.L", "paw.L", "toes.L"],
        "chest",
        [
            (0.15, -0.35, 0.9),
            (0.16, -0.25, 0.5),
            (0.16, -0.33, 0.12),
            (0.16, -0.38, 0.02),
            (0.16, -0.45, 0.0),
        ],
    )
    left += _chain(
        ["thigh.L", "shin.L", "hindpaw.L", "hindtoes.L"],
        "hips",
        [(0.15, 0.4, 0.85), (0.16, 0.2, 0.5), (0.16, 0.45, 0.15), (0.16, 0.4, 0.02), (0.16, 0.33, 0.0)],
    )
    left += _chain(
        ["CTRL_foot.L", "CTRL_toe.L"], "root", [(0.16, -0.33, 0.12), (0.16, -0.38, 0.02), (0.16, -0.45, 0.0)]
    )
    left += _chain(
        ["CTRL_hindfoot.L", "CTRL_hindtoe.L"],
        "root",
        [(0.16, 0.45, 0.15), (0.16, 0.4, 0.02), (0.16, 0.33, 0.0)],
    )
    left += [
        ("pole_front.L", "root", (0.16, -0.7, 0.5), (0.16, -0.8, 0.5)),
        ("pole_hind.L", "root", (0.16, 0.8, 0.5), (0.16, 0.9, 0.5)),
    ]
    return body + left + _mirror(left, _swap(".L", ".R"))


def _dragon_bones() -> list[Spec]:
    """A dragon: four legs, folded wings hanging low beside the body, a jaw, and a long tail
    whose last bones lie on the ground behind it."""
    body = _chain(
        ["hips", "spine", "chest"],
        None,
        [(0.0, 0.5, 1.3), (0.0, 0.15, 1.35), (0.0, -0.2, 1.38), (0.0, -0.5, 1.42)],
    )
    body += _chain(["neck", "head"], "chest", [(0.0, -0.5, 1.42), (0.0, -0.8, 1.7), (0.0, -1.1, 1.6)])
    body.append(("jaw", "head", (0.0, -0.85, 1.6), (0.0, -1.1, 1.45)))
    body += _chain(
        [f"tail.{k:03d}" for k in range(1, 7)],
        "hips",
        [
            (0.0, 0.5, 1.3),
            (0.0, 0.9, 1.0),
            (0.0, 1.3, 0.6),
            (0.0, 1.7, 0.25),
            (0.0, 2.1, 0.06),
            (0.0, 2.5, 0.02),
            (0.0, 2.9, 0.0),
        ],
    )
    left = _chain(
        ["upper_arm.L", "forearm.L", "hand.L", "finger.L"],
        "chest",
        [(0.25, -0.35, 1.25), (0.3, -0.25, 0.75), (0.3, -0.4, 0.2), (0.3, -0.5, 0.03), (0.3, -0.62, 0.0)],
    )
    left += _chain(
        ["thigh.L", "shin.L", "foot.L", "toe.L"],
        "hips",
        [(0.25, 0.45, 1.2), (0.3, 0.1, 0.8), (0.3, 0.4, 0.25), (0.3, 0.3, 0.03), (0.3, 0.15, 0.0)],
    )
    left += _chain(
        ["wing_upper.L", "wing_fore.L", "wing_finger1.L"],
        "chest",
        [(0.15, -0.2, 1.45), (0.6, 0.0, 1.6), (0.55, 0.5, 1.0), (0.5, 1.0, 0.35)],
    )
    left.append(("wing_finger2.L", "wing_fore.L", (0.55, 0.5, 1.0), (0.6, 0.8, 0.5)))
    return body + left + _mirror(left, _swap(".L", ".R"))


def _numbered(bones: Sequence[Spec]) -> tuple[list[Spec], dict[str, str]]:
    """``bones`` renamed ``Bone``, ``Bone.001``, ... in order (a file with no names), and the
    new name of each old one."""
    new = {b[0]: f"Bone.{i:03d}" if i else "Bone" for i, b in enumerate(bones)}
    return [(new[n], new[p] if p else None, h, t) for n, p, h, t in bones], new


def _beetle_bones() -> list[Spec]:
    """A game beetle as a glTF from an engine gives it: a body and a head, six sprawling legs
    of three bones (coxa, femur rising to a high knee, tibia down to the ground) hanging from
    the body, every bone named ``joint_N`` in file order. 20 cm high at the hips, legs 38 cm
    along the bones."""
    s = 0.2
    specs: list[Spec] = [
        ("Body", None, (0.0, 0.16, s), (0.0, -0.12, s)),
        ("Head", "Body", (0.0, -0.12, s), (0.0, -0.18, 1.05 * s)),
    ]
    for side, tag in ((1.0, "L"), (-1.0, "R")):
        for k, y in enumerate((-0.1, 0.0, 0.1)):
            out = np.array([1.0, 0.4 * np.sign(y), 0.0]) / math.hypot(1.0, 0.4 * np.sign(y))
            hip = np.array([0.03, y, s])
            coxa = hip + 0.02 * out
            knee = coxa + 0.06 * out + np.array([0.0, 0.0, 0.06])
            foot = knee + 0.08 * out
            foot[2] = 0.0
            points = [(side * float(p[0]), float(p[1]), float(p[2])) for p in (hip, coxa, knee, foot)]
            specs += _chain([f"coxa{k}.{tag}", f"femur{k}.{tag}", f"tibia{k}.{tag}"], "Body", points)
    new = {b[0]: f"joint_{i}" for i, b in enumerate(specs)}
    return [(new[n], new[p] if p else None, h, t) for n, p, h, t in specs]


def _in_holder(scene: Any, name: str) -> Any:
    """The horse parented to an empty that is moved, turned and scaled by 0.5 (a rig kept
    under a scene's root empty, as imported files and asset packs do): the rig stands where
    the empty puts it, at half size."""
    arm = _horse(scene, name)
    holder = bpy.data.objects.new(f"{name}_Holder", None)
    scene.collection.objects.link(holder)
    holder.location = (1.0, 2.0, 0.0)
    holder.rotation_euler = (0.0, 0.0, 0.5)
    holder.scale = (0.5, 0.5, 0.5)
    arm.parent = holder
    bpy.context.view_layer.update()
    return arm


def _mirrored(scene: Any, name: str) -> Any:
    """The horse mirrored as an object (Ctrl M, X: scale -1 on X)."""
    arm = _horse(scene, name)
    arm.scale = (-1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    return arm


def _copy_rotation_controls(scene: Any, name: str) -> Any:
    """The horse with a hand-made control chain beside each leg (``femur_ctrl.L`` ...: same
    joints, no skin) whose bones the deform leg bones copy with Copy Rotation at full
    influence, as rigs made by hand or exported from other tools often drive their legs: keys
    on the deform bones would be overwritten."""
    legs = ("scapula", "humerus", "radius", "cannon", "pastern", "hoof",
            "femur", "tibia", "metatarsus", "hind_pastern", "hind_hoof")
    bones = _horse_bones()
    ctrl = {n: f"{n[:-2]}_ctrl{n[-2:]}" for n, _p, _h, _t in bones if n[:-2] in legs}
    extra = [(ctrl[n], ctrl.get(p, p) if p else None, h, t) for n, p, h, t in bones if n in ctrl]
    arm = build(scene, name, [*bones, *extra])
    for n, c in ctrl.items():
        con = arm.pose.bones[n].constraints.new("COPY_ROTATION")
        con.target, con.subtarget = arm, c
    bpy.context.view_layer.update()
    return arm


# ---------------------------------------------------------------------------------------
# Auto-Rig Pro (the names and wiring of its rigs, rebuilt by script)
#
# What the names are based on: Auto-Rig Pro's own documentation (Game Engine Export: the
# ``c_traj`` controller, the hips controller ``c_root_master.x`` and the IK feet parented to
# it, ``forearm_stretch`` named "the final deforming bone"; Auto-Rig: ``c_foot_ik.l``,
# ``c_leg_pole.l``, ``c_thigh_fk.l``), and its Humanoid export as published skeletons and
# retargeting maps name it: ``root.x`` (the hips) > ``spine_01.x`` > ``spine_02.x`` >
# ``neck.x`` > ``head.x``; ``shoulder.l`` > ``arm_stretch.l`` > ``forearm_stretch.l`` >
# ``hand.l``; ``root.x`` > ``thigh_twist.l`` > ``thigh_stretch.l`` > ``leg_stretch.l`` >
# ``leg_twist.l`` > ``foot.l`` > ``toes_01.l`` (the thigh's twist half at the hip, the leg's at
# the ankle), ``.r`` mirrored. Left out of the control rig: the foot-roll and heel bones
# (``c_foot_roll.l``, ``c_foot_bank``...), ``c_thigh_b.l``, the stretch controllers
# (``c_stretch_leg.l``), the arms' and head's controls and the spine's ``c_root.x`` pivots
# beyond one per bone: the fixture has what drives the legs and the body.

#: The left leg's joints: hip, mid-thigh, knee, mid-shin, ankle, ball, toe tip.
_ARP_LEG = (_HIP, _lerp(_HIP, _KNEE, 0.5), _KNEE, _lerp(_KNEE, _ANKLE, 0.5), _ANKLE, _BALL, _TIP)
_ARP_DEFORM_LEG = ("thigh_twist.l", "thigh_stretch.l", "leg_stretch.l", "leg_twist.l", "foot.l", "toes_01.l")


def _arp_deform_bones() -> list[Spec]:
    """Auto-Rig Pro's Humanoid deform skeleton (as its game-engine export writes it): see above."""
    body = _spine(["root.x", "spine_01.x", "spine_02.x"], None, 0.95, 1.5)
    body += _spine(["neck.x", "head.x"], "spine_02.x", 1.5, 1.75)
    left = _chain(list(_ARP_DEFORM_LEG), "root.x", list(_ARP_LEG))
    left += _arm(["arm_stretch.l", "forearm_stretch.l", "hand.l"], "spine_02.x", "shoulder.l", "spine_02.x")
    return body + left + _mirror(left, _swap(".l", ".r"))


def _arp_dog_bones() -> list[Spec]:
    """An Auto-Rig Pro dog's deform skeleton, 60 cm at the withers: three-bone legs (``limbs``
    with ``c_thigh_b``, which deforms) hind ``c_thigh_b.l`` (femur) > ``thigh_twist.l`` >
    ``thigh_stretch.l`` (tibia) > ``leg_stretch.l`` > ``leg_twist.l`` (metatarsus) >
    ``foot.l`` > ``toes_01.l`` (the paw) under ``root.x``, and the front legs, a duplicated
    leg limb (``c_thigh_b_dupli_001.l`` > ``thigh_twist_dupli_001.l`` ...), under the chest
    ``spine_03.x``: the chains as a published ARP quadruped's deform bones list them. The
    spine runs from ``root.x`` at the hips forward to the head, the tail back from it."""
    body = _chain(
        ["root.x", "spine_01.x", "spine_02.x", "spine_03.x"],
        None,
        [(0.0, 0.3, 0.55), (0.0, 0.15, 0.57), (0.0, 0.0, 0.58), (0.0, -0.15, 0.6), (0.0, -0.28, 0.62)],
    )
    body += _chain(
        ["neck.x", "head.x"], "spine_03.x", [(0.0, -0.28, 0.62), (0.0, -0.4, 0.75), (0.0, -0.58, 0.72)]
    )
    body += _chain(
        ["tail_00.x", "tail_01.x"], "root.x", [(0.0, 0.3, 0.55), (0.0, 0.45, 0.5), (0.0, 0.6, 0.4)]
    )

    def leg(suffix: str, parent: str, points: Sequence[Vec]) -> list[Spec]:
        hip, stifle, hock, paw, ball, tip = points
        names = ["c_thigh_b", "thigh_twist", "thigh_stretch", "leg_stretch", "leg_twist", "foot", "toes_01"]
        return _chain([f"{n}{suffix}.l" for n in names], parent,
                      [hip, stifle, _lerp(stifle, hock, 0.5), hock, _lerp(hock, paw, 0.5), paw, ball, tip])

    left = leg("", "root.x", [(0.09, 0.3, 0.52), (0.1, 0.2, 0.34), (0.1, 0.36, 0.17), (0.1, 0.33, 0.04),
                              (0.1, 0.29, 0.012), (0.1, 0.24, 0.0)])
    left += leg("_dupli_001", "spine_03.x", [(0.09, -0.22, 0.55), (0.1, -0.28, 0.4), (0.1, -0.22, 0.26),
                                             (0.1, -0.25, 0.05), (0.1, -0.29, 0.012), (0.1, -0.34, 0.0)])
    return body + left + _mirror(left, _swap(".l", ".r"))


def _arp_control_bones() -> list[Spec]:
    """The deform skeleton and the controls and mechanism of an Auto-Rig Pro biped's body and
    legs: ``c_pos`` > ``c_traj`` > ``c_root_master.x`` > ``c_root.x`` (the hips), the spine's
    ``c_spine_01.x`` ...; per leg the FK controls ``c_thigh_fk.l`` > ``c_leg_fk.l`` >
    ``c_foot_fk.l`` > ``c_toes_fk.l``, the IK chain ``thigh_ik.l`` > ``leg_ik.l``, the IK foot
    ``c_foot_ik.l`` (under ``c_traj``) > ``foot_ik.l`` > ``c_toes_ik.l`` and the pole
    ``c_leg_pole.l``."""
    hip, _mid, knee, _low, ankle, ball, tip = _ARP_LEG
    body: list[Spec] = [
        ("c_pos", None, (0.0, 0.0, 0.0), (0.0, 0.5, 0.0)),
        ("c_traj", "c_pos", (0.0, 0.0, 0.0), (0.0, 0.3, 0.0)),
        ("c_root_master.x", "c_traj", (0.0, 0.0, 0.95), (0.0, 0.25, 0.95)),
    ]
    body += [(f"c_{n}", "c_root_master.x" if p is None else f"c_{p}", h, t)
             for n, p, h, t in _spine(["root.x", "spine_01.x", "spine_02.x"], None, 0.95, 1.5)]
    left = _chain(["c_thigh_fk.l", "c_leg_fk.l", "c_foot_fk.l", "c_toes_fk.l"], "c_root.x",
                  [hip, knee, ankle, ball, tip])
    left += _chain(["thigh_ik.l", "leg_ik.l"], "c_root.x", [hip, knee, ankle])
    left += _chain(["c_foot_ik.l"], "c_traj", [ankle, ball])
    left += _chain(["foot_ik.l", "c_toes_ik.l"], "c_foot_ik.l", [ankle, ball, tip])
    left.append(("c_leg_pole.l", "c_traj", (hip[0], -0.5, knee[2]), (hip[0], -0.6, knee[2])))
    return _arp_deform_bones() + body + left + _mirror(left, _swap(".l", ".r"))


def _arp_deform_names() -> set[str]:
    return {n for n, _p, _h, _t in _arp_deform_bones()}


def _arp_export(scene: Any, name: str) -> Any:
    """Auto-Rig Pro's game-engine export: the deform skeleton alone, every bone deforming."""
    return build(scene, name, _arp_deform_bones(), deform=lambda _n: True)


def _arp_rig(scene: Any, name: str) -> Any:
    """An Auto-Rig Pro biped as animators have it in Blender (:func:`_arp_control_bones`).
    The deform bones follow the controls: ``root.x`` and the spine copy the transforms of
    ``c_root.x``, ``c_spine_01.x`` ...; per leg ``thigh_twist.l`` (and with it its child
    ``thigh_stretch.l``), ``leg_stretch.l`` (and ``leg_twist.l``), ``foot.l`` and
    ``toes_01.l`` copy the rotation of the FK control and of the IK chain's bone, the IK copy's
    influence driven by ``1 - ik_fk_switch`` on ``c_foot_ik.l`` (1: FK, as the animator left
    it). ``leg_ik.l`` has the IK to ``c_foot_ik.l`` (two bones) with the pole
    ``c_leg_pole.l``. Deform and mechanism bones sit in hidden bone collections."""
    deform = _arp_deform_names()
    arm = build(scene, name, _arp_control_bones(), deform=lambda n: n in deform)
    data = arm.data
    hidden = data.collections.new("Deform and mechanism")
    shown = data.collections.new("Controls")
    for b in data.bones:
        (shown if b.name.startswith("c_") else hidden).assign(b)
    hidden.is_visible = False
    pbones = arm.pose.bones
    for n in ("root.x", "spine_01.x", "spine_02.x"):
        con = pbones[n].constraints.new("COPY_TRANSFORMS")
        con.target, con.subtarget = arm, f"c_{n}"
    for side in "lr":
        pbones[f"c_foot_ik.{side}"]["ik_fk_switch"] = 1.0
        for deform_bone, fk, ik in (("thigh_twist", "c_thigh_fk", "thigh_ik"),
                                    ("leg_stretch", "c_leg_fk", "leg_ik"),
                                    ("foot", "c_foot_fk", "foot_ik"), ("toes_01", "c_toes_fk", "c_toes_ik")):
            pb = pbones[f"{deform_bone}.{side}"]
            for target in (fk, ik):
                con = pb.constraints.new("COPY_ROTATION")
                con.target, con.subtarget = arm, f"{target}.{side}"
            fc = con.driver_add("influence")
            var = fc.driver.variables.new()
            var.name, var.type = "switch", "SINGLE_PROP"
            var.targets[0].id = arm
            var.targets[0].data_path = f'pose.bones["c_foot_ik.{side}"]["ik_fk_switch"]'
            fc.driver.expression = "1 - switch"
        ik = pbones[f"leg_ik.{side}"].constraints.new("IK")
        ik.target, ik.subtarget, ik.chain_count = arm, f"c_foot_ik.{side}", 2
        ik.pole_target, ik.pole_subtarget = arm, f"c_leg_pole.{side}"
        best: tuple[float, float] | None = None
        for angle in (0.0, 90.0, -90.0, 180.0):  # the pole angle that keeps the rest pose
            ik.pole_angle = math.radians(angle)
            bpy.context.view_layer.update()
            knee = pbones[f"leg_ik.{side}"].matrix.to_translation()
            err = (knee - data.bones[f"leg_ik.{side}"].head_local).length
            if best is None or err < best[0]:
                best = (err, angle)
        assert best is not None
        ik.pole_angle = math.radians(best[1])
    bpy.context.view_layer.update()
    return arm


_HORSE_NUMBERED = _numbered(_horse_bones())
_DRAGON_NUMBERED = _numbered(_dragon_bones())
_DRAGON_LEGS = {
    "L1": ("upper_arm.L", "hand.L"),
    "R1": ("upper_arm.R", "hand.R"),
    "L2": ("thigh.L", "foot.L"),
    "R2": ("thigh.R", "foot.R"),
}


# ---------------------------------------------------------------------------------------
# More families users bring (round 5)


def _vroid_bones() -> list[Spec]:
    """A VRoid Studio character as its VRM/glTF has it (VRM 0.x names): ``Root`` >
    ``J_Bip_C_Hips`` > ``J_Bip_L_UpperLeg`` > ``J_Bip_L_LowerLeg`` > ``J_Bip_L_Foot`` >
    ``J_Bip_L_ToeBase``, the spine and arms ``J_Bip_C_Spine`` ... ``J_Bip_L_Hand``, eyes
    ``J_Adj_L_FaceEye``, and the secondary (spring) bones that hang like legs: an ankle-long
    dress whose chains hang from each thigh (``J_Sec_L_SkirtFront0_01``, a short pivot, >
    ``J_Sec_L_SkirtFront1_01`` > ... near the floor), coat tails from the hips to the knees
    (``J_Sec_L_CoatSkirtBack_01`` ...), back hair to the waist and twin tails to the floor
    (``J_Sec_Hair1_05`` ...), the bust (``J_Sec_L_Bust1``)."""
    body: list[Spec] = [("Root", None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.1))]
    body += _spine(["J_Bip_C_Hips", "J_Bip_C_Spine", "J_Bip_C_Chest", "J_Bip_C_UpperChest"], "Root",
                   0.95, 1.45)
    body += _spine(["J_Bip_C_Neck", "J_Bip_C_Head"], "J_Bip_C_UpperChest", 1.45, 1.72)
    body += _chain(["J_Sec_Hair1_01", "J_Sec_Hair2_01", "J_Sec_Hair3_01"], "J_Bip_C_Head",
                   [(0.0, 0.08, 1.66), (0.0, 0.12, 1.45), (0.0, 0.13, 1.25), (0.0, 0.12, 1.05)])
    left = _chain(["J_Bip_L_UpperLeg", "J_Bip_L_LowerLeg", "J_Bip_L_Foot", "J_Bip_L_ToeBase"], "J_Bip_C_Hips",
                  [_HIP, _KNEE, _ANKLE, _BALL, _TIP])
    left += _arm(["J_Bip_L_UpperArm", "J_Bip_L_LowerArm", "J_Bip_L_Hand"], "J_Bip_C_UpperChest",
                 "J_Bip_L_Shoulder", "J_Bip_C_UpperChest")
    hand = left[-1][3]
    for finger, dy in (("Thumb", -0.02), ("Index", -0.01), ("Middle", 0.0), ("Ring", 0.01), ("Little", 0.02)):
        start = _plus(hand, (0.0, dy, 0.0))
        left += _chain([f"J_Bip_L_{finger}{j}" for j in (1, 2, 3)], "J_Bip_L_Hand",
                       [_plus(start, (0.02 * j, 0.0, -0.02 * j)) for j in range(4)])
    left.append(("J_Adj_L_FaceEye", "J_Bip_C_Head", (0.03, -0.07, 1.63), (0.03, -0.09, 1.63)))
    left += _chain(["J_Sec_L_Bust1", "J_Sec_L_Bust2"], "J_Bip_C_UpperChest",
                   [(0.05, -0.05, 1.33), (0.06, -0.1, 1.31), (0.06, -0.13, 1.3)])
    # The dress: per thigh a front, side and back chain, a 1 cm pivot at the hip then three
    # bones flaring down to 12 cm above the floor (VRoid's leg skirt).
    for part, (dx, dy) in (("Front", (0.0, -0.1)), ("Side", (0.1, 0.0)), ("Back", (0.0, 0.1))):
        top = _plus(_HIP, (0.5 * dx, 0.5 * dy, 0.0))
        pivot = _plus(top, (0.0, 0.0, -0.01))
        bottom = _plus(_HIP, (1.6 * dx + 0.03, 1.6 * dy, 0.12 - _HIP[2]))
        names = [f"J_Sec_L_Skirt{part}{k}_01" for k in range(4)]
        left += _chain(names, "J_Bip_L_UpperLeg",
                       [top, pivot, _lerp(pivot, bottom, 1 / 3), _lerp(pivot, bottom, 2 / 3), bottom])
    # Coat tails from the hips' back, down to the knees.
    left += _chain([f"J_Sec_L_CoatSkirtBack_0{k}" for k in (1, 2, 3)], "J_Bip_C_Hips",
                   [(0.08, 0.12, 0.97), (0.09, 0.16, 0.8), (0.1, 0.19, 0.62), (0.1, 0.21, 0.45)])
    # A twin tail from the side of the head to the floor (the right one ``J_Sec_Hair1_06``...).
    left += _chain([f"J_Sec_Hair{k}_05" for k in range(1, 6)], "J_Bip_C_Head",
                   [(0.1, 0.03, 1.68), (0.16, 0.06, 1.5), (0.2, 0.1, 1.2), (0.22, 0.12, 0.85),
                    (0.23, 0.13, 0.45), (0.23, 0.13, 0.06)])
    return body + left + _mirror(left, lambda n: n.replace("_L_", "_R_").replace("_05", "_06"))


def _makehuman_bones() -> list[Spec]:
    """MakeHuman's (MPFB's) default skeleton: ``root`` (the hips) > ``pelvis.L`` >
    ``upperleg01.L`` > ``upperleg02.L`` > ``lowerleg01.L`` > ``lowerleg02.L`` > ``foot.L`` >
    ``toe1-1.L`` ... (the thigh and the shin each in two bones, five toes of two or three
    bones), ``root`` > ``spine05`` ... ``spine01`` > ``neck01`` ... ``head`` > ``jaw``, and
    ``spine01`` > ``clavicle.L`` > ``shoulder01.L`` > ``upperarm01.L`` > ``upperarm02.L`` >
    ``lowerarm01.L`` > ``lowerarm02.L`` > ``wrist.L``."""
    body: list[Spec] = [("root", None, (0.0, 0.0, 0.95), (0.0, 0.0, 1.02))]
    body += _spine(["spine05", "spine04", "spine03", "spine02", "spine01"], "root", 1.02, 1.45)
    body += _spine(["neck01", "neck02", "neck03", "head"], "spine01", 1.45, 1.75)
    body.append(("jaw", "head", (0.0, -0.02, 1.6), (0.0, -0.08, 1.56)))
    left = _chain(["pelvis.L"], "root", [(0.0, 0.0, 0.95), _HIP])
    left += _chain(
        ["upperleg01.L", "upperleg02.L", "lowerleg01.L", "lowerleg02.L", "foot.L"], "pelvis.L",
        [_HIP, _lerp(_HIP, _KNEE, 0.4), _KNEE, _lerp(_KNEE, _ANKLE, 0.5), _ANKLE, _BALL],
    )
    for k in range(1, 6):
        start = _plus(_BALL, (0.012 * (3 - k), 0.0, 0.0))
        n = 2 if k == 1 else 3
        left += _chain([f"toe{k}-{j}.L" for j in range(1, n + 1)], "foot.L",
                       [_plus(start, (0.0, -0.02 * j, -0.002 * j)) for j in range(n + 1)])
    left.append(("eye.L", "head", (0.03, -0.07, 1.63), (0.03, -0.09, 1.63)))
    left.append(("breast.L", "spine02", (0.06, -0.06, 1.3), (0.07, -0.12, 1.28)))
    left += _arm(["shoulder01.L", "upperarm01.L", "upperarm02.L", "lowerarm01.L", "lowerarm02.L", "wrist.L"],
                 "spine01", "clavicle.L", "spine01")
    return body + left + _mirror(left, _swap(".L", ".R"))


def _genesis9_bones() -> list[Spec]:
    """DAZ Genesis 9: ``hip`` > ``pelvis`` > ``l_thigh`` > ``l_shin`` > ``l_foot`` >
    ``l_metatarsal`` > ``l_toes``, twist bones beside the limb bones (``l_thigh_twist1``,
    ``l_thigh_twist2`` under the thigh, ``l_shin_twist1``...), ``hip`` > ``spine1`` ...
    ``spine4`` > ``neck1`` > ``neck2`` > ``head``, the arms ``l_shoulder`` > ``l_upperarm`` >
    ``l_forearm`` > ``l_hand``."""
    body = [
        ("hip", None, (0.0, 0.0, 1.0), (0.0, 0.0, 1.05)),
        ("pelvis", "hip", (0.0, 0.0, 1.0), (0.0, 0.0, 0.9)),
    ]
    body += _spine(["spine1", "spine2", "spine3", "spine4"], "hip")
    body += _spine(["neck1", "neck2", "head"], "spine4", 1.5, 1.75)
    left = _chain(["l_thigh", "l_shin", "l_foot", "l_metatarsal", "l_toes"], "pelvis",
                  [_HIP, _KNEE, _ANKLE, (0.1, -0.05, 0.03), _BALL, _TIP])
    for bone, (a, b) in (("l_thigh", (_HIP, _KNEE)), ("l_shin", (_KNEE, _ANKLE))):
        left += [(f"{bone}_twist1", bone, _lerp(a, b, 0.2), _lerp(a, b, 0.5)),
                 (f"{bone}_twist2", bone, _lerp(a, b, 0.5), _lerp(a, b, 0.8))]
    left += _arm(["l_upperarm", "l_forearm", "l_hand"], "spine4", "l_shoulder", "spine4")
    return body + left + _mirror(left, lambda n: "r_" + n[2:] if n.startswith("l_") else n)


def _dog_bones() -> list[Spec]:
    """A game dog, 62 cm at the hips: a spine from the pelvis forward to the head, a jaw and two
    ears on the head, a relaxed tail of three bones hanging from the pelvis down behind the
    hind legs to 8 cm above the floor, legs of four bones (the last one the paw's toes)."""
    body = _chain(["pelvis", "spine", "chest"], None,
                  [(0.0, 0.3, 0.6), (0.0, 0.1, 0.62), (0.0, -0.15, 0.63), (0.0, -0.3, 0.64)])
    body += _chain(["neck", "head"], "chest", [(0.0, -0.3, 0.64), (0.0, -0.42, 0.8), (0.0, -0.6, 0.78)])
    body.append(("jaw", "head", (0.0, -0.45, 0.76), (0.0, -0.6, 0.7)))
    body += _chain(["tail1", "tail2", "tail3"], "pelvis",
                   [(0.0, 0.3, 0.6), (0.0, 0.45, 0.48), (0.0, 0.55, 0.3), (0.0, 0.58, 0.08)])
    left = [("ear.L", "head", (0.05, -0.45, 0.86), (0.08, -0.44, 0.97))]
    left += _chain(["upperarm.L", "forearm.L", "hand.L", "finger.L"], "chest",
                   [(0.1, -0.22, 0.6), (0.11, -0.15, 0.36), (0.11, -0.2, 0.1), (0.11, -0.24, 0.03),
                    (0.11, -0.3, 0.0)])
    left += _chain(["thigh.L", "shin.L", "foot.L", "toe.L"], "pelvis",
                   [(0.1, 0.28, 0.58), (0.11, 0.15, 0.38), (0.11, 0.32, 0.14), (0.11, 0.28, 0.03),
                    (0.11, 0.22, 0.0)])
    return body + left + _mirror(left, _swap(".L", ".R"))


def _bug_bones() -> list[Spec]:
    """A six-legged game bug, 12 cm at the hips: a thorax and an abdomen sloping down behind,
    a head with two mandibles reaching down in front to 3 cm above the floor and two long
    antennae, six legs of three bones (coxa, femur up to the knee, tibia down to the floor)."""
    s = 0.12
    specs: list[Spec] = [
        ("thorax", None, (0.0, 0.05, s), (0.0, -0.06, s)),
        ("abdomen", "thorax", (0.0, 0.05, s), (0.0, 0.2, 0.6 * s)),
        ("head", "thorax", (0.0, -0.06, s), (0.0, -0.1, 0.95 * s)),
    ]
    left: list[Spec] = []
    left += _chain(["mandible1.L", "mandible2.L"], "head",
                   [(0.01, -0.09, 0.9 * s), (0.02, -0.13, 0.6 * s), (0.01, -0.15, 0.03)])
    left += _chain(["antenna1.L", "antenna2.L"], "head",
                   [(0.01, -0.1, 1.0 * s), (0.04, -0.16, 1.4 * s), (0.07, -0.24, 1.6 * s)])
    for k, (y, yaw) in enumerate(((-0.04, -0.5), (0.0, 0.0), (0.04, 0.5)), start=1):
        out = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        hip = np.array([0.015, y, s])
        coxa = hip + 0.015 * out
        knee = coxa + 0.05 * out + np.array([0.0, 0.0, 0.03])
        foot = knee + 0.07 * out
        foot[2] = 0.0
        left += _chain([f"coxa{k}.L", f"femur{k}.L", f"tibia{k}.L"], "thorax",
                       [tuple(float(v) for v in p) for p in (hip, coxa, knee, foot)])  # type: ignore[misc]
    return specs + left + _mirror(left, _swap(".L", ".R"))


def _gltf_numbered(bones: Sequence[Spec]) -> tuple[list[Spec], dict[str, str]]:
    """``bones`` renamed as a glTF exported from a scene with no bone names arrives:
    ``Armature_Bone``, ``Armature_Bone_001``, ... in order."""
    new = {b[0]: f"Armature_Bone_{i:03d}" if i else "Armature_Bone" for i, b in enumerate(bones)}
    return [(new[n], new[p] if p else None, h, t) for n, p, h, t in bones], new


_DOG_NUMBERED = _numbered(_dog_bones())
_BUG_NUMBERED = _gltf_numbered(_bug_bones())


# ---------------------------------------------------------------------------------------
# Game creatures whose other limbs are the classic traps for leg detection (round 6)


def _out(azimuth: float) -> np.ndarray:
    """The horizontal unit vector ``azimuth`` degrees from forward (-Y) towards the left (+X)."""
    a = math.radians(azimuth)
    return np.array([math.sin(a), -math.cos(a), 0.0])


def _vec(p: np.ndarray) -> Vec:
    return (float(p[0]), float(p[1]), float(p[2]))


def _arthropod_leg(hip: Sequence[float], azimuth: float, coxa: float, femur: float, rise: float,
                   tibia: float, tarsus: float) -> list[Vec]:
    """The joints of an arthropod's left walking leg from ``hip``: a coxa out, a femur rising
    ``rise`` to a high knee, a tibia down to a tenth of the hip's height, a tarsus to the floor,
    each ``azimuth`` degrees from forward."""
    out = _out(azimuth)
    h = np.array(hip, dtype=np.float64)
    c = h + coxa * out + np.array([0.0, 0.0, -0.1 * coxa])
    k = c + femur * out + np.array([0.0, 0.0, rise])
    a = k + tibia * out
    a[2] = 0.12 * h[2]
    t = a + tarsus * out
    t[2] = 0.0
    return [_vec(p) for p in (h, c, k, a, t)]


def _scorpion_bones() -> list[Spec]:
    """A game scorpion 90 cm long with its claws, its body 16 cm above the floor: ``Root`` > ``Body`` (the
    mesosoma) > ``Head`` (the prosoma, the legs hanging from it), eight legs
    ``Leg1_Coxa.L`` > ``Leg1_Femur.L`` > ``Leg1_Tibia.L`` > ``Leg1_Tarsus.L`` ...; two pincer
    arms (the pedipalps) named as game artists name them, ``ClawArm1.L`` > ``ClawArm2.L`` >
    ``Claw.L`` > ``ClawFinger.L`` (leg words all: arm, claw), reaching forward and down to
    4 cm above the floor, longer than the legs; a segmented tail ``Tail1`` ... ``Tail5`` >
    ``Stinger`` curling up over the back; chelicerae on the head."""
    z = 0.16
    bones: list[Spec] = [
        ("Root", None, (0.0, 0.0, 0.0), (0.0, 0.1, 0.0)),
        ("Body", "Root", (0.0, 0.2, z), (0.0, -0.02, z)),
        ("Head", "Body", (0.0, -0.02, z), (0.0, -0.16, 0.95 * z)),
    ]
    # The tail: from the back of the body, back and up, then forward over the back.
    pts = [np.array([0.0, 0.2, z])]
    for k, angle in enumerate((15.0, 40.0, 70.0, 100.0, 130.0)):
        a = math.radians(angle)
        pts.append(pts[-1] + (0.11 - 0.008 * k) * np.array([0.0, math.cos(a), math.sin(a)]))
    a = math.radians(200.0)
    pts.append(pts[-1] + 0.07 * np.array([0.0, math.cos(a), math.sin(a)]))
    bones += _chain([*(f"Tail{k}" for k in range(1, 6)), "Stinger"], "Body", [_vec(p) for p in pts])
    left: list[Spec] = []
    for n, (y, azimuth) in enumerate(((-0.13, 55.0), (-0.09, 80.0), (-0.05, 105.0), (-0.01, 130.0)), start=1):
        left += _chain([f"Leg{n}_{b}.L" for b in ("Coxa", "Femur", "Tibia", "Tarsus")], "Head",
                       _arthropod_leg((0.035, y, 0.95 * z), azimuth, 0.03, 0.11, 0.07, 0.13, 0.05))
    left += _chain(["Chelicera.L"], "Head", [(0.015, -0.16, 0.95 * z), (0.02, -0.2, 0.85 * z)])
    left += _chain(["ClawArm1.L", "ClawArm2.L", "Claw.L", "ClawFinger.L"], "Head",
                   [(0.04, -0.15, 0.95 * z), (0.15, -0.24, 0.2), (0.12, -0.38, 0.1), (0.08, -0.5, 0.05),
                    (0.06, -0.57, 0.04)])
    return bones + left + _mirror(left, _swap(".L", ".R"))


_SCORPION_LEGS = {f"{s}{k}": (f"Leg{k}_Coxa.{s}", f"Leg{k}_Tibia.{s}") for k in range(1, 5) for s in "LR"}


def _raptor_bones() -> list[Spec]:
    """A game raptor in the Unreal style, 1 m at the hips and 3.3 m long: ``root`` >
    ``pelvis`` > ``spine_01`` ... ``spine_03`` > ``neck_01`` ... ``neck_04`` > ``head`` >
    ``jaw``; a tail ``tail_01`` ... ``tail_08`` held level behind; per leg ``thigh_l`` >
    ``calf_l`` > ``foot_l`` (the long metatarsus, steep) > ``ball_l`` > three toes
    ``toe_01_l`` > ``toe_01b_l`` ... flat on the floor and the raised sickle claw
    ``toe_claw_l``; two small arms ``clavicle_l`` > ``upperarm_l`` > ``lowerarm_l`` >
    ``hand_l`` > ``finger_01_l`` folded under the chest."""
    bones: list[Spec] = [("root", None, (0.0, 0.0, 0.0), (0.0, 0.2, 0.0))]
    bones += _chain(["pelvis", "spine_01", "spine_02", "spine_03"], "root",
                    [(0.0, 0.1, 1.0), (0.0, 0.0, 1.0), (0.0, -0.2, 1.02), (0.0, -0.4, 1.05),
                     (0.0, -0.55, 1.1)])
    bones += _chain([f"neck_0{k}" for k in range(1, 5)] + ["head"], "spine_03",
                    [(0.0, -0.55, 1.1), (0.0, -0.68, 1.25), (0.0, -0.78, 1.42), (0.0, -0.86, 1.58),
                     (0.0, -0.92, 1.7), (0.0, -1.2, 1.7)])
    bones.append(("jaw", "head", (0.0, -0.95, 1.66), (0.0, -1.18, 1.6)))
    bones += _chain([f"tail_0{k}" for k in range(1, 9)], "pelvis",
                    [(0.0, 0.1 + 0.25 * k, 1.0 - 0.01 * k) for k in range(9)])
    hip, knee, ankle, ball = (0.16, 0.05, 0.95), (0.18, -0.22, 0.58), (0.18, 0.12, 0.3), (0.18, 0.0, 0.04)
    left = _chain(["thigh_l", "calf_l", "foot_l", "ball_l"], "pelvis",
                  [hip, knee, ankle, ball, (0.18, -0.05, 0.02)])
    for k, dx in ((1, 0.03), (2, 0.0), (3, -0.03)):
        start = (0.18 + dx, -0.05, 0.02)
        left += _chain([f"toe_0{k}_l", f"toe_0{k}b_l"], "ball_l",
                       [start, (0.18 + 1.5 * dx, -0.13, 0.01), (0.18 + 2 * dx, -0.2, 0.0)])
    left.append(("toe_claw_l", "ball_l", (0.17, 0.0, 0.04), (0.165, -0.06, 0.1)))
    left += _chain(["clavicle_l", "upperarm_l", "lowerarm_l", "hand_l", "finger_01_l"], "spine_03",
                   [(0.04, -0.45, 1.0), (0.12, -0.5, 0.98), (0.14, -0.5, 0.8), (0.12, -0.66, 0.82),
                    (0.11, -0.72, 0.76), (0.1, -0.74, 0.7)])
    return bones + left + _mirror(left, lambda n: re.sub(r"_l$", "_r", n))


def _centaur_bones() -> list[Spec]:
    """A game centaur: a horse's body 1.45 m at the withers on four legs named as a game
    artist names a horse's (``front_upperleg.L`` > ``front_lowerleg.L`` > ``front_cannon.L``
    > ``front_hoof.L``, ``hind_upperleg.L`` ... ``hind_hoof.L``), the human torso rising from
    its chest ``spine_01`` > ``waist`` > ``spine_02`` > ``chest`` > ``neck`` > ``head`` with
    two arms hanging straight down beside the horse's shoulders (``shoulder.L`` >
    ``upperarm.L`` > ``forearm.L`` > ``hand.L`` > ``fingers.L``), and a tail."""
    bones = _chain(["pelvis", "spine_01"], None, [(0.0, 0.45, 1.35), (0.0, 0.05, 1.38), (0.0, -0.35, 1.42)])
    bones += _chain(["waist", "spine_02", "chest", "neck", "head"], "spine_01",
                    [(0.0, -0.35, 1.42), (0.0, -0.5, 1.65), (0.0, -0.55, 1.85), (0.0, -0.55, 2.1),
                     (0.0, -0.56, 2.2), (0.0, -0.56, 2.42)])
    bones += _chain(["tail_01", "tail_02"], "pelvis", [(0.0, 0.45, 1.35), (0.0, 0.7, 1.1), (0.0, 0.85, 0.75)])
    front = [(0.15, -0.3, 1.3), (0.17, -0.38, 0.9), (0.17, -0.36, 0.45), (0.17, -0.37, 0.1),
             (0.17, -0.42, 0.0)]
    hind = [(0.17, 0.42, 1.3), (0.2, 0.22, 0.9), (0.2, 0.5, 0.5), (0.2, 0.5, 0.1), (0.2, 0.45, 0.0)]
    left = _chain(["front_upperleg.L", "front_lowerleg.L", "front_cannon.L", "front_hoof.L"], "spine_01",
                  front)
    left += _chain(["hind_upperleg.L", "hind_lowerleg.L", "hind_cannon.L", "hind_hoof.L"], "pelvis", hind)
    left += _chain(["shoulder.L", "upperarm.L", "forearm.L", "hand.L", "fingers.L"], "chest",
                   [(0.03, -0.55, 2.05), (0.2, -0.55, 2.05), (0.24, -0.55, 1.75), (0.25, -0.57, 1.47),
                    (0.25, -0.58, 1.3), (0.25, -0.58, 1.2)])
    return bones + left + _mirror(left, _swap(".L", ".R"))


def _mantis_bones() -> list[Spec]:
    """A game praying mantis 45 cm long, its thorax 10 cm above the floor: a thorax with four
    walking legs ``Leg2_Coxa.L`` ... ``Leg3_Tarsus.L``, the long prothorax raised
    ahead (``Prothorax`` > ``Head`` > ``Antenna1.L``) carrying the raptorial forelegs
    ``Leg1_Coxa.L`` > ``Leg1_Femur.L`` > ``Leg1_Tibia.L`` > ``Leg1_Tarsus.L`` held up and
    folded (the tibia folded back against the femur), an abdomen behind."""
    z = 0.1
    bones: list[Spec] = [
        ("Thorax", None, (0.0, 0.04, z), (0.0, -0.04, z)),
        ("Abdomen", "Thorax", (0.0, 0.04, z), (0.0, 0.26, 0.8 * z)),
        ("Prothorax", "Thorax", (0.0, -0.04, z), (0.0, -0.16, 1.8 * z)),
        ("Head", "Prothorax", (0.0, -0.16, 1.8 * z), (0.0, -0.2, 1.75 * z)),
    ]
    left: list[Spec] = [("Antenna1.L", "Head", (0.01, -0.2, 1.8 * z), (0.05, -0.3, 2.2 * z))]
    for n, (y, azimuth) in ((2, (-0.02, 75.0)), (3, (0.03, 125.0))):
        left += _chain([f"Leg{n}_{b}.L" for b in ("Coxa", "Femur", "Tibia", "Tarsus")], "Thorax",
                       _arthropod_leg((0.015, y, 0.95 * z), azimuth, 0.015, 0.08, 0.05, 0.1, 0.04))
    left += _chain([f"Leg1_{b}.L" for b in ("Coxa", "Femur", "Tibia", "Tarsus")], "Prothorax",
                   [(0.015, -0.13, 1.6 * z), (0.025, -0.15, 1.3 * z), (0.03, -0.2, 2.0 * z),
                    (0.03, -0.14, 1.3 * z), (0.03, -0.13, 1.5 * z)])
    return bones + left + _mirror(left, _swap(".L", ".R"))


def _crab_bones() -> list[Spec]:
    """A game crab, its carapace 25 cm wide 12 cm above the floor, its legs spanning 75 cm:
    ``root`` > ``body`` > eyestalks ``eye.L``; eight legs splayed sideways ``leg1_upper.L`` > ``leg1_mid.L`` >
    ``leg1_lower.L`` > ``leg1_tip.L`` ... (rising to a high knee, then down to the floor);
    two claws held in front ``claw_arm.L`` > ``claw_forearm.L`` > ``claw.L`` > ``claw_finger.L``,
    their tips resting 3 cm above the floor."""
    z = 0.12
    bones: list[Spec] = [
        ("root", None, (0.0, 0.0, 0.0), (0.0, 0.1, 0.0)),
        ("body", "root", (0.0, 0.1, z), (0.0, -0.1, z)),
    ]
    left: list[Spec] = [("eye.L", "body", (0.03, -0.1, z), (0.04, -0.13, 1.4 * z))]
    for n, (y, azimuth) in enumerate(((-0.06, 75.0), (-0.02, 88.0), (0.02, 100.0), (0.06, 112.0)), start=1):
        hip = np.array([0.12, y, z])
        out = _out(azimuth)
        mid = hip + 0.1 * out + np.array([0.0, 0.0, 0.06])
        low = mid + 0.12 * out
        low[2] = 0.05
        tip = low + 0.04 * out
        tip[2] = 0.0
        left += _chain([f"leg{n}_upper.L", f"leg{n}_mid.L", f"leg{n}_lower.L"], "body",
                       [_vec(p) for p in (hip, mid, low, tip)])
    left += _chain(["claw_arm.L", "claw_forearm.L", "claw.L", "claw_finger.L"], "body",
                   [(0.08, -0.1, z), (0.16, -0.2, 0.1), (0.1, -0.3, 0.06), (0.05, -0.36, 0.04),
                    (0.025, -0.39, 0.03)])
    return bones + left + _mirror(left, _swap(".L", ".R"))


#: The centipede's segments and leg pairs.
_CENTIPEDE_SEGMENTS = 11


def _centipede_bones() -> list[Spec]:
    """A game centipede 1.1 m long, 6 cm high: ``Head`` > ``Segment01`` > ... ``Segment11``
    (each 10 cm long, a chain running back), a pair of legs on each segment
    ``Segment03_Leg.L`` > ``Segment03_Foot.L`` (22 legs), antennae and venom claws
    (``Forcipule.L``) on the head, two cerci at the tail."""
    z = 0.06
    n = _CENTIPEDE_SEGMENTS
    bones: list[Spec] = [("Head", None, (0.0, -0.1, z), (0.0, -0.16, z))]
    bones += _chain([f"Segment{k:02d}" for k in range(1, n + 1)], "Head",
                    [(0.0, -0.1 + 0.1 * k, z) for k in range(n + 1)])
    left: list[Spec] = [
        ("Antenna1.L", "Head", (0.01, -0.16, z), (0.05, -0.26, 1.4 * z)),
        ("Forcipule.L", "Head", (0.015, -0.12, 0.8 * z), (0.01, -0.17, 0.5 * z)),
        ("Cercus.L", f"Segment{n:02d}", (0.01, -0.1 + 0.1 * n, z), (0.04, 0.1 * n, 0.9 * z)),
    ]
    for k in range(1, n + 1):
        y = -0.1 + 0.1 * k - 0.05
        hip, knee, foot = (0.02, y, z), (0.07, y - 0.01, 1.2 * z), (0.11, y - 0.02, 0.0)
        left += _chain([f"Segment{k:02d}_Leg.L", f"Segment{k:02d}_Foot.L"], f"Segment{k:02d}",
                       [hip, knee, foot])
    return bones + left + _mirror(left, _swap(".L", ".R"))


def _kangaroo_bones() -> list[Spec]:
    """A game kangaroo standing 1.3 m: ``pelvis`` > ``spine_01`` ... ``chest`` > ``neck`` >
    ``head`` leaning forward, big hind legs ``thigh.L`` > ``shin.L`` > ``foot.L`` (long, flat on
    the floor) > ``toe.L``, small forelegs ``upperarm.L`` > ``forearm.L`` > ``hand.L``
    hanging to 16 cm above the floor, and a thick tail ``tail_01`` ... ``tail_05`` lying on
    the floor behind."""
    bones = _chain(["pelvis", "spine_01", "spine_02", "chest"], None,
                   [(0.0, 0.1, 0.65), (0.0, -0.05, 0.75), (0.0, -0.18, 0.88), (0.0, -0.28, 1.0),
                    (0.0, -0.35, 1.08)])
    bones += _chain(["neck", "head"], "chest", [(0.0, -0.35, 1.08), (0.0, -0.42, 1.2), (0.0, -0.58, 1.3)])
    bones += _chain([f"tail_0{k}" for k in range(1, 6)], "pelvis",
                    [(0.0, 0.1, 0.65), (0.0, 0.35, 0.45), (0.0, 0.6, 0.22), (0.0, 0.85, 0.07),
                     (0.0, 1.1, 0.01), (0.0, 1.35, 0.0)])
    left = _chain(["thigh.L", "shin.L", "foot.L", "toe.L"], "pelvis",
                  [(0.13, 0.08, 0.6), (0.15, -0.15, 0.4), (0.15, 0.2, 0.1), (0.15, -0.12, 0.01),
                   (0.15, -0.22, 0.0)])
    left += _chain(["upperarm.L", "forearm.L", "hand.L"], "chest",
                   [(0.09, -0.3, 0.95), (0.11, -0.36, 0.65), (0.11, -0.4, 0.3), (0.11, -0.44, 0.16)])
    return bones + left + _mirror(left, _swap(".L", ".R"))


def _snake_bones() -> list[Spec]:
    """A game snake 2 m long lying on the floor in an S: ``root`` > ``spine_01`` ... ``spine_16``
    > ``head`` > ``jaw`` and ``tongue``; no legs."""
    bones: list[Spec] = [("root", None, (0.0, 0.0, 0.0), (0.0, -0.1, 0.0))]
    pts = [(0.2 * math.sin(0.5 * k), -1.0 + 0.12 * k, 0.03) for k in range(17)][::-1]
    bones += _chain([f"spine_{k:02d}" for k in range(1, 17)], "root", pts)
    head = pts[-1]
    bones += [("head", "spine_16", head, (head[0], head[1] - 0.08, 0.035)),
              ("jaw", "head", (head[0], head[1] - 0.01, 0.025), (head[0], head[1] - 0.07, 0.02)),
              ("tongue", "jaw", (head[0], head[1] - 0.07, 0.025), (head[0], head[1] - 0.12, 0.025))]
    return bones


_CENTAUR_LEGS = {f"{s}{k}": (f"{row}_upperleg.{s}", f"{row}_cannon.{s}")
                 for k, row in ((1, "front"), (2, "hind")) for s in "LR"}
_SCORPION_NUMBERED = _numbered(_scorpion_bones())
_CENTAUR_NUMBERED = _numbered(_centaur_bones())
_KANGAROO_NUMBERED = _numbered(_kangaroo_bones())


# ---------------------------------------------------------------------------------------
# Building


def build(
    scene: Any,
    name: str,
    bones: Sequence[Spec],
    *,
    plus_y: float = 0.0,
    rotation: Sequence[float] = (0.0, 0.0, 0.0),
    connect: bool = True,
    turn: Sequence[float] = (0.0, 0.0, 0.0),
    scale: float = 1.0,
    deform: Callable[[str], bool] | None = None,
) -> Any:
    """An armature of ``bones`` (creature space) with a capsule skin, standing on z = 0.

    ``rotation``: the object's Euler rotation; the bones are placed so that the rig still
    stands in the world; ``turn`` then turns the object (and the rig with it).
    ``plus_y > 0``: every bone points along its own armature +Y with that length, as glTF/FBX
    importers leave them (the tails mean nothing). ``scale``: the object's uniform scale, the
    bones made larger by its inverse (an FBX in centimetres: 0.01). Helper bones
    (:data:`HELPERS`: roots, IK targets, end markers) deform nothing and have no skin;
    ``deform``: which bones deform (and have skin) instead, on a control rig.
    """
    data = bpy.data.armatures.new(name)
    arm = bpy.data.objects.new(name, data)
    scene.collection.objects.link(arm)
    arm.rotation_euler = tuple(rotation)
    arm.scale = (scale, scale, scale)
    inv = Matrix.LocRotScale(None, arm.rotation_euler, (scale, scale, scale)).inverted().to_3x3()
    plus_y /= scale
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    eb = data.edit_bones
    for n, _p, h, t in bones:
        b = eb.new(n)
        b.head = inv @ Vector(h)
        b.tail = b.head + Vector((0.0, plus_y, 0.0)) if plus_y > 0.0 else inv @ Vector(t)
    for n, p, _h, _t in bones:
        if p is not None:
            eb[n].parent = eb[p]
            if connect and plus_y == 0.0 and (Vector(eb[p].tail) - Vector(eb[n].head)).length < 1e-6:
                eb[n].use_connect = True
    bpy.ops.object.mode_set(mode="OBJECT")
    deforms = deform or (lambda n: not HELPERS.search(n))
    for b in data.bones:
        b.use_deform = deforms(b.name)
    _skin(arm, [spec for spec in bones if deforms(spec[0])], np.array(inv), scene)
    if any(turn):
        arm.rotation_euler = tuple(turn)
    bpy.context.view_layer.update()
    return arm


#: Bones that deform nothing in the rigs they stand for: roots, IK targets and poles, end
#: markers, Biped's footsteps, MMD's root and leg IK bones.
HELPERS = re.compile(
    r"(^root$|Root|^ik_|^CTRL_|_ctrl\.|^pole|Footsteps|^Bip01$|interaction|center_of_mass|"
    r"_End$|Nub$|全ての親|ＩＫ|IK親)"
)


def _skin(arm: Any, bones: Sequence[Spec], to_armature: np.ndarray, scene: Any) -> Any:
    """A capsule around each bone's real segment (head to tail in creature space, whatever
    the bone's own tail), rigidly weighted to it and deformed by ``arm``: the skin shows where
    the creature is, as an asset's mesh does."""
    verts_all, faces_all, groups = [], [], []
    offset = 0
    for n, _p, h, t in bones:
        d = Vector(t) - Vector(h)
        if d.length < 1e-9:
            continue
        verts, faces = creatures._capsule(d.length, 0.012, 0.008, n_around=6)
        turn = np.array(Vector((0.0, 1.0, 0.0)).rotation_difference(d.normalized()).to_matrix())
        world = verts @ turn.T + np.array(h)
        verts_all.append(world @ to_armature.T)
        faces_all += [tuple(i + offset for i in f) for f in faces]
        groups.append((n, range(offset, offset + len(verts))))
        offset += len(verts)
    mesh = bpy.data.meshes.new(f"{arm.name}_Skin")
    mesh.from_pydata(np.concatenate(verts_all).tolist(), [], faces_all)
    mesh.update()
    skin = bpy.data.objects.new(f"{arm.name}_Skin", mesh)
    scene.collection.objects.link(skin)
    skin.parent = arm
    for name, idx in groups:
        skin.vertex_groups.new(name=name).add(list(idx), 1.0, "REPLACE")
    modifier = skin.modifiers.new("Armature", "ARMATURE")
    modifier.object = arm
    return skin


def _horse(scene: Any, name: str, turn: Sequence[float] = (0.0, 0.0, 0.0), swap: bool = False) -> Any:
    return build(scene, name, _horse_bones(swap), turn=turn)


def _metarig(kind: str) -> Callable[[Any, str], Any]:
    """A builder of Rigify's ``kind`` metarig (Blender's own, added by its operator)."""

    def build_metarig(scene: Any, name: str) -> Any:
        import addon_utils

        if not addon_utils.check("rigify")[1]:
            addon_utils.enable("rigify", default_set=True)
        getattr(bpy.ops.object, f"armature_{kind}_metarig_add")()
        arm = bpy.context.view_layer.objects.active
        arm.name = name
        return arm

    return build_metarig


#: Generated Rigify rigs saved once per process (kind -> .blend), appended from there after.
_GENERATED: dict[str, str] = {}


def _generated(kind: str) -> Callable[[Any, str], Any]:
    """A builder of the rig Rigify generates from its ``kind`` metarig (``rigify_generate``,
    a few seconds; once per process, then appended from a saved copy), named as asked."""

    def build_generated(scene: Any, name: str) -> Any:
        if kind not in _GENERATED:
            metarig = _metarig(kind)(scene, "metarig")
            bpy.ops.pose.rigify_generate()
            rig = metarig.data.rigify_target_rig
            bpy.data.objects.remove(metarig)
            rig.name = "rig"
            path = f"{tempfile.mkdtemp(prefix='procloco_rigify_')}/{kind}.blend"
            bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
            _GENERATED[kind] = path
        else:
            with bpy.data.libraries.load(_GENERATED[kind], link=False) as (_src, dst):
                dst.objects = ["rig"]
            rig = dst.objects[0]
            scene.collection.objects.link(rig)
        rig.name = name
        bpy.context.view_layer.objects.active = rig
        bpy.context.view_layer.update()
        return rig

    return build_generated


def _pair(hip: str, end: str, hind_hip: str = "", hind_end: str = "") -> Expected:
    legs = {"L1": (f"{hip}.L", f"{end}.L"), "R1": (f"{hip}.R", f"{end}.R")}
    if hind_hip:
        legs |= {"L2": (f"{hind_hip}.L", f"{hind_end}.L"), "R2": (f"{hind_hip}.R", f"{hind_end}.R")}
    return Expected(legs)


def _pair_lower(hip: str, end: str) -> Expected:
    """:func:`_pair` with Auto-Rig Pro's lower-case sides (``.l``/``.r``)."""
    return Expected({"L1": (f"{hip}.l", f"{end}.l"), "R1": (f"{hip}.r", f"{end}.r")})


HUMAN_LEGS = {"L1": ("thigh", "shin"), "R1": ("thigh", "shin")}


def _human_expected(names: dict[str, str], rename: Callable[[str], str]) -> Expected:
    return Expected(
        {"L1": (names["thigh"], names["shin"]), "R1": (rename(names["thigh"]), rename(names["shin"]))}
    )


@dataclass(frozen=True)
class Fixture:
    build: Callable[[Any, str], Any]
    expected: Expected
    round_trip: bool = True  # exported and imported through glTF and FBX in the tests


_HORSE_LEGS = Expected(
    {
        "L1": ("scapula.L", "pastern.L"),
        "R1": ("scapula.R", "pastern.R"),
        "L2": ("femur.L", "hind_pastern.L"),
        "R2": ("femur.R", "hind_pastern.R"),
    }
)

FIXTURES: dict[str, Fixture] = {
    "mixamo_t": Fixture(
        lambda sc, n: build(sc, n, _humanoid(MIXAMO, _swap("Left", "Right"))),
        _human_expected(MIXAMO, _swap("Left", "Right")),
    ),
    "mixamo_a": Fixture(
        lambda sc, n: build(sc, n, _humanoid(MIXAMO, _swap("Left", "Right"), pose="A")),
        _human_expected(MIXAMO, _swap("Left", "Right")),
    ),
    "unreal": Fixture(
        lambda sc, n: build(sc, n, _unreal_bones()), _human_expected(UNREAL, _swap("_l", "_r"))
    ),
    "cc": Fixture(
        lambda sc, n: build(sc, n, _humanoid(CC, _swap("_L_", "_R_"), pose="A", root="CC_Base_BoneRoot")),
        _human_expected(CC, _swap("_L_", "_R_")),
    ),
    "biped": Fixture(
        lambda sc, n: build(sc, n, _humanoid(BIPED, _swap(" L ", " R "), root="Bip01")),
        _human_expected(BIPED, _swap(" L ", " R ")),
    ),
    "gltf_quadruped": Fixture(
        lambda sc, n: build(sc, n, _gltf_quadruped_bones(), plus_y=0.05, rotation=(math.pi / 2, 0.0, 0.0)),
        Expected(
            {
                "L1": ("b_LeftUpperArm_09", "b_LeftHand_011"),
                "R1": ("b_RightUpperArm_09", "b_RightHand_011"),
                "L2": ("b_LeftLeg01_015", "b_LeftFoot01_017"),
                "R2": ("b_RightLeg01_015", "b_RightFoot01_017"),
            }
        ),
    ),
    "spider8": Fixture(
        lambda sc, n: build(sc, n, _spider_bones()),
        Expected({f"{s}{k}": (f"Leg{k}Base.{s}", f"Leg{k}Fore.{s}") for k in range(1, 5) for s in "LR"}),
    ),
    "root_legs": Fixture(
        lambda sc, n: build(sc, n, _root_legs_bones()),
        Expected(
            {
                "L1": ("FrontLeftLeg", "FrontLeftShin"),
                "R1": ("FrontRightLeg", "FrontRightShin"),
                "L2": ("BackLeftLeg", "BackLeftShin"),
                "R2": ("BackRightLeg", "BackRightShin"),
            }
        ),
    ),
    "horse": Fixture(lambda sc, n: _horse(sc, n), _HORSE_LEGS),
    "swapped": Fixture(
        lambda sc, n: _horse(sc, n, swap=True),
        Expected(
            {
                "L1": ("scapula.R", "pastern.R"),
                "R1": ("scapula.L", "pastern.L"),
                "L2": ("femur.R", "hind_pastern.R"),
                "R2": ("femur.L", "hind_pastern.L"),
            }
        ),
    ),
    "rigify_horse": Fixture(_metarig("horse"), _pair("shoulder", "f_toe", "thigh", "r_toe"), False),
    "rigify_bird": Fixture(_metarig("bird"), _pair("thigh", "shin"), False),
    "rigify_basic_human": Fixture(_metarig("basic_human"), _pair("thigh", "shin"), False),
    # Rigs as their tools make them (the hierarchies of the tools, the skin only on deform bones)
    "mixamo_fbx": Fixture(
        lambda sc, n: build(
            sc, n, _mixamo_full_bones(), plus_y=0.05, rotation=(math.pi / 2, 0.0, 0.0), scale=0.01
        ),
        _human_expected(MIXAMO, _swap("Left", "Right")),
    ),
    "ue5_manny": Fixture(
        lambda sc, n: build(sc, n, _ue5_bones()),
        Expected({"L1": ("thigh_l", "calf_l"), "R1": ("thigh_r", "calf_r")}),
    ),
    "cc4": Fixture(
        lambda sc, n: build(sc, n, _cc4_bones()),
        Expected({"L1": ("CC_Base_L_Thigh", "CC_Base_L_Calf"), "R1": ("CC_Base_R_Thigh", "CC_Base_R_Calf")}),
    ),
    "max_biped": Fixture(
        lambda sc, n: build(sc, n, _max_biped_bones(), connect=False),
        _human_expected(BIPED, _swap(" L ", " R ")),
    ),
    "genesis8": Fixture(
        lambda sc, n: build(sc, n, _genesis8_bones()),
        Expected({"L1": ("lThighBend", "lShin"), "R1": ("rThighBend", "rShin")}),
    ),
    "mmd": Fixture(_mmd, Expected({"L1": ("左足", "左ひざ"), "R1": ("右足", "右ひざ")}), False),
    "mmd_ik_parent": Fixture(
        lambda sc, n: _mmd(sc, n, ik_parent=True),
        Expected({"L1": ("左足", "左ひざ"), "R1": ("右足", "右ひざ")}),
        False,
    ),
    "ik_quadruped": Fixture(
        lambda sc, n: build(sc, n, _ik_quadruped_bones()),
        Expected(
            {
                "L1": ("upperarm.L", "paw.L"),
                "R1": ("upperarm.R", "paw.R"),
                "L2": ("thigh.L", "shin.L"),
                "R2": ("thigh.R", "shin.R"),
            }
        ),
    ),
    "dragon": Fixture(lambda sc, n: build(sc, n, _dragon_bones()), Expected(_DRAGON_LEGS)),
    "dragon_numbered": Fixture(
        lambda sc, n: build(sc, n, _DRAGON_NUMBERED[0]),
        Expected({k: (_DRAGON_NUMBERED[1][h], _DRAGON_NUMBERED[1][e]) for k, (h, e) in _DRAGON_LEGS.items()}),
    ),
    "arp_rig": Fixture(_arp_rig, _pair_lower("thigh_twist", "leg_twist"), False),
    "arp_export": Fixture(_arp_export, _pair_lower("thigh_twist", "leg_twist")),
    "arp_dog": Fixture(
        lambda sc, n: build(sc, n, _arp_dog_bones(), deform=lambda _n: True),
        Expected({f"{s.upper()}{k}": (f"c_thigh_b{d}.{s}", f"leg_twist{d}.{s}")
                  for k, d in (("1", "_dupli_001"), ("2", "")) for s in "lr"}),
    ),
    "generated_wolf": Fixture(
        _generated("wolf"), _pair("ORG-front_thigh", "ORG-front_foot", "ORG-thigh", "ORG-foot"), False
    ),
    "generated_horse": Fixture(
        _generated("horse"), _pair("ORG-upper_arm", "ORG-f_toe", "ORG-thigh", "ORG-r_toe"), False
    ),
    "generated_cat": Fixture(
        _generated("cat"), _pair("ORG-upper_arm", "ORG-hand", "ORG-thigh", "ORG-foot"), False
    ),
    "generated_quadruped": Fixture(
        _generated("basic_quadruped"),
        _pair("ORG-front_thigh", "ORG-front_foot", "ORG-thigh", "ORG-foot"),
        False,
    ),
    "generated_human": Fixture(_generated("human"), _pair("ORG-thigh", "ORG-shin"), False),
    "generated_bird": Fixture(_generated("bird"), _pair("ORG-thigh", "ORG-shin"), False),
    "horse_in_holder": Fixture(_in_holder, _HORSE_LEGS),
    "copy_rotation_controls": Fixture(_copy_rotation_controls, _HORSE_LEGS, False),
    "horse_numbered": Fixture(
        lambda sc, n: build(sc, n, _HORSE_NUMBERED[0]),
        Expected({k: (_HORSE_NUMBERED[1][h], _HORSE_NUMBERED[1][e])
                  for k, (h, e) in _HORSE_LEGS.legs.items()}),
    ),
    "beetle_gltf": Fixture(
        lambda sc, n: build(sc, n, _beetle_bones(), plus_y=0.02),
        Expected(
            {
                "L1": ("joint_2", "joint_4"),
                "R1": ("joint_11", "joint_13"),
                "L2": ("joint_5", "joint_7"),
                "R2": ("joint_14", "joint_16"),
                "L3": ("joint_8", "joint_10"),
                "R3": ("joint_17", "joint_19"),
            }
        ),
    ),
    "vroid": Fixture(
        lambda sc, n: build(sc, n, _vroid_bones()),
        Expected({f"{s}1": (f"J_Bip_{s}_UpperLeg", f"J_Bip_{s}_LowerLeg") for s in "LR"}),
    ),
    "makehuman": Fixture(
        lambda sc, n: build(sc, n, _makehuman_bones()),
        Expected({"L1": ("upperleg01.L", "lowerleg02.L"), "R1": ("upperleg01.R", "lowerleg02.R")}),
    ),
    "genesis9": Fixture(
        lambda sc, n: build(sc, n, _genesis9_bones()),
        Expected({"L1": ("l_thigh", "l_shin"), "R1": ("r_thigh", "r_shin")}),
    ),
    "dog_numbered": Fixture(
        lambda sc, n: build(sc, n, _DOG_NUMBERED[0]),
        Expected({k: (_DOG_NUMBERED[1][h], _DOG_NUMBERED[1][e])
                  for k, (h, e) in _pair("upperarm", "hand", "thigh", "foot").legs.items()}),
    ),
    "bug_gltf": Fixture(
        lambda sc, n: build(sc, n, _BUG_NUMBERED[0], plus_y=0.01),
        Expected({f"{s}{k}": (_BUG_NUMBERED[1][f"coxa{k}.{s}"], _BUG_NUMBERED[1][f"tibia{k}.{s}"])
                  for k in (1, 2, 3) for s in "LR"}),
    ),
    # Game creatures whose other limbs are the classic traps (round 6)
    "scorpion": Fixture(lambda sc, n: build(sc, n, _scorpion_bones()), Expected(_SCORPION_LEGS)),
    "scorpion_numbered": Fixture(
        lambda sc, n: build(sc, n, _SCORPION_NUMBERED[0], deform=lambda b: b != "Bone"),  # the root: no skin
        Expected({k: (_SCORPION_NUMBERED[1][h], _SCORPION_NUMBERED[1][e])
                  for k, (h, e) in _SCORPION_LEGS.items()}),
        False,
    ),
    "raptor": Fixture(
        lambda sc, n: build(sc, n, _raptor_bones()),
        Expected({"L1": ("thigh_l", "foot_l"), "R1": ("thigh_r", "foot_r")}),
        False,
    ),
    "centaur": Fixture(lambda sc, n: build(sc, n, _centaur_bones()), Expected(_CENTAUR_LEGS)),
    "centaur_numbered": Fixture(
        lambda sc, n: build(sc, n, _CENTAUR_NUMBERED[0]),
        Expected({k: (_CENTAUR_NUMBERED[1][h], _CENTAUR_NUMBERED[1][e])
                  for k, (h, e) in _CENTAUR_LEGS.items()}),
        False,
    ),
    "mantis": Fixture(
        lambda sc, n: build(sc, n, _mantis_bones()),
        Expected({f"{s}{k - 1}": (f"Leg{k}_Coxa.{s}", f"Leg{k}_Tibia.{s}") for k in (2, 3) for s in "LR"}),
        False,
    ),
    "crab": Fixture(
        lambda sc, n: build(sc, n, _crab_bones()),
        Expected({f"{s}{k}": (f"leg{k}_upper.{s}", f"leg{k}_lower.{s}") for k in range(1, 5) for s in "LR"}),
        False,
    ),
    "centipede": Fixture(
        lambda sc, n: build(sc, n, _centipede_bones()),
        Expected({f"{s}{k}": (f"Segment{k:02d}_Leg.{s}", f"Segment{k:02d}_Foot.{s}")
                  for k in range(1, _CENTIPEDE_SEGMENTS + 1) for s in "LR"}),
        False,
    ),
    "kangaroo": Fixture(lambda sc, n: build(sc, n, _kangaroo_bones()), _pair("thigh", "shin")),
    "kangaroo_numbered": Fixture(
        lambda sc, n: build(sc, n, _KANGAROO_NUMBERED[0]),
        Expected({k: (_KANGAROO_NUMBERED[1][h], _KANGAROO_NUMBERED[1][e])
                  for k, (h, e) in _pair("thigh", "shin").legs.items()}),
        False,
    ),
    "snake": Fixture(
        lambda sc, n: build(sc, n, _snake_bones()),
        Expected(refusal="no chain of bones from the body reaches the ground"),
        False,
    ),
    "mirrored": Fixture(
        _mirrored, Expected(refusal="has a non-uniform or mirrored scale: apply its scale first"), False
    ),
    "shark": Fixture(
        _metarig("shark"), Expected(refusal="no chain of bones from the body reaches the ground"), False
    ),
    "on_side": Fixture(
        lambda sc, n: _horse(sc, n, turn=(0.0, math.pi / 2, 0.0)),
        Expected(refusal="the rig's up axis is world +X (it lies on its side"),
        False,
    ),
    "upside_down": Fixture(
        lambda sc, n: _horse(sc, n, turn=(0.0, math.pi, 0.0)),
        Expected(refusal="the rig's up axis is world -Z (it lies upside down"),
        False,
    ),
}
