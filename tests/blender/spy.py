"""Counting the calls of a function a test wants to see made (or not made)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest


def spy(monkeypatch: pytest.MonkeyPatch, owner: Any, name: str,
        note: Callable[..., Any]) -> list[Any]:
    """Replace ``owner.name`` for the test by a function that calls it as before and appends
    ``note(*args)`` to the list returned, once per call (e.g. ``lambda obj, *_: obj.name``)."""
    real = getattr(owner, name)
    calls: list[Any] = []

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls.append(note(*args))
        return real(*args, **kwargs)

    monkeypatch.setattr(owner, name, counted)
    return calls
