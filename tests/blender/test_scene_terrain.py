# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/scene_terrain.py: scene meshes become the core environment.

Heights are checked against ray casts into the real (evaluated) meshes.
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import scene_terrain
from procloco_addon.core.world.terrain import NO_SURFACE, ROLE_AVOID, ROLE_GROUND, ROLE_STEP_OVER
from tests.blender.pose_eval import ray_heights
from tools.examples import creatures

pytestmark = pytest.mark.blender


def _grid(name: str, size: float = 4.0, n: int = 24, amp: float = 0.3) -> Any:
    """A wavy terrain mesh made with numpy, then rotated, scaled and moved as an object."""
    xs = np.linspace(-size / 2, size / 2, n)
    gx, gy = np.meshgrid(xs, xs)
    gz = amp * np.sin(1.7 * gx) * np.cos(1.3 * gy)
    verts = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j)
             for i in range(n - 1) for j in range(n - 1)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts.tolist(), [], faces)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _cube(name: str, location: tuple[float, float, float], size: float = 0.5) -> Any:
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = name
    return obj


def test_heights_match_ray_casts_in_world_space(empty_scene: Any) -> None:
    ground = _grid("Ground")
    ground.location = (0.5, -0.3, 0.2)
    ground.rotation_euler = (0.0, 0.0, 0.6)
    ground.scale = (1.5, 1.5, 1.5)
    mod = ground.modifiers.new("Subdiv", "SUBSURF")
    mod.levels = 1
    crate = _cube("Crate", (0.8, 0.4, 0.6))
    bpy.context.view_layer.update()
    objs = scene_terrain.terrain_objects(bpy.context)
    assert [o.name for o in objs] == ["Crate", "Ground"]
    terrain = scene_terrain.build_environment(bpy.context, objs)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1.5, 1.5, size=(200, 2))
    got = terrain.environment.height_at(xy)
    want = ray_heights(xy, [ground, crate])
    assert np.all(want > -np.inf)
    assert np.allclose(got, want, atol=1e-4)


def test_rig_skin_hidden_and_ignored_objects_are_not_terrain(empty_scene: Any) -> None:
    ground = _grid("Ground")
    rig = creatures.build_robot(empty_scene)
    hidden = _cube("Hidden", (0.0, 0.0, 2.0))
    hidden.hide_set(True)
    ignored = _cube("Ignored", (1.0, 0.0, 0.5))
    ignored.procloco_role = "IGNORE"
    names = [o.name for o in scene_terrain.terrain_objects(bpy.context, [rig])]
    assert names == ["Ground"]
    # A chosen collection: only its meshes.
    col = bpy.data.collections.new("Terrain")
    empty_scene.collection.children.link(col)
    crate = _cube("Crate", (0.0, 1.0, 0.3))
    for c in list(crate.users_collection):
        c.objects.unlink(crate)
    col.objects.link(crate)
    names = [o.name for o in scene_terrain.terrain_objects(bpy.context, [rig], collection=col)]
    assert names == ["Crate"]
    del ground


def test_roles_and_avoided_obstacles(empty_scene: Any) -> None:
    _grid("Ground", amp=0.0)
    wall = _cube("Wall", (1.0, 0.0, 0.25))
    wall.procloco_role = "AVOID"
    step = _cube("Step", (-1.0, 0.0, 0.25))
    step.procloco_role = "STEP_OVER"
    bpy.context.view_layer.update()
    terrain = scene_terrain.build_environment(bpy.context, scene_terrain.terrain_objects(bpy.context))
    assert dict(zip(terrain.objects, terrain.roles, strict=True)) == {
        "Ground": ROLE_GROUND, "Step": ROLE_STEP_OVER, "Wall": ROLE_AVOID}
    forbidden = terrain.environment.forbidden_at(np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]]))
    assert forbidden.tolist() == [True, False, False]


def test_animated_object_is_a_moving_obstacle_sampled_per_frame(empty_scene: Any) -> None:
    ground = _grid("Ground", amp=0.0)
    crate = _cube("Mover", (-1.0, 0.0, 0.25))
    crate.keyframe_insert("location", frame=1)
    crate.location = (1.0, 0.5, 0.25)
    crate.keyframe_insert("location", frame=21)
    empty_scene.frame_set(7)
    frames = np.arange(1, 22)
    terrain = scene_terrain.build_environment(bpy.context, scene_terrain.terrain_objects(bpy.context), frames)
    assert empty_scene.frame_current == 7, "sampling restores the current frame"
    mover = terrain.objects.index("Mover")
    assert terrain.dynamic_index == (mover,)
    assert terrain.roles[mover] == ROLE_STEP_OVER  # AUTO on an animated object
    for f in (0, 10, 20):
        terrain.apply_frame(f)
        empty_scene.frame_set(int(frames[f]))
        center = np.array(crate.matrix_world.translation)[:2]
        xy = center[None] + np.array([[0.0, 0.0], [0.2, 0.1], [0.4, 0.0]])
        want = ray_heights(xy, [ground, crate])
        assert np.allclose(terrain.environment.height_at(xy), want, atol=1e-5)


def test_offset_and_missing_ground(empty_scene: Any) -> None:
    _grid("Ground", size=2.0, amp=0.0)
    terrain = scene_terrain.build_environment(bpy.context, scene_terrain.terrain_objects(bpy.context),
                                              z_offset=0.1)
    assert terrain.environment.height_at(np.zeros((1, 2)))[0] == pytest.approx(0.1)
    scene_terrain.check_ground_under(terrain, np.zeros((1, 2)), "Rig")
    with pytest.raises(scene_terrain.TerrainError, match="No ground under 'Rig'"):
        scene_terrain.check_ground_under(terrain, np.array([[0.0, 0.0], [5.0, 5.0]]), "Rig")
    assert terrain.environment.height_at(np.array([[5.0, 5.0]]))[0] == NO_SURFACE


def test_no_mesh_at_all_is_refused(empty_scene: Any) -> None:
    with pytest.raises(scene_terrain.TerrainError, match="No ground mesh"):
        scene_terrain.build_environment(bpy.context, scene_terrain.terrain_objects(bpy.context))
