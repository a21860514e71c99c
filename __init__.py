# SPDX-License-Identifier: GPL-3.0-or-later
"""ProcLoco extension entry point.

Blender loads this file from the root of the extension zip. All code lives in the
``procloco_addon`` package beside it, so that the same package can be imported as a
plain Python package (``import procloco_addon.core``) by tests and benchmarks without
going through Blender's extension machinery.
"""

from .procloco_addon import register, unregister

__all__ = ["register", "unregister"]
