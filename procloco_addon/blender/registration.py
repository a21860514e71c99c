# SPDX-License-Identifier: GPL-3.0-or-later
"""The one place where ProcLoco's Blender classes and properties are registered.

``CLASSES`` lists every class in registration order (property groups before the groups
and panels that use them). ``POINTERS`` lists the ``PointerProperty`` attachments made
on Blender ID types. ``unregister`` undoes both in reverse order, so enabling and
disabling the extension any number of times leaves nothing behind.
"""

from __future__ import annotations

import bpy

from .locomotion import property_group as locomotion_props

CLASSES: tuple[type, ...] = (
    locomotion_props.PROCLOCO_PG_rig_settings,
)

# (owner ID type, attribute name, property group class)
POINTERS: tuple[tuple[type, str, type], ...] = (
    (bpy.types.Object, "procloco", locomotion_props.PROCLOCO_PG_rig_settings),
)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for owner, attr, group in POINTERS:
        setattr(owner, attr, bpy.props.PointerProperty(type=group))


def unregister() -> None:
    for owner, attr, _group in reversed(POINTERS):
        if hasattr(owner, attr):
            delattr(owner, attr)
    for cls in reversed(CLASSES):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
