# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/rig/detect.py on plain arrays (no bpy): legs are found by what they are.

Random limb trees: a spine of one to three bones, mirrored pairs of legs of two to four
bones hanging from its bones down to the ground, limbs that do not reach the ground (arms,
antennae, a raised tail), random proportions, a random turn, scale and place of the object,
and tails that either meet the next bone or point anywhere (as importers leave them). Every
chain reaching the ground is found, whole, and none that does not.
"""

from __future__ import annotations

import itertools
import re
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.blender.rig.detect import _ground_chains, find_legs, forward_of
from procloco_addon.blender.rig.names import split_joints, split_name
from procloco_addon.blender.rig.rest import RigError, _Rest, joint_ends, with_leaf_ends


def _rest(
    names: list[str], parent: list[int], head: np.ndarray, tail: np.ndarray, world: np.ndarray | None = None
) -> _Rest:
    world = np.eye(4) if world is None else world
    scale = float(np.linalg.norm(world[:3, 0]))
    n = len(names)
    local = np.repeat(np.eye(4)[None], n, axis=0)
    return _Rest(
        tuple(names),
        {nm: i for i, nm in enumerate(names)},
        np.array(parent, dtype=np.int64),
        head @ world[:3, :3].T + world[:3, 3],
        tail @ world[:3, :3].T + world[:3, 3],
        local,
        world,
        scale,
    )


class Tree:
    """A random creature: bones as parallel lists, and the leg chains it was built with."""

    def __init__(self) -> None:
        self.names: list[str] = []
        self.parent: list[int] = []
        self.head: list[np.ndarray] = []
        self.tail: list[np.ndarray] = []
        self.legs: list[list[str]] = []

    def __repr__(self) -> str:
        return (
            f"Tree(parent={self.parent}, head={np.round(np.array(self.head), 4).tolist()}, "
            f"tail={np.round(np.array(self.tail), 4).tolist()}, legs={self.legs})"
        )

    def add(self, parent: int, head: np.ndarray, tail: np.ndarray) -> int:
        self.names.append(f"Bone{len(self.names):03d}")
        self.parent.append(parent)
        self.head.append(np.asarray(head, dtype=np.float64))
        self.tail.append(np.asarray(tail, dtype=np.float64))
        return len(self.names) - 1

    def chain(self, parent: int, points: np.ndarray) -> list[int]:
        out = []
        for a, b in itertools.pairwise(points):
            parent = self.add(parent, a, b)
            out.append(parent)
        return out


@st.composite
def creatures(
    draw: st.DrawFn,
    knees_up: float = 1.3,
    reach: float = 0.4,
    sprawl: float = 0.6,
) -> tuple[Tree, np.ndarray, bool]:
    """A random limb tree standing on z = 0, its object matrix, and whether tails mean anything.
    ``knees_up``: how high the legs' inner joints may be, ``sprawl``: how far out each leg
    bone goes, ``reach``: how far sideways each bone of the other limbs goes, in body heights."""
    tree = Tree()
    height = draw(st.floats(0.3, 2.0))
    n_pairs = draw(st.integers(1, 4))
    # each pair: bones, hip width, joints outward and down (inner ones 0.2 to ``knees_up`` body heights up)
    shapes = []
    for _ in range(n_pairs):
        k = draw(st.integers(2, 4))
        width = draw(st.floats(0.05, 0.5)) * height
        out = np.cumsum([width] + [draw(st.floats(0.0, sprawl)) * height for _ in range(k)])
        fwd = [0.0] + [draw(st.floats(-0.2, 0.2)) * height for _ in range(k)]
        z = [height] + [draw(st.floats(0.2, knees_up)) * height for _ in range(k - 1)] + [0.0]
        shapes.append(np.column_stack([out, fwd, z]))
    longest = max(float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in shapes)
    # pairs a fifth of the longest leg apart at least: distinct legs, not copies of one
    length = max(draw(st.floats(0.3, 1.5)) * height, 0.2 * (n_pairs + 1) * longest)
    n_spine = draw(st.integers(1, 3))
    y = np.linspace(0.5 * length, -0.5 * length, n_spine + 1)
    spine = tree.chain(-1, np.array([[0.0, yy, height] for yy in y]))
    for p, pts in enumerate(shapes):
        y0 = 0.5 * length - (p + 1) * length / (n_pairs + 1)
        carrier = spine[min(int((0.5 * length - y0) / length * n_spine), n_spine - 1)]
        placed = pts + np.array([0.0, y0, 0.0])
        for side in (1.0, -1.0):
            mirrored = placed * np.array([side, 1.0, 1.0])
            tree.legs.append([tree.names[i] for i in tree.chain(carrier, mirrored)])
    # limbs that do not reach the ground: at least 0.6 body heights up everywhere
    for _ in range(draw(st.integers(0, 3))):
        carrier = spine[draw(st.integers(0, n_spine - 1))]
        k = draw(st.integers(1, 4))
        start = tree.head[carrier]
        steps = [
            np.array([draw(st.floats(-reach, reach)), draw(st.floats(-0.4, 0.4)), draw(st.floats(-0.1, 0.3))])
            * height
            for _ in range(k)
        ]
        pts = np.vstack([start, start + np.cumsum(steps, axis=0)])
        pts[:, 2] = np.maximum(pts[:, 2], 0.6 * height)
        tree.chain(carrier, pts)
    yaw = draw(st.floats(-np.pi, np.pi))
    scale = draw(st.floats(0.01, 100.0))
    world = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    world[:3, :3] = scale * np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    world[:3, 3] = [draw(st.floats(-5, 5)), draw(st.floats(-5, 5)), draw(st.floats(-5, 5))]
    return tree, world, draw(st.booleans())


def _arrays(tree: Tree, meaningful: bool, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    head = np.array(tree.head)
    tail = np.array(tree.tail)
    if not meaningful:
        # every bone along a random direction of a fixed length: only heads are joints, and
        # each leg's tip is the head of an end bone (as glTF files carry them)
        tail = head + 0.05 * rng.normal(size=head.shape)
    return head, tail


@given(creatures(), st.integers(0, 2**32 - 1))
def test_every_chain_reaching_the_ground_is_found_and_none_other(
    case: tuple[Tree, np.ndarray, bool], seed: int
) -> None:
    tree, world, meaningful = case
    rng = np.random.default_rng(seed)
    if not meaningful:
        for leg in tree.legs:  # the tip as a bone of its own
            last = tree.names.index(leg[-1])
            end = tree.add(last, tree.tail[last], tree.tail[last])
            leg.append(tree.names[end])
    head, tail = _arrays(tree, meaningful, rng)
    rest = _rest(tree.names, tree.parent, head, tail, world)
    legs = find_legs(rest, np.zeros(len(tree.names), dtype=bool), "creature")
    found = sorted([*leg.bones, *leg.foot] for leg in legs)
    assert found == sorted(tree.legs)
    assert all("reaches the ground" in leg.reason for leg in legs)
    # mirrored pairs get one row each, left and right by where the hips are
    forward, _source = forward_of(rest, legs)
    left = np.cross([0.0, 0.0, 1.0], forward)
    centre = np.mean([rest.head[rest.index[leg.hip]] for leg in legs], axis=0)
    for leg in legs:
        lateral = float((rest.head[rest.index[leg.hip]] - centre) @ left)
        assert np.sign(lateral) == leg.side, (leg, lateral)


# Legs below the body, not sprawling far, other limbs close to the midline: with knees far
# above the body a rig upside down still has chains hanging from it to its lowest points, and
# on its side a sprawling leg or an arm reaching out as far as the legs hangs down too.
@given(creatures(knees_up=0.9, reach=0.05, sprawl=0.25), st.sampled_from(["side", "upside down"]))
def test_a_rig_lying_down_is_refused_naming_its_up_axis(
    case: tuple[Tree, np.ndarray, bool], how: str
) -> None:
    tree, world, _meaningful = case
    turn = np.eye(4)
    if how == "side":
        turn[:3, :3] = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]  # 90 degrees about Y
    else:
        turn[:3, :3] = np.diag([-1.0, 1.0, -1.0])  # 180 degrees about Y
    rest = _rest(tree.names, tree.parent, np.array(tree.head), np.array(tree.tail), turn @ world)
    axis = "+X" if how == "side" else "-Z"
    with pytest.raises(RigError, match=re.escape(f"the rig's up axis is world {axis}")):
        find_legs(rest, np.zeros(len(tree.names), dtype=bool), "creature")


def test_joint_ends_follow_children_when_tails_point_anywhere() -> None:
    parent = np.array([-1, 0, 1])
    head = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.5], [0.0, 0.1, 0.0]])
    tails_ok = np.array([[0.0, 0.0, 0.5], [0.0, 0.1, 0.0], [0.0, 0.3, 0.0]])
    end, meaningful = joint_ends(parent, head, tails_ok)
    assert meaningful
    np.testing.assert_array_equal(end, tails_ok)
    plus_y = head + np.array([0.0, 0.05, 0.0])
    end, meaningful = joint_ends(parent, head, plus_y)
    assert not meaningful
    np.testing.assert_array_equal(end, [head[1], head[2], head[2]])  # the leaf's extent is unknown


def test_a_leaf_takes_its_far_end_from_the_skin_when_its_tail_is_a_guess() -> None:
    names = ["body", "thigh", "shin", "foot"]
    parent = [-1, 0, 1, 2]
    head = np.array([[0.0, 0.2, 1.0], [0.1, 0.0, 1.0], [0.1, 0.0, 0.5], [0.1, 0.0, 0.1]])
    tail = np.array([head[1], head[2], head[3], [0.1, 0.0, -0.3]])  # the foot continues the shin: a guess
    rest = _rest(names, parent, head, tail)
    skin = {3: np.array([[0.1, 0.0, 0.1], [0.1, -0.1, 0.02], [0.1, -0.2, 0.0]])}
    np.testing.assert_allclose(with_leaf_ends(rest, skin).end[3], [0.1, -0.2, 0.0])
    # a skin around the bone's own tail keeps the tail
    tail[3] = [0.1, -0.2, 0.0]
    rest = _rest(names, parent, head, tail)
    np.testing.assert_allclose(with_leaf_ends(rest, skin).end[3], tail[3])


@pytest.mark.parametrize(
    ("name", "side", "tokens"),
    [
        ("mixamorig:LeftUpLeg", 1, ("up", "leg")),
        ("thigh_l", 1, ("thigh",)),
        ("CC_Base_L_Thigh", 1, ("thigh",)),
        ("Bip01 R Calf", -1, ("calf",)),
        ("thigh_ref.l", 1, ("thigh", "ref")),
        ("b_LeftLeg01_015", 1, ("leg", "01", "015")),
        ("Leg1Base.L", 1, ("leg", "1", "base")),
        ("FrontLeftLeg", 1, ("front", "leg")),
        ("BackRightToe", -1, ("back", "toe")),
        ("lThighTwist", 1, ("thigh", "twist")),
        ("CTRL_foot.L", 1, ("ctrl", "foot")),
    ],
)
def test_names_of_the_tools_animators_get_rigs_from(name: str, side: int, tokens: tuple[str, ...]) -> None:
    assert split_name(name) == (side, tokens)


def test_jaws_and_antennae_reaching_the_ground_are_not_legs() -> None:
    tree = Tree()
    body = tree.add(-1, [0.0, 0.2, 0.3], [0.0, -0.2, 0.3])
    for side in (1.0, -1.0):
        for y in (-0.1, 0.1):
            tree.legs.append(
                [
                    tree.names[i]
                    for i in tree.chain(
                        body, np.array([[0.1 * side, y, 0.3], [0.3 * side, y, 0.4], [0.5 * side, y, 0.0]])
                    )
                ]
            )
    jaw = tree.chain(body, np.array([[0.02, -0.2, 0.3], [0.05, -0.3, 0.1], [0.05, -0.35, 0.0]]))
    names = list(tree.names)
    names[jaw[0]], names[jaw[1]] = "JawBase.L", "Pincer.L"
    rest = _rest(names, tree.parent, np.array(tree.head), np.array(tree.tail))
    assert len(_ground_chains(rest)) == 4
    legs = find_legs(rest, np.zeros(len(names), dtype=bool), "spider")
    assert sorted([*leg.bones, *leg.foot] for leg in legs) == sorted(tree.legs)


def _biped(tree: Tree, thigh: int = 1) -> int:
    """A biped's pelvis, spine and two legs (``thigh`` bones from hip to knee) into ``tree``;
    its legs are appended to ``tree.legs``. Returns the pelvis."""
    pelvis = tree.add(-1, [0.0, 0.0, 1.0], [0.0, 0.0, 0.9])
    tree.chain(pelvis, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.3], [0.0, 0.0, 1.7]]))
    for side in (1.0, -1.0):
        hip, knee = np.array([0.1 * side, 0.0, 0.95]), np.array([0.1 * side, -0.02, 0.52])
        upper = [hip + (knee - hip) * k / thigh for k in range(thigh + 1)]
        pts = np.array([*upper, [0.1 * side, 0.03, 0.08], [0.1 * side, -0.12, 0.0]])
        tree.legs.append([tree.names[i] for i in tree.chain(pelvis, pts)])
    return pelvis


def test_a_thigh_in_two_bones_named_bend_and_twist_is_one_leg() -> None:
    # Genesis 8: lThighBend > lThighTwist > lShin; "twist" names a helper elsewhere (UE's
    # thigh_twist_01_l, a leaf beside the thigh), here the thigh's lower half.
    tree = Tree()
    _biped(tree, thigh=2)
    names = list(tree.names)
    for leg, prefix in zip(tree.legs, "lr", strict=True):
        for k, part in enumerate(("ThighBend", "ThighTwist", "Shin", "Foot")):
            names[names.index(leg[k])] = prefix + part
    rest = _rest(names, tree.parent, np.array(tree.head), np.array(tree.tail))
    legs = find_legs(rest, np.zeros(len(names), dtype=bool), "genesis")
    assert sorted((*leg.bones, *leg.foot) for leg in legs) == [
        ("lThighBend", "lThighTwist", "lShin", "lFoot"), ("rThighBend", "rThighTwist", "rShin", "rFoot")]


@pytest.mark.parametrize("named", [False, True])
def test_foot_controls_hanging_from_the_root_are_not_legs(named: bool) -> None:
    # An IK bone at each ankle with its toe bone (MMD's leg IK, a reverse foot) hangs from
    # the root beside the legs and reaches the ground: a chain low beside the legs' hips.
    tree = Tree()
    root = tree.add(-1, [0.0, 0.0, 0.0], [0.0, 0.0, 0.1])
    pelvis = _biped(tree)
    tree.parent[pelvis] = root
    controls = [tree.chain(root, np.array([[0.1 * side, 0.03, 0.08], [0.1 * side, -0.12, 0.0],
                                           [0.1 * side, -0.12, -0.05]])) for side in (1.0, -1.0)]
    names = list(tree.names)
    if named:
        for c, side in zip(controls, "LR", strict=True):
            names[c[0]], names[c[1]] = f"CTRL_foot.{side}", f"CTRL_toe.{side}"
    rest = _rest(names, tree.parent, np.array(tree.head), np.array(tree.tail))
    legs = find_legs(rest, np.zeros(len(names), dtype=bool), "biped")
    assert sorted([*leg.bones, *leg.foot] for leg in legs) == sorted(tree.legs)


def _standing_quadruped(tree: Tree) -> list[int]:
    """A quadruped of four three-bone legs 1 m high into ``tree`` (its legs appended to
    ``tree.legs``); returns its spine, back to front."""
    spine = tree.chain(-1, np.array([[0.0, 0.5, 1.0], [0.0, 0.0, 1.0], [0.0, -0.5, 1.0]]))
    for carrier, y in ((spine[1], -0.45), (spine[0], 0.45)):
        for side in (1.0, -1.0):
            pts = np.array([[0.15 * side, y, 0.95], [0.2 * side, y + 0.1, 0.5], [0.2 * side, y - 0.05, 0.05],
                            [0.2 * side, y - 0.15, 0.0]])
            tree.legs.append([tree.names[i] for i in tree.chain(carrier, pts)])
    return spine


@pytest.mark.parametrize("tail_bones", [2, 6])
def test_a_tail_lying_on_the_ground_is_not_a_leg(tail_bones: int) -> None:
    # No names to say so: a quadruped whose tail (long, or of many bones) ends on the ground
    # behind it; a leg on the midline ahead, as long as the others, stays a leg.
    tree = Tree()
    spine = _standing_quadruped(tree)
    front = tree.chain(spine[1], np.array([[0.0, -0.5, 1.0], [0.0, -0.7, 0.55], [0.0, -0.75, 0.05],
                                           [0.0, -0.85, 0.0]]))
    tree.legs.append([tree.names[i] for i in front])
    y = np.linspace(0.5, 2.6 if tail_bones > 2 else 2.2, tail_bones + 1)
    tree.chain(spine[0], np.column_stack([np.zeros_like(y), y, np.maximum(1.0 - 0.6 * (y - 0.5), 0.0)]))
    rest = _rest(tree.names, tree.parent, np.array(tree.head), np.array(tree.tail))
    legs = find_legs(rest, np.zeros(len(tree.names), dtype=bool), "creature")
    assert sorted([*leg.bones, *leg.foot] for leg in legs) == sorted(tree.legs)
    assert sorted(leg.label for leg in legs) == ["L2", "L3", "M1", "R2", "R3"]


def test_a_tail_hanging_short_of_the_ground_is_not_a_leg() -> None:
    # No names: a dog's relaxed tail of three bones hangs from the pelvis behind the hind
    # legs to 8 % of a leg above the floor (shorter than the legs, of fewer bones); a leg
    # on the midline ahead, standing on the ground, stays a leg.
    tree = Tree()
    spine = _standing_quadruped(tree)
    front = tree.chain(spine[1], np.array([[0.0, -0.5, 1.0], [0.0, -0.7, 0.55], [0.0, -0.75, 0.05],
                                           [0.0, -0.85, 0.0]]))
    tree.legs.append([tree.names[i] for i in front])
    tree.chain(spine[0], np.array([[0.0, 0.5, 1.0], [0.0, 0.7, 0.75], [0.0, 0.85, 0.4], [0.0, 0.9, 0.08]]))
    rest = _rest(tree.names, tree.parent, np.array(tree.head), np.array(tree.tail))
    legs = find_legs(rest, np.zeros(len(tree.names), dtype=bool), "dog")
    assert sorted([*leg.bones, *leg.foot] for leg in legs) == sorted(tree.legs)


@pytest.mark.parametrize("names", [False, True])
def test_claws_held_above_the_ground_the_legs_stand_on_are_not_legs(names: bool) -> None:
    # A scorpion's pincer arms, a crab's claws: a mirrored pair of limbs longer than the legs
    # reaching forward and down from the front of the body to 6 % of a leg above the floor
    # (within a quarter of their own length of it), named with leg words (ClawArm, Claw) or
    # not at all. Held at 3 % they would stand on the ground, and be legs.
    tree = Tree()
    spine = _standing_quadruped(tree)
    claws = [tree.chain(spine[1], np.array([[0.1 * side, -0.5, 0.95], [0.4 * side, -0.8, 0.8],
                                            [0.3 * side, -1.2, 0.4], [0.2 * side, -1.5, 0.07]]))
             for side in (1.0, -1.0)]
    labels = list(tree.names)
    if names:
        for claw, side in zip(claws, "LR", strict=True):
            for k, i in enumerate(claw):
                labels[i] = f"{('ClawArm1', 'ClawArm2', 'Claw')[k]}.{side}"
    rest = _rest(labels, tree.parent, np.array(tree.head), np.array(tree.tail))
    legs = find_legs(rest, np.zeros(len(labels), dtype=bool), "scorpion")
    found = sorted([*leg.bones, *leg.foot] for leg in legs)
    assert found == sorted([labels[tree.names.index(b)] for b in leg] for leg in tree.legs)


def test_a_paw_raised_alone_in_the_rest_pose_is_still_a_leg() -> None:
    # A dog modelled with one front paw lifted 10 % of a leg off the floor: its mirror leg
    # stands, and no other limb hangs as high; claws and forelegs hang in pairs.
    tree = Tree()
    _standing_quadruped(tree)
    head = np.array(tree.head)
    tail = np.array(tree.tail)
    raised = [tree.names.index(b) for b in tree.legs[0]]
    head[raised[1:], 2] += np.array([0.05, 0.1])
    tail[raised, 2] += np.array([0.05, 0.1, 0.1])
    rest = _rest(tree.names, tree.parent, head, tail)
    legs = find_legs(rest, np.zeros(len(tree.names), dtype=bool), "dog")
    assert sorted([*leg.bones, *leg.foot] for leg in legs) == sorted(tree.legs)


def test_a_short_steep_last_bone_is_the_foot() -> None:
    # A game horse's hoof: the leg's last bone, 6 % of the leg, pointing 60 degrees down to
    # the floor. It is the leg's foot (keeps its pose), not a segment the IK swings (a
    # centaur's hoof flipped up 93 degrees in a frame at the start of a swing).
    tree = Tree()
    spine = tree.chain(-1, np.array([[0.0, 0.5, 1.3], [0.0, -0.5, 1.3]]))
    for y in (-0.4, 0.4):
        for side in (1.0, -1.0):
            pts = np.array([[0.15 * side, y, 1.25], [0.17 * side, y - 0.08, 0.85],
                            [0.17 * side, y - 0.06, 0.45], [0.17 * side, y - 0.07, 0.1],
                            [0.17 * side, y - 0.12, 0.0]])
            tree.legs.append([tree.names[i] for i in tree.chain(spine[0], pts)])
    rest = _rest(tree.names, tree.parent, np.array(tree.head), np.array(tree.tail))
    legs = find_legs(rest, np.zeros(len(tree.names), dtype=bool), "centaur")
    assert sorted((list(leg.bones), list(leg.foot)) for leg in legs) == sorted(
        (leg[:-1], leg[-1:]) for leg in tree.legs)


def test_a_dress_hanging_from_the_thighs_is_not_legs() -> None:
    # VRoid hangs its skirt chains from each thigh (``J_Sec_L_SkirtFront0_01`` ...), an
    # ankle-long dress to near the floor: the legs are found from the thighs, the skirt is
    # no leg.
    tree = Tree()
    _biped(tree)
    names = list(tree.names)
    for leg, side in zip(tree.legs, "LR", strict=True):
        thigh = names.index(leg[0])
        x = float(tree.head[thigh][0])
        skirt = tree.chain(thigh, np.array([[x, -0.05, 0.95], [x, -0.08, 0.6], [x + 0.05, -0.12, 0.3],
                                            [x + 0.06, -0.14, 0.1]]))
        names += [f"J_Sec_{side}_SkirtFront{k}_01" for k in range(1, 4)]
        assert len(names) == skirt[-1] + 1
    rest = _rest(names, tree.parent, np.array(tree.head), np.array(tree.tail))
    legs = find_legs(rest, np.zeros(len(names), dtype=bool), "vroid")
    assert sorted([*leg.bones, *leg.foot] for leg in legs) == sorted(tree.legs)


@pytest.mark.parametrize(("bones", "halves"), [
    (("upperleg01.L", "upperleg02.L", "lowerleg01.L", "lowerleg02.L"), [1, 3]),  # MakeHuman
    (("DEF-thigh.L", "DEF-thigh.L.001", "DEF-shin.L", "DEF-shin.L.001"), [1, 3]),  # B-Bone split
    (("thigh_twist.l", "thigh_stretch.l", "leg_stretch.l", "leg_twist.l"), [1, 3]),  # Auto-Rig Pro
    (("b_LeftLeg01_015", "b_LeftLeg02_016", "b_LeftFoot01_017"), []),  # a thigh and a shin
    (("joint_2", "joint_3", "joint_4"), []),
    (("Bone.010", "Bone.011", "Bone.012"), []),
    (("Leg1Base.L", "Leg1Mid.L", "Leg1Fore.L"), []),
])
def test_the_halves_of_one_limb_bone_are_told_from_knees(bones: tuple[str, ...], halves: list[int]) -> None:
    assert split_joints(bones) == halves


def test_detection_imports_without_bpy(repo_root: Any) -> None:
    # sys.modules["bpy"] = None makes any "import bpy" fail, as where Blender is absent.
    code = (
        "import sys; sys.modules['bpy'] = None; "
        "import procloco_addon.blender.rig.detect, procloco_addon.blender.rig.pose, "
        "procloco_addon.blender.rig.morphology"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=repo_root)


@given(
    st.integers(0, 2**31 - 1),
    st.integers(4, 400),
    st.floats(-3.0, 3.0),
)
def test_a_foot_skins_sole_is_its_lowest_points_and_its_extremes(seed: int, n: int, turn: float) -> None:
    """sole_points on a random foot skin (a cloud of ``n`` vertices, turned about Z): at most
    SOLE_PROBES points, all of them skin vertices in the sole band; the lowest vertex is one;
    when the band has more points than that, those reaching furthest forward, back, left and
    right are among them; when it has fewer, it is all of them."""
    from procloco_addon.blender.rig.rest import SOLE_BAND, SOLE_PROBES, sole_points

    rng = np.random.default_rng(seed)
    pts = rng.uniform([-0.05, -0.15, 0.0], [0.05, 0.08, 0.1], size=(n, 3))
    c, s = np.cos(turn), np.sin(turn)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pts = pts @ rot.T
    forward = rot @ np.array([0.0, -1.0, 0.0])
    left = rot @ np.array([1.0, 0.0, 0.0])
    end = np.array([0.0, 0.0, 0.09])
    sole = sole_points(pts, end, forward, left)
    z = pts[:, 2]
    band = pts[z <= z.min() + SOLE_BAND * np.ptp(z)]
    assert 1 <= sole.shape[0] <= SOLE_PROBES
    assert np.all(np.isin(sole.view([("", sole.dtype)] * 3), band.view([("", band.dtype)] * 3)))
    assert np.any(np.all(sole == pts[np.argmin(z)], axis=1))
    if band.shape[0] <= SOLE_PROBES:
        assert sole.shape[0] == np.unique(band, axis=0).shape[0]
    rel_b, rel_s = band[:, :2] - end[:2], sole[:, :2] - end[:2]
    for axis in (forward[:2], -forward[:2], left[:2], -left[:2]):
        assert (rel_s @ axis).max() == pytest.approx((rel_b @ axis).max(), abs=1e-15)
