# SPDX-License-Identifier: GPL-3.0-or-later
"""Builders for ``examples.blend``: creatures, terrain and the scene around them.

``creatures`` makes rigged, skinned example creatures; ``terrain`` the heightmap ground
with crates, stairs and a gap; ``scene`` the camera, light and render settings.
``tools/build_examples.py`` puts them together and saves ``examples.blend``.
These modules need ``bpy`` (Blender as a Python module); they are development tools and
are not shipped in the extension zip.
"""
