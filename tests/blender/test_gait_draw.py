# SPDX-License-Identifier: GPL-3.0-or-later
"""The gait-circle picture shows the gait: measured from its pixels, not from the code.

Each test renders the circles with the GPU off screen, then reads angles back from the
image: the swing sector's start and end along the ring and the needle's direction
outside it must be within 2° of the settings (phase 0 at the top, clockwise).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from procloco_addon.blender.gait import draw, geometry
from procloco_addon.blender.locomotion import property_group as locomotion_props

TOLERANCE = 2.0 / 360.0  # two degrees, as a cycle fraction
SIZE = 512


@pytest.fixture(scope="module")
def gpu_ready(procloco_registered: Any) -> None:
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    draw.ensure_gpu_context()


def classify(image: np.ndarray, palette: draw.Palette = draw.DEFAULT_PALETTE) -> tuple[np.ndarray, list[str]]:
    """Index of the nearest palette colour for every pixel, and the palette's names."""
    names = ["background", "ring", "swing", "swing_active", "needle", "label", "handle"]
    colors = np.array([getattr(palette, n)[:3] for n in names], dtype=np.float32)
    dist = np.linalg.norm(image[..., None, :3] - colors[None, None], axis=-1)
    return np.argmin(dist, axis=-1), names


def ring_samples(image: np.ndarray, center: np.ndarray, radius: float,
                 phases: np.ndarray) -> np.ndarray:
    """Palette names of the pixels at ``radius`` from ``center`` for each phase."""
    labels, names = classify(image)
    angles = np.pi / 2.0 - 2.0 * np.pi * phases  # the documented convention: top, clockwise
    x = np.clip(np.round(center[0] + radius * np.cos(angles)).astype(int), 0, image.shape[1] - 1)
    y = np.clip(np.round(center[1] + radius * np.sin(angles)).astype(int), 0, image.shape[0] - 1)
    return np.array(names)[labels[y, x]]


def measure_sector(image: np.ndarray, layout: geometry.CircleLayout, leg: int) -> tuple[float, float]:
    """(start, end) phase of the one swing run on the leg's ring, read from pixels."""
    phases = np.arange(0.0, 1.0, 0.0005)
    mid = 0.5 * (geometry.RING_INNER + 1.0) * layout.radius
    seen = ring_samples(image, layout.centers[leg], mid, phases)
    swing = np.isin(seen, ["swing", "swing_active"])
    stance = seen == "ring"
    assert swing.any(), f"leg {leg}: ring shows {set(seen)}"
    assert stance.any(), f"leg {leg}: ring shows {set(seen)}"
    # The needle and the handles hide a few samples: an edge found across such a gap is put
    # in the gap's middle (where the needle stands when it sits on the edge).
    known = np.flatnonzero(swing | stance)
    state = swing[known]
    nxt = np.roll(known, -1)
    gap_mid = np.mod(phases[known] + 0.5 * np.mod(phases[nxt] - phases[known], 1.0), 1.0)
    rises = gap_mid[~state & np.roll(state, -1)]
    falls = gap_mid[state & ~np.roll(state, -1)]
    assert len(rises) == 1, f"leg {leg}: {len(rises)} swing runs"
    assert len(falls) == 1, f"leg {leg}: {len(falls)} swing runs"
    return float(rises[0]), float(falls[0])


def measure_needle(image: np.ndarray, layout: geometry.CircleLayout, leg: int) -> float:
    """Phase of the needle, from its pixels just outside the ring."""
    phases = np.arange(0.0, 1.0, 0.0005)
    seen = ring_samples(image, layout.centers[leg], 1.095 * layout.radius, phases)
    hit = phases[seen == "needle"]
    assert hit.size, f"leg {leg}: no needle outside the ring"
    angles = 2.0 * np.pi * hit
    return float(np.mod(np.arctan2(np.sin(angles).mean(), np.cos(angles).mean()) / (2 * np.pi), 1.0))


def cyclic_error(a: float, b: float) -> float:
    d = abs(a - b) % 1.0
    return min(d, 1.0 - d)


GAITS = {
    # Rotary gallop: lead changes sides front to back; L2's swing wraps past phase 0.
    "rotary_gallop": (["L1", "R1", "L2", "R2"], [0.10, 0.0, 0.55, 0.65], [0.40, 0.40, 0.52, 0.40]),
    "hexapod_tripod": (["L1", "R1", "L2", "R2", "L3", "R3"], [0.0, 0.5, 0.5, 0.0, 0.0, 0.5], [0.45] * 6),
    "pentapod": (["L1", "R1", "L2", "R2", "M3"], [0.0, 0.2, 0.4, 0.6, 0.8], [0.18, 0.25, 0.3, 0.12, 0.6]),
    "unnamed_legs": (["Leg1", "Leg2", "Leg3"], [0.95, 0.33, 0.66], [0.2, 0.2, 0.2]),
}


