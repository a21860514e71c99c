# SPDX-License-Identifier: GPL-3.0-or-later
"""Rigged, skinned example creatures for ProcLoco's tests and ``examples.blend``.

Every builder has the same signature and returns the armature object::

    build_spider(scene, name="Spider", location=(0, 0, 0), scale=1.0, collection=None)
    build_ant(...)      build_robot(...)     build_lizard(...)
    build_wolf(...)     build_human(...)     # Rigify wolf / human metarigs

``BUILDERS`` maps the kinds ``"spider" "ant" "robot" "lizard" "wolf" "human"`` to them.

Conventions (the same as Rigify's metarigs): the creature faces -Y, its left side is +X,
Z is up, and at ``location`` its feet stand on the plane ``z = location.z`` in the rest
pose. ``scale`` multiplies the rest geometry (bones and skin); the objects themselves keep
a unit scale, so rig readers see world sizes directly in the bones. The armature object
is linked to ``collection`` (default: the scene's master collection).

Sizes at ``scale=1`` are the real animal's, in metres:

========  ===================================================================  =============
kind      what                                                                  at scale 1
========  ===================================================================  =============
spider    tarantula: cephalothorax, abdomen, two pedipalps, 8 legs of 4 bones   legs ~9 cm,
                                                                                span ~15 cm
ant       large ant: thorax, head with 3-bone antennae, petiole, gaster,        body ~2.8 cm
          6 legs of 4 bones
robot     imaginary pentapod: a body, a sensor, 5 radial legs of 3 bones        span ~1.2 m
lizard    monitor-like: hips, 4 spine bones, chest, neck, head, 8-bone tail,    ~1 m long
          4 sprawling legs of 3 bones
wolf      Rigify wolf metarig (tail ``spine.003 > ... > spine``)                shoulder 0.9 m
human     Rigify human metarig                                                  1.98 m
========  ===================================================================  =============

``examples.blend`` scales the spider and the ant up (see ``tools/examples/scene.py``).

Leg chains (``LEG_CHAINS[kind]``: one tuple of bone names per leg, hip to foot, front
to back and left before right; ``BODY_BONE[kind]`` is the bone the legs hang from, through
the parents listed in the chain's first bone):

* spider/ant: ``Leg<n>_coxa.L > Leg<n>_femur.L > Leg<n>_tibia.L > Leg<n>_tarsus.L``
  (and ``.R``), children of ``Body`` (spider) or ``Thorax`` (ant);
* robot: ``Leg<n>_thigh > Leg<n>_shin > Leg<n>_foot``: no suffix for the midline front leg 1,
  ``.L``/``.R`` for the pairs 2 and 3 (a five-pointed star), children of ``Body``;
* lizard: hind ``thigh.L > shin.L > foot.L`` (child of ``Hips``) and front
  ``front_thigh.L > front_shin.L > front_foot.L`` (child of ``Chest``);
* wolf: Rigify's ``shoulder.L > front_thigh.L > front_shin.L > front_foot.L > front_toe.L``
  and ``thigh.L > shin.L > foot.L > toe.L``;
* human: Rigify's ``thigh.L > shin.L > foot.L > toe.L``.

In every chain the last bone's tail touches the ground. Leg bones are rolled so that
their local X axis is the knee hinge (horizontal, across the leg's vertical plane).

Skin: each creature has one mesh child named ``"<armature name>_Skin"`` (see
:func:`skin_of`): a tapered capsule per bone, one vertex group per bone (weight 1), an
Armature modifier on the armature, and a coloured material that Workbench shows. Skins get
the terrain role ``IGNORE``.

Settings: the builders set ``Object.procloco.speed`` and ``step_height`` (``RIG_SETTINGS``,
times ``scale``) when the add-on is registered, and ``obj["procloco_kind"]``; names the add-on
does not know are listed in ``obj["procloco_pending_settings"]``. They do not detect legs nor
apply a gait: ``GAIT_PRESET`` names the preset the example scene applies.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

import bpy
import numpy as np
from mathutils import Vector

from .procloco_props import apply_rig_settings, set_role

Vec3 = tuple[float, float, float]
Builder = Callable[..., Any]


@dataclass(frozen=True)
class BoneSpec:
    """One bone at ``scale=1``: creature space, feet on z=0, facing -Y, left at +X."""

    name: str
    parent: str | None
    head: Vec3
    tail: Vec3
    radius: tuple[float, float]  # skin capsule radius at head and tail; (0, 0) means no capsule
    connect: bool = False
    hinge: Vec3 | None = None  # leg bones: the knee axis the bone's X axis is rolled onto


# ---------------------------------------------------------------------------------------
# Geometry helpers


def _direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector ``azimuth`` degrees from forward (-Y) towards the left (+X), tilted up by ``elevation``."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.sin(a) * math.cos(e), -math.cos(a) * math.cos(e), math.sin(e)])


def _leg(
    names: Sequence[str],
    parent: str,
    hip: Vec3,
    azimuth_deg: float,
    lengths: Sequence[float],
    elevations_deg: Sequence[float],
    radii: Sequence[tuple[float, float]],
) -> list[BoneSpec]:
    """A leg in the vertical plane through ``hip`` at ``azimuth_deg``.

    ``elevations_deg`` gives the pitch of every segment but the last; the last one is
    pitched down just enough for its tail to reach the ground (z = 0).
    """
    if not len(names) == len(lengths) == len(radii) == len(elevations_deg) + 1:
        raise ValueError("a leg needs one length and radius per bone and one elevation less")
    hinge = _direction(azimuth_deg + 90.0, 0.0)  # horizontal, across the leg plane
    point = np.array(hip, dtype=float)
    specs: list[BoneSpec] = []
    for i, name in enumerate(names):
        if i < len(elevations_deg):
            elevation = elevations_deg[i]
        else:
            if not 0.0 < point[2] <= lengths[i]:
                raise ValueError(f"{name}: the last segment ({lengths[i]}) cannot reach the ground "
                                 f"from {point[2]}")
            elevation = -math.degrees(math.asin(point[2] / lengths[i]))
        tail = point + lengths[i] * _direction(azimuth_deg, elevation)
        if i == len(names) - 1:
            tail[2] = 0.0  # exactly on the ground, free of rounding
        specs.append(BoneSpec(name, parent if i == 0 else names[i - 1], _v(point), _v(tail), radii[i],
                              connect=i > 0, hinge=_v(hinge)))
        point = tail
    return specs


def _v(a: np.ndarray | Sequence[float]) -> Vec3:
    return (float(a[0]), float(a[1]), float(a[2]))


def _mirror(specs: Sequence[BoneSpec]) -> list[BoneSpec]:
    """The right-side copy (x -> -x, ``.L`` -> ``.R``) of left-side bones."""

    def flip_name(name: str | None) -> str | None:
        if name is not None and name.endswith(".L"):
            return name[:-2] + ".R"
        return name

    def flip(p: Vec3 | None) -> Vec3 | None:
        return None if p is None else (-p[0], p[1], p[2])

    out = []
    for s in specs:
        head, tail = flip(s.head), flip(s.tail)
        assert head is not None
        assert tail is not None
        out.append(replace(s, name=flip_name(s.name) or s.name, parent=flip_name(s.parent),
                           head=head, tail=tail, hinge=flip(s.hinge)))
    return out


def _chain(names: Sequence[str], parent: str | None, points: Sequence[Vec3],
           radii: Sequence[tuple[float, float]]) -> list[BoneSpec]:
    """Connected bones through ``points`` (one more point than names)."""
    return [BoneSpec(n, parent if i == 0 else names[i - 1], points[i], points[i + 1], radii[i], connect=i > 0)
            for i, n in enumerate(names)]


# ---------------------------------------------------------------------------------------
# Creature definitions at scale 1


def _mm(p: Sequence[float]) -> Vec3:
    return (p[0] * 1e-3, p[1] * 1e-3, p[2] * 1e-3)


def _spider_bones() -> list[BoneSpec]:
    mm = 1e-3
    bones = [
        # Cephalothorax from its back to the eyes; the legs hang from it.
        BoneSpec("Body", None, _mm((0, 10, 22)), _mm((0, -11, 24)), (10 * mm, 8 * mm)),
        BoneSpec("Abdomen", "Body", _mm((0, 13, 25)), _mm((0, 42, 27)), (14 * mm, 9 * mm)),
    ]
    palp = _chain(["Palp1.L", "Palp2.L"], "Body", [_mm((3, -11, 19)), _mm((6, -19, 22)), _mm((8, -26, 12))],
                  [(1.6 * mm, 1.4 * mm), (1.4 * mm, 1.0 * mm)])
    left = list(palp)
    # (azimuth from forward, femur elevation, coxa/femur/tibia/tarsus lengths in mm)
    legs = [(40.0, 48.0, (8, 25, 28, 30)), (75.0, 48.0, (8, 23, 25, 27)),
            (110.0, 50.0, (8, 20, 22, 26)), (150.0, 48.0, (8, 25, 28, 32))]
    for n, (azimuth, femur_up, lengths) in enumerate(legs, start=1):
        d = _direction(azimuth, 0.0) * 7.0
        hip = _mm((d[0], d[1], 21.0))
        names = [f"Leg{n}_{seg}.L" for seg in ("coxa", "femur", "tibia", "tarsus")]
        left += _leg(names, "Body", hip, azimuth, [x * mm for x in lengths], (10.0, femur_up, -40.0),
                     [(2.4 * mm, 2.2 * mm), (2.2 * mm, 1.9 * mm), (1.9 * mm, 1.5 * mm), (1.5 * mm, 0.9 * mm)])
    return bones + left + _mirror(left)


def _ant_bones() -> list[BoneSpec]:
    mm = 1e-3
    bones = [
        BoneSpec("Thorax", None, _mm((0, 3, 5)), _mm((0, -3, 5.6)), (1.5 * mm, 1.4 * mm)),
        BoneSpec("Head", "Thorax", _mm((0, -4, 5.8)), _mm((0, -8.5, 5.4)), (2.1 * mm, 1.8 * mm)),
        BoneSpec("Petiole", "Thorax", _mm((0, 3.4, 5.0)), _mm((0, 5.2, 5.6)), (0.7 * mm, 0.7 * mm)),
        BoneSpec("Gaster", "Petiole", _mm((0, 6.6, 6.0)), _mm((0, 12.0, 5.2)), (3.0 * mm, 2.2 * mm)),
    ]
    antenna_points = [_mm(p) for p in ((1.0, -7.5, 6.8), (2.6, -10.5, 9.6), (4.2, -13.5, 9.0),
                                       (5.0, -16.0, 6.8))]
    left = _chain(["Antenna1.L", "Antenna2.L", "Antenna3.L"], "Head", antenna_points,
                  [(0.35 * mm, 0.35 * mm), (0.35 * mm, 0.3 * mm), (0.3 * mm, 0.35 * mm)])
    leg_radii = [(0.5 * mm, 0.45 * mm), (0.45 * mm, 0.4 * mm), (0.4 * mm, 0.3 * mm), (0.3 * mm, 0.2 * mm)]
    # (hip y, azimuth, coxa/femur/tibia/tarsus lengths in mm)
    legs = [(-2.2, 35.0, (1.5, 5.0, 5.0, 5.0)), (0.0, 90.0, (1.5, 5.5, 5.5, 5.5)),
            (2.0, 140.0, (1.5, 6.5, 6.5, 6.5))]
    for n, (hip_y, azimuth, lengths) in enumerate(legs, start=1):
        names = [f"Leg{n}_{seg}.L" for seg in ("coxa", "femur", "tibia", "tarsus")]
        left += _leg(names, "Thorax", _mm((0.8, hip_y, 4.2)), azimuth, [x * mm for x in lengths],
                     (-40.0, 40.0, -45.0), leg_radii)
    return bones + left + _mirror(left)


def _robot_bones() -> list[BoneSpec]:
    bones = [
        BoneSpec("Body", None, (0.0, 0.12, 0.34), (0.0, -0.12, 0.34), (0.2, 0.2)),
        BoneSpec("Sensor", "Body", (0.0, 0.0, 0.5), (0.0, -0.06, 0.62), (0.05, 0.04)),
    ]
    radii = [(0.045, 0.04), (0.04, 0.03), (0.03, 0.02)]
    segments = ("thigh", "shin", "foot")
    lengths, elevations = (0.22, 0.32, 0.12), (30.0, -80.0)

    def hip(azimuth: float) -> Vec3:
        return _v(_direction(azimuth, 0.0) * 0.18 + np.array([0.0, 0.0, 0.32]))

    # A five-pointed star with one point ahead: the midline front leg 1, then pairs 2 and 3
    # (the labels M1, L2, R2, L3, R3 of the pentapod gait preset).
    front = _leg([f"Leg1_{seg}" for seg in segments], "Body", hip(0.0), 0.0, lengths, elevations, radii)
    left: list[BoneSpec] = []
    for n, azimuth in ((2, 72.0), (3, 144.0)):
        left += _leg([f"Leg{n}_{seg}.L" for seg in segments], "Body", hip(azimuth), azimuth, lengths,
                     elevations, radii)
    return bones + front + left + _mirror(left)


def _lizard_bones() -> list[BoneSpec]:
    z = 0.095
    spine_names = ["Hips", "Spine.001", "Spine.002", "Spine.003", "Spine.004", "Chest", "Neck", "Head"]
    spine_points: list[Vec3] = [
        (0.0, 0.12, z), (0.0, 0.06, z), (0.0, 0.0, z + 0.003), (0.0, -0.06, z + 0.005),
        (0.0, -0.12, z + 0.006), (0.0, -0.18, z + 0.006), (0.0, -0.25, z + 0.016),
        (0.0, -0.31, z + 0.022), (0.0, -0.41, z + 0.005),
    ]
    spine_radii = [(0.045, 0.05), (0.05, 0.052), (0.052, 0.052), (0.052, 0.05), (0.05, 0.046), (0.046, 0.04),
                   (0.036, 0.034), (0.036, 0.016)]
    bones = _chain(spine_names[:1], None, spine_points[:2], spine_radii[:1])
    bones += _chain(spine_names[1:], "Hips", spine_points[1:], spine_radii[1:])
    # The tail hangs from the hips' head and thins towards a tip just above the ground.
    n_tail = 8
    tail_points: list[Vec3] = [(0.0, 0.12 + 0.072 * i, z - (z - 0.03) * (i / n_tail) ** 1.5)
                               for i in range(n_tail + 1)]
    tail_r = np.linspace(0.042, 0.008, n_tail + 1)
    bones += _chain([f"Tail.{i:03d}" for i in range(1, n_tail + 1)], "Hips", tail_points,
                    [(float(tail_r[i]), float(tail_r[i + 1])) for i in range(n_tail)])
    leg_radii = [(0.024, 0.02), (0.02, 0.014), (0.014, 0.008)]
    left = _leg(["thigh.L", "shin.L", "foot.L"], "Hips", (0.04, 0.09, z - 0.01), 105.0,
                (0.09, 0.085, 0.06), (12.0, -62.0), leg_radii)
    left += _leg(["front_thigh.L", "front_shin.L", "front_foot.L"], "Chest", (0.04, -0.16, z - 0.005), 70.0,
                 (0.08, 0.08, 0.055), (12.0, -62.0), leg_radii)
    return bones + left + _mirror(left)


SPIDER_LEGS = tuple(tuple(f"Leg{n}_{seg}.{s}" for seg in ("coxa", "femur", "tibia", "tarsus"))
                    for n in range(1, 5) for s in "LR")
ANT_LEGS = tuple(tuple(f"Leg{n}_{seg}.{s}" for seg in ("coxa", "femur", "tibia", "tarsus"))
                 for n in range(1, 4) for s in "LR")
ROBOT_LEGS = (("Leg1_thigh", "Leg1_shin", "Leg1_foot"),
              *(tuple(f"Leg{n}_{seg}.{s}" for seg in ("thigh", "shin", "foot"))
                for n in (2, 3) for s in "LR"))
LIZARD_LEGS = (*(tuple(f"front_{seg}.{s}" for seg in ("thigh", "shin", "foot")) for s in "LR"),
               *(tuple(f"{seg}.{s}" for seg in ("thigh", "shin", "foot")) for s in "LR"))
_WOLF_FRONT = ("shoulder", "front_thigh", "front_shin", "front_foot", "front_toe")
WOLF_LEGS = (*(tuple(f"{seg}.{s}" for seg in _WOLF_FRONT) for s in "LR"),
             *(tuple(f"{seg}.{s}" for seg in ("thigh", "shin", "foot", "toe")) for s in "LR"))
HUMAN_LEGS = tuple(tuple(f"{seg}.{s}" for seg in ("thigh", "shin", "foot", "toe")) for s in "LR")

#: Per kind, one tuple of bone names per leg, hip to foot; front to back, left before right.
LEG_CHAINS: dict[str, tuple[tuple[str, ...], ...]] = {
    "spider": SPIDER_LEGS, "ant": ANT_LEGS, "robot": ROBOT_LEGS,
    "lizard": LIZARD_LEGS, "wolf": WOLF_LEGS, "human": HUMAN_LEGS,
}
#: Per kind, the root bone of the armature (pelvis/body).
ROOT_BONE = {"spider": "Body", "ant": "Thorax", "robot": "Body", "lizard": "Hips", "wolf": "spine.004",
             "human": "spine"}
#: Per kind, the bone each leg chain's first bone is parented to.
BODY_BONE: dict[str, tuple[str, ...]] = {
    "spider": ("Body",) * 8, "ant": ("Thorax",) * 6, "robot": ("Body",) * 5,
    "lizard": ("Chest", "Chest", "Hips", "Hips"),
    "wolf": ("spine.008", "spine.008", "spine.005", "spine.005"), "human": ("spine", "spine"),
}
#: Chains that are not legs but carry secondary motion (antennae, tails, palps), per kind.
APPENDAGES: dict[str, tuple[tuple[str, ...], ...]] = {
    "spider": (("Palp1.L", "Palp2.L"), ("Palp1.R", "Palp2.R"), ("Abdomen",)),
    "ant": (("Antenna1.L", "Antenna2.L", "Antenna3.L"), ("Antenna1.R", "Antenna2.R", "Antenna3.R"),
            ("Petiole", "Gaster")),
    "robot": (),
    "lizard": (tuple(f"Tail.{i:03d}" for i in range(1, 9)),),
    "wolf": (("spine.003", "spine.002", "spine.001", "spine"),),
    "human": (),
}

#: First-click ProcLoco settings per kind at scale 1 (lengths and speeds are multiplied by
#: ``scale``). Names are properties of ``Object.procloco``. Speeds are walking speeds, a
#: little under what the kind's gait preset gives at its leg length, so steps stay short.
RIG_SETTINGS: dict[str, dict[str, float]] = {
    "spider": {"speed": 0.06, "step_height": 0.012},
    "ant": {"speed": 0.012, "step_height": 0.002},
    "robot": {"speed": 0.45, "step_height": 0.08},
    "lizard": {"speed": 0.3, "step_height": 0.03, "use_visual_yaw": True},  # the thesis's lizard sway
    "wolf": {"speed": 0.8, "step_height": 0.08},
    "human": {"speed": 1.2, "step_height": 0.08},
}
_SCALED_SETTINGS = ("speed", "step_height")
#: Changes to the suggested secondary-motion chains per kind: ``{word in the chain's root
#: bone: {setting: value}}`` (settings of ``Object.procloco_secondary.chains``).
SECONDARY_SETTINGS: dict[str, dict[str, dict[str, float | bool]]] = {
    # A lively tail; stiff ears (a wolf's stand up: the default springy ears flop by 40°).
    "wolf": {"spine.003": {"settling_time": 1.0, "damping": 0.25},
             "ear": {"settling_time": 0.2, "damping": 0.9}},
}
#: The shipped gait preset (file stem in ``presets/gait``) each kind walks with; the example
#: scene applies it once the legs are detected (see ``scene.configure_example_rig``).
GAIT_PRESET: dict[str, str] = {
    "spider": "octopod_alternating_tetrapod",
    "ant": "hexapod_tripod",
    "robot": "pentapod_robot",
    "lizard": "quadruped_trot",
    "wolf": "quadruped_walk",
    "human": "biped_walk",
}

SKIN_COLORS: dict[str, tuple[float, float, float, float]] = {
    "spider": (0.12, 0.09, 0.08, 1.0),
    "ant": (0.55, 0.12, 0.06, 1.0),
    "robot": (0.55, 0.6, 0.68, 1.0),
    "lizard": (0.33, 0.5, 0.18, 1.0),
    "wolf": (0.45, 0.42, 0.4, 1.0),
    "human": (0.85, 0.62, 0.48, 1.0),
}


# ---------------------------------------------------------------------------------------
# Blender plumbing


@contextmanager
def _active_scene(scene: bpy.types.Scene) -> Iterator[None]:
    """Make ``scene`` the window's scene (edit mode and Rigify's operators act on it)."""
    window = bpy.context.window
    previous = window.scene if window is not None else None
    if window is not None and previous != scene:
        window.scene = scene
    try:
        if bpy.context.mode != "OBJECT" and bpy.context.active_object is not None:
            bpy.ops.object.mode_set(mode="OBJECT")
        yield
    finally:
        if window is not None and previous is not None and window.scene != previous:
            window.scene = previous


@contextmanager
def _edit_mode(scene: bpy.types.Scene, obj: bpy.types.Object) -> Iterator[None]:
    view_layer = scene.view_layers[0]
    view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        yield
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")


def _layer_collection(layer: bpy.types.LayerCollection, collection: bpy.types.Collection) -> Any:
    if layer.collection == collection:
        return layer
    for child in layer.children:
        found = _layer_collection(child, collection)
        if found is not None:
            return found
    return None


def _material(name: str, color: Sequence[float]) -> bpy.types.Material:
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    mat.diffuse_color = tuple(color)
    mat.roughness = 0.6
    if mat.node_tree is not None:
        bsdf = next((n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
        if bsdf is not None:
            bsdf.inputs["Base Color"].default_value = tuple(color)
    return mat


def _capsule(length: float, r0: float, r1: float,
             n_around: int = 10) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """A capsule along +Y from 0 to ``length``, radius ``r0`` at the head and ``r1`` at the tail.

    Returns bone-space vertices ``(n_verts, 3)`` and faces (triangles at the poles, quads between rings).
    """
    cap = np.radians([30.0, 60.0, 90.0])
    axial = np.concatenate([-r0 * np.cos(cap), length + r1 * np.cos(cap[::-1])])
    radial = np.concatenate([r0 * np.sin(cap), r1 * np.sin(cap[::-1])])
    angle = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
    n_rings = axial.shape[0]
    rings = np.empty((n_rings, n_around, 3))
    rings[:, :, 0] = radial[:, None] * np.cos(angle)[None, :]
    rings[:, :, 1] = axial[:, None]
    rings[:, :, 2] = radial[:, None] * np.sin(angle)[None, :]
    verts = np.concatenate([[[0.0, -r0, 0.0]], rings.reshape(-1, 3), [[0.0, length + r1, 0.0]]])
    last = verts.shape[0] - 1
    faces: list[tuple[int, ...]] = []
    for j in range(n_around):
        k = (j + 1) % n_around
        faces.append((0, 1 + k, 1 + j))
        for r in range(n_rings - 1):
            a, b = 1 + r * n_around, 1 + (r + 1) * n_around
            faces.append((a + j, a + k, b + k, b + j))
        base = 1 + (n_rings - 1) * n_around
        faces.append((base + j, base + k, last))
    return verts, faces


def _build_skin(arm: bpy.types.Object, radii: Mapping[str, tuple[float, float]],
                color: Sequence[float], collection: bpy.types.Collection) -> bpy.types.Object:
    """One capsule per bone in ``radii``, rigidly weighted to its bone, deformed by ``arm``."""
    all_verts: list[np.ndarray] = []
    all_faces: list[tuple[int, ...]] = []
    groups: list[tuple[str, range]] = []
    offset = 0
    for bone in arm.data.bones:
        if bone.name not in radii:
            continue
        r0, r1 = radii[bone.name]
        if r0 <= 0.0 and r1 <= 0.0:
            continue
        # Keep the capsule ends (mostly) above the ground plane of the rest pose.
        r0 = min(r0, max(bone.head_local.z, 0.35 * r0))
        r1 = min(r1, max(bone.tail_local.z, 0.35 * r1))
        verts, faces = _capsule(bone.length, r0, r1)
        m = np.array(bone.matrix_local)
        verts = verts @ m[:3, :3].T + m[:3, 3]
        all_verts.append(verts)
        all_faces += [tuple(i + offset for i in f) for f in faces]
        groups.append((bone.name, range(offset, offset + verts.shape[0])))
        offset += verts.shape[0]
    mesh = bpy.data.meshes.new(f"{arm.name}_Skin")
    mesh.from_pydata(np.concatenate(all_verts).tolist(), [], all_faces)
    mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), dtype=bool))
    mesh.materials.append(_material(f"{arm.name} skin", color))
    mesh.update()
    skin = bpy.data.objects.new(f"{arm.name}_Skin", mesh)
    collection.objects.link(skin)
    skin.parent = arm
    for bone_name, indices in groups:
        skin.vertex_groups.new(name=bone_name).add(list(indices), 1.0, "REPLACE")
    modifier = skin.modifiers.new("Armature", "ARMATURE")
    modifier.object = arm
    modifier.use_vertex_groups = True
    set_role(skin, "IGNORE")
    return skin


def skin_of(arm: bpy.types.Object) -> bpy.types.Object | None:
    """The skinned mesh a builder made for ``arm``: a child mesh deformed by it."""
    for child in arm.children:
        if child.type == "MESH" and any(m.type == "ARMATURE" and m.object == arm for m in child.modifiers):
            return child
    return None


def _finish(arm: bpy.types.Object, kind: str, scale: float) -> None:
    settings = {k: v * scale if k in _SCALED_SETTINGS else v for k, v in RIG_SETTINGS[kind].items()}
    missing = apply_rig_settings(arm, settings)
    arm["procloco_kind"] = kind
    if missing:  # the add-on is not registered, or lacks these settings
        arm["procloco_pending_settings"] = ",".join(sorted(missing))


def _build_custom(kind: str, bones: Sequence[BoneSpec], scene: bpy.types.Scene, name: str,
                  location: Sequence[float], scale: float,
                  collection: bpy.types.Collection | None) -> bpy.types.Object:
    if scale <= 0.0:
        raise ValueError("scale must be positive")
    collection = collection or scene.collection
    data = bpy.data.armatures.new(name)
    arm = bpy.data.objects.new(name, data)
    collection.objects.link(arm)
    arm.location = tuple(location)
    data.display_type = "STICK" if kind in ("spider", "ant") else "OCTAHEDRAL"
    with _active_scene(scene), _edit_mode(scene, arm):
        edit = data.edit_bones
        for spec in bones:
            eb = edit.new(spec.name)
            eb.head = Vector(spec.head) * scale
            eb.tail = Vector(spec.tail) * scale
        for spec in bones:
            eb = edit[spec.name]
            if spec.parent is not None:
                eb.parent = edit[spec.parent]
                eb.use_connect = spec.connect
            direction = (eb.tail - eb.head).normalized()
            if spec.hinge is not None:
                eb.align_roll(Vector(spec.hinge).cross(direction))  # local X onto the hinge
            else:
                up = Vector((0.0, 0.0, 1.0))
                eb.align_roll(up if abs(direction.dot(up)) < 0.95 else Vector((0.0, -1.0, 0.0)))
    radii = {s.name: (s.radius[0] * scale, s.radius[1] * scale) for s in bones}
    _build_skin(arm, radii, SKIN_COLORS[kind], collection)
    _finish(arm, kind, scale)
    return arm


# ---------------------------------------------------------------------------------------
# Public builders


def build_spider(scene: bpy.types.Scene, name: str = "Spider", location: Sequence[float] = (0.0, 0.0, 0.0),
                 scale: float = 1.0, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """An 8-legged tarantula (legs ~9 cm at ``scale=1``); returns the armature object."""
    return _build_custom("spider", _spider_bones(), scene, name, location, scale, collection)


def build_ant(scene: bpy.types.Scene, name: str = "Ant", location: Sequence[float] = (0.0, 0.0, 0.0),
              scale: float = 1.0, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """A 6-legged ant with 3-bone antennae (2.8 cm long at ``scale=1``); returns the armature object."""
    return _build_custom("ant", _ant_bones(), scene, name, location, scale, collection)


def build_robot(scene: bpy.types.Scene, name: str = "Robot", location: Sequence[float] = (0.0, 0.0, 0.0),
                scale: float = 1.0, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """A 5-legged robot: two side pairs and one rear midline leg; returns the armature object."""
    return _build_custom("robot", _robot_bones(), scene, name, location, scale, collection)


def build_lizard(scene: bpy.types.Scene, name: str = "Lizard", location: Sequence[float] = (0.0, 0.0, 0.0),
                 scale: float = 1.0, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """A sprawling lizard with a 6-bone spine, neck, head and 8-bone tail; returns the armature object."""
    return _build_custom("lizard", _lizard_bones(), scene, name, location, scale, collection)


def _descends_from(bone: Any, ancestor: str) -> bool:
    while bone is not None:
        if bone.name == ancestor:
            return True
        bone = bone.parent
    return False


def _build_metarig(kind: str, operator: Callable[[], Any],
                   radius_of: Callable[[Any, float], tuple[float, float]],
                   scene: bpy.types.Scene, name: str, location: Sequence[float], scale: float,
                   collection: bpy.types.Collection | None,
                   before_skin: Callable[[bpy.types.Scene, bpy.types.Object], None] | None = None,
                   ) -> bpy.types.Object:
    import addon_utils

    if scale <= 0.0:
        raise ValueError("scale must be positive")
    if not addon_utils.check("rigify")[1]:  # (enabled by default, loaded)
        addon_utils.enable("rigify", default_set=True)
    collection = collection or scene.collection
    with _active_scene(scene):
        view_layer = bpy.context.view_layer
        layer = _layer_collection(view_layer.layer_collection, collection)
        if layer is None:
            raise ValueError(f"collection {collection.name!r} is not in scene {scene.name!r}")
        previous_layer = view_layer.active_layer_collection
        view_layer.active_layer_collection = layer
        try:
            operator()
        finally:
            view_layer.active_layer_collection = previous_layer
        arm = view_layer.objects.active
        arm.name = name
        arm.data.name = name
        arm.location = tuple(location)
        if scale != 1.0:
            with _edit_mode(scene, arm):
                # Read every joint first: a connected bone's head is its parent's tail, so
                # scaling bone by bone would scale shared joints twice (and compound).
                rest = [(eb, eb.head.copy(), eb.tail.copy()) for eb in arm.data.edit_bones]
                for eb, head, tail in rest:
                    eb.head = head * scale
                    eb.tail = tail * scale
        if before_skin is not None:
            before_skin(scene, arm)
    radii: dict[str, tuple[float, float]] = {}
    for bone in arm.data.bones:
        if _descends_from(bone, "face"):
            continue  # the head's capsule stands for the face rig
        r0, r1 = radius_of(bone, bone.length / scale)  # (the radii of the unit-size rig)
        radii[bone.name] = (r0 * scale, r1 * scale)
    _build_skin(arm, radii, SKIN_COLORS[kind], collection)
    _finish(arm, kind, scale)
    return arm


def _wolf_radius(bone: Any, length: float) -> tuple[float, float]:
    fixed = {
        "spine.004": (0.11, 0.11), "spine.005": (0.11, 0.11), "spine.006": (0.115, 0.12),
        "spine.007": (0.12, 0.13), "spine.008": (0.13, 0.1), "spine.009": (0.075, 0.07),
        "spine.010": (0.07, 0.07), "spine.011": (0.08, 0.05),
        "spine.003": (0.05, 0.04), "spine.002": (0.045, 0.04), "spine.001": (0.04, 0.03),
        "spine": (0.03, 0.015),
        "shoulder.L": (0.04, 0.04), "shoulder.R": (0.04, 0.04),
        "thigh.L": (0.06, 0.04), "thigh.R": (0.06, 0.04),
    }
    if bone.name in fixed:
        return fixed[bone.name]
    words = set(bone.name.split(".")[0].split("_"))
    if "palm" in words:  # the paw's pads: thick enough to read as a paw, not as fingers
        return 0.022, 0.02
    if words & {"index", "middle", "ring", "pinky"}:
        return 0.016, 0.014
    r = min(max(0.18 * length, 0.008), 0.04)
    return r, 0.85 * r


def _human_radius(bone: Any, length: float) -> tuple[float, float]:
    fixed = {
        "spine": (0.13, 0.13), "spine.001": (0.12, 0.12), "spine.002": (0.12, 0.13), "spine.003": (0.13, 0.1),
        "spine.004": (0.05, 0.05), "spine.005": (0.05, 0.06), "spine.006": (0.1, 0.08),
        "thigh.L": (0.08, 0.055), "thigh.R": (0.08, 0.055), "shin.L": (0.055, 0.04), "shin.R": (0.055, 0.04),
        "foot.L": (0.04, 0.035), "foot.R": (0.04, 0.035), "toe.L": (0.03, 0.025), "toe.R": (0.03, 0.025),
        "upper_arm.L": (0.045, 0.038), "upper_arm.R": (0.045, 0.038),
        "forearm.L": (0.038, 0.03), "forearm.R": (0.038, 0.03), "hand.L": (0.03, 0.025),
        "hand.R": (0.03, 0.025), "shoulder.L": (0.045, 0.045), "shoulder.R": (0.045, 0.045),
        "breast.L": (0.0, 0.0), "breast.R": (0.0, 0.0),
        "pelvis.L": (0.0, 0.0), "pelvis.R": (0.0, 0.0), "heel.02.L": (0.0, 0.0), "heel.02.R": (0.0, 0.0),
    }
    if bone.name in fixed:
        return fixed[bone.name]
    r = min(max(0.25 * length, 0.006), 0.012)
    return r, 0.85 * r


def build_wolf(scene: bpy.types.Scene, name: str = "Wolf", location: Sequence[float] = (0.0, 0.0, 0.0),
               scale: float = 1.0, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """Rigify's wolf metarig (hips ``spine.004``, tail ``spine.003 > ... > spine``) with a capsule skin."""
    return _build_metarig("wolf", bpy.ops.object.armature_wolf_metarig_add, _wolf_radius,
                          scene, name, location, scale, collection)


