# SPDX-License-Identifier: GPL-3.0-or-later
"""Motion quality of every example creature at its gait preset's speed, on every kind of
terrain: the numbers of DESIGN.md's "What done means for the motion" per scenario.

    python benchmarks/bench_quality.py [--kinds spider,wolf] [--terrains flat,crates]
                                       [--speeds 0.5,1.0] [--frames 120] [--fps 24]
                                       [--core-defaults] [--crowd 20] [--verbose]

Creatures (``core.locomotion.morphology`` builders, scaled to the leg length of the example rig of the
same kind, with the gait preset the example applies): spider (octopod alternating
tetrapod), ant (hexapod tripod), robot (pentapod), wolf (quadruped walk, flexible spine),
wolf-rigid (the same without the spine), lizard (quadruped trot, flexible spine), human
(biped walk). Speeds are fractions of the preset's speed (leg lengths per second times the
leg length); step height and pelvis physics as the preset gives them on the first click.

Terrains, sized to the creature's leg length ``L``; the creature starts at the origin and
walks along +X:

- ``flat``; ``hills``: the wavy heightmap of the Blender tests (±0.06 L);
- ``crates``: hills plus a low crate to step on or over and a tall (1.5 L) crate to keep off
  beside the path (the Blender tests' layout); ``crates+mover``: the same with a low crate
  sliding across the path;
- ``moving``: an avoided crate 0.7 L wide and 0.6 L tall sliding ±1.2 L back and forth
  across the path every 4 s (up to 1.9 L/s; the example spider lane's moving crate);
- ``stairs``: four steps up (0.15 L rise), a landing, four steps down;
- ``gap``: a hole with no surface, 0.5 L wide, across the path (the ground is a mesh);
- ``turn``: flat ground, the heading commanded 90° to the left after 1.5 s.

Controller and planner settings are the creature-size scaling Generate Locomotion uses
(``core.locomotion.scaling.scaled_params``: cells, slices and edge height in leg lengths, gravity and
tolerances scaled with the creature as for the gait circles), unless ``--core-defaults``.

Each row gives, against its threshold: the largest stance-foot slide (2 mm), penetration
below a surface, a planted foot hanging above the ground (hover) and penetration into an
avoided obstacle (5 mm), IK error on reachable targets (1 cm), the largest target
extension (legs asked to reach more than their length, 1), the worst gait-phase error (1
frame), then planner failures, forced steps, straight fallback steps and swing frames bent
to what the leg reaches (a swinging foot whose trajectory point the leg cannot reach goes
to the closest point it can), frames in which the character stands on fewer than min(2,
legs - 1) feet (low) and on none (air). ``--crowd N`` adds N spiders of the crowd
benchmark's scene (moving crates): how many legs were asked past their length, and planner
failures per step. The last line is
``RESULT quality scenarios=<n> failing=<n> worst_slide_mm=<mm> worst_reach_cm=<cm>``.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from procloco_addon.core import metrics as mx
from procloco_addon.core.locomotion import morphology
from procloco_addon.core.locomotion.gait import find_gait_preset
from procloco_addon.core.locomotion.morphology import Morphology
from procloco_addon.core.locomotion.scaling import scaled_params
from procloco_addon.core.locomotion.sim import Controls, SimResult, Simulation, check_motion
from procloco_addon.core.locomotion.spine import SpineParams
from procloco_addon.core.locomotion.types import ControllerParams
from procloco_addon.core.world.terrain import (
    ROLE_AVOID,
    ROLE_GROUND,
    ROLE_STEP_OVER,
    Boxes,
    Environment,
    Heightmap,
    TriangleSoup,
)

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Kind:
    """An example creature: its core builder, the preset it walks with, the mean leg length
    of the example rig (metres) and whether it walks with the flexible spine."""

    build: Callable[[float], Morphology]
    preset: str
    leg: float
    spine: bool = False


KINDS: dict[str, Kind] = {
    "spider": Kind(morphology.spider, "octopod_alternating_tetrapod", 0.69),
    "ant": Kind(morphology.hexapod, "hexapod_tripod", 0.39),
    "robot": Kind(morphology.pentapod, "pentapod_robot", 0.66),
    "wolf": Kind(lambda s: morphology.quadruped(s, spine=True), "quadruped_walk", 0.73, spine=True),
    "wolf-rigid": Kind(lambda s: morphology.quadruped(s, spine=False), "quadruped_walk", 0.73),
    "lizard": Kind(lambda s: morphology.lizard(s, spine=True), "quadruped_trot", 0.167, spine=True),
    "human": Kind(morphology.biped, "biped_walk", 0.99),
}


@dataclass
class Terrain:
    """An environment, how it moves (``move(env, time)``, None if static) and the heading
    command (``heading(time)``)."""

    env: Environment
    move: Callable[[Environment, float], None] | None = None
    heading: Callable[[float], float] = field(default=lambda t: 0.0)


def _grid(leg: float, y_range: tuple[float, float] = (-3.0, 3.0)) -> tuple[FloatArray, FloatArray, float]:
    """Sample coordinates (x from -2 L to 10 L, y over ``y_range`` leg lengths) and spacing."""
    cell = 0.05 * leg
    x = np.arange(-2.0 * leg, 10.0 * leg, cell)
    y = np.arange(y_range[0] * leg, y_range[1] * leg, cell)
    return x, y, cell


def _hills(gx: FloatArray, gy: FloatArray, leg: float) -> FloatArray:
    """The Blender tests' wavy ground (walking along +X here), level near the start."""
    z = 0.06 * leg * np.sin(gy / (1.3 * leg)) * np.cos(gx / (1.7 * leg))
    return np.asarray(np.where(np.hypot(gx, gy) < 1.2 * leg, 0.0, z))