@pytest.mark.parametrize("name", sorted(GAITS))
def test_sector_angles_measured_from_pixels_match_the_gait(gpu_ready: None, name: str) -> None:
    labels, start, duration = GAITS[name]
    image = draw.render_gait_image(np.array(start), np.array(duration), labels, 0.37,
                                   width=SIZE, height=SIZE)
    assert image.shape == (SIZE, SIZE, 4)
    layout = geometry.layout_circles(labels, SIZE, SIZE)
    for leg in range(len(labels)):
        got_start, got_end = measure_sector(image, layout, leg)
        assert cyclic_error(got_start, start[leg]) <= TOLERANCE, (name, leg, got_start, start[leg])
        assert cyclic_error(got_end, start[leg] + duration[leg]) <= TOLERANCE, (name, leg, got_end)


def test_random_gaits_measured_from_pixels(gpu_ready: None) -> None:
    rng = np.random.default_rng(7)
    for n_legs in (2, 7, 8):
        labels = [f"L{i // 2 + 1}" if i % 2 == 0 else f"R{i // 2 + 1}" for i in range(n_legs)]
        start = rng.uniform(0.0, 1.0, n_legs)
        duration = rng.uniform(0.1, 0.85, n_legs)
        image = draw.render_gait_image(start, duration, labels, None, width=SIZE, height=SIZE)
        layout = geometry.layout_circles(labels, SIZE, SIZE)
        for leg in range(n_legs):
            got_start, got_end = measure_sector(image, layout, leg)
            assert cyclic_error(got_start, start[leg]) <= TOLERANCE, (n_legs, leg)
            assert cyclic_error(got_end, start[leg] + duration[leg]) <= TOLERANCE, (n_legs, leg)


@pytest.mark.parametrize("phase", [0.0, 0.13, 0.5, 0.77, 0.995])
def test_needle_points_at_the_phase(gpu_ready: None, phase: float) -> None:
    labels, start, duration = GAITS["hexapod_tripod"]
    image = draw.render_gait_image(np.array(start), np.array(duration), labels, phase,
                                   width=SIZE, height=SIZE)
    layout = geometry.layout_circles(labels, SIZE, SIZE)
    for leg in range(len(labels)):
        assert cyclic_error(measure_needle(image, layout, leg), phase) <= TOLERANCE, leg


def test_no_needle_when_phase_is_none(gpu_ready: None) -> None:
    labels, start, duration = GAITS["hexapod_tripod"]
    image = draw.render_gait_image(np.array(start), np.array(duration), labels, None, width=256, height=256)
    pixels, names = classify(image)
    assert not (pixels == names.index("needle")).any()


def test_sectors_under_the_needle_are_highlighted(gpu_ready: None) -> None:
    labels, start, duration = GAITS["hexapod_tripod"]
    phase = 0.2  # tripod: legs starting at 0 swing, the others stand
    image = draw.render_gait_image(np.array(start), np.array(duration), labels, phase,
                                   width=SIZE, height=SIZE)
    layout = geometry.layout_circles(labels, SIZE, SIZE)
    mid = 0.5 * (geometry.RING_INNER + 1.0) * layout.radius
    for leg in range(len(labels)):
        inside = start[leg] + 0.5 * duration[leg]
        seen = ring_samples(image, layout.centers[leg], mid, np.array([inside]))[0]
        expected = "swing_active" if start[leg] == 0.0 else "swing"
        assert seen == expected, (leg, seen)


def test_each_leg_is_labelled_inside_its_circle(gpu_ready: None) -> None:
    labels, start, duration = GAITS["rotary_gallop"]
    with_labels = draw.render_gait_image(np.array(start), np.array(duration), labels, None,
                                         width=SIZE, height=SIZE)
    without = draw.render_gait_image(np.array(start), np.array(duration), [""] * 4, None,
                                     width=SIZE, height=SIZE)
    layout = geometry.layout_circles(labels, SIZE, SIZE)
    changed = np.any(np.abs(with_labels - without) > 0.2, axis=-1)
    ys, xs = np.nonzero(changed)
    owner = np.argmin(np.linalg.norm(np.stack([xs, ys], 1)[:, None] - layout.centers[None], axis=-1), axis=1)
    inner = geometry.RING_INNER * layout.radius
    for leg in range(4):
        mine = owner == leg
        assert mine.sum() > 30, f"no label drawn for leg {leg}"
        dist = np.linalg.norm(np.stack([xs[mine], ys[mine]], 1) - layout.centers[leg], axis=1)
        assert dist.max() < inner, "label spills onto the ring"
    # Different texts draw differently.
    other = draw.render_gait_image(np.array(start), np.array(duration), ["A", "B", "C", "D"], None,
                                   width=SIZE, height=SIZE)
    assert np.any(np.abs(other - with_labels) > 0.2)


