# SPDX-License-Identifier: GPL-3.0-or-later
"""Bake Secondary Motion without the operator around it: chain suggestion and the bake job.

**Chains.** :func:`suggest_chains` proposes the bone chains that should swing: chains named
like appendages (tail, antenna, ear, palp, tentacle, hair, abdomen...) anywhere outside the
legs (ears not on two-legged rigs: a human's ears do not flop), and unnamed chains of three
bones or more that hang from the body or spine bones and are neither legs, arms, face nor
helper bones (the Rigify wolf metarig's tail is ``spine.003 > ...``). On a control rig (a
generated Rigify rig: mechanism bones driven by constraints) chains are made of the controls
the animator moves only (the generated wolf's tail controls ``spine.003 > ... > spine``, one
master control per ear), never of their ``ORG-``/``MCH-``/``DEF-`` copies.
Legs come from the rig's leg list (``Object.procloco.legs``), else from leg detection
(:func:`..rig.detect_legs`); the body and spine from :func:`..rig.read_rig`.

**The bake** of one rig is a :class:`Job` in three stages, like Generate Locomotion:

1. :func:`prepare` checks everything and changes nothing (raises :class:`BakeError`);
2. :func:`sample` plays the rig's current animation over the frame range (whatever drives
   it: a generated or hand-made Action, NLA, or no animation at all) and records the
   evaluated world pose of every chain bone, the poses their parents give them and every
   channel the source Action animates. It is a generator yielding the fraction done;
   :func:`cancel` puts the scene back as it was;
3. :func:`write` runs the pendulums (``core.secondary.pendulum``) and writes a **new** Action: the
   source's channels sampled at every frame, with the chain bones' rotations replaced by
   the swinging ones, keyed through :mod:`..pose_writer` (bones that constraints also move,
   like a Rigify tail's controls, are solved through the evaluated rig). Each chain hangs
   from its root's parent bone (or from the object): that body moving *and turning* (a hip
   sway, a turn starting) makes the chain swing.
   The source Action is left untouched and stays reachable (it is remembered as the rig's
   previous Action, see :mod:`..actions`).

Baking again over an Action that a previous bake made starts from that bake's source, so
repeated bakes replace the secondary motion instead of piling it up; the earlier bake is
deleted and the new one takes its name, unless something else uses it (an NLA strip,
another object) or it was given a fake user, and then it is kept.
"""

from __future__ import annotations

import time
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import bpy
import numpy as np

from ...core.secondary import pendulum as pend
from ...core.steps import run_steps
from .. import actions, pose_writer, rig, validate
from ..locomotion import property_group as locomotion_props
from ..rig import controls

__all__ = [
    "SECONDARY_SOURCE",
    "BakeError",
    "ChainSuggestion",
    "Job",
    "bake",
    "cancel",
    "chain_bones",
    "prepare",
    "sample",
    "suggest_chains",
    "suggest_into_settings",
    "write",
]

#: ID property on an Action made by a bake: the Action it was baked on (absent: no Action).
SECONDARY_SOURCE = "_procloco_secondary_source"
_SECONDARY_SLOT = "_procloco_secondary_source_slot"

# Words that name a swinging appendage.
APPENDAGE_WORDS = frozenset({
    "tail", "tails", "antenna", "antennae", "antennas", "feeler", "feelers", "palp", "palps", "pedipalp",
    "ear", "ears", "tentacle", "tentacles", "whisker", "whiskers", "hair", "ponytail", "braid", "fin", "fins",
    "tassel", "rope", "chain", "abdomen", "gaster", "petiole", "cape", "mane", "trunk", "tendril",
})
# First settings of a suggested chain, by the word in its root's name: (Ts s, ζ). Body parts
# (an ant's gaster, a spider's abdomen) are heavy and stiff; ears are short and springy.
_DEFAULTS: dict[str, tuple[float, float]] = {
    "abdomen": (0.3, 0.8), "gaster": (0.3, 0.8), "petiole": (0.3, 0.8),
    "ear": (0.35, 0.5), "ears": (0.35, 0.5),
    "antenna": (0.45, 0.35), "antennae": (0.45, 0.35), "antennas": (0.45, 0.35),
    "feeler": (0.45, 0.35), "palp": (0.35, 0.5), "palps": (0.35, 0.5), "pedipalp": (0.35, 0.5),
    "hair": (0.8, 0.3), "ponytail": (0.8, 0.3), "braid": (0.8, 0.3), "mane": (0.8, 0.3),
}

