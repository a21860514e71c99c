# SPDX-License-Identifier: GPL-3.0-or-later
"""The quality shown after each Generate Locomotion: figures measured on the posed rig."""
