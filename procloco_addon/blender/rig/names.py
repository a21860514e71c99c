# SPDX-License-Identifier: GPL-3.0-or-later
"""Bone names as hints: tokens, sides and the words that mark legs and helper bones."""

from __future__ import annotations

import functools
import re
from collections.abc import Sequence

# Prefixes that say nothing of what a bone is (``CTRL_``/``ctl_`` do: they stay, as words).
_PREFIX = re.compile(r"^(def|org|mch|jnt|jt|bn|bone|b|mixamorig\d*|cc_base|bip\d*)[-_.:\s]+",
                     re.IGNORECASE)
_SIDE_SUFFIX = re.compile(r"[-_.\s](l|r|left|right|lft|rgt)((?:\.\d+)?)$", re.IGNORECASE)
_SIDE_PREFIX = re.compile(r"^(l|r|left|right|lft|rgt)[-_.\s]", re.IGNORECASE)
_SIDE_CAMEL = re.compile(r"^(Left|Right)(?=[A-Z0-9])|(?<=[a-z0-9])(Left|Right)$")
_CAMEL = re.compile(r"(?<=[a-z])(?=[A-Z])|(?<=[A-Za-z])(?=[0-9])|(?<=[0-9])(?=[A-Za-z])")

LEG_WORDS = frozenset({
    "thigh", "shin", "calf", "knee", "foot", "feet", "toe", "toes", "leg", "legs", "upleg", "upperleg",
    "lowerleg", "coxa", "trochanter", "femur", "tibia", "tarsus", "metatarsus", "ankle", "paw", "hoof",
    "hock", "forearm", "hand", "arm", "claw", "pes", "manus", "limb", "ball", "toebase", "upperarm",
    "lowerarm", "scapula", "humerus", "radius", "ulna", "cannon", "pastern", "fetlock", "carpus",
    "metacarpus", "metatarsal", "femoral", "tarsal", "hind", "fore",
})
# Words of appendages that may reach down but are not legs (jaws, palps, fins, face bones),
# and of the clothes and hair that hang from a character's hips, thighs or head (VRoid's
# ``J_Sec_L_SkirtBack1_01``, ``J_Sec_L_CoatSkirtBack_01``, ``J_Sec_Hair1_05``: an ankle-long
# dress or a twin tail reaches the floor like a leg).
NON_LEG_WORDS = frozenset({
    "jaw", "jaws", "pincer", "pedipalp", "palp", "chelicera", "chelicerae", "antenna", "antennae", "fin",
    "fins", "tail", "wing", "mandible", "fang", "tongue", "ear", "teeth", "tooth", "mouth", "lip", "cheek",
    "nose", "brow", "eyebrow", "eye", "lid", "chin", "whisker", "tentacle", "hair", "beak",
    "skirt", "dress", "coat", "cape", "cloak", "robe", "gown", "cloth", "sleeve", "hood", "scarf", "ribbon",
    "bust", "breast", "ponytail", "braid", "bang", "bangs", "tassel", "apron", "belt",
})
# Helper words that may end a leg chain: the leaf bone marking a toe's tip (``LeftToe_End``).
TIP_WORDS = frozenset({"tip", "end", "nub", "null"})
# Words that make a bone a control, helper or mechanism bone, never part of a leg chain.
HELPER_WORDS = frozenset({
    "ik", "fk", "pole", "target", "tgt", "ctrl", "control", "mch", "helper", "twist", "roll", "heel",
    "tweak", "parent", "socket", "pivot", "vis", "hint", "aim", "root", "master", "prop", "rot", "ctl",
    "tip", "end", "nub", "null", "snap", "lock", "spin",
})
# Helper words that also name a segment of a limb: Genesis' ``lThighBend > lThighTwist > lShin``
# (a twist bone with the shin hanging from its end is the thigh's lower half, not a helper).
SEGMENT_WORDS = frozenset({"twist"})
_SIDES = {"l": 1, "left": 1, "lft": 1, "r": -1, "right": -1, "rgt": -1}


