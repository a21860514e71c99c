# SPDX-License-Identifier: GPL-3.0-or-later
"""The spine chain from the body bone to the head, and its layout as the core's flexible
spine (numpy only, on rest arrays)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .info import SpineLayout
from .names import _is_helper_name, split_name
from .rest import _UP, _Rest


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
        ends = np.stack([rest.head[i], rest.end[i]])
        if np.abs((ends - centre) @ left).max() > tol:
            return False
        parent_len = float(np.linalg.norm(rest.end[parent] - rest.head[parent]))
        if np.linalg.norm(rest.head[i] - rest.end[parent]) > 0.25 * parent_len + 1e-9 * rest.scale:
            return False
        return float((rest.end[i] - rest.head[i]) @ forward) > 1e-3 * leg_length

    chain = [body]
    while len(chain) < len(rest.names):
        kids = [k for k in rest.children(chain[-1]) if spine_like(chain[-1], k)]
        if not kids:
            break
        holding = [k for k in kids if carried(k)]
        if holding:
            chain.append(max(holding, key=lambda k: (carried(k), -k)))
        else:
            chain.append(max(kids, key=lambda k: (float(rest.end[k] @ forward), -k)))
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
