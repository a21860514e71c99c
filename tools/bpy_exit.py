# SPDX-License-Identifier: GPL-3.0-or-later
"""Leave a process that imported the ``bpy`` module with the right exit status.

The Blender 4.2 wheel crashes (SIGSEGV) while the interpreter shuts down once an add-on
whose property groups carry Python callbacks has been enabled — Rigify is one — even after
all work is done and files are saved; 4.5 and 5.x exit cleanly. On those older wheels the
dev scripts and the test session therefore end with ``os._exit`` after flushing their output,
so the exit status is the script's own and not the crash's.
"""

from __future__ import annotations

import os
import sys
from typing import NoReturn

FIRST_CLEAN_EXIT = (4, 5, 0)


def needs_hard_exit() -> bool:
    """True when ``bpy`` is loaded and is a version that crashes at interpreter exit."""
    bpy = sys.modules.get("bpy")
    version = getattr(getattr(bpy, "app", None), "version", None)
    return version is not None and tuple(version) < FIRST_CLEAN_EXIT


def exit_process(code: int) -> NoReturn:
    """``sys.exit(code)``, or on a crashing Blender wheel a flushed ``os._exit(code)``."""
    if needs_hard_exit():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