# Words of bones that must not swing on their own: face, hands and fingers, torso parts.
_STILL_WORDS = frozenset({
    "eye", "eyes", "lid", "brow", "lip", "lips", "jaw", "chin", "cheek", "nose", "teeth", "tooth", "tongue",
    "temple", "forehead", "face", "head", "neck", "skull", "mouth", "thumb", "index", "middle", "ring",
    "pinky", "finger", "fingers", "palm", "shoulder", "clavicle", "breast", "chest", "pelvis", "hip", "hips",
})
# Control and mechanism bones never swing; "tip"/"end" bones only end a chain.
_CONTROL_WORDS = rig.HELPER_WORDS - {"tip", "end", "root", "nub", "null"}
_END_WORDS = frozenset({"end", "nub", "null"})


class BakeError(ValueError):
    """The bake is refused; the message is meant for the user."""


# ---------------------------------------------------------------------------------------
# Chains


@dataclass(frozen=True)
class ChainSuggestion:
    """A proposed chain: ``label`` for the list, bones ``root`` down to ``tip``."""

    label: str
    root: str
    tip: str
    bones: tuple[str, ...]


def _tokens(name: str) -> set[str]:
    return set(rig.split_name(name)[1])


def _leg_chains(obj: bpy.types.Object) -> list[rig.LegChain]:
    """The rig's legs: its enabled leg list if it has one, else detected (none if neither)."""
    legs: list[rig.LegChain] = []
    settings = getattr(obj, "procloco", None)
    items = list(getattr(settings, "legs", []) or [])
    for item in items:
        if not item.enabled or not item.hip or not item.end:
            continue
        try:
            legs.append(rig.leg_from_bones(obj, item.hip, item.end, item.label or item.name))
        except rig.RigError:
            continue
    if legs:
        return legs
    try:
        return rig.detect_legs(obj)
    except rig.RigError:
        return []


def _body_and_spine(
    obj: bpy.types.Object, legs: Sequence[rig.LegChain]
) -> tuple[str | None, tuple[str, ...]]:
    if not legs:
        return None, ()
    try:
        info = rig.read_rig(obj, legs)
    except (rig.RigError, KeyError, ValueError):
        return None, ()
    return info.body_bone, info.spine


