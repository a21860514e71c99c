# SPDX-License-Identifier: GPL-3.0-or-later
"""The Blender shell: reads rigs and scenes, runs the core, writes Actions."""
