# SPDX-License-Identifier: GPL-3.0-or-later
"""Rest geometry of an armature as arrays, and the chain helpers shared by the rig modules.

Numpy only: :class:`_Rest` holds every bone's world-space rest head, tail and parent, so
detection and the spine search run on plain arrays (unit-testable without Blender).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

_UP = np.array([0.0, 0.0, 1.0])


class RigError(ValueError):
    """The armature cannot be animated as asked (the message is meant for the user)."""


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


def _apply(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Affine 4x4 ``m`` applied to points ``(..., 3)``."""
    return p @ m[:3, :3].T + m[:3, 3]


def _length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-300)


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
