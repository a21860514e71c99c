#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Export the gait-circle picture of gait presets as PNG images for the documentation.

Runs with Blender as a Python module (the ``bpy`` wheel in ``.venv``)::

    .venv/bin/python tools/export_gait_pngs.py                 # the README's set
    .venv/bin/python tools/export_gait_pngs.py --all           # every shipped preset
    .venv/bin/python tools/export_gait_pngs.py quadruped_trot --phase 0.3 --cell 160
    .venv/bin/python tools/export_gait_pngs.py --bench         # time one redraw per preset
    .venv/bin/python tools/export_gait_pngs.py --auto-chart    # the Gait: Auto chart of the README

Each image is ``docs/images/gait_<preset file stem>.png``, drawn by the same code as the
panel's picture (``procloco_addon.blender.gait.draw``): one circle per leg laid out like
the body seen from above, front legs at the top, swing sectors in orange (bright where
the needle has the leg in swing), the needle in blue.
"""

from __future__ import annotations

import argparse
import os
import struct
import sys
import tempfile
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# The README shows these (the issue asks for the gallops and the hexapod tripod at least).
README_PRESETS = (
    "quadruped_rotary_gallop",
    "quadruped_transverse_gallop",
    "quadruped_trot",
    "hexapod_tripod",
    "octopod_wave",
    "pentapod_robot",
)
DEFAULT_OUT = ROOT / "docs" / "images"


def write_png(path: Path, rgba: object) -> None:
    """Write an ``(h, w, 4)`` float array in [0, 1], rows bottom to top, as an 8-bit RGBA PNG.

    A plain zlib writer: the bytes depend on the pixels only (no time stamps), so an
    unchanged picture leaves the committed file unchanged.
    """
    import numpy as np

    pixels = np.asarray(rgba)
    data = np.clip(np.round(pixels[::-1] * 255.0), 0, 255).astype(np.uint8)  # top row first
    height, width = data.shape[:2]
    raw = b"".join(b"\x00" + data[row].tobytes() for row in range(height))

    def chunk(kind: bytes, payload: bytes) -> bytes:
        return (struct.pack(">I", len(payload)) + kind + payload
                + struct.pack(">I", zlib.crc32(kind + payload) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9))
           + chunk(b"IEND", b""))
    path.write_bytes(png)


def export(names: list[str], out_dir: Path, *, cell: int = 140, phase: float = 0.12) -> list[Path]:
    """Render each named shipped preset and write ``gait_<name>.png`` into ``out_dir``."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="procloco-export-"))
    import bpy

    from procloco_addon.blender.gait import draw, geometry
    from procloco_addon.core.locomotion import gait as core_gait

    bpy.ops.wm.read_homefile(use_empty=True)
    draw.ensure_gpu_context()
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name in names:
        path = core_gait.gait_preset_dir() / f"{name}.json"
        preset = core_gait.load_gait_preset(path)
        width, height = geometry.canvas_size(preset.legs, cell)
        image = draw.render_gait_image(preset.swing_start, preset.swing_duration, preset.legs, phase,
                                       width=width, height=height)
        target = out_dir / f"gait_{name}.png"
        write_png(target, image)
        written.append(target)
        print(f"{target.relative_to(ROOT) if target.is_relative_to(ROOT) else target}  "
              f"{preset.name}: {len(preset.legs)} legs, {width}x{height}")
    return written


