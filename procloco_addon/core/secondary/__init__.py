# SPDX-License-Identifier: GPL-3.0-or-later
"""Secondary motion (thesis chapter 5): ``pendulum``, time-based spring-dampers and trees of
3D pendulums that tails, antennae and ears follow, baked after the walk."""
