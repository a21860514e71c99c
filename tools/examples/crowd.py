# SPDX-License-Identifier: GPL-3.0-or-later
"""The crowd example: a swarm of spiders and a column of ants crossing a log, crates and
each other's paths, for ``examples_crowd.blend`` (``tools/build_crowd_example.py``).

API::

    build_crowd_scene(scene, spiders=40, ants=20, frame_end=168) -> CrowdScene
    crowd_ground_height(x, y) -> ndarray       # the ground's heightmap (gentle swells)

Layout (metres; Z up): the creatures travel along X in interleaved lanes ``LANE_PITCH``
apart, alternately a spider lane and an ant lane. The spiders start on the left (x < 0, in
rows ``ROW_PITCH`` apart going back from ``-FRONT_X``) facing +X, the ants on the right facing
-X, so the two groups meet in the middle and walk through each other's ranks. Across the
middle lies a low log (STEP_OVER), and low crates (STEP_OVER) stand in several lanes; two
tall crates (AVOID) stand beside the crowd as landmarks. Every creature walks straight along
its lane with the settings of its kind (its gait preset, with its speed and cycle time),
with a little of its own: a Seed Offset (its own start phase and a slightly different
stride), so the swarm does not march in lockstep.

Copies: one spider and one ant are built and configured as in ``examples.blend`` (Detect
Legs, the gait preset); every other creature of the kind is a linked duplicate of it, as
Alt+D makes: a new armature object sharing the armature data, with its skin sharing the mesh
data. Each keeps its own ProcLoco settings and gets its own Action on Generate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import bpy
import numpy as np
from mathutils import Vector

from . import creatures, terrain
from .procloco_props import set_role
from .scene import add_sun, bound_corners, configure_example_rig, frame_camera, setup_render, start_scene

#: Scale of each kind in the crowd: both about 0.6 m across (spider legs ~0.45 m).
CROWD_SCALE: dict[str, float] = {"spider": 5.0, "ant": 20.0}
#: Lanes: a spider lane every LANE_PITCH in y, an ant lane halfway between two.
LANE_PITCH = 1.2
ROW_PITCH = 1.0
#: x of each group's front row (the spiders' is negative: they walk towards +X).
FRONT_X = 1.1
FRAME_START = 1
FRAME_END = 168
FPS = 24
#: Where the camera looks from: in front of the crowd (-Y side), high up.
CAMERA_DIRECTION = (0.3, 1.0, -0.62)
X_RANGE = (-6.0, 5.5)
Y_RANGE = (-7.0, 7.0)
CELL = 0.25
LOG_RADIUS = 0.035
LOG_X = 0.0
#: (x, y, size, role) of the crates; the low ones stand in lanes, the tall ones beside the crowd.
CRATES: tuple[tuple[float, float, tuple[float, float, float], str], ...] = (
    (0.9, -2.7, (0.3, 0.3, 0.06), "STEP_OVER"),
    (1.2, 0.9, (0.35, 0.3, 0.07), "STEP_OVER"),
    (0.8, 3.3, (0.3, 0.35, 0.06), "STEP_OVER"),
    (1.6, -0.3, (0.3, 0.3, 0.06), "STEP_OVER"),
    (-0.9, -2.1, (0.3, 0.3, 0.06), "STEP_OVER"),
    (-1.2, 0.3, (0.3, 0.3, 0.07), "STEP_OVER"),
    (-0.8, 2.7, (0.3, 0.3, 0.06), "STEP_OVER"),
    (-1.4, -4.5, (0.35, 0.3, 0.06), "STEP_OVER"),
    (-5.0, 6.0, (0.8, 0.8, 1.0), "AVOID"),
    (3.5, 6.0, (0.8, 0.8, 1.0), "AVOID"),
)
_LOG_COLOR = (0.42, 0.28, 0.16, 1.0)


@dataclass
class CrowdScene:
    """What :func:`build_crowd_scene` made."""

    rigs: dict[str, list[bpy.types.Object]] = field(default_factory=dict)
    ground: bpy.types.Object | None = None
    log: bpy.types.Object | None = None
    crates: list[bpy.types.Object] = field(default_factory=list)
    camera: bpy.types.Object | None = None
    sun: bpy.types.Object | None = None


def crowd_ground_height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Gentle swells (±3 cm) across the ground; flat under the log and the crates."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    swell = 0.03 * np.sin(0.9 * x + 0.4) * np.sin(0.7 * y + 1.3)
    flat = np.ones_like(x)
    for cx, cy, size, _role in CRATES:
        near = np.maximum(np.abs(x - cx) - 0.5 * size[0], np.abs(y - cy) - 0.5 * size[1])
        flat = np.minimum(flat, np.clip(near / 0.4, 0.0, 1.0))
    flat = np.minimum(flat, np.clip((np.abs(x - LOG_X) - 0.1) / 0.5, 0.0, 1.0))
    return np.asarray(swell * flat)


def lanes(count: int, kind: str) -> np.ndarray:
    """y of each of ``count`` lanes of ``kind``: spider lanes ``LANE_PITCH`` apart around y = 0,
    each ant lane halfway between two spider lanes, whatever the counts."""
    k = np.arange(count) - count // 2
    return LANE_PITCH * (k + (0.25 if kind == "ant" else -0.25))


def starts(kind: str, count: int, n_lanes: int, front_x: float = FRONT_X) -> list[tuple[float, float]]:
    """Start (x, y) of ``count`` creatures of ``kind`` in ``n_lanes`` lanes, front row first,
    a little off the grid (a few cm) so the ranks are not ruler-straight."""
    ys = lanes(n_lanes, kind)
    side = -1.0 if kind == "spider" else 1.0
    rng = np.random.default_rng(17 if kind == "spider" else 71)
    out = []
    for i in range(count):
        row, lane = divmod(i, n_lanes)
        dx, dy = rng.uniform(-0.15, 0.15), rng.uniform(-0.05, 0.05)
        out.append((side * (front_x + ROW_PITCH * row) + dx, float(ys[lane]) + dy))
    return out


def _build_log(scene: bpy.types.Scene, collection: bpy.types.Collection, length: float) -> bpy.types.Object:
    """A low log lying across the crowd's way (along Y at ``LOG_X``), resting on the ground."""
    n = 12
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    verts = []
    for y in (-0.5 * length, 0.5 * length):
        verts += [(LOG_X + LOG_RADIUS * math.cos(a), y, LOG_RADIUS + LOG_RADIUS * math.sin(a)) for a in angle]
    faces: list[tuple[int, ...]] = [(i, (i + 1) % n, n + (i + 1) % n, n + i) for i in range(n)]
    faces += [tuple(range(n - 1, -1, -1)), tuple(range(n, 2 * n))]
    mesh = bpy.data.meshes.new("Log")
    mesh.from_pydata(verts, [], faces)
    mat = bpy.data.materials.get("Log") or bpy.data.materials.new("Log")
    mat.diffuse_color = _LOG_COLOR
    mesh.materials.append(mat)
    mesh.polygons.foreach_set("use_smooth", [True] * n + [False, False])
    mesh.update()
    log = bpy.data.objects.new("Log", mesh)
    collection.objects.link(log)
    set_role(log, "STEP_OVER")
    log["example_feature"] = "log"
    return log


