# SPDX-License-Identifier: GPL-3.0-or-later
"""Key Reduction: the generated Actions' keys thinned to the ones an animator needs."""
