# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait: Auto through Generate Locomotion, read off the posed rig's footfalls.

Each run ramps a creature's speed with a Gait Change (the speed reached evenly over its
transition time) and reads which feet lift together from the evaluated pose, frame by
frame. Creatures are sized with their object scale, so the same rig is a pony or a giant.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import rig
from procloco_addon.blender.gait import handler, rig_gait
from procloco_addon.blender.gait import panel as gait_panel
from procloco_addon.blender.locomotion import generate
from procloco_addon.core.locomotion import autogait
from tests.blender.pose_eval import leg_joints
from tests.blender.test_generate import _measure_on, _select_only, check_thresholds
from tests.blender.ui_recorder import draw_panel
from tests.core.test_autogait import first_frame, quadruped_phases, stable_runs
from tools.examples import creatures

pytestmark = pytest.mark.blender

FPS = 24


def _creature(scene: Any, kind: str, scale: float, size: float = 1.0) -> tuple[Any, float]:
    """A creature of ``kind`` at object scale ``scale × size`` on a large plane, its legs
    detected (a new rig: Auto), and its mean leg length. ``size`` also slows the scene's
    clock by ``√size`` (fps_base), so a creature ``size`` times larger makes the same steps
    in the same number of frames if it is dynamically similar."""
    scene.render.fps, scene.render.fps_base = FPS, float(np.sqrt(size))
    obj = creatures.BUILDERS[kind](scene)
    obj.scale = (scale * size,) * 3
    bpy.context.view_layer.update()
    leg = float(rig.read_rig(obj).leg_length.mean())
    bpy.ops.mesh.primitive_plane_add(size=70.0 * leg, location=(0.0, -30.0 * leg, 0.0))
    _select_only(obj)
    assert bpy.ops.procloco.detect_legs() == {"FINISHED"}
    assert obj.procloco.gait_mode == "AUTO"  # no gait chosen yet
    return obj, leg


def _ramp(obj: Any, frames: int, v0: float, changes: list[tuple[int, float, int]]) -> None:
    """Generate over ``frames`` frames starting at ``v0`` m/s; each change ``(frame, speed,
    ramp frames)`` is a Gait Change reaching ``speed`` over ``ramp frames``."""
    settings = obj.procloco
    settings.use_scene_range = False
    settings.frame_start, settings.frame_end = 1, frames
    settings.speed = v0
    scene = bpy.context.scene
    fps = scene.render.fps / scene.render.fps_base
    for frame, speed, ramp in changes:
        scene.frame_set(frame)
        _select_only(obj)
        assert bpy.ops.procloco.add_gait_change() == {"FINISHED"}
        change = obj.procloco.gait_changes[obj.procloco.active_gait_change_index]
        change.speed, change.transition_time = speed, ramp / fps
    scene.frame_set(1)


def _generate(obj: Any) -> tuple[generate.Job, np.ndarray]:
    """Generate through the operator's stages; returns the job and, per frame step, which
    feet moved (swinging) on the evaluated rig ``(F - 1, n_legs)``."""
    _select_only(obj)
    job = generate.prepare(bpy.context, obj)
    for _ in generate.simulate(job):
        pass
    generate.write(bpy.context, job)
    frames = [int(f) for f in job.frames]
    joints = leg_joints(obj, frames, [leg.bones for leg in job.info.legs])
    ends = np.stack([j[:, -1] for j in joints], axis=1)
    scale = float(job.info.leg_length.mean())
    return job, np.linalg.norm(np.diff(ends, axis=0), axis=2) > 1e-3 * scale


def _froude(job: generate.Job) -> np.ndarray:
    assert job.auto_gait is not None
    return np.asarray(job.auto_gait.froude(job.result.speed[1:]))


def _wolf_ramp(scene: Any, size: float) -> dict[str, Any]:
    """The wolf at horse size (×4; ``size`` more) ramping 0.2 -> 4 leg lengths/s (for size
    1; the ramp's leg-length speeds fall by √size): the read gaits per frame, the Froude
    numbers and speeds, the job."""
    obj, leg = _creature(scene, "wolf", 4.0, size)
    unit = leg / np.sqrt(size)
    _ramp(obj, 200, 0.2 * unit, [(2, 4.0 * unit, 150)])
    job, moving = _generate(obj)
    labels = [lg.label for lg in job.info.legs]
    return {"obj": obj, "job": job, "phases": quadruped_phases(moving, labels, 24), "fr": _froude(job),
            "speed": job.result.speed[1:], "leg": leg}