def suggest_chains(obj: bpy.types.Object) -> list[ChainSuggestion]:
    """Chains of ``obj`` that should carry secondary motion (see the module doc), root first.

    Never raises for an armature; returns ``[]`` when nothing qualifies.
    """
    bones = obj.data.bones
    names = [b.name for b in bones]
    parent = {b.name: (b.parent.name if b.parent else None) for b in bones}
    below_of = {n: [c.name for c in bones[n].children] for n in names}
    movable = _controls_of(obj)
    if movable is not None:
        # A control rig: chains are made of the controls the animator moves, each hanging
        # from its nearest control ancestor (mechanism and deform copies are never offered).
        def control_parent(n: str) -> str | None:
            up = parent[n]
            while up is not None and up not in movable:
                up = parent[up]
            return up

        parent = {n: control_parent(n) for n in names if n in movable}
        names = [n for n in names if n in movable]
    children: dict[str, list[str]] = {n: [] for n in names}
    for n in names:
        p = parent[n]
        if p is not None:
            children[p].append(n)
    tokens = {n: _tokens(n) for n in names}

    legs = _leg_chains(obj)
    body, spine = _body_and_spine(obj, legs)
    excluded: set[str] = set(spine)
    for leg in legs:
        excluded.update(leg.bones)
        excluded.update(leg.foot)
        stack = [leg.hip]
        while stack:  # everything below a hip: feet, toes, claws, fingers
            below = stack.pop()
            excluded.add(below)
            stack.extend(below_of[below])
    attach: set[str] = set(spine)
    if movable is not None:
        attach.update(names)  # controls hang from other controls, not from the solved bones
    elif body is not None:
        up: str | None = body
        while up is not None:
            excluded.add(up)
            attach.add(up)
            up = parent[up]
    else:
        attach.update(n for n in names if parent[n] is None)

    def usable(n: str) -> bool:
        return n not in excluded and not (tokens[n] & _CONTROL_WORDS) and bones[n].length > 0.0

    # 1. Chains named like appendages. A biped's ears are a face's (a human's do not flop).
    words = APPENDAGE_WORDS - {"ear", "ears"} if len(legs) == 2 else APPENDAGE_WORDS
    named = {n for n in names if usable(n) and tokens[n] & words}

    def named_next(n: str) -> str | None:
        kids = [c for c in children[n] if c in named]
        if len(kids) == 1:
            return kids[0]
        connected = [c for c in kids if bones[c].use_connect]
        return connected[0] if len(connected) == 1 else None

    chains: list[tuple[str, list[str]]] = []
    for n in names:
        if n not in named:
            continue
        p = parent[n]
        if p is not None and p in named and (named_next(p) == n or movable is not None):
            continue  # continues its parent's chain (on a control rig: is one of its controls)
        run = [n]
        while (nxt := named_next(run[-1])) is not None:
            run.append(nxt)
        chains.append((n, run))
    taken = {b for _label, run in chains for b in run}

    # 2. Unnamed chains of three bones or more hanging from the body or the spine.
    for a in names:
        if a not in attach:
            continue
        for c in children[a]:
            if c in taken or c in excluded:
                continue
            run = [c]
            while len(children[run[-1]]) == 1:
                run.append(children[run[-1]][0])
            if children[run[-1]]:
                continue  # branches: a limb or a body part, not a dangling chain
            while run and tokens[run[-1]] & _END_WORDS:
                run.pop()
            if len(run) < 3 or not all(usable(b) for b in run):
                continue
            if any(tokens[b] & (_STILL_WORDS | rig.LEG_WORDS) for b in run):
                continue
            label = f"Tail ({c})" if a == body else c
            chains.append((label, run))
            taken.update(run)

    chains = _dedupe(obj, chains)
    order = {n: i for i, n in enumerate(names)}
    chains.sort(key=lambda item: order[item[1][0]])
    return [ChainSuggestion(label, run[0], run[-1], tuple(run)) for label, run in chains]


def _controls_of(obj: bpy.types.Object) -> set[str] | None:
    """On a control rig (mechanism bones driven by constraints), the bones the animator moves;
    None on a plain rig."""
    graph = controls.ConstraintGraph(obj)
    driven = [n for n in graph.names if controls.is_mechanism_name(n) and not graph.free(n)]
    if not driven:
        return None
    return {n for n in graph.names if graph.keyable(n) and not (_tokens(n) & _CONTROL_WORDS)}


def _dedupe(obj: bpy.types.Object, chains: list[tuple[str, list[str]]]) -> list[tuple[str, list[str]]]:
    """One chain per appendage where a rig has parallel copies (Rigify's ORG-/DEF- bones):
    chains starting and ending at the same places are one; the copy with the fewest
    constrained bones wins, then the shorter name."""

    def ends(run: list[str]) -> tuple[np.ndarray, np.ndarray]:
        first, last = obj.data.bones[run[0]], obj.data.bones[run[-1]]
        return np.array(first.head_local), np.array(last.tail_local)

    def constrained(run: list[str]) -> int:
        return sum(1 for b in run if any(c.enabled for c in obj.pose.bones[b].constraints))

    ranked = sorted(chains, key=lambda item: (constrained(item[1]), len(item[1][0]), item[1][0]))
    kept: list[tuple[str, list[str]]] = []
    for label, run in ranked:
        h, t = ends(run)
        size = max(float(np.linalg.norm(t - h)), 1e-9)
        if any(np.linalg.norm(h - ends(k)[0]) < 0.02 * size and np.linalg.norm(t - ends(k)[1]) < 0.02 * size
               for _lb, k in kept):
            continue
        kept.append((label, run))
    return kept


