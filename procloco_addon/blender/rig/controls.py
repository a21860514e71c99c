# SPDX-License-Identifier: GPL-3.0-or-later
"""Which bones the animator moves: from the bones ProcLoco solves to the controls that drive them.

On a control rig (a generated Rigify rig, an Auto-Rig Pro rig, a studio's IK rig) the bones
ProcLoco solves (a leg's chain, the body bone, the spine) are not keyed: constraints copy them
from mechanism bones that IK chains and parent switches move, and those follow the bones the
animator poses. This module follows that **constraint graph** upstream and says which bones to
key so the evaluated (deform) bones land where the core put them.

The graph (:class:`ConstraintGraph`) is read from the *evaluated* rig, so influences, mutes and
parent-switch weights that drivers set are the ones in effect. Each bone depends on

- its parent, unless a later constraint replaces its whole transform (Copy Transforms at full
  influence, Armature): then on nothing before that constraint;
- the bone targets of its enabled constraints (Copy Location/Rotation/Transforms, Child Of,
  Armature targets with a weight, Damped Track, Stretch To, ...);
- for every bone of an IK chain, the IK's target and pole.

A **control** is a bone the animator is meant to move: its own transform counts (not replaced
by a constraint, its rotation not copied from another bone by a full Copy Rotation, not
rotated by an IK chain) and it is not a mechanism bone (Rigify's and
Auto-Rig Pro's ``ORG-``/``MCH-``/``DEF-``/``VIS_``/``WGT-`` bones, or bones only in hidden bone
collections).

Per leg (:func:`plan_controls`): the **IK control** is the IK target itself when the animator
moves it (MMD's ``左足ＩＫ``, even under a leg IK parent), else the most upstream control
feeding the leg's IK target that does not also carry the leg's hip (the body's controls and
the rig's root move the whole leg); the **pole** is the one feeding the IK's pole. Properties that drivers
read to switch a leg between FK and IK (Rigify's ``IK_FK`` on ``thigh_parent.L``, Auto-Rig
Pro's ``ik_fk_switch``) and to turn its pole on (Rigify's ``pole_vector``) are
:class:`Switch` es: they are set to the value that puts the leg in IK with a pole, and keyed.
When every bone of a leg is (or copies) a bone of an IK chain, that chain's stretch
(``ik_stretch``) is keyed off too: Blender's IK shortens stretchy bones when that reaches the
target with less bending (Rigify's chains stretch by 0.1).

**Drive Legs** (``drive``, the rig's ``drive_legs``) chooses between a leg's IK and FK
controls when its IK/FK switch offers both: ``"IK"``; ``"FK"`` (the switch set to its other
value, keyed, when that leaves no IK upstream of the leg); ``"AUTO"``: FK where the leg's IK
chain does not solve every bone of the leg. Rigify's three-bone paws (``limbs.paw``,
``front_paw``, ``rear_paw``: wolf, cat, horse, quadruped) are such legs: their paw bone copies
a target that stretchy helper chains place, so through the IK control the deform bones
shorten by 2-3 % and a knee flips at some frames, while their FK controls (``thigh_fk.L``,
``shin_fk.L``, ``foot_fk.L``, ``toe.L``) drive the ``ORG-`` chain, and with it the deform
bones, exactly as solved.
A leg with no IK upstream (an FK control rig, or a leg switched to FK) has each of its driven
bones turned by the nearest control upstream of it that does not carry the hip (its FK
control: Auto-Rig Pro's ``c_thigh_fk.l``, Rigify's ``thigh_fk.L``), parent first.
The **body control** is the most upstream control that carries the body bone and every hip but
no IK control and, where another one does, has a parent (Rigify's ``torso``, Auto-Rig Pro's
``c_root_master.x``, not the placement roots ``root``/``c_traj``) and, where another one
does, carries no IK target's control either (legs walked in FK: Auto-Rig Pro's ``c_traj``
under ``c_pos`` carries the idle IK feet). The second half of a limb bone split in two
(``names.split_joints``: ``thigh_stretch.l`` riding on ``thigh_twist.l``) needs no control:
the core keeps it in line with the first.
Any other solved bone that is driven gets the nearest control upstream of it (spine and tail
FK controls). Solved bones that are free are keyed themselves, as on plain FK rigs.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import bpy

from .names import split_joints

__all__ = [
    "DRIVE_MODES",
    "ConstraintGraph",
    "ControlKey",
    "ControlPlan",
    "LegControls",
    "Switch",
    "describe_leg",
    "is_mechanism_name",
    "plan_controls",
]

_MECHANISM = re.compile(r"^(ORG|MCH|DEF|VIS|WGT|TGT|MCH_|ROT)[-_.]", re.IGNORECASE)
_PROP_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\["((?:[^"\\]|\\.)*)"\]$')
_CONSTRAINT_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.constraints\["((?:[^"\\]|\\.)*)"\]')
_CHANNEL_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.'
                           r'(location|rotation_quaternion|rotation_euler|rotation_axis_angle|scale)$')
# Constraints that only clip the transform: they never carry a dependency, but a keyed bone
# under one may not reach its keys.
LIMIT_CONSTRAINTS = frozenset({"LIMIT_ROTATION", "LIMIT_LOCATION", "LIMIT_SCALE", "LIMIT_DISTANCE"})
# Constraints that replace the whole transform of their owner (at full influence).
_REPLACING = frozenset({"COPY_TRANSFORMS", "ARMATURE"})
# Constraints that only turn their owner towards their target.
_AIMING = frozenset({"STRETCH_TO", "DAMPED_TRACK", "TRACK_TO", "LOCKED_TRACK"})
_NAMES = {
    "COPY_TRANSFORMS": "Copy Transforms", "COPY_LOCATION": "Copy Location", "COPY_ROTATION": "Copy Rotation",
    "CHILD_OF": "Child Of", "DAMPED_TRACK": "Damped Track", "STRETCH_TO": "Stretch To",
    "TRACK_TO": "Track To",
    "LOCKED_TRACK": "Locked Track", "LIMIT_ROTATION": "Limit Rotation", "LIMIT_LOCATION": "Limit Location",
    "LIMIT_SCALE": "Limit Scale", "LIMIT_DISTANCE": "Limit Distance", "IK": "IK", "ARMATURE": "Armature",
}


def _unescape(s: str) -> str:
    return s.replace('\\"', '"').replace("\\\\", "\\")


def constraint_label(kind: str) -> str:
    """A constraint type as the user reads it (``LIMIT_ROTATION`` -> ``Limit Rotation``)."""
    return _NAMES.get(kind, kind.replace("_", " ").title())


def is_mechanism_name(name: str) -> bool:
    """Whether a bone's name marks it as rig mechanism (``ORG-``, ``MCH-``, ``DEF-``, ...)."""
    return bool(_MECHANISM.match(name))