@pytest.fixture(scope="module")
def wolf_runs(procloco_registered: Any) -> Iterator[dict[float, dict[str, Any]]]:
    runs = {}
    for size in (1.0, 10.0):
        bpy.ops.wm.read_homefile(use_empty=True)
        run = _wolf_ramp(bpy.context.scene, size)
        m = _measure_on(run["obj"], run["job"], [bpy.data.objects["Plane"]], [])
        run["thresholds"] = m
        run.pop("obj")
        runs[size] = run
    return runs


def test_a_quadruped_ramping_up_walks_trots_then_gallops_near_the_stated_froude_numbers(
        wolf_runs: dict[float, dict[str, Any]]) -> None:
    run = wolf_runs[1.0]
    phases, fr = run["phases"][12:-12], run["fr"][12:-12]  # where the reading window fits
    assert stable_runs(phases, 12) == [0, 1, 2]  # walk, trot (diagonals), gallop (girdles)
    trot, gallop = first_frame(phases, 1), first_frame(phases, 2)
    assert 0.5 <= fr[trot] <= 1.3, fr[trot]  # Alexander & Jayes 1983: walk -> trot at Fr 0.5
    assert 2.5 <= fr[gallop] <= 4.2, fr[gallop]  # trot -> gallop at Fr 2.5
    assert list(np.unique(run["job"].result.auto_band)) == [0, 1, 2]
    check_thresholds(run["thresholds"])


def test_ten_times_larger_changes_gait_at_root_ten_times_the_speed(
        wolf_runs: dict[float, dict[str, Any]]) -> None:
    small, big = wolf_runs[1.0], wolf_runs[10.0]
    assert big["leg"] == pytest.approx(10.0 * small["leg"], rel=1e-6)
    for gait in (1, 2):
        f_small = first_frame(small["phases"][12:-12], gait) + 12
        f_big = first_frame(big["phases"][12:-12], gait) + 12
        assert abs(f_big - f_small) <= 6, (gait, f_small, f_big)  # the same moment of the shot
        ratio = big["speed"][f_big] / small["speed"][f_small]
        assert ratio == pytest.approx(np.sqrt(10.0), rel=0.1)
    # the same walk to scale: lengths judged at the scale of the creature (legs of 29 m walking
    # 600 m from the origin are posed in single precision)
    m = dict(big["thresholds"])
    for key in ("slide", "penetration", "avoid", "reach"):
        m[key] /= 10.0
    check_thresholds(m)


