# SPDX-License-Identifier: GPL-3.0-or-later
"""ProcLoco: procedural locomotion for legged rigs.

``core`` is numpy-only and importable anywhere; ``blender`` holds everything that touches
``bpy`` and is only imported when Blender registers the extension.
"""


def register() -> None:
    from .blender import registration

    registration.register()


def unregister() -> None:
    from .blender import registration

    registration.unregister()
