# SPDX-License-Identifier: GPL-3.0-or-later
"""Camera, light, world and render settings for ``examples.blend``, and the whole scene.

API::

    setup_render(scene, resolution=(640, 360))    # Workbench, material colours, shadows
    add_sun(scene, collection=None) -> Object       # a sun for Cycles/EEVEE; sets Workbench's light direction
    bound_corners(objects) -> list[Vector]          # world corners of evaluated bounding boxes
    skin_points(obj, count=300) -> list[Vector]     # world vertices of the evaluated mesh, subsampled
    frame_camera(scene, points, direction=..., margin=0.04, camera=None) -> Object
    configure_example_rig(rig, kind, terrain_collection) -> list[str]   # first-click settings
    build_example_scene(scene) -> ExampleScene      # six creatures on the terrain, framed
    creature_screen_boxes(scene, rigs) -> {kind: [u0, v0, u1, v1]}
    render_close_ups(scene, rigs, tile=(320, 180)) -> {kind: pixels}              # one close-up each
    render_contact_sheet(scene, rigs, path, tile=(320, 180), columns=3, frames=None) -> path
        # close-ups in one PNG: side by side at the current frame, or one row per frame

``EXAMPLE_SCALE[kind]`` is the scale each creature is built at in the example: the
tarantula and the ant are giants (legs ~0.7 m and ~0.5 m), the others are real size.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import bpy
import numpy as np
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

from . import creatures, terrain
from .procloco_props import apply_rig_settings

PRESET_DIR = Path(__file__).resolve().parents[2] / "presets" / "gait"

#: Scale of each creature in ``examples.blend`` (its builder's ``scale``).
EXAMPLE_SCALE: dict[str, float] = {"spider": 8.0, "ant": 30.0, "robot": 1.0, "lizard": 1.0, "wolf": 1.0,
                                   "human": 1.0}
#: The creatures in lane order, and the objects' names.
CREATURE_NAMES: dict[str, str] = {"spider": "Spider", "ant": "Ant", "robot": "Robot", "lizard": "Lizard",
                                  "wolf": "Wolf", "human": "Human"}
FRAME_START = 1
FRAME_END = 120
FPS = 24
#: Where the camera looks from (towards the scene centre): in front of the creatures, raised.
CAMERA_DIRECTION = (-0.35, -1.0, -0.55)
#: Where close-ups look from (towards the creature): its left side (it faces -Y), a little
#: ahead of it, raised.
CLOSEUP_DIRECTION = (-1.0, 0.5, -0.5)
#: The stretch of ground (y) the camera keeps in view.
FRAMED_Y = (-2.5, 4.0)
#: Where the human walks to with Plan Biped Footsteps: up its stairs onto the landing (at its
#: walking pace it stands there by frame 120; the way down and on does not fit in the frames).
HUMAN_GOAL = (terrain.LANE_X["human"], -0.6, terrain.STAIR_STEPS * terrain.STAIR_RISE)


@dataclass
class ExampleScene:
    """What :func:`build_example_scene` made."""

    rigs: dict[str, bpy.types.Object] = field(default_factory=dict)
    terrain: terrain.Terrain | None = None
    camera: bpy.types.Object | None = None
    sun: bpy.types.Object | None = None


def setup_render(scene: bpy.types.Scene, resolution: tuple[int, int] = (640, 360)) -> None:
    """Workbench at ``resolution``, solid material colours, shadows and cavity, a pale sky."""
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    shading = scene.display.shading
    shading.light = "STUDIO"
    shading.color_type = "MATERIAL"
    shading.show_shadows = True
    shading.shadow_intensity = 0.45
    shading.show_cavity = False
    if scene.world is None:
        scene.world = bpy.data.worlds.new("Sky")
    scene.world.color = (0.62, 0.72, 0.85)


def add_sun(scene: bpy.types.Scene, collection: bpy.types.Collection | None = None,
            direction: Sequence[float] = (0.35, 0.45, -0.82)) -> bpy.types.Object:
    """A sun shining along ``direction``; Workbench's shadow light follows it."""
    light = bpy.data.lights.new("Sun", "SUN")
    light.energy = 3.0
    sun = bpy.data.objects.new("Sun", light)
    (collection or scene.collection).objects.link(sun)
    d = Vector(direction).normalized()
    sun.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
    sun.location = (0.0, 0.0, 10.0)
    # Workbench's light_direction points towards the light, in world space.
    scene.display.light_direction = tuple(-d)
    return sun


