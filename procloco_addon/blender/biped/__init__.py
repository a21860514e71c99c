# SPDX-License-Identifier: GPL-3.0-or-later
"""The biped feature: a clip database on the rig, and Plan Biped Footsteps."""
