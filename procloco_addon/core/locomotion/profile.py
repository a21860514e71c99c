# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-phase timing of a controller step, kept out of the logic: the orchestrator wraps each
phase's calls in ``Profiler.phase``; what is left of the step is ``rest``."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager


class Profiler:
    """Accumulates seconds of ``clock`` into ``into[name]`` per phase; ``finish`` books the
    step's time outside every phase as ``rest``."""

    def __init__(self, into: dict[str, float], clock: Callable[[], float] = time.perf_counter) -> None:
        self.into = into
        self.clock = clock
        self.start = clock()
        self.inside = 0.0

    @contextmanager
    def phase(self, name: str) -> Iterator[None]:
        """Time the block as phase ``name``."""
        t0 = self.clock()
        try:
            yield
        finally:
            spent = self.clock() - t0
            self.into[name] = self.into.get(name, 0.0) + spent
            self.inside += spent

    def finish(self) -> None:
        """Book the time since the start outside every phase as ``rest``."""
        self.into["rest"] = self.into.get("rest", 0.0) + self.clock() - self.start - self.inside
