# SPDX-License-Identifier: GPL-3.0-or-later
"""Reading an armature: legs, body, spine, and the core morphology; writing poses back.

A **leg** is the bone chain from its *hip* bone down to its *end-effector* bone (thesis
§3.1: "the name of each leg hip joint and the name of its end-effector, e.g. the joint
before the foot"). Bones after the end-effector that lie flat on the ground (a human's
foot and toes, a wolf's paw) are the leg's *foot*: they keep their rest orientation
(turned with the body's heading) instead of being solved by the IK.

Detection (:func:`detect_legs`) works in two passes:

1. **Names.** Bone names are split into tokens (``DEF-``/``ORG-``/``mixamorig:`` prefixes
   dropped, camelCase and separators split) and a side (``.L/.R``, ``_l/_r``,
   ``Left/Right``...). Runs of parent-to-child bones whose names hold a leg word (``thigh``,
   ``shin``, ``foot``, ``coxa``, ``femur``, ``tibia``, ``tarsus``, ``upper_arm``, ``Leg3``...)
   on one side form candidate chains. Bones whose names mark controls or helpers (``ik``,
   ``pole``, ``target``, ``heel``, ``MCH``...) never join a chain.
2. **Topology**, when names find fewer than two legs: every unbranched chain of bones that
   ends at a leaf, hangs from a branching bone and reaches down to the ground.

Either way a candidate is a leg only if it has at least two bones, its lowest point is
near the ground (the lowest contact of all candidates) and it reaches down from its hip.
A leaf bone parented to the root beside each foot (an IK target) is a one-bone chain and
is never a leg.

Geometry is read in **world space** from the armature's rest pose placed by the object's
world matrix, so scaled, rotated and moved rigs work (a uniform object scale is required:
non-uniform scale shears bone rotations). Everything the core sees is in the creature's
body frame (x forward, y left, z up) whose origin is the centroid of the hips.

The **spine** (:attr:`RigInfo.spine`) is the chain of bones from the body bone (the hips)
forward through the bones the legs hang from to the head: at each bone the chain goes on to
the child on the body's midline that carries the most legs, then, past the last girdle, to
the child that continues it forward. Each leg hangs from the nearest spine bone above its
hip. When the legs hang from two or more spine bones (quadrupeds, lizards) and
``read_rig(..., spine=True)``, :class:`SpineLayout` maps the chain to the core's flexible
spine (``core.spine``): its joints, its virtual pelvis nodes (the head, one per girdle, the
back girdle at the hips' head) and which bone carries each leg.

:func:`solve_pose` converts per-frame core results (body frame and joint positions in the
world, and with a spine its bones' rotations) into pose-bone ``matrix_basis`` rotations and
the body bone's location, keeping each leg's knee plane and adding no twist;
:mod:`.actions` writes them in each bone's rotation mode.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.morphology import Morphology
from ..core.spine import DEFAULT_JOINT_PITCH_LIMIT, DEFAULT_JOINT_YAW_LIMIT

__all__ = [
    "BodyInfo",
    "LegChain",
    "PoseTracks",
    "RigError",
    "RigInfo",
    "SpineLayout",
    "detect_legs",
    "leg_from_bones",
    "matrix_to_quaternion",
    "morphology_of",
    "read_rig",
    "solve_pose",
    "split_name",
]

_UP = np.array([0.0, 0.0, 1.0])
FOOT_EXTENT_SHARE = 1.0


class RigError(ValueError):
    """The armature cannot be animated as asked (the message is meant for the user)."""


# ---------------------------------------------------------------------------------------
# Names

_PREFIX = re.compile(r"^(def|org|mch|ctrl|ctl|jnt|jt|bn|bone|b|mixamorig\d*|cc_base|bip\d*)[-_.:\s]+",
                     re.IGNORECASE)
_SIDE_SUFFIX = re.compile(r"[-_.\s](l|r|left|right|lft|rgt)((?:\.\d+)?)$", re.IGNORECASE)
_SIDE_PREFIX = re.compile(r"^(l|r|left|right|lft|rgt)[-_.\s]", re.IGNORECASE)
_SIDE_CAMEL = re.compile(r"^(Left|Right)(?=[A-Z0-9])|(?<=[a-z0-9])(Left|Right)$")
_CAMEL = re.compile(r"(?<=[a-z])(?=[A-Z])|(?<=[A-Za-z])(?=[0-9])|(?<=[0-9])(?=[A-Za-z])")

LEG_WORDS = frozenset({
    "thigh", "shin", "calf", "knee", "foot", "feet", "toe", "toes", "leg", "legs", "upleg", "upperleg",
    "lowerleg", "coxa", "trochanter", "femur", "tibia", "tarsus", "metatarsus", "ankle", "paw", "hoof",
    "hock", "forearm", "hand", "arm", "claw", "pes", "manus", "limb",
})
# Words that make a bone a control, helper or mechanism bone, never part of a leg chain.
HELPER_WORDS = frozenset({
    "ik", "fk", "pole", "target", "tgt", "ctrl", "control", "mch", "helper", "twist", "roll", "heel",
    "tweak", "parent", "socket", "pivot", "vis", "hint", "aim", "root", "master", "prop", "rot", "ctl",
    "tip", "end", "nub", "null", "ref", "snap", "lock", "spin",
})
_SIDES = {"l": 1, "left": 1, "lft": 1, "r": -1, "right": -1, "rgt": -1}


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
    return side, tokens


def _is_leg_name(tokens: Sequence[str]) -> bool:
    words = set(tokens)
    return bool(words & LEG_WORDS) and not (words & HELPER_WORDS)


def _is_helper_name(tokens: Sequence[str]) -> bool:
    return bool(set(tokens) & HELPER_WORDS)


def _leg_number(tokens: Sequence[str]) -> str:
    """The number written next to 'leg' (``Leg3_coxa`` -> ``"3"``), else ``""``."""
    for i, t in enumerate(tokens):
        if t in {"leg", "legs", "limb"} and i + 1 < len(tokens) and tokens[i + 1].isdigit():
            return tokens[i + 1]
    return ""


# ---------------------------------------------------------------------------------------
# Rest geometry


@dataclass(frozen=True)
class _Rest:
    """Rest geometry of every bone in world space (uniformly scaled rig)."""

    names: tuple[str, ...]
    index: dict[str, int]
    parent: np.ndarray  # (B,) parent index or -1
    head: np.ndarray  # (B, 3) world
    tail: np.ndarray  # (B, 3) world
    local: np.ndarray  # (B, 4, 4) armature-space rest matrices (bone.matrix_local)
    world: np.ndarray  # (4, 4) object world matrix
    scale: float

    def children(self, i: int) -> list[int]:
        return [int(c) for c in np.flatnonzero(self.parent == i)]

    def ancestors(self, i: int) -> list[int]:
        out = []
        p = int(self.parent[i])
        while p >= 0:
            out.append(p)
            p = int(self.parent[p])
        return out


def _object_world(obj: bpy.types.Object) -> np.ndarray:
    return np.array(obj.matrix_world, dtype=np.float64)


def uniform_scale(world: np.ndarray) -> float | None:
    """The object's uniform scale, or None when it is not uniform (or has shear)."""
    m = world[:3, :3]
    scales = np.linalg.norm(m, axis=0)
    if np.any(scales < 1e-12):
        return None
    rot = m / scales
    if np.max(np.abs(rot.T @ rot - np.eye(3))) > 1e-4 or np.ptp(scales) > 1e-4 * scales.max():
        return None
    if np.linalg.det(rot) < 0:
        return None
    return float(scales.mean())


