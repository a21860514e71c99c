# SPDX-License-Identifier: GPL-3.0-or-later
"""Biped footprint planner with clip blending (the biped thesis, chapter 3).

One module per stage, in pipeline order:

* :mod:`.skeleton`, :mod:`.clip`, :mod:`.database` — the biped, its clips (role tags,
  foot contacts given or detected) and the clips analysed on a common phase grid;
* :mod:`.synth` — a procedural clip synthesiser (walks on arcs, runs, a jump, start,
  stop, idle) so nothing needs motion capture; :mod:`.scenarios` — test worlds;
* :mod:`.surface` — walkable surfaces: heights, platforms (islands), snapping;
* :mod:`.graph` — the footprint graph and A* (§3.2);
* :mod:`.smoothing` — binomial smoothing of positions and rotation logs (§3.3);
* :mod:`.blending` — playback with the most stable blend point (§3.4);
* :mod:`.refine` — refinement by local similarity maps (§3.5);
* :mod:`.trajectory` — body trajectory from footprint midpoints (§3.6);
* :mod:`.blend_groups` — turning by curvature, walk/run by speed (§3.7);
* :mod:`.ik` — body offset and leg swivel, holding the lower of heel and toe (§3.8);
* :mod:`.planner` — all of it: :func:`~.planner.plan_biped`.

Numpy only; no ``bpy``.
"""

from .clip import Clip, ClipRole
from .database import ClipDatabase
from .graph import GoalOffSurfaceError, GoalUnreachableError, NoClipsError, PlanCancelled, PlanningError
from .planner import BipedMotion, PlannerSettings, plan_biped
from .skeleton import LegJoints, Skeleton
from .surface import WalkableSurface

__all__ = [
    "BipedMotion",
    "Clip",
    "ClipDatabase",
    "ClipRole",
    "GoalOffSurfaceError",
    "GoalUnreachableError",
    "LegJoints",
    "NoClipsError",
    "PlanCancelled",
    "PlannerSettings",
    "PlanningError",
    "Skeleton",
    "WalkableSurface",
    "plan_biped",
]