def test_layout_follows_the_body_plan() -> None:
    layout = geometry.layout_circles(["L1", "R1", "L2", "R2", "M3"], 300, 400)
    x, y = layout.centers[:, 0], layout.centers[:, 1]
    assert x[0] < x[1]  # left legs on the left
    assert x[2] < x[3]
    assert y[0] == y[1] > y[2] == y[3] > y[4]  # front at the top, pairs side by side
    assert abs(x[4] - 150) < 1e-9  # midline leg centred
    # No two circles overlap and every circle (with the needle's overhang) is in the canvas.
    reach = geometry.NEEDLE_OUTER * layout.radius
    gaps = np.linalg.norm(layout.centers[:, None] - layout.centers[None], axis=-1) + np.eye(5) * 1e9
    assert gaps.min() > 2 * reach
    assert np.all(layout.centers - reach >= 0)
    assert np.all(layout.centers + reach <= [300, 400])
    sides = geometry.leg_sides(["thigh.L", "shin_r", "LeftUpLeg", "RightFoot", "Leg3", "M1"])
    assert sides.tolist() == [-1, 1, -1, 1, 0, 0]


def test_hit_test_finds_sector_handles() -> None:
    labels = ["L1", "R1"]
    start, duration = np.array([0.0, 0.25]), np.array([0.25, 0.5])
    layout = geometry.layout_circles(labels, 400, 200)
    mid = 0.5 * (geometry.RING_INNER + 1.0) * layout.radius
    c0, c1 = layout.centers
    assert geometry.hit_test(layout, start, duration, (c0[0], c0[1] + mid)) == (0, "START")  # top
    assert geometry.hit_test(layout, start, duration, (c0[0] + mid, c0[1])) == (0, "END")  # 3 o'clock
    assert geometry.hit_test(layout, start, duration, (c1[0], c1[1] - mid)) == (1, "MOVE")  # 6 o'clock
    assert geometry.hit_test(layout, start, duration, (c0[0], c0[1] - mid)) == (0, "RING")  # stance part
    assert geometry.hit_test(layout, start, duration, (c1[0] + mid, c1[1])) == (1, "START")
    assert geometry.hit_test(layout, start, duration, tuple(c0)) is None  # the label, not the ring
    assert geometry.point_phase(layout, 1, (c1[0] - mid, c1[1])) == pytest.approx(0.75)
    assert layout.contains((399.0, 1.0))
    assert not layout.contains((401.0, 100.0))
    assert not layout.contains((10.0, -1.0))


@pytest.mark.parametrize(
    ("handle", "start", "duration", "grab", "to", "previous", "expected"),
    [
        ("END", 0.1, 0.3, 0.4, 0.55, None, (0.1, 0.45)),  # end follows, start stays
        ("START", 0.1, 0.3, 0.1, 0.0, None, (0.0, 0.4)),  # start follows, end stays at 0.4
        ("START", 0.1, 0.3, 0.1, 0.9, None, (0.9, 0.5)),  # across phase 0
        ("MOVE", 0.8, 0.3, 0.9, 0.05, None, (0.95, 0.3)),  # whole sector turns, wrapping
        ("END", 0.1, 0.3, 0.4, 0.09, 0.97, (0.1, 0.98)),  # pushed past the start: sticks to full
        ("END", 0.1, 0.3, 0.4, 0.11, 0.03, (0.1, 0.02)),  # pulled back past it: sticks to minimum
    ],
)
def test_dragging_a_sector_edge(handle: str, start: float, duration: float, grab: float, to: float,
                                previous: float | None, expected: tuple[float, float]) -> None:
    got = geometry.drag_sector(handle, start, duration, grab, to, previous_duration=previous)
    assert got == pytest.approx(expected)
    assert geometry.MIN_DURATION <= got[1] <= 1.0 - geometry.MIN_DURATION


# -- the panel's picture follows the rig ----------------------------------------------------


