# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Preview: the timer's callback driven by hand (background mode runs no timers), on a
real rig; every result is checked on the posed rig through the depsgraph (pose_eval)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import actions
from procloco_addon.blender.live_preview import handler, preview
from procloco_addon.blender.locomotion import generate
from tests.blender import pose_eval
from tests.blender.scene_state import snapshot
from tests.blender.spy import spy
from tests.blender.ui_recorder import draw_panel
from tools.examples import creatures

pytestmark = pytest.mark.blender

FRAMES = 10
HIPS = "spine.004"  # the wolf metarig's hips
FEET = ("front_foot.L", "front_foot.R", "foot.L", "foot.R")
NOT_INPUTS = {"live_preview", "active_leg_index", "active_gait_change_index"}


class Clock:
    """The watcher's clock, moved by the test: debouncing without real waiting."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock() -> Iterator[Clock]:
    fake = Clock()
    handler._state.clock = fake
    yield fake
    handler._forget()
    handler._state.clock = time.monotonic


@pytest.fixture
def wolf(empty_scene: Any, clock: Clock) -> Any:
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    bpy.context.active_object.name = "Ground"
    obj = creatures.build_wolf(empty_scene)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    generate.detect_into_settings(obj)
    obj.procloco.use_scene_range = False
    obj.procloco.frame_start, obj.procloco.frame_end = 1, FRAMES
    obj.procloco.speed = 0.8
    return obj


def settle(clock: Clock, limit: int = 2000) -> int:
    """Call the timer until it has nothing to do, moving the clock by what it asks for
    (at least a millisecond). Returns the number of calls."""
    for n in range(1, limit):
        wait = handler.tick()
        if wait is None or (handler._state.run is None
                            and all(w.due is None for w in handler._state.watches.values())):
            return n
        clock.now += max(wait, 0.001)
    raise AssertionError("the timer never settled")


def tick_until_partial(obj: Any, clock: Clock, limit: int = 500) -> tuple[str | None, list[Any]]:
    """Call the timer (the clock 10 ms on a call) until the rig shows a preview of the current
    frame alone: that Action's name (None if it never did) and what each call asked to wait."""
    waits = []
    for _ in range(limit):
        waits.append(handler.tick())
        clock.now += 0.01
        current = obj.animation_data.action if obj.animation_data else None
        if current is not None and current.get(preview.PARTIAL_TAG):
            return current.name, waits
    return None, waits


def procloco_actions() -> list[Any]:
    return [a for a in bpy.data.actions if actions.is_generated(a)]


def hips_track(obj: Any) -> np.ndarray:
    """World position of the hips at every generated frame ``(F, 3)``, as Blender poses them."""
    return pose_eval.pose_matrices(obj, range(1, FRAMES + 1), [HIPS])[:, 0, :3, 3]


def travelled(obj: Any) -> float:
    track = hips_track(obj)
    return float(np.linalg.norm(track[-1, :2] - track[0, :2]))


def user_action(obj: Any) -> Any:
    """A hand-made Action on the rig: a key on the tail bone."""
    action = bpy.data.actions.new("My Tail")
    obj.animation_data_create()
    actions.assign_action(obj, action)
    pb = obj.pose.bones["spine"]
    pb.rotation_mode = "XYZ"
    pb.rotation_euler = (0.3, 0.0, 0.0)
    pb.keyframe_insert("rotation_euler", frame=1)
    return action


# ---------------------------------------------------------------------------------------


