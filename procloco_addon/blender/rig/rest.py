# SPDX-License-Identifier: GPL-3.0-or-later
"""Rest geometry of an armature as arrays, and the chain helpers shared by the rig modules.

Numpy only: :class:`_Rest` holds every bone's world-space rest head, tail and parent, so
detection and the spine search run on plain arrays (unit-testable without Blender).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field

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
    # (B, 3) world: where each bone's far joint is (see :func:`joint_ends`); from the tails
    # when not given.
    end: np.ndarray = None  # type: ignore[assignment]
    tails_meaningful: bool = True
    # (B,) bool: leaf bones an FBX exporter added at its parent's tail (``<parent>_end``):
    # they mark a tail, not a joint, and are left out of the rig's geometry.
    phantom: np.ndarray = None  # type: ignore[assignment]
    # Each bone's children (not phantom), made on first use: detection asks for them
    # hundreds of times per bone.
    _kids: list[list[int]] | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.phantom is None:
            has_kids = np.zeros(len(self.names), dtype=bool)
            has_kids[self.parent[self.parent >= 0]] = True
            object.__setattr__(self, "phantom", np.array(
                [not has_kids[i] and p >= 0 and n == self.names[p] + "_end"
                 for i, (n, p) in enumerate(zip(self.names, self.parent.tolist(), strict=True))], dtype=bool))
        if self.end is None:
            # A control rig's mechanism and control bones (Rigify's MCH-, tweak, IK, FK and
            # face bones, Auto-Rig Pro's c_ controls) sit anywhere on their parents: only its
            # skeleton (Rigify's ORG-/DEF- bones, else the bones not named as controls) says
            # whether the tails are joints.
            copies = np.array([bool(re.match(r"^(ORG|DEF)[-_.]", n)) for n in self.names], dtype=bool)
            skeleton = copies if copies.any() else np.array(
                [not re.match(r"^(MCH|VIS|WGT|c)[-_.]", n) for n in self.names], dtype=bool)
            end, meaningful = joint_ends(np.where(self.phantom, -1, self.parent), self.head, self.tail,
                                         skeleton)
            object.__setattr__(self, "end", end)
            object.__setattr__(self, "tails_meaningful", meaningful)

    def children(self, i: int) -> list[int]:
        """Bone ``i``'s children in bone order (a new list: callers may change it)."""
        if self._kids is None:
            kids: list[list[int]] = [[] for _ in self.names]
            for c, p in enumerate(self.parent.tolist()):
                if p >= 0 and not self.phantom[c]:
                    kids[p].append(c)
            object.__setattr__(self, "_kids", kids)
            return list(kids[i])
        return list(self._kids[i])

    def ancestors(self, i: int) -> list[int]:
        return _ancestors_of(self.parent, i)