def test_panel_picture_follows_the_rig(gpu_ready: None, empty_scene: Any) -> None:
    import bpy

    from procloco_addon.blender.gait import handler
    from tests.blender.test_gait_presets import SHIPPED, make_rig

    obj = make_rig(empty_scene, n_pairs=3)
    bpy.ops.procloco.apply_gait_preset(filepath=str(SHIPPED / "hexapod_tripod.json"))
    settings = obj.procloco
    handler.request_refresh()
    assert handler.flush()
    labels = tuple(leg.label for leg in settings.legs)
    layout = geometry.layout_circles(labels, handler.PREVIEW_SIZE, handler.PREVIEW_SIZE)

    def check(pixels: np.ndarray, phase: float) -> None:
        for i, leg in enumerate(settings.legs):
            start, end = measure_sector(pixels, layout, i)
            assert cyclic_error(start, leg.swing_start) <= TOLERANCE, (i, start)
            assert cyclic_error(end, leg.swing_start + leg.swing_duration) <= TOLERANCE, (i, end)
            assert cyclic_error(measure_needle(pixels, layout, i), phase) <= TOLERANCE, i

    fps = empty_scene.render.fps / empty_scene.render.fps_base
    start_frame = locomotion_props.frame_range(settings, empty_scene)[0]

    def phase_now() -> float:
        return ((empty_scene.frame_current - start_frame) / fps / settings.cycle_time) % 1.0

    check(handler.preview_pixels(), phase_now())
    assert not handler.flush()  # nothing changed: no redraw

    # A value edited (the UI tags the object; the depsgraph handler asks for a redraw).
    settings.legs[2].swing_start = 0.2
    obj.update_tag()
    bpy.context.view_layer.update()
    assert handler.flush()
    check(handler.preview_pixels(), phase_now())

    # A frame change moves the needle (frame_change_post handler).
    empty_scene.frame_set(start_frame + 7)
    assert handler.flush()
    check(handler.preview_pixels(), (7 / fps / settings.cycle_time) % 1.0)


def test_unregister_removes_handlers_and_picture(gpu_ready: None, empty_scene: Any) -> None:
    import bpy

    import procloco_addon
    from procloco_addon.blender.gait import handler

    ours = {handler._on_depsgraph_update, handler._on_frame_change, handler._on_load_post}
    assert ours <= set(bpy.app.handlers.depsgraph_update_post) | set(bpy.app.handlers.frame_change_post) \
        | set(bpy.app.handlers.load_post)
    procloco_addon.unregister()
    try:
        left = [h for lst in (bpy.app.handlers.depsgraph_update_post, bpy.app.handlers.frame_change_post,
                              bpy.app.handlers.load_post) for h in lst if h in ours]
        assert left == []
        assert handler.preview() is None
        assert not hasattr(bpy.types.WindowManager, "procloco_gait_view")
    finally:
        procloco_addon.register()
    assert handler.preview() is not None


# -- the viewport overlay ---------------------------------------------------------------------


class _Region:
    """The parts of a 3D view's main region the overlay uses."""

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height, self.x, self.y, self.type = width, height, 0, 0, "WINDOW"


@pytest.fixture
def overlay_rig(gpu_ready: None, empty_scene: Any) -> Any:
    import bpy

    from tests.blender.test_gait_presets import SHIPPED, make_rig

    obj = make_rig(empty_scene)
    bpy.ops.procloco.apply_gait_preset(filepath=str(SHIPPED / "quadruped_rotary_gallop.json"))
    view = bpy.context.window_manager.procloco_gait_view
    view.show_overlay = True
    yield obj
    view.show_overlay = False
    view.overlay_corner = "BOTTOM_LEFT"


