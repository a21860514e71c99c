# SPDX-License-Identifier: GPL-3.0-or-later
"""The fallback straight-step planner: the last resort when the footprint planner finds no
couple for a foot that must move (left behind, its support gone, or its swing cut by a
moving obstacle). A straight arc to the preferred spot, or the nearest spot around it the leg
can step to (``straight_step``), its end segments kept clear of ground edges
(``clear_end_segments``)."""

from __future__ import annotations

import numpy as np

from ..world.terrain import Environment
from .reach import hip_distance, reach_bound
from .rig import Rig
from .types import VOID, ControllerParams, FloatArray


def straight_step(
    env: Environment, rig: Rig, p: ControllerParams, leg: int, start: FloatArray, target_xy: FloatArray,
    u: FloatArray, step_height: float, search: float, hip_start: FloatArray, hip_end_xy: FloatArray,
) -> tuple[FloatArray, FloatArray] | None:
    """Last resort when the planner finds no couple for a foot that must move: a straight
    arc lifted ``step_height`` over what it crosses, to ``target_xy`` or else the nearest
    spot around it (up to the step's length or ``search`` metres away, whichever is more)
    that the leg can step to: landing on a surface outside avoided obstacles, the line not
    through an avoided obstacle (a foot standing on one may leave across it), and nothing
    on the way taller, above the higher end, than the leg's hip stands above its foot at
    rest less ``step_height`` (higher, the leg could not fold enough to pass). None when
    there is no such spot: the foot stays rather than step onto air or out of reach.

    Returns the samples ``(k + 1, 3)`` at ``u (k + 1,)`` and the landing point ``(3,)``."""
    reach = max(float(np.linalg.norm(target_xy - start[:2])), search) + 1e-3
    ring = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    radii = np.linspace(0.1, 1.0, 6) * reach
    dirs = np.stack([np.cos(ring), np.sin(ring)], axis=1)
    around = target_xy[None, None, :] + radii[:, None, None] * dirs[None, :, :]
    spots = np.concatenate([target_xy[None, :], around.reshape(-1, 2)])  # nearest first
    n_u = u.shape[0]
    xy = start[None, None, :2] + u[None, :, None] * (spots - start[:2])[:, None, :]
    flat = xy.reshape(-1, 2)
    surface = env.height_at(flat).reshape(-1, n_u)
    forbidden = env.forbidden_at(flat).reshape(-1, n_u)
    landing = (surface[:, -1] > VOID) & ~forbidden[:, -1]
    # leaving an avoided obstacle the foot stands on is allowed; entering one is not
    leaving = np.logical_and.accumulate(forbidden, axis=1)
    crossing = (forbidden & ~leaving)[:, 1:-1].any(axis=1)
    end_z = np.where(surface[:, -1] > VOID, surface[:, -1], start[2])
    # the arc rises from the ground under the start (a foot already in the air is not
    # lifted a step height above where it is: re-plan after re-plan it would ratchet up)
    z0 = min(float(start[2]), float(surface[0, 0])) if surface[0, 0] > VOID else float(start[2])
    base = z0 + u[None, :] * (end_z - z0)[:, None]
    # a foot leaving an avoided obstacle that came at it goes out sideways at its height
    # (as the planner's swings do, pathing.clearance_elevation), not over the top
    tall = leaving & (surface > start[2] + step_height)
    under = np.where((surface > VOID) & ~tall, surface, base)
    climb = np.maximum((under - base).max(axis=1), 0.0)
    rest = float(rig.rest_height[leg])
    ok = landing & ~crossing & (climb <= max(rest - step_height, 0.25 * rest))
    lift = climb + step_height
    z = base + 4.0 * u[None, :] * (1.0 - u[None, :]) * lift[:, None]
    # from where the foot is: never below the straight line from it down to the landing
    z = np.maximum(z, start[2] + u[None, :] * (end_z - start[2])[:, None])
    z[:, 0] = start[2]
    inner = (u > 0.0) & (u < 1.0)
    # clear of the ground at each sample and at its neighbours: the polyline between two
    # samples must not cut the edge of a stair or crate lying between them
    near = under.copy()
    near[:, 1:] = np.maximum(near[:, 1:], under[:, :-1])
    near[:, :-1] = np.maximum(near[:, :-1], under[:, 1:])
    z[:, inner] = np.maximum(z[:, inner], near[:, inner] + 0.25 * step_height)
    # and within the leg's length of the hip all the way (the hip moving to touch-down)
    pts = np.concatenate([xy, z[..., None]], axis=2)
    dist = hip_distance(rig, p, leg, pts, hip_start, hip_end_xy)
    ok &= (dist <= reach_bound(rig, leg, float(dist[0, 0]), u)[None, :]).all(axis=1)
    if not np.any(ok):
        return None
    k = int(np.flatnonzero(ok)[0])
    return clear_end_segments(env, pts[k].copy(), step_height), np.array(
        [spots[k, 0], spots[k, 1], float(end_z[k])]
    )

def clear_end_segments(env: Environment, pts: FloatArray, step_height: float) -> FloatArray:
    """The first and last segments of a straight step's samples ``pts (k + 1, 3)`` made
    to clear any ground edge they cross (a foot lifting off just below a stair, or
    landing just past one): the foot then rises straight up from its start, or comes
    straight down onto its landing, from the height of the ground it passes."""
    if pts.shape[0] < 3:
        return pts
    t = np.linspace(0.0, 1.0, 33)[1:-1]
    for a, b, moved in ((0, 1, 1), (-1, -2, -2)):
        line = pts[a][None, :] + t[:, None] * (pts[b] - pts[a])[None, :]
        ground = env.height_at(line[:, :2])
        if np.any(ground > line[:, 2]):
            pts[moved, :2] = pts[a, :2]
            pts[moved, 2] = max(float(pts[moved, 2]), float(ground.max()) + 0.25 * step_height)
    return pts
