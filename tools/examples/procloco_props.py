# SPDX-License-Identifier: GPL-3.0-or-later
"""Setting ProcLoco's saved properties on example objects.

The examples only *set* ``Object.procloco_role`` (terrain role) and ``Object.procloco``
(per-rig locomotion settings); the add-on registers and owns them. The helpers set what is
registered and return the names they could not set, so the build script can say what is
still missing instead of failing, and a test can insist on it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import bpy

#: The terrain roles of ``Object.procloco_role``.
ROLES = ("AUTO", "GROUND", "STEP_OVER", "AVOID", "IGNORE")


def role_registered() -> bool:
    """True when the add-on has registered ``Object.procloco_role``."""
    return "procloco_role" in bpy.types.Object.bl_rna.properties


def set_role(obj: bpy.types.Object, role: str) -> bool:
    """Give ``obj`` its terrain role; False (and nothing set) while the property is not registered."""
    if role not in ROLES:
        raise ValueError(f"unknown terrain role {role!r}; expected one of {ROLES}")
    if not role_registered():
        return False
    obj.procloco_role = role
    return True


def apply_rig_settings(obj: bpy.types.Object, settings: Mapping[str, Any]) -> list[str]:
    """Set each ``name: value`` of ``settings`` on ``obj.procloco``.

    Returns the names that are not (yet) properties of the rig settings group; those are
    skipped. Values that the property refuses (wrong type, unknown enum item) raise.
    """
    if "procloco" not in bpy.types.Object.bl_rna.properties:
        return sorted(settings)
    group = obj.procloco
    known = group.bl_rna.properties
    missing: list[str] = []
    for key, value in settings.items():
        if key not in known:
            missing.append(key)
            continue
        setattr(group, key, value)
    return missing
