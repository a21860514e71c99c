# SPDX-License-Identifier: GPL-3.0-or-later
"""The world the creatures walk in, shared by every system (thesis §3.4):

- ``terrain``: the environment (heightmap, boxes, triangle soups, moving obstacles) and the
  per-character planning windows (elevation, forbidden cells, foot-size dilation);
- ``pathing``: paths over a window (octile wavefront, line of sight, cardinal curves, the
  hull-lifted height profile): one foot trajectory sampled at constant speed.
"""
