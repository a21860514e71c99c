#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Build ``examples_crowd.blend`` at the repository root from nothing: the crowd example.

    .venv-4.2/bin/python tools/build_crowd_example.py            # writes examples_crowd.blend
    .venv/bin/python tools/build_crowd_example.py --output out/crowd.blend --spiders 4 --ants 2 \
        --frames 48 --render out/crowd.png

Forty spiders and twenty ants (linked duplicates of one of each, every one with its own
ProcLoco settings, seed and gait phase) start on opposite sides of a log and walk through
each other's ranks, over low crates, on gently swelling ground; a camera frames the whole
crossing, Workbench at 640×360 like ``examples.blend`` (see ``tools/examples/crowd.py``).
Built with the 4.2 LTS wheel, both Blenders open it (as ``tools/build_examples.py`` says).
``python3 tools/dev.py example --crowd`` builds it when missing, generates and renders it.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# Keeps Blender out of the user's configuration folders before bpy is imported.
from tools.build_examples import bpy, save_built, version_warning  # noqa: E402

DEFAULT_OUTPUT = ROOT / "examples_crowd.blend"


def build(output: Path = DEFAULT_OUTPUT, spiders: int = 40, ants: int = 20, frames: int | None = None,
          render: Path | None = None) -> list[str]:
    """Build the crowd in a fresh file and save it to ``output`` (frames 1-``frames``; render
    frame 1 to ``render``). Returns the warnings: settings the add-on did not take."""
    crowd = importlib.import_module("tools.examples.crowd")

    def populate(scene: bpy.types.Scene) -> list[str]:
        built = crowd.build_crowd_scene(scene, spiders=spiders, ants=ants,
                                        frame_end=frames or crowd.FRAME_END)
        return [f"{group[0].name}: rig settings not set yet: {group[0]['procloco_pending_settings']}"
                for group in built.rigs.values() if group[0].get("procloco_pending_settings")]

    return save_built(output, populate, render)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT,
                        help="where to save (default: examples_crowd.blend)")
    parser.add_argument("--spiders", type=int, default=40)
    parser.add_argument("--ants", type=int, default=20)
    parser.add_argument("--frames", type=int, default=None, help="last frame (default 168)")
    parser.add_argument("--render", type=Path, default=None, help="also render frame 1 to this PNG")
    args = parser.parse_args(argv)
    warnings = build(args.output.resolve(), args.spiders, args.ants, args.frames,
                     args.render.resolve() if args.render else None)
    warnings += version_warning("examples_crowd.blend")
    for warning in warnings:
        print(f"[crowd] warning: {warning}")
    print(f"[crowd] wrote {args.output} ({args.output.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    from tools.bpy_exit import exit_process

    exit_process(main())