def suggest_into_settings(obj: bpy.types.Object) -> list[ChainSuggestion]:
    """Fill ``obj.procloco_secondary.chains`` with :func:`suggest_chains`.

    New chains start with settings that suit what they are (a heavy abdomen is stiffer than
    an antenna; tails and unnamed chains get the defaults). A chain already listed with the
    same root and tip keeps its settings; chains the user added that are not suggested are
    kept too. Returns the suggestions.
    """
    settings = obj.procloco_secondary
    found = suggest_chains(obj)
    existing = {(c.root, c.tip) for c in settings.chains}
    for s in found:
        if (s.root, s.tip) in existing:
            continue
        item = settings.chains.add()
        item.name = s.label
        item.root = s.root
        item.tip = s.tip
        for word in sorted(_tokens(s.root) & _DEFAULTS.keys()):
            item.settling_time, item.damping = _DEFAULTS[word]
    settings.active_chain_index = min(settings.active_chain_index, max(len(settings.chains) - 1, 0))
    return found


def chain_bones(obj: bpy.types.Object, root: str, tip: str, label: str = "") -> list[str]:
    """The bones from ``root`` down to ``tip`` (parent to child), validated.

    Raises :class:`BakeError` when a bone is missing, ``root`` is not an ancestor of ``tip``
    or a bone has (near) zero length.
    """
    name = label or f"{root} > {tip}"
    bones = obj.data.bones
    for b in (root, tip):
        if not b:
            raise BakeError(f"Chain {name}: choose both its root and its tip bone")
        if b not in bones:
            raise BakeError(f"Chain {name}: '{obj.name}' has no bone '{b}'")
    run = [tip]
    cur = bones[tip]
    while cur.name != root:
        cur = cur.parent
        if cur is None:
            raise BakeError(f"Chain {name}: '{root}' is not an ancestor of '{tip}'")
        run.append(cur.name)
    run.reverse()
    size = max((b.length for b in bones), default=1.0)
    for b in run:
        if bones[b].length <= 1e-4 * size:
            raise BakeError(f"Chain {name}: bone '{b}' has zero length, so it has no direction to swing; "
                            "give it a length or end the chain before it")
    return run


# ---------------------------------------------------------------------------------------
# The bake job


@dataclass
class Job:
    """One rig's bake: what :func:`prepare` read, what :func:`sample` records."""

    obj_name: str
    bones: list[str]  # every pendulum bone, chains in list order, each root to tip
    parents: list[str | None]  # each bone's parent bone in the armature
    forest: pend.PendulumForest
    frames: np.ndarray  # (F,) frame numbers
    fps: float
    source: bpy.types.Action | None  # the Action the bake layers on
    source_slot: str  # its slot identifier on 4.4+ ("" otherwise)
    switch_action: bool  # the source must be assigned while sampling (re-bake)
    channels: list[actions.Channel]  # the source's channels copied into the new Action
    restore_frame: tuple[int, float]
    warnings: list[str] = field(default_factory=list)
    # While sampling a re-bake, the rig's own Action (the earlier bake) is set aside here.
    set_aside: tuple[bpy.types.Action | None, str] | None = None
    # Filled by sample():
    world: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (F, n, 4, 4) bones, world
    parent_pose: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (F, n, 4, 4) armature space
    object_world: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (F, 4, 4)
    values: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (F, C) channel values
    sampled: bool = False
    timings: dict[str, float] = field(default_factory=dict)
    # Filled by simulate_steps(): local rotations (F, n, 4) and world matrices (F, n, 4, 4).
    swung: tuple[np.ndarray, np.ndarray] | None = None


def _frame_range(context: Any, obj: bpy.types.Object) -> tuple[int, int]:
    settings = getattr(obj, "procloco", None)
    if settings is not None:
        start, end = locomotion_props.frame_range(settings, context.scene)
    else:
        start, end = context.scene.frame_start, context.scene.frame_end
    return int(start), int(end)


def _source_of(obj: bpy.types.Object) -> tuple[bpy.types.Action | None, str, bool]:
    """The Action to bake on, its slot, and whether it must be assigned while sampling."""
    adt = obj.animation_data
    current = adt.action if adt is not None else None
    slot = ""
    if actions.is_slotted() and adt is not None and adt.action_slot is not None:
        slot = str(adt.action_slot.identifier)
    if current is not None and SECONDARY_SOURCE in current:
        source = current.get(SECONDARY_SOURCE)
        if isinstance(source, bpy.types.Action):
            return source, str(current.get(_SECONDARY_SLOT, "")), True
        return None, "", True  # the earlier bake was made on a rig with no Action
    return current, slot, False