def test_a_hexapod_goes_from_a_wave_to_a_tripod(empty_scene: Any) -> None:
    obj, leg = _creature(empty_scene, "ant", 320.0)  # four-metre legs: gaits change at low leg speeds
    # The ant's legs are crowded along its body: its stance sweeps a quarter of the model's,
    # and it takes each gait at a quarter of the model's speed (AutoGaitParams.band_scale)
    auto = rig_gait.auto_params(obj, rig.read_rig(obj))
    assert auto is not None
    crowded = auto.band_scale
    assert 0.2 < crowded < 0.3
    # A wave (at 0.33 leg lengths a second of the model's) held over five steps of each
    # foot, then up to the tripod near the top speed. (Its swings keep their time, so its
    # wave cycles last as long as the model's: about 70 frames here; before, the cycle ran
    # 2.6 times faster to keep the model's sweep within the legs' reach. Slower still, below
    # 0.1 m/s with these four-metre legs, the walk steps early and fails to plan its
    # footsteps with or without the stroke: a very slow walk's own limitation.)
    _ramp(obj, 240, 0.33 * crowded * leg, [(140, 0.9 * crowded * leg, 40)])
    job, moving = _generate(obj)
    labels = [lg.label for lg in job.info.legs]
    # Every leg steps on the gait's beat: its feet find footprints beside each other (the
    # ant's tarsi reach far: the other feet are kept off its soles, not off its toes' reach).
    assert not job.result.plan_failed.any()
    assert job.result.forced.sum() <= 2, job.result.forced.sum(axis=0)
    on_beat = ~(job.result.forced[1:] | job.result.forced[:-1])
    tripods = [[labels.index(lb) for lb in group] for group in (("L1", "R2", "L3"), ("R1", "L2", "R3"))]

    def lifts(frames: slice) -> list[int]:
        """The legs in the order their feet lift in ``frames``, on the beat."""
        m = moving[frames] & on_beat[frames]
        up = m[1:] & ~m[:-1]
        return [int(k) for f in range(up.shape[0]) for k in np.flatnonzero(up[f])]

    # The wave (Wilson 1966): on each side the feet lift one after the other, back to front
    # (hind, middle, front, hind, ...), and the tripods do not lift together.
    for side in "LR":
        order = [labels[k][1] for k in lifts(slice(5, 135)) if labels[k][0] == side]
        assert len(order) >= 4, order
        assert all(int(b) == (int(a) - 2) % 3 + 1 for a, b in itertools.pairwise(order)), (side, order)

    def together(frames: slice) -> float:
        """How often the three feet of each tripod move alike."""
        m = moving[frames]
        return float(np.mean([m[:, g[0]] == m[:, k] for g in tripods for k in g[1:]]))

    assert together(slice(5, 135)) < 0.75
    # The tripod: L1, R2 and L3 swing together, then R1, L2 and R3.
    late = slice(200, 239)
    assert together(late) > 0.95
    a, b = moving[late][:, tripods[0][0]], moving[late][:, tripods[1][0]]
    assert np.mean(a != b) > 0.85  # one tripod up, the other down (both move as feet swap)
    assert list(np.unique(job.result.auto_band)) == [0, 1, 2]  # wave, tetrapod, tripod
    fr = _froude(job)
    first_tripod = int(np.flatnonzero(job.result.auto_band[1:] == 2)[0])
    tripod_low = autogait.FAMILIES["hexapod"].bands[2].fr_low
    assert fr[first_tripod] == pytest.approx(1.2 * tripod_low * crowded**2, rel=0.05)
    check_thresholds(_measure_on(obj, job, [bpy.data.objects["Plane"]], []))


def test_a_biped_walks_then_runs(empty_scene: Any) -> None:
    obj, leg = _creature(empty_scene, "human", 1.0)
    _ramp(obj, 150, 0.6 * leg, [(2, 3.0 * leg, 90)])
    job, moving = _generate(obj)
    # quick steps of a foot left behind are off the gait's beat (README: known limitations)
    on_beat = ~(job.result.forced[1:] | job.result.forced[:-1]).any(axis=1)
    both_up = np.all(moving, axis=1) & on_beat
    both_down = ~np.any(moving, axis=1) & on_beat
    assert not both_up[2:40].any()  # a walk: never both feet in the air
    assert both_down[2:40].any()  # double support
    assert both_up[110:].mean() > 0.1  # a run: a flight phase each step
    assert list(np.unique(job.result.auto_band)) == [0, 1]
    fr = _froude(job)
    switch = int(np.flatnonzero(np.diff(job.result.auto_band) > 0)[0])
    assert 0.5 <= fr[switch] <= 0.7  # walk -> run at Fr 0.5 (+ hysteresis)
    check_thresholds(_measure_on(obj, job, [bpy.data.objects["Plane"]], []))