def export_auto_chart(out_dir: Path) -> Path:
    """Write ``auto_gait_chart.png``: the panel's Gait: Auto chart and circles for a horse-sized
    quadruped (hips 1.5 m high) speeding up from 0.5 to 7 m/s over 200 frames at 24 fps,
    at frame 180 (galloping), side by side."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="procloco-export-"))
    import bpy
    import numpy as np

    from procloco_addon.blender.gait import draw, handler, rig_gait
    from procloco_addon.core.locomotion import autogait

    bpy.ops.wm.read_homefile(use_empty=True)
    draw.ensure_gpu_context()
    labels = ("L1", "R1", "L2", "R2")
    params = autogait.auto_gait_params(labels, 1.5, 1.6)
    assert params is not None
    speed = 0.5 + 6.5 * np.clip(np.arange(200) / 160.0, 0.0, 1.0)
    band, duty, _ = params.schedule(speed)
    frame = 180
    width, height = 2 * handler.CHART_SIZE[0], 2 * handler.CHART_SIZE[1]
    chart = draw.render_auto_chart(params.names, rig_gait.boundary_speeds(params), speed, frame,
                                   width=width, height=height, band=band)
    circles = draw.render_gait_image(params.patterns[band[frame]], np.full(4, 1.0 - duty[frame]), labels,
                                     0.3, width=height, height=height)
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / "auto_gait_chart.png"
    write_png(target, np.concatenate([chart, circles], axis=1))
    print(f"{target.relative_to(ROOT) if target.is_relative_to(ROOT) else target}  "
          f"{params.names[band[frame]]} at {speed[frame]:.1f} m/s")
    return target


def bench(names: list[str], repeats: int = 20) -> None:
    """Print how long the panel's picture takes to draw and read back (the cost of one
    redraw after a change), per preset, at the panel's size and at the README's size."""
    import time

    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="procloco-export-"))
    import bpy

    from procloco_addon.blender.gait import draw, geometry, handler
    from procloco_addon.core.locomotion import gait as core_gait

    bpy.ops.wm.read_homefile(use_empty=True)
    start = time.perf_counter()
    draw.ensure_gpu_context()
    print(f"GPU context (background mode, one tiny Workbench render): {time.perf_counter() - start:.3f} s")
    print(f"{'preset':32s} {'legs':>4s} {'size':>9s} {'ms / redraw':>12s}")
    for name in names:
        preset = core_gait.load_gait_preset(core_gait.gait_preset_dir() / f"{name}.json")
        sizes = [(handler.PREVIEW_SIZE, handler.PREVIEW_SIZE), geometry.canvas_size(preset.legs, 140)]
        for width, height in sizes:
            draw.render_gait_image(preset.swing_start, preset.swing_duration, preset.legs, 0.1,
                                   width=width, height=height)  # warm-up (shader compilation)
            t0 = time.perf_counter()
            for i in range(repeats):
                draw.render_gait_image(preset.swing_start, preset.swing_duration, preset.legs, i / repeats,
                                       width=width, height=height)
            ms = (time.perf_counter() - t0) / repeats * 1e3
            print(f"{preset.name:32s} {len(preset.legs):4d} {f'{width}x{height}':>9s} {ms:12.1f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("presets", nargs="*", help="preset file stems (default: the README's set)")
    parser.add_argument("--all", action="store_true", help="every shipped preset")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default docs/images)")
    parser.add_argument("--cell", type=int, default=140, help="pixels per leg circle (default 140)")
    parser.add_argument("--phase", type=float, default=0.12, help="needle phase in [0, 1) (default 0.12)")
    parser.add_argument("--bench", action="store_true", help="time the drawing instead of writing files")
    parser.add_argument("--auto-chart", action="store_true", help="write the Gait: Auto chart picture")
    args = parser.parse_args(argv)
    if args.auto_chart:
        export_auto_chart(args.out)
        return 0

    from procloco_addon.core.locomotion import gait as core_gait

    if args.all:
        names = [p.stem for p in core_gait.list_gait_presets()]
    else:
        names = args.presets or [n for n in README_PRESETS
                                 if (core_gait.gait_preset_dir() / f"{n}.json").is_file()]
    missing = [n for n in names if not (core_gait.gait_preset_dir() / f"{n}.json").is_file()]
    if missing:
        print(f"no shipped preset named: {', '.join(missing)}", file=sys.stderr)
        return 2
    if not names:
        print("no presets to export", file=sys.stderr)
        return 2
    if args.bench:
        bench(names)
        return 0
    export(names, args.out, cell=args.cell, phase=args.phase)
    return 0


if __name__ == "__main__":
    sys.exit(main())
