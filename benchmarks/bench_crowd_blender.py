# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate Locomotion on many selected rigs at once, in Blender (the ``bpy`` module).

    python benchmarks/bench_crowd_blender.py [--counts 1,10,100] [--frames 120]

Scene: ``--counts`` Rigify wolf metarigs (capsule skins, ``tools.examples.creatures``) in a
grid 3 m apart, all selected, on a flat, gently bumpy heightmap mesh large enough for the
whole herd; 120 frames at 24 fps, 1 m/s, default settings otherwise. For each count the
scene is built afresh, then ``procloco.generate_locomotion`` runs once (straight through,
as in background mode) and is timed as a whole; the same rigs are then generated once more
phase by phase (``crowd.read_all`` and ``crowd.read_terrain`` reading rigs and terrain,
``crowd.simulate`` stepping them all in one simulation, and ``generate.write_all`` solving
poses and writing keys) to show where the time goes.

Prints seconds, seconds per rig and the ratio to one rig. Ends with
``RESULT crowd_blender one_s=<s> hundred_s=<s> ratio=<r>`` (the largest count stands for
"hundred" when ``--counts`` does not reach 100).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
_HOME = Path(tempfile.mkdtemp(prefix="procloco-bench-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_HOME / "config"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import procloco_addon  # noqa: E402
from procloco_addon.blender.locomotion import crowd, generate  # noqa: E402
from tools.examples import creatures  # noqa: E402

SPACING = 3.0  # m between neighbouring wolves


def build_scene(count: int, n_frames: int) -> list[bpy.types.Object]:
    """``count`` wolves on bumpy ground, all selected (the first active)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, n_frames
    scene.render.fps = 24
    side = int(np.ceil(np.sqrt(count)))
    half = 0.5 * side * SPACING + 1.0 + n_frames / 24.0 * 1.2  # the herd plus a walk either way
    n = int(np.clip(2 * half / 0.12, 32, 400))
    xs = np.linspace(-half, half, n)
    ys = xs
    gx, gy = np.meshgrid(xs, ys)
    gz = 0.02 * np.sin(gx / 0.7) * np.cos(gy / 0.9)
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j)
             for i in range(n - 1) for j in range(n - 1)]
    mesh = bpy.data.meshes.new("Ground")
    mesh.from_pydata(np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()]).tolist(), [], faces)
    scene.collection.objects.link(bpy.data.objects.new("Ground", mesh))
    wolves = []
    for k in range(count):
        x = (k % side - 0.5 * (side - 1)) * SPACING
        y = (k // side - 0.5 * (side - 1)) * SPACING
        wolf = creatures.build_wolf(scene, name=f"Wolf{k:03d}", location=(x, y, 0.0))
        wolf.procloco.speed = 1.0
        wolves.append(wolf)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for wolf in wolves:
        wolf.select_set(True)
    bpy.context.view_layer.objects.active = wolves[0]
    return wolves


def run(count: int, n_frames: int) -> dict[str, float]:
    wolves = build_scene(count, n_frames)
    t0 = time.perf_counter()
    assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
    total = time.perf_counter() - t0
    context = bpy.context
    t0 = time.perf_counter()
    jobs = crowd.read_all(context, wolves)
    groups = crowd.batches(jobs)
    for _ in crowd.read_terrain(context, groups):
        pass
    t1 = time.perf_counter()
    for _ in crowd.simulate(groups):  # one simulation for the whole herd
        pass
    t2 = time.perf_counter()
    generate.write_all(context, jobs)
    t3 = time.perf_counter()
    return {"total": total, "read": t1 - t0, "simulate": t2 - t1, "write": t3 - t2}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", default="1,10,100", help="comma-separated numbers of wolves")
    ap.add_argument("--frames", type=int, default=120)
    args = ap.parse_args()
    counts = [int(c) for c in args.counts.split(",")]
    procloco_addon.register()
    try:
        rows = {count: run(count, args.frames) for count in counts}
        # (the table after every run: the operator prints its progress while it works)
        print(f"\nGenerate Locomotion on N selected wolves, {args.frames} frames; "
              f"Blender {bpy.app.version_string}, {platform.processor() or platform.machine()}, "
              f"{os.cpu_count()} cores")
        one = rows[counts[0]]["total"] / counts[0]
        print(f"{'rigs':>6} {'total s':>9} {'per rig s':>10} {'x one':>7} | "
              f"{'read s':>8} {'sim s':>8} {'write s':>8}")
        for count, r in rows.items():
            print(f"{count:>6} {r['total']:>9.2f} {r['total'] / count:>10.3f} {r['total'] / one:>7.1f} | "
                  f"{r['read']:>8.2f} {r['simulate']:>8.2f} {r['write']:>8.2f}")
        first, last = counts[0], counts[-1]
        one_s = rows[first]["total"] / first
        print(f"RESULT crowd_blender one_s={one_s:.3f} hundred_s={rows[last]['total']:.3f} "
              f"ratio={rows[last]['total'] / one_s:.1f}")
    finally:
        procloco_addon.unregister()


if __name__ == "__main__":
    main()
