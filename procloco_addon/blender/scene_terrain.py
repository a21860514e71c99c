# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene meshes -> the core :class:`~procloco_addon.core.terrain.Environment`.

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
deforms) become *dynamic* soups: :func:`sample_motion` evaluates them once per frame and the
simulation moves them with ``Environment.set_soup_vertices`` before each step.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.terrain import NO_SURFACE, ROLE_AVOID, ROLE_GROUND, ROLE_STEP_OVER, Environment, TriangleSoup

__all__ = [
    "ROLE_ITEMS",
    "SceneTerrain",
    "TerrainError",
    "build_environment",
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


class TerrainError(ValueError):
    """No usable terrain (the message is meant for the user)."""


@dataclass
class SceneTerrain:
    """The environment built from the scene and where each soup came from.

    ``objects[i]`` made ``environment.soups[i]``; ``dynamic_index`` lists the soups that move
    and ``motion[k]`` is ``(F, v, 3)`` world vertices of ``dynamic_index[k]`` per frame of
    ``frames`` (filled by :func:`sample_motion`).
    """

    environment: Environment
    objects: tuple[str, ...]
    roles: tuple[int, ...]
    dynamic_index: tuple[int, ...]
    frames: np.ndarray
    motion: tuple[np.ndarray, ...]
    z_offset: float = 0.0
    warnings: list[str] = field(default_factory=list)

    def apply_frame(self, f: int) -> None:
        """Move every dynamic soup to where it is at ``frames[f]``."""
        for k, i in enumerate(self.dynamic_index):
            self.environment.set_soup_vertices(i, self.motion[k][f])


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


def _maybe_animated(obj: bpy.types.Object) -> bool:
    """Could the object move or deform over time (cheap test before sampling)?"""
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
    depsgraph = context.evaluated_depsgraph_get()
    frames_a = np.asarray(list(frames), dtype=np.int64)
    maybe = [o for o in objects if _maybe_animated(o)] if frames_a.size else []
    motion = sample_motion(context, maybe, frames_a) if maybe else {}
    soups: list[TriangleSoup] = []
    names: list[str] = []
    roles: list[int] = []
    dyn_index: list[int] = []
    dyn_motion: list[np.ndarray] = []
    offset = np.array([0.0, 0.0, z_offset])
    warnings: list[str] = []
    for obj in objects:
        verts, tris = read_triangles(obj, depsgraph)
        if tris.shape[0] == 0:
            continue
        track = motion.get(obj.name)
        if track is not None and track.shape[1] != verts.shape[0]:
            track = None
        # Vertices that are NaN or infinite (at any sampled frame) cannot be walked on: the
        # triangles using them are left out and the object is named.
        finite = np.all(np.isfinite(verts), axis=1)
        if track is not None:
            finite &= np.all(np.isfinite(track), axis=(0, 2))
        if not np.all(finite):
            keep = np.all(finite[tris], axis=1)
            warnings.append(f"'{obj.name}' has {int(np.sum(~finite))} vertices that are not finite (NaN or "
                            f"infinite): {int(np.sum(~keep))} of its {tris.shape[0]} triangles are left out "
                            "of the terrain")
            tris = tris[keep]
            verts = np.where(finite[:, None], verts, 0.0)
            if track is not None:
                track = np.where(finite[None, :, None], track, 0.0)
            if tris.shape[0] == 0:
                continue
        moving = track is not None and bool(np.max(np.abs(track - track[:1])) > 1e-6)
        role = object_role(obj, moving)
        if role not in _ROLE_CODES:
            continue
        if moving and track is not None:
            dyn_index.append(len(soups))
            dyn_motion.append(track + offset)
            verts = track[0]
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
) -> dict[str, np.ndarray]:
    """World vertices of each object at each frame: name -> ``(F, v, 3)``.

    Rigid movers are read once and moved by their world matrix per frame; objects whose
    mesh data or modifiers may change are re-evaluated per frame. The scene's current frame
    is restored afterwards.
    """
    scene = context.scene
    old_frame, old_sub = scene.frame_current, scene.frame_subframe
    depsgraph = context.evaluated_depsgraph_get()
    base: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    deforming: set[str] = set()
    for obj in objects:
        verts, _tris = read_triangles(obj, depsgraph)
        inv = np.linalg.inv(np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64))
        base[obj.name] = (verts @ inv[:3, :3].T + inv[:3, 3], inv)
        data = obj.data
        keys = getattr(data, "shape_keys", None)
        if (len(obj.modifiers) or getattr(data, "animation_data", None) is not None
                or (keys is not None and keys.animation_data is not None)):
            deforming.add(obj.name)
    out = {o.name: np.empty((len(frames), base[o.name][0].shape[0], 3)) for o in objects}
    try:
        for f, frame in enumerate(frames):
            scene.frame_set(int(frame))
            depsgraph = context.evaluated_depsgraph_get()
            for obj in objects:
                local = base[obj.name][0]
                if obj.name in deforming:
                    verts, _ = read_triangles(obj, depsgraph)
                    if verts.shape[0] != local.shape[0]:
                        out.pop(obj.name, None)  # topology changes: cannot be tracked
                        deforming.discard(obj.name)
                        continue
                    out[obj.name][f] = verts
                elif obj.name in out:
                    m = np.array(obj.evaluated_get(depsgraph).matrix_world, dtype=np.float64)
                    out[obj.name][f] = local @ m[:3, :3].T + m[:3, 3]
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
