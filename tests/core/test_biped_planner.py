# SPDX-License-Identifier: GPL-3.0-or-later
"""The whole biped pipeline on the thesis' scenarios (§4.1) and its guarantees."""

from __future__ import annotations

import numpy as np
import pytest

from procloco_addon.core.biped import quat, synth
from procloco_addon.core.biped.database import ClipDatabase
from procloco_addon.core.biped.graph import (
    GoalOffSurfaceError,
    GoalUnreachableError,
    NoClipsError,
    PlanCancelled,
)
from procloco_addon.core.biped.ik import achieved_points
from procloco_addon.core.biped.planner import (
    BipedMotion,
    PlannerSettings,
    foot_size,
    plan_biped,
    stance_slide,
)
from procloco_addon.core.biped.scenarios import SCENARIOS, Scenario, stairs
from procloco_addon.core.biped.skeleton import forward_kinematics
from procloco_addon.core.biped.surface import WalkableSurface, rectangle


@pytest.fixture(scope="module")
def db() -> ClipDatabase:
    skel = synth.make_skeleton()
    return ClipDatabase(skel, synth.standard_library(skel))


_PLANS: dict[str, tuple[Scenario, WalkableSurface, BipedMotion]] = {}


def _planned(db: ClipDatabase, name: str) -> tuple[Scenario, WalkableSurface, BipedMotion]:
    if name not in _PLANS:
        sc = SCENARIOS[name]()
        surf = sc.surface()
        motion = plan_biped(
            db,
            surf,
            sc.start_pos,
            sc.start_yaw,
            sc.goal,
            settings=PlannerSettings(allow_run=sc.allow_run),
            rng=np.random.default_rng(11),
        )
        _PLANS[name] = (sc, surf, motion)
    return _PLANS[name]


