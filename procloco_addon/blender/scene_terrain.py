# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene meshes -> the core :class:`~procloco_addon.core.world.terrain.Environment`.

Which objects: the meshes of a chosen collection (and its children), or by default every
visible mesh-like object of the view layer, minus

* anything whose terrain role (``Object.procloco_role``) is ``IGNORE``,
* the rigs being animated, their children and any mesh an Armature modifier ties to them
  (a creature's own skin is not ground).

Each object's role: ``GROUND`` and ``STEP_OVER`` are surfaces feet stand on or pass over,
``AVOID`` is never stepped on nor over. ``AUTO`` (the default) is ``GROUND`` for static
objects and ``STEP_OVER`` for animated ones.

Geometry is the *evaluated* mesh (modifiers applied) in world space, read with
``foreach_get`` into numpy (``loop_triangles``): no per-vertex or per-ray Python loop.

Objects that move during the frame range (their world matrix changes, or their mesh
deforms) become *dynamic* soups, moved before each simulation step. Work and memory follow
what changes: an object that only moves rigidly has its triangles read once and one matrix
per frame (a translation is a shift of the core's soup, ``Environment.move_soup``; a turn
re-places its vertices); only a deforming mesh is sampled per frame, in single precision,
and refused with a message when that would take more than :data:`DEFORM_BUDGET_BYTES`.
:func:`build_environment_steps` does this as progress steps (the operator shows them and
stops on Esc).
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import bpy
import numpy as np

from ..core.steps import run_steps
from ..core.world.terrain import (
    NO_SURFACE,
    ROLE_AVOID,
    ROLE_GROUND,
    ROLE_STEP_OVER,
    Environment,
    TriangleSoup,
)

__all__ = [
    "DEFORM_BUDGET_BYTES",
    "ROLE_ITEMS",
    "Motion",
    "SceneTerrain",
    "TerrainError",
    "build_environment",
    "build_environment_steps",
    "check_ground_under",
    "hidden_note",
    "object_role",
    "read_triangles",
    "sample_motion",
    "terrain_objects",
]

#: Items of ``Object.procloco_role``.
ROLE_ITEMS = (
    ("AUTO", "Auto", "Ground when static, step-over obstacle when animated"),
    ("GROUND", "Ground", "A surface feet stand on"),
    ("STEP_OVER", "Step Over", "An obstacle feet may stand on or step over"),
    ("AVOID", "Avoid", "An obstacle feet never touch nor pass over"),
    ("IGNORE", "Ignore", "Not part of the terrain"),
)
_ROLE_CODES = {"GROUND": ROLE_GROUND, "STEP_OVER": ROLE_STEP_OVER, "AVOID": ROLE_AVOID}
_MESHLIKE = frozenset({"MESH", "CURVE", "SURFACE", "FONT", "META"})


#: Most memory the per-frame vertices of deforming terrain may take (all objects together).
DEFORM_BUDGET_BYTES = 1 << 30


class TerrainError(ValueError):
    """No usable terrain (the message is meant for the user)."""


@dataclass
class Motion:
    """How one object moves over the frames ``F``: rigidly, ``relative`` ``(F, 4, 4)`` its
    world matrix at each frame times the inverse of the first frame's (vertices ``base``
    ``(v, 3)`` where they are at the first frame); or deforming, ``vertices`` ``(F, v, 3)``
    float32 world vertices per frame."""

    relative: np.ndarray | None = None
    base: np.ndarray | None = None
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None  # (f, 3) triangles, when read with the rigid base

    def at(self, f: int) -> np.ndarray:
        """World vertices ``(v, 3)`` at frame index ``f``."""
        if self.vertices is not None:
            return self.vertices[f].astype(np.float64)
        assert self.relative is not None
        assert self.base is not None
        m = self.relative[f]
        return self.base @ m[:3, :3].T + m[:3, 3]

    def moves(self) -> bool:
        """Does anything move by more than a micrometre?"""
        if self.vertices is not None:
            return bool(np.max(np.abs(self.vertices - self.vertices[:1])) > 1e-6)
        assert self.relative is not None
        assert self.base is not None
        reach = float(np.max(np.abs(self.base))) if self.base.size else 0.0
        d = self.relative - np.eye(4)
        return bool(np.max(np.abs(d[:, :3, :3])) * reach + np.max(np.abs(d[:, :3, 3])) > 1e-6)


@dataclass
class SceneTerrain:
    """The environment built from the scene and where each soup came from.

    ``objects[i]`` made ``environment.soups[i]``; ``dynamic_index`` lists the soups that move
    and ``motion[k]`` how ``dynamic_index[k]`` moves over ``frames`` (a :class:`Motion`, its
    vertices raised by ``z_offset`` like the soups').
    """

    environment: Environment
    objects: tuple[str, ...]
    roles: tuple[int, ...]
    dynamic_index: tuple[int, ...]
    frames: np.ndarray
    motion: tuple[Motion, ...]
    z_offset: float = 0.0
    warnings: list[str] = field(default_factory=list)

    def apply_frame(self, f: int) -> None:
        """Move every dynamic soup to where it is at ``frames[f]``."""
        for k, i in enumerate(self.dynamic_index):
            motion = self.motion[k]
            rel = motion.relative
            if rel is not None and np.allclose(rel[f, :3, :3], np.eye(3), rtol=0.0, atol=1e-12):
                self.environment.move_soup(i, rel[f, :3, 3])  # translated: triangles kept
            else:
                self.environment.set_soup_vertices(i, motion.at(f))


def object_role(obj: bpy.types.Object, animated: bool = False) -> str:
    """The object's terrain role name, ``AUTO`` resolved."""
    role = getattr(obj, "procloco_role", "AUTO")
    if role == "AUTO":
        return "STEP_OVER" if animated else "GROUND"
    return str(role)


def _rig_owned(obj: bpy.types.Object, rigs: set[str]) -> bool:
    """Is ``obj`` part of one of the rigs (a child of it, or deformed by it)?"""
    p = obj.parent
    while p is not None:
        if p.name in rigs:
            return True
        p = p.parent
    return any(m.type == "ARMATURE" and m.object is not None and m.object.name in rigs for m in obj.modifiers)


def _collection_objects(collection: bpy.types.Collection) -> list[bpy.types.Object]:
    return list(collection.all_objects)


def terrain_objects(
    context: bpy.types.Context,
    rigs: Iterable[bpy.types.Object] = (),
    collection: bpy.types.Collection | None = None,
) -> list[bpy.types.Object]:
    """The objects that make the terrain (see the module doc), in a stable order."""
    rig_names = {r.name for r in rigs}
    view_layer = context.view_layer
    view_layer.update()  # visibility flags of objects added since the last update
    if collection is not None:
        candidates = _collection_objects(collection)
    else:
        candidates = [o for o in view_layer.objects if o.visible_get(view_layer=view_layer)]
    out = []
    for obj in candidates:
        if obj.type not in _MESHLIKE or obj.name in rig_names:
            continue
        if getattr(obj, "procloco_role", "AUTO") == "IGNORE":
            continue
        if _rig_owned(obj, rig_names):
            continue
        out.append(obj)
    return sorted(out, key=lambda o: o.name)


def read_triangles(obj: bpy.types.Object, depsgraph: bpy.types.Depsgraph) -> tuple[np.ndarray, np.ndarray]:
    """World vertices ``(v, 3)`` and triangles ``(f, 3)`` of the evaluated object."""
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        mesh.calc_loop_triangles()
        n_v = len(mesh.vertices)
        co = np.empty(n_v * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        n_t = len(mesh.loop_triangles)
        tri = np.empty(n_t * 3, dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", tri)
    finally:
        ev.to_mesh_clear()
    m = np.array(ev.matrix_world, dtype=np.float64)
    verts = co.reshape(n_v, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    return verts, tri.reshape(n_t, 3).astype(np.int64)


# Modifiers whose result depends on the frame by themselves (no keys needed).
_TIME_MODIFIERS = frozenset({"WAVE", "OCEAN", "CLOTH", "SOFT_BODY", "DYNAMIC_PAINT", "FLUID", "EXPLODE",
                             "BUILD", "MESH_CACHE", "MESH_SEQUENCE_CACHE"})


def _maybe_animated(obj: bpy.types.Object, depth: int = 0) -> bool:
    """Could the object move or deform over time (cheap test before sampling)?"""
    for mod in getattr(obj, "modifiers", ()):
        if mod.type in _TIME_MODIFIERS:
            return True
        other = getattr(mod, "object", None)  # hooks, lattices, armatures, curves ...
        if other is not None and other != obj and depth < 4 and _maybe_animated(other, depth + 1):
            return True
    cur: bpy.types.Object | None = obj
    while cur is not None:
        adt = cur.animation_data
        if adt is not None and (adt.action is not None or len(adt.drivers) or len(adt.nla_tracks)):
            return True
        if len(cur.constraints):
            return True
        cur = cur.parent
    data = obj.data
    if data is not None and getattr(data, "animation_data", None) is not None:
        return True
    keys = getattr(data, "shape_keys", None)
    return bool(keys is not None and keys.animation_data is not None)


def build_environment(
    context: bpy.types.Context,
    objects: Sequence[bpy.types.Object],
    frames: Sequence[int] | np.ndarray = (),
    z_offset: float = 0.0,
) -> SceneTerrain:
    """Read ``objects`` at the current frame into an Environment of triangle soups.

    ``z_offset`` raises every surface (used to keep an ankle-high end-effector above the
    ground). When ``frames`` are given, objects that may be animated are sampled at each
    of them (:func:`sample_motion`) and those that really move become dynamic soups.
    Raises :class:`TerrainError` when there is nothing to walk on.
    """
    return run_steps(build_environment_steps(context, objects, frames, z_offset))


def build_environment_steps(
    context: bpy.types.Context,
    objects: Sequence[bpy.types.Object],
    frames: Sequence[int] | np.ndarray = (),
    z_offset: float = 0.0,
) -> Generator[float, None, SceneTerrain]:
    """:func:`build_environment` as progress steps: yields the fraction of the animated
    objects' frames sampled and returns the :class:`SceneTerrain`. Closing it early puts the
    scene's frame back."""
    depsgraph = context.evaluated_depsgraph_get()
    frames_a = np.asarray(list(frames), dtype=np.int64)
    maybe = [o for o in objects if _maybe_animated(o)] if frames_a.size else []
    motion: dict[str, Motion] = {}
    if maybe:
        motion = yield from sample_motion_steps(context, maybe, frames_a)
    soups: list[TriangleSoup] = []
    names: list[str] = []
    roles: list[int] = []
    dyn_index: list[int] = []
    dyn_motion: list[Motion] = []
    offset = np.array([0.0, 0.0, z_offset])
    warnings: list[str] = []
    for obj in objects:
        track = motion.get(obj.name)
        if track is not None and track.faces is not None and track.base is not None:
            verts, tris = track.base, track.faces  # read once, at the first frame
        else:
            verts, tris = read_triangles(obj, depsgraph)
        if tris.shape[0] == 0:
            continue
        if track is not None:
            if track.base is not None:
                verts = track.base  # where it is at the first frame
            elif track.vertices is not None and track.vertices.shape[1] != verts.shape[0]:
                track = None
        # Vertices that are NaN or infinite (at any sampled frame) cannot be walked on: the
        # triangles using them are left out and the object is named.
        finite = np.all(np.isfinite(verts), axis=1)
        if track is not None and track.vertices is not None:
            finite &= np.all(np.isfinite(track.vertices), axis=(0, 2))
        if track is not None and track.relative is not None and not np.all(np.isfinite(track.relative)):
            track = None  # a non-finite placement at some frame: read where it is now
        if not np.all(finite):
            keep = np.all(finite[tris], axis=1)
            warnings.append(f"'{obj.name}' has {int(np.sum(~finite))} vertices that are not finite (NaN or "
                            f"infinite): {int(np.sum(~keep))} of its {tris.shape[0]} triangles are left out "
                            "of the terrain")
            tris = tris[keep]
            verts = np.where(finite[:, None], verts, 0.0)
            if track is not None and track.vertices is not None:
                track.vertices = np.where(finite[None, :, None], track.vertices, 0.0).astype(np.float32)
            if track is not None and track.base is not None:
                track.base = verts
            if tris.shape[0] == 0:
                continue
        moving = track is not None and track.moves()
        role = object_role(obj, moving)
        if role not in _ROLE_CODES:
            continue
        if moving and track is not None:
            dyn_index.append(len(soups))
            verts = track.at(0)
            if track.vertices is not None:
                track.vertices += offset.astype(np.float32)
            elif track.relative is not None:
                # Rigid: the soup holds the first frame's vertices; each frame's placement
                # is relative to it, about the raised vertices.
                lift = np.eye(4)
                lift[2, 3] = z_offset
                track.relative = lift @ track.relative @ np.linalg.inv(lift)
                track.base = verts + offset
            dyn_motion.append(track)
        soups.append(TriangleSoup(verts + offset, tris, _ROLE_CODES[role], moving))
        names.append(obj.name)
        roles.append(_ROLE_CODES[role])
    if not soups:
        raise TerrainError("No ground mesh found: add a mesh under the creature "
                           "(or choose the terrain collection)")
    return SceneTerrain(Environment(soups=soups), tuple(names), tuple(roles), tuple(dyn_index), frames_a,
                        tuple(dyn_motion), z_offset, warnings)


def sample_motion(
    context: bpy.types.Context, objects: Sequence[bpy.types.Object], frames: np.ndarray
) -> dict[str, Motion]:
    """How each object moves over ``frames``: name -> :class:`Motion` (see
    :func:`sample_motion_steps`)."""
    return run_steps(sample_motion_steps(context, objects, frames))


def _deforms(obj: bpy.types.Object) -> bool:
    """Could the mesh itself change over time: a modifier that changes by itself or follows
    another object, a keyed modifier setting, animated mesh data or shape keys? (Other
    modifiers give the same mesh at every frame: the object then moves rigidly.)"""
    data = obj.data
    keys = getattr(data, "shape_keys", None)
    if getattr(data, "animation_data", None) is not None:
        return True
    if keys is not None and keys.animation_data is not None:
        return True
    adt = obj.animation_data
    if adt is not None:
        paths = [fc.data_path for fc in adt.drivers]
        if adt.action is not None:
            paths += [ch.data_path for ch in _channels(adt.action, obj)]
        if any(p.startswith("modifiers[") for p in paths) or len(adt.nla_tracks):
            return True
    return any(m.type in _TIME_MODIFIERS or getattr(m, "object", None) is not None for m in obj.modifiers)


def _channels(action: bpy.types.Action, obj: bpy.types.Object) -> list[Any]:
    from . import actions

    return actions.channels_of(action, obj)


def sample_motion_steps(
    context: bpy.types.Context, objects: Sequence[bpy.types.Object], frames: np.ndarray
) -> Generator[float, None, dict[str, Motion]]:
    """Play ``frames`` and record how each object moves; yields the fraction done and
    returns name -> :class:`Motion`.

    A rigid mover's triangles are read once and its world matrix per frame; an object whose
    mesh data or modifiers may change is re-read per frame (float32) — refused with
    :class:`TerrainError` beyond :data:`DEFORM_BUDGET_BYTES`. An object whose vertex count
    changes is dropped (it cannot be tracked). The scene's current frame is put back
    afterwards, also when the generator is closed early.
    """
    scene = context.scene
    old_frame, old_sub = scene.frame_current, scene.frame_subframe
    depsgraph = context.evaluated_depsgraph_get()
    n_f = len(frames)
    deforming = [o for o in objects if _deforms(o)]
    counts = {o.name: len(o.evaluated_get(depsgraph).data.vertices) if o.type == "MESH" else 0
              for o in deforming}
    need = sum(n_f * max(c, 1) * 12 for c in counts.values())
    if need > DEFORM_BUDGET_BYTES:
        big = max(counts, key=lambda n: counts[n])
        raise TerrainError(f"'{big}' deforms (modifiers, shape keys or animated mesh data): sampling it over "
                           f"{n_f} frames takes {need / 2**30:.1f} GiB, more than the "
                           f"{DEFORM_BUDGET_BYTES / 2**30:.0f} GiB allowed. Shorten the frame range, apply "
                           "its modifiers, or set its terrain role to Ignore")
    rigid = [o for o in objects if o not in deforming]
    matrices = {o.name: np.empty((n_f, 4, 4)) for o in rigid}
    vertices: dict[str, np.ndarray] = {}
    try:
        for f, frame in enumerate(frames):
            scene.frame_set(int(frame))
            depsgraph = context.evaluated_depsgraph_get()
            for obj in rigid:
                matrices[obj.name][f] = np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64)
            for obj in deforming:
                if obj.name not in counts:
                    continue
                verts, _ = read_triangles(obj, depsgraph)
                track = vertices.get(obj.name)
                if track is None:
                    track = vertices[obj.name] = np.empty((n_f, verts.shape[0], 3), dtype=np.float32)
                if verts.shape[0] != track.shape[1]:
                    vertices.pop(obj.name)  # topology changes: cannot be tracked
                    counts.pop(obj.name)
                    continue
                track[f] = verts
            yield (f + 1) / n_f
        scene.frame_set(int(frames[0]))
        depsgraph = context.evaluated_depsgraph_get()
        out: dict[str, Motion] = {name: Motion(vertices=v) for name, v in vertices.items()}
        for obj in rigid:
            m = matrices[obj.name]
            base, faces = read_triangles(obj, depsgraph)  # at the first frame
            with np.errstate(all="ignore"):
                rel = m @ np.linalg.inv(m[0]) if np.all(np.isfinite(m[0])) else m * np.nan
            out[obj.name] = Motion(relative=rel, base=base, faces=faces)
    finally:
        scene.frame_set(old_frame, subframe=old_sub)
    return out


#: How far above the ground (in leg lengths) a creature's feet may start.
MAX_START_GAP_LEGS = 2.0


def check_ground_under(
    terrain: SceneTerrain, points: np.ndarray, who: str, reach: float | None = None
) -> None:
    """Raise :class:`TerrainError` unless there is a surface under every point.

    ``points``: ``(n, 2)`` ground positions, or ``(n, 3)`` feet contacts; with 3D points and
    ``reach`` (the leg length), feet more than :data:`MAX_START_GAP_LEGS` leg lengths above
    the surface under them are refused too (the creature would drop onto it in one frame).
    """
    pts = np.asarray(points, dtype=np.float64)
    h = terrain.environment.height_at(pts[:, :2].reshape(-1, 2))
    if np.any(h <= NO_SURFACE * 0.5):
        missing = int(np.sum(h <= NO_SURFACE * 0.5))
        raise TerrainError(f"No ground under '{who}': {missing} of its feet stand over no mesh "
                           "(move it over the terrain or choose the terrain collection)")
    if reach is not None and pts.shape[1] == 3:
        gap = float(np.min(pts[:, 2] - (h - terrain.z_offset)))
        if gap > MAX_START_GAP_LEGS * reach:
            raise TerrainError(f"'{who}' stands {gap:.3g} m above the ground under it ({gap / reach:.3g} leg "
                               "lengths): move it down onto the terrain")


def hidden_note(context: bpy.types.Context, rigs: Iterable[bpy.types.Object] = ()) -> str:
    """`` ('A', 'B' hidden: ...)`` naming the hidden meshes of the view layer that would be
    terrain if they were visible, or ``""``: said when no ground is found."""
    rig_names = {r.name for r in rigs}
    view_layer = context.view_layer
    hidden = [o.name for o in view_layer.objects
              if o.type in _MESHLIKE and o.name not in rig_names and not o.visible_get(view_layer=view_layer)
              and getattr(o, "procloco_role", "AUTO") != "IGNORE" and not _rig_owned(o, rig_names)]
    if not hidden:
        return ""
    names = ", ".join(f"'{n}'" for n in sorted(hidden)[:5]) + (" ..." if len(hidden) > 5 else "")
    verb = "is" if len(hidden) == 1 else "are"
    return f" ({names} {verb} hidden: unhide it to walk on it)"