def prepare(context: Any, obj: Any) -> Job:
    """Check ``obj`` and its chain settings and read what the bake needs; changes nothing.

    Raises :class:`BakeError` with a message for the user.
    """
    if obj is None or getattr(obj, "type", None) != "ARMATURE":
        raise BakeError("Select an armature: secondary motion is baked on a rig's bones")
    if getattr(context, "mode", "OBJECT") not in {"OBJECT", "POSE"}:
        raise BakeError("Leave edit mode first")
    problem = (validate.placement_problem(obj) or validate.tweak_mode_problem(obj)
               or validate.non_finite_setting(obj.procloco_secondary, f"'{obj.name}'"))
    if problem is not None:
        raise BakeError(problem)
    settings = obj.procloco_secondary
    items = [c for c in settings.chains if c.enabled]
    if not settings.chains:
        raise BakeError(f"'{obj.name}' has no chains: press Suggest Chains or add one "
                        "(tail, antennae, ears...)")
    if not items:
        raise BakeError(f"Every chain of '{obj.name}' is disabled: enable at least one")
    start, end = _frame_range(context, obj)
    problem = validate.frame_range_problem(obj.name, start, end, "baking")
    if problem is not None:
        raise BakeError(problem)
    scale = np.linalg.norm(np.array(obj.matrix_world)[:3, :3], axis=0)
    if np.ptp(scale) > 1e-4 * scale.max():
        raise BakeError(f"'{obj.name}' has a non-uniform scale {tuple(np.round(scale, 4))}: apply it first")

    bones: list[str] = []
    chain_of: dict[str, str] = {}
    per_bone: list[tuple[float, float, int, float]] = []
    for item in items:
        label = item.name or f"{item.root} > {item.tip}"
        run = chain_bones(obj, item.root, item.tip, label)
        for b in run:
            if b in chain_of:
                raise BakeError(f"Bone '{b}' is in two chains ({chain_of[b]} and {label}): "
                                "a bone may swing in one chain only")
            chain_of[b] = label
        bones += run
        mode = pend.REST_GRAVITY if item.rest_direction == "GRAVITY" else pend.REST_ANIMATION
        per_bone += [(item.settling_time, item.damping, mode, item.influence)] * len(run)
    index = {b: i for i, b in enumerate(bones)}
    parents = [obj.data.bones[b].parent.name if obj.data.bones[b].parent else None for b in bones]
    # A chain whose root hangs from a bone of another chain continues that chain's tree.
    father = [index.get(p, -1) if p is not None else -1 for p in parents]
    ts, zeta, rest, influence = (np.array(v) for v in zip(*per_bone, strict=True))
    length = np.array([obj.data.bones[b].length for b in bones]) * float(scale.max())
    try:
        forest = pend.PendulumForest(father, length, ts, zeta, rest_mode=rest, influence=influence,
                                     reaction=bool(settings.use_reaction))
    except ValueError as err:
        raise BakeError(f"Chains of '{obj.name}': {err}") from err

    # Constraints between the bones of the rig are solved through (see write); drivers, limits
    # and constraints following other objects are not.
    warnings = controls.driver_warnings(obj, bones)
    warnings += controls.constraint_warnings(controls.ConstraintGraph(obj), bones, ())
    for b in bones:
        bone = obj.data.bones[b]
        if not bone.use_inherit_rotation or bone.inherit_scale not in {"FULL", "NONE_LEGACY"}:
            warnings.append(f"bone '{b}' does not inherit its parent's rotation or scale fully; "
                            "its baked rotation may be off")

    source, slot, switch = _source_of(obj)
    channels = actions.channels_of(source, obj) if source is not None else []
    swung = set(bones)
    kept = []
    for ch in channels:
        owner = _pose_bone_of(ch.data_path)
        if owner in swung and ch.data_path.rsplit(".", 1)[-1].startswith("rotation_"):
            continue  # replaced by the swinging rotation
        kept.append(ch)
    fps = context.scene.render.fps / context.scene.render.fps_base
    return Job(
        obj_name=obj.name, bones=bones, parents=parents, forest=forest,
        frames=np.arange(start, end + 1), fps=float(fps), source=source, source_slot=slot,
        switch_action=switch, channels=kept,
        restore_frame=(context.scene.frame_current, float(context.scene.frame_subframe)),
        warnings=warnings,
    )