def _heightmap(leg: float, hills: bool, y_range: tuple[float, float] = (-3.0, 3.0)) -> Heightmap:
    x, y, cell = _grid(leg, y_range)
    gx, gy = np.meshgrid(x, y)
    z = _hills(gx, gy, leg) if hills else np.zeros_like(gx)
    return Heightmap(z, np.array([x[0], y[0]]), cell)


_BoxRow = tuple[tuple[float, float], tuple[float, float, float], int, bool]


def _boxes(hm: Heightmap, rows: list[_BoxRow]) -> Boxes:
    """Upright boxes ``(centre xy, size, role, moving)`` resting on the heightmap (their bottom
    at the lowest ground under their corners)."""
    xy = np.array([r[0] for r in rows], dtype=np.float64)
    size = np.array([r[1] for r in rows], dtype=np.float64)
    corners = np.array([[-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5], [0.5, 0.5], [0.0, 0.0]])
    under = hm.sample(xy[:, None, :] + corners[None, :, :] * size[:, None, :2])
    centre = np.column_stack([xy, under.min(axis=1) - 0.005])
    role = np.array([r[2] for r in rows])
    return Boxes(centre, size, np.zeros(len(rows)), role, np.array([r[3] for r in rows]))


def terrain(name: str, leg: float, fps: float, frames: int) -> Terrain:
    """The terrain ``name`` sized to a leg of ``leg`` metres (see the module docstring)."""
    L = leg
    if name == "flat":
        return Terrain(Environment(_heightmap(L, hills=False)))
    if name == "hills":
        return Terrain(Environment(_heightmap(L, hills=True)))
    if name in ("crates", "crates+mover"):
        hm = _heightmap(L, hills=True)
        rows = [
            ((1.6 * L, 0.25 * L), (0.6 * L, 1.0 * L, 0.12 * L), ROLE_STEP_OVER, False),
            ((2.6 * L, 1.25 * L), (0.8 * L, 0.8 * L, 1.5 * L), ROLE_AVOID, False),
        ]
        mover = name == "crates+mover"
        if mover:
            rows.append(((3.2 * L, -3.0 * L), (0.6 * L, 0.6 * L, 0.1 * L), ROLE_STEP_OVER, True))
        env = Environment(hm, _boxes(hm, rows))
        if not mover:
            return Terrain(env)
        z0 = float(env.boxes.center[2, 2])
        duration = (frames - 1) / fps

        def slide(e: Environment, t: float) -> None:
            y = -3.0 * L + 6.0 * L * min(t / duration, 1.0)
            e.move_boxes(np.array([2]), np.array([[3.2 * L, y, z0]]), np.zeros(1))

        return Terrain(env, slide)
    if name == "moving":
        hm = _heightmap(L, hills=False)
        env = Environment(hm, _boxes(hm, [((2.4 * L, 0.0), (0.7 * L, 0.7 * L, 0.6 * L), ROLE_AVOID, True)]))

        def sway(e: Environment, t: float) -> None:
            y = 1.2 * L * np.sin(2.0 * np.pi * t / 4.0)
            e.move_boxes(np.array([0]), np.array([[2.4 * L, y, -0.005]]), np.zeros(1))

        sway(env, 0.0)
        return Terrain(env, sway)
    if name == "stairs":
        hm = _heightmap(L, hills=False)
        rise, tread, n = 0.15 * L, 0.4 * L, 4
        x0 = 1.5 * L
        blocks = [(x0 + k * tread, x0 + (k + 1) * tread, (k + 1) * rise) for k in range(n)]
        top = x0 + n * tread
        blocks.append((top, top + 1.5 * L, n * rise))
        down = top + 1.5 * L
        blocks += [(down + k * tread, down + (k + 1) * tread, (n - 1 - k) * rise) for k in range(n - 1)]
        rows = [(((a + b) / 2, 0.0), (b - a, 4.0 * L, h), ROLE_GROUND, False) for a, b, h in blocks]
        xy = np.array([r[0] for r in rows])
        size = np.array([r[1] for r in rows])
        boxes = Boxes(np.column_stack([xy, np.zeros(len(rows))]), size, np.zeros(len(rows)),
                      np.full(len(rows), ROLE_GROUND), np.zeros(len(rows), dtype=bool))
        return Terrain(Environment(hm, boxes))
    if name == "gap":
        x, y, cell = _grid(L)
        gx, gy = np.meshgrid(x, y)
        verts = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
        ny, nx = gx.shape
        i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
        v00 = (j * nx + i).ravel()
        cx = (x[:-1] + 0.5 * cell)[i.ravel()]
        keep = ~((cx > 2.0 * L) & (cx < 2.5 * L))
        v00 = v00[keep]
        tris = np.concatenate([np.column_stack([v00, v00 + 1, v00 + nx + 1]),
                               np.column_stack([v00, v00 + nx + 1, v00 + nx])])
        return Terrain(Environment(soups=[TriangleSoup(verts, tris, ROLE_GROUND)]))
    if name == "turn":
        return Terrain(Environment(_heightmap(L, hills=False, y_range=(-3.0, 10.0))),
                       heading=lambda t: 0.0 if t <= 1.5 else 0.5 * np.pi)
    raise ValueError(f"unknown terrain {name!r}")


