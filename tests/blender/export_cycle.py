# SPDX-License-Identifier: GPL-3.0-or-later
"""Round-trip a saved scene through Blender's own glTF exporter and importer, in a Blender of
its own (see :mod:`tests.blender.export_fixtures` for why never in the test process):
``python -m tests.blender.export_cycle IN.blend OUT.glb OUT.blend`` exports every object of
``IN.blend`` with its animation to ``OUT.glb``, imports that into an empty scene and saves it
as ``OUT.blend`` for the test to open.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from tests.blender.export_fixtures import ROOT, enable_io


def round_trip_in_subprocess(blend: Path, glb: Path, out: Path) -> None:
    """:func:`main` in a new Python with the same interpreter (so the same ``bpy``)."""
    command = [sys.executable, "-m", "tests.blender.export_cycle", str(blend), str(glb), str(out)]
    proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0 or not out.exists():
        raise RuntimeError(f"the glTF round trip failed (exit {proc.returncode}):\n"
                           f"{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")


def main(argv: Sequence[str]) -> int:
    import bpy

    blend, glb, out = argv
    bpy.ops.wm.open_mainfile(filepath=blend)
    enable_io()
    bpy.ops.export_scene.gltf(filepath=glb, export_format="GLB", export_animations=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=glb)
    bpy.ops.wm.save_as_mainfile(filepath=out, copy=True)
    return 0


if __name__ == "__main__":
    status = main(sys.argv[1:])
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # the files are written and closed; skip the teardown 4.2 crashes in
