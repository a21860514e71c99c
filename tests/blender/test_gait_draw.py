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
    # The needle and the handles cover a few samples: they take the state before them.
    state = np.where(swing, 1, np.where(stance, 0, -1))
    for i in np.flatnonzero(state < 0):
        state[i] = state[i - 1]
    rises = np.flatnonzero((state == 1) & (np.roll(state, 1) == 0))
    falls = np.flatnonzero((state == 0) & (np.roll(state, 1) == 1))
    assert len(rises) == 1, f"leg {leg}: {len(rises)} swing runs"
    assert len(falls) == 1, f"leg {leg}: {len(falls)} swing runs"
    return float(phases[rises[0]]), float(phases[falls[0]])


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
    assert geometry.hit_test(layout, start, duration, (c1[0], c1[1] - mid)) == (1, "RING")  # 6 o'clock
    assert geometry.hit_test(layout, start, duration, (c1[0] + mid, c1[1])) == (1, "START")
    assert geometry.hit_test(layout, start, duration, tuple(c0)) is None  # the label, not the ring
    assert geometry.point_phase(layout, 1, (c1[0] - mid, c1[1])) == pytest.approx(0.75)