def test_a_speed_hovering_at_a_boundary_flips_the_gait_at_most_once(empty_scene: Any) -> None:
    obj, _leg = _creature(empty_scene, "wolf", 4.0)
    job0 = generate.prepare(bpy.context, obj)
    assert job0.auto_gait is not None
    boundary = float(rig_gait.boundary_speeds(job0.auto_gait)[0])  # walk -> trot
    # the speed goes back and forth by ±7 % around the boundary every 20 frames
    wiggle = [(20 * k, boundary * (1.07 if k % 2 else 0.93), 10) for k in range(1, 6)]
    _ramp(obj, 130, 0.93 * boundary, wiggle)
    job, moving = _generate(obj)
    bands = job.result.auto_band
    assert np.count_nonzero(np.diff(bands)) <= 1
    # without hysteresis it would have changed gait at every crossing
    bare = autogait.band_schedule(job.auto_gait.family, _froude(job), hysteresis=0.0)
    assert np.count_nonzero(np.diff(bare)) >= 4
    phases = quadruped_phases(moving, [lg.label for lg in job.info.legs], 24)[12:-12]
    assert len(stable_runs(phases, 12)) <= 2
    check_thresholds(_measure_on(obj, job, [bpy.data.objects["Plane"]], []))


def test_the_panel_shows_the_current_gait_and_the_chart(empty_scene: Any) -> None:
    from procloco_addon.blender.gait import draw

    obj, leg = _creature(empty_scene, "wolf", 4.0)
    _ramp(obj, 60, 0.2 * leg, [(2, 4.0 * leg, 50)])
    draw.ensure_gpu_context()
    ui = draw_panel(gait_panel.PROCLOCO_PT_gait)
    assert ui.has_prop("gait_mode")
    assert ui.has_prop("gait_speed_scale")
    assert "PROCLOCO_MT_auto_gait_presets" in ui.menus()
    assert any("Predicted" in t for t in ui.labels())  # not generated yet
    empty_scene.frame_set(5)
    handler.refresh(force=True)
    walk_chart = handler.chart_pixels().copy()
    early = rig_gait.circles_at_frame(obj, empty_scene)
    empty_scene.frame_set(58)
    handler.refresh()
    late = rig_gait.circles_at_frame(obj, empty_scene)
    assert early is not None
    assert late is not None
    trot = generate.core_gait.find_gait_preset("quadruped_trot").gait(early[0])
    gallop = generate.core_gait.find_gait_preset("quadruped_transverse_gallop").gait(early[0])
    walk = generate.core_gait.find_gait_preset("quadruped_walk").gait(early[0])
    assert np.allclose(early[1], walk.swing_start)
    assert np.allclose(late[1], gallop.swing_start)
    assert not np.allclose(late[1], trot.swing_start)
    assert np.any(np.abs(handler.chart_pixels() - walk_chart) > 0.1)  # the frame marker moved
    # generated: the circles show what was generated at each frame
    _generate(obj)
    track = rig_gait.auto_track(obj, empty_scene)
    assert track is not None
    assert track.recorded
    assert not any("Predicted" in t for t in draw_panel(gait_panel.PROCLOCO_PT_gait).labels())
    # choosing a preset chooses the gait: Circles
    assert bpy.ops.procloco.apply_gait_preset(
        filepath=str(generate.core_gait.gait_preset_dir() / "quadruped_trot.json")) == {"FINISHED"}
    assert obj.procloco.gait_mode == "CIRCLES"
    assert rig_gait.auto_track(obj, empty_scene) is None


def test_the_batch_command_sets_the_gait(empty_scene: Any, capsys: pytest.CaptureFixture[str]) -> None:
    from procloco_addon.blender import actions, cli

    bpy.ops.mesh.primitive_plane_add(size=8.0)
    robot = creatures.build_robot(empty_scene)
    assert cli.main(["generate", "--rig", "Robot", "--frames", "1", "8", "--gait", "pentapod_robot"]) == 0
    assert robot.procloco.gait_mode == "CIRCLES"
    assert robot.procloco.gait_preset == "Pentapod robot"
    # an explicit speed wins over the preset's own (the preset is applied first)
    assert cli.main(["generate", "--rig", "Robot", "--frames", "1", "8", "--gait", "pentapod_robot",
                     "--speed", "0.123"]) == 0
    assert robot.procloco.speed == pytest.approx(0.123)
    assert cli.main(["generate", "--rig", "Robot", "--frames", "1", "8", "--gait", "auto"]) == 0
    assert robot.procloco.gait_mode == "AUTO"
    action = actions.generated_action(robot)
    assert action is not None
    assert rig_gait.TRACK_PROPERTY in action  # what Auto chose, kept for the panel
    capsys.readouterr()
    assert cli.main(["generate", "--rig", "Robot", "--gait", "moonwalk"]) == 1
    assert "no gait preset named 'moonwalk'" in capsys.readouterr().err
    assert robot.procloco.gait_mode == "AUTO"