def _active(c: bpy.types.Constraint) -> bool:
    return bool(getattr(c, "enabled", not getattr(c, "mute", False))) and float(c.influence) > 1e-6


@dataclass
class _Node:
    deps: dict[str, int] = field(default_factory=dict)  # bone -> 0 parent, 1 constraint, 2 IK
    replaced: bool = False  # its own basis is overwritten by a constraint
    turned: bool = False  # its own rotation is overwritten by a constraint (Copy Rotation)
    in_ik: bool = False  # an IK chain sets its rotation
    ik: list[tuple[str, str | None]] = field(default_factory=list)  # IKs reaching it: (target, pole)
    limits: list[str] = field(default_factory=list)  # limit constraint types on it
    external: list[tuple[str, str]] = field(default_factory=list)  # (constraint type, object name)
    aims: set[str] = field(default_factory=set)  # bones it only points at (Stretch To, Damped Track...)


class ConstraintGraph:
    """The dependencies between the bones of armature ``obj``, as evaluated now (see module doc)."""

    def __init__(self, obj: bpy.types.Object) -> None:
        self.obj = obj
        depsgraph = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(depsgraph)
        bones = obj.data.bones
        self.names = [b.name for b in bones]
        self.nodes: dict[str, _Node] = {n: _Node() for n in self.names}
        hidden = self._hidden_bones(obj)
        self.controls = {n for n in self.names if not is_mechanism_name(n) and n not in hidden}
        for pb in ev.pose.bones:
            node = self.nodes[pb.name]
            parent_kept = True
            for c in reversed(list(pb.constraints)):
                if not _active(c):
                    continue
                kind = c.type
                if kind in LIMIT_CONSTRAINTS:
                    node.limits.append(kind)
                    continue
                for target, sub in self._targets(c):
                    if target is None:
                        continue
                    if target.original.name != obj.name or target.type != "ARMATURE":
                        node.external.append((kind, target.original.name))
                    elif sub and sub in self.nodes:
                        node.deps.setdefault(sub, 1)
                        if kind in _AIMING:
                            node.aims.add(sub)
                if kind == "IK":
                    self._add_ik(ev, pb, c)
                full = float(c.influence) >= 0.999 and getattr(c, "mix_mode", "REPLACE") == "REPLACE"
                if kind == "COPY_ROTATION" and full and all(getattr(c, f"use_{a}", True) for a in "xyz"):
                    node.turned = True
                if kind in _REPLACING and full:
                    node.replaced = True
                    parent_kept = False
                    break
            if parent_kept and pb.parent is not None:
                node.deps.setdefault(pb.parent.name, 0)

    @staticmethod
    def _hidden_bones(obj: bpy.types.Object) -> set[str]:
        """Bones only in hidden bone collections (mechanism on rigs that sort their bones)."""
        out: set[str] = set()
        for b in obj.data.bones:
            colls = list(getattr(b, "collections", ()))
            if colls and not any(getattr(c, "is_visible", True) for c in colls):
                out.add(b.name)
        return out

    @staticmethod
    def _targets(c: bpy.types.Constraint) -> list[tuple[bpy.types.Object | None, str]]:
        if c.type == "ARMATURE":
            return [(t.target, t.subtarget) for t in c.targets if float(t.weight) > 1e-6]
        out: list[tuple[bpy.types.Object | None, str]] = []
        if hasattr(c, "target"):
            out.append((c.target, getattr(c, "subtarget", "")))
        if c.type == "IK" and getattr(c, "pole_target", None) is not None:
            out.append((c.pole_target, c.pole_subtarget))
        return out

    def _add_ik(self, ev: bpy.types.Object, pb: bpy.types.PoseBone, c: bpy.types.Constraint) -> None:
        target = c.subtarget if c.target is not None and c.target.original.name == self.obj.name else ""
        pole = (c.pole_subtarget if getattr(c, "pole_target", None) is not None
                and c.pole_target.original.name == self.obj.name else None) or None
        count = int(c.chain_count)
        cur: bpy.types.PoseBone | None = pb
        k = 0
        while cur is not None and (count == 0 or k < count):
            node = self.nodes[cur.name]
            node.in_ik = True
            node.ik.append((target, pole))
            if target:
                node.deps.setdefault(target, 2)
            if pole:
                node.deps.setdefault(pole, 2)
            cur = cur.parent
            k += 1

    # -- queries --------------------------------------------------------------------------

    def free(self, name: str) -> bool:
        """Whether a bone's own keys decide its pose (no constraint replaces it, no IK turns it)."""
        node = self.nodes[name]
        return not node.replaced and not node.in_ik and not any(
            v == 1 for v in node.deps.values())

    def keyable(self, name: str) -> bool:
        """Whether a bone is a control the animator moves (its own transform counts: no
        constraint replaces it or its rotation, no IK turns it)."""
        node = self.nodes[name]
        return name in self.controls and not node.replaced and not node.turned and not node.in_ik

    def upstream(self, names: Iterable[str], blocked: Iterable[str] = ()) -> dict[str, int]:
        """Every bone ``names`` depend on, with its distance (the bones themselves at 0),
        not walking through ``blocked`` bones."""
        stop = set(blocked)
        dist: dict[str, int] = {}
        queue: deque[str] = deque()
        for n in names:
            if n in self.nodes and n not in dist:
                dist[n] = 0
                queue.append(n)
        while queue:
            cur = queue.popleft()
            for d in self.nodes[cur].deps:
                if d not in dist and d not in stop:
                    dist[d] = dist[cur] + 1
                    queue.append(d)
        return dist

    def controls_upstream(self, names: Iterable[str], blocked: Iterable[str] = ()) -> dict[str, int]:
        return {n: d for n, d in self.upstream(names, blocked).items() if self.keyable(n)}

    def iks_upstream(self, names: Iterable[str]) -> list[tuple[str, str | None]]:
        """The (target, pole) of every IK that turns a bone ``names`` depend on, nearest first."""
        up = self.upstream(names)
        out: list[tuple[str, str | None]] = []
        for n in sorted(up, key=lambda n: (up[n], n)):
            for ik in self.nodes[n].ik:
                if ik not in out:
                    out.append(ik)
        return out

    def roots(self, candidates: Iterable[str]) -> list[str]:
        """The candidates that depend on no other candidate (the most upstream ones)."""
        cands = list(dict.fromkeys(candidates))
        cand_set = set(cands)
        out = []
        for c in cands:
            up = self.upstream([c])
            if not any(o in cand_set and o != c for o in up):
                out.append(c)
        return out