def skin_points(obj: bpy.types.Object, count: int = 300) -> list[Vector]:
    """Up to ``count`` evenly picked vertices of ``obj``'s evaluated (posed) mesh, in world space."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        co = np.empty(len(mesh.vertices) * 3)
        mesh.vertices.foreach_get("co", co)
    finally:
        evaluated.to_mesh_clear()
    co = co.reshape(-1, 3)
    if co.shape[0] > count:
        co = co[np.linspace(0, co.shape[0] - 1, count).round().astype(int)]
    m = np.array(evaluated.matrix_world)
    return [Vector(p) for p in co @ m[:3, :3].T + m[:3, 3]]


def bound_corners(objects: Iterable[bpy.types.Object]) -> list[Vector]:
    """World-space corners of the evaluated bounding boxes of ``objects`` (8 per object)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    points: list[Vector] = []
    for obj in objects:
        evaluated = obj.evaluated_get(depsgraph)
        points += [evaluated.matrix_world @ Vector(c) for c in evaluated.bound_box]
    return points


def frame_camera(scene: bpy.types.Scene, points: Sequence[Vector],
                 direction: Sequence[float] = CAMERA_DIRECTION, margin: float = 0.04,
                 lens: float = 35.0, collection: bpy.types.Collection | None = None,
                 camera: bpy.types.Object | None = None) -> bpy.types.Object:
    """Aim ``camera`` (default: the scene camera, made if missing) along ``direction`` at the
    centre of the world-space ``points``, backed off until every point is inside the frame
    with ``margin`` (a fraction of the frame) to spare."""
    camera = camera or scene.camera
    if camera is None:
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        (collection or scene.collection).objects.link(camera)
        scene.camera = camera
    camera.data.lens = lens
    camera.data.clip_end = 500.0
    d = Vector(direction).normalized()
    camera.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
    lo = Vector(np.min(np.array(points), axis=0))
    hi = Vector(np.max(np.array(points), axis=0))
    target = 0.5 * (lo + hi)

    def fits(distance: float) -> bool:
        camera.location = target - d * distance
        bpy.context.view_layer.update()
        for p in points:
            u, v, depth = world_to_camera_view(scene, camera, p)  # any camera; the scene's aspect
            inside = margin <= u <= 1 - margin and margin <= v <= 1 - margin
            if depth <= camera.data.clip_start or not inside:
                return False
        return True

    near, far = 0.1, 10.0
    while not fits(far):
        far *= 2.0
        if far > 1e4:
            raise RuntimeError("cannot frame the objects")
    for _ in range(40):
        mid = 0.5 * (near + far)
        near, far = (near, mid) if fits(mid) else (mid, far)
    fits(far)
    return camera


