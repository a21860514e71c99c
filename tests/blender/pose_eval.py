# SPDX-License-Identifier: GPL-3.0-or-later
"""Helpers for tests: evaluate an animated rig through Blender's depsgraph, frame by frame.

These read what Blender itself computes (``scene.frame_set`` then the evaluated object's
pose), never what ProcLoco believes it wrote, so assertions check the real result: Actions,
constraints, parenting and object transforms included.

Shapes: ``frames`` ``(n_frames,)``; matrices ``(n_frames, n_bones, 4, 4)``; points
``(n_frames, n_bones, 3)``; all in world space unless a name says otherwise.
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np


def pose_matrices(obj: bpy.types.Object, frames: Sequence[int], bone_names: Sequence[str]) -> np.ndarray:
    """World matrices of ``bone_names`` of armature ``obj`` at each frame: ``(F, B, 4, 4)``."""
    scene = bpy.context.scene
    names = [pb.name for pb in obj.pose.bones]
    index = np.array([names.index(n) for n in bone_names], dtype=np.int64)
    out = np.empty((len(frames), len(bone_names), 4, 4))
    buf = np.empty(len(names) * 16, dtype=np.float32)
    old = scene.frame_current
    try:
        for f, frame in enumerate(frames):
            scene.frame_set(int(frame))
            depsgraph = bpy.context.evaluated_depsgraph_get()
            ev = obj.evaluated_get(depsgraph)
            ev.pose.bones.foreach_get("matrix", buf)
            # foreach_get gives each 4x4 column-major (Blender's matrix memory layout).
            local = buf.reshape(len(names), 4, 4).transpose(0, 2, 1)[index].astype(np.float64)
            world = np.array(ev.matrix_world, dtype=np.float64)
            out[f] = world @ local
    finally:
        scene.frame_set(old)
    return out


def bone_heads_tails(
    obj: bpy.types.Object, frames: Sequence[int], bone_names: Sequence[str]
) -> tuple[np.ndarray, np.ndarray]:
    """World head and tail positions ``(F, B, 3)`` of the named bones at each frame."""
    mats = pose_matrices(obj, frames, bone_names)
    lengths = np.array([obj.data.bones[n].length for n in bone_names])
    heads = mats[..., :3, 3]
    # A pose bone's tail lies along its local +Y axis, at the bone's length (scaled by the matrix).
    tails = heads + mats[..., :3, 1] * lengths[None, :, None]
    return heads, tails


def object_world_matrices(obj: bpy.types.Object, frames: Sequence[int]) -> np.ndarray:
    """Evaluated world matrix of any object at each frame: ``(F, 4, 4)``."""
    scene = bpy.context.scene
    out = np.empty((len(frames), 4, 4))
    old = scene.frame_current
    try:
        for f, frame in enumerate(frames):
            scene.frame_set(int(frame))
            depsgraph = bpy.context.evaluated_depsgraph_get()
            out[f] = np.array(obj.evaluated_get(depsgraph).matrix_world)
    finally:
        scene.frame_set(old)
    return out


def skin_vertices(mesh_obj: bpy.types.Object, frames: Sequence[int], groups: Sequence[str],
                  min_weight: float = 0.5) -> np.ndarray:
    """World positions ``(F, p, 3)`` of ``mesh_obj``'s vertices weighted at least ``min_weight``
    to any of the vertex ``groups``, deformed (the evaluated mesh) at each frame."""
    wanted = {g.index for g in mesh_obj.vertex_groups if g.name in groups}
    index = np.array([v.index for v in mesh_obj.data.vertices
                      if any(g.group in wanted and g.weight >= min_weight for g in v.groups)], dtype=np.int64)
    scene = bpy.context.scene
    out = np.empty((len(frames), index.size, 3))
    old = scene.frame_current
    try:
        for f, frame in enumerate(frames):
            scene.frame_set(int(frame))
            ev = mesh_obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
            mesh = ev.to_mesh()
            co = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
            mesh.vertices.foreach_get("co", co)
            world = np.array(ev.matrix_world, dtype=np.float64)
            ev.to_mesh_clear()
            pts = co.reshape(-1, 3)[index]
            out[f] = pts @ world[:3, :3].T + world[:3, 3]
    finally:
        scene.frame_set(old)
    return out


def ray_heights(xy: np.ndarray, objects: Sequence[bpy.types.Object], z_top: float = 100.0) -> np.ndarray:
    """Highest surface of ``objects`` straight under each point, by ray casts into the evaluated
    meshes at the current frame. xy: ``(n, 2)``; returns ``(n,)`` (``-inf`` where nothing is hit)."""
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    depsgraph = bpy.context.evaluated_depsgraph_get()
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    best = np.full(len(xy), -np.inf)
    for ob in objects:
        ev = ob.evaluated_get(depsgraph)
        tree = BVHTree.FromObject(ev, depsgraph)
        mw = ev.matrix_world
        inv = mw.inverted()
        direction = (inv.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
        for n, (x, y) in enumerate(xy):
            origin = inv @ Vector((x, y, z_top))
            hit = tree.ray_cast(origin, direction)
            if hit[0] is not None:
                z = (mw @ hit[0]).z
                best[n] = max(best[n], z)
    return best


def inside_any(points: np.ndarray, objects: Sequence[bpy.types.Object], margin: float = 0.0) -> np.ndarray:
    """Whether each point ``(n, 3)`` lies inside one of the closed meshes ``objects`` deeper than
    ``margin``, at the current frame (nearest-surface normal test). Returns ``(n,)`` bool."""
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    depsgraph = bpy.context.evaluated_depsgraph_get()
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    inside = np.zeros(len(pts), dtype=bool)
    for ob in objects:
        ev = ob.evaluated_get(depsgraph)
        tree = BVHTree.FromObject(ev, depsgraph)
        mw = ev.matrix_world
        inv = mw.inverted()
        for n, p in enumerate(pts):
            local = inv @ Vector(p)
            loc, normal, _i, _d = tree.find_nearest(local)
            if loc is None:
                continue
            depth_vec = mw.to_3x3() @ (loc - local)
            if normal.dot(local - loc) < 0.0 and depth_vec.length > margin:
                inside[n] = True
    return inside


def leg_joints(
    obj: bpy.types.Object, frames: Sequence[int], legs: Sequence[Sequence[str]]
) -> list[np.ndarray]:
    """Per leg (bone names hip to end-effector) the evaluated world joints ``(F, k + 1, 3)``:
    each bone's head, then the last bone's tail."""
    names = [b for leg in legs for b in leg]
    heads, tails = bone_heads_tails(obj, frames, names)
    out = []
    k = 0
    for leg in legs:
        n = len(leg)
        out.append(np.concatenate([heads[:, k:k + n], tails[:, k + n - 1:k + n]], axis=1))
        k += n
    return out


def ray_heights_over_time(
    frames: Sequence[int], xy: np.ndarray, objects: Sequence[bpy.types.Object]
) -> np.ndarray:
    """Ray-cast surface heights under ``xy`` ``(F, n, 2)`` at each frame (moving meshes move): ``(F, n)``."""
    scene = bpy.context.scene
    old = scene.frame_current
    out = np.empty(xy.shape[:2])
    try:
        for f, frame in enumerate(frames):
            scene.frame_set(int(frame))
            out[f] = ray_heights(xy[f], objects)
    finally:
        scene.frame_set(old)
    return out


