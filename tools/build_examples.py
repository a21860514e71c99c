#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Build ``examples.blend`` at the repository root from nothing.

    .venv-4.2/bin/python tools/build_examples.py                  # writes examples.blend
    .venv/bin/python tools/build_examples.py --output out/x.blend --render out/examples.png \
        --contact-sheet out/creatures.png

The committed file is built with the oldest supported Blender (the 4.2 LTS wheel, made by
``python3 tools/dev.py venv --blender 4.2``): Blender opens files from older versions, and
4.2 cannot read files saved by 4.3 and later.

Starts from an empty Blender file every time, so running it again gives the same scene:
six creatures (spider, ant, five-legged robot, lizard, Rigify wolf, Rigify human), each
with a capsule skin, on a heightmap terrain with static and moving crates, stairs and a
gap, a camera framing everything, a sun, and Workbench at 640×360 (see ``tools/examples``).
The add-on is registered from the source tree first, so each object's ProcLoco settings
and terrain role are saved in the file; anything the add-on does not register yet is
listed on the way out.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
# Keep Blender from writing into the user's own configuration folders.
_HOME = Path(tempfile.mkdtemp(prefix="procloco-examples-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_HOME / "config"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402

DEFAULT_OUTPUT = ROOT / "examples.blend"


def build(output: Path = DEFAULT_OUTPUT, render: Path | None = None,
          contact_sheet: Path | None = None) -> list[str]:
    """Build the example scene in a fresh file, save it to ``output`` (and render frame 1 to
    ``render``, close-ups of each creature to ``contact_sheet``). Returns the warnings:
    settings, roles or operators the add-on did not provide."""
    # Imported by name: the tools are type-checked apart from the add-on's package tree.
    procloco_props = importlib.import_module("tools.examples.procloco_props")
    scene = importlib.import_module("tools.examples.scene")

    def populate(scene_: bpy.types.Scene) -> list[str]:
        built = scene.build_example_scene(scene_)
        warnings: list[str] = []
        if not procloco_props.role_registered():
            warnings.append("Object.procloco_role is not registered: terrain roles were not set")
        for kind, rig in built.rigs.items():
            pending = rig.get("procloco_pending_settings", "")
            if pending:
                warnings.append(f"{kind}: rig settings not set yet: {pending}")
        if contact_sheet is not None:
            after.append(lambda: scene.render_contact_sheet(bpy.context.scene, built.rigs, contact_sheet))
        return warnings

    after: list[Callable[[], object]] = []
    return save_built(output, populate, render, after)


def save_built(output: Path, populate: Callable[[bpy.types.Scene], list[str]], render: Path | None = None,
               after: Sequence[Callable[[], object]] = ()) -> list[str]:
    """Fill a fresh, empty file with ``populate(scene)`` (the add-on registered from the source
    tree meanwhile, so the objects' ProcLoco settings are saved), save it to ``output`` without
    a ``.blend1`` beside it, render frame 1 to ``render`` and run ``after``. Returns
    ``populate``'s warnings."""
    procloco_addon = importlib.import_module("procloco_addon")
    bpy.ops.wm.read_homefile(use_empty=True)
    registered = False
    if "procloco" not in bpy.types.Object.bl_rna.properties:
        procloco_addon.register()
        registered = True
    try:
        warnings = populate(bpy.context.scene)
        output.parent.mkdir(parents=True, exist_ok=True)
        bpy.context.preferences.filepaths.save_version = 0  # no .blend1 next to it
        bpy.ops.wm.save_as_mainfile(filepath=str(output), compress=True)
        if render is not None:
            render.parent.mkdir(parents=True, exist_ok=True)
            bpy.context.scene.render.filepath = str(render)
            bpy.ops.render.render(write_still=True)
        for step in after:
            step()
    finally:
        if registered:
            procloco_addon.unregister()
    return warnings



def version_warning(name: str) -> list[str]:
    """A warning when this Blender writes files that 4.2 LTS cannot open (4.3 and later)."""
    if bpy.app.version < (4, 3, 0):
        return []
    return [f"built with Blender {bpy.app.version_string}: Blender 4.2 cannot open this file; "
            f"build the committed {name} with the 4.2 wheel (.venv-4.2)"]

def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT,
                        help="where to save (default: examples.blend)")
    parser.add_argument("--render", type=Path, default=None, help="also render frame 1 to this PNG")
    parser.add_argument("--contact-sheet", type=Path, default=None,
                        help="also render a close-up of each creature, side by side, to this PNG")
    args = parser.parse_args(argv)
    warnings = build(args.output.resolve(), args.render.resolve() if args.render else None,
                     args.contact_sheet.resolve() if args.contact_sheet else None)
    warnings += version_warning("examples.blend")
    for warning in warnings:
        print(f"[examples] warning: {warning}")
    size_mb = args.output.stat().st_size / 1e6
    print(f"[examples] wrote {args.output} ({size_mb:.2f} MB)")
    return 0


if __name__ == "__main__":
    from tools.bpy_exit import exit_process

    exit_process(main())