TERRAINS = ("flat", "hills", "crates", "crates+mover", "moving", "stairs", "gap", "turn")


@dataclass
class Row:
    kind: str
    terrain: str
    speed: float
    report: mx.MotionReport
    travel: float
    failed: int
    forced: int
    fallback: int
    bent: int
    low: int
    airborne: int
    seconds: float

    @property
    def passed(self) -> bool:
        return self.report.passed


def run_one(kind_name: str, terrain_name: str, speed_frac: float, frames: int, fps: float,
            core_defaults: bool = False) -> tuple[Row, SimResult]:
    """Simulate one scenario and measure it."""
    kind = KINDS[kind_name]
    unit = kind.build(1.0)
    scale = kind.leg / float(unit.leg_length.mean())
    m = kind.build(scale)
    leg = float(m.leg_length.mean())
    preset = find_gait_preset(kind.preset)
    gait = preset.gait(m.labels)
    speed = preset.speed * leg * speed_frac
    step_height = preset.step_height * leg
    ter = terrain(terrain_name, leg, fps, frames)
    if core_defaults:
        params, planner = None, None
    else:
        params, planner_one = scaled_params(leg, step_height)
        planner = [planner_one]

    def controls(t: float) -> Controls:
        return Controls(speed=speed, heading=ter.heading(t), step_height=step_height, pelvis_physics=True)

    sim = Simulation(ter.env, [m], gait, controls=controls, dt=1.0 / fps, params=params, planner=planner,
                     spine=SpineParams() if kind.spine else None)
    move = ter.move

    def on_step(s: Simulation) -> None:
        if move is not None:
            move(s.env, s.time + s.dt)

    t0 = time.perf_counter()
    res = sim.run(frames - 1, on_step=on_step if move is not None else None)
    seconds = time.perf_counter() - t0
    report = check_motion(res, ter.env, settle=preset.cycle_time)
    down = res.contact.sum(axis=1)
    n_legs = res.contact.shape[1]
    row = Row(
        kind_name, terrain_name, speed_frac, report,
        travel=float(np.linalg.norm(res.pelvis_position[-1, 0, :2] - res.pelvis_position[0, 0, :2])) / leg,
        failed=int(res.stats["n_failed"].sum()), forced=int(res.stats["n_forced"].sum()),
        fallback=int(res.stats["n_fallback"].sum()), bent=int(res.stats["n_bent"].sum()),
        low=int((down < min(2, n_legs - 1)).sum()), airborne=int((down == 0).sum()), seconds=seconds,
    )
    return row, res


