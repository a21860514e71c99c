#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""Draw the README's picture of the Quality panel, with real figures of the example wolf.

    .venv/bin/python tools/quality_panel_picture.py            # docs/images/quality_panel.png

Blender draws no UI headless, so this is not a screenshot. The example wolf of
``examples.blend`` is generated with Generate Locomotion (the operator, the file's own
settings), twice: as it is, and with its legs held 6 cm up by Limit Location constraints
on its hips (a deliberately bad setup, so the red rows show). After each run the panel's
own ``draw`` code (``quality.panel.draw_quality``) lays its lines out into a small stand-in
layout that records labels, buttons, splits and their alert / active / enabled states; the
stand-in's boxes are then drawn with Blender's ``gpu`` and ``blf`` modules off screen, in
the colours of Blender's default theme, without icons. The figures are those the panel
holds after the runs. numpy and Blender only.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
_HOME = Path(tempfile.mkdtemp(prefix="procloco-quality-picture-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

DEFAULT_OUT = ROOT / "docs" / "images" / "quality_panel.png"
RIG = "Wolf"

#: Blender's default theme, roughly: panel, header, text, buttons, the alert red.
PANEL = (0.188, 0.188, 0.188, 1.0)
HEADER = (0.157, 0.157, 0.157, 1.0)
BACKGROUND = (0.114, 0.114, 0.114, 1.0)
TEXT = (0.9, 0.9, 0.9, 1.0)
BUTTON = (0.33, 0.33, 0.33, 1.0)
ALERT_TEXT = (1.0, 0.35, 0.3, 1.0)
ALERT_BUTTON = (0.6, 0.16, 0.14, 1.0)

ROW = 22  # pixels per row (Blender's UI unit at resolution scale 1.1)
WIDTH = 330  # a sidebar panel's width


# ------------------------------------------------------------------ the stand-in layout


@dataclass
class Cell:
    """A label or a button."""

    kind: str
    text: str
    alert: bool
    active: bool
    enabled: bool


class _Props:
    """What ``layout.operator`` returns: accepts the operator's properties."""

    def __setattr__(self, name: str, value: Any) -> None:
        object.__setattr__(self, name, value)


@dataclass
class Layout:
    """Records the calls ``draw_quality`` makes (``column``, ``row``, ``split``, ``label``,
    ``operator``) as a tree; ``alert``, ``active`` and ``enabled`` are inherited like
    Blender's."""

    kind: str = "column"
    factor: float = 0.0
    parent: Layout | None = None
    items: list[Layout | Cell] = field(default_factory=list)
    alert: bool = False
    active: bool = True
    enabled: bool = True
    scale_y: float = 1.0

    def _state(self, attr: str) -> bool:
        chain = []
        node: Layout | None = self
        while node is not None:
            chain.append(bool(getattr(node, attr)))
            node = node.parent
        return any(chain) if attr == "alert" else all(chain)

    def _child(self, kind: str, factor: float = 0.0) -> Layout:
        child = Layout(kind=kind, factor=factor, parent=self)
        self.items.append(child)
        return child

    def column(self, align: bool = False, heading: str = "") -> Layout:
        return self._child("column")

    def row(self, align: bool = False, heading: str = "") -> Layout:
        return self._child("row")

    def split(self, factor: float = 0.0, align: bool = False) -> Layout:
        return self._child("split", factor)

    def _cell(self, kind: str, text: str) -> None:
        states = (self._state("alert"), self._state("active"), self._state("enabled"))
        self.items.append(Cell(kind, text, *states))

    def label(self, text: str = "", icon: str = "NONE") -> None:
        self._cell("label", text)

    def operator(self, operator: str, text: str = "", icon: str = "NONE") -> _Props:
        self._cell("button", text)
        return _Props()


Placed = list[tuple[Cell, float, float, float]]


def place(node: Layout | Cell, x: float, y: float, w: float) -> tuple[Placed, float]:
    """Lay ``node`` out from its top-left corner ``(x, y)`` (y down) at width ``w``: the
    cells with their boxes ``(cell, x, y, w)`` and the height used."""
    if isinstance(node, Cell):
        return [(node, x, y, w)], ROW
    out: Placed = []
    if node.kind == "column":
        h = 0.0
        for item in node.items:
            cells, dh = place(item, x, y + h, w)
            out += cells
            h += dh * node.scale_y
        return out, h
    # a row shares its width equally; a split gives its first item ``factor`` of it
    n = len(node.items)
    if node.kind == "split" and n > 1:
        widths = [w * node.factor] + [w * (1.0 - node.factor) / (n - 1)] * (n - 1)
    else:
        widths = [w / max(n, 1)] * n
    h = 0.0
    for item, dw in zip(node.items, widths, strict=True):
        cells, dh = place(item, x, y, dw)
        out += cells
        h = max(h, dh)
        x += dw
    return out, h


# ------------------------------------------------------------------ the runs


def _generate_wolf(hold_legs_up: bool) -> Any:
    """Open examples.blend, generate the wolf (legs held up by 6 cm if asked); return it."""
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples.blend"))
    wolf = bpy.data.objects[RIG]
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    wolf.select_set(True)
    bpy.context.view_layer.objects.active = wolf
    if hold_legs_up:
        bpy.ops.procloco.detect_legs()
        for item in wolf.procloco.legs:
            head = wolf.matrix_world @ wolf.data.bones[item.hip].head_local
            c = wolf.pose.bones[item.hip].constraints.new("LIMIT_LOCATION")
            c.owner_space, c.use_min_z, c.min_z = "WORLD", True, head.z + 0.06
    if bpy.ops.procloco.generate_locomotion() != {"FINISHED"}:
        raise RuntimeError("Generate Locomotion failed on the example wolf")
    return wolf


def _panel_cells(wolf: Any) -> tuple[Placed, float]:
    panel = importlib_module("procloco_addon.blender.quality.panel")
    root = Layout()
    panel.draw_quality(root, wolf)
    return place(root, 10.0, 8.0, WIDTH - 20.0)


def importlib_module(name: str) -> Any:
    import importlib

    return importlib.import_module(name)


def render(panels: list[tuple[str, Placed, float]]) -> np.ndarray:
    """The panels side by side, each under its title and a "Quality" header: RGBA rows
    bottom to top."""
    import blf
    import gpu
    from gpu_extras.batch import batch_for_shader

    draw = importlib_module("procloco_addon.blender.gait.draw")
    draw.ensure_gpu_context()
    gap, title_h, header_h = 16, 26, 26
    body_h = max(h for _t, _c, h in panels) + 14
    width = len(panels) * WIDTH + (len(panels) + 1) * gap
    height = int(title_h + header_h + body_h + 2 * gap)
    shader = gpu.shader.from_builtin("UNIFORM_COLOR")

    def rect(x: float, y_top: float, w: float, h: float, color: tuple[float, ...]) -> None:
        y0 = height - y_top - h  # pixels up from the bottom
        pts = [(x, y0), (x + w, y0), (x + w, y0 + h), (x, y0 + h)]
        batch = batch_for_shader(shader, "TRIS", {"pos": pts}, indices=[(0, 1, 2), (0, 2, 3)])
        shader.bind()
        shader.uniform_float("color", color)
        batch.draw(shader)

    def text(x: float, y_top: float, h: float, s: str, color: tuple[float, ...], size: float = 12.0,
             center_w: float | None = None, clip: float | None = None) -> None:
        blf.size(0, size)
        if clip is not None:  # Blender cuts a label that does not fit with an ellipsis
            while len(s) > 1 and blf.dimensions(0, s)[0] > clip - 8:
                s = s[:-2] + "\u2026"
        tw, th = blf.dimensions(0, s or "x")
        if center_w is not None:
            x += 0.5 * (center_w - tw)
        blf.color(0, *color)
        blf.position(0, x, height - y_top - 0.5 * (h + th) - 1.0, 0.0)
        blf.draw(0, s)

    def draw_all() -> None:
        for k, (title, cells, _h) in enumerate(panels):
            x0 = gap + k * (WIDTH + gap)
            text(x0, gap, title_h, title, TEXT, 13.0)
            top = gap + title_h
            rect(x0, top, WIDTH, header_h, HEADER)
            text(x0 + 10, top, header_h, "Quality", TEXT, 13.0)
            rect(x0, top + header_h, WIDTH, body_h, PANEL)
            for cell, cx, cy, cw in cells:
                y = top + header_h + cy
                dim = 1.0 if cell.active and cell.enabled else 0.5
                if cell.kind == "button":
                    fill = ALERT_BUTTON if cell.alert else BUTTON
                    shade = (*(c * (0.6 + 0.4 * dim) for c in fill[:3]), 1.0)
                    rect(x0 + cx + 1, y + 1, cw - 2, ROW - 2, shade)
                    text(x0 + cx, y, ROW, cell.text, (*TEXT[:3], dim), 12.0, center_w=cw, clip=cw)
                else:
                    color = ALERT_TEXT if cell.alert else TEXT
                    text(x0 + cx + 4, y, ROW, cell.text, (*color[:3], dim), 12.0, clip=cw)

    return np.asarray(draw.render_offscreen(width, height, draw_all, BACKGROUND))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output PNG (default docs/images)")
    args = parser.parse_args(argv)
    procloco_addon = importlib_module("procloco_addon")
    export = importlib_module("tools.export_gait_pngs")
    measure = importlib_module("procloco_addon.blender.quality.measure")
    procloco_addon.register()
    panels = []
    for bad, title in ((False, "The example wolf"), (True, "Its legs held 6 cm up (a bad setup)")):
        wolf = _generate_wolf(bad)
        print(measure.summary_line(wolf))
        cells, h = _panel_cells(wolf)
        panels.append((title, cells, h))
    image = render(panels)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    export.write_png(args.out, image)
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]})")
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)  # Blender as a module may crash at interpreter exit
