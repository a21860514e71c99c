# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Preview: the walk re-generated in slices, from a timer, while its settings are edited."""
