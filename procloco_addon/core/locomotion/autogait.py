# SPDX-License-Identifier: GPL-3.0-or-later
"""Auto gait: the gait, the stride and the cycle follow the speed (thesis Appendix D, future work).

The thesis lists as future work choosing the gait parameters from the speed alone. Animals
do it after one rule, **dynamic similarity** (Alexander & Jayes 1983, *A dynamic similarity
hypothesis for the gaits of quadrupedal mammals*, J. Zool. 201): animals of different sizes
move alike at equal Froude number ``Fr = v² / (g h)``, ``h`` the hip height. At equal Fr
they use the same gait, the same relative stride ``λ / h`` and the same duty factor (the
share of the cycle a foot is on the ground), so the speeds at which a creature changes gait
grow with the square root of its size.

What this module computes from the speed, per creature family (``AutoBand`` lists):

- **Gait bands** of Fr. Quadrupeds walk below Fr ≈ 0.5, trot up to Fr ≈ 2.5 and gallop
  above (Alexander & Jayes 1983: the trot-gallop change at Fr between 2 and 3). Bipeds walk
  below Fr ≈ 0.5 and run above (Alexander 1984, *The gaits of bipedal and quadrupedal
  animals*, Int. J. Robotics Research 3; Alexander 1989, *Optimization and gaits in the
  locomotion of vertebrates*, Physiol. Rev. 69). Insects use a metachronal wave at low
  speed, a tetrapod gait at middle speeds and the alternating tripod at high speed, and
  spiders a wave and an alternating tetrapod (Wilson 1966, *Insect walking*, Annu. Rev.
  Entomol. 11; Wilson 1967, *Stepping patterns in tarantula spiders*, J. Exp. Biol. 47).
  Each band's footfall pattern (the swing starts) is a shipped gait preset's.
- **Stride and cycle** of mammals and birds: relative stride ``λ / h ≈ 2.3 Fr^0.3``
  (Alexander 1976, *Estimates of speeds of dinosaurs*, Nature 261), cycle ``λ / v``.
- **Duty factor** falling with speed (Alexander & Jayes 1983; Alexander 1984): interpolated
  in log Fr across each band between two values chosen within the usual ranges (walks about
  0.8 to 0.6, trots 0.6 to 0.45, gallops 0.42 to 0.35 — lower ones make the controller's
  front feet outrun it — human walking 0.65 to 0.55, running 0.4 to 0.3).
- **Many legs**: the swing lasts about the same time at every speed and the stance shortens
  as the speed rises (Wilson 1966), so the duty factor is ``1 / (1 + k √Fr)`` (a constant
  swing time ``c √(h / g)`` and a constant stance sweep ``(c / k) h``); the band follows from
  the duty factor (wave above 0.75, tetrapod above 0.6 for six legs; wave above 0.7 for
  eight), which fixes Fr boundaries in the same way as for mammals.

**Hysteresis.** A band is left upwards only once Fr exceeds its upper boundary by the
relative ``hysteresis``, and downwards only once Fr is that much below its lower boundary,
so a speed hovering at a boundary does not flip the gait back and forth; the change itself
goes through the thesis's §3.3 transition (``GaitManager.start_transition``). Within a band
the duty factor and the cycle follow the speed continuously (``GaitManager.retarget``:
a leg takes its new disk only while in stance).

**Crowded legs.** The swing model's constant stance sweep (0.67 leg) is what legs spread
along the body allow. Legs crowded along it (a beetle's, an ant's) allow less: a foot landing
must stay behind its neighbour's before that one lifts (``rig.stroke_limits``). Given the
creature's ``stroke`` (the longest stance sweep its legs allow, ``rig.Rig.stroke_limit``), the
sweep is at most ``STROKE_SHARE`` of it: the swing keeps its time and the stance shortens,
so the duty factor falls and the faster gaits come at lower speeds, exactly as if the speed
were multiplied by ``1 / stroke_scale`` (``AutoGaitParams.band_scale``). Without it the
controller kept the sweep and ran the whole cycle faster (``rig.rate_scale``): a crowded
hexapod's swings lasted a frame or two.

**Bias.** ``speed_scale`` multiplies the speeds at which the gait changes (Fr boundaries by
its square): 1.5 keeps a creature walking to 1.5 times the speed. ``AutoBand`` patterns can
be replaced by any preset for the same legs (per-band overrides).

Everything is in SI units: speeds in m/s, ``h`` in metres, times in seconds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .gait import Gait, GaitError, GaitManager, GaitPreset, find_gait_preset

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

G = 9.81  # m/s²
#: Fr below which nothing changes any more (standing still): keeps the cycle finite at v = 0.
FR_FLOOR = 0.005
#: Alexander (1976): λ / h = STRIDE_COEFFICIENT · Fr^STRIDE_EXPONENT.
STRIDE_COEFFICIENT = 2.3
STRIDE_EXPONENT = 0.3
#: Many legs (Wilson 1966): swing time ``SWING_TIME · √(h / g)``, duty ``1 / (1 + DUTY_K √Fr)``.
#: With h the leg length, a half-metre leg swings in about 0.23 s, as the shipped insect and
#: spider presets (0.18-0.23 s); the stance sweep is ``SWING_TIME / DUTY_K`` = 0.67 leg.
SWING_TIME = 1.0
DUTY_K = 1.5
#: Duty factors are kept within these (a foot always both lifts and lands).
DUTY_MIN, DUTY_MAX = 0.2, 0.9
#: Share of the legs' longest stance sweep (``AutoGaitParams.stroke``) the swing model's sweep
#: keeps to. The longest sweep puts a landing foot its clearance behind the neighbour's
#: foot that is about to lift; the planner's grid forbids a cell when the foot box may touch
#: it anywhere in the cell, so at the full sweep the landing spot is often taken and the
#: feet behind are pushed back or inward, under the hip (measured on a crowded beetle: hind
#: feet landing 7 cm inward, its coxae turning 90-120 degrees in a frame as the swing folds
#: the leg; at 0.75 of the sweep every foot lands where it was meant to).
STROKE_SHARE = 0.75

MODEL_STRIDE = "stride"  # mammals and birds: stride from Alexander (1976)
MODEL_SWING = "swing"  # insects and spiders: constant swing time (Wilson 1966)


@dataclass(frozen=True)
class AutoBand:
    """One gait of an auto-gait family, used from Froude number ``fr_low`` upward.

    - ``name``: the gait's name (``"walk"``, ``"trot"``...); ``preset``: the shipped preset
      (file stem) whose footfall pattern it uses; ``source``: who observed the band.
    - ``duty``: ``(at fr_low, at the next band's fr_low)`` duty factors of the stride model
      (log-Fr interpolation; the last band uses ``fr_top`` as its end). Unused by the swing
      model, whose duty comes from ``1 / (1 + DUTY_K √Fr)``.
    """

    name: str
    fr_low: float
    preset: str
    duty: tuple[float, float] = (0.6, 0.6)
    source: str = ""


@dataclass(frozen=True)
class AutoFamily:
    """The bands of one kind of creature, in rising Fr (the first from Fr 0), and its model
    (``MODEL_STRIDE`` or ``MODEL_SWING``). ``fr_top``: where the last band's duty ends."""

    name: str
    bands: tuple[AutoBand, ...]
    model: str
    fr_top: float = 10.0

    def boundaries(self) -> FloatArray:
        """``(n_bands - 1,)`` Fr at which each band after the first begins."""
        return np.array([b.fr_low for b in self.bands[1:]], dtype=np.float64)


def _swing_band_fr(duty: float) -> float:
    """The Fr at which the swing model's duty factor is ``duty``."""
    return ((1.0 / duty - 1.0) / DUTY_K) ** 2


_AJ83 = "Alexander & Jayes 1983, A dynamic similarity hypothesis for the gaits of quadrupedal mammals"
_A84 = "Alexander 1984, The gaits of bipedal and quadrupedal animals"
_W66 = "Wilson 1966, Insect walking"
_W67 = "Wilson 1967, Stepping patterns in tarantula spiders"

FAMILIES: dict[str, AutoFamily] = {
    "biped": AutoFamily("biped", (
        AutoBand("walk", 0.0, "biped_walk", (0.65, 0.55), _A84),
        AutoBand("run", 0.5, "biped_run", (0.4, 0.3), _A84),
    ), MODEL_STRIDE, fr_top=5.0),
    "quadruped": AutoFamily("quadruped", (
        AutoBand("walk", 0.0, "quadruped_walk", (0.8, 0.6), _AJ83),
        AutoBand("trot", 0.5, "quadruped_trot", (0.6, 0.45), _AJ83),
        AutoBand("gallop", 2.5, "quadruped_transverse_gallop", (0.42, 0.35), _AJ83),
    ), MODEL_STRIDE),
    "hexapod": AutoFamily("hexapod", (
        AutoBand("wave", 0.0, "hexapod_wave", source=_W66),
        AutoBand("tetrapod", _swing_band_fr(0.75), "hexapod_tetrapod", source=_W66),
        AutoBand("tripod", _swing_band_fr(0.6), "hexapod_tripod", source=_W66),
    ), MODEL_SWING),
    "octopod": AutoFamily("octopod", (
        AutoBand("wave", 0.0, "octopod_wave", source=_W67),
        AutoBand("alternating tetrapod", _swing_band_fr(0.7), "octopod_alternating_tetrapod", source=_W67),
    ), MODEL_SWING),
    "pentapod": AutoFamily("pentapod", (
        AutoBand("wave", 0.0, "pentapod_robot", source="a robot's wave gait (see the preset)"),
    ), MODEL_SWING),
}


def family_for(labels: Sequence[str]) -> AutoFamily | None:
    """The family whose presets fit legs ``labels`` (by leg count), or None."""
    name = {2: "biped", 4: "quadruped", 5: "pentapod", 6: "hexapod", 8: "octopod"}.get(len(labels))
    return FAMILIES.get(name) if name is not None else None


# ---------------------------------------------------------------------------- the models
def froude(speed: npt.ArrayLike, size: float, g: float = G) -> FloatArray:
    """Froude number ``v² / (g h)`` of speeds ``(...)`` m/s for a creature of size ``h`` m."""
    v = np.asarray(speed, dtype=np.float64)
    return np.asarray(v * v / (g * max(float(size), 1e-9)))


def relative_stride(fr: npt.ArrayLike) -> FloatArray:
    """Stride over hip height ``λ / h = 2.3 Fr^0.3`` (Alexander 1976), for Fr ``(...)``."""
    f = np.maximum(np.asarray(fr, dtype=np.float64), FR_FLOOR)
    return np.asarray(STRIDE_COEFFICIENT * f ** STRIDE_EXPONENT)


def _band_end(family: AutoFamily, band: int) -> float:
    return family.bands[band + 1].fr_low if band + 1 < len(family.bands) else family.fr_top


def duty_factor(family: AutoFamily, band: npt.ArrayLike, fr: npt.ArrayLike) -> FloatArray:
    """Duty factor ``(...)`` in band indices ``band (...)`` at Froude numbers ``fr (...)``.

    Stride model: log-Fr interpolation between the band's two duty values over its Fr range
    (held beyond it). Swing model: ``1 / (1 + DUTY_K √Fr)``. Clipped to [DUTY_MIN, DUTY_MAX].
    """
    f = np.maximum(np.asarray(fr, dtype=np.float64), FR_FLOOR)
    b = np.asarray(band, dtype=np.int64)
    if family.model == MODEL_SWING:
        # the tripod / alternating tetrapod keeps half the feet down: no duty under 0.5
        duty = np.broadcast_arrays(1.0 / (1.0 + DUTY_K * np.sqrt(f)), b)[0]
        return np.asarray(np.clip(duty, 0.5, DUTY_MAX))
    lo = np.array([max(bd.fr_low, FR_FLOOR * 2.0) for bd in family.bands])[b]
    hi = np.array([_band_end(family, k) for k in range(len(family.bands))])[b]
    d0 = np.array([bd.duty[0] for bd in family.bands])[b]
    d1 = np.array([bd.duty[1] for bd in family.bands])[b]
    u = np.clip(np.log(f / lo) / np.log(hi / lo), 0.0, 1.0)
    return np.asarray(np.clip(d0 + u * (d1 - d0), DUTY_MIN, DUTY_MAX))


def cycle_time(family: AutoFamily, fr: npt.ArrayLike, duty: npt.ArrayLike, size: float,
               g: float = G) -> FloatArray:
    """Cycle time in seconds ``(...)`` at Froude numbers ``fr`` with duty factors ``duty``.

    Stride model: ``λ / v`` with ``λ = 2.3 Fr^0.3 h`` (Alexander 1976), which is
    ``2.3 Fr^-0.2 √(h / g)``. Swing model: a constant swing ``SWING_TIME √(h / g)`` over the
    swing share ``1 - duty`` (Wilson 1966). Both are finite at Fr 0 (Fr held at FR_FLOOR).
    """
    f = np.maximum(np.asarray(fr, dtype=np.float64), FR_FLOOR)
    unit = math.sqrt(max(float(size), 1e-9) / g)
    if family.model == MODEL_SWING:
        return np.asarray(SWING_TIME * unit / (1.0 - np.asarray(duty, dtype=np.float64)))
    return np.asarray(STRIDE_COEFFICIENT * f ** (STRIDE_EXPONENT - 0.5) * unit)


def band_of(family: AutoFamily, fr: npt.ArrayLike, speed_scale: float = 1.0) -> IntArray:
    """The band ``(...)`` for Froude numbers ``fr (...)`` without hysteresis."""
    edges = family.boundaries() * speed_scale ** 2
    return np.asarray(np.searchsorted(edges, np.asarray(fr, dtype=np.float64), side="right"), dtype=np.int64)


def next_band(family: AutoFamily, current: int, fr: float, speed_scale: float = 1.0,
              hysteresis: float = 0.2) -> int:
    """The band after ``current`` at Froude number ``fr``, with hysteresis: a boundary
    ``b`` is crossed upward above ``b (1 + hysteresis)`` and downward below
    ``b (1 - hysteresis)`` (boundaries scaled by ``speed_scale²``)."""
    edges = family.boundaries() * speed_scale ** 2
    band = int(current)
    while band < edges.size and fr > edges[band] * (1.0 + hysteresis):
        band += 1
    while band > 0 and fr < edges[band - 1] * (1.0 - hysteresis):
        band -= 1
    return band


def band_schedule(family: AutoFamily, fr: npt.ArrayLike, speed_scale: float = 1.0,
                  hysteresis: float = 0.2, start: int | None = None) -> IntArray:
    """Bands ``(F,)`` chosen along Froude numbers ``fr (F,)`` with hysteresis; the first
    frame's band has none (``start`` overrides it)."""
    f = np.asarray(fr, dtype=np.float64).reshape(-1)
    out = np.zeros(f.shape[0], dtype=np.int64)
    if f.size == 0:
        return out
    band = int(band_of(family, f[0], speed_scale)) if start is None else int(start)
    for i, value in enumerate(f):
        band = next_band(family, band, float(value), speed_scale, hysteresis)
        out[i] = band
    return out


# ---------------------------------------------------------------------------- per creature
@dataclass(frozen=True, eq=False)
class AutoGaitParams:
    """Auto gait of one creature.

    - ``family``: its bands and model; ``patterns``: ``(n_bands, n_legs)`` swing starts of
      each band in the creature's leg order (from the band presets, or overrides);
      ``names``: each band's gait name (an override's preset name).
    - ``size``: ``h`` in metres (hip height, or leg length for sprawling legs: see
      ``creature_size``); ``speed_scale``: the bias of the boundaries; ``hysteresis``:
      relative Fr margin; ``transition_cycles``: a gait change's §3.3 transition time in
      cycles of the gait it leaves; ``g``: gravity.
    - ``stroke``: the longest stance sweep the legs allow, metres (``rig.Rig.stroke_limit``;
      None: as long as the model's). The swing model keeps its sweep within
      ``STROKE_SHARE`` of it (``stroke_scale``).
    """

    family: AutoFamily
    patterns: FloatArray
    names: tuple[str, ...]
    size: float
    speed_scale: float = 1.0
    hysteresis: float = 0.2
    transition_cycles: float = 0.5
    g: float = G
    stroke: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.size) and self.size > 0.0):
            raise GaitError(f"auto gait needs a positive creature size, got {self.size!r}")
        if not (math.isfinite(self.speed_scale) and self.speed_scale > 0.0):
            raise GaitError(f"gait speed scale must be positive, got {self.speed_scale!r}")
        if self.stroke is not None and not (math.isfinite(self.stroke) and self.stroke > 0.0):
            raise GaitError(f"auto gait needs a positive stroke, got {self.stroke!r}")
        if self.patterns.shape[0] != len(self.family.bands) or len(self.names) != len(self.family.bands):
            raise GaitError("one pattern and one name per band")

    @property
    def n_legs(self) -> int:
        return int(self.patterns.shape[1])

    def froude(self, speed: npt.ArrayLike) -> FloatArray:
        return froude(speed, self.size, self.g)

    @property
    def stroke_scale(self) -> float:
        """The swing model's stance sweep over the model's own (``SWING_TIME / DUTY_K`` sizes),
        at most 1: ``STROKE_SHARE`` of ``stroke`` where the legs allow less (1 for the stride
        model and without ``stroke``)."""
        if self.stroke is None or self.family.model != MODEL_SWING:
            return 1.0
        return min(1.0, STROKE_SHARE * self.stroke / (SWING_TIME / DUTY_K * self.size))

    @property
    def band_scale(self) -> float:
        """What the speeds of the gait bands and the duty factors are scaled by: the bias
        ``speed_scale`` times ``stroke_scale`` (a sweep shortened by ``stroke_scale`` at the
        same swing time is the model's duty at the speed over ``stroke_scale``)."""
        return self.speed_scale * self.stroke_scale

    def top_speed(self) -> float:
        """The fastest speed (m/s) at which the swing model's gait keeps its swing time: its
        duty factor reaches its floor (0.5) there, and faster the controller runs the whole
        cycle faster. ``inf`` for the stride model."""
        if self.family.model != MODEL_SWING:
            return math.inf
        # 1 / (1 + DUTY_K sqrt(Fr) / band_scale) = 0.5
        return self.band_scale / DUTY_K * math.sqrt(self.g * self.size)

    def gait(self, band: int, speed: float) -> Gait:
        """The gait of band ``band`` at ``speed`` m/s: its pattern, every swing lasting
        ``1 - duty``, and the cycle time."""
        fr = float(self.froude(speed))
        # the duty follows the biased speed, so it stays continuous across the shifted bands
        duty = float(duty_factor(self.family, band, fr / self.band_scale ** 2))
        cycle = float(cycle_time(self.family, fr, duty, self.size, self.g))
        n = self.n_legs
        return Gait(self.patterns[band].copy(), np.full(n, 1.0 - duty), cycle, self.names[band])

    def schedule(self, speed: npt.ArrayLike) -> tuple[IntArray, FloatArray, FloatArray]:
        """Along speeds ``(F,)`` m/s: bands ``(F,)``, duty factors ``(F,)`` and cycle times
        ``(F,)`` s, as ``AutoGait`` chooses them (what the panel's chart shows)."""
        fr = self.froude(np.asarray(speed, dtype=np.float64).reshape(-1))
        bands = band_schedule(self.family, fr, self.band_scale, self.hysteresis)
        duty = duty_factor(self.family, bands, fr / self.band_scale ** 2)
        cycle = cycle_time(self.family, fr, duty, self.size, self.g)
        return bands, duty, cycle