def test_every_setting_of_the_rig_is_an_input_of_the_preview(wolf: Any) -> None:
    """A change to any ProcLoco setting (a leg's and a gait change's too) changes what the
    preview is made from; the toggle and the lists' cursors do not."""
    scene = bpy.context.scene
    change = wolf.procloco.gait_changes.add()
    groups = [wolf.procloco, wolf.procloco.legs[0], change]
    checked = []
    for group in groups:
        for prop in group.bl_rna.properties:
            key = prop.identifier
            if prop.is_readonly or prop.type in {"COLLECTION", "POINTER"} or key == "rna_type":
                continue
            before = preview.settings_signature(wolf, scene)
            old = getattr(group, key)
            if prop.type == "BOOLEAN":
                new: Any = not old
            elif prop.type == "ENUM":
                new = next(item.identifier for item in prop.enum_items if item.identifier != old)
            elif prop.type == "STRING":
                new = old + "x"
            elif getattr(prop, "is_array", False):
                new = tuple(v + 0.25 for v in old)
            else:
                step = 1 if prop.type == "INT" else 0.25
                new = old + step if old + step <= prop.hard_max else old - step
            setattr(group, key, new)
            changed = preview.settings_signature(wolf, scene) != before
            setattr(group, key, old)
            assert changed == (key not in NOT_INPUTS), key
            checked.append(key)
    assert {"speed", "swing_start", "offset", "transition_time", "use_spine", "gait_mode"} <= set(checked)
    before = preview.settings_signature(wolf, scene)
    wolf.procloco.path = bpy.data.objects["Ground"]
    assert preview.settings_signature(wolf, scene) != before


def test_a_settings_change_regenerates_and_supersedes_the_last_preview(wolf: Any, clock: Clock) -> None:
    mine = user_action(wolf)
    mine_keys = snapshot()["action_keys"]["My Tail"]
    wolf.procloco.live_preview = True
    settle(clock)
    first = preview.preview_action(wolf)
    assert first is not None
    slow = travelled(wolf)
    assert slow > 0.5 * 0.8 * (FRAMES - 1) / 24.0  # it walks

    clock.now += 1.0
    wolf.procloco.speed = 1.6  # twice as fast: about twice as far
    settle(clock)
    fast = travelled(wolf)
    assert fast > 1.6 * slow
    assert len(procloco_actions()) == 1, [a.name for a in bpy.data.actions]  # the first one is gone
    assert preview.preview_action(wolf) is not None
    assert snapshot()["action_keys"]["My Tail"] == mine_keys  # never touched
    assert mine.users >= 1  # remembered by the rig for Clear Generated Action