@dataclass(frozen=True)
class Switch:
    """A custom property ``prop`` of pose bone ``bone`` set (and keyed) to ``value``; with
    ``kind`` ``"STRETCH"``, the pose bone's own ``ik_stretch`` (an IK chain's bone)."""

    bone: str
    prop: str
    value: float
    kind: str  # "IK_FK", "POLE" or "STRETCH"

    @property
    def data_path(self) -> str:
        bone, prop = bpy.utils.escape_identifier(self.bone), bpy.utils.escape_identifier(self.prop)
        if self.kind == "STRETCH":
            return f'pose.bones["{bone}"].{self.prop}'
        return f'pose.bones["{bone}"]["{prop}"]'

    def read(self, obj: bpy.types.Object) -> float:
        """The value the switch has on ``obj`` now."""
        pb = obj.pose.bones[self.bone]
        return float(getattr(pb, self.prop) if self.kind == "STRETCH" else pb[self.prop])

    def write(self, obj: bpy.types.Object, value: float) -> None:
        """Set the switch on ``obj`` to ``value`` (the property keeps its type)."""
        pb = obj.pose.bones[self.bone]
        if self.kind == "STRETCH":
            setattr(pb, self.prop, float(value))
        else:
            old = pb[self.prop]
            pb[self.prop] = type(old)(value) if isinstance(old, (bool, int, float)) else value


