# SPDX-License-Identifier: GPL-3.0-or-later
"""Make Cycle: game-ready loops of whole gait cycles (settings, operator, panel)."""
