# SPDX-License-Identifier: GPL-3.0-or-later
"""The README's main job: generate locomotion for every creature of ``examples.blend``.

    python3 tools/dev.py example [--blend examples.blend] [--out out/example]
                                 [--rig NAME ...] [--frame-step N] [--resolution W H] [--info]

Runs Blender headless (the ``bpy`` module), enables ProcLoco the way Blender does — as an
extension from a repository that points at this checkout — opens ``examples.blend`` (built
first by ``tools/build_examples.py`` when it is missing), and runs the extension's batch
command: ``procloco generate --all --render ... --contact-sheet ... --save ...``. It
writes into ``--out``:

* ``examples_generated.blend`` — the scene with one new Action per creature,
* ``frames/frame_####.png`` — Workbench renders (every ``--frame-step``-th frame),
* ``contact_sheet.png`` — twelve of those frames tiled.

``--info`` only lists the rigs and the legs ProcLoco finds on each.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
_HOME = Path(tempfile.mkdtemp(prefix="procloco-example-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_HOME / "config"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402

# Blender's own modules are importable once bpy is.
addon_utils = importlib.import_module("addon_utils")

REPO_MODULE = "procloco_example"
PACKAGE = f"bl_ext.{REPO_MODULE}.procloco"


def enable_extension() -> str:
    """Enable ProcLoco as an extension from this checkout; returns its package name."""
    repo_dir = _HOME / "extensions"
    repo_dir.mkdir(parents=True, exist_ok=True)
    link = repo_dir / "procloco"
    if not link.exists():
        link.symlink_to(ROOT, target_is_directory=True)
    bpy.context.preferences.extensions.repos.new(name="ProcLoco example", module=REPO_MODULE,
                                                 custom_directory=str(repo_dir), source="USER")
    addon_utils.enable(PACKAGE, default_set=True, handle_error=None)
    if not addon_utils.check(PACKAGE)[1]:
        sys.exit("could not enable the ProcLoco extension")
    return PACKAGE


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--blend", type=Path, default=ROOT / "examples.blend")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "example")
    parser.add_argument("--rig", action="append", default=[], help="only these rigs (default: all)")
    parser.add_argument("--frame-step", type=int, default=4, help="render every N-th frame")
    parser.add_argument("--resolution", nargs=2, type=int, default=(640, 360), metavar=("W", "H"))
    parser.add_argument("--info", action="store_true", help="only list the rigs and their legs")
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    if not args.blend.exists():
        print(f"[example] {args.blend.name} is missing: building it with tools/build_examples.py", flush=True)
        build = importlib.import_module("tools.build_examples")
        build.build(args.blend)
        bpy.ops.wm.read_homefile(use_empty=True)
    package = enable_extension()
    print(f"[example] enabled {package} (Blender {bpy.app.version_string})", flush=True)
    bpy.ops.wm.open_mainfile(filepath=str(args.blend))
    cli = importlib.import_module(f"{package}.procloco_addon.blender.cli")
    if args.info:
        return int(cli.main(["info"]))
    out = args.out.resolve()
    command = ["generate", *(["--all"] if not args.rig else [x for r in args.rig for x in ("--rig", r)]),
               "--render", str(out / "frames"), "--frame-step", str(args.frame_step),
               "--resolution", *map(str, args.resolution),
               "--contact-sheet", str(out / "contact_sheet.png"),
               "--save", str(out / "examples_generated.blend")]
    print("[example] procloco " + " ".join(command), flush=True)
    status = int(cli.main(command))
    took = time.perf_counter() - t0
    print(f"[example] done in {took:.1f} s (status {status}); results in {out}", flush=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