def _fmt(value: float, limit: float, spec: str) -> str:
    mark = "!" if value > limit else " "
    return f"{value:{spec}}{mark}"


def print_table(rows: list[Row]) -> None:
    head = (f"{'creature':<11}{'terrain':<13}{'speed':>5} {'slide mm':>9} {'pen mm':>8} {'hover mm':>9} "
            f"{'avoid mm':>9} "
            f"{'reach cm':>9} {'ext':>7} {'phase':>6} {'fail':>5} {'forced':>6} {'fallbk':>6} {'bent':>5} "
            f"{'low':>4} {'air':>4} "
            f"{'travel':>6} "
            f"{'s':>5}")
    print(head)
    print("-" * len(head))
    for r in rows:
        rep = r.report
        phase = rep.phase.max_abs if rep.phase is not None else 0.0
        print(
            f"{r.kind:<11}{r.terrain:<13}{r.speed:>5.2f} "
            f"{_fmt(float(rep.stance_slide.max()) * 1000, mx.MAX_STANCE_SLIDE * 1000, '8.2f')} "
            f"{_fmt(rep.penetration * 1000, mx.MAX_PENETRATION * 1000, '7.2f')} "
            f"{_fmt(rep.hover * 1000, mx.MAX_PENETRATION * 1000, '8.2f')} "
            f"{_fmt(rep.avoid_intrusion * 1000, mx.MAX_PENETRATION * 1000, '8.2f')} "
            f"{_fmt(float(rep.reach_error.max()) * 100, mx.MAX_REACH_ERROR * 100, '8.3f')} "
            f"{_fmt(float(rep.extension.max()), mx.MAX_EXTENSION, '6.3f')} "
            f"{_fmt(phase, mx.MAX_PHASE_ERROR_FRAMES, '5.2f')} "
            f"{r.failed:>5d} {r.forced:>6d} {r.fallback:>6d} {r.bent:>5d} {r.low:>4d} {r.airborne:>4d} "
            f"{r.travel:>6.2f} {r.seconds:>5.1f}"
        )