@dataclass(frozen=True)
class ControlKey:
    """One control and how its keys are found.

    ``mode``: ``"RIGID"`` (the control carries ``anchor`` rigidly: it moves by the anchor's
    error), ``"MOVE"`` (it moves by the anchor's head error only: the anchor points at
    another bone, which turns it), ``"TURN"`` (it turns by the anchor's rotation error, rotation keyed only),
    ``"IK"`` (it turns like ``anchor`` and moves by the error of the leg's
    end-effector ``leg``), ``"POLE"`` (placed on the side of leg ``leg``'s knee, at its
    current distance from it).

    ``follows``: for ``"TURN"``, the control (turned before it in the same pass) whose turn it
    inherits (its parent in an FK chain: ``shin_fk.L`` follows ``thigh_fk.L``), so that a
    whole FK chain lands in one pass.
    """

    bone: str
    mode: str
    anchor: str
    leg: int = -1
    follows: str = ""


@dataclass(frozen=True)
class LegControls:
    """The controls of one leg: IK target, pole and switches, or its FK controls (hip first;
    all empty when the leg is free)."""

    ik: str | None = None
    pole: str | None = None
    switches: tuple[Switch, ...] = ()
    fk: tuple[str, ...] = ()


@dataclass(frozen=True)
class ControlPlan:
    """What to key for the solved bones of one rig (see :func:`plan_controls`)."""

    direct: tuple[str, ...]  # solved bones keyed themselves
    controls: tuple[ControlKey, ...]  # controls keyed in their place
    legs: tuple[LegControls, ...]
    switches: tuple[Switch, ...]
    uncovered: tuple[str, ...]  # driven solved bones no control was found for
    warnings: tuple[str, ...] = ()

    @property
    def uses_controls(self) -> bool:
        return bool(self.controls or self.switches)

    @property
    def keyed_bones(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys([*self.direct, *(c.bone for c in self.controls)]))


def _driver_switches(obj: bpy.types.Object, bones: set[str]) -> list[tuple[str, str]]:
    """Custom properties ``(bone, prop)`` read by drivers on constraints of ``bones``."""
    adt = obj.animation_data
    if adt is None:
        return []
    out: list[tuple[str, str]] = []
    for fc in adt.drivers:
        m = _CONSTRAINT_PATH.match(fc.data_path)
        if m is None or _unescape(m.group(1)) not in bones:
            continue
        for var in fc.driver.variables:
            for t in var.targets:
                if t.id is None or getattr(t.id, "name", None) != obj.name:
                    continue
                pm = _PROP_PATH.match(t.data_path or "")
                if pm is not None:
                    item = (_unescape(pm.group(1)), _unescape(pm.group(2)))
                    if item not in out:
                        out.append(item)
    return out


def _switch_kind(prop: str) -> str | None:
    words = set(re.split(r"[^a-z]+", prop.lower()))
    low = prop.lower().replace("_", "").replace(" ", "")
    if ("ik" in words and "fk" in words) or "ikfk" in low or "fkik" in low:
        return "IK_FK"
    if "pole" in words and not ({"parent", "space"} & words):
        return "POLE"
    return None


