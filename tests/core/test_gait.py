# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait circles, presets, transitions with the forbidden-zone rule, the gait manager."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core.locomotion import gait as gaits
from procloco_addon.core.locomotion.gait import Gait, GaitError, GaitManager, GaitPresetError

REQUIRED_PRESETS = {
    "biped_walk",
    "biped_run",
    "quadruped_walk",
    "quadruped_trot",
    "quadruped_pace",
    "quadruped_canter",
    "quadruped_transverse_gallop",
    "quadruped_rotary_gallop",
    "quadruped_bound",
    "hexapod_tripod",
    "hexapod_tetrapod",
    "hexapod_wave",
    "octopod_alternating_tetrapod",
    "octopod_wave",
    "pentapod_robot",
}


def _max_in_swing(g: Gait) -> int:
    phases = np.linspace(0.0, 1.0, 2001, endpoint=False)
    return int(g.in_swing(phases).sum(axis=1).max())


def test_every_required_preset_ships_and_loads() -> None:
    stems = {p.stem for p in gaits.list_gait_presets()}
    assert stems >= REQUIRED_PRESETS
    for path in gaits.list_gait_presets():
        preset = gaits.load_gait_preset(path)
        assert len(preset.source) > 20, f"{path.name} must name its source"
        assert preset.gait().n_legs == len(preset.legs)
        # strides fit the legs: the stance sweep at the preset speed stays under a leg length
        stroke = preset.speed * preset.cycle_time * (1.0 - preset.swing_duration)
        assert np.all(stroke <= 0.95), path.name


def test_presets_have_their_named_patterns() -> None:
    def load(stem: str) -> gaits.GaitPreset:
        return gaits.load_gait_preset(gaits.gait_preset_dir() / f"{stem}.json")

    trot = load("quadruped_trot").gait(["L1", "R1", "L2", "R2"])
    assert trot.swing_start[0] == trot.swing_start[3]
    assert trot.swing_start[1] == trot.swing_start[2]
    pace = load("quadruped_pace").gait(["L1", "L2", "R1", "R2"])
    assert pace.swing_start[0] == pace.swing_start[1]
    assert pace.swing_start[2] == pace.swing_start[3]
    tripod = load("hexapod_tripod").gait(["L1", "R2", "L3", "R1", "L2", "R3"])
    assert len(set(tripod.swing_start[:3])) == 1
    assert len(set(tripod.swing_start[3:])) == 1
    assert _max_in_swing(load("hexapod_wave").gait()) == 1
    assert _max_in_swing(load("octopod_wave").gait()) == 2
    assert _max_in_swing(load("pentapod_robot").gait()) <= 2
    gallop = load("quadruped_transverse_gallop").gait()
    assert _max_in_swing(gallop) == 4  # a suspension phase
    assert _max_in_swing(load("quadruped_walk").gait()) == 2


def test_preset_gait_follows_the_characters_labels() -> None:
    preset = gaits.find_gait_preset("quadruped_walk")
    g = preset.gait(["R2", "L2", "R1", "L1"])
    np.testing.assert_allclose(g.swing_start, preset.swing_start[[3, 2, 1, 0]])
    with pytest.raises(GaitError, match="L1, R1, L2, R2"):
        preset.gait(["L1", "R1", "L2", "X2"])
    with pytest.raises(GaitError):
        preset.gait(["L1", "R1"])
    assert gaits.find_gait_preset("Quadruped walk").name == "Quadruped walk"
    with pytest.raises(GaitPresetError, match="no gait preset"):
        gaits.find_gait_preset("moonwalk")


def _good() -> dict[str, object]:
    return json.loads((gaits.gait_preset_dir() / "quadruped_trot.json").read_text())


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"format": "procloco.gait/0"}, "'format' must be"),
        ({"swing_duration": [0.35, 0.0, 0.35, 0.35]}, "leg R1.*zero or full-cycle"),
        ({"swing_duration": [0.35, 0.35, 1.0, 0.35]}, "leg L2.*zero or full-cycle"),
        ({"swing_start": [0.0, 1.0, 0.5, 0.0]}, r"\[0, 1\)"),
        ({"swing_start": [0.0, 0.5]}, "list of 4 numbers"),
        ({"swing_start": [0.0, "a", 0.5, 0.0]}, "list of 4 numbers"),
        ({"legs": ["L1", "R1", "L2", "Left"]}, "look like L1"),
        ({"legs": ["L1", "R1", "L1", "R2"]}, "not unique"),
        ({"cycle_time": 0}, "'cycle_time' must be > 0"),
        ({"speed": -1.0}, "'speed' must be >= 0"),
        ({"source": ""}, "'source' must be a non-empty string"),
        ({"cycle_time": True}, "'cycle_time' must be a number"),
    ],
)
def test_malformed_presets_are_refused_clearly(
    tmp_path: Path, change: dict[str, object], message: str
) -> None:
    data = _good()
    data.update(change)
    path = tmp_path / "broken.json"
    path.write_text(json.dumps(data))
    with pytest.raises(GaitPresetError, match=r"broken\.json: .*" + message):
        gaits.load_gait_preset(path)