def _pose_bone_of(data_path: str) -> str | None:
    """``'pose.bones["tail"].rotation_quaternion'`` -> ``'tail'``; None for other paths."""
    prefix = 'pose.bones["'
    if not data_path.startswith(prefix):
        return None
    end = data_path.find('"]', len(prefix))
    if end < 0:
        return None
    return data_path[len(prefix):end].replace('\\"', '"').replace("\\\\", "\\")


def _restore(context: Any, job: Job, obj: Any) -> None:
    """Give the rig back its own Action (if a re-bake set it aside) and the scene its frame."""
    if job.set_aside is not None and obj is not None:
        actions.assign_action(obj, job.set_aside[0], job.set_aside[1])
    job.set_aside = None
    frame, sub = job.restore_frame
    context.scene.frame_set(frame, subframe=sub)


def sample(context: Any, job: Job) -> Generator[float, None, None]:
    """Play the animation over the frame range and record the poses; yields the fraction done.

    Leaves the scene as it found it when it ends or is closed early (:func:`cancel`).
    """
    obj = bpy.data.objects.get(job.obj_name)
    if obj is None:
        raise BakeError(f"'{job.obj_name}' was deleted during the bake")
    t0 = time.perf_counter()
    scene = context.scene
    names = [pb.name for pb in obj.pose.bones]
    where = {n: i for i, n in enumerate(names)}
    idx = np.array([where[b] for b in job.bones])
    pidx = np.array([where[p] if p is not None else -1 for p in job.parents])
    n_frames, n = job.frames.size, len(job.bones)
    world = np.empty((n_frames, n, 4, 4))
    parent_pose = np.tile(np.eye(4), (n_frames, n, 1, 1))
    object_world = np.empty((n_frames, 4, 4))
    values = np.empty((n_frames, len(job.channels)))
    buf = np.empty(len(names) * 16, dtype=np.float32)
    if job.switch_action:
        adt = obj.animation_data
        own_slot = ""
        if actions.is_slotted() and adt is not None and adt.action_slot is not None:
            own_slot = str(adt.action_slot.identifier)
        job.set_aside = (adt.action if adt is not None else None, own_slot)
        actions.assign_action(obj, job.source, job.source_slot)
    try:
        for k, frame in enumerate(job.frames):
            scene.frame_set(int(frame))
            ev = obj.evaluated_get(context.evaluated_depsgraph_get())
            ev.pose.bones.foreach_get("matrix", buf)
            pose = buf.reshape(len(names), 4, 4).transpose(0, 2, 1).astype(np.float64)
            obj_world = np.array(ev.matrix_world, dtype=np.float64)
            object_world[k] = obj_world
            world[k] = obj_world @ pose[idx]
            has_parent = pidx >= 0
            parent_pose[k, has_parent] = pose[pidx[has_parent]]
            for c, ch in enumerate(job.channels):
                values[k, c] = _channel_value(ev, ch)
            yield (k + 1) / n_frames
    finally:
        _restore(context, job, obj)
    job.world, job.parent_pose, job.object_world, job.values = world, parent_pose, object_world, values
    job.sampled = True
    job.timings["sample_s"] = time.perf_counter() - t0


def _channel_value(ev: Any, ch: actions.Channel) -> float:
    try:
        value = ev.path_resolve(ch.data_path)
    except ValueError:
        return float("nan")
    try:
        return float(value[ch.index])
    except TypeError:
        return float(value)


def cancel(context: Any, job: Job) -> None:
    """Stop a bake before :func:`write`: nothing is written and the scene is as before."""
    _restore(context, job, bpy.data.objects.get(job.obj_name))


