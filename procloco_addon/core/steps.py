# SPDX-License-Identifier: GPL-3.0-or-later
"""Work done in steps: a generator that yields the fraction done (so a caller can show
progress and stop it by closing it) and returns its result. These run one through, or map
its fractions onto a share of a larger job."""

from __future__ import annotations

from collections.abc import Generator
from typing import Any, TypeVar

__all__ = ["run_steps", "scaled_steps"]

_T = TypeVar("_T")


def run_steps(steps: Generator[Any, None, _T]) -> _T:
    """Run ``steps`` to its end and return its result."""
    while True:
        try:
            next(steps)
        except StopIteration as done:
            result: _T = done.value
            return result


def scaled_steps(steps: Generator[float, None, _T], low: float, high: float) -> Generator[float, None, _T]:
    """``steps`` with its fractions mapped onto ``[low, high]``; returns its result."""
    while True:
        try:
            fraction = next(steps)
        except StopIteration as done:
            result: _T = done.value
            return result
        yield low + (high - low) * fraction
