# SPDX-License-Identifier: GPL-3.0-or-later
"""Draws the chosen leg chains in the viewport while the Rig & Legs section is open.

The Rig & Legs panel calls :func:`panel_drawn` each time it draws (only an open panel
draws); a ``SpaceView3D`` ``POST_VIEW`` callback draws the enabled legs of that rig as
lines through their joints for :data:`SHOW_FOR` seconds after, so a wrong leg shows at
once. :func:`chain_lines` computes the segments (tested headless; nothing is drawn in
background mode).
"""

from __future__ import annotations

import itertools
import time
from typing import Any

import bpy
import numpy as np

__all__ = ["SHOW_FOR", "chain_lines", "panel_drawn", "register", "unregister"]

#: Seconds the chains stay drawn after the panel last drew.
SHOW_FOR = 3.0
COLOR = (1.0, 0.55, 0.1, 0.9)


class _State:
    draw_handle: Any = None
    rig: str = ""
    seen: float = -np.inf


_state = _State()


def panel_drawn(obj: bpy.types.Object) -> None:
    """The Rig & Legs panel of ``obj`` is open (it just drew)."""
    _state.rig = obj.name
    _state.seen = time.monotonic()


def showing() -> str:
    """The name of the rig whose chains are drawn now ("" when none)."""
    return _state.rig if time.monotonic() - _state.seen <= SHOW_FOR else ""


def chain_lines(obj: bpy.types.Object) -> np.ndarray:
    """World segments ``(n, 2, 3)`` through the joints of each enabled leg of ``obj`` in its
    current pose: each bone's head, then the end-effector's far joint (its child's head, or
    its tail when it has none)."""
    bones = obj.pose.bones
    world = np.array(obj.matrix_world)
    segments = []
    for leg in obj.procloco.legs:
        if not leg.enabled or leg.hip not in bones or leg.end not in bones:
            continue
        chain = [bones[leg.end]]
        while chain[-1].name != leg.hip and chain[-1].parent is not None:
            chain.append(chain[-1].parent)
        if chain[-1].name != leg.hip:
            continue
        chain.reverse()
        kids = chain[-1].children
        tip = kids[0].head if kids else chain[-1].tail
        pts = np.array([tuple(b.head) for b in chain] + [tuple(tip)])
        pts = pts @ world[:3, :3].T + world[:3, 3]
        segments += list(itertools.pairwise(pts))
    return np.array(segments, dtype=np.float64).reshape(-1, 2, 3)


def _draw() -> None:
    name = showing()
    obj = bpy.data.objects.get(name) if name else None
    if obj is None or obj.type != "ARMATURE" or bpy.app.background:
        return
    lines = chain_lines(obj)
    if not len(lines):
        return
    import gpu
    from gpu_extras.batch import batch_for_shader

    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    batch = batch_for_shader(shader, "LINES", {"pos": lines.reshape(-1, 3).astype(np.float32).tolist()})
    gpu.state.line_width_set(3.0)
    gpu.state.depth_test_set("NONE")
    gpu.state.blend_set("ALPHA")
    shader.uniform_float("color", COLOR)
    batch.draw(shader)
    gpu.state.blend_set("NONE")
    gpu.state.line_width_set(1.0)


def register() -> None:
    _state.draw_handle = bpy.types.SpaceView3D.draw_handler_add(_draw, (), "WINDOW", "POST_VIEW")


def unregister() -> None:
    if _state.draw_handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_state.draw_handle, "WINDOW")
        _state.draw_handle = None
    _state.rig, _state.seen = "", -np.inf
