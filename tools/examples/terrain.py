# SPDX-License-Identifier: GPL-3.0-or-later
"""The example terrain: a heightmap ground with a checker, crates (static and moving),
stairs and a gap, laid out in one lane per example creature.

API (stable; other tests build on it)::

    build_terrain(scene, collection=None, frame_start=1, frame_end=250, fps=None) -> Terrain
    ground_height(x, y) -> ndarray          # the heightmap, vectorised; z of the ground at (x, y)
    build_ground(scene, name, x_range, y_range, cell, height=ground_height, collection=None, holes=())
    build_crate(scene, name, center_xy, size, role, collection=None, base_z=None)
    animate_crate(crate, frames, locations)  # keyframes through the add-on's Action writer
    LANE_X[kind], START_Y                   # where each creature stands

World layout (metres; creatures walk towards -Y, the way Rigify metarigs face): the ground
spans x in [-8, 8], y in [-8, 5]; it is flat (z = 0) for y > 2 and everywhere a
creature starts, stairs stand or the gap is cut. Lanes, 2.4 m wide, centred on ``LANE_X``:

======  =============================================================================
lane    what is in front of the creature
======  =============================================================================
spider  flat: two low crates (STEP_OVER), a tall crate (AVOID), a crate moving across
ant     rolling heightmap hills (±0.22 m), a tall crate (AVOID), a low crate (STEP_OVER)
robot   a round hill rising 0.7 m over 4 m, starting 1 m ahead of it
lizard  a low plank (STEP_OVER), a crate moving across (AVOID), gentle hills beyond
wolf    a gap (a hole 0.375 m wide in the ground) and a low crate (STEP_OVER)
human   stairs: 4 steps up (0.15 m rise, 0.35 m tread), a landing at 0.6 m, 4 steps down
======  =============================================================================

Roles (``Object.procloco_role``): the ground and the stairs are ``GROUND``; crates are
``STEP_OVER`` (feet may land on them or pass over them) or ``AVOID`` (feet keep off);
moving crates are ``AVOID`` and animated with keyframes, so the terrain reader samples
them per frame. The gap is a hole cut in the ground: no surface at all, so swing paths may
pass over it but no foot lands in it; the trench under it (walls and a floor 0.6 m down) is
only there to be seen and has the role ``IGNORE``. Crate origins sit at the middle of
their bottom face; every object carries ``obj["example_feature"]`` naming what it is
(``ground``, ``stairs``, ``gap``, ``static_crate``, ``moving_crate``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import bpy
import numpy as np

from .procloco_props import set_role

HeightFn = Callable[[np.ndarray, np.ndarray], np.ndarray]

#: Lane centre (x) of each example creature; every creature starts at ``y = START_Y``.
LANE_WIDTH = 2.4
LANE_X: dict[str, float] = {kind: (i - 2.5) * LANE_WIDTH
                            for i, kind in enumerate(("spider", "ant", "robot", "lizard", "wolf", "human"))}
START_Y = 3.0
X_RANGE = (-8.0, 8.0)
Y_RANGE = (-8.0, 5.0)
CELL = 0.125

GAP_RECT = (2.875, 4.75, -0.625, -0.25)  # x0, x1, y0, y1: on ground-cell edges
GAP_DEPTH = 0.6
STAIR_RISE = 0.15
STAIR_TREAD = 0.35
STAIR_STEPS = 4
STAIR_LANDING = 1.2
STAIR_X = (5.2, 6.8)
STAIR_Y0 = 1.0  # where the first step begins; the flight climbs towards -Y

_COLORS = {
    "ground_light": (0.62, 0.64, 0.6, 1.0),
    "ground_dark": (0.36, 0.4, 0.36, 1.0),
    "stairs": (0.72, 0.7, 0.66, 1.0),
    "gap": (0.08, 0.07, 0.07, 1.0),
    "STEP_OVER": (0.74, 0.56, 0.3, 1.0),
    "AVOID": (0.55, 0.18, 0.12, 1.0),
    "moving": (0.95, 0.55, 0.08, 1.0),
}


@dataclass
class Terrain:
    """The objects :func:`build_terrain` made."""

    ground: bpy.types.Object
    stairs: bpy.types.Object
    gap: bpy.types.Object
    static_crates: list[bpy.types.Object] = field(default_factory=list)
    moving_crates: list[bpy.types.Object] = field(default_factory=list)

    def all_objects(self) -> list[bpy.types.Object]:
        return [self.ground, self.stairs, self.gap, *self.static_crates, *self.moving_crates]


# ---------------------------------------------------------------------------------------
# The heightmap


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def ground_height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Ground elevation at ``(x, y)`` (same-shaped arrays), in metres.

    Zero at the start strip (y > 2), in the spider, wolf and human lanes (crates, gap and
    stairs stand on flat ground) and under the lizard's crates; rolling hills in the ant and
    lizard lanes and a round hill in the robot's.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    # Lane boundaries are at multiples of LANE_WIDTH; amplitudes blend over ±0.3 m around them.
    b = LANE_WIDTH * np.array([-2.0, -1.0, 0.0, 1.0])  # spider|ant, ant|robot, robot|lizard, lizard|wolf
    edges = np.stack([b - 0.3, b + 0.3], axis=1).ravel()
    bump_amp = np.interp(x, edges, [0.0, 0.22, 0.22, 0.05, 0.05, 0.1, 0.1, 0.0])
    # A round-shouldered hill across the robot's lane (raised cosine, zero 1.6 m off its centre).
    off = np.clip(np.abs(x - LANE_X["robot"]) / 1.6, 0.0, 1.0)
    slope_amp = 0.35 * (1.0 + np.cos(np.pi * off))
    bumps = 0.6 * np.sin(1.9 * x + 0.3) * np.sin(1.5 * y + 1.1) + 0.4 * np.sin(1.1 * x - 1.7 * y + 0.5)
    bump_in = _smoothstep((0.8 - y) / 1.5)
    # The lizard lane stays flat until its moving crate is behind it.
    lizard = np.interp(x, edges[4:8], [0.0, 1.0, 1.0, 0.0])
    bump_in = bump_in * (1.0 - lizard * (1.0 - _smoothstep((-1.0 - y) / 1.5)))
    hill = _smoothstep((2.0 - y) / 4.0)
    return np.asarray(bump_amp * bumps * bump_in + slope_amp * hill)


# ---------------------------------------------------------------------------------------
# Building blocks


def _material(name: str, color: Sequence[float]) -> bpy.types.Material:
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    mat.diffuse_color = tuple(color)
    mat.roughness = 0.8
    if mat.node_tree is not None:
        bsdf = next((n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
        if bsdf is not None:
            bsdf.inputs["Base Color"].default_value = tuple(color)
    return mat


def _link(scene: bpy.types.Scene, obj: bpy.types.Object, collection: bpy.types.Collection | None) -> None:
    (collection or scene.collection).objects.link(obj)


def build_ground(
    scene: bpy.types.Scene,
    name: str = "Ground",
    x_range: tuple[float, float] = X_RANGE,
    y_range: tuple[float, float] = Y_RANGE,
    cell: float = CELL,
    height: HeightFn = ground_height,
    collection: bpy.types.Collection | None = None,
    holes: Sequence[tuple[float, float, float, float]] = (),
    checker: float = 1.0,
) -> bpy.types.Object:
    """A displaced grid: ``height(x, y)`` sampled at ``cell`` spacing, a ``checker`` (metres)
    of two materials, and no faces whose centre falls in one of the ``holes`` rectangles
    ``(x0, x1, y0, y1)``. Role GROUND."""
    nx = round((x_range[1] - x_range[0]) / cell)
    ny = round((y_range[1] - y_range[0]) / cell)
    xs = x_range[0] + cell * np.arange(nx + 1)
    ys = y_range[0] + cell * np.arange(ny + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="xy")  # (ny+1, nx+1)
    verts = np.stack([gx, gy, height(gx, gy)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    v00 = (j * (nx + 1) + i).ravel()
    quads = np.stack([v00, v00 + 1, v00 + nx + 2, v00 + nx + 1], axis=1)
    cx = (xs[:-1][None, :] + 0.5 * cell).repeat(ny, axis=0).ravel()
    cy = (ys[:-1][:, None] + 0.5 * cell).repeat(nx, axis=1).ravel()
    keep = np.ones(quads.shape[0], dtype=bool)
    for x0, x1, y0, y1 in holes:
        keep &= ~((cx > x0) & (cx < x1) & (cy > y0) & (cy < y1))
    quads, cx, cy = quads[keep], cx[keep], cy[keep]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts.tolist(), [], quads.tolist())
    mesh.materials.append(_material("Ground light", _COLORS["ground_light"]))
    mesh.materials.append(_material("Ground dark", _COLORS["ground_dark"]))
    check = ((np.floor(cx / checker) + np.floor(cy / checker)) % 2).astype(np.int32)
    mesh.polygons.foreach_set("material_index", check)
    mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), dtype=bool))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    _link(scene, obj, collection)
    set_role(obj, "GROUND")
    obj["example_feature"] = "ground"
    return obj


def _box(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float,
         offset: int = 0) -> tuple[list[tuple[float, float, float]], list[tuple[int, ...]]]:
    verts = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return verts, [tuple(i + offset for i in f) for f in faces]


def build_crate(
    scene: bpy.types.Scene,
    name: str,
    center_xy: Sequence[float],
    size: Sequence[float],
    role: str,
    collection: bpy.types.Collection | None = None,
    base_z: float | None = None,
    material: str | None = None,
) -> bpy.types.Object:
    """A box ``size = (sx, sy, sz)`` whose bottom centre is at ``center_xy``; it rests on the
    ground (slightly sunk into it where the ground is uneven) unless ``base_z`` is given."""
    sx, sy, sz = (float(s) for s in size)
    if base_z is None:
        px = center_xy[0] + np.array([-0.5, 0.5, -0.5, 0.5, 0.0]) * sx
        py = center_xy[1] + np.array([-0.5, -0.5, 0.5, 0.5, 0.0]) * sy
        base_z = float(ground_height(px, py).min())
        base_z = base_z - 0.01 if abs(base_z) > 1e-9 else 0.0  # sink a little into uneven ground
    verts, faces = _box(-sx / 2, sx / 2, -sy / 2, sy / 2, 0.0, sz)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    key = material or role
    mesh.materials.append(_material(f"Crate {key.lower().replace('_', ' ')}", _COLORS[key]))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = (float(center_xy[0]), float(center_xy[1]), base_z)
    _link(scene, obj, collection)
    set_role(obj, role)
    obj["example_feature"] = "static_crate"
    return obj


def animate_crate(crate: bpy.types.Object, frames: np.ndarray, locations: np.ndarray) -> bpy.types.Action:
    """Key ``crate.location`` at ``frames`` ``(n,)`` to ``locations`` ``(n, 3)`` (linear).

    Written through the add-on's Action writer, the one place that writes keyframes. The
    Action is the scene's own animation, not a ProcLoco generation, so its "generated" tag
    is removed after writing: ProcLoco must treat it like any animation the user made.
    """
    # Imported by name: these tools are type-checked as their own tree, apart from the add-on.
    actions = importlib.import_module("procloco_addon.blender.actions")

    action = actions.new_action(crate, suffix="Motion")
    actions.write_object_transforms(action, crate, np.asarray(frames, dtype=float), locations=locations)
    del action[actions.GENERATED_TAG]
    actions.assign_action(crate, action)
    crate["example_feature"] = "moving_crate"
    return action


def build_stairs(scene: bpy.types.Scene, name: str = "Stairs",
                 collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """Steps up towards -Y from ``STAIR_Y0``, a landing, and steps down again; one mesh, role GROUND."""
    x0, x1 = STAIR_X
    verts: list[tuple[float, float, float]] = []
    faces: list[tuple[int, ...]] = []
    top = STAIR_STEPS * STAIR_RISE
    y = STAIR_Y0
    blocks: list[tuple[float, float, float]] = []  # (y_start, y_end, height), y decreasing
    for k in range(1, STAIR_STEPS + 1):
        blocks.append((y, y - STAIR_TREAD, k * STAIR_RISE))
        y -= STAIR_TREAD
    blocks.append((y, y - STAIR_LANDING, top))
    y -= STAIR_LANDING
    for k in range(STAIR_STEPS - 1, -1, -1):
        if k == 0:
            break
        blocks.append((y, y - STAIR_TREAD, k * STAIR_RISE))
        y -= STAIR_TREAD
    for y_start, y_end, h in blocks:
        v, f = _box(x0, x1, y_end, y_start, 0.0, h, offset=len(verts))
        verts += v
        faces += f
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.materials.append(_material("Stairs", _COLORS["stairs"]))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    _link(scene, obj, collection)
    set_role(obj, "GROUND")
    obj["example_feature"] = "stairs"
    return obj


def build_gap(scene: bpy.types.Scene, name: str = "Gap", rect: tuple[float, float, float, float] = GAP_RECT,
              depth: float = GAP_DEPTH, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """What one sees under the hole cut in the ground: an open box (floor and walls, faces
    pointing inwards) ``depth`` deep. Role IGNORE: the gap itself is the lack of ground."""
    x0, x1, y0, y1 = rect
    verts, faces = _box(x0, x1, y0, y1, -depth, 0.0)
    faces = [tuple(reversed(f)) for f in faces[:1] + faces[2:]]  # no lid; normals inwards
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.materials.append(_material("Gap", _COLORS["gap"]))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    _link(scene, obj, collection)
    set_role(obj, "IGNORE")
    obj["example_feature"] = "gap"
    return obj


# ---------------------------------------------------------------------------------------
# The whole terrain

# (name, lane, dx, y, size, role); dx is from the lane centre.
_STATIC_CRATES: tuple[tuple[str, str, float, float, tuple[float, float, float], str], ...] = (
    ("Crate.Spider.Low1", "spider", -0.1, 1.0, (0.5, 0.5, 0.18), "STEP_OVER"),
    ("Crate.Spider.Tall", "spider", -0.75, -0.3, (0.6, 0.6, 0.8), "AVOID"),
    ("Crate.Spider.Low2", "spider", 0.3, -1.3, (0.6, 0.4, 0.22), "STEP_OVER"),
    ("Crate.Ant.Tall", "ant", 0.7, -0.4, (0.5, 0.5, 0.6), "AVOID"),
    ("Crate.Ant.Low", "ant", -0.2, 0.9, (0.4, 0.4, 0.12), "STEP_OVER"),
    ("Crate.Lizard.Plank", "lizard", 0.0, 1.9, (0.3, 0.3, 0.05), "STEP_OVER"),
    ("Crate.Wolf.Low", "wolf", 0.1, 1.3, (0.4, 0.4, 0.2), "STEP_OVER"),
)
# (name, lane, y, size, amplitude along x, period in seconds, phase in cycles)
_MOVING_CRATES: tuple[tuple[str, str, float, tuple[float, float, float], float, float, float], ...] = (
    ("Crate.Spider.Moving", "spider", -2.2, (0.5, 0.5, 0.4), 0.8, 4.0, 0.0),
    ("Crate.Lizard.Moving", "lizard", 1.25, (0.35, 0.35, 0.3), 0.8, 3.0, 0.25),
)


def build_terrain(scene: bpy.types.Scene, collection: bpy.types.Collection | None = None,
                  frame_start: int = 1, frame_end: int = 250, fps: float | None = None) -> Terrain:
    """Ground, stairs, gap, static crates and crates moving (keyed every frame from
    ``frame_start`` to ``frame_end``) across the spider's and the lizard's lanes."""
    if frame_end < frame_start:
        raise ValueError("frame_end must not be before frame_start")
    fps = float(fps if fps is not None else scene.render.fps / scene.render.fps_base)
    ground = build_ground(scene, collection=collection, holes=[GAP_RECT])
    stairs = build_stairs(scene, collection=collection)
    gap = build_gap(scene, collection=collection)
    terrain = Terrain(ground, stairs, gap)
    for name, lane, dx, y, size, role in _STATIC_CRATES:
        terrain.static_crates.append(build_crate(scene, name, (LANE_X[lane] + dx, y), size, role, collection))
    frames = np.arange(frame_start, frame_end + 1, dtype=float)
    for name, lane, y, size, amplitude, period, phase in _MOVING_CRATES:
        crate = build_crate(scene, name, (LANE_X[lane], y), size, "AVOID", collection, material="moving")
        t = (frames - frame_start) / fps
        locations = np.zeros((frames.shape[0], 3))
        locations[:, 0] = LANE_X[lane] + amplitude * np.sin(2.0 * np.pi * (t / period + phase))
        locations[:, 1] = y
        locations[:, 2] = crate.location.z
        animate_crate(crate, frames, locations)
        terrain.moving_crates.append(crate)
    return terrain