def simulate(job: Job) -> tuple[np.ndarray, np.ndarray]:
    """Run the pendulums on the sampled poses: local rotations ``(F, n, 4)`` (w, x, y, z) of
    every chain bone for its ``matrix_basis``, and the world matrices ``(F, n, 4, 4)``."""
    if job.swung is None:
        for _fraction in simulate_steps(job):
            pass
    assert job.swung is not None
    return job.swung


#: Pendulum steps between two progress reports of :func:`simulate_steps`.
SLICE_STEPS = 2048


def simulate_steps(job: Job) -> Generator[float, None, None]:
    """:func:`simulate` in slices, yielding the fraction done (a long bake shows progress and
    stops on Esc); the result lands in ``job.swung``."""
    if not job.sampled:
        raise RuntimeError("sample() the job before simulating it")
    t0 = time.perf_counter()
    times = (job.frames - job.frames[0]) / job.fps
    heads = job.world[..., :3, 3]
    frames = pend.orthonormalize_frames(job.world[..., :3, :3])
    # Each chain hangs from its root's parent bone (or the object): that body turning,
    # swaying or rolling makes the chain lag and swing.
    anchors = pend.orthonormalize_frames((job.object_world[:, None] @ job.parent_pose)[..., :3, :3])
    result = yield from pend.simulate_steps(job.forest, times, heads, frames, anchor_frame=anchors,
                                            slice_steps=SLICE_STEPS)
    job.timings["simulate_s"] = time.perf_counter() - t0

    obj = bpy.data.objects[job.obj_name]
    n_frames, n = result.head.shape[:2]
    # World -> armature space (uniform object scale).
    obj_inv = np.linalg.inv(job.object_world)  # (F, 4, 4)
    new_world = np.tile(np.eye(4), (n_frames, n, 1, 1))
    bone_scale = np.linalg.norm(job.world[..., :3, :3], axis=-2)  # (F, n, 3) column lengths
    new_world[..., :3, :3] = result.rotation * bone_scale[..., None, :]
    new_world[..., :3, 3] = result.head
    pose = obj_inv[:, None] @ new_world  # (F, n, 4, 4) armature space
    index = {b: i for i, b in enumerate(job.bones)}
    basis_rot = np.empty((n_frames, n, 3, 3))
    for i, b in enumerate(job.bones):
        bone = obj.data.bones[b]
        rest = np.array(bone.matrix_local, dtype=np.float64)
        p = job.parents[i]
        if p is None:
            basis = np.linalg.inv(rest) @ pose[:, i]
        else:
            parent_rest = np.array(obj.data.bones[p].matrix_local, dtype=np.float64)
            rest_rel = np.linalg.inv(parent_rest) @ rest
            parent_pose = pose[:, index[p]] if p in index else job.parent_pose[:, i]
            basis = np.linalg.inv(parent_pose @ rest_rel) @ pose[:, i]
        basis_rot[:, i] = basis[:, :3, :3] / np.linalg.norm(basis[:, :3, :3], axis=-2, keepdims=True)
    quats = rig.matrix_to_quaternion(basis_rot.reshape(-1, 3, 3)).reshape(n_frames, n, 4)
    job.swung = (quats, new_world)


def write(context: Any, job: Job) -> bpy.types.Action:
    """Simulate and write a new Action on the rig, assigned in place of the source."""
    return run_steps(write_steps(context, job))


