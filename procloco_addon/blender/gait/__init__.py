# SPDX-License-Identifier: GPL-3.0-or-later
"""Gait circles in the interface: the drawn picture, the viewport overlay, gait presets."""