def test_missing_fields_unreadable_and_non_json_files(tmp_path: Path) -> None:
    data = _good()
    del data["step_height"]
    (tmp_path / "a.json").write_text(json.dumps(data))
    with pytest.raises(GaitPresetError, match=r"missing field.*step_height"):
        gaits.load_gait_preset(tmp_path / "a.json")
    (tmp_path / "b.json").write_text("{not json")
    with pytest.raises(GaitPresetError, match="not valid JSON"):
        gaits.load_gait_preset(tmp_path / "b.json")
    with pytest.raises(GaitPresetError, match="cannot be read"):
        gaits.load_gait_preset(tmp_path / "missing.json")
    (tmp_path / "c.json").write_text("[1, 2]")
    with pytest.raises(GaitPresetError, match="one JSON object"):
        gaits.load_gait_preset(tmp_path / "c.json")


def test_preset_round_trips_through_json(tmp_path: Path) -> None:
    preset = gaits.find_gait_preset("hexapod_tetrapod")
    path = tmp_path / "copy.json"
    path.write_text(json.dumps(preset.to_json()))
    again = gaits.load_gait_preset(path)
    np.testing.assert_allclose(again.swing_start, preset.swing_start)
    assert again.legs == preset.legs
    assert again.source == preset.source


def test_a_preset_file_is_read_again_once_it_changes(tmp_path: Path) -> None:
    """An unchanged file is read once (the same preset, its arrays read-only so nobody can
    change the kept copy); an edited one is read again, a broken one refused again; a folder
    is listed again once a file is added."""
    import os

    path = tmp_path / "mine.json"
    data = gaits.find_gait_preset("hexapod_tetrapod").to_json()
    path.write_text(json.dumps(data))
    first = gaits.load_gait_preset(path)
    assert gaits.load_gait_preset(path) is first
    with pytest.raises(ValueError, match="read-only"):
        first.swing_start[0] = 0.5
    data["cycle_time"] = 2.5
    path.write_text(json.dumps(data))
    os.utime(path, ns=(1, 1))  # another modification time, as an edit gives it
    again = gaits.load_gait_preset(path)
    assert again.cycle_time == 2.5
    assert first.cycle_time != 2.5
    path.write_text("{")
    with pytest.raises(GaitPresetError, match="not valid JSON"):
        gaits.load_gait_preset(path)
    # The folder's files are listed again once one is added.
    assert gaits.list_gait_presets(tmp_path) == [path]
    (tmp_path / "another.json").write_text(json.dumps(data))
    os.utime(tmp_path, ns=(2, 2))  # (a folder's time, as adding a file sets it)
    assert gaits.list_gait_presets(tmp_path) == [tmp_path / "another.json", path]


def test_gait_refuses_zero_and_full_swings() -> None:
    with pytest.raises(GaitError, match="strictly between 0 and 1"):
        Gait(np.array([0.0, 0.5]), np.array([0.4, 1.0]), 1.0)
    with pytest.raises(GaitError, match="cycle time"):
        Gait(np.array([0.0]), np.array([0.4]), 0.0)


def test_transition_direction_follows_figure_3_11() -> None:
    # overlapping sectors: the start moves forward inside the union
    assert gaits.transition_direction(0.0, 0.3, 0.3) == 1.0
    # going forward from 0.5 to 0.2 would cross the destination's finish (0.6): backward
    assert gaits.transition_direction(0.5, 0.2, 0.4) == -1.0
    # disjoint sectors, finish not on the forward arc: forward
    assert gaits.transition_direction(0.0, 0.5, 0.2) == 1.0


@given(st.floats(0.0, 0.999), st.floats(0.0, 0.999), st.floats(0.05, 0.95), st.floats(0.05, 0.95))
def test_interpolated_start_never_crosses_the_destination_finish(
    src: float, dst: float, src_dur: float, dst_dur: float
) -> None:
    direction = gaits.transition_direction(np.array([src]), np.array([dst]), np.array([dst_dur]))
    lam = np.linspace(0.0, 1.0, 201)
    start, duration = gaits.interpolate_disks(
        np.full(201, src),
        np.full(201, src_dur),
        np.full(201, dst),
        np.full(201, dst_dur),
        np.full(201, direction[0]),
        lam,
    )
    assert start[0] == pytest.approx(src % 1.0)
    assert start[-1] == pytest.approx(dst, abs=1e-9)
    np.testing.assert_allclose(duration, src_dur + lam * (dst_dur - src_dur))
    # the start moves monotonically along one direction by less than a full turn
    steps = np.mod(np.diff(start) * direction[0] + 0.5, 1.0) - 0.5
    assert np.all(steps >= -1e-12)
    travelled = steps.sum()
    assert travelled < 1.0
    # the swept arc does not contain the destination's finish (unless it cannot be avoided
    # because it lies on both arcs, which only happens when it equals the source start)
    finish = (dst + dst_dur) % 1.0
    swept = np.mod((finish - src) * direction[0], 1.0)
    assert not (1e-9 < swept < travelled - 1e-9)


def _run(manager: GaitManager, steps: int, dt: float) -> list[gaits.GaitStep]:
    return [manager.advance(dt) for _ in range(steps)]