#: Where the example human's upper arms and forearms point at rest (left arm; the right one
#: mirrored): hanging at its sides, a little out, the elbows slightly bent, instead of the
#: metarig's A pose.
HUMAN_ARM_DIRECTION: dict[str, Vec3] = {"upper_arm": (0.2, -0.05, -1.0), "forearm": (0.1, -0.3, -1.0)}


def _lower_arms(scene: bpy.types.Scene, arm: bpy.types.Object) -> None:
    """Turn each arm bone of :data:`HUMAN_ARM_DIRECTION` (and every bone below it) about its
    head so it points that way, in the rest pose."""
    with _edit_mode(scene, arm):
        edit = arm.data.edit_bones
        for side, sign in (("L", 1.0), ("R", -1.0)):
            for name, (x, y, z) in HUMAN_ARM_DIRECTION.items():
                bone = edit.get(f"{name}.{side}")
                if bone is None:
                    continue
                turn = (bone.tail - bone.head).rotation_difference(Vector((sign * x, y, z))).to_matrix()
                pivot = bone.head.copy()
                # All new ends first: connected children's heads follow their parents' tails.
                moved = [(eb, pivot + turn @ (eb.head - pivot), pivot + turn @ (eb.tail - pivot),
                          turn @ eb.z_axis) for eb in [bone, *bone.children_recursive]]
                for eb, head, tail, z_axis in moved:
                    eb.head, eb.tail = head, tail
                    eb.align_roll(z_axis)


def build_human(scene: bpy.types.Scene, name: str = "Human", location: Sequence[float] = (0.0, 0.0, 0.0),
                scale: float = 1.0, collection: bpy.types.Collection | None = None) -> bpy.types.Object:
    """Rigify's human metarig (hips ``spine``, legs ``thigh > shin > foot > toe``) with a capsule
    skin, its arms lowered to hang at its sides (:data:`HUMAN_ARM_DIRECTION`)."""
    return _build_metarig("human", bpy.ops.object.armature_human_metarig_add, _human_radius,
                          scene, name, location, scale, collection, before_skin=_lower_arms)


#: The builders by kind.
BUILDERS: dict[str, Builder] = {
    "spider": build_spider, "ant": build_ant, "robot": build_robot,
    "lizard": build_lizard, "wolf": build_wolf, "human": build_human,
}