def _rest_of(obj: bpy.types.Object) -> _Rest:
    if obj is None or obj.type != "ARMATURE":
        raise RigError("The active object is not an armature: select a rig")
    world = _object_world(obj)
    scale = uniform_scale(world)
    if scale is None:
        raise RigError(f"'{obj.name}' has a non-uniform or mirrored scale: apply its scale first (Ctrl A)")
    bones = obj.data.bones
    names = tuple(b.name for b in bones)
    index = {n: i for i, n in enumerate(names)}
    n = len(names)
    if n == 0:
        raise RigError(f"'{obj.name}' has no bones")
    parent = np.array([index[b.parent.name] if b.parent else -1 for b in bones], dtype=np.int64)
    local = np.empty(n * 16, dtype=np.float32)
    bones.foreach_get("matrix_local", local)
    local_m = local.reshape(n, 4, 4).transpose(0, 2, 1).astype(np.float64)
    head_l = np.empty(n * 3, dtype=np.float32)
    tail_l = np.empty(n * 3, dtype=np.float32)
    bones.foreach_get("head_local", head_l)
    bones.foreach_get("tail_local", tail_l)
    head = _apply(world, head_l.reshape(n, 3).astype(np.float64))
    tail = _apply(world, tail_l.reshape(n, 3).astype(np.float64))
    return _Rest(names, index, parent, head, tail, local_m, world, scale)