def crowd(n_chars: int, steps: int, seed: int = 0) -> dict[str, float]:
    """``n_chars`` spiders (legs 1.08 m) of the crowd benchmark walking ``steps`` steps in its
    scene: legs asked past their length, their worst extension, failures per step."""
    from benchmarks.scenes import make_crowd_scene, spawn_points

    scene = make_crowd_scene(seed=seed)
    xy, heading = spawn_points(scene, n_chars, seed=seed + 1)
    spider = morphology.spider(2.0)
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(spider.labels)
    gait = gait.with_cycle_time(0.7 * float(np.sqrt(2.0)))
    sim = Simulation(scene.env, [spider] * n_chars, gait, start_xy=xy, start_yaw=heading,
                     controls=Controls(speed=0.6, heading=heading, step_height=0.1),
                     phase="random", seed=seed,
                     params=ControllerParams(window_cells=70, window_cell=0.07))
    for _ in range(steps):
        scene.advance(sim.dt)
        sim.step()
    res = sim.result()
    ext = mx.target_extension(res.hips, res.foot, res.legs.leg_length)
    slide = mx.stance_sliding(res.end_effector, res.contact)
    return {
        "legs": float(res.legs.n_legs),
        "over_1": float((ext > mx.MAX_EXTENSION).sum()),
        "worst_ext": float(ext.max()),
        "sliding_legs": float((slide > mx.MAX_STANCE_SLIDE).sum()),
        "worst_slide_mm": float(slide.max() * 1000),
        "failed_per_step": float(res.stats["n_failed"][1:].mean()),
        "forced_per_step": float(res.stats["n_forced"][1:].mean()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--terrains", default=",".join(TERRAINS))
    ap.add_argument("--speeds", default="1.0")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--fps", type=float, default=24.0)
    ap.add_argument("--core-defaults", action="store_true")
    ap.add_argument("--crowd", type=int, default=0)
    ap.add_argument("--crowd-steps", type=int, default=90)
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args()
    settings = "core default" if args.core_defaults else "creature-scaled"
    print(f"bench_quality: {platform.python_version()} numpy {np.__version__}, {args.frames} frames at "
          f"{args.fps:g} fps, {settings} controller and planner settings")
    rows: list[Row] = []
    for kind in args.kinds.split(","):
        for ter in args.terrains.split(","):
            for speed in (float(s) for s in args.speeds.split(",")):
                row, _ = run_one(kind, ter, speed, args.frames, args.fps, args.core_defaults)
                rows.append(row)
                if args.verbose and not row.passed:
                    print(kind, ter, speed, "; ".join(row.report.failures()), flush=True)
    print_table(rows)
    failing = [r for r in rows if not r.passed]
    print(f"\n{len(rows) - len(failing)} of {len(rows)} scenarios meet every threshold "
          "(! marks a number over its threshold)")
    if args.crowd:
        c = crowd(args.crowd, args.crowd_steps)
        print(f"\ncrowd: {args.crowd} spiders, {args.crowd_steps} steps, moving crates: "
              f"{c['over_1']:.0f} of {c['legs']:.0f} legs asked past their length "
              f"(worst {c['worst_ext']:.3f}), {c['sliding_legs']:.0f} sliding > 2 mm "
              f"(worst {c['worst_slide_mm']:.1f} mm), {c['failed_per_step']:.3f} planner failures "
              f"and {c['forced_per_step']:.3f} forced steps per step")
    worst_slide = max(float(r.report.stance_slide.max()) for r in rows) * 1000
    worst_reach = max(float(r.report.reach_error.max()) for r in rows) * 100
    print(f"RESULT quality scenarios={len(rows)} failing={len(failing)} worst_slide_mm={worst_slide:.2f} "
          f"worst_reach_cm={worst_reach:.3f}")


if __name__ == "__main__":
    main()