def _all_upstream(obj: bpy.types.Object, names: Iterable[str]) -> set[str]:
    """Bones ``names`` reach through any constraint, whatever its influence (for switches)."""
    pbones = obj.pose.bones
    seen: set[str] = set()
    stack = [n for n in names if n in pbones]
    # Every IK constraint of the rig, once (``children_recursive`` per bone walks the whole rig).
    iks = [(pb, c) for pb in pbones for c in pb.constraints if c.type == "IK" and c.subtarget in pbones]
    while stack:
        n = stack.pop()
        if n in seen:
            continue
        seen.add(n)
        pb = pbones[n]
        if pb.parent is not None:
            stack.append(pb.parent.name)
        for c in pb.constraints:
            for _t, sub in ConstraintGraph._targets(c):
                if sub and sub in pbones:
                    stack.append(sub)
            if c.type == "ARMATURE":
                stack.extend(t.subtarget for t in c.targets if t.subtarget in pbones)
        # IK chains reaching n from below (from a bone under n, up the chain's length)
        for child, c in iks:
            if child.name == n:
                continue
            chain = int(c.chain_count)
            up, k = child, 0
            while up is not None and (chain == 0 or k < chain):
                if up.name == n:
                    stack.append(c.subtarget)
                    if c.pole_subtarget in pbones:
                        stack.append(c.pole_subtarget)
                up, k = up.parent, k + 1
    return seen


def _set_props(obj: bpy.types.Object, values: dict[tuple[str, str], float]) -> None:
    for (bone, prop), value in values.items():
        pb = obj.pose.bones[bone]
        old = pb[prop]
        pb[prop] = type(old)(value) if isinstance(old, (bool, int, float)) else value
    obj.update_tag()
    bpy.context.view_layer.update()


def _choose_switches(obj: bpy.types.Object, leg_bones: Sequence[str], chain: Sequence[str],
                     originals: dict[tuple[str, str], float]) -> list[Switch]:
    """The IK/FK and pole switches of a leg, set to IK with a pole (left set on the rig; the
    values they had are added to ``originals``)."""
    found = _driver_switches(obj, _all_upstream(obj, leg_bones))
    out: list[Switch] = []
    for kind in ("IK_FK", "POLE"):
        for bone, prop in found:
            if _switch_kind(prop) != kind:
                continue
            old = obj.pose.bones[bone][prop]
            if not isinstance(old, (bool, int, float)):
                continue
            originals.setdefault((bone, prop), float(old))
            best = None
            for value in (0.0, 1.0) if kind == "IK_FK" else (1.0, 0.0):
                _set_props(obj, {(bone, prop): value})
                iks = ConstraintGraph(obj).iks_upstream(chain)
                if kind == "IK_FK" and iks:
                    best = value
                    break
                if kind == "POLE" and any(pole for _t, pole in iks):
                    best = value
                    break
            if best is None:
                _set_props(obj, {(bone, prop): float(old)})
            else:
                out.append(Switch(bone, prop, best, kind))
    return out


def _ik_solves(graph: ConstraintGraph, bones: Sequence[str]) -> set[str] | None:
    """The bones of the IK chains that solve leg ``bones`` (each bone is, or copies, a bone of
    an IK chain), or None when some bone of the leg follows something else (the paw of
    Rigify's three-bone legs copies the target its stretchy helper chains place)."""
    chain: set[str] = set()
    halves = _rigid_halves(graph, bones)
    for b in bones:
        solving = {b} if graph.nodes[b].in_ik else {
            d for d, kind in graph.nodes[b].deps.items() if kind == 1 and graph.nodes[d].in_ik}
        if not solving and b not in halves:
            return None
        chain |= solving
    return chain


def _rigid_halves(graph: ConstraintGraph, bones: Sequence[str]) -> set[str]:
    """The bones of leg ``bones`` that are the second half of a limb bone split in two
    (``names.split_joints``: Auto-Rig Pro's ``thigh_stretch.l`` under ``thigh_twist.l``)
    and only ride on the first half (no constraint, no IK, no own keys: not a control). The
    core keeps such a joint at its rest angle, so they need no control of their own."""
    out = set()
    for j in split_joints(bones):
        b, node = bones[j], graph.nodes[bones[j]]
        if set(node.deps) == {bones[j - 1]} and not node.in_ik and b not in graph.controls:
            out.add(b)
    return out


