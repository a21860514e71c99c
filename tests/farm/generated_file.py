# SPDX-License-Identifier: GPL-3.0-or-later
"""What a generated .blend holds: each rig's Action, saved settings, and whether it moves."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_INSPECT = """
import bpy, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
import procloco_addon
procloco_addon.register()
bpy.ops.wm.open_mainfile(filepath=sys.argv[2])
scene = bpy.context.scene
first, last = int(sys.argv[3]), int(sys.argv[4])
for name in sys.argv[5:]:
    obj = bpy.data.objects[name]
    heads = []
    for frame in (first, last):
        scene.frame_set(frame)
        m = np.array(obj.matrix_world)
        heads.append(np.array([m[:3, :3] @ np.array(pb.head) + m[:3, 3] for pb in obj.pose.bones]))
    moved = float(np.linalg.norm(heads[1] - heads[0], axis=1).max())
    s = obj.procloco
    print("RIG", name, obj.animation_data.action.name, s.frame_start, s.frame_end, s.seed, moved, sep="|")
sys.stdout.flush()
import os; os._exit(0)
"""


def rigs_in(blend: Path, rigs: list[str], frames: tuple[int, int]) -> dict[str, tuple[str, int, int, int]]:
    """Open ``blend`` in a fresh interpreter and report, for each rig, its Action, its saved
    frame range and seed; asserts that the posed rig moved between the two ``frames``
    (evaluated through the depsgraph, so the Action drives it)."""
    result = subprocess.run([sys.executable, "-c", _INSPECT, str(ROOT), str(blend), *map(str, frames), *rigs],
                            capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    found = {}
    for line in result.stdout.splitlines():
        if line.startswith("RIG|"):
            _, name, action, start, end, seed, moved = line.split("|")
            assert float(moved) > 0.01, f"{name} does not move between frames {frames}"
            found[name] = (action, int(start), int(end), int(seed))
    return found