def test_a_second_change_supersedes_the_first_in_flight(wolf: Any, clock: Clock,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    clock.now += 1.0
    wolf.procloco.speed = 1.2
    # Timer calls of a few milliseconds: three of them never finish the walk, however fast.
    monkeypatch.setattr(handler, "BUDGET_S", 0.002)
    for _ in range(3):  # the first change's regeneration starts at once and is under way
        handler.tick()
        clock.now += 0.01
    assert handler.status(wolf).state == "running"
    wolf.procloco.speed = 0.4  # a second change before the first is done
    handler.tick()
    assert handler._state.run is None  # cut short
    assert handler.status(wolf).state == "waiting"
    clock.now += 0.1
    handler.tick()
    assert handler._state.run is None  # still settling: 0.2 s after the last edit
    settle(clock)
    assert len(procloco_actions()) == 1
    shown = hips_track(wolf)
    # What Generate Locomotion makes of the final settings, on the same rig.
    wolf.procloco.live_preview = False
    settle(clock)  # kept
    bpy.ops.procloco.generate_locomotion()
    assert len(procloco_actions()) == 1  # Generate superseded the kept walk
    np.testing.assert_allclose(hips_track(wolf), shown, atol=1e-6)


def test_debounce_waits_for_edits_to_settle(wolf: Any, clock: Clock) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    clock.now += 1.0
    wolf.procloco.spacing = 1.1
    handler.tick()
    assert handler._state.run is not None  # after a quiet time: at once
    clock.now += 0.05
    wolf.procloco.spacing = 1.2
    handler.tick()
    assert handler._state.run is None  # cut short: waits until 0.2 s after this edit
    assert handler._state.watches[wolf.name].due == pytest.approx(clock.now + handler.DEBOUNCE_S)
    clock.now += handler.DEBOUNCE_S - 0.01
    handler.tick()
    assert handler._state.run is None
    clock.now += 0.02
    handler.tick()
    assert handler._state.run is not None


def test_the_current_frame_is_shown_before_the_rest_of_the_range(wolf: Any, clock: Clock,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    wolf.procloco.live_preview = True
    bpy.context.scene.frame_set(4)
    # one step a tick (a tick's time budget could hold the whole short regeneration)
    monkeypatch.setattr(handler, "BUDGET_S", 0.0)
    partial, _ = tick_until_partial(wolf, clock)
    assert partial is not None, "the current frame's pose was never written on its own"
    assert handler._state.run is not None  # the rest of the range is still to come
    early = pose_eval.pose_matrices(wolf, [4], [HIPS, *FEET])[0]
    settle(clock)
    assert not any(a.get(preview.PARTIAL_TAG) for a in bpy.data.actions)  # replaced by the whole walk
    assert len(procloco_actions()) == 1
    final = pose_eval.pose_matrices(wolf, [4], [HIPS, *FEET])[0]
    np.testing.assert_allclose(early[:, :3, 3], final[:, :3, 3], atol=1e-5)
    assert np.ptp(hips_track(wolf)[:, 1]) > 0.01  # and the whole range walks


def test_the_last_frame_is_shown_before_the_whole_range_is_written(wolf: Any, clock: Clock,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """On the range's last frame too the current pose comes first (one frame keyed), and the
    timer asks for no wait between its slices while the walk is under way."""
    wolf.procloco.live_preview = True
    bpy.context.scene.frame_set(FRAMES)
    monkeypatch.setattr(handler, "BUDGET_S", 0.0)  # one step a tick
    partial, waits = tick_until_partial(wolf, clock)
    assert partial is not None, "the last frame's pose was never written on its own"
    assert handler._state.run is not None  # the whole walk is still to come
    assert waits[-1] == 0.0  # (a run in flight is advanced at the next turn of the event loop)
    early = pose_eval.pose_matrices(wolf, [FRAMES], [HIPS, *FEET])[0]
    settle(clock)
    final = pose_eval.pose_matrices(wolf, [FRAMES], [HIPS, *FEET])[0]
    np.testing.assert_allclose(early[:, :3, 3], final[:, :3, 3], atol=1e-5)
    assert len(procloco_actions()) == 1


def keys_of(obj: Any) -> dict[Any, tuple[np.ndarray, np.ndarray]]:
    """The rig's Action, F-curve by F-curve: ``{channel: (frames, values)}``."""
    action = obj.animation_data.action
    return {channel: (frames, values) for channel, frames, values in actions.read_channels(action, obj)}


def assert_same_keys(got: dict[Any, Any], want: dict[Any, Any]) -> None:
    assert got.keys() == want.keys()
    for channel, (frames, values) in want.items():  # (the same code on the same inputs: exact)
        np.testing.assert_array_equal(got[channel][0], frames, err_msg=str(channel))
        np.testing.assert_array_equal(got[channel][1], values, err_msg=str(channel))


def test_an_edit_of_a_later_gait_change_simulates_only_from_there(
        wolf: Any, clock: Clock, monkeypatch: pytest.MonkeyPatch) -> None:
    """A regeneration on the same terrain starts from the last run's state at the last frame
    its inputs leave as they were, kept before the current frame, before each Gait Change
    and at the last frame (a Gait Change added at the current frame, then edited; the range
    made longer or shorter), and its walk is Generate's key for key; an edit of the speed
    simulates the whole range."""
    from procloco_addon.blender.locomotion import simulation
    from procloco_addon.core.locomotion.sim import Simulation

    monkeypatch.setattr(simulation, "CHECKPOINT_FRAMES", 1000)  # (no states kept on a regular beat)
    # (frames recorded before a step: its frame index is this)
    steps = spy(monkeypatch, Simulation, "step", lambda sim, *_: sim.n_frames)
    bpy.context.scene.frame_set(8)  # (frame index 7)
    wolf.procloco.live_preview = True
    settle(clock)
    assert steps == list(range(1, FRAMES))  # the first run: every frame
    before = keys_of(wolf)

    steps.clear()
    clock.now += 1.0
    assert bpy.ops.procloco.add_gait_change() == {"FINISHED"}  # at the current frame
    change = wolf.procloco.gait_changes[0]
    change.speed, change.transition_time = 0.6, 0.1
    settle(clock)
    assert steps == [7, 8, 9]  # from the state kept before the current frame
    clock.now += 1.0
    change.speed = 0.3  # (both speeds below the rig's: Auto's planning window, sized by the fastest, stays)
    settle(clock)
    assert steps == [7, 8, 9] * 2  # from the state kept before the Gait Change
    shown = keys_of(wolf)
    assert any(not np.array_equal(shown[c][1], before[c][1]) for c in before)  # it did change

    steps.clear()
    clock.now += 1.0
    wolf.procloco.frame_end = FRAMES + 2  # two frames more (no animated terrain: the same terrain)
    settle(clock)
    assert steps == [10, 11]  # from the state kept at the last frame
    clock.now += 1.0
    wolf.procloco.frame_end = FRAMES  # and back: nothing to simulate
    settle(clock)
    assert steps == [10, 11]
    assert_same_keys(keys_of(wolf), shown)

    steps.clear()
    clock.now += 1.0
    wolf.procloco.speed = 0.9  # from the first frame on
    settle(clock)
    assert steps == list(range(1, FRAMES))
    clock.now += 1.0
    wolf.procloco.speed = 0.8  # back: the last run's inputs differ from the first frame on too
    settle(clock)
    assert steps == list(range(1, FRAMES)) * 2
    assert_same_keys(keys_of(wolf), shown)

    wolf.procloco.live_preview = False
    settle(clock)  # kept
    bpy.ops.procloco.generate_locomotion()  # the same settings, simulated from the first frame
    assert_same_keys(keys_of(wolf), shown)


def test_a_terrain_object_moved_where_the_walk_never_looked_simulates_nothing_again(
        wolf: Any, clock: Clock, monkeypatch: pytest.MonkeyPatch) -> None:
    """A terrain object moved far from the walk (out of every planning window and point the
    simulation asked) leaves the whole walk as it was: nothing is simulated again. Moved
    under the walk's start, every frame is. Either way the walk is Generate's key for key."""
    from procloco_addon.core.locomotion.sim import Simulation

    steps = spy(monkeypatch, Simulation, "step", lambda sim, *_: sim.n_frames)
    bpy.ops.mesh.primitive_cube_add(size=0.2, location=(3.0, 3.0, 0.1))
    crate = bpy.context.active_object
    bpy.context.view_layer.objects.active = wolf
    wolf.procloco.live_preview = True
    settle(clock)
    assert steps == list(range(1, FRAMES))
    far = keys_of(wolf)

    steps.clear()
    clock.now += 1.0
    crate.location = (3.2, 2.5, 0.1)  # still far from the walk
    bpy.context.view_layer.update()  # (the depsgraph handler sees the move)
    settle(clock)
    assert steps == []
    assert preview.up_to_date(wolf, preview.input_signature(bpy.context, wolf)[0])  # (of the new terrain)
    assert_same_keys(keys_of(wolf), far)

    clock.now += 1.0
    crate.location = (0.0, 0.0, -0.05)  # under the wolf's start (a step of 5 cm)
    bpy.context.view_layer.update()
    settle(clock)
    assert steps == list(range(1, FRAMES))
    shown = keys_of(wolf)
    assert any(not np.array_equal(shown[c][1], far[c][1]) for c in far)

    wolf.procloco.live_preview = False
    settle(clock)
    bpy.ops.procloco.generate_locomotion()
    assert_same_keys(keys_of(wolf), shown)
    crate.location = (3.2, 2.5, 0.1)
    bpy.ops.procloco.generate_locomotion()
    assert_same_keys(keys_of(wolf), far)


def test_a_setting_edited_reuses_the_rig_read_and_a_painted_weight_is_read_again(
        wolf: Any, clock: Clock, monkeypatch: pytest.MonkeyPatch) -> None:
    from procloco_addon.blender.rig import read

    calls = spy(monkeypatch, read, "_read_rig", lambda obj, *_: obj.name)
    wolf.procloco.live_preview = True
    settle(clock)
    clock.now += 1.0
    wolf.procloco.speed = 1.1
    settle(clock)  # (read again: the bones the preview keys are now read at rest)
    assert calls == [wolf.name] * 2
    clock.now += 1.0
    wolf.procloco.speed = 1.2
    settle(clock)
    assert calls == [wolf.name] * 2  # a setting edited: the rig as read before
    assert travelled(wolf) > 0.5 * 1.2 * (FRAMES - 1) / 24.0
    skin = next(o for o in bpy.data.objects if o.type == "MESH" and o.name != "Ground")
    skin.vertex_groups["toe.L"].add([0], 0.2, "REPLACE")  # a weight painted
    bpy.context.view_layer.update()  # (the depsgraph handler sees the mesh edited)
    clock.now += 1.0
    wolf.procloco.speed = 1.0
    settle(clock)
    assert calls == [wolf.name] * 3


def test_moving_a_terrain_object_regenerates(wolf: Any, clock: Clock) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    low = pose_eval.pose_matrices(wolf, [FRAMES], list(FEET))[0, :, 2, 3]
    clock.now += 1.0
    bpy.data.objects["Ground"].location.z = 0.02
    bpy.context.view_layer.update()  # the depsgraph handler sees the move
    assert handler._state.watches[wolf.name].due == clock.now  # after a quiet time: at once
    handler.tick()
    assert handler._state.run is not None
    clock.now += 0.01
    bpy.data.objects["Ground"].location.z = 0.05  # a drag: the moves that follow wait for the last
    bpy.context.view_layer.update()
    assert handler._state.watches[wolf.name].hinted  # (seen when the run in flight is done)
    settle(clock)
    high = pose_eval.pose_matrices(wolf, [FRAMES], list(FEET))[0, :, 2, 3]
    np.testing.assert_allclose(high - low, 0.05, atol=0.01)  # the feet stand on the raised ground
    assert len(procloco_actions()) == 1
    clock.now += 1.0
    bpy.data.objects["Ground"].location.z = 0.06
    bpy.context.view_layer.update()
    assert handler._state.watches[wolf.name].due == clock.now
    clock.now += 0.05
    bpy.data.objects["Ground"].location.z = 0.07  # before the timer ran: waits for the drag to stop
    bpy.context.view_layer.update()
    assert handler._state.watches[wolf.name].due == pytest.approx(clock.now + handler.DEBOUNCE_S)
    settle(clock)


def test_editing_the_path_curve_and_dragging_a_gait_sector_regenerate(wolf: Any, clock: Clock) -> None:
    from procloco_addon.blender.gait import rig_gait

    curve = bpy.data.curves.new("Path", "CURVE")
    spline = curve.splines.new("POLY")
    spline.points.add(1)
    spline.points[0].co = (0.0, 0.0, 0.0, 1.0)
    spline.points[1].co = (0.3, -1.5, 0.0, 1.0)
    path = bpy.data.objects.new("Path", curve)
    bpy.context.scene.collection.objects.link(path)
    wolf.procloco.path = path
    wolf.procloco.gait_mode = "CIRCLES"  # (the viewport gait editor edits the circles, not Auto)
    wolf.procloco.live_preview = True
    settle(clock)
    track = hips_track(wolf)
    right = track[-1, 0] - track[0, 0]
    clock.now += 1.0
    spline.points[1].co = (-0.3, -1.5, 0.0, 1.0)  # the curve edited: its end to the other side
    bpy.context.view_layer.update()  # the depsgraph handler sees the curve change
    settle(clock)
    track = hips_track(wolf)
    left = track[-1, 0] - track[0, 0]
    assert right - left > 0.03, (right, left)  # the walk follows the edited curve
    feet = pose_eval.pose_matrices(wolf, [FRAMES], list(FEET))[0, :, :3, 3]
    clock.now += 1.0
    rig_gait.set_leg_sector(wolf, 0, 0.5, 0.3)  # what the viewport gait editor does while dragging
    settle(clock)
    moved = pose_eval.pose_matrices(wolf, [FRAMES], list(FEET))[0, :, :3, 3]
    assert np.max(np.linalg.norm(moved - feet, axis=1)) > 0.01
    assert len(procloco_actions()) == 1


def test_an_error_stops_the_preview_and_changes_nothing(wolf: Any, clock: Clock) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    shown = preview.preview_action(wolf)
    clock.now += 1.0
    wolf.procloco.step_height = 50.0  # more than a leg length: refused
    before = snapshot()
    settle(clock)
    assert handler.status(wolf).state == "error"
    assert "Step Height" in handler.status(wolf).text
    assert snapshot() == before
    assert preview.preview_action(wolf) == shown
    clock.now += 1.0
    assert settle(clock) <= 2  # stopped: no new attempt while nothing changes
    layout = draw_panel(_generate_panel())
    assert any("Step Height" in text for text in layout.labels())
    wolf.procloco.step_height = 0.1  # fixed: it runs again
    settle(clock)
    assert handler.status(wolf).state == "ready"
    assert preview.preview_action(wolf) != shown


def test_a_failure_after_the_current_frame_was_shown_gives_the_last_preview_back(
        wolf: Any, clock: Clock, monkeypatch: pytest.MonkeyPatch) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    bpy.context.scene.frame_set(3)
    clock.now += 1.0
    before = snapshot()
    real = generate.write_all_steps

    def failing(context: Any, jobs: Any) -> Any:
        if jobs[0].frames.size > 1:  # the whole walk, after the current frame was written
            raise generate.GenerateError("the disk is full")
        return (yield from real(context, jobs))

    monkeypatch.setattr(preview.generate, "write_all_steps", failing)
    wolf.procloco.speed = 1.3
    settle(clock)
    assert handler.status(wolf).state == "error"
    monkeypatch.setattr(preview.generate, "write_all_steps", real)
    wolf.procloco.speed = 0.8  # back as it was
    assert snapshot() == before


def test_a_failure_in_the_first_regeneration_leaves_an_earlier_walk_as_it_was(
        wolf: Any, clock: Clock, monkeypatch: pytest.MonkeyPatch) -> None:
    bpy.ops.procloco.generate_locomotion()
    bpy.context.scene.frame_set(2)
    wolf.procloco.live_preview = True
    before = snapshot()
    real = generate.write_all_steps

    def failing(context: Any, jobs: Any) -> Any:
        if jobs[0].frames.size > 1:
            raise RuntimeError("out of memory")
        return (yield from real(context, jobs))

    monkeypatch.setattr(preview.generate, "write_all_steps", failing)
    settle(clock)
    assert handler.status(wolf).state == "error"
    assert "out of memory" in handler.status(wolf).text
    assert snapshot() == before  # the earlier walk assigned, no fake user, no bookkeeping left
    assert not preview.is_previewing(wolf)


def test_switching_off_keeps_the_walk_and_discard_gives_back_the_users_action(wolf: Any,
                                                                              clock: Clock) -> None:
    mine = user_action(wolf)
    wolf.procloco.live_preview = True
    settle(clock)
    walked = hips_track(wolf)
    wolf.procloco.live_preview = False
    settle(clock)
    kept = actions.generated_action(wolf)
    assert kept is not None
    assert preview.PREVIEW_TAG not in kept
    assert not preview.is_previewing(wolf)
    np.testing.assert_allclose(hips_track(wolf), walked, atol=1e-9)
    assert bpy.ops.procloco.clear_generated_action() == {"FINISHED"}
    assert wolf.animation_data.action == mine

    wolf.procloco.live_preview = True
    settle(clock)
    assert preview.preview_action(wolf) is not None
    assert bpy.ops.procloco.discard_live_preview() == {"FINISHED"}
    assert not wolf.procloco.live_preview
    assert wolf.animation_data.action == mine
    assert procloco_actions() == []


def test_discard_gives_back_an_earlier_generated_walk(wolf: Any, clock: Clock) -> None:
    bpy.ops.procloco.generate_locomotion()
    earlier = actions.generated_action(wolf)
    name, track = earlier.name, hips_track(wolf)
    wolf.procloco.speed = 1.6
    wolf.procloco.live_preview = True
    settle(clock)
    assert earlier.name in bpy.data.actions  # kept alive while the preview runs
    assert travelled(wolf) > 1.6 * float(np.linalg.norm(track[-1, :2] - track[0, :2]))
    assert bpy.ops.procloco.discard_live_preview() == {"FINISHED"}
    assert wolf.animation_data.action == earlier
    assert earlier.name == name
    assert not earlier.use_fake_user
    assert procloco_actions() == [earlier]
    np.testing.assert_allclose(hips_track(wolf), track, atol=1e-9)
    # Switching off instead supersedes the earlier walk, as Generate Locomotion would.
    wolf.procloco.live_preview = True
    settle(clock)
    wolf.procloco.live_preview = False
    settle(clock)
    assert procloco_actions() == [actions.generated_action(wolf)]
    assert actions.generated_action(wolf).name == name


def test_the_toggle_is_saved_and_a_reloaded_preview_is_not_made_again(wolf: Any, clock: Clock,
                                                                       tmp_path: Any) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    shown = preview.preview_action(wolf).name
    path = str(tmp_path / "live.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    obj = bpy.data.objects["Wolf"]
    assert obj.procloco.live_preview
    assert handler._on_load_post in bpy.app.handlers.load_post
    clock.now += 1.0
    settle(clock)
    assert preview.preview_action(obj).name == shown  # up to date: not made again
    obj.procloco.seed = 3
    settle(clock)
    assert preview.preview_action(obj) is not None
    assert len(procloco_actions()) == 1


def test_unregister_removes_the_timer_and_handlers(wolf: Any, clock: Clock,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    import procloco_addon

    wolf.procloco.live_preview = True
    handler.wake()
    assert bpy.app.timers.is_registered(handler.tick)
    monkeypatch.setattr(handler, "BUDGET_S", 0.002)  # (three calls never finish the walk)
    for _ in range(3):
        handler.tick()
    assert handler._state.run is not None
    procloco_addon.unregister()
    try:
        assert not bpy.app.timers.is_registered(handler.tick)
        ours = [h for name in ("depsgraph_update_post", "load_pre", "load_post", "undo_pre", "undo_post")
                for h in getattr(bpy.app.handlers, name) if getattr(h, "__module__", "") == handler.__name__]
        assert ours == []
        assert handler._state.run is None
        # the half-done one taken back
        assert [a for a in bpy.data.actions if a.get(preview.PREVIEW_TAG)] == []
    finally:
        procloco_addon.register()
    assert handler._on_depsgraph_update in bpy.app.handlers.depsgraph_update_post


def _generate_panel() -> type:
    from procloco_addon.blender.ui.main import PROCLOCO_PT_generate

    return PROCLOCO_PT_generate


def test_generate_clicked_during_a_preview_becomes_its_new_base(wolf: Any, clock: Clock) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    bpy.ops.procloco.generate_locomotion()  # supersedes the preview Action, as any earlier walk
    clicked = actions.generated_action(wolf)
    assert preview.preview_action(wolf) is None
    settle(clock)
    assert handler.status(wolf).state == "idle"
    assert any("not a preview" in text for text in draw_panel(_generate_panel()).labels())
    clock.now += 1.0
    wolf.procloco.speed = 1.2
    settle(clock)
    assert preview.preview_action(wolf) is not None
    assert clicked.name in bpy.data.actions  # kept for Discard Preview
    wolf.procloco.live_preview = False
    settle(clock)
    assert procloco_actions() == [actions.generated_action(wolf)]  # kept: the clicked walk superseded


def test_a_file_saved_in_the_middle_of_a_regeneration_leaves_no_preview_behind(
        wolf: Any, clock: Clock, tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    wolf.procloco.live_preview = True
    settle(clock)
    bpy.context.scene.frame_set(3)
    clock.now += 1.0
    wolf.procloco.speed = 1.2
    # one step a tick (a tick's time budget could hold the whole short regeneration)
    monkeypatch.setattr(handler, "BUDGET_S", 0.0)
    for _ in range(500):  # until the current frame's pose is shown, the rest still to come
        handler.tick()
        clock.now += 0.01
        if wolf.animation_data.action.get(preview.PARTIAL_TAG):
            break
    # the last whole walk is kept meanwhile, by a fake user
    assert len([a for a in bpy.data.actions if a.get(preview.PREVIEW_TAG)]) == 2
    path = str(tmp_path / "midway.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    obj = bpy.data.objects["Wolf"]
    settle(clock)
    assert [a for a in bpy.data.actions if a.get(preview.PREVIEW_TAG)] == [obj.animation_data.action]
    assert preview.up_to_date(obj, preview.input_signature(bpy.context, obj)[0])