def _read_png(path: Path) -> np.ndarray:
    image = bpy.data.images.load(str(path))
    try:
        w, h = image.size
        pixels = np.empty(w * h * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    return pixels.reshape(h, w, 4)  # row 0 is the bottom of the picture


def _save_png(pixels: np.ndarray, path: Path) -> Path:
    """Save ``(h, w, 4)`` float pixels (row 0 at the bottom) as a PNG at ``path``."""
    image = bpy.data.images.new("ProcLoco contact sheet", pixels.shape[1], pixels.shape[0], alpha=False)
    try:
        image.pixels.foreach_set(np.ascontiguousarray(pixels, dtype=np.float32).ravel())
        path.parent.mkdir(parents=True, exist_ok=True)
        image.filepath_raw = str(path)
        image.file_format = "PNG"
        image.save()
    finally:
        bpy.data.images.remove(image)
    return path


def _occluders(scene: bpy.types.Scene, eye: Vector, points: Sequence[Vector],
               target: bpy.types.Object) -> list[bpy.types.Object]:
    """Crates that a ray from ``eye`` to one of ``points`` hits before ``target``: what hides
    the creature from the close-up camera (a tall crate beside it). The ground and the stairs
    are never taken away."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    found: list[bpy.types.Object] = []
    for p in points:
        d = p - eye
        hit, _loc, _normal, _index, obj, _m = scene.ray_cast(depsgraph, eye, d.normalized(),
                                                             distance=d.length)
        if not hit or obj is None:
            continue
        original = obj.original
        crate = original.get("example_feature") in ("static_crate", "moving_crate")
        if crate and original != target and original not in found and not original.hide_render:
            found.append(original)
    return found


def render_close_ups(scene: bpy.types.Scene, rigs: dict[str, bpy.types.Object],
                     tile: tuple[int, int] = (320, 180),
                     direction: Sequence[float] = CLOSEUP_DIRECTION,
                     margin: float = 0.08, hide_occluders: bool = True) -> dict[str, np.ndarray]:
    """Render each creature close up at the current frame (Workbench, ``tile`` pixels): the
    camera looks along ``direction`` at the creature's posed skin, framed with ``margin`` to spare.
    Crates in front of the creature (seen from the camera) are left out of its picture unless
    ``hide_occluders`` is False.
    Returns ``{kind: (h, w, 4) pixels}`` (row 0 at the bottom; creatures without a skin are
    left out). The scene's camera, resolution, engine and output path are left as they were."""
    render = scene.render
    saved = (scene.camera, render.resolution_x, render.resolution_y, render.resolution_percentage,
             render.filepath, render.engine)
    camera = bpy.data.objects.new("Close-up camera", bpy.data.cameras.new("Close-up camera"))
    scene.collection.objects.link(camera)
    out: dict[str, np.ndarray] = {}
    try:
        render.engine = "BLENDER_WORKBENCH"
        render.resolution_x, render.resolution_y = tile
        render.resolution_percentage = 100
        with tempfile.TemporaryDirectory() as tmp:
            for kind, rig in rigs.items():
                skin = creatures.skin_of(rig)
                if skin is None:
                    continue
                points = skin_points(skin)
                frame_camera(scene, points, direction=direction, margin=margin, lens=50.0, camera=camera)
                scene.camera = camera
                hidden = (_occluders(scene, camera.matrix_world.translation, points[::10], skin)
                          if hide_occluders else [])
                for obj in hidden:
                    obj.hide_render = True
                try:
                    render.filepath = str(Path(tmp) / f"{kind}.png")
                    bpy.ops.render.render(write_still=True)
                finally:
                    for obj in hidden:
                        obj.hide_render = False
                out[kind] = _read_png(Path(render.filepath))
    finally:
        (scene.camera, render.resolution_x, render.resolution_y, render.resolution_percentage,
         render.filepath, render.engine) = saved
        camera_data = camera.data
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(camera_data)
    return out


def render_contact_sheet(scene: bpy.types.Scene, rigs: dict[str, bpy.types.Object], path: Path,
                         tile: tuple[int, int] = (320, 180), columns: int = 3,
                         direction: Sequence[float] = CLOSEUP_DIRECTION,
                         frames: Sequence[int] | None = None) -> Path:
    """Render each creature close up (see :func:`render_close_ups`) and save the tiles as one
    PNG at ``path``.

    Without ``frames``: the current frame, the creatures side by side, ``columns`` per row.
    With ``frames``: one row per frame (top to bottom), one column per creature (in the order
    of ``rigs``); the scene is put back on its current frame afterwards.

    The scene's camera, resolution and output path are left as they were.
    """
    if frames is None:
        shots = [render_close_ups(scene, rigs, tile, direction)]
        n_cols = columns
        n_rows = -(-len(rigs) // columns)
    else:
        current = scene.frame_current
        try:
            shots = []
            for frame in frames:
                scene.frame_set(int(frame))
                shots.append(render_close_ups(scene, rigs, tile, direction))
        finally:
            scene.frame_set(current)
        n_cols, n_rows = len(rigs), len(shots)
    sheet = np.ones((n_rows * tile[1], n_cols * tile[0], 4), dtype=np.float32)
    for r, shot in enumerate(shots):
        for i, kind in enumerate(rigs):
            if kind not in shot:
                continue
            row, col = (r, i) if frames is not None else divmod(i, columns)
            top = (n_rows - 1 - row) * tile[1]  # image rows count from the bottom
            sheet[top:top + tile[1], col * tile[0]:(col + 1) * tile[0]] = shot[kind]
    return _save_png(sheet, path)


def _operator_registered(idname: str) -> bool:
    module, name = idname.split(".")
    try:
        getattr(getattr(bpy.ops, module), name).get_rna_type()
    except (AttributeError, KeyError):
        return False
    return True


def configure_example_rig(rig: bpy.types.Object, kind: str,
                          terrain_collection: bpy.types.Collection | None) -> list[str]:
    """Settings that make Generate work on the first click: the terrain collection, the
    scene's frame range, the legs (found by the add-on's own Detect Legs operator) and the
    kind's gait preset (applied by the add-on's Apply Gait Preset operator), as a user would;
    the suggested secondary-motion chains (Suggest Chains) so Bake Secondary Motion works on
    the first click too; for the human, Plan Biped Footsteps' clips and goal.

    Returns what could not be done (the add-on lacks a setting or an operator, or refused).
    """
    problems = [f"setting '{name}' is not registered"
                for name in apply_rig_settings(rig, {"terrain_collection": terrain_collection,
                                                     "use_scene_range": True})]
    if "procloco" not in bpy.types.Object.bl_rna.properties:
        return [*problems, "the add-on is not registered"]
    view_layer = bpy.context.view_layer
    view_layer.objects.active = rig
    with bpy.context.temp_override(active_object=rig, object=rig, selected_objects=[rig]):
        if not _operator_registered("procloco.detect_legs"):
            problems.append("operator procloco.detect_legs is not registered: legs not detected")
        elif bpy.ops.procloco.detect_legs() != {"FINISHED"}:
            problems.append("Detect Legs refused the rig")
        preset_path = PRESET_DIR / f"{creatures.GAIT_PRESET[kind]}.json"
        if len(rig.procloco.legs) == 0:
            problems.append(f"no legs, so gait preset {preset_path.stem} not applied")
        elif not _operator_registered("procloco.apply_gait_preset"):
            problems.append("operator procloco.apply_gait_preset is not registered: gait not applied")
        elif bpy.ops.procloco.apply_gait_preset(filepath=str(preset_path)) != {"FINISHED"}:
            problems.append(f"gait preset {preset_path.stem} refused")
        else:
            rig.procloco.gait_preset = json.loads(preset_path.read_text(encoding="utf-8"))["name"]
        problems += _configure_secondary(rig, kind)
        if kind == "human":
            problems += _configure_biped(rig)
    return problems


def _configure_secondary(rig: bpy.types.Object, kind: str) -> list[str]:
    """The suggested pendulum chains (Suggest Chains), with the kind's changes
    (``creatures.SECONDARY_SETTINGS``)."""
    if not _operator_registered("procloco.suggest_secondary_chains"):
        return ["operator procloco.suggest_secondary_chains is not registered: no chains"]
    if bpy.ops.procloco.suggest_secondary_chains() != {"FINISHED"}:
        return ["Suggest Chains refused the rig"]
    for chain in rig.procloco_secondary.chains:
        for word, values in creatures.SECONDARY_SETTINGS.get(kind, {}).items():
            if word in chain.root:
                for name, value in values.items():
                    setattr(chain, name, value)
    return []


def _configure_biped(rig: bpy.types.Object) -> list[str]:
    """Plan Biped Footsteps ready to run: walking clips made for the rig (Make Example Clips,
    no runs or jumps: it walks up the stairs) and a goal, the Empty ``"<rig> Goal"`` on the
    stairs' landing (``HUMAN_GOAL``)."""
    if not _operator_registered("procloco.make_biped_clips"):
        return ["operator procloco.make_biped_clips is not registered: no biped clips"]
    if bpy.ops.procloco.make_biped_clips(runs=False, jump=False) != {"FINISHED"}:
        return ["Make Example Clips refused the rig"]
    goal = bpy.data.objects.new(f"{rig.name} Goal", None)
    goal.empty_display_type = "SINGLE_ARROW"
    goal.empty_display_size = 0.3
    for collection in rig.users_collection:
        collection.objects.link(goal)
    goal.location = HUMAN_GOAL
    settings = rig.procloco_biped
    settings.goal = goal
    settings.allow_run = False
    return []


def start_scene(scene: bpy.types.Scene, frame_end: int,
                creatures_name: str) -> tuple[bpy.types.Collection, bpy.types.Collection]:
    """Frames ``FRAME_START``–``frame_end`` at ``FPS`` on the first frame, and two new
    collections in the scene: the creatures' (``creatures_name``) and ``Terrain``."""
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    scene.frame_start, scene.frame_end = FRAME_START, frame_end
    scene.frame_set(FRAME_START)
    creature_coll = bpy.data.collections.new(creatures_name)
    terrain_coll = bpy.data.collections.new("Terrain")
    scene.collection.children.link(terrain_coll)
    scene.collection.children.link(creature_coll)
    return creature_coll, terrain_coll


def build_example_scene(scene: bpy.types.Scene) -> ExampleScene:
    """The six creatures on the terrain (collections ``Creatures`` and ``Terrain``), a camera
    framing everything, a sun, Workbench at 640×360, frames 1–120 at 24 fps (5 s: at the
    speeds of their gait presets every creature meets its lane's obstacles)."""
    creature_coll, terrain_coll = start_scene(scene, FRAME_END, "Creatures")
    out = ExampleScene()
    out.terrain = terrain.build_terrain(scene, terrain_coll, FRAME_START, FRAME_END, FPS)
    for kind, name in CREATURE_NAMES.items():
        location = (terrain.LANE_X[kind], terrain.START_Y, 0.0)
        rig = creatures.BUILDERS[kind](scene, name=name, location=location,
                                       scale=EXAMPLE_SCALE[kind], collection=creature_coll)
        problems = configure_example_rig(rig, kind, terrain_coll)
        if problems:
            rig["procloco_pending_settings"] = "; ".join(problems)
        out.rigs[kind] = rig
    setup_render(scene)
    out.sun = add_sun(scene)
    # Frame what the creatures meet, not the whole ground: its far edges may leave the picture.
    t = out.terrain
    framed = bound_corners([t.stairs, t.gap, *t.static_crates, *t.moving_crates])
    framed += bound_corners(s for s in (creatures.skin_of(r) for r in out.rigs.values()) if s is not None)
    # The ground along each lane, from behind the creatures to past the obstacles.
    for x in terrain.LANE_X.values():
        for y in FRAMED_Y:
            framed.append(Vector((x, y, float(terrain.ground_height(np.array(x), np.array(y))))))
    # Each creature as far down its lane, standing on the highest ground of it (hills, stairs).
    ys = np.linspace(FRAMED_Y[0], terrain.START_Y, 60)
    stairs = np.array(bound_corners([t.stairs]))
    for kind, rig in out.rigs.items():
        skin = creatures.skin_of(rig)
        if skin is None:
            continue
        x = terrain.LANE_X[kind]
        top = float(terrain.ground_height(np.full_like(ys, x), ys).max())
        if stairs[:, 0].min() <= x <= stairs[:, 0].max():
            top = max(top, float(stairs[:, 2].max()))
        framed += [c + Vector((0.0, FRAMED_Y[0] - terrain.START_Y, top)) for c in bound_corners([skin])]
    out.camera = frame_camera(scene, framed)
    return out


def creature_screen_boxes(scene: bpy.types.Scene, rigs: dict[str, bpy.types.Object]) -> dict[str, np.ndarray]:
    """Each creature skin's bounding box in normalised camera coordinates: ``[u0, v0, u1, v1]``."""
    out: dict[str, np.ndarray] = {}
    for kind, rig in rigs.items():
        skin = creatures.skin_of(rig)
        if skin is None:
            continue
        uv = np.array([world_to_camera_view(scene, scene.camera, p)[:2] for p in bound_corners([skin])])
        out[kind] = np.concatenate([uv.min(axis=0), uv.max(axis=0)])
    return out