def _inside(poly: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Points inside a convex polygon (counter-clockwise corners)."""
    a = poly[:, :2]
    b = np.roll(a, -1, axis=0)
    cross = (b[:, 0] - a[:, 0]) * (xy[:, None, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (
        xy[:, None, 0] - a[:, 0]
    )
    return np.all(cross >= 0.0, axis=1)


SCENES = ["corridor", "curve", "turns", "jumps"]


@pytest.mark.parametrize("name", SCENES)
def test_reaches_the_goal(db: ClipDatabase, name: str) -> None:
    sc, _, m = _planned(db, name)
    assert np.linalg.norm(m.root_pos[-1, :2] - sc.goal[:2]) < 0.10
    assert np.allclose(m.root_pos[0, :2], sc.start_pos[:2], atol=0.05)


@pytest.mark.parametrize("name", SCENES)
def test_planted_feet_do_not_slide(db: ClipDatabase, name: str) -> None:
    _, _, m = _planned(db, name)
    pts = achieved_points(db.skeleton, m.ik)
    slide = stance_slide(pts, m.ik.ik_point, m.contact)
    assert np.nanmax(slide) <= 0.002
    f, s = np.nonzero(m.ik.ik_point >= 0)
    err = np.linalg.norm(pts[f, s, m.ik.ik_point[f, s]] - m.ik_targets[f, s], axis=1)
    assert err.max() <= 0.01


@pytest.mark.parametrize("name", SCENES)
def test_footprints_lie_on_the_surfaces(db: ClipDatabase, name: str) -> None:
    sc, surf, m = _planned(db, name)
    fp = m.footprints
    # Every sole wholly supported at its heading (not merely its centre away from edges).
    assert surf.with_foot(*foot_size(db.skeleton)).supports(fp.pos, fp.yaw).all()
    assert np.allclose(fp.pos[:, 2], surf.height_at(fp.pos), atol=1e-6)
    for gap in sc.gaps:
        assert not _inside(gap, fp.pos).any()
    # The planted feet themselves: heel and toe over the surface, on it within 5 mm.
    pts = achieved_points(db.skeleton, m.ik)
    f, s = np.nonzero(m.ik.ik_point >= 0)
    held = pts[f, s, m.ik.ik_point[f, s]]
    assert surf.supported(held).all()
    assert np.abs(held[:, 2] - surf.height_at(held)).max() < 0.005
    for gap in sc.gaps:
        assert not _inside(gap, pts[f, s].reshape(-1, 3)).any()


@pytest.mark.parametrize("name", SCENES)
def test_bones_keep_their_lengths(db: ClipDatabase, name: str) -> None:
    _, _, m = _planned(db, name)
    skel = db.skeleton
    pos, _ = forward_kinematics(skel, m.joint_rot, m.pelvis_pos)
    lengths = np.linalg.norm(pos[:, 1:] - pos[:, skel.parents[1:]], axis=-1)
    assert np.allclose(lengths, np.linalg.norm(skel.offsets[1:], axis=1), rtol=1e-4)


def test_jumps_jumps_twice_and_runs_into_the_jumps(db: ClipDatabase) -> None:
    _, _, m = _planned(db, "jumps")
    roles = [db.infos[int(c)].role.family for c in m.clips]
    assert roles.count("jump") == 2
    assert roles[0] == "start"
    assert roles[-1] == "stop"
    # The stride before each jump is mostly run (s near 1 at the special clip, §3.7.2).
    runs = [i.index for i in db.by_role("run")]
    for k in np.flatnonzero(np.array(roles) == "jump"):
        assert m.weights[k - 1, -1, runs].sum() > 0.9
    # ... and the character walks again at the start.
    assert m.weights[1, 0, runs].sum() < 0.1


def test_turns_walks_only_and_blends_the_turning_group(db: ClipDatabase) -> None:
    _, _, m = _planned(db, "turns")
    runs = [i.index for i in db.by_role("run")]
    assert m.weights[..., runs].max() == 0.0
    walks = [i.index for i in db.by_role("walk")]
    w = m.weights[1:-1][..., walks]
    # Blended, not one clip at a time: many samples mix two walks.
    mixed = np.sum(w > 0.05, axis=-1) >= 2
    assert mixed.mean() > 0.3


def test_curve_curvature_matches_the_walkway(db: ClipDatabase) -> None:
    _, _, m = _planned(db, "curve")
    walks = {i.index: i.curvature for i in db.by_role("walk")}
    w = m.weights[3:-3]  # away from the start and the stop
    tau = sum(w[..., c] * k for c, k in walks.items())
    # The walkway is a circle of radius 5 m; the body follows it at about that curvature.
    assert np.median(tau) == pytest.approx(1.0 / 5.0, abs=0.06)


def test_same_seed_same_motion(db: ClipDatabase) -> None:
    sc = SCENARIOS["corridor"]()
    surf = sc.surface()
    a = plan_biped(db, surf, sc.start_pos, sc.start_yaw, sc.goal, rng=np.random.default_rng(5))
    b = plan_biped(db, surf, sc.start_pos, sc.start_yaw, sc.goal, rng=np.random.default_rng(5))
    assert np.array_equal(a.joint_rot, b.joint_rot)
    assert np.array_equal(a.root_pos, b.root_pos)
    assert np.array_equal(a.footprints.pos, b.footprints.pos)
    c = plan_biped(db, surf, sc.start_pos, sc.start_yaw, sc.goal, rng=np.random.default_rng(6))
    assert not np.array_equal(a.footprints.pos, c.footprints.pos)  # the graph's samples differ


def test_goal_heading(db: ClipDatabase) -> None:
    surf = WalkableSurface.from_polygons([rectangle((3.0, 0.0, 0.0), (8.0, 8.0))])
    m = plan_biped(db, surf, np.zeros(3), 0.0, np.array([3.5, 1.5]), goal_yaw=np.pi / 2)
    assert np.linalg.norm(m.root_pos[-1, :2] - [3.5, 1.5]) < 0.1
    assert abs(quat.wrap_angle(m.root_yaw[-1] - np.pi / 2)) < 0.05


def test_clear_errors(db: ClipDatabase) -> None:
    surf = WalkableSurface.from_polygons(
        [rectangle((2.0, 0.0, 0.0), (6.0, 2.0)), rectangle((14.0, 0.0, 0.0), (4.0, 2.0))]
    )
    with pytest.raises(GoalOffSurfaceError, match="not on a walkable surface"):
        plan_biped(db, surf, np.zeros(3), 0.0, np.array([8.0, 0.0]))
    with pytest.raises(GoalUnreachableError, match="cannot be reached"):
        plan_biped(db, surf, np.zeros(3), 0.0, np.array([14.0, 0.0]))
    walk_only = ClipDatabase(db.skeleton, [c for c in db.clips if c.role.family == "walk"])
    with pytest.raises(NoClipsError, match="START, a STOP"):
        plan_biped(walk_only, surf, np.zeros(3), 0.0, np.array([3.0, 0.0]))


def test_progress_and_cancel(db: ClipDatabase) -> None:
    sc = SCENARIOS["corridor"]()
    surf = sc.surface()
    seen: list[str] = []

    def record(fraction: float, stage: str) -> bool:
        seen.append(stage)
        return True

    plan_biped(db, surf, sc.start_pos, sc.start_yaw, sc.goal, progress=record)
    assert seen[0] == "search"
    assert seen[-1] == "done"
    assert {"smoothing", "blend groups", "inverse kinematics"} <= set(seen)
    with pytest.raises(PlanCancelled):
        plan_biped(db, surf, sc.start_pos, sc.start_yaw, sc.goal, progress=lambda f, s: s != "smoothing")


_STAIRS: dict[tuple[float, float], tuple[Scenario, WalkableSurface, BipedMotion]] = {}


def _stairs(db: ClipDatabase, goal: tuple[float, float]) -> tuple[Scenario, WalkableSurface, BipedMotion]:
    """The stairs scene with runs and jumps allowed (the clip library has both)."""
    if goal not in _STAIRS:
        sc = stairs(goal)
        surf = sc.surface()
        motion = plan_biped(db, surf, sc.start_pos, sc.start_yaw, sc.goal, rng=np.random.default_rng(11))
        _STAIRS[goal] = (sc, surf, motion)
    return _STAIRS[goal]


def foot_points_world(db: ClipDatabase, m: BipedMotion) -> np.ndarray:
    """Every joint of both feet (the ankles and all below them) in the world: ``(F, P, 3)``."""
    skel = db.skeleton
    pos, _ = forward_kinematics(skel, m.joint_rot, m.pelvis_pos)
    feet = [
        j
        for j in range(skel.n_joints)
        if skel.is_descendant(j, skel.left.ankle) or skel.is_descendant(j, skel.right.ankle)
    ]
    return m.root_pos[:, None, :] + quat.rot2(m.root_yaw[:, None], pos[:, feet])


@pytest.mark.parametrize("goal", [(9.0, 0.0), (4.8, 0.0)], ids=["beyond", "landing"])
def test_stairs_are_walked_a_tread_at_a_time(db: ClipDatabase, goal: tuple[float, float]) -> None:
    sc, surf, m = _stairs(db, goal)
    assert np.linalg.norm(m.root_pos[-1, :2] - sc.goal[:2]) < 0.10
    fp = m.footprints
    assert fp.pos[:, 2].max() == pytest.approx(0.6)  # up on the landing
    # Every foot set down wholly on one tread; from one footprint to the next one rise.
    assert surf.with_foot(*foot_size(db.skeleton)).supports(fp.pos, fp.yaw).all()
    assert np.abs(np.diff(fp.pos[:, 2])).max() <= 0.15 + 1e-6
    # Walked, not jumped (the library has a jump and runs).
    roles = {db.infos[int(c)].role.family for c in m.clips}
    assert "jump" not in roles


@pytest.mark.parametrize("goal", [(9.0, 0.0), (4.8, 0.0)], ids=["beyond", "landing"])
def test_stairs_feet_never_enter_the_steps(db: ClipDatabase, goal: tuple[float, float]) -> None:
    """Planted or swinging, no joint of a foot goes below the tread or into a riser."""
    _, surf, m = _stairs(db, goal)
    pts = foot_points_world(db, m)
    ground = surf.height_at(pts[..., :2])
    assert np.isfinite(ground).all()
    assert (ground - pts[..., 2]).max() <= 0.005
    # Still planted where planted: no sliding, targets reached.
    held = achieved_points(db.skeleton, m.ik)
    assert np.nanmax(stance_slide(held, m.ik.ik_point, m.contact)) <= 0.002