@pytest.mark.parametrize("corner", ["BOTTOM_LEFT", "TOP_RIGHT"])
def test_overlay_draws_the_gait_in_the_chosen_corner(overlay_rig: Any, corner: str) -> None:
    import bpy

    from procloco_addon.blender.gait import handler
    from tests.blender.ui_recorder import ContextStandIn

    view = bpy.context.window_manager.procloco_gait_view
    view.overlay_corner = corner
    region = _Region(640, 480)
    context = ContextStandIn(area=None, region=region)
    drawn: list[bool] = []
    image = draw.render_offscreen(640, 480, lambda: drawn.append(handler.draw_overlay(context, region)),
                                  clear=(0.5, 0.5, 0.5, 1.0))
    assert drawn == [True]
    labels = tuple(leg.label for leg in overlay_rig.procloco.legs)
    layout, (x, y) = handler.overlay_layout(context, region, labels)
    width, height = geometry.canvas_size(labels, view.overlay_cell)
    assert (x < 320) == corner.endswith("LEFT")
    assert (y < 240) == corner.startswith("BOTTOM")
    assert 0 <= x <= 640 - width
    assert 0 <= y <= 480 - height
    centers = layout.centers + np.array([x, y])
    shifted = geometry.CircleLayout(640, 480, centers, layout.radius, layout.label_pos, 10.0)
    for i, leg in enumerate(overlay_rig.procloco.legs):
        start, end = measure_sector(image, shifted, i)
        assert cyclic_error(start, leg.swing_start) <= TOLERANCE
        assert cyclic_error(end, leg.swing_start + leg.swing_duration) <= TOLERANCE
    # Outside the overlay's rectangle the viewport is untouched.
    outside = np.ones(image.shape[:2], dtype=bool)
    outside[int(y):int(y) + height, int(x):int(x) + width] = False
    assert np.allclose(image[outside][:, :3], 0.5, atol=0.01)

    view.show_overlay = False
    assert handler.draw_overlay(context, region) is False


def test_dragging_in_the_overlay_edits_the_rig(overlay_rig: Any) -> None:
    from procloco_addon.blender.gait import handler, ops
    from tests.blender.ui_recorder import ContextStandIn

    legs = overlay_rig.procloco.legs
    region = _Region(640, 480)
    labels = tuple(leg.label for leg in legs)
    layout, _offset = handler.overlay_layout(ContextStandIn(area=None), region, labels)
    mid = 0.5 * (geometry.RING_INNER + 1.0) * layout.radius

    def at(leg: int, phase: float) -> tuple[float, float]:
        angle = np.pi / 2 - 2 * np.pi * phase
        return (layout.centers[leg, 0] + mid * np.cos(angle), layout.centers[leg, 1] + mid * np.sin(angle))

    editor = ops.OverlayEditor(overlay_rig)
    start, duration = legs[1].swing_start, legs[1].swing_duration
    # Grab R1's end and drag it 0.1 of a cycle further: the start stays.
    assert editor.press(layout, at(1, start + duration))
    assert editor.move(layout, at(1, start + duration + 0.1))
    assert editor.release()
    assert legs[1].swing_start == pytest.approx(start, abs=1e-6)
    assert legs[1].swing_duration == pytest.approx(duration + 0.1, abs=0.005)

    # Grab the middle of L2's sector and turn it; Ctrl-like snapping to 1/20.
    start2, duration2 = legs[2].swing_start, legs[2].swing_duration
    assert editor.press(layout, at(2, start2 + duration2 / 2))
    editor.move(layout, at(2, start2 + duration2 / 2 + 0.23), snap=0.05)
    assert legs[2].swing_duration == pytest.approx(duration2, abs=1e-6)
    assert (legs[2].swing_start - start2) % 1.0 == pytest.approx(0.25, abs=0.051)
    # Esc while dragging puts the values back.
    assert editor.cancel()
    assert legs[2].swing_start == pytest.approx(start2, abs=1e-6)

    # A press on the stance part of a ring, or off the rings, grabs nothing.
    before = [(leg.swing_start, leg.swing_duration) for leg in legs]
    assert not editor.press(layout, at(0, legs[0].swing_start + legs[0].swing_duration + 0.15))
    assert not editor.press(layout, (1.0, 1.0))
    assert not editor.move(layout, at(0, 0.5))
    assert [(leg.swing_start, leg.swing_duration) for leg in legs] == before


def test_exported_png_is_the_picture(gpu_ready: None, tmp_path: Any) -> None:
    import bpy

    from procloco_addon.core.locomotion import gait as core_gait
    from tools import export_gait_pngs

    assert {"quadruped_rotary_gallop", "quadruped_transverse_gallop", "hexapod_tripod"} <= set(
        export_gait_pngs.README_PRESETS)
    [path] = export_gait_pngs.export(["hexapod_tripod"], tmp_path, cell=90, phase=0.3)
    assert path.name == "gait_hexapod_tripod.png"
    preset = core_gait.load_gait_preset(core_gait.gait_preset_dir() / "hexapod_tripod.json")
    width, height = geometry.canvas_size(preset.legs, 90)
    expected = draw.render_gait_image(preset.swing_start, preset.swing_duration, preset.legs, 0.3,
                                      width=width, height=height)
    image = bpy.data.images.load(str(path))
    try:
        assert tuple(image.size) == (width, height)
        pixels = np.empty(width * height * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    assert np.abs(pixels.reshape(height, width, 4) - expected).max() <= 1.0 / 255 + 1e-6
