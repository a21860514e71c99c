# SPDX-License-Identifier: GPL-3.0-or-later
"""The ProcLoco sidebar tab: the parent panel every feature's sub-panels hang from."""
