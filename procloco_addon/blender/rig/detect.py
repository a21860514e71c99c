# SPDX-License-Identifier: GPL-3.0-or-later
"""Leg detection on rest arrays (numpy only): candidate chains by names and by topology,
which of them are legs, their flat foot bones, the forward axis and the L/R labels."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .names import _is_helper_name, _is_leg_name, _leg_number, split_name
from .rest import _UP, RigError, _chain_points, _continuing_child, _length, _Rest


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
        if any(np.linalg.norm(pts[0] - _chain_points(rest, k)[0]) < tol
               and np.linalg.norm(pts[-1] - _chain_points(rest, k)[-1]) < tol for k in kept):
            continue
        kept.append(chain)
    return sorted(kept, key=lambda c: c[0])

def find_legs(rest: _Rest, constrained: np.ndarray, rig_name: str) -> list[LegChain]:
    """The legs of the rig ``rest`` by names, else by topology (see the package doc).

    constrained: ``(B,)`` bool, bones with constraints that override their pose. Returns legs
    labelled and ordered front to back, left before right (``L1, R1, L2, ...``; a leg on the
    midline is ``M<row>``). Raises :class:`RigError` when no leg is found.
    """
    chains = _valid_legs(rest, _name_chains(rest))
    if len(chains) < 2:
        topo = _valid_legs(rest, _topology_chains(rest))
        if len(topo) > len(chains):
            chains = topo
    chains = _dedupe(rest, chains, constrained)
    if not chains:
        raise RigError(f"No legs found on '{rig_name}': name them (thigh/shin/foot, coxa/femur/tibia/tarsus, "
                       "Leg1...) or set hip and end-effector bones in the Rig & Legs panel")
    legs = []
    for chain in chains:
        ik, foot = _split_foot(rest, chain)
        side = split_name(rest.names[chain[0]])[0]
        legs.append(LegChain(tuple(rest.names[i] for i in ik), tuple(rest.names[i] for i in foot), side))
    return _label_legs(rest, legs, _forward_axis(rest, legs, "AUTO"))


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
