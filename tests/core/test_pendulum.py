# SPDX-License-Identifier: GPL-3.0-or-later
"""3D pendulums (thesis chapter 5): springs, trees, the superimposed layer, frame rates."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from procloco_addon.core.secondary import pendulum as P  # noqa: N812

# A bar hanging straight down: columns x = X, y (the bar) = -Z, z = Y.
DOWN = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _frame_from_dir(direction: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    y = direction / np.linalg.norm(direction)
    hint = np.array([0.0, 1.0, 0.0]) if up is None else up
    if abs(np.dot(hint, y)) > 0.9:
        hint = np.array([1.0, 0.0, 0.0])
    x = np.cross(y, hint)
    x /= np.linalg.norm(x)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _chain_pose(root: np.ndarray, angles: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """A planar chain hanging from ``root`` (T, 3), bone i turned by ``angles[:, i]`` about Y."""
    n_t, n = angles.shape
    heads = np.zeros((n_t, n, 3))
    frames = np.zeros((n_t, n, 3, 3))
    p = root.copy()
    for i in range(n):
        a = angles[:, i]
        d = np.stack([np.sin(a), np.zeros_like(a), -np.cos(a)], axis=-1)
        x = np.stack([np.cos(a), np.zeros_like(a), np.sin(a)], axis=-1)
        frames[:, i] = np.stack([x, d, np.cross(x, d)], axis=-1)
        heads[:, i] = p
        p = p + length * d
    return heads, frames


def _released(
    settling_time: float, damping: float, theta0: float = 0.4
) -> tuple[np.ndarray, np.ndarray, float]:
    """One gravity pendulum started ``theta0`` off vertical, at rest: (times, θx, h)."""
    forest = P.PendulumForest([-1], [0.5], settling_time, damping, rest_mode=[P.REST_GRAVITY])
    sim = P.PendulumSimulator(forest)
    tilted = _frame_from_dir(np.array([np.sin(theta0), 0.0, -np.cos(theta0)]), up=np.array([0.0, 1.0, 0.0]))
    head = np.zeros((1, 3))
    sim.reset(head, tilted[None])
    steps = int(np.ceil(3.0 * settling_time / sim.h))
    theta = [sim.state.theta[0, 0]]
    theta.extend(sim.step(head, tilted[None]).theta[0, 0] for _ in range(steps))
    return np.arange(steps + 1) * sim.h, np.array(theta), sim.h


# --- spring-dampers (thesis §5.2) -------------------------------------------------------


@pytest.mark.parametrize(
    ("settling_time", "damping"), [(0.5, 0.3), (1.0, 0.5), (0.8, 0.7), (0.6, 1.0), (1.2, 1.6)]
)
def test_released_spring_enters_and_stays_in_5_percent_band_at_ts(
    settling_time: float, damping: float
) -> None:
    t, theta, h = _released(settling_time, damping)
    outside = np.abs(theta) > P.TOLERANCE_FRACTION * abs(theta[0])
    settled_at = t[np.flatnonzero(outside)[-1] + 1]
    assert abs(settled_at - settling_time) <= h + 1e-12
    # And it is really moving before that: outside the band one step earlier than Ts - h.
    assert np.any(outside[t < settling_time - 2 * h])


@pytest.mark.parametrize("damping", [1.0, 1.3, 2.5])
def test_critically_and_over_damped_springs_never_overshoot(damping: float) -> None:
    _t, theta, _h = _released(0.7, damping)
    assert np.all(theta > 0.0)
    assert np.all(np.diff(theta) <= 1e-15)  # monotone return


@pytest.mark.parametrize("damping", [0.15, 0.3, 0.5, 0.7])
def test_underdamped_overshoot_matches_analytic_value(damping: float) -> None:
    _t, theta, _h = _released(0.9, damping)
    overshoot = -theta.min() / theta[0]
    analytic = np.exp(-damping * np.pi / np.sqrt(1.0 - damping**2))
    assert overshoot == pytest.approx(analytic, rel=0.05)


def test_settling_factor_is_the_last_exit_of_the_band() -> None:
    zeta = np.array([0.1, 0.25, 0.5, 0.69, 0.9, 1.0, 2.0])
    tau = P.settling_factor(zeta)
    for z, ts in zip(zeta, tau, strict=True):
        grid = np.linspace(ts, ts + 60.0, 20001)
        x = P._released_response(grid, np.full_like(grid, z))
        assert np.all(np.abs(x) <= 0.05 + 1e-9)
        assert abs(P._released_response(np.array([ts]), np.array([z]))[0]) == pytest.approx(0.05, abs=1e-9)


def test_eq_5_1_envelope_and_eq_5_2_constants() -> None:
    ts, zeta = np.array([0.5, 2.0]), np.array([0.3, 0.8])
    assert np.allclose(P.natural_frequency_envelope(ts, zeta), -np.log(0.05) / (zeta * ts))
    omega0, k, c = P.spring_constants(ts, zeta, mass=2.0)
    assert np.allclose(omega0, P.settling_factor(zeta) / ts)
    assert np.allclose(k, 2.0 * omega0**2)
    assert np.allclose(c, 2.0 * 2.0 * zeta * omega0)
    # For light damping the corrected ω0 is close to eq. 5.1's envelope value.
    assert P.natural_frequency(1.0, 0.1) == pytest.approx(P.natural_frequency_envelope(1.0, 0.1), rel=0.1)


def test_stiff_springs_raise_the_internal_rate_and_stay_stable() -> None:
    forest = P.PendulumForest([-1], [0.1], 0.02, 0.3)
    sim = P.PendulumSimulator(forest)
    assert sim.h < 1.0 / P.DEFAULT_RATE_HZ
    assert forest.omega0[0] * sim.h <= P.MAX_OMEGA_STEP
    _t, theta, _h = _released(0.02, 0.3)
    assert np.all(np.isfinite(theta))
    assert np.abs(theta).max() <= abs(theta[0]) + 1e-12


# --- the superimposed layer (thesis §5.4, §5.5.1) -----------------------------------------


def test_no_perturbation_reproduces_the_animation_exactly() -> None:
    times = np.arange(0, 97) / 24.0
    wag = 0.5 * np.sin(2 * np.pi * 0.8 * times)[:, None] * np.arange(1, 5)[None, :]
    heads, frames = _chain_pose(np.tile([0.0, 0.0, 1.0], (times.size, 1)), wag, 0.2)
    # Add an animated twist about each bone: the pendulums must keep it.
    twist = 0.3 * np.cos(times)[:, None, None, None]
    c, s = np.cos(twist[..., 0, 0]), np.sin(twist[..., 0, 0])
    x, z = frames[..., :, 0].copy(), frames[..., :, 2].copy()
    frames[..., :, 0] = c[..., None] * x + s[..., None] * z
    frames[..., :, 2] = -s[..., None] * x + c[..., None] * z
    forest = P.PendulumForest.chains([[0.2] * 4], settling_time=0.4, damping=0.3)
    result = P.simulate(forest, times, heads, frames)
    assert np.abs(result.rotation - frames).max() < 1e-12
    assert np.abs(result.head - heads).max() < 1e-12
    assert np.abs(result.theta).max() < 1e-12


def test_constant_velocity_body_leaves_the_chain_as_animated() -> None:
    times = np.arange(0, 49) / 24.0
    root = np.stack([1.5 * times, 0.3 * times, np.ones_like(times)], axis=-1)
    heads, frames = _chain_pose(root, np.zeros((times.size, 3)), 0.25)
    result = P.simulate(P.PendulumForest.chains([[0.25] * 3]), times, heads, frames)
    assert np.abs(result.theta).max() < 1e-9
    assert np.abs(result.head - heads).max() < 1e-9


def test_stopping_body_swings_the_tail_forward_then_settles() -> None:
    times = np.arange(0, 121) / 30.0
    # Moves along +X at 1 m/s and stops smoothly between 1.0 s and 1.2 s.
    braking = 1.0 + (times - 1.0) - 2.5 * (times - 1.0) ** 2
    x = np.where(times < 1.0, times, np.where(times < 1.2, braking, 1.1))
    root = np.stack([x, np.zeros_like(x), np.ones_like(x)], axis=-1)
    heads, frames = _chain_pose(root, np.zeros((times.size, 3)), 0.2)
    forest = P.PendulumForest.chains([[0.2] * 3], settling_time=0.8, damping=0.4)
    result = P.simulate(forest, times, heads, frames)
    tip = result.head[:, -1] + 0.2 * result.rotation[:, -1, :, 1]
    moving = times < 0.95
    assert np.abs(result.theta[moving]).max() < 1e-9
    # Deceleration throws the hanging tail forward (+X, the bar's frame x axis here).
    assert tip[:, 0].max() - 1.1 > 0.02
    assert result.theta[(times > 1.0) & (times < 1.6), :, 0].max() > 0.05
    # ... and it comes back: the last 0.5 s are near rest.
    assert np.abs(result.theta[times > 3.5]).max() < 0.1 * np.abs(result.theta).max()


def test_bone_lengths_and_root_anchor_are_preserved_under_violent_motion() -> None:
    rng = np.random.default_rng(3)
    times = np.arange(0, 61) / 24.0
    root = np.cumsum(rng.normal(0.0, 0.05, (times.size, 3)), axis=0)
    heads, frames = _chain_pose(root, 0.4 * rng.normal(size=(times.size, 5)), 0.15)
    forest = P.PendulumForest.chains([[0.15] * 5], settling_time=0.3, damping=0.2)
    result = P.simulate(forest, times, heads, frames)
    assert np.abs(result.theta).max() > 0.1  # really perturbed
    lengths = np.linalg.norm(np.diff(result.head, axis=1), axis=-1)
    assert np.abs(lengths - 0.15).max() < 1e-9
    assert np.abs(result.head[:, 0] - heads[:, 0]).max() == 0.0
    # Frames stay rotations; the tail of a bone is its child's head.
    gram = np.einsum("tnij,tnik->tnjk", result.rotation, result.rotation)
    assert np.abs(gram - np.eye(3)).max() < 1e-9
    tails = result.head[:, :-1] + 0.15 * result.rotation[:, :-1, :, 1]
    assert np.abs(tails - result.head[:, 1:]).max() < 1e-9


def test_influence_scales_the_swing_away_from_the_animation() -> None:
    times = np.arange(0, 49) / 24.0
    root = np.stack([np.sin(3 * times), np.zeros_like(times), np.ones_like(times)], axis=-1)
    heads, frames = _chain_pose(root, np.zeros((times.size, 2)), 0.3)
    full = P.simulate(P.PendulumForest.chains([[0.3] * 2]), times, heads, frames)
    off = P.simulate(P.PendulumForest.chains([[0.3] * 2], influence=0.0), times, heads, frames)
    half = P.simulate(P.PendulumForest.chains([[0.3] * 2], influence=0.5), times, heads, frames)
    assert np.abs(off.rotation - frames).max() < 1e-12
    assert np.allclose(off.theta, full.theta)  # influence does not change the dynamics
    down = frames[..., 0, :, 1]
    angle_full = np.arccos(np.clip(np.einsum("ti,ti->t", full.rotation[:, 0, :, 1], down), -1, 1))
    angle_half = np.arccos(np.clip(np.einsum("ti,ti->t", half.rotation[:, 0, :, 1], down), -1, 1))
    assert angle_full.max() > 0.05
    assert np.allclose(angle_half, 0.5 * angle_full, atol=1e-9)


def test_gravity_rest_direction_hangs_the_chain_and_keeps_twist() -> None:
    times = np.arange(0, 73) / 24.0
    n_t = times.size
    heads = np.zeros((n_t, 2, 3))
    heads[:, 1] = [0.0, 0.4, 0.0]
    horizontal = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # bar along +Y
    frames = np.broadcast_to(horizontal, (n_t, 2, 3, 3)).copy()
    forest = P.PendulumForest([-1, 0], [0.4, 0.4], 0.5, 1.0, rest_mode=[P.REST_GRAVITY] * 2)
    result = P.simulate(forest, times, heads, frames)
    assert np.allclose(result.rotation[0], frames[0], atol=1e-12)  # starts where animated
    assert np.allclose(result.rotation[-1, :, :, 1], [0.0, 0.0, -1.0], atol=0.02)  # ends hanging
    # Twist: the x axis (perpendicular to the swing) is kept.
    assert np.allclose(result.rotation[-1, :, :, 0], [1.0, 0.0, 0.0], atol=1e-9)


# --- trees: son pursuit, father pursuit, combination (thesis §5.3) ----------------------


def _hanging(n_t: int, parent: list[int], length: float) -> tuple[np.ndarray, np.ndarray]:
    """Every bone hangs down; a son's head is its father's tail."""
    n = len(parent)
    heads = np.zeros((n_t, n, 3))
    for i, f in enumerate(parent):
        if f >= 0:
            heads[:, i] = heads[:, f] + [0.0, 0.0, -length]
    return heads, np.broadcast_to(DOWN, (n_t, n, 3, 3)).copy()


def test_impulse_on_the_tip_drags_its_ancestors_and_settles_back() -> None:
    times = np.arange(0, 121) / 24.0
    heads, frames = _hanging(times.size, [-1, 0, 1], 0.3)
    forest = P.PendulumForest([-1, 0, 1], [0.3] * 3, 0.8, 0.5)
    kick = P.Impulses(np.array([0.5]), np.array([2]), np.array([[0.15, 0.0, 0.0]]))
    result = P.simulate(forest, times, heads, frames, impulses=kick)
    before = times < 0.5 - 1e-9
    assert np.abs(result.theta[before]).max() == 0.0
    k = np.searchsorted(times, 0.5) + 1
    swing = result.theta[k, :, 0]
    # All turn toward +X; the displaced son most, then its father, then the root.
    assert np.all(swing > 0.0)
    assert swing[2] > swing[1] > swing[0]
    assert np.abs(result.theta[k, :, 1]).max() < 1e-12  # stays in the XZ plane
    assert np.abs(result.head[:, 0] - heads[:, 0]).max() == 0.0  # fixed anchor
    assert np.abs(result.theta[-1]).max() < 0.05 * swing[2]


def _father_error_after_pull(combine: str, pulled: list[int], weights: list[float] | None = None) -> float:
    """A father with two identical hanging sons; displace the sons ``pulled`` by 10 cm."""
    parent = [-1, 0, 0]
    heads, frames = _hanging(1, parent, 0.3)
    # One-way passes: the sons' springs pushing back would blur the rule under test.
    forest = P.PendulumForest(
        parent, [0.3] * 3, 0.8, 0.5, combine=combine, child_weight=weights, reaction=False  # type: ignore[arg-type]
    )
    sim = P.PendulumSimulator(forest)
    sim.reset(heads[0], frames[0])
    impulse = np.zeros((3, 3))
    impulse[pulled] = [0.1, 0.0, 0.0]
    return float(sim.step(heads[0], frames[0], impulse).theta[0, 0])


def test_sons_pulls_are_summed_averaged_or_weighted() -> None:
    one = _father_error_after_pull("sum", [1])
    assert one > 0.0
    assert _father_error_after_pull("sum", [2]) == pytest.approx(one, rel=1e-12)
    assert _father_error_after_pull("sum", [1, 2]) == pytest.approx(2.0 * one, rel=1e-12)
    assert _father_error_after_pull("average", [1]) == pytest.approx(0.5 * one, rel=1e-12)
    assert _father_error_after_pull("average", [1, 2]) == pytest.approx(one, rel=1e-12)
    weights = [1.0, 3.0, 1.0]
    assert _father_error_after_pull("weighted", [1], weights) == pytest.approx(0.75 * one, rel=1e-12)
    assert _father_error_after_pull("weighted", [2], weights) == pytest.approx(0.25 * one, rel=1e-12)
    assert _father_error_after_pull("weighted", [1, 2], weights) == pytest.approx(one, rel=1e-12)


def test_father_pursuit_moves_sons_with_a_swinging_father() -> None:
    times = np.arange(0, 49) / 24.0
    heads, frames = _hanging(times.size, [-1, 0], 0.3)
    forest = P.PendulumForest([-1, 0], [0.3, 0.3], 0.6, 0.3)
    kick = P.Impulses(np.array([0.2]), np.array([0]), np.array([[0.1, 0.0, 0.0]]))
    result = P.simulate(forest, times, heads, frames, impulses=kick)
    # The son was not displaced itself, but its anchor moved with its father: it lags (its
    # error points the other way first) and then swings.
    after = times > 0.2
    assert result.theta[after, 1, 0].min() < -0.01
    assert np.abs(result.head[:, 1] - (result.head[:, 0] + 0.3 * result.rotation[:, 0, :, 1])).max() < 1e-12


def _random_tree(draw: st.DrawFn) -> list[int]:
    n = draw(st.integers(1, 9))
    return [-1] + [draw(st.integers(-1, i - 1)) for i in range(1, n)]


@pytest.mark.slow
@settings(max_examples=20)
@given(data=st.data())
def test_pendulum_order_never_changes_results(data: st.DataObject) -> None:
    parent = _random_tree(data.draw)
    n = len(parent)
    perm = np.array(data.draw(st.permutations(range(n))))
    times = np.arange(0, 25) / 24.0
    heads, frames = _hanging(times.size, parent, 0.2)
    heads = heads + np.stack([0.3 * np.sin(4 * times), 0.1 * times**2, np.zeros_like(times)], -1)[:, None]
    kick = P.Impulses(np.array([0.3]), np.array([n - 1]), np.array([[0.05, 0.02, 0.0]]))
    a = P.simulate(P.PendulumForest(parent, [0.2] * n, 0.5, 0.4), times, heads, frames, impulses=kick)
    # The same trees listed in another order (sons may now come before fathers).
    inv = np.argsort(perm)
    parent_p = [int(inv[parent[p]]) if parent[p] >= 0 else -1 for p in perm]
    kick_p = P.Impulses(kick.time, inv[kick.node], kick.displacement)
    b = P.simulate(P.PendulumForest(parent_p, [0.2] * n, 0.5, 0.4), times, heads[:, perm], frames[:, perm],
                   impulses=kick_p)
    # Sons' pulls and reactions are summed in another order, so results agree to rounding,
    # which the dynamics may grow a little over a second of violent motion.
    assert np.allclose(a.rotation[:, perm], b.rotation, rtol=0.0, atol=1e-6)
    assert np.allclose(a.head[:, perm], b.head, rtol=0.0, atol=1e-6)
    again = P.simulate(P.PendulumForest(parent, [0.2] * n, 0.5, 0.4), times, heads, frames, impulses=kick)
    # Run to run: equal to rounding. (numpy's AVX-512 kernels were seen to differ by one ulp
    # between calls on some machines, so this is not a bitwise comparison.)
    assert np.allclose(a.rotation, again.rotation, rtol=0.0, atol=1e-6)


@pytest.mark.slow
@settings(max_examples=20)
@given(
    seed=st.integers(0, 2**31 - 1),
    settling=st.floats(0.1, 2.0),
    damping=st.floats(0.1, 2.0),
)
def test_random_motion_keeps_lengths_and_finite_poses(seed: int, settling: float, damping: float) -> None:
    rng = np.random.default_rng(seed)
    parent = [-1, 0, 1, 1, 3]
    times = np.arange(0, 31) / 30.0
    heads, frames = _hanging(times.size, parent, 0.1)
    heads = heads + np.cumsum(rng.normal(0.0, 0.03, (times.size, 3)), axis=0)[:, None]
    rest = rng.integers(0, 2, size=len(parent))
    forest = P.PendulumForest(parent, [0.1] * 5, settling, damping, rest_mode=rest)
    result = P.simulate(forest, times, heads, frames)
    assert np.all(np.isfinite(result.rotation))
    assert np.all(np.isfinite(result.head))
    for i, f in enumerate(parent):
        if f >= 0:
            tail = result.head[:, f] + 0.1 * result.rotation[:, f, :, 1]
            assert np.abs(result.head[:, i] - tail).max() < 1e-9


# --- frame rates ---------------------------------------------------------------------------


def test_24_and_60_fps_give_the_same_pose_at_shared_times() -> None:
    def motion(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # The body starts at rest, trots and bobs, then stops; the tail wags slowly.
        x = 0.4 * (times - np.sin(2.0 * times) / 2.0)
        z = 1.0 + 0.03 * np.sin(2 * np.pi * 2.0 * times) * np.minimum(times, 1.0)
        root = np.stack([x, 0.1 * np.sin(1.5 * times) ** 2, z], axis=-1)
        wag = 0.3 * np.sin(2 * np.pi * 0.5 * times)[:, None] * np.ones(4)
        return _chain_pose(root, wag, 0.15)

    forest = P.PendulumForest.chains([[0.15] * 4], settling_time=0.5, damping=0.35)
    t24, t60 = np.arange(0, 73) / 24.0, np.arange(0, 181) / 60.0
    r24 = P.simulate(forest, t24, *motion(t24))
    r60 = P.simulate(forest, t60, *motion(t60))
    i24, i60 = np.arange(0, 73, 2), np.arange(0, 181, 5)  # every 1/12 s
    assert np.allclose(t24[i24], t60[i60])
    assert np.abs(r60.theta).max() > 0.03  # there is secondary motion to compare
    dir24, dir60 = r24.rotation[i24, :, :, 1], r60.rotation[i60, :, :, 1]
    angle = np.arccos(np.clip(np.einsum("tni,tni->tn", dir24, dir60), -1.0, 1.0))
    assert angle.max() < 0.01  # radians
    assert np.abs(r24.head[i24] - r60.head[i60]).max() < 2e-3  # metres, 0.6 m chain


# --- bad input --------------------------------------------------------------------------


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"parent": [-1, 0], "length": [0.2, 0.0]}, "length > 0"),
    ({"parent": [1, 0], "length": [0.2, 0.2]}, "cycle"),
    ({"parent": [-1, 5], "length": [0.2, 0.2]}, "parent indices"),
    ({"parent": [-1, 0], "length": [0.2, 0.2], "damping": 0.0}, "ζ"),
    ({"parent": [-1, 0], "length": [0.2, 0.2], "settling_time": -1.0}, "Ts"),
    ({"parent": [-1, 0], "length": [0.2, 0.2], "influence": 2.0}, "influence"),
    ({"parent": [-1, 0], "length": [0.2, 0.2], "combine": "max"}, "combine"),
])
def test_bad_forests_are_refused_with_a_clear_message(kwargs: dict[str, object], message: str) -> None:
    args = {"settling_time": 0.5, "damping": 0.5, **kwargs}
    parent, length = args.pop("parent"), args.pop("length")
    ts, zeta = args.pop("settling_time"), args.pop("damping")
    with pytest.raises(ValueError, match=message):
        P.PendulumForest(parent, length, ts, zeta, **args)  # type: ignore[arg-type]


def test_bad_animations_are_refused() -> None:
    forest = P.PendulumForest.chains([[0.2, 0.2]])
    heads, frames = _hanging(3, [-1, 0], 0.2)
    times = np.array([0.0, 0.1, 0.2])
    with pytest.raises(ValueError, match="increasing"):
        P.simulate(forest, times[::-1], heads, frames)
    with pytest.raises(ValueError, match="expected head"):
        P.simulate(forest, times, heads[:, :1], frames)
    heads[1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        P.simulate(forest, times, heads, frames)


def test_single_sample_and_single_bone_are_handled() -> None:
    heads, frames = _hanging(1, [-1], 0.2)
    result = P.simulate(P.PendulumForest.chains([[0.2]]), np.array([0.0]), heads, frames)
    assert np.allclose(result.rotation, frames)
    assert np.allclose(result.head, heads)


# --- chains as physical chains (reaction) -------------------------------------------------


def test_tree_stiffening_gives_the_slowest_swing_the_requested_frequency() -> None:
    single = P.PendulumForest([-1], [0.3], 0.6, 0.4)
    assert single.tree_scale[0] == 1.0
    pair = P.PendulumForest([-1, 0], [0.2, 0.2], 0.6, 0.4)
    # Uniform two-bar chain of point masses: slowest mode ω² = (3 - √5)/2 · ω0².
    assert np.allclose(pair.tree_scale, 1.0 / np.sqrt((3.0 - np.sqrt(5.0)) / 2.0))
    assert np.all(P.PendulumForest([-1, 0], [0.2, 0.2], 0.6, 0.4, reaction=False).tree_scale == 1.0)


def _shaken_chain(reaction: bool, n: int = 8, damping: float = 0.35) -> np.ndarray:
    """Largest swing (deg) of each bar after 4 s of shaking the anchor by 1 cm at ω0."""
    forest = P.PendulumForest.chains([[0.08] * n], settling_time=0.6, damping=damping, reaction=reaction)
    times = np.arange(0, 241) / 30.0
    root = np.stack([0.01 * np.sin(forest.omega0[0] * times), 0 * times, 1 + 0 * times], -1)
    heads, frames = _chain_pose(root, np.zeros((times.size, n)), 0.08)
    result = P.simulate(forest, times, heads, frames)
    return np.degrees(np.abs(result.theta[times > 4.0]).max(axis=(0, 2)))


def test_chains_shaken_at_resonance_do_not_amplify_along_their_length() -> None:
    swing = _shaken_chain(reaction=True)
    assert swing.max() < 15.0
    assert np.all(np.diff(swing) <= 1e-9)  # the tip swings least at this frequency
    # The thesis's one-way passes cannot hand energy back: the same chain whirls.
    one_way = _shaken_chain(reaction=False)
    assert one_way[-1] > 90.0
    assert one_way[-1] > 5.0 * one_way[0]


@pytest.mark.parametrize("n", [2, 4, 8])
def test_kicked_chain_settles_within_three_settling_times(n: int) -> None:
    times = np.arange(0, 151) / 30.0
    parent = [-1, *range(n - 1)]
    heads, frames = _hanging(times.size, parent, 0.1)
    forest = P.PendulumForest(parent, [0.1] * n, 0.6, 0.5)
    kick = P.Impulses(np.array([0.2]), np.array([n - 1]), np.array([[0.05, 0.0, 0.0]]))
    result = P.simulate(forest, times, heads, frames, impulses=kick)
    tip = result.head[:, -1] + 0.1 * result.rotation[:, -1, :, 1]
    away = np.linalg.norm(tip - tip[0], axis=1)
    outside = np.flatnonzero(away > 0.05 * away.max())
    assert times[outside[-1]] - 0.2 <= 3 * 0.6


@pytest.mark.parametrize("reaction", [True, False])
def test_violent_input_stays_bounded(reaction: bool) -> None:
    """An anchor that jumps to full speed and teleports, and tips kicked every step: the bars
    stop at the swing limit instead of whirling, and nothing blows up."""
    parent = [-1, 0, 1, 2, 3, 4, -1, 6, 7, 6, 9]
    lengths = [0.08] * 6 + [0.05, 0.06, 0.06, 0.06, 0.06]
    forest = P.PendulumForest(parent, lengths, 0.6, 0.35, reaction=reaction)
    sim = P.PendulumSimulator(forest)
    heads, frames = _hanging(1, parent, 0.06)
    sim.reset(heads[0], frames[0])
    kick = np.zeros((len(parent), 3))
    kick[[3, 8, 10]] = [[0.01, 0.004, -0.012], [-0.02, 0.0, 0.01], [0.0, 0.015, 0.0]]
    worst = 0.0
    for k in range(600):
        jump = np.array([1.5 * (k % 200) * sim.h, 0.0, 0.0])  # 1.5 m/s from rest, back to 0 every 200 steps
        state = sim.step(heads[0] + jump, frames[0], kick)
        worst = max(worst, float(np.linalg.norm(state.theta, axis=1).max()))
    assert np.all(np.isfinite(state.theta))
    assert worst <= P.MAX_SWING + 1e-12
    assert worst > 1.0  # it was violent


# --- the body turning: angular motion of the anchor (thesis §5.3.1, extended) ------------


def _yaw(angle: np.ndarray) -> np.ndarray:
    """Rotations (T, 3, 3) about world Z by ``angle`` (T,)."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.zeros((*angle.shape, 3, 3))
    rot[..., 0, 0], rot[..., 0, 1], rot[..., 1, 0], rot[..., 1, 1], rot[..., 2, 2] = c, -s, s, c, 1.0
    return rot