def creature_size(family: AutoFamily, hip_height: float, leg_length: float) -> float:
    """The length ``h`` of the Froude number: the hip height for bipeds and quadrupeds
    (Alexander & Jayes 1983), the leg length for sprawling many-legged creatures, whose hips
    sit low for their legs."""
    return float(hip_height if family.model == MODEL_STRIDE else leg_length)


def auto_gait_params(
    labels: Sequence[str],
    hip_height: float,
    leg_length: float,
    *,
    speed_scale: float = 1.0,
    overrides: Mapping[str, GaitPreset] | None = None,
    hysteresis: float = 0.2,
    preset_dir: Path | None = None,
    stroke: float | None = None,
) -> AutoGaitParams | None:
    """Auto gait for legs ``labels`` (None when no family fits the leg count).

    ``overrides``: band name -> preset whose pattern replaces the band's (legs by label);
    ``stroke``: the longest stance sweep the legs allow (m; ``AutoGaitParams.stroke``).
    Raises ``GaitError`` when a preset does not fit the legs.
    """
    family = family_for(labels)
    if family is None:
        return None
    patterns = []
    names = []
    for band in family.bands:
        preset = (overrides or {}).get(band.name)
        if preset is None:
            preset = find_gait_preset(band.preset, preset_dir)
            names.append(band.name)
        else:
            names.append(preset.name)
        patterns.append(preset.gait(labels).swing_start)
    return AutoGaitParams(family, np.stack(patterns), tuple(names),
                          creature_size(family, hip_height, leg_length), speed_scale, hysteresis,
                          stroke=stroke)


