# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the biped feature.

* **Plan Biped Footsteps** (``procloco.plan_biped_footsteps``): walks the rig from where it
  stands to the goal object over the scene's walkable surfaces, with the clips of its clip
  list, and writes the motion as a new Action (the previous one is remembered). In the UI
  it runs modal: the planning happens in a worker thread (the core is numpy only), the
  status bar shows progress, Esc cancels and nothing is written. In background mode and
  from scripts it runs straight through.
* **Add / Remove Biped Clip**: edit the clip list.
* **Make Example Clips** (``procloco.make_biped_clips``): synthesises a full clip set
  (start, stop, idle, walks on arcs, runs, a jump) fitted to the rig and adds it to the
  list, so the planner works without motion capture.

Every operator refuses bad input with ``report({"ERROR"}, ...)`` and ``{"CANCELLED"}``,
having changed nothing.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import bpy
import numpy as np

from ...core.biped import quat, synth
from ...core.biped.clip import Clip, ClipRole
from ...core.biped.database import ClipDatabase
from ...core.biped.graph import GraphSettings, PlanCancelled, PlanningError
from ...core.biped.ik import IKSettings
from ...core.biped.planner import BipedMotion, PlannerSettings, plan_biped
from ...core.biped.skeleton import LEFT, forward_kinematics
from ...core.biped.surface import WalkableSurface
from .. import actions, validate
from ..keys.reduce import last_reduction
from ..modal import ProgressOperator, RemoveActiveItem, Steps, poll_armature
from . import bridge

__all__ = [
    "PROCLOCO_OT_add_biped_clip",
    "PROCLOCO_OT_make_biped_clips",
    "PROCLOCO_OT_plan_biped_footsteps",
    "PROCLOCO_OT_remove_biped_clip",
    "PlanJob",
    "finish",
    "prepare",
    "run",
]


# ---------------------------------------------------------------------------------------
# Plan Biped Footsteps: prepare (Blender) / run (core, any thread) / finish (Blender)


@dataclass
class PlanJob:
    """Everything one planning needs, read from Blender by :func:`prepare`."""

    obj_name: str
    brig: bridge.BipedRig
    db: ClipDatabase
    surface: WalkableSurface
    start_pos: np.ndarray
    start_yaw: float
    goal: np.ndarray
    goal_yaw: float | None
    settings: PlannerSettings
    seed: int
    start_frame: int
    cancel: threading.Event = field(default_factory=threading.Event)
    progress: float = 0.0
    stage: str = "reading clips"
    result: BipedMotion | None = None
    error: str | None = None
    timings: dict[str, float] = field(default_factory=dict)


def _used_clips(settings: Any) -> list[tuple[bpy.types.Action, ClipRole]]:
    return [
        (item.action, ClipRole(item.role)) for item in settings.clips if item.use and item.action is not None
    ]