def test_needle_lifts_and_lands_on_the_sector_edges() -> None:
    g = Gait(np.array([0.1, 0.6]), np.array([0.3, 0.45]), cycle_time=1.0)
    dt = 1.0 / 50.0
    mgr = GaitManager(np.zeros(2, dtype=np.int64), [g])
    needles, lifts, lands = [], [], []
    for _ in range(150):
        step = mgr.advance(dt)
        needles.append(mgr.needle[0])
        lifts.append(step.lifted)
        lands.append(step.landed)
    needles_a = np.array(needles)
    for leg in range(2):
        lift_phase = needles_a[np.array(lifts)[:, leg]]
        land_phase = needles_a[np.array(lands)[:, leg]]
        assert lift_phase.size == 3
        assert land_phase.size == 3
        assert np.all(np.mod(lift_phase - g.swing_start[leg], 1.0) < dt + 1e-9)
        finish = g.swing_start[leg] + g.swing_duration[leg]
        assert np.all(np.mod(land_phase - finish, 1.0) < dt + 1e-9)


def test_rate_scale_speeds_the_needle_up() -> None:
    g = Gait(np.array([0.0]), np.array([0.5]), cycle_time=1.0)
    mgr = GaitManager(np.zeros(1, dtype=np.int64), [g])
    mgr.advance(0.1, rate_scale=2.0)
    assert mgr.needle[0] == pytest.approx(0.2)


def _transition_run(
    src: Gait, dst: Gait, transition_time: float, dt: float = 1.0 / 60.0, seconds: float = 6.0
) -> tuple[GaitManager, list[gaits.GaitStep], list[np.ndarray]]:
    n = src.n_legs
    mgr = GaitManager(np.zeros(n, dtype=np.int64), [src])
    steps: list[gaits.GaitStep] = []
    needles: list[np.ndarray] = []
    for k in range(int(seconds / dt)):
        if k == int(1.0 / dt):
            mgr.start_transition([0], [dst], transition_time)
        steps.append(mgr.advance(dt))
        needles.append(mgr.needle.copy())
    return mgr, steps, needles


@pytest.mark.parametrize("transition_time", [0.0, 1.5])
def test_transition_walk_to_gallop_swaps_only_in_stance_and_never_pops(transition_time: float) -> None:
    labels = ["L1", "R1", "L2", "R2"]
    walk = gaits.find_gait_preset("quadruped_walk").gait(labels).with_cycle_time(0.8)
    gallop = gaits.find_gait_preset("quadruped_rotary_gallop").gait(labels).with_cycle_time(0.8)
    dt = 1.0 / 60.0
    mgr, steps, _ = _transition_run(walk, gallop, transition_time, dt)
    swing = np.array([s.swing for s in steps])
    swapped = np.array([s.swapped for s in steps])
    prev_swing = np.vstack([walk.in_swing(0.0)[None, :], swing[:-1]])
    assert swapped.any()
    assert not np.any(swapped & prev_swing), "a disk was swapped during a swing"
    # every complete swing lasts at least the shorter of the two durations (minus a frame)
    shortest = min(walk.swing_duration.min(), gallop.swing_duration.min()) * 0.8
    for leg in range(4):
        col = swing[:, leg].astype(int)
        edges = np.diff(col)
        ups = np.flatnonzero(edges == 1)
        downs = np.flatnonzero(edges == -1)
        for u in ups:
            later = downs[downs > u]
            if later.size:
                assert (later[0] - u) * dt >= shortest - dt - 1e-9
    # after the transition time plus one cycle, every leg holds the gallop's disk
    np.testing.assert_allclose(mgr.disk_start, gallop.swing_start)
    np.testing.assert_allclose(mgr.disk_duration, gallop.swing_duration)
    assert not mgr.tr_active[0]


def test_transition_interpolates_cycle_time_and_restarts_from_the_current_disks() -> None:
    a = Gait(np.array([0.0, 0.5]), np.array([0.4, 0.4]), 1.0)
    b = Gait(np.array([0.2, 0.7]), np.array([0.3, 0.3]), 0.5)
    c = Gait(np.array([0.0, 0.5]), np.array([0.5, 0.5]), 0.8)
    mgr = GaitManager(np.zeros(2, dtype=np.int64), [a])
    mgr.start_transition([0], [b], 1.0)
    for _ in range(50):
        mgr.advance(0.01)
    start, duration, cycle = mgr.target_disks()
    np.testing.assert_allclose(cycle, [0.75])
    np.testing.assert_allclose(duration, [0.35, 0.35])
    np.testing.assert_allclose(start, [0.1, 0.6])
    mgr.start_transition([0], [c], 1.0)
    np.testing.assert_allclose(mgr.src_start, [0.1, 0.6])
    np.testing.assert_allclose(mgr.src_cycle, [0.75])


def test_manager_checks_leg_counts() -> None:
    with pytest.raises(GaitError, match="has 2 legs, the character 3"):
        GaitManager(np.zeros(3, dtype=np.int64), [Gait(np.array([0.0, 0.5]), np.array([0.4, 0.4]), 1.0)])