def rest_hip_height(rest_joints: FloatArray, n_segments: IntArray) -> float:
    """Mean height of the hips above the feet at rest, from ``rest_joints (n_legs, s + 1, 3)``
    (body frame, z up) and ``n_segments (n_legs,)``."""
    feet = rest_joints[np.arange(rest_joints.shape[0]), n_segments, 2]
    return float(np.mean(rest_joints[:, 0, 2] - feet))


class AutoGait:
    """Drives the gait of characters of a ``GaitManager`` from their speed, step by step.

    ``params``: one ``AutoGaitParams`` per character (None: the character keeps its gait);
    ``speed (C,)``: the speeds at the start. ``gaits()`` gives the starting gaits; call
    ``update(manager, speed)`` before each step: a band change starts a §3.3 transition
    over ``transition_cycles`` cycles, otherwise the disks and the cycle follow the speed
    (``GaitManager.retarget``). ``band (C,)`` is each character's current band (-1 without).
    """

    def __init__(self, params: Sequence[AutoGaitParams | None], speed: npt.ArrayLike) -> None:
        self.params = list(params)
        v = np.broadcast_to(np.asarray(speed, dtype=np.float64), (len(self.params),))
        self.band = np.array(
            [-1 if p is None else int(band_of(p.family, p.froude(v[c]), p.band_scale))
             for c, p in enumerate(self.params)], dtype=np.int64)
        self.n_changes = np.zeros(len(self.params), dtype=np.int64)
        self._speed = v.copy()
        # each character's last (band, speed, gait): at a steady speed the same gait is asked
        # for frame after frame, and building it cost more than the rest of the update
        self._last: list[tuple[int, float, Gait] | None] = [None] * len(self.params)
        # what next_band and froude read of each character, made once: the characters with
        # an auto gait, their boundaries (scaled), hysteresis and g * size
        self._auto = [c for c, p in enumerate(self.params) if p is not None]
        self._edges = [p.family.boundaries() * p.band_scale ** 2 if p is not None else None
                       for p in self.params]
        self._g_size = np.array([p.g * max(float(p.size), 1e-9) for c in self._auto
                                 if (p := self.params[c]) is not None], dtype=np.float64)

    def gaits(self, fallback: Sequence[Gait]) -> list[Gait]:
        """Starting gaits: the auto gait at the starting speed, else ``fallback[c]``."""
        return [fallback[c] if p is None else p.gait(int(self.band[c]), float(self._speed[c]))
                for c, p in enumerate(self.params)]

    def update(self, manager: GaitManager, speed: npt.ArrayLike) -> None:
        """Retarget ``manager``'s characters for speeds ``(C,)`` m/s (non-finite: 0)."""
        v = np.empty(len(self.params))
        v[...] = speed  # (one for all, or one each)
        v = np.where(np.isfinite(v), np.abs(v), 0.0)
        auto = self._auto
        if not auto:
            return
        # every character's Froude number at once (froude's arithmetic), then next_band's
        # tests in plain floats with each character's boundaries made once
        speeds = v[auto]
        frs: list[float] = (speeds * speeds / self._g_size).tolist()
        speed_list: list[float] = speeds.tolist()
        bands: list[int] = self.band.tolist()
        kept_chars: list[int] = []
        kept_gaits: list[Gait] = []
        for c, fr, speed in zip(auto, frs, speed_list, strict=True):
            p = self.params[c]
            edges = self._edges[c]
            assert p is not None
            assert edges is not None
            band = bands[c]
            up, down = 1.0 + p.hysteresis, 1.0 - p.hysteresis
            while band < edges.size and fr > edges[band] * up:
                band += 1
            while band > 0 and fr < edges[band - 1] * down:
                band -= 1
            last = self._last[c]
            if last is not None and last[0] == band and last[1] == speed:
                gait = last[2]
            else:
                gait = p.gait(band, speed)
                self._last[c] = (band, speed, gait)
            if band != bands[c]:
                time = p.transition_cycles * float(manager.cycle_time[c])
                manager.start_transition([c], [gait], time)
                self.band[c] = band
                self.n_changes[c] += 1
            else:
                kept_chars.append(c)
                kept_gaits.append(gait)
        if kept_chars:
            manager.retarget_many(kept_chars, kept_gaits)
