# SPDX-License-Identifier: GPL-3.0-or-later
"""Adding or removing footprints when the stride no longer fits the speed.

The biped thesis' discussion (§4.3, "Footprint count") notes the flaw this module
removes: blend groups may make the character run over footprints the graph laid out for
a walk (or walk over a run's), and smoothing may shorten the path, but the *number* of
footprints never changes, so a runner takes walking strides. The thesis leaves "adaptively
remove or add footprints" to future work.

After the blend groups have set the curvature and the walk/run parameter along the path,
every run of consecutive walk/run strides (between special clips: start, jump, stop) is
laid out again. Along the polyline of its right footprints, the number of strides needed
is ``∫ dℓ / stride(ℓ)``, where ``stride`` is the right-to-right distance of the clips
blended there; when that rounds to another count than the graph's, the right footprints
are re-placed at equal shares of that integral (short strides where the character walks,
long ones where it runs), the left footprints between them from the clips' own geometry,
and the blend weights carried over by arc length. The ends of each run stay where they
were: they belong to the special clips. Strides the caller asks to ``keep`` (the short
strides the footprint graph chose to put a foot on every tread of a stair) end runs like
special clips and are never re-laid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .blending import Footprints, Plan, plan_footprints
from .database import ClipDatabase
from .graph import relative_to_right
from .skeleton import RIGHT
from .surface import WalkableSurface

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Respaced:
    """The plan and desired footprints after re-spacing, plus what changed per run of
    strides: ``(first segment, old count, new count)``."""

    plan: Plan
    footprints: Footprints
    changes: tuple[tuple[int, int, int], ...]
    terrace: IntArray | None = None


def clip_strides(db: ClipDatabase) -> FloatArray:
    """Right-to-right stride length of each clip ``(C,)`` (0 for start, stop and idle)."""
    out = np.zeros(len(db.clips))
    for info in db.infos:
        if info.role.family in ("walk", "run", "jump"):
            rel, _ = relative_to_right(info, info.end_right_pos, info.end_right_yaw)
            out[info.index] = float(np.linalg.norm(rel[:2]))
    return out


def _right_index(fp: Footprints, k: int) -> int:
    idx = np.flatnonzero((fp.segment == k) & (fp.side == RIGHT))
    return int(idx[0])


def _weights_at(plan: Plan, u: FloatArray) -> FloatArray:
    """Plan weights ``(M, C)`` at segment coordinates ``u`` (within-segment interpolation)."""
    k = np.clip(np.floor(u).astype(np.int64), 0, plan.n_segments - 1)
    s = plan.weights.shape[1]
    f = np.clip(u - k, 0.0, 1.0) * (s - 1)
    i0 = np.minimum(np.floor(f).astype(np.int64), s - 2)
    a = (f - i0)[:, None]
    return plan.weights[k, i0] * (1 - a) + plan.weights[k, i0 + 1] * a


def respace(
    db: ClipDatabase,
    plan: Plan,
    want: Footprints,
    surface: WalkableSurface | None,
    island: IntArray,
    keep: BoolArray | None = None,
    terrace: IntArray | None = None,
) -> tuple[Respaced, IntArray]:
    """Re-lay the walk/run strides of ``plan`` so their count fits their blended clips.

    ``want`` holds the desired footprints of ``plan`` (the smoothed ones); ``island`` their
    platforms; ``keep (K,)`` marks segments not to re-lay; ``terrace`` (optional) the
    footprints' terraces, which snapping then keeps, with the soles supported (the new
    footprints' terraces are in the result). Returns the new plan and footprints, and the new
    footprints' platforms.
    """
    strides = clip_strides(db)
    families = [db.infos[int(c)].role.family for c in plan.clips]
    group = np.array([f in ("walk", "run") for f in families])
    if keep is not None:
        group &= ~np.asarray(keep, dtype=bool)
    n_seg = plan.n_segments
    runs: list[tuple[int, int]] = []
    k = 0
    while k < n_seg:
        if group[k]:
            j = k
            while j + 1 < n_seg and group[j + 1]:
                j += 1
            runs.append((k, j))
            k = j + 1
        else:
            k += 1
    right = [_right_index(want, k) for k in range(n_seg)]
    r_pos = want.pos[right]
    r_yaw = want.yaw[right]
    # New segment list: (old u at the segment's start and end, right pose) per segment.
    seg_u: list[tuple[float, float]] = []
    seg_pose: list[tuple[FloatArray, float]] = []
    changes: list[tuple[int, int, int]] = []
    k = 0
    for k0, k1 in runs:
        for kk in range(k, k0):
            seg_u.append((float(kk), float(kk + 1)))
            seg_pose.append((r_pos[kk], float(r_yaw[kk])))
        # Strides of this run and the polyline of its right footprints (with the next one).
        pts = r_pos[k0 : k1 + 2]
        seg_len = np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1)
        arc = np.concatenate(([0.0], np.cumsum(seg_len)))
        mid_w = _weights_at(plan, np.arange(k0, k1 + 1) + 0.5)
        natural = np.maximum(mid_w @ strides, 1e-6)
        need = np.concatenate(([0.0], np.cumsum(seg_len / natural)))
        n_old = k1 - k0 + 1
        n_new = max(1, round(float(need[-1])))
        if n_new == n_old:
            for kk in range(k0, k1 + 1):
                seg_u.append((float(kk), float(kk + 1)))
                seg_pose.append((r_pos[kk], float(r_yaw[kk])))
        else:
            changes.append((len(seg_u), n_old, n_new))
            share = np.linspace(0.0, float(need[-1]), n_new + 1)
            new_arc = np.interp(share, need, arc)
            u_old = k0 + np.interp(new_arc, arc, np.arange(n_old + 1, dtype=float))
            yaw_unwrapped = np.unwrap(r_yaw[k0 : k1 + 2])
            for i in range(n_new):
                p = np.array([np.interp(new_arc[i], arc, pts[:, d]) for d in range(3)])
                y = float(np.interp(new_arc[i], arc, yaw_unwrapped))
                seg_u.append((float(u_old[i]), float(u_old[i + 1])))
                seg_pose.append((p, y))
        k = k1 + 1
    for kk in range(k, n_seg):
        seg_u.append((float(kk), float(kk + 1)))
        seg_pose.append((r_pos[kk], float(r_yaw[kk])))
    if not changes:
        return Respaced(plan, want, (), terrace), island

    # The new plan: weights carried over by old segment coordinate (so by arc length).
    n_new_seg = len(seg_u)
    samples = plan.weights.shape[1]
    phase = np.linspace(0.0, 1.0, samples)
    weights = np.empty((n_new_seg, samples, plan.weights.shape[2]))
    clips = np.empty(n_new_seg, dtype=np.int64)
    old_of_new = np.full(n_new_seg, -1, dtype=np.int64)
    for i, (ua, ub) in enumerate(seg_u):
        if ub - ua == 1.0 and float(ua).is_integer():
            old = int(ua)
            weights[i] = plan.weights[old]
            clips[i] = plan.clips[old]
            old_of_new[i] = old
            continue
        # The last sample stays inside the run: the next segment is a special clip.
        u = np.minimum(ua + phase * (ub - ua), ub - 1e-9)
        w = _weights_at(plan, u)
        weights[i] = w / w.sum(axis=1, keepdims=True)
        clips[i] = int(np.argmax(w[samples // 2]))
    new_plan = Plan(clips, weights, plan.start_pos, plan.start_yaw)
    rp = np.array([p for p, _ in seg_pose])
    ry = np.unwrap(np.array([y for _, y in seg_pose]))
    fresh = plan_footprints(db, new_plan, (rp, ry))
    pos = fresh.pos.copy()
    yaw = fresh.yaw.copy()
    carried = np.full(len(fresh), -1, dtype=np.int64)
    # Footprints of unchanged segments keep their smoothed poses.
    for i in range(len(fresh)):
        old = old_of_new[int(fresh.segment[i])]
        if old < 0:
            continue
        same = np.flatnonzero((want.segment == old) & (want.side == fresh.side[i]))
        nth = int(np.sum((fresh.segment[:i] == fresh.segment[i]) & (fresh.side[:i] == fresh.side[i])))
        if nth < len(same):
            pos[i] = want.pos[same[nth]]
            yaw[i] = want.yaw[same[nth]]
            carried[i] = same[nth]
    yaw = np.unwrap(yaw)
    new_island = np.full(len(fresh), -1, dtype=np.int64)
    new_terrace: IntArray | None = None
    if surface is not None:
        new_island = surface.island_at(pos)
        bad = new_island < 0
        if np.any(bad):
            new_island[bad] = surface.island_at(surface.snap(pos[bad]))
        move = np.ones(len(fresh), dtype=bool)
        move[:2] = move[-2:] = False
        if terrace is None:
            pos[move] = surface.snap(pos[move], new_island[move])
        else:
            # Kept footprints keep their terraces; new ones stand on the nearest supported spot.
            new_terrace = np.where(carried >= 0, terrace[np.maximum(carried, 0)], -1)
            fresh_fp = np.flatnonzero(new_terrace < 0)
            near = surface.snap(pos[fresh_fp], new_island[fresh_fp], yaw=yaw[fresh_fp])
            new_terrace[fresh_fp] = surface.terrace_at(near)
            pos[move] = surface.snap(pos[move], new_island[move], yaw=yaw[move], terrace=new_terrace[move])
    footprints = Footprints(fresh.side, fresh.segment, fresh.u_td, fresh.u_lo, pos, yaw, fresh.time)
    return Respaced(new_plan, footprints, tuple(changes), new_terrace), new_island
