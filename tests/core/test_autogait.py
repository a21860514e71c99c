# SPDX-License-Identifier: GPL-3.0-or-later
"""Auto gait: Froude bands, stride, duty factor, hysteresis, and the gait manager it drives."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from procloco_addon.core.locomotion import autogait as ag
from procloco_addon.core.locomotion.gait import GaitError, GaitManager, find_gait_preset

QUAD = ("L1", "R1", "L2", "R2")
HEX = ("L1", "R1", "L2", "R2", "L3", "R3")
OCT = ("L1", "R1", "L2", "R2", "L3", "R3", "L4", "R4")
BIPED = ("L1", "R1")


def _params(labels: tuple[str, ...], size: float = 1.0, **kw: float) -> ag.AutoGaitParams:
    p = ag.auto_gait_params(labels, size, size, **kw)  # type: ignore[arg-type]
    assert p is not None
    return p


def _speed_at(p: ag.AutoGaitParams, fr: float) -> float:
    return float(np.sqrt(fr * p.g * p.size))


def test_froude_and_alexanders_stride() -> None:
    assert ag.froude(3.0, 1.0, 9.0) == pytest.approx(1.0)
    # Alexander (1976): lambda / h = 2.3 Fr^0.3
    assert ag.relative_stride(1.0) == pytest.approx(2.3)
    assert ag.relative_stride(0.5) == pytest.approx(2.3 * 0.5 ** 0.3)
    p = _params(QUAD, 1.2)
    v = _speed_at(p, 1.0)
    gait = p.gait(1, v)
    assert v * gait.cycle_time == pytest.approx(2.3 * 1.2)  # stride = speed x cycle


def test_each_family_uses_the_gaits_of_its_sources() -> None:
    assert _params(QUAD).names == ("walk", "trot", "gallop")
    assert list(_params(QUAD).family.boundaries()) == [0.5, 2.5]  # Alexander & Jayes 1983
    assert _params(BIPED).names == ("walk", "run")
    assert list(_params(BIPED).family.boundaries()) == [0.5]
    assert _params(HEX).names == ("wave", "tetrapod", "tripod")  # Wilson 1966
    assert _params(OCT).names == ("wave", "alternating tetrapod")  # Wilson 1967
    assert ag.auto_gait_params(("L1", "R1", "L2"), 1.0, 1.0) is None
    trot = find_gait_preset("quadruped_trot").gait(QUAD)
    assert np.allclose(_params(QUAD).patterns[1], trot.swing_start)


@pytest.mark.parametrize("labels", [BIPED, QUAD, HEX, OCT])
def test_duty_factor_falls_and_bands_rise_with_speed(labels: tuple[str, ...]) -> None:
    p = _params(labels, 0.7)
    speeds = np.linspace(0.0, _speed_at(p, 6.0), 400)
    bands, duty, cycle = p.schedule(speeds)
    assert np.all(np.diff(bands) >= 0)
    assert bands[0] == 0
    assert bands[-1] == len(p.names) - 1
    assert np.all(np.diff(duty) <= 1e-12)
    assert np.all((duty >= ag.DUTY_MIN) & (duty <= ag.DUTY_MAX))
    assert np.all(np.isfinite(cycle))
    assert np.all(cycle > 0.0)
    # the stride (speed x cycle) grows with speed
    stride = speeds * cycle
    assert np.all(np.diff(stride) >= -1e-12)


def test_many_legs_keep_the_swing_and_shorten_the_stance() -> None:
    p = _params(HEX, 0.5)
    speeds = np.linspace(_speed_at(p, 0.02), _speed_at(p, 0.4), 50)
    _, duty, cycle = p.schedule(speeds)
    swing = (1.0 - duty) * cycle
    stance = duty * cycle
    assert np.allclose(swing, ag.SWING_TIME * np.sqrt(0.5 / ag.G))  # Wilson 1966
    assert np.all(np.diff(stance) < 0.0)


def test_dynamic_similarity_transitions_at_sqrt_size_times_the_speed() -> None:
    small, big = _params(QUAD, 0.5), _params(QUAD, 5.0)
    speeds = np.linspace(0.0, _speed_at(small, 5.0), 300)
    b_small, d_small, c_small = small.schedule(speeds)
    b_big, d_big, c_big = big.schedule(np.sqrt(10.0) * speeds)
    assert np.array_equal(b_small, b_big)
    assert np.allclose(d_small, d_big)
    assert np.allclose(c_big, np.sqrt(10.0) * c_small)


def test_speed_scale_moves_the_boundaries() -> None:
    plain, slow = _params(QUAD, 1.0), _params(QUAD, 1.0, speed_scale=1.5)
    speeds = np.linspace(0.0, _speed_at(plain, 6.0), 600)
    first_trot = speeds[np.argmax(plain.schedule(speeds)[0] == 1)]
    first_trot_scaled = speeds[np.argmax(slow.schedule(speeds)[0] == 1)]
    assert first_trot_scaled == pytest.approx(1.5 * first_trot, rel=0.02)
    with pytest.raises(GaitError, match="speed scale"):
        _params(QUAD, 1.0, speed_scale=0.0)


def test_hysteresis_a_speed_hovering_at_a_boundary_flips_at_most_once() -> None:
    p = _params(QUAD, 1.0)
    boundary = _speed_at(p, 0.5)
    t = np.linspace(0.0, 20.0, 2000)
    hover = boundary * (1.0 + 0.08 * np.sin(2.0 * np.pi * t))  # Fr within ±17 % of 0.5
    bands = p.schedule(hover)[0]
    assert np.count_nonzero(np.diff(bands)) <= 1
    # a speed that really goes back and forth changes gait each time
    swings = boundary * (1.0 + 0.4 * np.sin(2.0 * np.pi * t / 5.0))
    assert np.count_nonzero(np.diff(p.schedule(swings)[0])) >= 6


@given(st.lists(st.floats(-50.0, 50.0, allow_nan=False), min_size=1, max_size=40),
       st.floats(1e-3, 100.0), st.floats(0.3, 3.0), st.sampled_from([BIPED, QUAD, HEX, OCT]))
def test_no_nan_for_any_speed_and_size(speeds: list[float], size: float, scale: float,
                                       labels: tuple[str, ...]) -> None:
    p = _params(labels, size, speed_scale=scale)
    bands, duty, cycle = p.schedule(np.abs(speeds))
    assert np.all(np.isfinite(duty))
    assert np.all(np.isfinite(cycle))
    assert np.all(cycle > 0.0)
    for b, v in zip(bands, speeds, strict=True):
        g = p.gait(int(b), abs(v))
        assert np.all((g.swing_duration > 0.0) & (g.swing_duration < 1.0))


@given(st.floats(0.0, 20.0), st.floats(0.0, 20.0), st.floats(0.05, 10.0))
def test_bands_are_monotone_in_speed(v1: float, v2: float, size: float) -> None:
    p = _params(QUAD, size)
    lo, hi = sorted((v1, v2))
    assert ag.band_of(p.family, p.froude(lo)) <= ag.band_of(p.family, p.froude(hi))


def test_the_driver_walks_trots_gallops_swapping_disks_only_in_stance() -> None:
    p = _params(QUAD, 1.0)
    driver = ag.AutoGait([p], [_speed_at(p, 0.05)])
    manager = GaitManager(np.zeros(4, dtype=np.int64), driver.gaits([]))
    dt = 1.0 / 30.0
    top = _speed_at(p, 4.0)
    bands, swapped_in_swing = [], 0
    for k in range(600):
        v = _speed_at(p, 0.05) + (top - _speed_at(p, 0.05)) * min(k / 450.0, 1.0)
        driver.update(manager, [v])
        was_swing = manager.swing.copy()
        step = manager.advance(dt)
        swapped_in_swing += int(np.count_nonzero(step.swapped & was_swing))
        bands.append(int(driver.band[0]))
    assert swapped_in_swing == 0
    assert bands[0] == 0
    assert bands[-1] == 2
    assert int(driver.n_changes[0]) == 2
    final = p.gait(2, top)
    assert manager.cycle_time[0] == pytest.approx(final.cycle_time)
    assert np.allclose(manager.disk_start, final.swing_start)
    assert np.allclose(manager.disk_duration, final.swing_duration)


def test_a_steady_speed_retargets_to_the_same_gait_as_a_fresh_driver() -> None:
    p = _params(QUAD, 1.0)
    v = _speed_at(p, 0.3)
    driver = ag.AutoGait([p], [v])
    manager = GaitManager(np.zeros(4, dtype=np.int64), driver.gaits([]))
    for _ in range(5):  # the same speed again and again (the gait is reused)
        driver.update(manager, [v])
        manager.advance(1.0 / 30.0)
    want = p.gait(int(driver.band[0]), v)
    np.testing.assert_array_equal(manager.dst_start, want.swing_start)
    np.testing.assert_array_equal(manager.dst_duration, want.swing_duration)
    assert manager.dst_cycle[0] == want.cycle_time
    driver.update(manager, [1.2 * v])  # a new speed: a new gait
    assert manager.dst_cycle[0] == p.gait(int(driver.band[0]), 1.2 * v).cycle_time


def test_per_band_overrides_from_presets() -> None:
    pace = find_gait_preset("quadruped_pace")
    p = ag.auto_gait_params(QUAD, 1.0, 1.0, overrides={"trot": pace})
    assert p is not None
    assert p.names == ("walk", "Quadruped pace", "gallop")
    assert np.allclose(p.patterns[1], pace.gait(QUAD).swing_start)
    with pytest.raises(GaitError):
        ag.auto_gait_params(QUAD, 1.0, 1.0, overrides={"trot": find_gait_preset("hexapod_tripod")})


def test_retarget_changes_the_destination_without_a_new_transition() -> None:
    p = _params(QUAD, 1.0)
    walk = p.gait(0, _speed_at(p, 0.1))
    manager = GaitManager(np.zeros(4, dtype=np.int64), [walk])
    faster = p.gait(0, _speed_at(p, 0.3))
    manager.retarget(0, faster)
    assert manager.cycle_time[0] == pytest.approx(faster.cycle_time)
    assert not manager.tr_active[0]
    for _ in range(200):
        manager.advance(1.0 / 30.0)
    assert np.allclose(manager.disk_duration, faster.swing_duration)
    with pytest.raises(GaitError):
        manager.retarget(0, _params(HEX).gait(0, 0.1))


# ---------------------------------------------------------------------------- in the system loop
def quadruped_pairs(lifted: np.ndarray, labels: Sequence[str], window: int) -> dict[str, np.ndarray]:
    """How often the feet of each kind of pair of a quadruped are in the same state (both up
    or both down) around each frame of ``lifted (F, 4)`` (feet in the air; sliding
    ``window`` frames): ``(F,)`` per kind, the mean over its two pairs."""
    i = {lb: list(labels).index(lb) for lb in QUAD}
    kernel = np.ones(window) / window

    def same(a: str, b: str) -> np.ndarray:
        return np.convolve((lifted[:, i[a]] == lifted[:, i[b]]).astype(float), kernel, mode="same")

    return {
        "diagonal": 0.5 * (same("L1", "R2") + same("R1", "L2")),
        "lateral": 0.5 * (same("L1", "L2") + same("R1", "R2")),
        "girdle": 0.5 * (same("L1", "R1") + same("L2", "R2")),
    }


def quadruped_phases(lifted: np.ndarray, labels: Sequence[str], window: int) -> np.ndarray:
    """``(F,)`` the gait read off the footfalls around each frame: 0 walk (no kind of pair
    moves together), 1 trot (diagonal feet together), 2 gallop (the fore feet nearly
    together and the hind feet nearly together); -1 undecided (in a transition)."""
    pairs = quadruped_pairs(lifted, labels, window)
    diag, girdle, lateral = pairs["diagonal"], pairs["girdle"], pairs["lateral"]
    out = np.full(lifted.shape[0], -1)
    out[np.maximum(np.maximum(diag, girdle), lateral) < 0.65] = 0
    out[(diag > 0.85) & (diag > girdle + 0.3)] = 1
    out[(girdle > 0.7) & (girdle > diag + 0.25)] = 2
    return out


def stable_runs(phases: np.ndarray, min_run: int) -> list[int]:
    """The read gaits that hold for at least ``min_run`` frames in a row, in order (runs of
    the same gait merged): the gait sequence without its transitions."""
    out: list[int] = []
    start = 0
    for k in range(1, phases.size + 1):
        if k == phases.size or phases[k] != phases[start]:
            if k - start >= min_run and phases[start] >= 0 and (not out or out[-1] != phases[start]):
                out.append(int(phases[start]))
            start = k
    return out


def first_frame(phases: np.ndarray, value: int) -> int:
    """First frame whose read gait is ``value`` (-1 if none)."""
    hits = np.flatnonzero(phases == value)
    return int(hits[0]) if hits.size else -1


def test_a_quadruped_ramping_up_walks_trots_then_gallops_near_the_stated_froude_numbers() -> None:
    from procloco_addon.core.locomotion import morphology as morph
    from procloco_addon.core.locomotion.sim import Controls, Simulation, check_motion
    from tests.core.test_sim import flat

    m = morph.quadruped(3.0)
    h = ag.rest_hip_height(m.rest_joints, m.n_segments)
    p = ag.auto_gait_params(m.labels, h, float(m.leg_length.mean()))
    assert p is not None
    dt, n = 1.0 / 30.0, 240
    v0, v1 = np.sqrt(0.05 * ag.G * h), np.sqrt(4.5 * ag.G * h)

    def speed(t: float) -> float:
        return float(v0 + (v1 - v0) * min(t / (n * dt * 0.7), 1.0))

    env = flat(300.0)
    sim = Simulation(env, [m], find_gait_preset("quadruped_walk").gait(m.labels),
                     controls=lambda t: Controls(speed=speed(t), heading=0.0, step_height=0.05 * 3.0),
                     auto_gait=[p], dt=dt)
    res = sim.run(n)
    phases = quadruped_phases(~res.contact, m.labels, window=12)[6:-6]  # the window fits
    fr = p.froude([speed(t) for t in res.time])[6:-6]
    trot, gallop = first_frame(phases, 1), first_frame(phases, 2)
    assert np.all(phases[:20] == 0)  # a walk at first
    assert 0 < trot < gallop
    assert 0.5 <= fr[trot] <= 1.1  # walk -> trot at Fr 0.5 (+ hysteresis and a transition)
    assert 2.5 <= fr[gallop] <= 4.0  # trot -> gallop at Fr 2.5
    assert stable_runs(phases, 10) == [0, 1, 2]
    assert np.all(phases[-20:] == 2)
    assert int(sim.auto_gait.n_changes[0]) == 2
    report = check_motion(res, env)
    assert report.passed, report.failures()


def test_a_short_stroke_shortens_the_stance_and_keeps_the_swing_time() -> None:
    # Legs that allow a third of the model's stance sweep (a beetle's, crowded along its
    # body): up to the top speed the sweep stays within STROKE_SHARE of it and the swing
    # keeps its time; the faster gaits come at lower speeds, as at a speed 1 / stroke_scale.
    free = _params(HEX, 0.4)
    model = ag.SWING_TIME / ag.DUTY_K * 0.4
    crowded = _params(HEX, 0.4, stroke=model / 3.0)
    assert free.stroke_scale == 1.0
    assert crowded.stroke_scale == pytest.approx(ag.STROKE_SHARE / 3.0)
    swing = ag.SWING_TIME * np.sqrt(0.4 / ag.G)
    top = crowded.top_speed()
    assert top == pytest.approx(crowded.stroke_scale * free.top_speed())
    for v in np.linspace(0.05, 1.0, 12) * top:
        band, duty, cycle = (float(x[0]) for x in crowded.schedule([v]))
        assert v * duty * cycle <= ag.STROKE_SHARE * model / 3.0 + 1e-12  # the stance sweep
        assert (1.0 - duty) * cycle == pytest.approx(swing)  # the swing time
        assert band == float(free.schedule([v / crowded.stroke_scale])[0][0])
    # the model's own sweep is kept where the legs allow more, and mammals keep their stride
    assert _params(HEX, 0.4, stroke=2.0 * model).stroke_scale == 1.0
    assert _params(QUAD, 0.4, stroke=0.01).band_scale == 1.0
    assert _params(QUAD, 0.4).top_speed() == np.inf
