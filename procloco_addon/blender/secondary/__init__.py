# SPDX-License-Identifier: GPL-3.0-or-later
"""Secondary motion: 3D pendulums on tails, antennae and ears, baked into a new Action."""
