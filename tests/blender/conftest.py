# SPDX-License-Identifier: GPL-3.0-or-later
"""Fixtures for tests that run Blender as a Python module.

``procloco`` registers the add-on once per session straight from the source package
(``procloco_addon.register()``) and gives every test an empty scene through
``bpy.ops.wm.read_homefile(use_empty=True)``, so tests never leak state into each other.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import bpy
import pytest


@pytest.fixture(scope="session")
def procloco_registered() -> Iterator[Any]:
    import procloco_addon

    procloco_addon.register()
    yield procloco_addon
    procloco_addon.unregister()


@pytest.fixture
def empty_scene(procloco_registered: Any) -> Any:
    """A fresh empty scene with the add-on registered."""
    bpy.ops.wm.read_homefile(use_empty=True)
    return bpy.context.scene