def joint_ends(parent: np.ndarray, head: np.ndarray, tail: np.ndarray,
               counted: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """Each bone's far joint ``(B, 3)``, and whether the rig's tails mean anything (judged on
    the ``counted`` ``(B,)`` bones, all by default).

    Blender-made rigs put a bone's tail where its child starts: there the tails are the
    joints. glTF and FBX importers give bones arbitrary tails (each along its own +Y, of a
    guessed length): when fewer than 70 % of the bones with children (not counting those
    whose children all start at their head) have a child starting at their tail, a bone's
    far joint is the head of its child with the largest subtree (the chain's continuation),
    and a leaf's is its own head (its extent is unknown: it comes from its children, the
    skin or nothing).
    """
    n = parent.shape[0]
    span = float(np.ptp(np.vstack([head, tail]), axis=0).max()) if n else 0.0
    tol = 1e-4 * max(span, 1e-12)
    # Every parent-child pair at once: how far each child starts from its parent's head and
    # tail, the farthest and nearest child of each parent.
    child = np.flatnonzero(parent >= 0)
    par = parent[child]
    has_kids = np.zeros(n, dtype=bool)
    has_kids[par] = True
    from_head = np.full(n, -np.inf)
    np.maximum.at(from_head, par, np.linalg.norm(head[child] - head[par], axis=1))
    from_tail = np.full(n, np.inf)
    np.minimum.at(from_tail, par, np.linalg.norm(head[child] - tail[par], axis=1))
    # A bone whose children all start at its own head (a generated rig's tweak and mechanism
    # bones hang there) says nothing about its tail.
    telling = has_kids & (from_head >= tol)
    judged = telling & (np.ones(n, dtype=bool) if counted is None else np.asarray(counted, dtype=bool))
    if not judged.any():
        judged = telling if telling.any() else has_kids
    hits = int(np.count_nonzero(judged & (from_tail < tol)))
    # Blender-made rigs have 0.74 (a generated Rigify cat: palms whose toes start apart) to
    # 1 of them; importers' guessed tails 0 to 0.6.
    if not has_kids.any() or hits >= 0.7 * int(np.count_nonzero(judged)):
        return tail.copy(), True
    kids: list[list[int]] = [[] for _ in range(n)]
    for i, p in enumerate(parent.tolist()):
        if p >= 0:
            kids[p].append(i)
    with_kids = [i for i in range(n) if kids[i]]
    size = np.ones(n, dtype=np.int64)
    for i in sorted(range(n), key=lambda j: -_depth(parent, j)):  # children before parents
        if parent[i] >= 0:
            size[parent[i]] += size[i]
    end = head.copy()
    for i in with_kids:
        away = [c for c in kids[i] if np.linalg.norm(head[c] - head[i]) > tol]
        if away:
            c = max(away, key=lambda c: (size[c], float(np.linalg.norm(head[c] - head[i]))))
            end[i] = head[c]
    return end, False


def with_leaf_ends(rest: _Rest, skin: dict[int, np.ndarray]) -> _Rest:
    """``rest`` with the far joint of leaf bones taken from their skin where the tail is
    not to be trusted. skin: bone index -> ``(p, 3)`` world points weighted to that bone.

    A leaf's far joint is its skin's point farthest from its head when the rig's tails mean
    nothing, or when that point lies more than 30° off the tail's direction or at under half
    or over 1.5 times the tail's distance (an importer's guess: a glTF leaf continues its
    parent's direction). Otherwise the tail stays (a Blender-made rig with a skin around it).
    """
    end = rest.end.copy()
    for i, pts in skin.items():
        if rest.children(i) or pts.shape[0] == 0:
            continue
        d = pts - rest.head[i]
        far = pts[int(np.argmax(np.linalg.norm(d, axis=1)))]
        reach = float(np.linalg.norm(far - rest.head[i]))
        bone = rest.tail[i] - rest.head[i]
        length = float(np.linalg.norm(bone))
        if rest.tails_meaningful and length > 0.0 and reach > 0.0:
            cos = float((far - rest.head[i]) @ bone) / (reach * length)
            if cos >= np.cos(np.radians(30.0)) and 0.5 * length <= reach <= 1.5 * length:
                continue
        end[i] = far
    return _Rest(rest.names, rest.index, rest.parent, rest.head, rest.tail, rest.local, rest.world,
                 rest.scale, end, rest.tails_meaningful, rest.phantom)


#: The band above a foot skin's lowest vertex that is its sole, as a share of the skin's height.
SOLE_BAND = 0.25
#: At most this many sole probes per foot from its skin.
SOLE_PROBES = 32


def sole_points(points: np.ndarray, end: np.ndarray, forward: np.ndarray, left: np.ndarray) -> np.ndarray:
    """The sole of a foot's skin: ``(s, 3)`` points, ``s <= SOLE_PROBES``, among ``points``
    ``(p, 3)`` (world positions of the vertices weighted to the foot).

    The sole is the vertices within :data:`SOLE_BAND` of the skin's height above its lowest
    vertex. All of them when there are few; else the lowest, the ones reaching furthest
    forward, back, left and right of the end-effector ``end`` ``(3,)`` (toe tip, heel, sides)
    and more spread evenly among the rest (farthest-point sampling), so a foot pitched onto a
    slope finds the vertex that touches it. ``forward`` and ``left`` ``(3,)``: the body's
    horizontal axes.
    """
    z = points[:, 2]
    low = float(z.min())
    band = np.unique(points[z <= low + SOLE_BAND * max(float(z.max()) - low, 0.0)], axis=0)
    if band.shape[0] <= SOLE_PROBES:
        return band
    rel = band[:, :2] - end[:2]
    along = rel @ forward[:2]
    across = rel @ left[:2]
    pick = list(dict.fromkeys([int(np.argmin(band[:, 2])), int(np.argmax(along)), int(np.argmin(along)),
                               int(np.argmax(across)), int(np.argmin(across))]))
    dist = np.min(np.linalg.norm(band[:, None, :] - band[None, pick, :], axis=2), axis=1)
    while len(pick) < SOLE_PROBES:
        k = int(np.argmax(dist))
        pick.append(k)
        dist = np.minimum(dist, np.linalg.norm(band - band[k], axis=1))
    return band[np.sort(pick)]


_COPY_PREFIX = re.compile(r"^ORG[-_.]")


def skeleton_view(rest: _Rest) -> _Rest:
    """``rest`` with the metarig's hierarchy put back among a generated rig's ``ORG-`` bones.

    Rigify parents each ``ORG-`` spine bone to its own tweak control, so the spine is no
    parent chain: ``ORG-spine.006`` hangs from ``tweak_spine.006``, not from
    ``ORG-spine.005``. Here an ``ORG-`` bone whose parent is not an ``ORG-`` bone takes as its
    parent the ``ORG-`` bone whose tail is at its head (where the metarig connected them), else
    its nearest ``ORG-`` ancestor; other bones keep theirs. For reading the body and the spine
    only: poses are always composed along the real parents. ``rest`` itself when the rig has
    no such bones.
    """
    org = np.array([bool(_COPY_PREFIX.match(n)) for n in rest.names], dtype=bool)
    if not org.any():
        return rest
    tol = 1e-5 * max(rest.scale, 1e-9) * max(float(np.ptp(rest.head, axis=0).max()), 1e-9)
    org_idx = np.flatnonzero(org)
    parent = rest.parent.copy()
    changed = False
    for i in org_idx.tolist():
        p = int(rest.parent[i])
        if p < 0 or org[p]:
            continue
        at_head = [int(j) for j in org_idx if j != i and np.linalg.norm(rest.tail[j] - rest.head[i]) < tol
                   and i not in _ancestors_of(rest.parent, int(j))]
        new = at_head[0] if len(at_head) == 1 else next((a for a in rest.ancestors(i) if org[a]), p)
        if new != p and i not in _ancestors_of(parent, new):
            parent[i] = new
            changed = True
    if not changed:
        return rest
    return _Rest(rest.names, rest.index, parent, rest.head, rest.tail, rest.local, rest.world,
                 rest.scale, rest.end, rest.tails_meaningful, rest.phantom)


def _ancestors_of(parent: np.ndarray, i: int) -> list[int]:
    """Bone ``i``'s ancestors in the ``(B,)`` parent array, nearest first."""
    out: list[int] = []
    p = int(parent[i])
    while p >= 0:
        out.append(p)
        p = int(parent[p])
    return out


def _depth(parent: np.ndarray, i: int) -> int:
    d = 0
    while parent[i] >= 0:
        i = int(parent[i])
        d += 1
    return d


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


def affine_inverse(m: np.ndarray) -> np.ndarray:
    """Inverses of affine 4x4 matrices ``(..., 4, 4)`` (last row ``0 0 0 1``: bone and object
    matrices), element-wise. ``np.linalg.inv`` makes one LAPACK call per matrix, which costs
    far more than the arithmetic for 4x4 matrices (and much more again when its threads wait
    on a busy machine); the pose of a rig over its frames inverts thousands of them."""
    m = np.asarray(m, dtype=np.float64)
    a, b, c = m[..., :3, 0], m[..., :3, 1], m[..., :3, 2]  # the 3x3 part's columns
    # The inverse's rows are the cross products of the columns over the determinant.
    rows = np.stack([_cross(b, c), _cross(c, a), _cross(a, b)], axis=-2)
    det = np.sum(a * rows[..., 0, :], axis=-1)
    out = np.zeros(m.shape)
    out[..., :3, :3] = rows / det[..., None, None]
    t = m[..., :3, 3]
    out[..., :3, 3] = -np.sum(out[..., :3, :3] * t[..., None, :], axis=-1)
    out[..., 3, 3] = 1.0
    return out


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """The rotation nearest each matrix ``(..., 3, 3)`` (its polar factor, what ``u @ vt`` of
    its SVD gives), by Newton's iteration ``X <- (X + X^-T) / 2`` written out element-wise
    (a LAPACK SVD per matrix costs far more for the thousands of nearly orthonormal 3x3
    matrices a walk's bones give: two or three iterations reach the last bit)."""
    x = np.asarray(m, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(30):
            a, b, c = x[..., :, 0], x[..., :, 1], x[..., :, 2]
            cof = np.stack([_cross(b, c), _cross(c, a), _cross(a, b)], axis=-1)  # det * X^-T
            det = np.sum(a * cof[..., :, 0], axis=-1)
            nxt = 0.5 * (x + cof / det[..., None, None])
            done = float(np.abs(nxt - x).max(initial=0.0)) <= 1e-15
            x = nxt
            if done:
                break
    if not np.all(np.isfinite(x)):  # a singular matrix (a bone scaled to nothing): the SVD's answer
        u, _s, vt = np.linalg.svd(np.asarray(m, dtype=np.float64))
        x = u @ vt
    return x


def affine_inverses(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """:func:`affine_inverse` of every matrix of ``mats`` (bone name -> ``(4, 4)``), in one call."""
    if not mats:
        return {}
    return dict(zip(mats, affine_inverse(np.stack(list(mats.values()))), strict=True))


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cross products of ``(..., 3)`` vectors, written out (``np.cross`` is slower on small arrays)."""
    return np.stack([u[..., 1] * v[..., 2] - u[..., 2] * v[..., 1],
                     u[..., 2] * v[..., 0] - u[..., 0] * v[..., 2],
                     u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]], axis=-1)


def _length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-300)


def _chain_points(rest: _Rest, idx: Sequence[int]) -> np.ndarray:
    """Joint points of a chain: each bone's head, then the last bone's far joint ``(k + 1, 3)``."""
    return np.vstack([rest.head[list(idx)], rest.end[idx[-1]][None]])


#: Mechanism bones a generated control rig hangs beside the bone they follow, at the same
#: place (Rigify's ``MCH-r_toe.L`` beside ``ORG-r_toe.L`` under ``ORG-foot.L``).
_MECHANISM_PREFIX = re.compile(r"^(MCH|VIS|WGT|TGT)[-_.]", re.IGNORECASE)


def _continuing_child(rest: _Rest, i: int, allowed: set[int] | None = None) -> int | None:
    """The child that continues a chain: a connected one first, then the one reaching lowest;
    a mechanism child (``MCH-``) only when the parent is one or there is no other."""
    kids = [c for c in rest.children(i) if allowed is None or c in allowed]
    if not _MECHANISM_PREFIX.match(rest.names[i]):
        kids = [c for c in kids if not _MECHANISM_PREFIX.match(rest.names[c])] or kids
    if not kids:
        return None
    tol = 1e-6 * max(rest.scale, 1e-9)
    connected = [c for c in kids if np.linalg.norm(rest.head[c] - rest.end[i]) < tol]
    pool = connected or kids
    return min(pool, key=lambda c: (_subtree_min_z(rest, c), c))


def _subtree_min_z(rest: _Rest, i: int) -> float:
    stack = [i]
    low = np.inf
    while stack:
        j = stack.pop()
        low = min(low, rest.head[j, 2], rest.end[j, 2])
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
