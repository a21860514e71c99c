# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate Locomotion: settings, operators and panel for the multi-legged walk."""