def prepare(context: bpy.types.Context, obj: bpy.types.Object) -> PlanJob:
    """Read the rig, its clips, the goal and the walkable surface. Raises
    :class:`bridge.BipedError` with a message for the user; changes nothing."""
    t0 = time.perf_counter()
    if obj is None or obj.type != "ARMATURE":
        raise bridge.BipedError("The active object is not an armature: select the biped rig")
    settings = obj.procloco_biped
    problem = (validate.placement_problem(obj) or validate.tweak_mode_problem(obj)
               or validate.non_finite_setting(settings, f"'{obj.name}'"))
    if problem is None and settings.goal is not None:
        problem = validate.placement_problem(settings.goal)
    if problem is not None:
        raise bridge.BipedError(problem)
    tagged = _used_clips(settings)
    if not tagged:
        raise bridge.BipedError(
            "No clips are tagged: add the rig's Actions to the biped clip list with their "
            "roles, or click Make Example Clips"
        )
    families = {role.family for _, role in tagged}
    missing = [
        name for name, fam in (("Start", "start"), ("Stop", "stop"), ("Walk", "walk")) if fam not in families
    ]
    if missing:
        raise bridge.BipedError(f"The clip list needs at least a {', a '.join(missing)} clip")
    goal_obj = settings.goal
    if goal_obj is None:
        raise bridge.BipedError("Set a goal object: the character walks to it")
    if goal_obj == obj:
        raise bridge.BipedError("The goal cannot be the rig itself")
    brig = bridge.biped_rig(obj)
    clips: list[Clip] = []
    for action, role in tagged:
        clips.append(bridge.read_clip(context, obj, brig, action, role))
    try:
        db = ClipDatabase(brig.skeleton, clips)
    except ValueError as err:
        raise bridge.BipedError(f"The clips cannot be used together: {err}") from err
    gm = np.array(goal_obj.matrix_world, dtype=np.float64)
    goal = gm[:3, 3].copy()
    goal_yaw = None
    if settings.use_goal_heading:
        front = -gm[:3, 1]
        if np.hypot(front[0], front[1]) < 1e-6:
            raise bridge.BipedError(
                f"The goal '{goal_obj.name}' faces straight up or down: turn it to set a heading"
            )
        goal_yaw = float(np.arctan2(front[1], front[0]))
    rest, _ = forward_kinematics(
        brig.skeleton, quat.identity((brig.skeleton.n_joints,)), brig.skeleton.offsets[0]
    )
    leg = brig.skeleton.leg(LEFT)
    foot_length = float(np.linalg.norm(rest[leg.toe, :2] - rest[leg.heel, :2]))
    surface = bridge.walkable_surface(
        context,
        obj,
        brig,
        obj.procloco.terrain_collection,
        brig.root0,
        goal,
        float(settings.max_slope),
        0.5 * foot_length,
    )
    k = synth.body_scale(brig.skeleton)
    _check_goal(surface, goal_obj.name, obj.name, goal, brig.root0, k)
    scene = context.scene
    fps = scene.render.fps / scene.render.fps_base
    graph = GraphSettings(
        cell=0.1 * k,
        position_tolerance=0.1 * k,
        max_step_height=0.2 * k,
        goal_radius=0.25 * k,
        field_cell=0.2 * k,
    )
    core_settings = PlannerSettings(
        dt=1.0 / fps,
        graph=graph,
        crossfade=float(settings.crossfade),
        blend_groups=bool(settings.use_blend_groups),
        allow_run=bool(settings.allow_run),
        sigma=float(settings.speed_change),
        ik=IKSettings(swing_clearance=0.02 * k),
    )
    start_frame = scene.frame_start if settings.use_scene_start else int(settings.start_frame)
    job = PlanJob(
        obj.name,
        brig,
        db,
        surface,
        brig.root0.copy(),
        brig.yaw0,
        goal,
        goal_yaw,
        core_settings,
        int(settings.seed),
        int(start_frame),
    )
    job.timings["read_s"] = time.perf_counter() - t0
    return job


#: How far (in body scales, about a leg length) the goal may be above or below the walkable
#: surface under it, and how near the start it is "where the rig stands".
_GOAL_HEIGHT_TOLERANCE = 0.3
_GOAL_AT_START = 0.25


def _check_goal(surface: WalkableSurface, goal_name: str, rig_name: str, goal: np.ndarray,
                start: np.ndarray, k: float) -> None:
    """Refuse a goal that is not on a walkable surface (in the air, up a wall, inside an
    avoided object) or that is where the rig already stands."""
    h = float(surface.height_at(goal[None, :2])[0])
    if not np.isfinite(h):
        raise bridge.BipedError(f"The goal '{goal_name}' is not on a walkable surface (no upward face of "
                                "the terrain under it, or an avoided object covers it): move it onto the "
                                "ground")
    if abs(float(goal[2]) - h) > _GOAL_HEIGHT_TOLERANCE * k:
        where = "above" if goal[2] > h else "below"
        gap = abs(float(goal[2]) - h)
        raise bridge.BipedError(f"The goal '{goal_name}' is {gap:.3g} m {where} the walkable surface under "
                                "it: put it on the ground the character should reach")
    if float(np.linalg.norm(goal[:2] - start[:2])) < _GOAL_AT_START * k:
        raise bridge.BipedError(f"The goal '{goal_name}' is where '{rig_name}' already stands: move the goal "
                                "away to plan a walk")


