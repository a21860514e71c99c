# SPDX-License-Identifier: GPL-3.0-or-later
"""Benchmark scenes: the thesis's Table 3.1 environment, seeded and deterministic.

Table 3.1 (thesis §3.8) times 100 eight-legged characters in "a heightmap and obstacles
(3000 crates, 40% dynamic)"; the French summary gives the heightmap as 100 m on a side. This
module builds that scene for the core (no Blender):

    scene = make_crowd_scene(seed=0)
    env = scene.env                       # procloco_addon.core.world.terrain.Environment
    xy, heading = spawn_points(scene, 100, seed=1)
    scene.advance(1 / 30)                 # moves the dynamic crates (env.move_boxes)

Crates are oriented boxes standing on the terrain, 0.2–0.6 m wide and 0.05–0.45 m high; 30 %
are "avoid" crates (walked around), the rest may be stepped on or over. Moving crates slide
back and forth along their own direction (amplitude 0.3–1.5 m, period 4–12 s) while turning
slowly, and follow the terrain's height. Everything depends on the seed only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from procloco_addon.core.world.terrain import ROLE_AVOID, ROLE_STEP_OVER, Boxes, Environment, Heightmap

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


@dataclass
class CrowdScene:
    """The environment plus what it takes to move its dynamic crates.

    ``moving``: ``(k,)`` box indices of the moving crates; ``home``: ``(k, 2)`` their centres
    at time 0; ``axis``: ``(k, 2)`` unit directions of travel; ``amplitude``, ``omega``,
    ``phase``, ``yaw0``, ``spin``: ``(k,)`` motion parameters; ``half_size``: ``(k, 2)``;
    ``size``: side of the square world in metres; ``time``: seconds since the start.
    """

    env: Environment
    heightmap: Heightmap
    size: float
    moving: IntArray
    home: FloatArray
    axis: FloatArray
    amplitude: FloatArray
    omega: FloatArray
    phase: FloatArray
    yaw0: FloatArray
    spin: FloatArray
    half_size: FloatArray
    time: float = 0.0

    def pose_at(self, time: float) -> tuple[FloatArray, FloatArray]:
        """Centres ``(k, 3)`` (bottom faces) and yaws ``(k,)`` of the moving crates at ``time``."""
        offset = self.amplitude * np.sin(self.omega * time + self.phase)
        xy = self.home + self.axis * offset[:, None]
        yaw = self.yaw0 + self.spin * time
        z = _ground_under(self.heightmap, xy, self.half_size, yaw)
        return np.column_stack([xy, z]), yaw

    def advance(self, dt: float) -> None:
        """Move the dynamic crates forward by ``dt`` seconds."""
        self.time += float(dt)
        centre, yaw = self.pose_at(self.time)
        self.env.move_boxes(self.moving, centre, yaw)


def _ground_under(hm: Heightmap, xy: FloatArray, half: FloatArray, yaw: FloatArray) -> FloatArray:
    """Lowest terrain height under each crate's corners and centre: crates rest on the ground
    without a gap (slightly sunk on slopes)."""
    c, s = np.cos(yaw), np.sin(yaw)
    pts = [xy]
    for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        dx = sx * half[:, 0]
        dy = sy * half[:, 1]
        pts.append(xy + np.column_stack([c * dx - s * dy, s * dx + c * dy]))
    return np.min(np.stack([hm.sample(p) for p in pts]), axis=0)


def make_heightmap(rng: np.random.Generator, size: float, cell: float, amplitude: float = 1.2) -> Heightmap:
    """Rolling terrain: a sum of a few long sine waves (slopes below about 20 %)."""
    n = round(size / cell) + 1
    coords = np.arange(n) * cell - 0.5 * size
    gx, gy = np.meshgrid(coords, coords)
    z = np.zeros_like(gx)
    for _ in range(6):
        wavelength = rng.uniform(12.0, 45.0)
        angle = rng.uniform(0.0, np.pi)
        k = 2.0 * np.pi / wavelength
        a = amplitude * rng.uniform(0.15, 0.35)
        z += a * np.sin(k * (np.cos(angle) * gx + np.sin(angle) * gy) + rng.uniform(0.0, 2.0 * np.pi))
    return Heightmap(z, np.array([-0.5 * size, -0.5 * size]), cell)


def make_crowd_scene(
    seed: int = 0,
    size: float = 100.0,
    n_crates: int = 3000,
    moving_fraction: float = 0.4,
    avoid_fraction: float = 0.3,
    heightmap_cell: float = 0.5,
) -> CrowdScene:
    """The Table 3.1 scene: a ``size`` × ``size`` m heightmap centred on the origin with
    ``n_crates`` crates, ``moving_fraction`` of them moving."""
    rng = np.random.default_rng(seed)
    hm = make_heightmap(rng, size, heightmap_cell)
    margin = 2.0
    xy = rng.uniform(-0.5 * size + margin, 0.5 * size - margin, (n_crates, 2))
    footprint = rng.uniform(0.2, 0.6, (n_crates, 2))
    height = rng.uniform(0.05, 0.45, n_crates)
    yaw = rng.uniform(0.0, np.pi, n_crates)
    role = np.where(rng.random(n_crates) < avoid_fraction, ROLE_AVOID, ROLE_STEP_OVER)
    n_moving = round(moving_fraction * n_crates)
    dynamic = np.zeros(n_crates, dtype=bool)
    moving = np.sort(rng.choice(n_crates, n_moving, replace=False)).astype(np.intp)
    dynamic[moving] = True
    half = 0.5 * footprint
    z = _ground_under(hm, xy, half, yaw)
    boxes = Boxes(np.column_stack([xy, z]), np.column_stack([footprint, height]), yaw, role, dynamic)
    env = Environment(hm, boxes)
    k = moving.size
    travel = rng.uniform(0.0, 2.0 * np.pi, k)
    return CrowdScene(
        env=env,
        heightmap=hm,
        size=size,
        moving=moving,
        home=xy[moving].copy(),
        axis=np.column_stack([np.cos(travel), np.sin(travel)]),
        amplitude=rng.uniform(0.3, 1.5, k),
        omega=2.0 * np.pi / rng.uniform(4.0, 12.0, k),
        phase=rng.uniform(0.0, 2.0 * np.pi, k),
        yaw0=yaw[moving].copy(),
        spin=rng.uniform(-0.3, 0.3, k),
        half_size=half[moving].copy(),
    )


def spawn_points(
    scene: CrowdScene, n: int, seed: int = 1, spread: float = 0.8
) -> tuple[FloatArray, FloatArray]:
    """``n`` character positions ``(n, 2)`` and headings ``(n,)``: uniformly over the middle
    ``spread`` of the world, away from avoided crates (resampled while one lies within 0.5 m)."""
    rng = np.random.default_rng(seed)
    half = 0.5 * scene.size * spread
    out = np.zeros((n, 2))
    todo = np.arange(n)
    ring = 0.5 * np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    for _ in range(100):
        if todo.size == 0:
            break
        out[todo] = rng.uniform(-half, half, (todo.size, 2))
        probe = (out[todo][:, None, :] + ring[None, :, :]).reshape(-1, 2)
        bad = scene.env.forbidden_at(probe).reshape(todo.size, -1).any(axis=1)
        todo = todo[bad]
    heading = rng.uniform(-np.pi, np.pi, n)
    return out, heading
