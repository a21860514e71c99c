# SPDX-License-Identifier: GPL-3.0-or-later
"""Work in steps: run through, or its fractions mapped onto a share of a larger job."""

from __future__ import annotations

from collections.abc import Generator

import pytest

from procloco_addon.core.steps import run_steps, scaled_steps


def _work(log: list[float]) -> Generator[float, None, str]:
    for f in (0.25, 0.5, 1.0):
        log.append(f)
        yield f
    return "done"


def test_run_steps_runs_every_step_and_returns_the_result() -> None:
    log: list[float] = []
    assert run_steps(_work(log)) == "done"
    assert log == [0.25, 0.5, 1.0]


def test_scaled_steps_maps_the_fractions_and_keeps_the_result() -> None:
    outer = scaled_steps(_work([]), 0.5, 0.9)
    seen = [next(outer) for _ in range(3)]
    with pytest.raises(StopIteration) as done:
        next(outer)
    assert done.value.value == "done"
    assert seen == pytest.approx([0.6, 0.7, 0.9], abs=1e-15)


def test_closing_the_scaled_steps_stops_the_work() -> None:
    log: list[float] = []
    outer = scaled_steps(_work(log), 0.0, 1.0)
    next(outer)
    outer.close()
    assert log == [0.25]