@functools.lru_cache(maxsize=8192)  # detection splits every bone's name again and again
def split_name(name: str) -> tuple[int, tuple[str, ...]]:
    """``(side, tokens)`` of a bone name: side +1 left, -1 right, 0 none; tokens lower-case.

    ``"DEF-front_thigh.L"`` -> ``(1, ("front", "thigh"))``; ``"LeftUpLeg"`` -> ``(1, ("up", "leg"))``;
    ``"Leg3_tarsus.R"`` -> ``(-1, ("leg", "3", "tarsus"))``.
    """
    base = name
    for _ in range(2):
        base = _PREFIX.sub("", base)
    side = 0
    m = _SIDE_SUFFIX.search(base)
    if m:
        side = _SIDES[m.group(1).lower()]
        base = base[: m.start()] + (m.group(2) or "")
    else:
        m = _SIDE_PREFIX.match(base)
        if m:
            side = _SIDES[m.group(1).lower()]
            base = base[m.end():]
        else:
            m = _SIDE_CAMEL.search(base)
            if m:
                side = 1 if (m.group(1) or m.group(2)) == "Left" else -1
                base = base[: m.start()] + base[m.end():]
    spaced = _CAMEL.sub(" ", base)
    tokens = tuple(t for t in re.split(r"[^A-Za-z0-9]+", spaced.lower()) if t)
    if side == 0:  # a side word inside the name: FrontLeftLeg, Leg_L_01
        sided = [t for t in tokens if t in _SIDES]
        if len(sided) == 1:
            side = _SIDES[sided[0]]
            tokens = tuple(t for t in tokens if t != sided[0])
    return side, tokens


def _is_leg_name(tokens: Sequence[str], segment: bool = False) -> bool:
    """Whether a name marks a leg bone. ``segment``: the bone is a segment of its chain (the
    next bone hangs from its end), so a segment word (``lThighTwist``) does not make it a helper."""
    words = set(tokens)
    helpers = words & HELPER_WORDS
    if segment:
        helpers -= SEGMENT_WORDS
    return bool(words & LEG_WORDS) and not helpers


def _is_helper_name(tokens: Sequence[str]) -> bool:
    return bool(set(tokens) & HELPER_WORDS)


def _is_control_name(tokens: Sequence[str], segment: bool = False) -> bool:
    """A control or mechanism bone (IK target, pole, twist...); a toe's tip bone is not, nor
    (``segment``: the next bone of its chain hangs from its end) a limb segment named twist."""
    words = set(tokens) & (HELPER_WORDS - TIP_WORDS)
    if segment:
        words -= SEGMENT_WORDS
    return bool(words)


def _is_non_leg_name(tokens: Sequence[str]) -> bool:
    return bool(set(tokens) & NON_LEG_WORDS)


def _leg_number(tokens: Sequence[str]) -> str:
    """The number written next to 'leg' (``Leg3_coxa`` -> ``"3"``), else ``""``."""
    for i, t in enumerate(tokens):
        if t in {"leg", "legs", "limb"} and i + 1 < len(tokens) and tokens[i + 1].isdigit():
            return tokens[i + 1]
    return ""


#: Words of the bones a rig splits one limb bone into (Auto-Rig Pro's ``thigh_twist.l`` >
#: ``thigh_stretch.l``, Genesis' ``lThighBend`` > ``lThighTwist``).
SPLIT_WORDS = frozenset({"twist", "stretch", "bend"})


#: Leg words that name a whole limb or its end, not one segment: ``Leg01`` > ``Leg02`` are a
#: thigh and a shin (a game quadruped's hind leg), ``Foot01`` > ``Foot02`` a cannon and a hoof.
WHOLE_LIMB_WORDS = frozenset({
    "leg", "legs", "limb", "hind", "fore", "arm", "foot", "feet", "toe", "toes", "paw", "hoof", "claw",
    "hand", "manus", "pes",
})


def split_joints(bones: Sequence[str]) -> list[int]:
    """The hinges of a leg chain (1 .. len(bones) - 1, hinge ``j`` between ``bones[j - 1]``
    and ``bones[j]``) that join two halves of one limb bone: one of the two names a split
    (``twist``, ``stretch``, ``bend``) and without those words both name the same limb
    (``thigh``, ``leg``); or the two names differ only in their numbers and name the same
    segment of a limb (MakeHuman's ``upperleg01.L`` > ``upperleg02.L`` and ``lowerleg01.L``
    > ``lowerleg02.L``, a B-Bone split's ``thigh.L`` > ``thigh.L.001``; not
    :data:`WHOLE_LIMB_WORDS`). A knee never does: ``thigh_stretch.l`` > ``leg_stretch.l``
    name two limbs, ``upperleg02.L`` > ``lowerleg01.L`` too, and Auto-Rig Pro's
    ``c_thigh_b.l`` > ``thigh_twist.l`` (a three-bone leg's hip) are two bones."""
    out = []
    for j in range(1, len(bones)):
        a, b = set(split_name(bones[j - 1])[1]), set(split_name(bones[j])[1])
        if (a | b) & SPLIT_WORDS and a - SPLIT_WORDS == b - SPLIT_WORDS and a & LEG_WORDS:
            out.append(j)
            continue
        words = {t for t in a if not t.isdigit()}
        if a != b and words == {t for t in b if not t.isdigit()} and words & (LEG_WORDS - WHOLE_LIMB_WORDS):
            out.append(j)
    return out
