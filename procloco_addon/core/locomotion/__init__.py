# SPDX-License-Identifier: GPL-3.0-or-later
"""Legged locomotion (thesis chapters 3 and 4): everything from a creature's legs to its walk.

The creature, its gait and the run:

- ``morphology``: legs of any count and segment count, joint limits, body box, spine model;
- ``gait``: gait circles, the needle, transitions; ``autogait``: Gait: Auto (Froude bands);
- ``progression``: burst-like speed and the gait randomizer (§4.3);
- ``sim``: the one simulation loop (many characters, commands, paths, gait changes, frame 0),
  ``SimResult``; ``scaling``: the controller's constants scaled to the creature's size;
- ``cycle``: game-ready loops cut from a walk.

The algorithms the controller calls:

- ``footprints``: the footstep planner (candidates, slices, the best-couple search, LOD);
- ``ik``: leg-plane IK; ``pelvis_physics``: pogo-stick particles (§4.1);
- ``spine``: virtual pelvis nodes and the four spine steps (§4.2, §4.4).

The character controller (§3.2, §3.6), split by concern: ``controller.Controller`` is the
orchestrator; every other module owns one concern and is plain functions on arrays:

- ``types``: ``ControllerParams``, ``PlannerLOD``, ``StepControls``, ``StepStats``;
- ``state``: per-foot state, a ``Phase`` per foot plus its ``SwingPlan``;
- ``rig``: fixed per-rig geometry and the stride rule (needle speed-up);
- ``planning``: plan orchestration around the footprint planner (``core.locomotion.footprints``);
- ``obstacles``: moving obstacles, supports under planted feet, push-out;
- ``fallback``: the straight-step planner of last resort;
- ``pelvis``: hull pose, feet-error feedback, pogo particles;
- ``spine_link``: the spine groups (``core.locomotion.spine``) inside the step;
- ``reach``: reach guard, stretched legs, IK;
- ``stepping``: the foot-state rules of a step (landings, forced steps, swing timing);
- ``profile``: the per-phase timer of a step.
"""
