# SPDX-License-Identifier: GPL-3.0-or-later
"""Legged locomotion: the character controller (thesis §3.2, §3.6, §4.1, §4.2), split by
concern. ``controller.Controller`` is the orchestrator; every other module owns one concern
and is plain functions on arrays:

- ``types``: ``ControllerParams``, ``PlannerLOD``, ``StepControls``, ``StepStats``;
- ``state``: per-foot state, a ``Phase`` per foot plus its ``SwingPlan``;
- ``rig``: fixed per-rig geometry and the stride rule (needle speed-up);
- ``planning``: plan orchestration around the footprint planner (``core.footprints``);
- ``obstacles``: moving obstacles, supports under planted feet, push-out;
- ``fallback``: the straight-step planner of last resort;
- ``pelvis``: hull pose, feet-error feedback, pogo particles;
- ``spine_link``: the spine groups (``core.spine``) inside the step;
- ``reach``: reach guard, stretched legs, IK;
- ``stepping``: the foot-state rules of a step (landings, forced steps, swing timing);
- ``profile``: the per-phase timer of a step.
"""
