# SPDX-License-Identifier: GPL-3.0-or-later
"""Write fixture rigs (``rig_fixtures``) with Blender's own glTF and FBX exporters, in a Blender
of their own: ``python -m tests.blender.export_fixtures OUT_DIR NAME [NAME ...]`` writes
``OUT_DIR/NAME.glb`` and ``OUT_DIR/NAME.fbx`` for each fixture.

Why a process of its own: Blender 4.2's glTF exporter is not safe to run in a long-lived
Blender. In the test process, after a few hundred tests' worth of ``read_homefile``, it has died
with a segmentation fault where it sets ``context.window.scene`` (not reproducible in a short
run); and any 4.2 Python process that ran it once (a cube is enough) dies with a segmentation
fault when it exits. 5.0 has neither. So a fresh Blender writes the files and leaves without
Blender's teardown; the tests read them back with the importers in the test process.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

FORMATS = ("gltf", "fbx")
ROOT = Path(__file__).resolve().parents[2]


def path_of(out_dir: str | os.PathLike[str], name: str, fmt: str) -> Path:
    """Where the fixture ``name`` exported as ``fmt`` (``"gltf"`` or ``"fbx"``) is written."""
    return Path(out_dir) / f"{name}.{'glb' if fmt == 'gltf' else 'fbx'}"


def export_in_subprocess(out_dir: str | os.PathLike[str], names: Sequence[str]) -> None:
    """Every fixture of ``names`` in both formats into ``out_dir``, by a new Python running this
    module with the same interpreter (so the same ``bpy``)."""
    proc = subprocess.run(
        [sys.executable, "-m", "tests.blender.export_fixtures", str(out_dir), *names],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )
    if proc.returncode != 0:
        raise RuntimeError(
            f"exporting the fixtures failed (exit {proc.returncode}):\n"
            f"{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
        )


def enable_io() -> None:
    """Blender's glTF and FBX add-ons, enabled if they are not."""
    import addon_utils  # on the path once ``bpy`` is imported

    for module in ("io_scene_gltf2", "io_scene_fbx"):
        if not addon_utils.check(module)[1]:
            addon_utils.enable(module, default_set=True)


def main(argv: Sequence[str]) -> int:
    import bpy

    from tests.blender.rig_fixtures import FIXTURES

    out_dir, names = argv[0], argv[1:]
    enable_io()
    for name in names:
        bpy.ops.wm.read_homefile(use_empty=True)
        FIXTURES[name].build(bpy.context.scene, name)
        bpy.ops.export_scene.gltf(filepath=str(path_of(out_dir, name, "gltf")), export_format="GLB")
        bpy.ops.export_scene.fbx(filepath=str(path_of(out_dir, name, "fbx")))
    return 0


if __name__ == "__main__":
    status = main(sys.argv[1:])
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # the files are written and closed; skip the teardown 4.2 crashes in