def write_steps(context: Any, job: Job) -> Generator[float, None, bpy.types.Action]:
    """:func:`write`, yielding the fraction done; closed early (Esc) or failing, it deletes
    the new Action and gives the rig back its Action, slot and pose."""
    obj = bpy.data.objects.get(job.obj_name)
    if obj is None:
        raise BakeError(f"'{job.obj_name}' was deleted during the bake")
    _quats, world = simulate(job)
    t0 = time.perf_counter()
    frames = job.frames.astype(np.float64)
    action = actions.new_action(obj, suffix="Secondary")
    try:
        if job.source is not None:
            action[SECONDARY_SOURCE] = job.source
            action[_SECONDARY_SLOT] = job.source_slot
        else:
            action[SECONDARY_SOURCE] = ""
        good = [c for c in range(len(job.channels)) if np.all(np.isfinite(job.values[:, c]))]
        if good:
            actions.write_channels(action, obj, [job.channels[c] for c in good], frames, job.values[:, good])
        # Over an earlier bake, this bake supersedes it: the earlier one is deleted (and this
        # one takes its name) unless something else uses it or it was given a fake user, in
        # which case it is kept with a fake user. The remembered previous Action stays the
        # user's own (see actions.assign_generated_action).
        adt = obj.animation_data
        current = adt.action if adt is not None else None
        rebake = current is not None and actions.is_generated(current) and SECONDARY_SOURCE in current
        request, plan = _pose_request(obj, job, world)
        actions.remember_pose(action, obj, job.bones)
        memo = actions.remember_assignment(obj)
        frame = (context.scene.frame_current, context.scene.frame_subframe)
        superseded: list[tuple[bpy.types.Action, bpy.types.Action]] = []
        try:
            yield from pose_writer.write_pose_steps(action, obj, request, plan, replace=rebake,
                                                    superseded=superseded)
            _reduce_keys(obj, action, job)
        except BaseException:
            actions.restore_pose(obj, action)
            actions.undo_assignment(obj, memo)
            context.scene.frame_set(frame[0], subframe=frame[1])
            raise
    except BaseException:  # an error, or closed early (Esc)
        bpy.data.actions.remove(action)
        raise
    actions.delete_superseded(superseded)  # the earlier bake, once this one is written
    job.timings["write_s"] = time.perf_counter() - t0
    return action


def _reduce_keys(obj: bpy.types.Object, action: bpy.types.Action, job: Job) -> None:
    """Key Reduction of the bake when the rig has it on (see :mod:`..keys.reduce`): the
    feet are the rig's legs' end-effectors, and the frames the source Action keyed (a reduced
    walk's contacts) stay keys of the channels copied from it."""
    from ..keys import reduce

    settings = getattr(obj, "procloco_keys", None)
    if settings is None or not settings.use_key_reduction:
        return
    feet = [item.end for item in obj.procloco.legs if item.enabled and item.end]
    required: dict[Any, np.ndarray] = {}
    if job.source is not None:
        for channel, keyed, _values in actions.read_channels(job.source, obj):
            if keyed.size < job.frames.size:
                required[(channel.data_path, channel.index)] = np.isin(job.frames.astype(np.float64),
                                                                       np.round(keyed))
    reduce.reduce_if_enabled(obj, action, job.frames, feet, required)


def _pose_request(obj: bpy.types.Object, job: Job,
                  world: np.ndarray) -> tuple[pose_writer.PoseRequest, controls.ControlPlan]:
    """The swinging chain bones (world matrices ``world`` ``(F, n, 4, 4)``) as targets for
    :mod:`..pose_writer`, rotations only: free bones keyed themselves, bones that constraints
    also move (a Rigify tail's controls copy each other's
    rotation) solved through the evaluated rig, each as its own anchor."""
    bones = obj.data.bones
    rest = {b.name: np.array(b.matrix_local, dtype=np.float64) for b in bones}
    parents = {b.name: (b.parent.name if b.parent else None) for b in bones}
    basis = {pb.name: np.array(pb.matrix_basis, dtype=np.float64) for pb in obj.pose.bones}
    pose = np.linalg.inv(job.object_world)[:, None] @ world  # (F, n, 4, 4) armature space
    hung = {p: job.parent_pose[:, i] for i, p in enumerate(job.parents)
            if p is not None and p not in job.bones}
    graph = controls.ConstraintGraph(obj)
    free = tuple(b for b in job.bones if graph.free(b))
    plan = controls.ControlPlan(
        direct=free, controls=tuple(controls.ControlKey(b, "RIGID", b) for b in job.bones if b not in free),
        legs=(), switches=(), uncovered=())
    request = pose_writer.PoseRequest(
        frames=job.frames, bones=tuple(job.bones), armature=pose,
        keyed_location=np.zeros(len(job.bones), dtype=bool), world0=np.eye(4), rest_local=rest,
        parents=parents, basis=basis, per_frame=True, parent_pose=hung)
    return request, plan


def bake(context: Any, obj: Any) -> bpy.types.Action:
    """Prepare, sample and write in one go (scripts, batch mode, tests)."""
    job = prepare(context, obj)
    for _fraction in sample(context, job):
        pass
    return write(context, job)