def run(job: PlanJob) -> None:
    """Plan (core only: safe in a worker thread). Sets ``job.result`` or ``job.error``."""
    t0 = time.perf_counter()

    def progress(fraction: float, stage: str) -> bool:
        job.progress = fraction
        job.stage = stage
        return not job.cancel.is_set()

    try:
        job.result = plan_biped(
            job.db,
            job.surface,
            job.start_pos,
            job.start_yaw,
            job.goal,
            job.goal_yaw,
            job.settings,
            np.random.default_rng(job.seed),
            progress,
        )
    except PlanCancelled:
        job.error = "cancelled"
    except PlanningError as err:
        msg = str(err)
        job.error = msg[:1].upper() + msg[1:]
    job.timings["plan_s"] = time.perf_counter() - t0


def finish(context: bpy.types.Context, job: PlanJob) -> bpy.types.Action:
    """Write the planned motion as a new Action on the rig and assign it."""
    assert job.result is not None
    obj = bpy.data.objects.get(job.obj_name)
    if obj is None or obj.type != "ARMATURE":
        raise bridge.BipedError(f"The rig '{job.obj_name}' is gone: nothing was written")
    return bridge.write_motion(obj, job.brig, job.result, job.start_frame)


class PROCLOCO_OT_plan_biped_footsteps(ProgressOperator, bpy.types.Operator):
    """Plan the biped's footsteps to the goal over the scene's surfaces and write the walk as a new Action"""

    bl_idname = "procloco.plan_biped_footsteps"
    bl_label = "Plan Biped Footsteps"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    _cancelled_message: ClassVar[str] = "Planning cancelled: nothing was changed"
    # the planning runs in a worker thread: each tick only reads its progress
    _tick_budget_s: ClassVar[float] = 0.0
    _timer_step_s: ClassVar[float] = 0.05
    _job: PlanJob | None = None

    @classmethod
    def poll(cls, context: Any) -> bool:
        if not poll_armature(cls, context, "Select the biped's armature to plan for"):
            return False
        settings = context.active_object.procloco_biped
        if settings.goal is None:
            cls.poll_message_set("Set a goal object in the Biped panel")
            return False
        return True

    def _prepare(self, context: Any) -> bool:
        try:
            self._job = prepare(context, context.active_object)
        except bridge.BipedError as err:
            self.report({"ERROR"}, str(err))
            return False
        return True

    def _finish(self, context: Any) -> set[str]:
        job = self._job
        assert job is not None
        if job.error is not None:
            self.report({"ERROR"}, job.error)
            return {"CANCELLED"}
        try:
            action = finish(context, job)
        except bridge.BipedError as err:
            self.report({"ERROR"}, str(err))
            return {"CANCELLED"}
        except (actions.ActionError, ValueError) as err:
            self.report({"ERROR"}, f"Could not write the Action: {err}")
            return {"CANCELLED"}
        for warning in job.brig.warnings:
            self.report({"WARNING"}, warning)
        motion = job.result
        assert motion is not None
        last = job.start_frame + motion.n_frames - 1
        self.report(
            {"INFO"},
            f"Planned {len(motion.footprints)} footprints, frames {job.start_frame}-{last}: '{action.name}'",
        )
        reduced = last_reduction(bpy.data.objects[job.obj_name])
        if reduced is not None:
            self.report({"INFO"}, f"{job.obj_name}: {reduced.describe()}")
        return {"FINISHED"}

    def _run(self, context: Any, modal: bool) -> Steps:
        job = self._job
        assert job is not None
        if not modal:
            yield f"planning the footsteps of {job.obj_name}", 0.0
            run(job)
            return
        thread = threading.Thread(target=run, args=(job,), daemon=True)
        thread.start()
        try:
            while thread.is_alive():
                yield f"biped {job.stage}", job.progress
        finally:
            job.cancel.set()  # closed early (Esc): the worker stops at its next check

    def _discard(self, context: Any) -> None:
        if self._job is not None:
            self._job.cancel.set()