def linked_duplicate(rig: bpy.types.Object, name: str, collection: bpy.types.Collection) -> bpy.types.Object:
    """A linked duplicate of ``rig`` and its skin (as Alt+D): new objects sharing the armature
    and mesh data, the skin parented to and deformed by the new rig. Custom properties and
    ProcLoco settings are copied; the animation is not."""
    copy = rig.copy()
    copy.name = name
    copy.animation_data_clear()
    collection.objects.link(copy)
    skin = creatures.skin_of(rig)
    if skin is not None:
        skin_copy = skin.copy()
        skin_copy.name = f"{name}_Skin"
        collection.objects.link(skin_copy)
        skin_copy.parent = copy
        for modifier in skin_copy.modifiers:
            if modifier.type == "ARMATURE" and modifier.object == rig:
                modifier.object = copy
    return copy


def _individualise(rig: bpy.types.Object, index: int) -> None:
    """A creature's own Seed Offset: its own start phase and a slightly different stride. Its
    speed and seed stay the kind's: rigs that differ in them walk in separate simulations."""
    settings = rig.procloco
    if "seed_offset" in settings.bl_rna.properties:
        settings.seed_offset = index + 1


def build_crowd_scene(scene: bpy.types.Scene, spiders: int = 40, ants: int = 20,
                      frame_end: int = FRAME_END, spider_lanes: int = 10, ant_lanes: int = 10,
                      front_x: float = FRONT_X) -> CrowdScene:
    """The crowd (collections ``Crowd`` and ``Terrain``), a camera framing it, a sun, Workbench
    at 640×360, frames 1–``frame_end`` at 24 fps. Spiders fill ``spider_lanes`` lanes row by
    row, ants ``ant_lanes``; each group's front row starts ``front_x`` from the log."""
    if spiders < 1 or ants < 0:
        raise ValueError("the crowd needs at least one spider and no negative number of ants")
    crowd_coll, terrain_coll = start_scene(scene, frame_end, "Crowd")
    out = CrowdScene()
    out.ground = terrain.build_ground(scene, "Ground", X_RANGE, Y_RANGE, CELL, crowd_ground_height,
                                      collection=terrain_coll)
    n_lanes = max(min(spiders, spider_lanes), min(ants, ant_lanes))
    out.log = _build_log(scene, terrain_coll, length=LANE_PITCH * (n_lanes + 1))
    for i, (x, y, size, role) in enumerate(CRATES):
        name = f"Crate.{'Low' if role == 'STEP_OVER' else 'Tall'}.{i + 1}"
        # On the ground, which is flat under every crate (the builder's default base follows
        # the other example's heightmap).
        out.crates.append(terrain.build_crate(scene, name, (x, y), size, role, terrain_coll, base_z=0.0))
    for kind, count, kind_lanes in (("spider", spiders, spider_lanes), ("ant", ants, ant_lanes)):
        if count == 0:
            continue
        title = kind.capitalize()
        places = starts(kind, count, min(count, kind_lanes), front_x)
        rng = np.random.default_rng(3 if kind == "spider" else 5)
        first = creatures.BUILDERS[kind](scene, name=f"{title}.001", location=(0.0, 0.0, 0.0),
                                         scale=CROWD_SCALE[kind], collection=crowd_coll)
        problems = configure_example_rig(first, kind, terrain_coll)
        if problems:
            first["procloco_pending_settings"] = "; ".join(problems)
        group = [first]
        group += [linked_duplicate(first, f"{title}.{i + 1:03d}", crowd_coll) for i in range(1, count)]
        facing = 0.5 * math.pi if kind == "spider" else -0.5 * math.pi  # -Y turned onto +X / -X
        for i, (rig, (x, y)) in enumerate(zip(group, places, strict=True)):
            rig.location = (x, y, float(crowd_ground_height(np.array(x), np.array(y))))
            rig.rotation_euler = (0.0, 0.0, facing + float(rng.uniform(-0.03, 0.03)))
            _individualise(rig, i)
        out.rigs[kind] = group
    setup_render(scene)
    out.sun = add_sun(scene)
    bpy.context.view_layer.update()
    # The crowd where it starts, and where its front rows are when it has crossed.
    skins = [s for s in (creatures.skin_of(r) for g in out.rigs.values() for r in g) if s is not None]
    points = bound_corners(skins)
    reach = (frame_end - FRAME_START) / FPS * max(r.procloco.speed for g in out.rigs.values() for r in g)
    points += [p + Vector((math.copysign(reach, -p.x), 0.0, 0.0)) for p in points]
    points += bound_corners([out.log, *out.crates[:-2]])
    out.camera = frame_camera(scene, points, direction=CAMERA_DIRECTION, margin=0.03)
    return out