def test_a_preset_replaces_one_of_autos_gaits_and_the_speed_scale_moves_them(empty_scene: Any) -> None:
    from procloco_addon.blender.gait import ops as gait_ops
    from tests.blender.ui_recorder import draw_menu

    obj, leg = _creature(empty_scene, "wolf", 4.0)
    _ramp(obj, 40, 2.0 * leg, [])  # a trot
    pace = generate.core_gait.gait_preset_dir() / "quadruped_pace.json"
    menu = draw_menu(gait_ops.PROCLOCO_MT_auto_gait_presets)
    assert "Quadruped pace" in [c.text for c in menu.operator_calls("procloco.set_auto_gait")]
    assert bpy.ops.procloco.set_auto_gait(band="trot", filepath=str(pace)) == {"FINISHED"}
    shown = rig_gait.circles_at_frame(obj, empty_scene, 20)
    assert shown is not None
    assert np.allclose(shown[1], generate.core_gait.load_gait_preset(pace).gait(shown[0]).swing_start)
    with pytest.raises(RuntimeError, match="Cannot use this preset"):
        bpy.ops.procloco.set_auto_gait(band="trot", filepath=str(pace.with_name("hexapod_tripod.json")))
    assert bpy.ops.procloco.set_auto_gait(band="trot") == {"FINISHED"}  # back to the shipped trot
    assert obj.procloco.auto_gait_overrides == ""
    before = rig_gait.auto_track(obj, empty_scene)
    obj.procloco.gait_speed_scale = 2.0  # trots only from twice the speed: a walk
    after = rig_gait.auto_track(obj, empty_scene)
    assert before is not None
    assert after is not None
    assert np.allclose(after.boundaries, 2.0 * before.boundaries)
    assert set(before.band.tolist()) == {1}
    assert set(after.band.tolist()) == {0}


def test_chart_layout_puts_the_bands_and_the_speed_on_one_axis() -> None:
    from procloco_addon.blender.gait import geometry

    speed = np.linspace(0.5, 7.0, 50)
    layout = geometry.chart_layout(np.array([2.7, 6.1]), speed, 10, 320, 160)
    bands = layout.bands
    assert bands.shape == (3, 4)
    assert np.all(np.diff(bands[:, 1]) > 0.0)  # walk at the bottom, gallop on top
    assert np.allclose(bands[1:, 1], bands[:-1, 3])  # the bands touch at the boundaries
    assert np.allclose(layout.speed_y(2.7), bands[1, 1])
    assert np.all(np.diff(layout.curve[:, 1]) > 0.0)  # the speed rises: so does the line
    assert layout.marker_x == pytest.approx(layout.curve[10, 0])
    assert geometry.chart_layout(np.array([2.7]), speed, None, 320, 160).marker_x is None


def test_five_legs_other_than_the_pentapods_walk_on_their_circles(empty_scene: Any) -> None:
    # Auto's five-legged gaits are the pentapod's (M1 ahead, then two pairs): a five-legged rig
    # labelled otherwise (two pairs, then its odd leg behind) walks with its gait circles.
    obj, leg = _creature(empty_scene, "robot", 1.0)
    relabel = {"M1": "M3", "L2": "L1", "R2": "R1", "L3": "L2", "R3": "R2"}
    for item in obj.procloco.legs:
        item.label = relabel[item.label]
    settings = obj.procloco
    settings.use_scene_range = False
    settings.frame_start, settings.frame_end = 1, 24
    job = generate.prepare(bpy.context, obj)
    assert any("Auto gait knows no gaits for 5 legs (" in w for w in job.warnings), job.warnings
    assert job.auto_gait is None
    for _ in generate.simulate(job):
        pass
    generate.write(bpy.context, job)
    assert float(np.linalg.norm(job.result.body[-1, :2, 3] - job.result.body[0, :2, 3])) > 0.1 * leg
