# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait circles, the needle, gait transitions and gait presets (thesis §3.3).

A gait gives each leg a *disk*: the swing phase is the arc ``[start, start + duration)`` of
the cycle (fractions, mod 1); the rest of the circle is stance. A needle per character
turns once per cycle; a leg is in swing while the needle is inside its sector.

Transitions (thesis §3.3, figure 3.11): the start of each source sector is interpolated
toward the start of its destination sector, and the duration linearly. The direction is
the one that does not pass over the *finish* of the destination sector: the union of both
sectors is where the interpolation may go, the rest of the circle is forbidden. A leg's
disk is replaced by the interpolated one only while the leg is in stance, and only when the
swap does not drop the needle in the middle of the new sector, so a foot never lifts for a
truncated swing and never lands early ("no foot popping").

Presets are JSON files (``presets/gait/*.json``, format in ``docs/DEVELOPING.md``) read by
``load_gait_preset``, which rejects malformed files with a ``GaitPresetError`` naming the
file and the problem.

``GaitManager`` runs the needles and disks of many characters at once: characters are
``(C,)`` arrays, legs are one flat ``(N,)`` axis with ``leg_char`` saying whose leg it is
(see ``morphology.LegBatch``).
"""

from __future__ import annotations

import functools
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..geometry import clip

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

PRESET_FORMAT = "procloco.gait/1"
_LABEL = re.compile(r"^[LRM][1-9][0-9]*$")


class GaitError(ValueError):
    """A gait that cannot be used (bad fractions, wrong leg count...)."""


class GaitPresetError(GaitError):
    """A malformed gait preset file; the message names the file and the problem."""


# ---------------------------------------------------------------------------- circle helpers
_PHASE_EPS = 1e-9  # a needle this close below a sector's start counts as on it (float round-off)


def swing_elapsed(phase: npt.ArrayLike, start: npt.ArrayLike) -> FloatArray:
    """Cycle fraction since the sector's start, in ``[0, 1)`` (the swing's age while in swing)."""
    rel = np.mod(np.asarray(phase, dtype=np.float64) - np.asarray(start, dtype=np.float64), 1.0)
    return np.where(rel > 1.0 - _PHASE_EPS, 0.0, rel)


def in_swing(phase: npt.ArrayLike, start: npt.ArrayLike, duration: npt.ArrayLike) -> BoolArray:
    """Whether the needle at ``phase`` is inside the swing arc ``[start, start + duration)``."""
    return np.asarray(swing_elapsed(phase, start) < np.asarray(duration, dtype=np.float64) - _PHASE_EPS)


def stance_elapsed(phase: npt.ArrayLike, start: npt.ArrayLike, duration: npt.ArrayLike) -> FloatArray:
    """Cycle fraction since the sector's finish (touch-down), in ``[0, 1)``."""
    finish = np.asarray(start, dtype=np.float64) + np.asarray(duration, dtype=np.float64)
    return swing_elapsed(phase, finish)


def transition_direction(
    src_start: npt.ArrayLike, dst_start: npt.ArrayLike, dst_duration: npt.ArrayLike
) -> FloatArray:
    """+1 to move a sector's start forward (with the needle), -1 backward (thesis §3.3).

    Forward sweeps the arc ``src_start -> dst_start``; if the destination's finish
    ``dst_start + dst_duration`` lies strictly inside that arc, going forward would cross
    the forbidden zone, so the start moves backward instead.
    """
    s = np.asarray(src_start, dtype=np.float64)
    d = np.asarray(dst_start, dtype=np.float64)
    forward_arc = np.mod(d - s, 1.0)
    finish_at = np.mod(d + np.asarray(dst_duration, dtype=np.float64) - s, 1.0)
    crosses = (finish_at > 0.0) & (finish_at < forward_arc)
    return np.where(crosses, -1.0, 1.0)


def interpolate_disks(
    src_start: FloatArray,
    src_duration: FloatArray,
    dst_start: FloatArray,
    dst_duration: FloatArray,
    direction: FloatArray,
    amount: FloatArray | float,
) -> tuple[FloatArray, FloatArray]:
    """Disks ``amount`` (0..1) of the way from source to destination, along ``direction``."""
    lam = clip(np.asarray(amount, dtype=np.float64), 0.0, 1.0)
    forward = np.mod(dst_start - src_start, 1.0)
    arc = np.where(direction > 0.0, forward, forward - 1.0)
    arc = np.where(forward == 0.0, 0.0, arc)
    start = np.mod(src_start + lam * arc, 1.0)
    start = np.where(start >= 1.0, 0.0, start)  # mod of a tiny negative number rounds to 1.0
    start = np.where(lam >= 1.0, dst_start, np.where(lam <= 0.0, np.mod(src_start, 1.0), start))
    duration = src_duration + lam * (dst_duration - src_duration)
    return start, duration


# ---------------------------------------------------------------------------- gait data
@dataclass(frozen=True, eq=False)
class Gait:
    """Gait circles of one character: per leg ``swing_start`` and ``swing_duration`` as
    cycle fractions (``(n_legs,)``, start in [0, 1), duration in (0, 1)), and the cycle time
    in seconds. Legs are in the character's label order."""

    swing_start: FloatArray
    swing_duration: FloatArray
    cycle_time: float
    name: str = ""

    def __post_init__(self) -> None:
        start = np.asarray(self.swing_start, dtype=np.float64).reshape(-1)
        duration = np.asarray(self.swing_duration, dtype=np.float64).reshape(-1)
        if start.shape != duration.shape or start.size == 0:
            raise GaitError("swing_start and swing_duration need one value per leg")
        if not np.all(np.isfinite(start)) or not np.all(np.isfinite(duration)):
            raise GaitError("gait fractions must be finite")
        if np.any(duration <= 0.0) or np.any(duration >= 1.0):
            bad = int(np.flatnonzero((duration <= 0.0) | (duration >= 1.0))[0])
            raise GaitError(
                f"leg {bad}: swing duration {duration[bad]:g} must be strictly between 0 and 1 "
                "(a zero or full-cycle swing never touches or never leaves the ground)"
            )
        if not (math.isfinite(self.cycle_time) and self.cycle_time > 0.0):
            raise GaitError(f"cycle time must be positive, got {self.cycle_time!r}")
        object.__setattr__(self, "swing_start", np.mod(start, 1.0))
        object.__setattr__(self, "swing_duration", duration)

    @property
    def n_legs(self) -> int:
        return int(self.swing_start.shape[0])

    def in_swing(self, phase: npt.ArrayLike) -> BoolArray:
        """``(..., n_legs)`` swing flags for needle phases of shape ``(...)``."""
        ph = np.asarray(phase, dtype=np.float64)[..., None]
        return in_swing(ph, self.swing_start, self.swing_duration)

    def with_cycle_time(self, cycle_time: float) -> Gait:
        return Gait(self.swing_start.copy(), self.swing_duration.copy(), cycle_time, self.name)


@dataclass(frozen=True, eq=False)
class GaitPreset:
    """A gait preset file's content. ``speed`` is in leg lengths per second and
    ``step_height`` in leg lengths (multiply by a rig's leg length for metres)."""

    name: str
    legs: tuple[str, ...]
    swing_start: FloatArray
    swing_duration: FloatArray
    cycle_time: float
    speed: float
    step_height: float
    source: str
    path: Path | None = field(default=None, compare=False)

    def gait(self, labels: Sequence[str] | None = None) -> Gait:
        """The gait for legs named ``labels`` (default the preset's own order).

        Raises ``GaitError`` when a label is not in the preset or the counts differ.
        """
        if labels is None:
            order = np.arange(len(self.legs))
        else:
            labels_t = tuple(labels)
            missing = [lb for lb in labels_t if lb not in self.legs]
            if missing or len(labels_t) != len(self.legs):
                raise GaitError(
                    f"gait preset {self.name!r} is for legs {', '.join(self.legs)}; "
                    f"the character has {', '.join(labels_t)}"
                )
            order = np.array([self.legs.index(lb) for lb in labels_t])
        return Gait(
            self.swing_start[order].copy(), self.swing_duration[order].copy(), self.cycle_time, self.name
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "format": PRESET_FORMAT,
            "name": self.name,
            "legs": list(self.legs),
            "swing_start": [float(v) for v in self.swing_start],
            "swing_duration": [float(v) for v in self.swing_duration],
            "cycle_time": self.cycle_time,
            "speed": self.speed,
            "step_height": self.step_height,
            "source": self.source,
        }


@functools.cache
def gait_preset_dir() -> Path:
    """The folder of the shipped gait presets (``presets/gait`` at the extension root)."""
    return Path(__file__).resolve().parents[3] / "presets" / "gait"


# Preset files listed, by folder: the folder's modification time then and its files.
_listed: dict[Path, tuple[int, list[Path]]] = {}


def list_gait_presets(directory: Path | None = None) -> list[Path]:
    """Preset files in ``directory`` (default the shipped ones), sorted by file name (listed
    again only once the folder changed: a file added, removed or renamed)."""
    folder = gait_preset_dir() if directory is None else Path(directory)
    try:
        stamp = folder.stat().st_mtime_ns
    except OSError:
        return []
    known = _listed.get(folder)
    if known is None or known[0] != stamp:
        known = (stamp, sorted(folder.glob("*.json")))
        _listed[folder] = known
    return list(known[1])


def _fail(path: Path | str, problem: str) -> GaitPresetError:
    return GaitPresetError(f"gait preset {Path(path).name}: {problem}")


def parse_gait_preset(data: Any, path: Path | str = "<data>") -> GaitPreset:
    """Validate a decoded preset (``dict``) and build a ``GaitPreset``."""
    if not isinstance(data, dict):
        raise _fail(path, "the file must hold one JSON object")
    if data.get("format") != PRESET_FORMAT:
        raise _fail(path, f"'format' must be {PRESET_FORMAT!r}, got {data.get('format')!r}")
    required = (
        "name",
        "legs",
        "swing_start",
        "swing_duration",
        "cycle_time",
        "speed",
        "step_height",
        "source",
    )
    missing = [k for k in required if k not in data]
    if missing:
        raise _fail(path, f"missing field(s): {', '.join(missing)}")
    for key in ("name", "source"):
        if not isinstance(data[key], str) or not data[key].strip():
            raise _fail(path, f"'{key}' must be a non-empty string")
    legs = data["legs"]
    if not isinstance(legs, list) or not legs or not all(isinstance(lb, str) for lb in legs):
        raise _fail(path, '\'legs\' must be a non-empty list of labels such as "L1", "R1"')
    bad_labels = [lb for lb in legs if not _LABEL.match(lb)]
    if bad_labels:
        raise _fail(path, f"leg labels must look like L1, R1, M3: got {', '.join(map(repr, bad_labels))}")
    if len(set(legs)) != len(legs):
        raise _fail(path, "leg labels are not unique")

    def numbers(key: str) -> FloatArray:
        values = data[key]
        if (
            not isinstance(values, list)
            or len(values) != len(legs)
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
        ):
            raise _fail(path, f"'{key}' must be a list of {len(legs)} numbers (one per leg)")
        arr = np.asarray(values, dtype=np.float64)
        if not np.all(np.isfinite(arr)):
            raise _fail(path, f"'{key}' has a non-finite value")
        return arr

    start = numbers("swing_start")
    duration = numbers("swing_duration")
    if np.any(start < 0.0) or np.any(start >= 1.0):
        raise _fail(path, "'swing_start' values must be cycle fractions in [0, 1)")
    bad = np.flatnonzero((duration <= 0.0) | (duration >= 1.0))
    if bad.size:
        raise _fail(
            path,
            f"leg {legs[int(bad[0])]}: 'swing_duration' must be in (0, 1); "
            "a zero or full-cycle swing never touches or never leaves the ground",
        )

    def positive(key: str, allow_zero: bool) -> float:
        v = data[key]
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise _fail(path, f"'{key}' must be a number")
        if v < 0.0 or (v == 0.0 and not allow_zero):
            raise _fail(path, f"'{key}' must be {'>= 0' if allow_zero else '> 0'}, got {v}")
        return float(v)

    return GaitPreset(
        name=data["name"].strip(),
        legs=tuple(legs),
        swing_start=start,
        swing_duration=duration,
        cycle_time=positive("cycle_time", False),
        speed=positive("speed", True),
        step_height=positive("step_height", True),
        source=data["source"].strip(),
        path=Path(path) if not isinstance(path, Path) else path,
    )


# Presets read, by path: the file's (modification time, size) when read and its preset.
_loaded: dict[Path, tuple[tuple[int, int], GaitPreset]] = {}


def load_gait_preset(path: Path | str) -> GaitPreset:
    """Read and validate a gait preset file; ``GaitPresetError`` says what is wrong. A file
    read before and unchanged since (its modification time and size) is not read again
    (Generate on a hundred rigs looks the shipped presets up for each); the preset's arrays
    are read-only."""
    p = Path(path)
    try:
        stat = p.stat()
        known = _loaded.get(p)
        if known is not None and known[0] == (stat.st_mtime_ns, stat.st_size):
            return known[1]
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise _fail(p, f"cannot be read ({exc.strerror or exc})") from exc
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _fail(p, f"is not valid JSON (line {exc.lineno}: {exc.msg})") from exc
    preset = parse_gait_preset(data, p)
    preset.swing_start.setflags(write=False)
    preset.swing_duration.setflags(write=False)
    _loaded[p] = ((stat.st_mtime_ns, stat.st_size), preset)
    return preset


def find_gait_preset(name: str, directory: Path | None = None) -> GaitPreset:
    """The shipped preset with file stem or display name ``name`` (case-insensitive)."""
    wanted = name.strip().lower()
    for path in list_gait_presets(directory):
        if path.stem.lower() == wanted:
            return load_gait_preset(path)
    for path in list_gait_presets(directory):
        preset = load_gait_preset(path)
        if preset.name.lower() == wanted:
            return preset
    raise GaitPresetError(f"no gait preset named {name!r}")


# ---------------------------------------------------------------------------- the manager
@dataclass(frozen=True, eq=False)
class GaitStep:
    """What happened to the legs during one ``GaitManager.advance``.

    - ``swing``: ``(N,)`` legs in swing after the step.
    - ``lifted`` / ``landed``: ``(N,)`` legs that left / touched the ground during the step.
    - ``swing_progress``: ``(N,)`` fraction of the current swing done (0 in stance).
    - ``stance_progress``: ``(N,)`` fraction of the current stance done (0 in swing).
    - ``swing_time`` / ``stance_time``: ``(N,)`` current durations in seconds at the
      needle's current rate.
    - ``swapped``: ``(N,)`` legs whose disk was replaced this step.
    """

    swing: BoolArray
    lifted: BoolArray
    landed: BoolArray
    swing_progress: FloatArray
    stance_progress: FloatArray
    swing_time: FloatArray
    stance_time: FloatArray
    swapped: BoolArray


class GaitManager:
    """Needles and disks of many characters (thesis §3.3), stepped together.

    ``leg_char (N,)`` maps each leg to its character; ``gaits`` holds one ``Gait`` per
    character (legs in the same order as that character's rows of the flat leg axis);
    ``phase (C,)`` is each needle's starting position.
    """

    def __init__(self, leg_char: IntArray, gaits: Sequence[Gait], phase: npt.ArrayLike | None = None) -> None:
        self.leg_char = np.asarray(leg_char, dtype=np.int64)
        n_chars = len(gaits)
        counts = np.bincount(self.leg_char, minlength=n_chars)
        for c, g in enumerate(gaits):
            if g.n_legs != counts[c]:
                raise GaitError(
                    f"character {c}: gait {g.name!r} has {g.n_legs} legs, the character {counts[c]}"
                )
        self.n_chars = n_chars
        self.time = 0.0
        self.needle = (
            np.zeros(n_chars)
            if phase is None
            else np.mod(np.broadcast_to(np.asarray(phase, dtype=np.float64), (n_chars,)).copy(), 1.0)
        )
        self.disk_start: FloatArray = np.concatenate([g.swing_start for g in gaits])
        self.disk_duration: FloatArray = np.concatenate([g.swing_duration for g in gaits])
        self.cycle_time: FloatArray = np.array([g.cycle_time for g in gaits], dtype=np.float64)
        self.rate_scale: FloatArray = np.ones(n_chars)
        self.swing = in_swing(self.needle[self.leg_char], self.disk_start, self.disk_duration)
        # transition state
        self.tr_active = np.zeros(n_chars, dtype=bool)
        self.tr_t0 = np.zeros(n_chars)
        self.tr_duration = np.ones(n_chars)
        self.src_start = self.disk_start.copy()
        self.src_duration = self.disk_duration.copy()
        self.dst_start = self.disk_start.copy()
        self.dst_duration = self.disk_duration.copy()
        self.direction = np.ones(self.leg_char.shape[0])
        self.src_cycle = self.cycle_time.copy()
        self.dst_cycle = self.cycle_time.copy()
        self.legs_of = [np.flatnonzero(self.leg_char == c) for c in range(n_chars)]  # each character's legs

    # -------------------------------------------------------------- transitions
    def target_disks(self, time: float | None = None) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The interpolated ("computed") disks at ``time``: ``(start (N,), duration (N,),
        cycle_time (C,))``. Outside a transition these are the destination disks."""
        if not np.logical_or.reduce(self.tr_active):
            # no transition: every leg at amount 1 (interpolate_disks' numbers, without its work)
            duration = self.src_duration + (self.dst_duration - self.src_duration)
            return self.dst_start.copy(), duration, self.src_cycle + (self.dst_cycle - self.src_cycle)
        t = self.time if time is None else time
        lam_c = np.where(
            self.tr_active, clip((t - self.tr_t0) / np.maximum(self.tr_duration, 1e-9), 0.0, 1.0), 1.0
        )
        lam = lam_c[self.leg_char]
        start, duration = interpolate_disks(
            self.src_start, self.src_duration, self.dst_start, self.dst_duration, self.direction, lam
        )
        cycle = self.src_cycle + lam_c * (self.dst_cycle - self.src_cycle)
        return start, duration, cycle

    def start_transition(self, chars: npt.ArrayLike, gaits: Sequence[Gait], transition_time: float) -> None:
        """Begin moving characters ``chars`` toward ``gaits`` over ``transition_time`` seconds.

        A transition that starts while another runs begins from the disks interpolated so
        far. ``transition_time`` 0 swaps each leg at its next stance.
        """
        char_idx = np.atleast_1d(np.asarray(chars, dtype=np.int64))
        if len(gaits) != char_idx.size:
            raise GaitError("one gait per character")
        start, duration, cycle = self.target_disks()
        for c, g in zip(char_idx.tolist(), gaits, strict=True):
            legs = self.legs_of[c]
            if g.n_legs != legs.size:
                raise GaitError(
                    f"character {c}: gait {g.name!r} has {g.n_legs} legs, the character {legs.size}"
                )
            self.src_start[legs] = start[legs]
            self.src_duration[legs] = duration[legs]
            self.dst_start[legs] = g.swing_start
            self.dst_duration[legs] = g.swing_duration
            self.direction[legs] = transition_direction(start[legs], g.swing_start, g.swing_duration)
            self.src_cycle[c] = cycle[c]
            self.dst_cycle[c] = g.cycle_time
            self.tr_active[c] = True
            self.tr_t0[c] = self.time
            self.tr_duration[c] = max(float(transition_time), 0.0)

    def retarget(self, char: int, gait: Gait) -> None:
        """Change character ``char``'s destination to ``gait`` without restarting its
        transition: outside a transition the disks become ``gait``'s as each leg reaches
        stance, and the cycle time at once; during one, the transition ends on ``gait``.

        For small changes of the same pattern (the auto gait's duty factor and cycle
        following the speed); a new pattern goes through ``start_transition``.
        """
        legs = self.legs_of[char]
        if gait.n_legs != legs.size:
            raise GaitError(f"character {char}: gait {gait.name!r} has {gait.n_legs} legs, "
                            f"the character {legs.size}")
        self.dst_start[legs] = gait.swing_start
        self.dst_duration[legs] = gait.swing_duration
        self.dst_cycle[char] = gait.cycle_time
        if not self.tr_active[char]:
            self.src_cycle[char] = gait.cycle_time
            self.cycle_time[char] = gait.cycle_time

    def retarget_many(self, chars: Sequence[int], gaits: Sequence[Gait]) -> None:
        """:meth:`retarget` of characters ``chars`` (each once) to ``gaits``, in one pass of
        array operations."""
        if not chars:
            return
        if len(chars) == 1:
            self.retarget(chars[0], gaits[0])
            return
        legs = [self.legs_of[c] for c in chars]
        for c, g, lg in zip(chars, gaits, legs, strict=True):
            if g.n_legs != lg.size:
                raise GaitError(f"character {c}: gait {g.name!r} has {g.n_legs} legs, "
                                f"the character {lg.size}")
        at = np.concatenate(legs)
        self.dst_start[at] = np.concatenate([g.swing_start for g in gaits])
        self.dst_duration[at] = np.concatenate([g.swing_duration for g in gaits])
        ch = np.asarray(chars, dtype=np.int64)
        cycle = np.array([g.cycle_time for g in gaits], dtype=np.float64)
        self.dst_cycle[ch] = cycle
        free = ~self.tr_active[ch]
        self.src_cycle[ch[free]] = cycle[free]
        self.cycle_time[ch[free]] = cycle[free]

    # -------------------------------------------------------------- stepping
    def rate(self) -> FloatArray:
        """``(C,)`` needle speed in cycles per second."""
        return self.rate_scale / self.cycle_time

    def advance(self, dt: float, rate_scale: npt.ArrayLike | None = None) -> GaitStep:
        """Move every needle by ``dt`` seconds; swap disks of legs in stance; report events.

        ``rate_scale (C,)`` multiplies the needle speed (the controller shortens the cycle
        when the stride would outrun the legs).
        """
        if rate_scale is not None:
            self.rate_scale = np.empty(self.n_chars)
            self.rate_scale[...] = rate_scale
        self.time += dt
        # (the disks at the new time serve the cycle time and, below, the disk swap)
        new_start, new_duration, cycle = self.target_disks()
        self.cycle_time = cycle
        step = dt * self.rate()
        self.needle = np.mod(self.needle + step, 1.0)
        needle = self.needle[self.leg_char]
        step_leg = step[self.leg_char]

        # disk swap, only for legs in stance, never dropping the needle deep inside a sector
        changed = (new_start != self.disk_start) | (new_duration != self.disk_duration)
        tol = step_leg + 1e-9
        elapsed_new = swing_elapsed(needle, new_start)
        fresh_new = ~(elapsed_new < new_duration - _PHASE_EPS) | (elapsed_new <= tol)  # (~in_swing | ...)
        swap = changed & ~self.swing & fresh_new
        self.disk_start = np.where(swap, new_start, self.disk_start)
        self.disk_duration = np.where(swap, new_duration, self.disk_duration)
        done = self.tr_active & (self.time - self.tr_t0 >= self.tr_duration)
        if np.logical_or.reduce(done):
            # the transition is complete once every leg of the character holds its final disk
            final = (self.disk_start == self.dst_start) & (self.disk_duration == self.dst_duration)
            all_final = np.bincount(self.leg_char, weights=final.astype(np.float64), minlength=self.n_chars)
            n_legs = np.bincount(self.leg_char, minlength=self.n_chars)
            self.tr_active &= ~(done & (all_final == n_legs))

        was_swing = self.swing
        elapsed = swing_elapsed(needle, self.disk_start)
        self.swing = elapsed < self.disk_duration - _PHASE_EPS  # (in_swing)
        # a swing already under way continues until its own (frozen) sector ends
        lifted = self.swing & ~was_swing
        landed = ~self.swing & was_swing
        swing_progress = np.where(self.swing, elapsed / self.disk_duration, 0.0)
        stance_progress = np.where(
            self.swing,
            0.0,
            stance_elapsed(needle, self.disk_start, self.disk_duration) / (1.0 - self.disk_duration),
        )
        period = 1.0 / self.rate()[self.leg_char]
        return GaitStep(
            swing=self.swing.copy(),
            lifted=lifted,
            landed=landed,
            swing_progress=swing_progress,
            stance_progress=stance_progress,
            swing_time=self.disk_duration * period,
            stance_time=(1.0 - self.disk_duration) * period,
            swapped=swap,
        )
