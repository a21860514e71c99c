#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The README's picture of the gait circles edited live, made headless and honestly.

Runs with Blender as a Python module (the ``bpy`` wheel in ``.venv``)::

    .venv/bin/python tools/live_preview_picture.py            # docs/images/live_preview_gait_edit.png

No screenshot of Blender's window can be taken without a display, so the picture is made
of what Live Preview itself produces: the Rigify wolf metarig with Live Preview on walks a
quadruped walk; its gait circles are then edited to a trot (each leg's sector set as the
panel's Start and Swing fields or the viewport editor would), and Live Preview's timer
callback, driven here by hand, re-generates the walk. Each row is the gait-circle picture
drawn by the panel's own drawing code (``gait.draw``), then Workbench renders of the
previewed walk at three frames. The timer's figures (time to the current frame's pose and
to the whole walk) are printed.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

OUT = ROOT / "docs" / "images" / "live_preview_gait_edit.png"
FRAMES = (10, 20, 30)
TILE = (300, 220)
CHART = 220
# The trot the walk's circles are edited into: diagonal pairs together (Hildebrand 1965).
TROT = {"L1": (0.0, 0.4), "R1": (0.5, 0.4), "L2": (0.5, 0.4), "R2": (0.0, 0.4)}


def _settle(obj: object) -> tuple[float, float]:
    """Drive the timer until the preview of ``obj`` is done: (seconds to the current frame's
    pose, seconds to the whole walk)."""
    from procloco_addon.blender.live_preview import handler as h
    from procloco_addon.blender.live_preview import preview

    t0 = time.perf_counter()
    first = None
    while True:
        wait = h.tick()
        adt = getattr(obj, "animation_data", None)
        action = adt.action if adt is not None else None
        if first is None and action is not None and action.get(preview.PARTIAL_TAG):
            first = time.perf_counter() - t0
        if wait is None or (h._state.run is None and all(w.due is None for w in h._state.watches.values())):
            return first if first is not None else float("nan"), time.perf_counter() - t0
        time.sleep(min(wait, 0.01))


def main() -> int:
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="procloco-user-"))
    import bpy
    import numpy as np

    import procloco_addon
    from procloco_addon.blender import cli
    from procloco_addon.blender.gait import draw, rig_gait
    from procloco_addon.blender.live_preview import handler
    from procloco_addon.blender.locomotion import generate
    from procloco_addon.core.locomotion import gait as core_gait
    from tools.examples import creatures
    from tools.export_gait_pngs import write_png

    procloco_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=40, y_subdivisions=40, size=12.0)
    ground = bpy.context.active_object
    ground.name = "Ground"
    mat = bpy.data.materials.new("Ground")
    mat.diffuse_color = (0.55, 0.6, 0.5, 1.0)
    ground.data.materials.append(mat)
    wolf = creatures.build_wolf(scene)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    wolf.select_set(True)
    bpy.context.view_layer.objects.active = wolf
    generate.detect_into_settings(wolf)
    rig_gait.apply_preset(wolf, core_gait.find_gait_preset("quadruped_walk"))
    settings = wolf.procloco
    settings.gait_mode = "CIRCLES"
    settings.use_scene_range = False
    settings.frame_start, settings.frame_end = 1, 40
    scene.frame_set(FRAMES[1])
    scene.render.fps = 24
    shading = scene.display.shading
    shading.light, shading.color_type = "STUDIO", "MATERIAL"

    world = bpy.data.worlds.new("Sky")
    world.color = (0.78, 0.82, 0.86)
    scene.world = world
    # A camera at the wolf's left side, a little above it, kept level with its hips.
    cam = bpy.data.objects.new("Side", bpy.data.cameras.new("Side"))
    scene.collection.objects.link(cam)
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 1.9
    cam.rotation_euler = (np.pi / 2 - 0.3, 0.0, np.pi / 2)
    scene.camera = cam

    def render(frames: tuple[int, ...], folder: Path) -> list[np.ndarray]:
        tiles = []
        for frame in frames:
            scene.frame_set(frame)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            hips = wolf.evaluated_get(depsgraph).pose.bones["spine.004"]
            y = float((wolf.matrix_world @ hips.head).y)
            cam.location = (4.0, y - 0.25, 1.6)
            files = cli.render_frames(scene, folder / str(frame), [frame], resolution=TILE)
            tiles.append(cli.image_pixels(files[0]))
        return tiles

    draw.ensure_gpu_context()
    rows = []
    settings.live_preview = True
    for step in ("walk", "trot"):
        if step == "trot":
            for k, item in enumerate(settings.legs):
                start, duration = TROT[item.label]
                rig_gait.set_leg_sector(wolf, k, start, duration)  # as the panel's fields do
        first, whole = _settle(wolf)
        print(f"{step}: current frame's pose after {first:.3f} s, whole walk after {whole:.3f} s")
        gait = rig_gait.read_rig_gait(wolf, scene)
        assert gait is not None
        phase = rig_gait.phase_at_frame(gait, scene, FRAMES[1])
        chart = draw.render_gait_image(gait.swing_start, gait.swing_duration, gait.labels, phase,
                                       width=CHART, height=CHART)
        with tempfile.TemporaryDirectory() as tmp:
            tiles = render(FRAMES, Path(tmp))
        height = TILE[1]
        pad = np.ones((height, 8, 4), np.float32)
        chart_tile = np.ones((height, CHART, 4), np.float32)
        chart_tile[(height - CHART) // 2:(height - CHART) // 2 + CHART] = chart
        chart_tile[..., 3] = 1.0
        parts = [chart_tile]
        for tile in tiles:
            tile = tile.copy()
            tile[..., 3] = 1.0
            parts += [pad, tile]
        rows.append(np.concatenate(parts, axis=1))
    settings.live_preview = False
    handler.tick()
    gap = np.ones((8, rows[0].shape[1], 4), np.float32)
    picture = np.concatenate([rows[1], gap, rows[0]], axis=0)  # rows bottom to top: the walk on top
    write_png(OUT, picture)
    print(f"wrote {OUT.relative_to(ROOT)} ({picture.shape[1]}x{picture.shape[0]})")
    sys.stdout.flush()
    os._exit(0)


if __name__ == "__main__":
    raise SystemExit(main())
