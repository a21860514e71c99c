# SPDX-License-Identifier: GPL-3.0-or-later
"""Leg detection on rest arrays (numpy only): candidate chains by names and by topology,
which of them are legs, their flat foot bones, the forward axis and the L/R labels."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .names import (
    _is_control_name,
    _is_leg_name,
    _is_non_leg_name,
    _leg_number,
    split_name,
)
from .rest import _UP, RigError, _chain_points, _continuing_child, _descendants, _length, _Rest

#: Words of the bones that show which way a creature faces.
HEAD_WORDS = frozenset({"head", "neck", "skull", "snout", "muzzle", "cephalothorax"})


@dataclass(frozen=True)
class LegChain:
    """One leg: ``bones`` hip to end-effector (parent to child), then the flat ``foot`` bones."""

    bones: tuple[str, ...]
    foot: tuple[str, ...] = ()
    side: int = 0
    label: str = ""
    # Why detection chose it ("reaches the ground; mirrored pair; name"); empty when set by hand.
    reason: str = ""

    @property
    def hip(self) -> str:
        return self.bones[0]

    @property
    def end(self) -> str:
        return self.bones[-1]


#: A chain's last bone shorter than this share of the chain is a foot bone (a hoof), however steep.
TIP_SHARE = 0.1


def _split_foot(rest: _Rest, idx: list[int]) -> tuple[list[int], list[int]]:
    """Split a hip-to-tip chain into the IK part and the trailing flat foot bones.

    A trailing bone is part of the foot when both its ends are within 20 % of the leg's length
    above the lowest point and it lies nearly flat (less than 45 degrees from horizontal) or,
    the chain's last bone, is short (under :data:`TIP_SHARE` of the chain: a hoof or a claw
    pointing down, which the IK would swing about its joint as a segment of the leg). At least
    two bones stay in the IK part.
    """
    pts = _chain_points(rest, idx)
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    ground = float(pts[:, 2].min())
    band = 0.2 * length
    cut = len(idx)
    while cut > 2:
        b = idx[cut - 1]
        d = rest.end[b] - rest.head[b]
        if np.linalg.norm(d) <= 1e-9 * max(length, 1e-12):
            cut -= 1  # a leaf of unknown extent (imported rig): where the foot starts, never a joint
            continue
        horiz = float(np.linalg.norm(d[:2]))
        flat = abs(d[2]) < horiz or (cut == len(idx) and float(np.linalg.norm(d)) < TIP_SHARE * length)
        low = rest.head[b, 2] - ground < band and rest.end[b, 2] - ground < band
        if flat and low:
            cut -= 1
        else:
            break
    return idx[:cut], idx[cut:]


def _foot_after(rest: _Rest, end: int) -> list[int]:
    """Flat bones continuing below/after a user-chosen end-effector (at most two), never a
    control or helper bone (an imported ``l_shin``'s tail points at ``l_shin_twist1``)."""
    out: list[int] = []
    cur = end
    chain_len = float(np.linalg.norm(rest.end[end] - rest.head[end]))
    control = _control_bones(rest)
    for _ in range(2):
        allowed = {c for c in rest.children(cur) if not control[c]}
        nxt = _continuing_child(rest, cur, allowed) if allowed else None
        if nxt is None:
            break
        d = rest.end[nxt] - rest.head[nxt]
        if abs(d[2]) >= np.linalg.norm(d[:2]) or rest.head[nxt, 2] > rest.end[end, 2] + 0.5 * chain_len:
            break
        out.append(nxt)
        cur = nxt
    return out


def _segments(rest: _Rest) -> np.ndarray:
    """``(B,)`` bool: bones that are a segment of their chain, a child hanging from their far
    joint (Genesis' ``lThighTwist``, the thigh's lower half with the shin at its end)."""
    out = np.zeros(len(rest.names), dtype=bool)
    for i in range(len(rest.names)):
        length = float(np.linalg.norm(rest.end[i] - rest.head[i]))
        if length > 0.0 and any(np.linalg.norm(rest.head[c] - rest.end[i]) <= 0.01 * length
                                for c in rest.children(i)):
            out[i] = True
    return out


def _control_bones(rest: _Rest) -> np.ndarray:
    """``(B,)`` bool: bones named as controls or helpers (IK targets, poles, twist helpers...),
    not counting limb segments named twist (:func:`_segments`)."""
    segment = _segments(rest)
    return np.array([_is_control_name(split_name(n)[1], bool(segment[i])) for i, n in enumerate(rest.names)],
                    dtype=bool)


def _name_chains(rest: _Rest) -> list[list[int]]:
    info = [split_name(n) for n in rest.names]
    segment = _segments(rest)
    legish = [_is_leg_name(t, bool(segment[i])) for i, (_s, t) in enumerate(info)]
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


#: A chain stands on the ground when the lowest point of its limb is within this share of
#: its length of the lowest limb's.
STAND_SHARE = 0.02
#: Where two chains or more stand on the ground, a chain whose limb stays this share of
#: their mean length above it hangs: a scorpion's or a crab's claws held just above the
#: floor, a kangaroo's forelegs; not a leg when another hangs as high (a mirrored pair).
HANG_SHARE = 0.05


def _standing(rest: _Rest, chains: Sequence[Sequence[int]]) -> list[bool]:
    """Which of ``chains`` stand on the ground rather than hang above it (:data:`HANG_SHARE`)
    with another chain hanging as high (within :data:`STAND_SHARE` of the standing chains'
    length): claws and forelegs come in pairs, while a paw raised alone in the rest pose is
    still a leg. A limb reaches as low as its chain and every bone below the chain's end (a
    name run that stops at the shin, ``thigh.L > shin.L``, goes on down to the paw)."""
    if len(chains) < 3:
        return [True] * len(chains)
    points = [_chain_points(rest, c) for c in chains]
    reach = np.array([min(float(p[:, 2].min()), float(_subtree_points(rest, c[-1])[:, 2].min()))
                      for p, c in zip(points, chains, strict=True)])
    lengths = np.array([_length(p) for p in points])
    gap = reach - float(reach.min())
    standing = gap <= STAND_SHARE * lengths
    if int(standing.sum()) < 2:
        return [True] * len(chains)
    # Judged against the standing chains' length: a claw's own length says nothing of how
    # far above the feet it is held.
    ref = float(lengths[standing].mean())
    hanging = gap > HANG_SHARE * ref
    paired = np.abs(gap[:, None] - gap[None, :]) <= STAND_SHARE * ref
    np.fill_diagonal(paired, False)
    return (~(hanging & (paired & hanging[None, :]).any(axis=1))).tolist()


def _dedupe(rest: _Rest, chains: list[list[int]], constrained: np.ndarray) -> list[list[int]]:
    """Keep one chain per leg where a rig has parallel copies (Rigify's ORG-/DEF- bones):
    chains whose hips and tips coincide are one leg; the copy with the fewest constrained
    bones (``constrained`` ``(B,)`` bool: the bone has an overriding constraint) wins, then
    the one with the fewest bones."""

    def count(chain: list[int]) -> int:
        return sum(1 for i in chain if constrained[i])

    ranked = sorted(chains, key=lambda c: (count(c), len(c), c[0]))
    kept: list[list[int]] = []
    for chain in ranked:
        pts = _chain_points(rest, chain)
        tol = 0.02 * _length(pts)
        # The tips, or the last bones' heads: a leaf toe's far end is a guess that differs
        # between the copies (an ORG toe with children, a DEF toe without).
        if any(np.linalg.norm(pts[0] - _chain_points(rest, k)[0]) < tol
               and (np.linalg.norm(pts[-1] - _chain_points(rest, k)[-1]) < tol
                    or np.linalg.norm(pts[-2] - _chain_points(rest, k)[-2]) < tol) for k in kept):
            continue
        kept.append(chain)
    return sorted(kept, key=lambda c: c[0])

def _rig_ground(rest: _Rest) -> float:
    """The rig's lowest point along world up, over every bone that is not a control."""
    control = _control_bones(rest)
    keep = [i for i in range(len(rest.names)) if not control[i] and not rest.phantom[i]]
    if not keep:
        keep = list(range(len(rest.names)))
    return float(min(rest.head[keep, 2].min(), rest.end[keep, 2].min()))


def _subtree_points(rest: _Rest, i: int) -> np.ndarray:
    idx = [i, *_descendants(rest, i)]
    return np.vstack([rest.head[idx], rest.end[idx]])


def _ground_chains(rest: _Rest) -> list[list[int]]:
    """Chains by what a leg is: from each leaf up to where it joins the body, then down again.

    Walking up from a leaf, a branch is passed when every other child of it is an appendage
    of the same limb: a small one (reaching less than half as far from the branch as the
    limb walked so far: a twist or helper bone) or a low one (all of it below half the
    branch's height above the rig's lowest point, or in the lowest 15 % of the rig's height:
    toes, a heel, a paw's pads). The first branch carrying anything else (another leg, the
    spine, an arm) is the body; the bone below it is the hip. From each hip the chain goes
    down through the continuing child (:func:`.rest._continuing_child`) to a leaf. Control
    bones (IK targets, poles) are ignored, and so are bones with a non-leg name (jaw, tail,
    skirt...) where they branch off a limb: VRoid hangs its dress from the thighs, and the
    thigh stays the hip. Chains with a non-leg name are dropped.
    """
    names = [split_name(n)[1] for n in rest.names]
    non_leg = np.array([_is_non_leg_name(t) for t in names], dtype=bool)
    control = _control_bones(rest)
    ground = _rig_ground(rest)
    # Bones this low belong to the feet (a paw's pads and fingers, a hoof's parts).
    foot_band = 0.15 * (float(max(rest.head[:, 2].max(), rest.end[:, 2].max())) - ground)
    n = len(rest.names)
    kids = [rest.children(i) for i in range(n)]
    subtree: dict[int, np.ndarray] = {}  # the walk up from every leaf asks for the same ones

    def appendage(branch: int, other: int, path: list[int]) -> bool:
        if other not in subtree:
            subtree[other] = _subtree_points(rest, other)
        pts = subtree[other]
        reach = float(np.linalg.norm(pts - rest.head[branch], axis=1).max())
        ours = np.vstack([rest.head[path], rest.end[path]])
        if reach < 0.5 * float(np.linalg.norm(ours - rest.head[branch], axis=1).max()):
            return True
        low = max(0.5 * (float(rest.head[branch, 2]) - ground), foot_band)
        return float(pts[:, 2].max()) - ground <= low

    hips: set[int] = set()
    for leaf in range(n):
        if kids[leaf] or control[leaf] or rest.phantom[leaf]:
            continue
        cur, path = leaf, [leaf]
        while True:
            p = int(rest.parent[cur])
            if p < 0:
                cur = -1  # hangs from nothing: not a limb of a body
                break
            others = [c for c in kids[p] if c != cur and not control[c] and not non_leg[c]]
            if others and not all(appendage(p, c, path) for c in others):
                break
            cur = p
            path.append(p)
        if cur >= 0:
            hips.add(cur)
    chains = []
    for hip in sorted(hips):
        chain = [hip]
        while True:
            allowed = {c for c in kids[chain[-1]] if not control[c]}
            allowed = {c for c in allowed if not non_leg[c]} or allowed
            nxt = _continuing_child(rest, chain[-1], allowed) if allowed else None
            if nxt is None:
                break
            chain.append(nxt)
        if any(control[b] or _is_non_leg_name(names[b]) for b in chain):
            continue
        chains.append(chain)
    return chains


def _merge_names(rest: _Rest, geo: list[list[int]], named: list[list[int]]) -> list[tuple[list[int], str]]:
    """Geometric chains, each starting at the hip its name run gives when one covers most of
    it (names say where a leg starts: a wolf's ``front_thigh``, not its ``shoulder``); named
    chains reaching the ground that geometry missed are kept too. ``(chain, reason)`` pairs."""
    out: list[tuple[list[int], str]] = []
    used: set[int] = set()
    for g in geo:
        where = {b: k for k, b in enumerate(g)}
        reason = "reaches the ground"
        best = g
        for m, chain in enumerate(named):
            if chain[0] not in where:
                continue
            cut = g[where[chain[0]]:]
            drop_cut = float(rest.head[cut[0], 2] - _chain_points(rest, cut)[:, 2].min())
            drop_all = float(rest.head[g[0], 2] - _chain_points(rest, g)[:, 2].min())
            used.add(m)
            if len(cut) >= 2 and drop_cut >= 0.5 * drop_all:
                # the named run itself when it lies along the chain (it ends where names say)
                best = list(chain) if cut[:len(chain)] == list(chain) else cut
                reason = "reaches the ground; name"
        out.append((best, reason))
    taken = {b for chain, _r in out for b in chain}
    for m, chain in enumerate(named):
        if m not in used and not (set(chain) & taken):
            out.append((chain, "name; reaches the ground"))
    return out


#: A leg's hip stands at least this share of the highest hip's height above the ground.
HIP_SHARE = 1.0 / 3.0


def _chains_along(rest: _Rest) -> list[tuple[list[int], str]]:
    """The leg chains of ``rest`` with world +Z up, and why each was chosen.

    A chain whose hip is low beside the others' (under :data:`HIP_SHARE` of the highest
    hip's height above the ground) is not a leg: it is a foot control hanging from the root
    (an IK bone with its toe bone, ``CTRL_foot.L > CTRL_toe.L``, MMD's leg IK), not a limb
    carrying the body. Of the others, a chain hanging above the ground the rest stand on
    (:func:`_standing`) is not a leg either, whatever its bones are called: a scorpion's
    pincer arms ``ClawArm1.L > ... > ClawFinger.L``, a kangaroo's forelegs.
    """
    named = [c for c in _name_chains(rest)
             if not any(_is_non_leg_name(split_name(rest.names[b])[1]) for b in c)]
    found = _merge_names(rest, _valid_legs(rest, _ground_chains(rest)), _valid_legs(rest, named))
    if not found:
        return found
    ground = min(float(_chain_points(rest, c)[:, 2].min()) for c, _r in found)
    hip = np.array([float(rest.head[c[0], 2]) - ground for c, _r in found])
    found = [f for f, h in zip(found, hip.tolist(), strict=True) if h >= HIP_SHARE * float(hip.max())]
    return [f for f, stands in zip(found, _standing(rest, [c for c, _r in found]), strict=True) if stands]


_AXES = {"+X": (1.0, 0.0, 0.0), "-X": (-1.0, 0.0, 0.0), "+Y": (0.0, 1.0, 0.0), "-Y": (0.0, -1.0, 0.0),
         "-Z": (0.0, 0.0, -1.0)}


def _turned(rest: _Rest, axis: np.ndarray) -> _Rest:
    """``rest`` turned so world ``axis`` points up (+Z): as if the rig stood on that side."""
    a = np.asarray(axis, dtype=np.float64)
    if a[2] < -0.5:
        rot = np.diag([1.0, -1.0, -1.0])
    else:
        v = np.cross(a, _UP)
        c = float(a @ _UP)
        vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
        rot = np.eye(3) + vx + vx @ vx / (1.0 + c)
    return _Rest(rest.names, rest.index, rest.parent, rest.head @ rot.T, rest.tail @ rot.T, rest.local,
                 rest.world, rest.scale, rest.end @ rot.T, rest.tails_meaningful, rest.phantom)


def _drop(rest: _Rest, chains: Sequence[Sequence[int]]) -> float:
    """The mean drop of ``chains`` from hip to tip along world up (0 without chains)."""
    if not chains:
        return 0.0
    return float(np.mean([float(rest.head[c[0], 2] - _chain_points(rest, c)[:, 2].min()) for c in chains]))


def _stance(rest: _Rest, chains: Sequence[Sequence[int]]) -> float:
    """How well ``chains`` stand: their mean drop from hip to tip over the rig's height."""
    height = float(np.ptp(np.concatenate([rest.head[:, 2], rest.end[:, 2]])))
    return _drop(rest, chains) / max(height, 1e-12)


def _describe(rest: _Rest, chains: Sequence[Sequence[int]]) -> str:
    return ", ".join(f"{rest.names[c[0]]} > {rest.names[c[-1]]}" for c in chains[:4]) + (
        ", ..." if len(chains) > 4 else "")


def find_legs(rest: _Rest, constrained: np.ndarray, rig_name: str) -> list[LegChain]:
    """The legs of the rig ``rest`` (see the package doc).

    A leg is a chain of bones from the body whose tip is among the rig's lowest points along
    world up (:func:`_ground_chains`), names only saying where it starts and which bones are
    not legs. constrained: ``(B,)`` bool, bones with constraints that override their pose.
    Returns legs labelled and ordered front to back, left before right (``L1, R1, L2, ...``;
    a leg on the midline is ``M<row>``), each with the reason it was chosen. Raises
    :class:`RigError` when no leg reaches the ground, or when the rig lies on its side or
    upside down (more legs would reach the ground along another world axis).
    """
    found = _chains_along(rest)
    # Along which world axis do the legs stand? Another axis wins when its legs reach down
    # twice as far for the rig's size (a wolf on its side: legs, against cheek bones)...
    here = _stance(rest, [c for c, _r in found])
    turned = {name: _turned(rest, np.array(axis)) for name, axis in _AXES.items()}
    other = {name: [c for c, _r in _chains_along(t)] for name, t in turned.items()}
    score = {name: _stance(turned[name], chains) for name, chains in other.items()}
    # ... or when it finds more legs standing better (an upside-down rig's knees, a
    # sprawling rig's legs on its side, against the few chains that hang down).
    # One chain alone cannot hold a body up: two legs along another axis win over it.
    # More chains count only when they reach down further too: a thin biped lying on its face
    # has its toes and foot controls "hanging" towards the ground, by a foot's length.
    drop_here = _drop(rest, [c for c, _r in found])
    better = [k for k in score if len(other[k]) >= 2 and (
        score[k] > 2.0 * here or len(found) < 2
        or (score[k] > here and len(other[k]) > len(found) and _drop(turned[k], other[k]) > drop_here))]
    best_axis = max(better, key=lambda k: (score[k] * len(other[k]), k == "-Z")) if better else ""
    n_best = len(other[best_axis]) if better else 0
    if better:
        how = "upside down" if best_axis == "-Z" else "on its side"
        instead = f" (found instead: {_describe(rest, [c for c, _r in found])})" if found else ""
        raise RigError(f"No legs reach the ground under the body of '{rig_name}': the rig's up axis is world "
                       f"{best_axis} (it lies {how}; {n_best} legs reach down that way){instead}. Rotate the "
                       "object so its legs stand on the ground, then detect again")
    if not found:
        raise RigError(f"No legs found on '{rig_name}': no chain of bones from the body reaches the ground "
                       "in the rest pose. Name them (thigh/shin/foot, coxa/femur/tibia/tarsus, Leg1...) or "
                       "set hip and end-effector bones in the Rig & Legs panel")
    found = _dedupe_reasons(rest, found, constrained)
    legs = []
    for chain, reason in found:
        ik, foot = _split_foot(rest, chain)
        side = split_name(rest.names[chain[0]])[0]
        legs.append(LegChain(tuple(rest.names[i] for i in ik), tuple(rest.names[i] for i in foot), side,
                             reason=reason))
    forward, _source = forward_of(rest, legs)
    labelled = _label_legs(rest, legs, forward)
    tails = _tails(rest, labelled, forward)
    if tails:
        kept = [LegChain(leg.bones, leg.foot, leg.side, reason=leg.reason)
                for leg in labelled if leg not in tails]
        forward, _source = forward_of(rest, kept)
        labelled = _label_legs(rest, kept, forward)
    return _mark_pairs(labelled)


#: A chain on the midline longer than this many times the paired legs (on average) is a tail.
TAIL_SHARE = 1.5
#: A midline chain whose lowest point stays this share of the paired legs' length above
#: theirs does not stand on the ground: a tail hanging down, not a leg.
TAIL_CLEARANCE = 0.05


def _tails(rest: _Rest, legs: Sequence[LegChain], forward: np.ndarray) -> list[LegChain]:
    """The midline chains of ``legs`` that are a tail, not a leg (a rig with no names that
    say so: ``Bone.005``): unpaired, hanging from behind every paired leg's hip, reaching
    further back, and either lying on the ground (longer than :data:`TAIL_SHARE` times the
    paired legs or of more bones than any of them) or hanging down short of it (its lowest
    point :data:`TAIL_CLEARANCE` of the paired legs' length above theirs: a dog's relaxed
    tail). A pentapod's midline leg (ahead, as long as the others, on the ground) stays a
    leg. Only on rigs with two paired legs or more."""
    paired = [leg for leg in legs if leg.side != 0]
    if len(paired) < 2:
        return []

    def pts(leg: LegChain) -> np.ndarray:
        return _chain_points(rest, [rest.index[b] for b in (*leg.bones, *leg.foot)])

    length = float(np.mean([_length(pts(leg)) for leg in paired]))
    bones = max(len(leg.bones) + len(leg.foot) for leg in paired)
    hips_fwd = min(float(pts(leg)[0] @ forward) for leg in paired)
    ground = min(float(pts(leg)[:, 2].min()) for leg in paired)
    out = []
    for leg in legs:
        if leg.side != 0:
            continue
        p = pts(leg)
        behind = float(p[0] @ forward) < hips_fwd and float(p[-1] @ forward) < float(p[0] @ forward)
        long = _length(p) > TAIL_SHARE * length or len(leg.bones) + len(leg.foot) > bones
        hanging = float(p[:, 2].min()) - ground > TAIL_CLEARANCE * length
        if behind and (long or hanging):
            out.append(leg)
    return out


def _dedupe_reasons(rest: _Rest, found: list[tuple[list[int], str]],
                    constrained: np.ndarray) -> list[tuple[list[int], str]]:
    reasons = {tuple(c): r for c, r in found}
    return [(c, reasons[tuple(c)]) for c in _dedupe(rest, [c for c, _r in found], constrained)]


def _mark_pairs(legs: list[LegChain]) -> list[LegChain]:
    """Add "mirrored pair" to the reason of legs whose row has a left and a right leg."""
    rows: dict[str, set[int]] = {}
    for leg in legs:
        rows.setdefault(leg.label[1:], set()).add(leg.side)
    out = []
    for leg in legs:
        paired = {1, -1} <= rows.get(leg.label[1:], set())
        reason = f"{leg.reason}; mirrored pair" if paired and leg.reason else leg.reason
        out.append(LegChain(leg.bones, leg.foot, leg.side, leg.label, reason))
    return out


def leg_between(rest: _Rest, hip: str, end: str, label: str, rig_name: str) -> LegChain:
    """A leg from user-chosen hip and end-effector bones of the rig ``rest``, validated.

    Raises :class:`RigError` when a bone is missing, the hip is not an ancestor of the end
    (or the end itself), or a bone of the chain has zero length.
    """
    name = label or f"{hip} > {end}"
    for bone in (hip, end):
        if not bone:
            raise RigError(f"Leg {name}: choose both a hip and an end-effector bone")
        if bone not in rest.index:
            raise RigError(f"Leg {name}: '{rig_name}' has no bone '{bone}'")
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
        if np.linalg.norm(rest.end[i] - rest.head[i]) < 1e-9:
            raise RigError(f"Leg {name}: bone '{rest.names[i]}' has zero length")
    pts = _chain_points(rest, chain)
    if np.any(np.linalg.norm(np.diff(pts, axis=0), axis=1) < 1e-9):
        raise RigError(f"Leg {name}: two joints of the chain coincide (zero-length segment)")
    foot = _foot_after(rest, e)
    side = split_name(hip)[0]
    return LegChain(tuple(rest.names[i] for i in chain), tuple(rest.names[i] for i in foot), side, label)

def forward_of(rest: _Rest, legs: Sequence[LegChain]) -> tuple[np.ndarray, str]:
    """Horizontal unit forward direction of the creature in the world ``(3,)``, and what says so.

    In this order: the feet's toes (the bones after the end-effectors point forward, when
    they agree), the head or neck bone ahead of the hips, the L/R names of the hips, the
    object's -Y axis (Blender characters face -Y).
    """
    rot = rest.world[:3, :3] / rest.scale
    if legs:
        lengths = [_length(_chain_points(rest, [rest.index[b] for b in leg.bones])) for leg in legs]
        reach = float(np.mean(lengths))
        toes = []
        for leg in legs:
            if not leg.foot:
                continue
            end = rest.head[rest.index[leg.foot[0]]]
            pts = np.vstack([_subtree_points(rest, rest.index[f]) for f in leg.foot])
            d = pts[:, :2] - end[:2]
            far = d[int(np.argmax(np.linalg.norm(d, axis=1)))]
            if np.linalg.norm(far) > 0.05 * reach:
                toes.append(far / np.linalg.norm(far))
        if len(toes) >= max(2, (len(legs) + 1) // 2):
            mean = np.mean(toes, axis=0)
            if np.linalg.norm(mean) > 0.5:
                return _flat(np.array([mean[0], mean[1], 0.0])), "toes"
        hips = np.array([rest.head[rest.index[leg.hip]] for leg in legs])
        centre = hips.mean(axis=0)
        in_legs = {b for leg in legs for b in (*leg.bones, *leg.foot)}
        heads = [i for i, n in enumerate(rest.names)
                 if i not in in_legs and set(split_name(n)[1]) & HEAD_WORDS]
        if heads:
            d = np.mean(rest.end[heads], axis=0) - centre
            d[2] = 0.0
            if np.linalg.norm(d) > 0.2 * reach:
                return _flat(d), "head"
        sides = np.array([leg.side for leg in legs])
        if np.any(sides > 0) and np.any(sides < 0):
            left = hips[sides > 0].mean(axis=0) - hips[sides < 0].mean(axis=0)
            left[2] = 0.0
            if np.linalg.norm(left) > 1e-9:
                return _flat(np.cross(left, _UP)), "L/R names"
    return _flat(rot @ np.array([0.0, -1.0, 0.0])), "object's -Y axis"


def _flat(f: np.ndarray) -> np.ndarray:
    f = np.array([f[0], f[1], 0.0])
    n = np.linalg.norm(f)
    if n < 1e-9:
        raise RigError("Cannot tell which way the rig faces: its -Y axis points up or down")
    return f / n


def _forward_axis(rest: _Rest, legs: Sequence[LegChain], mode: str) -> np.ndarray:
    """Horizontal unit forward direction of the creature in the world: the object's axis
    ``mode`` (``"-Y"``, ``"+X"``...) or, with ``"AUTO"``, :func:`forward_of`."""
    rot = rest.world[:3, :3] / rest.scale
    local_axes = {"-Y": (0, -1, 0), "+Y": (0, 1, 0), "+X": (1, 0, 0), "-X": (-1, 0, 0)}
    if mode in local_axes:
        return _flat(rot @ np.array(local_axes[mode], dtype=np.float64))
    return forward_of(rest, legs)[0]


def _label_legs(rest: _Rest, legs: Sequence[LegChain], forward: np.ndarray) -> list[LegChain]:
    """Sides from hip positions (names when a hip is near the midline); rows front to back;
    labels L1, R1, ...; sorted."""
    left = np.cross(_UP, forward)
    hips = np.array([rest.head[rest.index[leg.hip]] for leg in legs])
    center = hips.mean(axis=0)
    lengths = np.array([_length(_chain_points(rest, [rest.index[b] for b in leg.bones])) for leg in legs])
    lateral_all = (hips - center) @ left
    # Off the midline: by a tenth of a leg, or by a quarter of the widest hip (narrow pairs).
    tol = max(min(0.1 * float(lengths.mean()), 0.25 * float(np.abs(lateral_all).max())),
              1e-6 * float(lengths.mean()))
    fwd = (hips - center) @ forward
    sides = []
    for i, (leg, lateral) in enumerate(zip(legs, lateral_all.tolist(), strict=True)):
        # a leg with a mirror image across the midline is on its own side however close
        mirrored = any(j != i and lateral * lateral_all[j] < 0.0
                       and abs(lateral + lateral_all[j]) < 0.25 * abs(lateral)
                       and abs(fwd[i] - fwd[j]) < tol + 0.25 * abs(lateral) for j in range(len(legs)))
        if abs(lateral) > tol or (mirrored and abs(lateral) > 1e-6 * float(lengths.mean())):
            side = 1 if lateral > 0.0 else -1
        else:
            side = leg.side
        sides.append(side)
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
                out.append(LegChain(leg.bones, leg.foot, s, leg.label or f"{prefix}{r}", leg.reason))
    return out
