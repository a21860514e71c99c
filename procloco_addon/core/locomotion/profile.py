# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-phase timing of a controller step, kept out of the logic: the orchestrator wraps each
phase's calls in ``Profiler.phase``; what is left of the step is ``rest``."""

from __future__ import annotations

import time
from collections.abc import Callable
from types import TracebackType


class _Phase:
    """The context of one phase of a :class:`Profiler` (a plain class: a generator-based
    context manager cost more than some of the phases it timed)."""

    __slots__ = ("name", "profiler", "t0")

    def __init__(self, profiler: Profiler, name: str) -> None:
        self.profiler = profiler
        self.name = name
        self.t0 = 0.0

    def __enter__(self) -> None:
        self.t0 = self.profiler.clock()

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        p = self.profiler
        spent = p.clock() - self.t0
        p.into[self.name] = p.into.get(self.name, 0.0) + spent
        p.inside += spent


class Profiler:
    """Accumulates seconds of ``clock`` into ``into[name]`` per phase; ``finish`` books the
    step's time outside every phase as ``rest``."""

    def __init__(self, into: dict[str, float], clock: Callable[[], float] = time.perf_counter) -> None:
        self.into = into
        self.clock = clock
        self.start = clock()
        self.inside = 0.0

    def phase(self, name: str) -> _Phase:
        """Time the block (``with profiler.phase(name):``) as phase ``name``."""
        return _Phase(self, name)

    def finish(self) -> None:
        """Book the time since the start outside every phase as ``rest``."""
        self.into["rest"] = self.into.get("rest", 0.0) + self.clock() - self.start - self.inside