def _apply(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Affine 4x4 ``m`` applied to points ``(..., 3)``."""
    return p @ m[:3, :3].T + m[:3, 3]


# ---------------------------------------------------------------------------------------
# Legs


@dataclass(frozen=True)
class LegChain:
    """One leg: ``bones`` hip to end-effector (parent to child), then the flat ``foot`` bones."""

    bones: tuple[str, ...]
    foot: tuple[str, ...] = ()
    side: int = 0
    label: str = ""

    @property
    def hip(self) -> str:
        return self.bones[0]

    @property
    def end(self) -> str:
        return self.bones[-1]


def _chain_points(rest: _Rest, idx: Sequence[int]) -> np.ndarray:
    """Joint points of a chain: each bone's head, then the last bone's tail ``(k + 1, 3)``."""
    return np.vstack([rest.head[list(idx)], rest.tail[idx[-1]][None]])


def _continuing_child(rest: _Rest, i: int, allowed: set[int] | None = None) -> int | None:
    """The child that continues a chain: a connected one first, then the one reaching lowest."""
    kids = [c for c in rest.children(i) if allowed is None or c in allowed]
    if not kids:
        return None
    tol = 1e-6 * max(rest.scale, 1e-9)
    connected = [c for c in kids if np.linalg.norm(rest.head[c] - rest.tail[i]) < tol]
    pool = connected or kids
    return min(pool, key=lambda c: (_subtree_min_z(rest, c), c))


def _subtree_min_z(rest: _Rest, i: int) -> float:
    stack = [i]
    low = np.inf
    while stack:
        j = stack.pop()
        low = min(low, rest.head[j, 2], rest.tail[j, 2])
        stack.extend(rest.children(j))
    return float(low)


def _split_foot(rest: _Rest, idx: list[int]) -> tuple[list[int], list[int]]:
    """Split a hip-to-tip chain into the IK part and the trailing flat foot bones.

    A trailing bone is part of the foot when it lies nearly flat (less than 45 degrees from
    horizontal) and both its ends are within 20 % of the leg's length above the lowest point.
    At least two bones stay in the IK part.
    """
    pts = _chain_points(rest, idx)
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    ground = float(pts[:, 2].min())
    band = 0.2 * length
    cut = len(idx)
    while cut > 2:
        b = idx[cut - 1]
        d = rest.tail[b] - rest.head[b]
        horiz = float(np.linalg.norm(d[:2]))
        flat = abs(d[2]) < horiz  # under 45 degrees
        low = rest.head[b, 2] - ground < band and rest.tail[b, 2] - ground < band
        if flat and low:
            cut -= 1
        else:
            break
    return idx[:cut], idx[cut:]


def _foot_after(rest: _Rest, end: int) -> list[int]:
    """Flat bones continuing below/after a user-chosen end-effector (at most two)."""
    out: list[int] = []
    cur = end
    chain_len = float(np.linalg.norm(rest.tail[end] - rest.head[end]))
    for _ in range(2):
        nxt = _continuing_child(rest, cur)
        if nxt is None:
            break
        d = rest.tail[nxt] - rest.head[nxt]
        if abs(d[2]) >= np.linalg.norm(d[:2]) or rest.head[nxt, 2] > rest.tail[end, 2] + 0.5 * chain_len:
            break
        out.append(nxt)
        cur = nxt
    return out


def _name_chains(rest: _Rest) -> list[list[int]]:
    info = [split_name(n) for n in rest.names]
    legish = [_is_leg_name(t) for _s, t in info]
    group = [(s, _leg_number(t)) for s, t in info]
    chains: list[list[int]] = []
    for i in range(len(rest.names)):
        if not legish[i]:
            continue
        p = int(rest.parent[i])
        if p >= 0 and legish[p] and group[p][0] == group[i][0]:
            continue  # not the start of a run
        chain = [i]
        cur = i
        while True:
            allowed = {c for c in rest.children(cur) if legish[c] and group[c][0] == group[i][0]}
            nxt = _continuing_child(rest, cur, allowed) if allowed else None
            if nxt is None:
                break
            chain.append(nxt)
            cur = nxt
        chains.append(chain)
    return chains


def _topology_chains(rest: _Rest) -> list[list[int]]:
    chains = []
    for leaf in range(len(rest.names)):
        if rest.children(leaf):
            continue
        chain = [leaf]
        p = int(rest.parent[leaf])
        while p >= 0 and len(rest.children(p)) == 1 and rest.parent[p] >= 0:
            chain.append(p)
            p = int(rest.parent[p])
        if p < 0:
            continue  # hangs from nothing: the body itself, not a leg
        chain.reverse()
        if any(_is_helper_name(split_name(rest.names[b])[1]) for b in chain):
            continue
        chains.append(chain)
    return chains


def _valid_legs(rest: _Rest, chains: list[list[int]]) -> list[list[int]]:
    """Keep chains that are legs: two bones or more, reaching down to the common ground."""
    good = []
    for chain in chains:
        if len(chain) < 2:
            continue
        pts = _chain_points(rest, chain)
        length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
        if length <= 0.0:
            continue
        low = float(pts[:, 2].min())
        # the tip end of the chain must be the low end, well below the hip
        if pts[0, 2] - low < 0.1 * length or pts[-1, 2] - low > 0.25 * length:
            continue
        good.append(chain)
    if not good:
        return []
    lows = np.array([_chain_points(rest, c)[:, 2].min() for c in good])
    lengths = np.array([np.linalg.norm(np.diff(_chain_points(rest, c), axis=0), axis=1).sum() for c in good])
    ground = float(lows.min())
    return [c for c, low, ln in zip(good, lows, lengths, strict=True) if low - ground <= 0.25 * ln]


def _dedupe(obj: bpy.types.Object, rest: _Rest, chains: list[list[int]]) -> list[list[int]]:
    """Keep one chain per leg where a rig has parallel copies (Rigify's ORG-/DEF- bones):
    chains whose hips and tips coincide are one leg; the copy with the fewest constrained
    bones wins, then the one with the fewest bones."""

    def constrained(chain: list[int]) -> int:
        pbones = obj.pose.bones
        return sum(1 for i in chain
                   if any(c.type in _OVERRIDING_CONSTRAINTS for c in pbones[rest.names[i]].constraints))

    ranked = sorted(chains, key=lambda c: (constrained(c), len(c), c[0]))
    kept: list[list[int]] = []
    for chain in ranked:
        pts = _chain_points(rest, chain)
        tol = 0.02 * _length(pts)
        if any(np.linalg.norm(pts[0] - _chain_points(rest, k)[0]) < tol
               and np.linalg.norm(pts[-1] - _chain_points(rest, k)[-1]) < tol for k in kept):
            continue
        kept.append(chain)
    return sorted(kept, key=lambda c: c[0])


def detect_legs(obj: bpy.types.Object) -> list[LegChain]:
    """Find the legs of armature ``obj`` by names, else by topology (see the module doc).

    Returns legs labelled and ordered front to back, left before right (``L1, R1, L2, ...``;
    a leg on the midline is ``M<row>``). Raises :class:`RigError` when no leg is found.
    """
    rest = _rest_of(obj)
    chains = _valid_legs(rest, _name_chains(rest))
    if len(chains) < 2:
        topo = _valid_legs(rest, _topology_chains(rest))
        if len(topo) > len(chains):
            chains = topo
    chains = _dedupe(obj, rest, chains)
    if not chains:
        raise RigError(f"No legs found on '{obj.name}': name them (thigh/shin/foot, coxa/femur/tibia/tarsus, "
                       "Leg1...) or set hip and end-effector bones in the Rig & Legs panel")
    legs = []
    for chain in chains:
        ik, foot = _split_foot(rest, chain)
        side = split_name(rest.names[chain[0]])[0]
        legs.append(LegChain(tuple(rest.names[i] for i in ik), tuple(rest.names[i] for i in foot), side))
    return _label_legs(rest, legs, _forward_axis(rest, legs, "AUTO"))


def leg_from_bones(obj: bpy.types.Object, hip: str, end: str, label: str = "") -> LegChain:
    """A leg from user-chosen hip and end-effector bones, validated.

    Raises :class:`RigError` when a bone is missing, the hip is not an ancestor of the end
    (or the end itself), or a bone of the chain has zero length.
    """
    rest = _rest_of(obj)
    name = label or f"{hip} > {end}"
    for bone in (hip, end):
        if not bone:
            raise RigError(f"Leg {name}: choose both a hip and an end-effector bone")
        if bone not in rest.index:
            raise RigError(f"Leg {name}: '{obj.name}' has no bone '{bone}'")
    h, e = rest.index[hip], rest.index[end]
    chain = [e]
    cur = e
    while cur != h:
        cur = int(rest.parent[cur])
        if cur < 0:
            raise RigError(f"Leg {name}: hip '{hip}' is not an ancestor of end-effector '{end}'")
        chain.append(cur)
    chain.reverse()
    for i in chain:
        if np.linalg.norm(rest.tail[i] - rest.head[i]) < 1e-9:
            raise RigError(f"Leg {name}: bone '{rest.names[i]}' has zero length")
    pts = _chain_points(rest, chain)
    if np.any(np.linalg.norm(np.diff(pts, axis=0), axis=1) < 1e-9):
        raise RigError(f"Leg {name}: two joints of the chain coincide (zero-length segment)")
    foot = _foot_after(rest, e)
    side = split_name(hip)[0]
    return LegChain(tuple(rest.names[i] for i in chain), tuple(rest.names[i] for i in foot), side, label)


def _forward_axis(rest: _Rest, legs: Sequence[LegChain], mode: str) -> np.ndarray:
    """Horizontal unit forward direction of the creature in the world."""
    rot = rest.world[:3, :3] / rest.scale
    local_axes = {"-Y": (0, -1, 0), "+Y": (0, 1, 0), "+X": (1, 0, 0), "-X": (-1, 0, 0)}
    if mode in local_axes:
        f = rot @ np.array(local_axes[mode], dtype=np.float64)
    else:
        hips = np.array([rest.head[rest.index[leg.hip]] for leg in legs]) if legs else np.zeros((0, 3))
        sides = np.array([leg.side for leg in legs])
        f = np.zeros(3)
        if np.any(sides > 0) and np.any(sides < 0):
            left = hips[sides > 0].mean(axis=0) - hips[sides < 0].mean(axis=0)
            left[2] = 0.0
            if np.linalg.norm(left) > 1e-9:
                f = np.cross(left, _UP)
        if np.linalg.norm(f[:2]) < 1e-9:
            f = rot @ np.array([0.0, -1.0, 0.0])  # Blender characters face -Y
    f = np.array([f[0], f[1], 0.0])
    n = np.linalg.norm(f)
    if n < 1e-9:
        raise RigError("Cannot tell which way the rig faces: its -Y axis points up or down")
    return f / n


def _label_legs(rest: _Rest, legs: Sequence[LegChain], forward: np.ndarray) -> list[LegChain]:
    """Sides from names or hip positions; rows front to back; labels L1, R1, ...; sorted."""
    left = np.cross(_UP, forward)
    hips = np.array([rest.head[rest.index[leg.hip]] for leg in legs])
    center = hips.mean(axis=0)
    lengths = np.array([_length(_chain_points(rest, [rest.index[b] for b in leg.bones])) for leg in legs])
    tol = 0.1 * float(lengths.mean())
    sides = []
    for leg, hip in zip(legs, hips, strict=True):
        side = leg.side
        if side == 0:
            lateral = float((hip - center) @ left)
            side = 1 if lateral > tol else (-1 if lateral < -tol else 0)
        sides.append(side)
    fwd = (hips - center) @ forward
    # Pair the i-th left leg with the i-th right leg (front to back); midline legs get rows
    # of their own, placed by where they are along the body.
    by_side = {s: sorted((i for i in range(len(legs)) if sides[i] == s), key=lambda i: -fwd[i])
               for s in (1, -1, 0)}
    rows: list[dict[int, int]] = [{s: by_side[s][r] for s in (1, -1) if r < len(by_side[s])}
                                  for r in range(max(len(by_side[1]), len(by_side[-1])))]
    for i in by_side[0]:
        row_fwd = [max(fwd[j] for j in row.values()) for row in rows]
        pos = sum(1 for f in row_fwd if f > fwd[i])
        rows.insert(pos, {0: i})
    out = []
    for r, row in enumerate(rows, start=1):
        for s in (1, -1, 0):
            if s in row:
                leg = legs[row[s]]
                prefix = {1: "L", -1: "R", 0: "M"}[s]
                out.append(LegChain(leg.bones, leg.foot, s, leg.label or f"{prefix}{r}"))
    return out


# ---------------------------------------------------------------------------------------
# The whole rig


@dataclass(frozen=True)
class BodyInfo:
    """The creature's body frame at rest, in the world."""

    origin: np.ndarray  # (3,) centroid of the hips
    forward: np.ndarray  # (3,) horizontal unit
    left: np.ndarray  # (3,)

    @property
    def matrix(self) -> np.ndarray:
        """``(4, 4)`` body-to-world rigid transform."""
        m = np.eye(4)
        m[:3, 0] = self.forward
        m[:3, 1] = self.left
        m[:3, 2] = _UP
        m[:3, 3] = self.origin
        return m


@dataclass(frozen=True)
class SpineLayout:
    """The rig's spine chain as the core's flexible spine (``core.spine.SpineModel``).

    - ``joints``: ``(J, 3)`` world rest joints, head first: the tip of the head bone, then
      the head of every chain bone from the head bone back to the body bone (``J - 1``
      bones). Core bone ``i`` joins joints ``i`` and ``i + 1``: it is chain bone
      ``spine[-1 - i]`` of :attr:`RigInfo.spine`.
    - ``key_joint``: ``(K,)`` the virtual pelvis nodes: 0 (the head), one joint per girdle
      (the end of its bone nearest the legs' hips), ``J - 1`` (the body bone's head, the back
      girdle).
    - ``leg_key``: ``(L,)`` the node each leg belongs to; ``leg_bone``: ``(L,)`` the core
      bone each leg's hip hangs from (its nearest spine ancestor).
    """

    joints: np.ndarray
    key_joint: np.ndarray
    leg_key: np.ndarray
    leg_bone: np.ndarray


@dataclass(frozen=True)
class RigInfo:
    """Everything the shell needs about one armature, read once per generation.

    Arrays are in world space at the generation's first frame unless named ``_local``.
    ``spine`` is the spine chain from the body bone to the head (parent to child; empty when
    the rig has none); ``spine_layout`` is set when the spine drives the body (read with
    ``spine=True`` from a rig whose legs hang from two or more spine bones): its bones are
    then keyed too.
    """

    object_name: str
    legs: tuple[LegChain, ...]
    body_bone: str
    spine: tuple[str, ...]
    body: BodyInfo
    joints: tuple[np.ndarray, ...]  # per leg (k + 1, 3) rest joints (heads, then the end's tail)
    contact: np.ndarray  # (n_legs, 3) lowest point of each foot (ground contact) at rest
    foot_height: np.ndarray  # (n_legs,) height of the end-effector above its contact point
    foot_extent: np.ndarray  # (n_legs, 2) half size of each foot's ground print (forward, left)
    foot_points: tuple[np.ndarray, ...]  # per leg (p, 3) rest points of the foot bones (sole probes)
    # Per leg: (target bone, joint index) when an IK constraint on the leg pulls the chain to
    # a bone of this rig; that bone is keyed so the joint reaches the simulated position.
    ik_targets: tuple[tuple[str, int] | None, ...]
    world: np.ndarray  # (4, 4) object world matrix
    scale: float
    rest_local: dict[str, np.ndarray] = field(repr=False)  # bone -> (4, 4) armature-space rest
    parents: dict[str, str | None] = field(repr=False)
    basis: dict[str, np.ndarray] = field(repr=False)  # bone -> (4, 4) current matrix_basis
    warnings: tuple[str, ...] = ()
    spine_layout: SpineLayout | None = None

    @property
    def leg_length(self) -> np.ndarray:
        return np.array([np.linalg.norm(np.diff(j, axis=0), axis=1).sum() for j in self.joints])

    @property
    def driven_bones(self) -> tuple[str, ...]:
        names = [self.body_bone]
        if self.spine_layout is not None:
            names += list(self.spine)
        for leg in self.legs:
            names += list(leg.bones)
            names += list(leg.foot[:1])
        names += [t[0] for t in self.ik_targets if t is not None]
        return tuple(dict.fromkeys(names))


_OVERRIDING_CONSTRAINTS = frozenset({
    "IK", "COPY_ROTATION", "COPY_TRANSFORMS", "DAMPED_TRACK", "LOCKED_TRACK", "TRACK_TO", "STRETCH_TO",
    "CHILD_OF", "ARMATURE", "SPLINE_IK", "ACTION", "TRANSFORM", "CLAMP_TO", "FOLLOW_PATH",
})


def read_rig(
    obj: bpy.types.Object, legs: Sequence[LegChain] | None = None, forward_axis: str = "AUTO",
    spine: bool = False, at_rest: Collection[str] = (),
) -> RigInfo:
    """Read ``obj``'s legs (given, else detected), body bone, spine and rest geometry.

    ``spine``: drive the spine chain when the rig has one that carries two girdles or more
    (:attr:`RigInfo.spine_layout`); its bones are then read at rest, like the legs.
    Bones that are not driven keep their current pose (:attr:`RigInfo.basis`), except those
    named in ``at_rest``, which are taken at rest.
    Raises :class:`RigError` for anything that cannot be animated (not an armature, bad
    legs, legs with no common body bone, non-uniform scale).
    """
    rest = _rest_of(obj)
    if legs is None:
        legs = detect_legs(obj)
    legs = list(legs)
    if not legs:
        raise RigError(f"'{obj.name}' has no enabled legs")
    for leg in legs:
        for b in (*leg.bones, *leg.foot):
            if b not in rest.index:
                raise RigError(f"Leg {leg.label}: '{obj.name}' has no bone '{b}'")
    used = [b for leg in legs for b in leg.bones]
    if len(set(used)) != len(used):
        raise RigError("Two legs share a bone: each bone may belong to one leg only")
    if any(not leg.label for leg in legs) or len({leg.label for leg in legs}) != len(legs):
        legs = _label_legs(rest, [LegChain(leg.bones, leg.foot, leg.side) for leg in legs],
                           _forward_axis(rest, legs, forward_axis))
    forward = _forward_axis(rest, legs, forward_axis)
    left = np.cross(_UP, forward)

    hip_idx = [rest.index[leg.hip] for leg in legs]
    body_idx = _common_ancestor(rest, hip_idx)
    if body_idx is None:
        raise RigError("The legs do not hang from one body: their hips have no common parent bone")
    # A connected bone cannot be moved (its head is its parent's tail): the body motion goes
    # to the first ancestor that can.
    while obj.data.bones[rest.names[body_idx]].use_connect and rest.parent[body_idx] >= 0:
        body_idx = int(rest.parent[body_idx])
    mean_leg = float(np.mean([_length(_chain_points(rest, [rest.index[b] for b in leg.bones]))
                              for leg in legs]))
    chain = _spine_chain(rest, body_idx, hip_idx, forward, mean_leg)
    carried = spine and _spine_layout(rest, chain, hip_idx, rest.head, rest.tail) is not None

    basis = _current_basis(obj)
    for name in at_rest:
        if name in basis:
            basis[name] = np.eye(4)
    ik_targets = [_ik_target(obj, rest, leg) for leg in legs]
    driven = {rest.index[b] for leg in legs for b in (*leg.bones, *leg.foot[:1])} | {body_idx}
    if carried:
        driven |= set(chain)
    driven |= {rest.index[t[0]] for t in ik_targets if t is not None}
    posed_local = _posed_rest(rest, basis, driven)
    heads = _apply(rest.world, posed_local[:, :3, 3])
    tails = _apply(rest.world, posed_local[:, :3, 3] + posed_local[:, :3, 1]
                   * np.array([obj.data.bones[n].length for n in rest.names])[:, None])

    joints = []
    contact = []
    foot_h = []
    foot_ext = []
    foot_pts = []
    for leg in legs:
        idx = [rest.index[b] for b in leg.bones]
        pts = np.vstack([heads[idx], tails[idx[-1]][None]])
        joints.append(pts)
        below = [pts[-1]]
        for f in leg.foot:
            k = rest.index[f]
            below += [heads[k], tails[k]]
            below += [heads[c] for c in _descendants(rest, k)] + [tails[c] for c in _descendants(rest, k)]
        below_a = np.array(below)
        low = below_a[np.argmin(below_a[:, 2])]
        contact.append(np.array([pts[-1, 0], pts[-1, 1], low[2]]))
        foot_h.append(float(pts[-1, 2] - low[2]))
        # How far the foot bones reach from the end-effector, along and across the body.
        rel = below_a[:, :2] - pts[-1, :2]
        foot_ext.append(np.array([np.abs(rel @ forward[:2]).max(), np.abs(rel @ left[:2]).max()]))
        # Sole probes: the foot points reaching furthest from the end-effector (toe tips, heel).
        probes = below_a[1:]
        if probes.shape[0] > 6:
            far = np.argsort(-np.linalg.norm(probes[:, :2] - pts[-1, :2], axis=1), kind="stable")[:6]
            probes = probes[np.sort(far)]
        foot_pts.append(probes)
    origin = np.array([j[0] for j in joints]).mean(axis=0)
    body = BodyInfo(origin, forward, left)
    layout = _spine_layout(rest, chain, hip_idx, heads, tails) if carried else None

    warnings = []
    handled = {t[0] for t in ik_targets if t is not None}
    for name in sorted(rest.names[i] for i in driven):
        pb = obj.pose.bones[name]
        bad = [c.type for c in pb.constraints
               if c.enabled and c.influence > 0.0 and c.type in _OVERRIDING_CONSTRAINTS
               and not (c.type == "IK" and c.target == obj and c.subtarget in handled)]
        if bad:
            warnings.append(f"bone '{name}' has {', '.join(sorted(set(bad)))} constraints that override the "
                            "generated keys")

    return RigInfo(
        object_name=obj.name,
        legs=tuple(legs),
        body_bone=rest.names[body_idx],
        spine=tuple(rest.names[i] for i in chain),
        body=body,
        joints=tuple(joints),
        contact=np.array(contact),
        foot_height=np.array(foot_h),
        foot_extent=np.array(foot_ext),
        foot_points=tuple(foot_pts),
        ik_targets=tuple(ik_targets),
        world=rest.world,
        scale=rest.scale,
        rest_local={n: rest.local[i] for i, n in enumerate(rest.names)},
        parents={n: (rest.names[int(rest.parent[i])] if rest.parent[i] >= 0 else None)
                 for i, n in enumerate(rest.names)},
        basis=basis,
        warnings=tuple(warnings),
        spine_layout=layout,
    )


def _ik_target(obj: bpy.types.Object, rest: _Rest, leg: LegChain) -> tuple[str, int] | None:
    """The bone an enabled IK constraint on ``leg`` pulls the chain to, and the index of the
    joint it pulls (the constrained bone's tail, or its head with "Use Tail" off)."""
    chain = set(leg.bones)
    for k, name in enumerate(leg.bones):
        for c in obj.pose.bones[name].constraints:
            if c.type != "IK" or not c.enabled or c.influence <= 0.0 or c.target != obj:
                continue
            target = c.subtarget
            if target not in rest.index or target in chain:
                continue
            # A target that moves with the chain itself would be a dependency cycle.
            if any(rest.names[a] in chain for a in rest.ancestors(rest.index[target])):
                continue
            return target, (k + 1 if c.use_tail else k)
    return None


def _descendants(rest: _Rest, i: int) -> list[int]:
    out = []
    stack = rest.children(i)
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(rest.children(j))
    return out


def _common_ancestor(rest: _Rest, idx: Sequence[int]) -> int | None:
    """The deepest bone that is a proper ancestor of every bone in ``idx``."""
    common: list[int] | None = None
    for i in idx:
        anc = rest.ancestors(i)
        common = anc if common is None else [a for a in common if a in set(anc)]
    return common[0] if common else None


def _spine_chain(
    rest: _Rest, body: int, hips: Sequence[int], forward: np.ndarray, leg_length: float
) -> list[int]:
    """The spine chain from the body bone to the head, parent to child (see the module doc).

    A spine bone lies on the body's midline (its ends within 3 % of a leg length of the
    vertical plane through the hips' centre and ``forward``), points forward, starts where
    its parent ends (within a quarter of the parent's length), is not a leg's hip and has no
    helper name. At each bone the chain takes the such child whose subtree holds the most
    hips; when none holds any (past the last girdle), the one reaching furthest forward.
    """
    centre = rest.head[list(hips)].mean(axis=0)
    left = np.cross(_UP, forward)
    tol = 0.03 * leg_length
    hip_set = set(hips)
    below: dict[int, int] = {}

    def carried(i: int) -> int:
        if i not in below:
            below[i] = sum(1 for h in hips if i in rest.ancestors(h))
        return below[i]

    def spine_like(parent: int, i: int) -> bool:
        if i in hip_set or _is_helper_name(split_name(rest.names[i])[1]):
            return False
        ends = np.stack([rest.head[i], rest.tail[i]])
        if np.abs((ends - centre) @ left).max() > tol:
            return False
        parent_len = float(np.linalg.norm(rest.tail[parent] - rest.head[parent]))
        if np.linalg.norm(rest.head[i] - rest.tail[parent]) > 0.25 * parent_len + 1e-9 * rest.scale:
            return False
        return float((rest.tail[i] - rest.head[i]) @ forward) > 1e-3 * leg_length

    chain = [body]
    while len(chain) < len(rest.names):
        kids = [k for k in rest.children(chain[-1]) if spine_like(chain[-1], k)]
        if not kids:
            break
        holding = [k for k in kids if carried(k)]
        if holding:
            chain.append(max(holding, key=lambda k: (carried(k), -k)))
        else:
            chain.append(max(kids, key=lambda k: (float(rest.tail[k] @ forward), -k)))
    return chain


def _carriers(rest: _Rest, chain: Sequence[int], hips: Sequence[int]) -> list[int]:
    """Per hip, the position in ``chain`` of its nearest spine ancestor."""
    where = {b: i for i, b in enumerate(chain)}
    return [next(where[a] for a in rest.ancestors(h) if a in where) for h in hips]


def _spine_layout(rest: _Rest, chain: Sequence[int], hips: Sequence[int], heads: np.ndarray,
                  tails: np.ndarray) -> SpineLayout | None:
    """The core spine of ``chain`` (see :class:`SpineLayout`) from the rig's rest heads and
    tails ``(B, 3)``, or None when the legs do not make two girdles with a head in front."""
    n = len(chain)
    if n < 2:
        return None
    order = list(chain)[::-1]  # head bone first: core bone i is order[i]
    joints = np.vstack([tails[order[0]][None], heads[order]])
    core_of = {b: i for i, b in enumerate(order)}
    leg_bone = np.array([core_of[chain[c]] for c in _carriers(rest, chain, hips)], dtype=np.int64)
    back = int(leg_bone.max())  # the back-most carrier bone
    key_of_bone: dict[int, int] = {}
    for b in sorted(set(leg_bone.tolist())):
        if b == back:
            key_of_bone[b] = n  # the back girdle: the body bone's head, the chain's last joint
            continue
        mine = np.array([heads[h] for h, lb in zip(hips, leg_bone, strict=True) if lb == b]).mean(axis=0)
        # the end of the carrier bone nearest its legs' hips: joint b (front) or b + 1 (back)
        front_nearer = np.linalg.norm(joints[b] - mine) <= np.linalg.norm(joints[b + 1] - mine)
        key_of_bone[b] = b if front_nearer else b + 1
    keys = sorted(set(key_of_bone.values()))
    if keys[0] == 0 or len(keys) < 2:
        return None  # legs at the head, or one girdle only
    key_joint = np.array([0, *keys], dtype=np.int64)
    leg_key = np.array([int(np.searchsorted(key_joint, key_of_bone[int(b)])) for b in leg_bone],
                       dtype=np.int64)
    return SpineLayout(joints=joints, key_joint=key_joint, leg_key=leg_key, leg_bone=leg_bone)


def _current_basis(obj: bpy.types.Object) -> dict[str, np.ndarray]:
    pose = obj.pose
    n = len(pose.bones)
    buf = np.empty(n * 16, dtype=np.float32)
    pose.bones.foreach_get("matrix_basis", buf)
    mats = buf.reshape(n, 4, 4).transpose(0, 2, 1).astype(np.float64)
    return {pb.name: mats[i] for i, pb in enumerate(pose.bones)}


def _posed_rest(rest: _Rest, basis: dict[str, np.ndarray], driven: set[int]) -> np.ndarray:
    """Armature-space matrices of every bone with driven bones at rest and the others as
    currently posed (their pose persists under the generated Action). ``(B, 4, 4)``."""
    n = len(rest.names)
    out = np.empty((n, 4, 4))
    done = np.zeros(n, dtype=bool)

    def solve(i: int) -> np.ndarray:
        if done[i]:
            return out[i]
        b = np.eye(4) if i in driven else basis[rest.names[i]]
        p = int(rest.parent[i])
        if p < 0:
            out[i] = rest.local[i] @ b
        else:
            out[i] = solve(p) @ np.linalg.inv(rest.local[p]) @ rest.local[i] @ b
        done[i] = True
        return out[i]

    for i in range(n):
        solve(i)
    return out


# ---------------------------------------------------------------------------------------
# Core morphology


def morphology_of(
    info: RigInfo,
    joint_yaw_limit: float = DEFAULT_JOINT_YAW_LIMIT,
    joint_pitch_limit: float = DEFAULT_JOINT_PITCH_LIMIT,
) -> Morphology:
    """The core morphology of the rig, in its body frame (origin at the hips' centroid).

    The end-effectors are the core's feet. A leg whose foot bones hold its end-effector above
    the ground (a human's ankle) is handled by the caller, which raises the terrain the core
    sees by :attr:`RigInfo.foot_height` (see ``locomotion.generate``). With a
    :attr:`RigInfo.spine_layout` the morphology has the flexible spine
    (``Morphology.with_spine``) with these per-joint limits (radians).
    """
    to_body = np.linalg.inv(info.body.matrix)
    chains = [_apply(to_body, j) for j in info.joints]
    hips = np.array([c[0] for c in chains])
    ends = np.array([c[-1] for c in chains])
    if float(np.mean(hips[:, 2] - ends[:, 2])) <= 0.0:
        raise RigError("The hips are not above the feet: the rig must stand on its legs in its rest pose")
    lo, hi = hips[:, :2].min(axis=0), hips[:, :2].max(axis=0)
    reach = float(info.leg_length.mean())
    # The footprint the planner keeps clear: at least 4 % of the leg, and as far as the foot
    # bones (toes, paw) reach from the end-effector (its box is centred on the end-effector).
    foot_half = np.maximum(FOOT_EXTENT_SHARE * info.foot_extent.max(axis=0), 0.04 * reach)
    try:
        morph = Morphology.from_rest_joints(
            chains,
            [leg.label for leg in info.legs],
            body_box=(0.5 * (lo + hi), 0.5 * (hi - lo) + 0.1 * reach),
            foot_half_extents=foot_half,
        )
        layout = info.spine_layout
        if layout is not None:
            morph = morph.with_spine(
                _apply(to_body, layout.joints), key_joint=layout.key_joint, leg_key=layout.leg_key,
                leg_bone=layout.leg_bone, joint_yaw_limit=joint_yaw_limit,
                joint_pitch_limit=joint_pitch_limit,
            )
        return morph
    except ValueError as err:
        raise RigError(str(err)) from err


# ---------------------------------------------------------------------------------------
# Poses back to bones


@dataclass(frozen=True)
class PoseTracks:
    """Per-frame ``matrix_basis`` components of the driven bones.

    ``rotations`` ``(F, B, 4)`` quaternions (w, x, y, z); ``locations`` ``(F, B, 3)``;
    ``keyed_location[b]`` says whether bone ``b``'s location should be keyed.
    """

    bones: tuple[str, ...]
    rotations: np.ndarray
    locations: np.ndarray
    keyed_location: np.ndarray


def matrix_to_quaternion(m: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices -> ``(..., 4)`` unit quaternions (w, x, y, z), w >= 0."""
    m = np.asarray(m, dtype=np.float64)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # |w|, |x|, |y|, |z| from the diagonal; signs from the off-diagonal terms relative to
    # the largest component (Shepperd's method, numerically stable for any rotation).
    diag = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    k = np.argmax(diag, axis=-1)
    s21, s02, s10 = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    a01, a02, a12 = m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1]
    rows = np.stack([
        np.stack([diag[..., 0], s21, s02, s10], -1),
        np.stack([s21, diag[..., 1], a01, a02], -1),
        np.stack([s02, a01, diag[..., 2], a12], -1),
        np.stack([s10, a02, a12, diag[..., 3]], -1),
    ], axis=-2)  # row k is proportional to q * q_k
    q = np.take_along_axis(rows, k[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def _length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-300)


def _frames(direction: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(..., 3, 3)`` with columns (direction, normal made perpendicular, cross)."""
    e1 = _unit(direction)
    e2 = normal - np.sum(normal * e1, axis=-1, keepdims=True) * e1
    e2 = _unit(e2)
    e3 = np.cross(e1, e2)
    return np.stack([e1, e2, e3], axis=-1)


def _bend_normal(joints: np.ndarray) -> np.ndarray:
    """Sum of consecutive segment cross products ``(..., 3)`` for chains ``(..., k + 1, 3)``."""
    seg = np.diff(joints, axis=-2)
    if seg.shape[-2] < 2:
        return np.zeros((*seg.shape[:-2], 3))
    return np.cross(seg[..., :-1, :], seg[..., 1:, :]).sum(axis=-2)


def _yaw_only(rot: np.ndarray) -> np.ndarray:
    """The rotation about world Z that turns the x axis like ``rot`` does ``(..., 3, 3)``."""
    x = rot[..., :, 0]
    ang = np.arctan2(x[..., 1], x[..., 0])
    c, s = np.cos(ang), np.sin(ang)
    out = np.zeros(rot.shape)
    out[..., 0, 0] = c
    out[..., 0, 1] = -s
    out[..., 1, 0] = s
    out[..., 1, 1] = c
    out[..., 2, 2] = 1.0
    return out


#: ``ground(frame_index (n,), xy (n, 2)) -> (n,)`` world surface heights, ``-inf`` over nothing.
GroundFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _foot_pitch(
    rel: np.ndarray, end: np.ndarray, heights: np.ndarray, limit: float,
    lift: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pitch ``(F,)`` about each foot's horizontal cross axis that sets its sole on the ground.

    rel: ``(F, P, 3)`` sole points relative to the end-effector ``end`` ``(F, 3)`` (foot at its
    yaw-turned rest orientation); heights ``(F, P)`` ground under them. The smallest rotation
    keeping every forward point above the ground: up a slope or onto an edge the toes lift,
    down a slope they follow it. Points behind the end-effector (heels) are left alone.
    ``lift`` ``(F,)``: how far the end-effector is above where it stands when planted (``inf``
    over no ground); the downward pitch fades out as the foot rises by half its length, so a
    lifted foot does not point its toes at the ground below (swing, or over a gap).
    """
    d = rel[..., :2].sum(axis=1)
    d_norm = np.linalg.norm(d, axis=-1, keepdims=True)
    d = np.divide(d, d_norm, out=np.zeros_like(d), where=d_norm > 1e-12)
    a = np.einsum("fpi,fi->fp", rel[..., :2], d)  # forward reach of each point
    b = rel[..., 2]
    c = heights - end[:, None, 2]
    radius = np.hypot(a, b)
    ok = (a > 1e-6 * np.maximum(radius, 1e-12)) & np.isfinite(heights)
    need = np.arcsin(np.clip(c / np.maximum(radius, 1e-12), -1.0, 1.0)) - np.arctan2(b, a)
    theta = np.where(ok, need, -np.inf).max(axis=1)
    theta = np.where(np.isfinite(theta), theta, 0.0)
    if lift is not None:
        fade = 0.5 * np.where(ok, radius, 0.0).max(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.clip(1.0 - np.maximum(lift, 0.0) / np.maximum(fade, 1e-12), 0.0, 1.0)
        theta = np.where(theta < 0.0, theta * np.nan_to_num(share, nan=0.0), theta)
    return np.clip(theta, -limit, limit), d


def _axis_rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotations ``(F, 3, 3)`` by ``angle (F,)`` about unit ``axis (F, 3)`` (Rodrigues)."""
    k = axis
    kx = np.zeros((*k.shape[:-1], 3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    s = np.sin(angle)[..., None, None]
    c = np.cos(angle)[..., None, None]
    return np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)


def solve_pose(
    info: RigInfo,
    body_world: np.ndarray,
    joints_world: Sequence[np.ndarray],
    ground: GroundFn | None = None,
    max_foot_pitch: float = np.radians(50.0),
    *,
    spine_rotation: np.ndarray | None = None,
    spine_joints: np.ndarray | None = None,
    leg_frames: np.ndarray | None = None,
) -> PoseTracks:
    """Pose-bone channels that put the rig where the core says, frame by frame.

    body_world: ``(F, 4, 4)`` rigid body-to-world transforms (the body frame of
    :class:`BodyInfo` moved by the simulation). joints_world: per leg ``(F, k + 1, 3)``
    world joint positions (hip, inner joints, end-effector), in ``info.legs`` order.

    Each leg bone's rotation maps its rest segment onto the simulated one and its rest
    leg-plane normal onto the simulated plane's normal (no added twist; a straight leg keeps
    the body-turned rest normal). The body bone moves rigidly with the body frame; the first
    foot bone keeps its rest orientation turned by the body's heading and, when ``ground``
    is given (:data:`GroundFn`), pitches about its cross axis so its sole lies on the ground
    (toes lift onto slopes and edges, up to ``max_foot_pitch``).

    With a driven spine (:attr:`RigInfo.spine_layout`), ``spine_rotation`` ``(F, J - 1, 3, 3)``
    (``core.spine.SpinePose.bone_rotation``: each core bone's rotation from its rest direction
    in the body frame to the world) turns the spine bones, the body bone's head goes to
    ``spine_joints[:, -1]`` (``(F, J, 3)``), and ``leg_frames`` ``(F, L, 3, 3)`` (body-to-world
    rotation each leg hangs from) turns each leg's rest knee plane and foot instead of the
    body frame.
    """
    body_world = np.asarray(body_world, dtype=np.float64)
    n_frames = body_world.shape[0]
    delta = body_world @ np.linalg.inv(info.body.matrix)[None]  # (F, 4, 4) rest body -> current
    delta_rot = delta[:, :3, :3]
    body_rest_t = info.body.matrix[:3, :3].T  # world rest -> body frame
    n_legs = len(info.legs)
    if leg_frames is None:
        leg_delta = np.broadcast_to(delta_rot[:, None], (n_frames, n_legs, 3, 3))
    else:
        leg_delta = np.asarray(leg_frames, dtype=np.float64) @ body_rest_t
    leg_yaw = _yaw_only(leg_delta)
    spine_on = info.spine_layout is not None
    if spine_on and (spine_rotation is None or spine_joints is None):
        raise ValueError("the rig's spine is driven: give its spine_rotation and spine_joints")
    w = info.world
    w_rot = w[:3, :3] / info.scale
    w_inv = np.linalg.inv(w)

    # Desired world rotation (F, 3, 3) of every driven bone; world head of the body bone.
    rest_rot = {n: w_rot @ (m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0))
                for n, m in info.rest_local.items()}
    desired: dict[str, np.ndarray] = {}
    desired[info.body_bone] = delta_rot @ rest_rot[info.body_bone]
    body_head_rest = _apply(w, info.rest_local[info.body_bone][:3, 3][None])[0]
    body_head = np.einsum("fij,j->fi", delta[:, :3, :3], body_head_rest) + delta[:, :3, 3]
    if spine_on:
        assert spine_rotation is not None
        assert spine_joints is not None
        turn = np.asarray(spine_rotation, dtype=np.float64) @ body_rest_t  # world rest -> now
        for i, name in enumerate(info.spine[::-1]):  # core bones run from the head back
            desired[name] = turn[:, i] @ rest_rot[name]
        body_head = np.asarray(spine_joints, dtype=np.float64)[:, -1]

    for k, (leg, rest_j, cur_j) in enumerate(zip(info.legs, info.joints, joints_world, strict=True)):
        cur_j = np.asarray(cur_j, dtype=np.float64)
        want = (n_frames, len(leg.bones) + 1, 3)
        if cur_j.shape != want:
            raise ValueError(f"leg {leg.label}: joints shape {cur_j.shape}, expected {want}")
        n_rest = _bend_normal(rest_j)
        if np.linalg.norm(n_rest) < 1e-9 * max(float(np.linalg.norm(np.diff(rest_j, axis=0))), 1e-9) ** 2:
            # straight rest leg: bend like a knee, about the body's left axis
            n_rest = np.cross(rest_j[-1] - rest_j[0], info.body.forward)
        n_rest = _unit(n_rest)
        n_turned = np.einsum("fij,j->fi", leg_delta[:, k], n_rest)
        n_cur = _bend_normal(cur_j)
        size = np.linalg.norm(n_cur, axis=-1)
        scale2 = np.sum(np.diff(cur_j, axis=1) ** 2, axis=(1, 2))
        weak = size < 1e-4 * scale2
        n_cur = np.where(weak[:, None], n_turned, _unit(n_cur))
        flip = np.sum(n_cur * n_turned, axis=-1) < 0.0
        n_cur = np.where(flip[:, None], -n_cur, n_cur)
        seg_rest = np.diff(rest_j, axis=0)
        seg_cur = np.diff(cur_j, axis=1)
        for b, name in enumerate(leg.bones):
            f_rest = _frames(seg_rest[b], n_rest)
            f_cur = _frames(seg_cur[:, b], n_cur)
            desired[name] = f_cur @ np.swapaxes(f_rest, -1, -2)[None] @ rest_rot[name]
        if leg.foot:
            desired[leg.foot[0]] = leg_yaw[:, k] @ rest_rot[leg.foot[0]]

    # Bones that IK constraints pull the legs to: placed where the simulated joint is,
    # turned with the body's heading.
    moved_heads: dict[str, np.ndarray] = {info.body_bone: body_head}
    for k, target in enumerate(info.ik_targets):
        if target is None:
            continue
        bone, joint = target
        desired[bone] = leg_yaw[:, k] @ rest_rot[bone]
        moved_heads[bone] = np.asarray(joints_world[k], dtype=np.float64)[:, joint]

    if ground is not None:
        _pitch_feet(info, joints_world, leg_yaw, rest_rot, desired, ground, max_foot_pitch)

    bones = info.driven_bones
    # Armature-space pose matrices, parents before children.
    order = _hierarchy_order(info, bones)
    pose: dict[str, np.ndarray] = {}
    basis_out: dict[str, np.ndarray] = {}
    for name in order:
        parent = info.parents[name]
        rest_l = info.rest_local[name]
        if parent is None:
            base = np.broadcast_to(rest_l, (n_frames, 4, 4))
        else:
            base = pose[parent] @ (np.linalg.inv(info.rest_local[parent]) @ rest_l)[None]
        if name in desired:
            goal = np.empty((n_frames, 4, 4))
            goal[:, :3, :3] = np.swapaxes(w_rot, 0, 1)[None] @ desired[name]
            if name in moved_heads:
                goal[:, :3, 3] = _apply(w_inv, moved_heads[name])
            else:
                goal[:, :3, 3] = base[:, :3, 3]  # heads follow their parents
            goal[:, 3] = (0.0, 0.0, 0.0, 1.0)
            basis = np.linalg.inv(base) @ goal
            basis_out[name] = basis
            pose[name] = base @ basis
        else:
            pose[name] = base @ info.basis[name][None]

    rotations = np.stack([matrix_to_quaternion(_orthonormal(basis_out[b][:, :3, :3])) for b in bones], axis=1)
    locations = np.stack([basis_out[b][:, :3, 3] for b in bones], axis=1)
    keyed = np.array([b in moved_heads for b in bones])
    return PoseTracks(bones, rotations, locations, keyed)


def _pitch_feet(info: RigInfo, joints_world: Sequence[np.ndarray], leg_yaw: np.ndarray,
                rest_rot: dict[str, np.ndarray], desired: dict[str, np.ndarray], ground: GroundFn,
                limit: float) -> None:
    """Turn each leg's first foot bone so its sole follows the ground (see :func:`solve_pose`).
    ``leg_yaw`` ``(F, L, 3, 3)``: the heading turn of what each leg hangs from."""
    dynamic = bool(getattr(ground, "dynamic", True))
    legs = [k for k, leg in enumerate(info.legs) if leg.foot and info.foot_points[k].shape[0]]
    if not legs:
        return
    n_frames = leg_yaw.shape[0]
    rels, ends = [], []
    for k in legs:
        ends.append(np.asarray(joints_world[k], dtype=np.float64)[:, -1])
        rels.append(np.einsum("fij,pj->fpi", leg_yaw[:, k], info.foot_points[k] - info.joints[k][-1]))
    counts = [r.shape[1] for r in rels]
    bounds = np.cumsum([0, *counts])
    turns = [np.eye(3)[None].repeat(n_frames, axis=0) for _ in legs]
    pitched: list[np.ndarray | None] = [None] * len(legs)
    # How far each end-effector is above where it would stand on the ground under it.
    end_xy = np.concatenate([end[:, :2] for end in ends])
    end_frame = np.tile(np.arange(n_frames), len(legs))
    under = np.asarray(ground(end_frame if dynamic else np.zeros_like(end_frame), end_xy), dtype=np.float64)
    lifts = [end[:, 2] - info.foot_height[k] - under[j * n_frames:(j + 1) * n_frames]
             for j, (k, end) in enumerate(zip(legs, ends, strict=True))]
    # Pitching moves the sole points sideways too, onto other ground: a few passes (heights
    # where the pitched points are, the pitch from the rest sole). After the first the pitch
    # only rises: a toe pitched down past an edge onto the higher ground it now stands over
    # is lifted, never pitched down again (a down-and-up swing could end inside the edge).
    for _ in range(3):
        xy = np.concatenate([end[:, None, :2] + np.einsum("fij,fpj->fpi", turn, rel)[..., :2]
                             for turn, rel, end in zip(turns, rels, ends, strict=True)], axis=1)
        # Planted feet query the same places frame after frame: ask once per distinct place.
        frame_of = np.repeat(np.arange(n_frames), xy.shape[1])
        flat = xy.reshape(-1, 2)
        key = frame_of if dynamic else np.zeros_like(frame_of)
        uniq, inverse = np.unique(np.column_stack([key, flat]), axis=0, return_inverse=True)
        found = np.asarray(ground(uniq[:, 0].astype(np.int64), uniq[:, 1:]), dtype=np.float64)
        heights = found[inverse.reshape(-1)].reshape(xy.shape[:2])
        for j, (rel, end) in enumerate(zip(rels, ends, strict=True)):
            theta, d = _foot_pitch(rel, end, heights[:, bounds[j]:bounds[j + 1]], limit, lifts[j])
            before = pitched[j]
            if before is not None:
                theta = np.maximum(theta, before)
            pitched[j] = theta
            axis = np.cross(np.concatenate([d, np.zeros((n_frames, 1))], axis=1), _UP)
            axis_n = np.linalg.norm(axis, axis=1, keepdims=True)
            axis = np.divide(axis, axis_n, out=np.zeros_like(axis), where=axis_n > 1e-12)
            turns[j] = _axis_rotation(axis, np.where(axis_n[:, 0] > 1e-12, theta, 0.0))
    for j, k in enumerate(legs):
        name = info.legs[k].foot[0]
        desired[name] = turns[j] @ desired[name]


def _orthonormal(m: np.ndarray) -> np.ndarray:
    u, _s, vt = np.linalg.svd(m)
    return u @ vt


def _hierarchy_order(info: RigInfo, bones: Sequence[str]) -> list[str]:
    """``bones`` and all their ancestors, parents first."""
    needed: list[str] = []
    for b in bones:
        chain = []
        cur: str | None = b
        while cur is not None and cur not in needed and cur not in chain:
            chain.append(cur)
            cur = info.parents[cur]
        needed.extend(reversed(chain))
    depth = {}
    for b in needed:
        d = 0
        cur = info.parents[b]
        while cur is not None:
            d += 1
            cur = info.parents[cur]
        depth[b] = d
    return sorted(dict.fromkeys(needed), key=lambda b: depth[b])
