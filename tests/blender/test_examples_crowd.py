# SPDX-License-Identifier: GPL-3.0-or-later
"""The crowd example (``tools/examples/crowd.py``), small: three spiders and two ants built
as the example builds its sixty (linked duplicates of one configured rig per kind), started
near the log so that within 40 frames they walk over it and past each other, generated with
the batch command ``procloco generate --all``.

Measured on the posed rigs, frame by frame through the depsgraph: every rig has its own
Action, its feet keep the thresholds of "What done means for the motion" (see
``test_generate._measure_on``) over the crowd's ground, log and crates, the copies do not
step in lockstep, and no foot of one creature is ever inside another creature's body box
(the box, in the body's heading frame, around its body's skin: cephalothorax and abdomen,
or thorax, head, petiole and gaster).
"""

from __future__ import annotations

from typing import Any

import bpy
import numpy as np
import pytest

from procloco_addon.blender import cli
from procloco_addon.blender.locomotion import crowd as crowd_batch
from tests.blender.pose_eval import pose_matrices, skin_vertices
from tests.blender.test_generate import _measure_on, check_no_pops, check_thresholds, without_pops
from tools.examples import creatures, crowd

pytestmark = pytest.mark.blender

#: The bones whose skin is a creature's body (not its legs, palps or antennae).
BODY_BONES = {"spider": ("Body", "Abdomen"), "ant": ("Thorax", "Head", "Petiole", "Gaster")}
FRAMES = 40


def _body_boxes(rig: Any, frames: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame the body box of ``rig``: its frame (origin ``(F, 3)``, horizontal forward and
    left axes ``(F, 2, 3)``) and half sizes ``(F, 3)`` around the body's skin vertices."""
    kind = str(rig["procloco_kind"])
    skin = creatures.skin_of(rig)
    assert skin is not None
    verts = skin_vertices(skin, frames, BODY_BONES[kind])  # (F, p, 3)
    body = pose_matrices(rig, frames, [BODY_BONES[kind][0]])[:, 0]
    forward = body[:, :3, 1].copy()  # both body bones point forward
    forward[:, 2] = 0.0
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    left = np.stack([-forward[:, 1], forward[:, 0], np.zeros(len(frames))], axis=1)
    up = np.broadcast_to([0.0, 0.0, 1.0], forward.shape)
    axes = np.stack([forward, left, up], axis=1)  # (F, 3, 3)
    local = np.einsum("fij,fpj->fpi", axes, verts)
    lo, hi = local.min(axis=1), local.max(axis=1)
    centre = np.einsum("fij,fi->fj", axes, 0.5 * (lo + hi))
    return centre, axes, 0.5 * (hi - lo)


def test_crowd_example_generates_every_rig_and_no_foot_enters_another_body(empty_scene: Any) -> None:
    scene = bpy.context.scene
    built = crowd.build_crowd_scene(scene, spiders=3, ants=2, frame_end=FRAMES, spider_lanes=3, ant_lanes=2,
                                    front_x=0.45)
    rigs = [rig for group in built.rigs.values() for rig in group]
    assert [len(built.rigs[k]) for k in ("spider", "ant")] == [3, 2]
    for group in built.rigs.values():
        assert "procloco_pending_settings" not in group[0]
        assert all(rig.data == group[0].data for rig in group)  # linked duplicates
        assert len({rig.procloco.seed_offset for rig in group}) == len(group)

    for crate in built.crates:  # every crate stands on the crowd's ground, none floats or sinks
        x, y, z = crate.location
        assert abs(z - float(crowd.crowd_ground_height(np.array(x), np.array(y)))) < 0.01, crate.name

    assert cli.main(["generate", "--all"]) == 0

    actions = [rig.animation_data.action for rig in rigs]
    assert [a.name for a in actions] == [f"{rig.name} ProcLoco" for rig in rigs]
    assert len(set(actions)) == len(rigs)  # each its own Action, also on shared armature data
    terrain = list(bpy.data.collections["Terrain"].objects)
    avoid = [o for o in terrain if o.procloco_role == "AVOID"]
    frames = list(range(crowd.FRAME_START, FRAMES + 1))
    feet: dict[str, np.ndarray] = {}
    swings: dict[str, np.ndarray] = {}
    crossed_log = 0
    # The same inputs again, to read what was simulated (the posed feet must match it): all
    # the rigs read and stepped together, as the batch command did.
    jobs = crowd_batch.read_all(bpy.context, rigs)
    groups = crowd_batch.batches(jobs)
    # One simulation per kind at most (rigs of different foot heights and leg lengths walk
    # in separate ones, see simulation.batch_key).
    assert len(groups) <= len(built.rigs), [g.names for g in groups]
    for _ in crowd_batch.read_terrain(bpy.context, groups):
        pass
    for _ in crowd_batch.simulate(groups):
        pass
    for rig, job in zip(rigs, jobs, strict=True):
        m = _measure_on(rig, job, terrain, avoid)
        feet[rig.name] = m.pop("ends")
        swings[rig.name] = job.result.swing
        check_thresholds(without_pops(m))
        assert m["travel"] > 0.15 * crowd.CROWD_SCALE["spider"] / 5.0, (rig.name, m["travel"])
        check_no_pops(m, str(rig["procloco_kind"]))
        x = feet[rig.name][..., 0]
        crossed_log += int(bool(np.any(np.sign(x[0] - crowd.LOG_X) != np.sign(x[-1] - crowd.LOG_X))))
    assert crossed_log >= 3, "too few creatures stepped over the log"
    # Copies of one rig do not step in lockstep: their gait phases differ.
    spiders = [r.name for r in built.rigs["spider"]]
    assert not np.array_equal(swings[spiders[0]], swings[spiders[1]])

    for other in rigs:
        centre, axes, half = _body_boxes(other, frames)
        for rig in rigs:
            if rig == other:
                continue
            local = np.einsum("fij,flj->fli", axes, feet[rig.name] - centre[:, None, :])
            depth = np.min(half[:, None, :] - np.abs(local), axis=-1)  # > 0: inside the box
            assert depth.max() <= 0.0, f"a foot of {rig.name} entered {other.name}'s body box"
