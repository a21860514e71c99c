# SPDX-License-Identifier: GPL-3.0-or-later
"""Round-trip fixture rigs (``rig_fixtures``) through Blender's own glTF and FBX exporters and
importers, in a Blender of their own: ``python -m tests.blender.export_fixtures OUT_DIR NAME
[NAME ...]`` writes, for each fixture, ``NAME.glb`` and ``NAME.fbx``, then reads each back into
an empty scene with every importer setting of :data:`IMPORTS` and saves that scene as a .blend
(:func:`imported_path`), which the tests open.

Why a process of its own: Blender 4.2's glTF add-on is not safe to run in a long-lived Blender.
In the test process, after a few hundred tests' worth of ``read_homefile``, its exporter has
died with a segmentation fault where it sets ``context.window.scene`` and its importer in
``create_bones`` (neither reproducible in a short run); and any 4.2 Python process that ran the
exporter once (a cube is enough) dies with a segmentation fault when it exits. 5.0 shows none
of this. So a fresh Blender does the round trips and leaves without Blender's teardown; the
test process only opens .blend files.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
#: (format, importer options): the importers' defaults, then another bone direction.
IMPORTS: list[tuple[str, dict[str, Any]]] = [
    ("gltf", {}),
    ("gltf", {"bone_heuristic": "TEMPERANCE"}),
    ("fbx", {}),
    ("fbx", {"automatic_bone_orientation": True}),
]


def options_id(options: dict[str, Any]) -> str:
    """A short name for importer ``options``: ``"default"``, ``"TEMPERANCE"``, ``"True"``."""
    return "-".join(str(v) for v in options.values()) or "default"


def path_of(out_dir: str | os.PathLike[str], name: str, fmt: str) -> Path:
    """Where the fixture ``name`` exported as ``fmt`` (``"gltf"`` or ``"fbx"``) is written."""
    return Path(out_dir) / f"{name}.{'glb' if fmt == 'gltf' else 'fbx'}"


def imported_path(out_dir: str | os.PathLike[str], name: str, fmt: str, options: dict[str, Any]) -> Path:
    """The .blend holding the fixture ``name`` as ``fmt``'s importer read it with ``options``."""
    return Path(out_dir) / f"{name}-{fmt}-{options_id(options)}.blend"


def round_trip_in_subprocess(out_dir: str | os.PathLike[str], names: Sequence[str]) -> None:
    """Every fixture of ``names`` exported and imported (see the module doc) into ``out_dir``,
    by a new Python running this module with the same interpreter (so the same ``bpy``)."""
    proc = subprocess.run(
        [sys.executable, "-m", "tests.blender.export_fixtures", str(out_dir), *names],
        cwd=ROOT, capture_output=True, text=True, timeout=900,
    )
    if proc.returncode != 0:
        raise RuntimeError(
            f"the fixtures' round trip failed (exit {proc.returncode}):\n"
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
        for fmt, options in IMPORTS:
            bpy.ops.wm.read_homefile(use_empty=True)
            read = bpy.ops.import_scene.gltf if fmt == "gltf" else bpy.ops.import_scene.fbx
            read(filepath=str(path_of(out_dir, name, fmt)), **options)
            bpy.ops.wm.save_as_mainfile(filepath=str(imported_path(out_dir, name, fmt, options)), copy=True)
    return 0


if __name__ == "__main__":
    status = main(sys.argv[1:])
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # the files are written and closed; skip the teardown 4.2 crashes in
