# SPDX-License-Identifier: GPL-3.0-or-later
"""Registered property groups carry no Python functions where Blender 4.2 cannot bear them.

Blender 4.2 crashes at exit once an extension was uninstalled whose property groups hold
Python functions: methods, or ``update``/``poll``/``get``/``set`` callbacks (4.5 does not).
CI runs the newest Blender, so this checks the classes themselves; the 4.2 job's packaging
test shows the crash itself.
"""

from __future__ import annotations

import inspect
from typing import Any

import bpy

from procloco_addon.blender import registration

# Callbacks allowed where the running Blender bears them: (class, property, keyword).
ALLOWED_FROM_4_5 = {("PROCLOCO_PG_rig_settings", "path", "poll")}

GROUPS = [cls for cls in registration.CLASSES if issubclass(cls, bpy.types.PropertyGroup)]


def _callbacks(cls: type) -> set[tuple[str, str, str]]:
    found = set()
    for name, prop in getattr(cls, "__annotations__", {}).items():
        keywords: dict[str, Any] = getattr(prop, "keywords", {})
        for key, value in keywords.items():
            if callable(value) and not isinstance(value, type):
                found.add((cls.__name__, name, key))
    return found


def test_property_groups_define_no_methods() -> None:
    assert GROUPS, "no property groups registered?"
    methods = [
        f"{cls.__name__}.{name}"
        for cls in GROUPS
        for name, value in vars(cls).items()
        if not name.startswith("__") and (inspect.isfunction(value) or isinstance(value, (staticmethod,
                                                                                         classmethod)))
    ]
    assert methods == []


def test_property_callbacks_only_where_blender_bears_them() -> None:
    found = set().union(*(_callbacks(cls) for cls in GROUPS))
    if bpy.app.version >= (4, 5, 0):
        assert found <= ALLOWED_FROM_4_5
        assert found == ALLOWED_FROM_4_5  # the path picker still filters curves where it can
    else:
        assert found == set()