# ---------------------------------------------------------------------------------------
# Clip list


class PROCLOCO_OT_add_biped_clip(bpy.types.Operator):
    """Add a clip to the biped's clip list (the rig's current Action, when it is not listed yet)"""

    bl_idname = "procloco.add_biped_clip"
    bl_label = "Add Biped Clip"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return poll_armature(cls, context, "Select the biped's armature whose clips to list")

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        settings = obj.procloco_biped
        item = settings.clips.add()
        adt = obj.animation_data
        current = adt.action if adt is not None else None
        if (
            current is not None
            and not actions.is_generated(current)
            and all(c.action != current for c in settings.clips)
        ):
            item.action = current
        settings.active_clip_index = len(settings.clips) - 1
        return {"FINISHED"}


class PROCLOCO_OT_remove_biped_clip(RemoveActiveItem, bpy.types.Operator):
    """Remove the selected clip from the biped's clip list (the Action itself is kept)"""

    bl_idname = "procloco.remove_biped_clip"
    bl_label = "Remove Biped Clip"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}
    _settings, _items, _index = "procloco_biped", "clips", "active_clip_index"
    _no_rig = "Select the biped's armature whose clips to list"
    _no_item = "Select a clip in the list"


class PROCLOCO_OT_make_biped_clips(bpy.types.Operator):
    """Synthesise clips for this rig (start, stop, idle, walks, runs, a jump) as new Actions and list them"""

    bl_idname = "procloco.make_biped_clips"
    bl_label = "Make Example Clips"
    bl_options: ClassVar[set[str]] = {"REGISTER", "UNDO"}

    runs: bpy.props.BoolProperty(name="Runs", default=True, description="Also make running clips")
    jump: bpy.props.BoolProperty(name="Jump", default=True, description="Also make a running jump")

    @classmethod
    def poll(cls, context: Any) -> bool:
        return poll_armature(cls, context, "Select the biped's armature to make clips for")

    def execute(self, context: Any) -> set[str]:
        obj = context.active_object
        try:
            brig = bridge.biped_rig(obj)
            scene = context.scene
            fps = scene.render.fps / scene.render.fps_base
            clips = synth.standard_library(
                brig.skeleton, fps=fps, run=self.runs, jump=self.jump, step_width=brig.step_width
            )
        except (bridge.BipedError, AssertionError, ValueError) as err:
            self.report({"ERROR"}, f"Could not make clips for '{obj.name}': {err}")
            return {"CANCELLED"}
        made: list[bpy.types.Action] = []
        try:
            made.extend(bridge.write_clip_action(obj, brig, clip) for clip in clips)
        except (actions.ActionError, ValueError) as err:
            for action in made:
                bpy.data.actions.remove(action)
            self.report({"ERROR"}, f"Could not write the clips: {err}")
            return {"CANCELLED"}
        settings = obj.procloco_biped
        for action, clip in zip(made, clips, strict=True):
            action.use_fake_user = True  # listed clips are not assigned to anything
            item = settings.clips.add()
            item.action = action
            item.role = clip.role.value
        settings.active_clip_index = len(settings.clips) - 1
        self.report({"INFO"}, f"Made {len(made)} clips for '{obj.name}'")
        return {"FINISHED"}