# A horizontal bar pointing backwards (body -X): x = Y, y (the bar) = -X, z = Z.
BACKWARD = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _tail_on_turning_body(
    body_yaw: np.ndarray, n: int, length: float, centre: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A straight tail of ``n`` bars pointing backwards from the origin, carried rigidly by a
    body that yaws by ``body_yaw`` (T,) about a vertical axis through ``centre`` (default:
    the tail's root): heads (T, n, 3), frames (T, n, 3, 3), anchor frames (T, n, 3, 3)."""
    rot = _yaw(body_yaw)
    pivot = np.zeros(3) if centre is None else centre
    rest = np.array([[-length * i, 0.0, 0.0] for i in range(n)])
    heads = np.einsum("tij,nj->tni", rot, rest - pivot) + pivot
    frames = np.broadcast_to((rot @ BACKWARD)[:, None], (body_yaw.size, n, 3, 3)).copy()
    anchors = np.broadcast_to(rot[:, None], (body_yaw.size, n, 3, 3)).copy()
    return heads, frames, anchors


def _world_yaw(direction: np.ndarray) -> np.ndarray:
    """Yaw (rad) of backward-pointing bars (..., 3): 0 along -X."""
    return np.arctan2(-direction[..., 1], -direction[..., 0])


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped into [-π, π)."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def _fit_sine(t: np.ndarray, x: np.ndarray, omega: float) -> complex:
    """Least-squares phasor of ``x`` (T,) at ``omega``: x ≈ Im(z · exp(iωt))."""
    basis = np.column_stack([np.sin(omega * t), np.cos(omega * t)])
    (a, b), *_ = np.linalg.lstsq(basis, x, rcond=None)
    return complex(a, b)


@pytest.mark.parametrize(("ratio", "damping"), [(0.6, 0.3), (1.0, 0.5), (1.7, 0.3)])
def test_a_body_yawing_back_and_forth_drives_a_bar_like_a_damped_oscillator(
    ratio: float, damping: float
) -> None:
    """Anchor yaw β = β0 sin Ωt about the bar's head: the error e (bar yaw minus body yaw) obeys
    e'' + 2ζω0 e' + ω0² e = -β''. Its steady response is e/β = Ω² / (ω0² - Ω² + 2iζω0Ω)."""
    forest = P.PendulumForest([-1], [0.4], 0.6, damping)
    omega0 = float(forest.omega0[0])
    omega = ratio * omega0
    times = np.arange(0, 241) / 30.0
    beta0 = np.radians(10.0)
    body = beta0 * np.sin(omega * times)
    heads, frames, anchors = _tail_on_turning_body(body, 1, 0.4)
    result = P.simulate(forest, times, heads, frames, anchor_frame=anchors)
    error = _wrap(_world_yaw(result.rotation[:, 0, :, 1]) - body)
    steady = times > 3 * 0.6
    measured = _fit_sine(times[steady], error[steady], omega) / beta0
    expected = omega**2 / (omega0**2 - omega**2 + 2j * damping * omega0 * omega)
    assert abs(measured) == pytest.approx(abs(expected), rel=0.01)
    assert abs(np.angle(measured / expected)) < 0.01  # radians
    # The bar lags behind the body: its world yaw's phase trails the body's.
    assert np.angle(1.0 + measured) < -0.05
    # The bar stays horizontal and keeps its length; its anchor does not move.
    assert np.abs(result.rotation[:, 0, 2, 1]).max() < 1e-9
    assert np.abs(result.head - heads).max() < 1e-12


def test_without_anchor_frames_a_turning_body_carries_its_chain_rigidly() -> None:
    times = np.arange(0, 121) / 30.0
    heads, frames, _anchors = _tail_on_turning_body(np.radians(10.0) * np.sin(6.0 * times), 4, 0.1)
    result = P.simulate(P.PendulumForest.chains([[0.1] * 4]), times, heads, frames)
    assert np.abs(result.theta).max() < 1e-9


@pytest.mark.parametrize("reaction", [True, False])
def test_a_tail_on_a_swaying_body_lags_and_swings(reaction: bool) -> None:
    """A 6-bar tail on hips swaying ±10° at 1.5 Hz: the tip swings by several degrees against
    the animation and its world yaw lags the body's; bone lengths and the root stay."""
    times = np.arange(0, 145) / 24.0
    omega = 2 * np.pi * 1.5
    body = np.radians(10.0) * np.sin(omega * times)
    heads, frames, anchors = _tail_on_turning_body(body, 6, 0.1)
    forest = P.PendulumForest.chains([[0.1] * 6], settling_time=0.6, damping=0.4, reaction=reaction)
    result = P.simulate(forest, times, heads, frames, anchor_frame=anchors)
    tip = result.head[:, -1] + 0.1 * result.rotation[:, -1, :, 1]
    tip_yaw = _world_yaw(tip - result.head[:, 0])
    steady = times > 2.0
    assert np.degrees(np.abs(_wrap(tip_yaw - body))[steady].max()) > 4.0
    tip_phasor = _fit_sine(times[steady], tip_yaw[steady], omega)
    lag = np.angle(tip_phasor / _fit_sine(times[steady], body[steady], omega))
    assert -np.pi < lag < -0.2  # radians behind the body
    lengths = np.linalg.norm(np.diff(result.head, axis=1), axis=-1)
    assert np.abs(lengths - 0.1).max() < 1e-9
    assert np.abs(result.head[:, 0] - heads[:, 0]).max() < 1e-12


def test_a_steady_turn_carries_the_chain_as_animated() -> None:
    times = np.arange(0, 97) / 24.0
    heads, frames, anchors = _tail_on_turning_body(1.5 * times, 6, 0.1)  # 1.5 rad/s from the start
    result = P.simulate(P.PendulumForest.chains([[0.1] * 6]), times, heads, frames, anchor_frame=anchors)
    assert np.abs(result.theta).max() < 1e-9
    assert np.abs(result.rotation - frames).max() < 1e-9


def _ramped_yaw(times: np.ndarray, rate: float, start: float, ramp: float) -> np.ndarray:
    """Yaw of a body at rest that starts turning at ``start`` and reaches ``rate`` (rad/s) in
    ``ramp`` seconds, then turns steadily."""
    t = times - start
    return np.where(t < 0.0, 0.0, np.where(t < ramp, 0.5 * rate * t**2 / ramp, rate * (t - 0.5 * ramp)))


def test_a_turn_starting_swings_the_tail_out_of_the_turn_then_it_settles() -> None:
    times = np.arange(0, 145) / 24.0
    body = _ramped_yaw(times, 1.5, 0.5, 0.3)
    heads, frames, anchors = _tail_on_turning_body(body, 6, 0.1)
    forest = P.PendulumForest.chains([[0.1] * 6], settling_time=0.6, damping=0.35)
    result = P.simulate(forest, times, heads, frames, anchor_frame=anchors)
    swing = np.abs(result.theta).max(axis=(1, 2))
    assert swing[times < 0.5].max() < 1e-12  # at rest: as animated
    # Turning left (counter-clockwise) leaves the tail behind: it points to the right of the
    # animated tail, i.e. its world yaw falls short of the body's.
    tip = result.head[:, -1] + 0.1 * result.rotation[:, -1, :, 1]
    behind = _wrap(body - _world_yaw(tip - result.head[:, 0]))
    ramp = (times > 0.5) & (times < 1.0)
    assert np.degrees(behind[ramp].max()) > 1.0
    # Once the turn is steady the tail comes back to the animation and stays there.
    assert swing[times > 0.8 + 4 * 0.6].max() < 0.01 * swing.max()


def test_walking_a_circle_leans_the_tail_out_of_the_turn_steadily() -> None:
    """The body walks a left-hand circle of 0.5 m radius (it turns about a point beside it): the
    tail's root is swung round the circle, and its centripetal acceleration leaves the tail
    leaning out of the turn, steadily (the chain's own rotation adds nothing)."""
    times = np.arange(0, 145) / 24.0
    body = _ramped_yaw(times, 1.5, 0.5, 0.3)
    centre = np.array([0.0, 0.5, 0.0])  # on the left of the root: the body faces +X
    heads, frames, anchors = _tail_on_turning_body(body, 4, 0.1, centre=centre)
    forest = P.PendulumForest.chains([[0.1] * 4], settling_time=0.6, damping=0.5)
    result = P.simulate(forest, times, heads, frames, anchor_frame=anchors)
    tip = result.head[:, -1] + 0.1 * result.rotation[:, -1, :, 1]
    animated_tip = heads[:, -1] + 0.1 * frames[:, -1, :, 1]
    outward = np.linalg.norm(tip - centre, axis=1) - np.linalg.norm(animated_tip - centre, axis=1)
    late = times > 0.8 + 4 * 0.6
    assert outward[late].min() > 0.005  # metres, on a 0.4 m tail
    assert np.ptp(outward[late]) < 1e-4  # steady: no swinging


def _hanging_under_rolling_body(rate: float, with_anchors: bool) -> np.ndarray:
    """Errors (T, 3, 2) of a 3-bar gravity chain hanging from a body that rolls ±25° about the
    chain's top (already rolling at the first sample), sampled ``rate`` times a second."""
    times = np.arange(0, int(3 * rate) + 1) / rate
    roll = np.radians(25.0) * np.sin(4.0 * times)
    c, s = np.cos(roll), np.sin(roll)
    rot = np.zeros((times.size, 3, 3))
    rot[:, 0, 0], rot[:, 1, 1], rot[:, 1, 2], rot[:, 2, 1], rot[:, 2, 2] = 1.0, c, -s, s, c
    heads0, frames0 = _hanging(1, [-1, 0, 1], 0.2)
    heads = np.einsum("tij,nj->tni", rot, heads0[0])
    frames = np.einsum("tij,njk->tnik", rot, frames0[0])
    anchors = np.broadcast_to(rot[:, None], frames.shape).copy() if with_anchors else None
    forest = P.PendulumForest([-1, 0, 1], [0.2] * 3, 0.6, 0.4, rest_mode=[P.REST_GRAVITY] * 3)
    return P.simulate(forest, times, heads, frames, anchor_frame=anchors).theta


@pytest.mark.parametrize("with_anchors", [True, False])
def test_a_hanging_chain_under_a_rolling_body_hangs_still(with_anchors: bool) -> None:
    """The top does not move, gravity targets do not turn with the body, and each bar's anchor
    (its father's tip) stays put in the world: the chain hangs still, from the first frame."""
    internal = 1.0 / P.PendulumSimulator(P.PendulumForest([-1, 0, 1], [0.2] * 3, 0.6, 0.4)).h
    assert np.abs(_hanging_under_rolling_body(internal, with_anchors)).max() < 1e-9
    # From 24 fps samples, but for the interpolation between them (heads along cubic curves,
    # frames by normalised blends, which differ slightly on a circle).
    assert np.degrees(np.abs(_hanging_under_rolling_body(24.0, with_anchors)).max()) < 0.1


def test_a_chain_animated_straight_up_hangs_down_attached() -> None:
    """Gravity bars whose animation points straight up swing opposite to it: each father's
    swing is then a half turn, and its sons still hang from its tip."""
    times = np.arange(0, 97) / 24.0
    up = np.stack([np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([0.0, -1.0, 0.0])], axis=-1)
    heads = np.zeros((times.size, 3, 3))
    heads[:, :, 2] = [0.0, 0.2, 0.4]
    heads[:, :, 0] = 0.3 * times[:, None]  # walking along X
    frames = np.broadcast_to(up, (times.size, 3, 3, 3)).copy()
    forest = P.PendulumForest([-1, 0, 1], [0.2] * 3, 0.5, 1.0, rest_mode=[P.REST_GRAVITY] * 3)
    result = P.simulate(forest, times, heads, frames)
    tails = result.head[:, :-1] + 0.2 * result.rotation[:, :-1, :, 1]
    assert np.abs(tails - result.head[:, 1:]).max() < 1e-9
    assert np.allclose(result.rotation[-1, :, :, 1], [0.0, 0.0, -1.0], atol=1e-6)


def test_no_perturbation_is_exact_with_anchor_frames_too() -> None:
    """A hand-animated wag on a body at rest, anchors given: the wag is animation, not a turn."""
    times = np.arange(0, 73) / 24.0
    wag = 0.5 * np.sin(2 * np.pi * 0.8 * times)[:, None] * np.arange(1, 5)[None, :]
    heads, frames = _chain_pose(np.tile([0.0, 0.0, 1.0], (times.size, 1)), wag, 0.2)
    anchors = np.broadcast_to(P.orthonormalize_frames(np.eye(3) + 0.1), frames.shape)
    forest = P.PendulumForest.chains([[0.2] * 4], settling_time=0.4, damping=0.3)
    result = P.simulate(forest, times, heads, frames, anchor_frame=anchors)
    assert np.abs(result.theta).max() < 1e-12
    assert np.abs(result.rotation - frames).max() < 1e-12


def test_a_turning_body_gives_the_same_motion_at_24_and_60_fps() -> None:
    forest = P.PendulumForest.chains([[0.1] * 5], settling_time=0.5, damping=0.35)
    runs = {}
    for fps in (24, 60):
        times = np.arange(0, 3 * fps + 1) / fps
        body = np.radians(12.0) * np.sin(2 * np.pi * 1.2 * times) * np.minimum(times, 1.0) + _ramped_yaw(
            times, 1.0, 1.5, 0.4)
        heads, frames, anchors = _tail_on_turning_body(body, 5, 0.1)
        runs[fps] = P.simulate(forest, times, heads, frames, anchor_frame=anchors)
    i24, i60 = np.arange(0, 73, 2), np.arange(0, 181, 5)
    assert np.degrees(np.abs(runs[60].theta).max()) > 3.0
    d24, d60 = runs[24].rotation[i24, :, :, 1], runs[60].rotation[i60, :, :, 1]
    angle = np.arccos(np.clip(np.einsum("tni,tni->tn", d24, d60), -1.0, 1.0))
    assert np.degrees(angle.max()) < 0.5


def test_stepping_with_anchor_frames_starts_from_a_steady_turn() -> None:
    """The step-by-step API: a body already turning at 2 rad/s is told so at reset and its tail
    follows as animated; a simulator not told so sees the turn start with a kick."""
    forest = P.PendulumForest.chains([[0.1] * 3])
    told, surprised = P.PendulumSimulator(forest), P.PendulumSimulator(forest)
    h = told.h
    pose = [_tail_on_turning_body(np.array([2.0 * k * h]), 3, 0.1) for k in range(60)]
    spin = np.tile([0.0, 0.0, 2.0], (3, 1))
    told.reset(pose[0][0][0], pose[0][1][0], anchor_frame=pose[0][2][0], anchor_angular_velocity=spin)
    surprised.reset(pose[0][0][0], pose[0][1][0], anchor_frame=pose[0][2][0])
    for heads, frames, anchors in pose[1:]:
        told.step(heads[0], frames[0], anchor_frame=anchors[0])
        surprised.step(heads[0], frames[0], anchor_frame=anchors[0])
    assert np.abs(told.state.theta).max() < 1e-9
    assert np.abs(surprised.state.theta).max() > 1e-3


def test_bad_anchor_frames_are_refused() -> None:
    forest = P.PendulumForest.chains([[0.2, 0.2]])
    heads, frames = _hanging(3, [-1, 0], 0.2)
    times = np.array([0.0, 0.1, 0.2])
    with pytest.raises(ValueError, match="anchor_frame"):
        P.simulate(forest, times, heads, frames, anchor_frame=frames[:, :1])
    bad = frames.copy()
    bad[1, 0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="anchor frames contain NaN"):
        P.simulate(forest, times, heads, frames, anchor_frame=bad)