def _stretch_switches(obj: bpy.types.Object, chain: set[str]) -> list[Switch]:
    """The bones of the IK ``chain`` that solves a leg (:func:`_ik_solves`) that may stretch
    (``ik_stretch`` > 0, not driven), each a switch to no stretch. Blender's IK shortens a
    stretchy chain's bones when that reaches the target with less bending: a generated Rigify
    human's thigh and shin by up to 2.5 % while it walks. The walk never asks a leg to reach
    beyond its length."""
    adt = obj.animation_data
    driven = set()
    if adt is not None:
        for fc in adt.drivers:
            m = re.match(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.ik_stretch$', fc.data_path)
            if m is not None and not fc.mute:
                driven.add(_unescape(m.group(1)))
    pbones = obj.pose.bones
    return [Switch(n, "ik_stretch", 0.0, "STRETCH") for n in sorted(chain)
            if float(pbones[n].ik_stretch) > 0.0 and n not in driven]


def _fk_switch(switches: Sequence[Switch]) -> Switch | None:
    """A leg's IK/FK switch (set to IK, 0 or 1) at its other value, or None."""
    for s in switches:
        if s.kind == "IK_FK" and s.value in (0.0, 1.0):
            return Switch(s.bone, s.prop, 1.0 - s.value, s.kind)
    return None


#: How Generate Locomotion drives a leg that has both IK and FK controls (``drive``).
DRIVE_MODES = ("AUTO", "IK", "FK")


def plan_controls(
    obj: bpy.types.Object,
    legs: Sequence[tuple[Sequence[str], Sequence[str]]],
    body: str,
    others: Sequence[str] = (),
    drive: str | None = None,
) -> ControlPlan:
    """Which bones to key for the solved bones of ``obj`` (see the module doc).

    legs: per leg ``(bones hip to end-effector, foot bones)``; ``body``: the body bone;
    ``others``: further solved bones (spine, chain bones), parents first. ``drive``: for legs
    with an IK/FK switch, ``"IK"`` (their IK controls), ``"FK"`` (their FK controls) or
    ``"AUTO"`` (FK where the leg's IK chain does not solve every bone of the leg, so that
    driving it through the IK control would squash or flip the deform bones); None: the
    rig's own setting (``Object.procloco.drive_legs``). The rig is left as it was (switches
    are tried and put back).
    """
    if drive is None:
        drive = str(getattr(getattr(obj, "procloco", None), "drive_legs", "AUTO"))
    solved = [body, *others, *(b for bones, foot in legs for b in (*bones, *foot[:1]))]
    originals: dict[tuple[str, str], float] = {}
    try:
        switches: list[list[Switch]] = []
        for bones, foot in legs:
            switches.append(_choose_switches(obj, [*bones, *foot[:1]], bones, originals))
        # _choose_switches leaves its choices set: read the graph in that state.
        graph = ConstraintGraph(obj)
        chains = [_ik_solves(graph, bones) for bones, _foot in legs]
        want_fk = [drive == "FK" or (drive == "AUTO" and chain is None) for chain in chains]
        # A switch shared with a leg that stays in IK stays as it is.
        ik_only = {(s.bone, s.prop) for k, sw in enumerate(switches) if not want_fk[k] for s in sw}
        fk: dict[int, Switch] = {}
        for k, (bones, _foot) in enumerate(legs):
            flip = _fk_switch([s for s in switches[k] if (s.bone, s.prop) not in ik_only])
            if want_fk[k] and flip is not None and graph.iks_upstream(bones):
                fk[k] = flip
        if fk:  # those legs in FK (one evaluation); one whose IK is still upstream stays in IK
            _set_props(obj, {(s.bone, s.prop): s.value for s in fk.values()})
            graph = ConstraintGraph(obj)
            still_ik = {k for k in fk if graph.iks_upstream(legs[k][0])}
            if still_ik:
                _set_props(obj, {(fk[k].bone, fk[k].prop): 1.0 - fk[k].value for k in still_ik})
                graph = ConstraintGraph(obj)
                fk = {k: s for k, s in fk.items() if k not in still_ik}
        for k, chain in enumerate(chains):
            if k in fk:
                switches[k] = [fk[k]]
            elif chain is not None:
                switches[k].extend(_stretch_switches(obj, chain))
        return _plan(graph, legs, body, list(others), solved, switches)
    finally:
        if originals:
            _set_props(obj, originals)


def _plan(graph: ConstraintGraph, legs: Sequence[tuple[Sequence[str], Sequence[str]]], body: str,
          others: list[str], solved: list[str], switches: list[list[Switch]]) -> ControlPlan:
    free = [b for b in dict.fromkeys(solved) if b in graph.nodes and graph.free(b)]
    # On a control rig (some solved bone is driven), mechanism bones are never keyed: their
    # controls are. On a plain rig every solved bone is keyed itself, whatever its name.
    control_rig = len(free) < len(dict.fromkeys(solved))
    direct = [b for b in free if not control_rig or b in graph.controls]
    controls: list[ControlKey] = []
    used: set[str] = set()
    uncovered: list[str] = []
    leg_out: list[LegControls] = []
    pbones = graph.obj.pose.bones
    all_switches: list[Switch] = []

    ik_controls: list[str] = []
    for k, (bones, foot) in enumerate(legs):
        hip = bones[0]
        hip_parent = pbones[hip].parent
        base = set(graph.controls_upstream([hip_parent.name])) if hip_parent is not None else set()
        leg_bones = [*bones, *foot[:1]]
        if all(b in direct for b in leg_bones):
            leg_out.append(LegControls())
            continue
        iks = graph.iks_upstream(bones)
        ik_ctrl = pole_ctrl = None
        if iks:
            targets = [t for t, _p in iks if t]
            poles = [p for _t, p in iks if p]
            # The foot control moves the IK target without riding on the body (knee-swing
            # and FK controls hang from the hip's parent) and not through the pole.
            cands = [c for c in graph.controls_upstream(targets, blocked=poles) if c not in base
                     and (hip_parent is None or hip_parent.name not in graph.upstream([c]))]
            # The IK target itself when the animator moves it (MMD's leg IK under its leg IK
            # parent), else the most upstream control moving it (Rigify's foot_ik.L).
            roots = [t for t in targets if t in cands][:1] or graph.roots(cands)
            if roots:
                up = graph.upstream(leg_bones)
                ik_ctrl = min(roots, key=lambda c: (up.get(c, 1 << 30), c))
            if poles:
                target_side = set(graph.controls_upstream(targets, blocked=poles)) | base
                pcands = [c for c in graph.controls_upstream(poles) if c not in target_side]
                proots = graph.roots(pcands)
                if proots:
                    pole_ctrl = proots[0]
        sw = tuple(switches[k])
        all_switches.extend(s for s in sw if (s.bone, s.prop) not in {(o.bone, o.prop) for o in all_switches})
        if ik_ctrl is not None:
            # The control turns like the solved bone nearest to it downstream.
            anchor = _nearest_solved(graph, ik_ctrl, [*foot[:1], *bones[::-1]])
            controls.append(ControlKey(ik_ctrl, "IK", anchor, k))
            used.add(ik_ctrl)
            ik_controls.append(ik_ctrl)
            if pole_ctrl is not None and pole_ctrl not in used:
                controls.append(ControlKey(pole_ctrl, "POLE", bones[0], k))
                used.add(pole_ctrl)
            covered = set(leg_bones)
        else:  # an FK leg: each driven bone turned by its nearest control (its FK control)
            covered = set()
            fk_ctrls: list[str] = []
            halves = _rigid_halves(graph, bones)
            for b in leg_bones:
                if b in direct:
                    continue
                if b in halves:  # rides on the bone above it, at its rest angle
                    covered.add(b)
                    continue
                up = graph.controls_upstream([b])
                fk = [c for c in up if c not in used and c not in base]
                if not fk:
                    break
                ctrl = min(fk, key=lambda c: (up[c], c))
                above = graph.upstream([ctrl])
                follows = min((c for c in fk_ctrls if c in above), key=lambda c: above[c], default="")
                controls.append(ControlKey(ctrl, "TURN", b, follows=follows))
                used.add(ctrl)
                covered.add(b)
                fk_ctrls.append(ctrl)
        leg_out.append(LegControls(ik_ctrl, pole_ctrl, sw, () if ik_ctrl else tuple(fk_ctrls)))
        uncovered.extend(b for b in leg_bones if b not in covered and b not in direct)

    # The body: the most upstream control carrying the body bone and every hip, no IK control.
    ik_up = set(graph.upstream(ik_controls)) if ik_controls else set()
    if body not in direct:
        hips = [bones[0] for bones, _f in legs]
        body_cands = set(graph.controls_upstream([body]))
        for h in hips:
            parent = pbones[h].parent
            body_cands &= set(graph.controls_upstream([parent.name if parent is not None else h]))
        body_cands -= ik_up | used
        # Not the rig's placement root (Rigify's ``root``, Auto-Rig Pro's ``c_traj``: no parent)
        # while a control under it carries the body too.
        placed = {c for c in body_cands if pbones[c].parent is not None}
        # Nor, on legs walked in FK, a control that also carries their idle IK feet
        # (Auto-Rig Pro's ``c_traj`` under ``c_pos``): switched back to IK, the feet would
        # have travelled with the body.
        idle_ik = set(graph.upstream([t for node in graph.nodes.values() for t, _p in node.ik if t]))
        placed = (placed - idle_ik) or placed
        roots = graph.roots(sorted(placed or body_cands))
        if roots:
            up = graph.upstream([body])
            ctrl = min(roots, key=lambda c: (up[c], c))
            controls.append(ControlKey(ctrl, "RIGID", body))
            used.add(ctrl)
        else:
            uncovered.append(body)
    # Anything else that is driven: the nearest control upstream of it, not yet used.
    body_up = set(graph.upstream([body]))
    for name in others:
        if name in direct or name == body:
            continue
        up = graph.controls_upstream([name])
        cands = [c for c in up if c not in used and c not in ik_up and (c not in body_up or up[c] <= 1)]
        if cands:
            # What it copies its transform from before what it only points at (Rigify's
            # ORG-spine.010 copies tweak_spine.010 and stretches to the head control).
            aims = graph.nodes[name].aims
            ctrl = min(cands, key=lambda c: (up[c], c in aims, c))
            # A bone that points at another bone is turned by that one, not by its control.
            controls.append(ControlKey(ctrl, "MOVE" if aims else "RIGID", name))
            used.add(ctrl)
        else:
            uncovered.append(name)
    # Keys on a solved bone that is also driven would fight its controls: not keyed.
    direct = [b for b in direct if b not in uncovered]
    return ControlPlan(tuple(direct), tuple(controls), tuple(leg_out), tuple(all_switches),
                       tuple(dict.fromkeys(uncovered)))


def _nearest_solved(graph: ConstraintGraph, control: str, solved: Sequence[str]) -> str:
    """The solved bone (of ``solved``) the fewest graph steps downstream of ``control``."""
    best = solved[0]
    best_d = 1 << 30
    for b in solved:
        d = graph.upstream([b]).get(control)
        if d is not None and d < best_d:
            best, best_d = b, d
    return best


def describe_leg(leg: LegControls) -> str:
    """What is keyed for a leg, for the user: ``"IK foot_ik.L, pole thigh_ik_target.L"``,
    ``"FK c_thigh_fk.l, c_leg_fk.l"``."""
    parts = [f"FK {', '.join(leg.fk)}"] if leg.fk else []
    if leg.ik:
        parts.append(f"IK {leg.ik}")
    if leg.pole:
        parts.append(f"pole {leg.pole}")
    parts.extend(f"{s.prop} = {s.value:g} on {s.bone}" for s in leg.switches if s.kind != "STRETCH")
    if any(s.kind == "STRETCH" for s in leg.switches):
        parts.append("IK stretch off")
    return ", ".join(parts)


def driver_warnings(obj: bpy.types.Object, keyed: Iterable[str]) -> list[str]:
    """A warning per driver on a transform channel of a ``keyed`` bone (it overrides the keys)."""
    adt = obj.animation_data
    if adt is None:
        return []
    keyed = set(keyed)
    out = []
    for fc in adt.drivers:
        m = _CHANNEL_PATH.match(fc.data_path)
        if m is None or fc.mute:
            continue
        bone = _unescape(m.group(1))
        if bone in keyed:
            out.append(f"bone '{bone}': a driver on {m.group(2)}[{fc.array_index}] overrides the generated "
                       "keys, so the bone will not follow them (the feet may be off the plan)")
    return out


def constraint_warnings(graph: ConstraintGraph, keyed: Iterable[str], solved: Iterable[str]) -> list[str]:
    """Warnings for limit constraints on keyed or solved bones and constraints with targets
    outside the rig on them: ProcLoco cannot drive through either."""
    out: list[str] = []
    for bone in dict.fromkeys([*keyed, *solved]):
        node = graph.nodes.get(bone)
        if node is None:
            continue
        out.extend(f"bone '{bone}': a {constraint_label(kind)} constraint clips its pose, so it may "
                   "not reach the generated keys (the feet may be off the plan)"
                   for kind in dict.fromkeys(node.limits))
        out.extend(f"bone '{bone}': a {constraint_label(kind)} constraint follows '{target}', outside "
                   "the rig, which ProcLoco does not drive (the bone may not land where planned)"
                   for kind, target in dict.fromkeys(node.external))
    return out
