# SPDX-License-Identifier: GPL-3.0-or-later
"""Numpy-only locomotion algorithms.

Nothing in this package imports ``bpy``, ``mathutils`` or any other Blender module: every
algorithm takes plain arrays and small dataclasses and returns arrays, so it can be unit
tested and benchmarked outside Blender. Units: metres, seconds, radians; Z is up.
"""
