# SPDX-License-Identifier: GPL-3.0-or-later
"""Crowd step time on the thesis's Table 3.1 scene, with LOD, zoomed LOD and no LOD.

    python benchmarks/bench_crowd.py [--chars 100] [--steps 60] [--warmup 15] [--seed 0]
                                     [--scale 2.0] [--profile] [--modes LOD,...]
                                     [--avoid] [--spread 0.8]

The scene (benchmarks/scenes.py): a 100 m heightmap with 3000 crates, 40 % of them moving;
planning windows of 70 × 70 cells of 7 cm. The crowd: ``--chars`` eight-legged spiders
(``morphology.spider(scale)``; at the default scale 2 the legs are 1.08 m long, so a 7 cm cell
is 6.5 % of a leg, the controller's own default ratio), alternating tetrapod gait, walking
at 0.3 × scale m/s along random headings; pelvis pseudo-physics off (chapter 3 system). The
crates move between steps; that motion is not part of the step time.

Three camera set-ups, as in thesis §3.7 and Table 3.1:

- **LOD**: every character on screen, seen from a corner of the crowd; the planner budget
  falls linearly with the distance to the camera, from 3 couples after the first valid one
  with 10 cm slices (nearest) to the first valid couple without slices (farthest).
- **LOD zoomed**: the camera zoomed on one character; the nearest half of the crowd is on
  screen with the same linear budget but a full search for the nearest; the other half is
  off screen: first valid couple, no slices, no IK.
- **No LOD**: everyone does the full best-couple search with 10 cm slices, and the IK.

The table gives the mean step time and its parts (maps = window grids, planning = the
footprint planner, IK, rest = everything else in the controller) next to the thesis's
figures (C++, four threads), then planner counts per step. Times are CPU seconds of this
single-threaded process (``time.process_time``), so that other jobs on a shared machine do
not inflate them; the wall time is printed beside them. The last line is
``RESULT crowd step_s_lod=<s> step_s_zlod=<s> step_s_nolod=<s>``.

``--avoid``: the spiders see each other (``Simulation(avoid=...)``: bodies and feet as
obstacles, steering); ``--spread``: the share of the world they start in (0.8; 0.1 packs
the 100 spiders into 10 m × 10 m, where they meet all the time).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import platform
import pstats
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.scenes import CrowdScene, make_crowd_scene, spawn_points
from procloco_addon.core.locomotion import morphology
from procloco_addon.core.locomotion.gait import find_gait_preset
from procloco_addon.core.locomotion.sim import Controls, Simulation
from procloco_addon.core.locomotion.types import ControllerParams, PlannerLOD

FloatArray = npt.NDArray[np.float64]

THESIS = {"LOD": (0.029, 0.004, 0.013), "LOD zoomed": (0.032, 0.004, 0.006), "No LOD": (0.051, 0.004, 0.013)}
PHASES = ("maps", "planning", "ik", "rest")


@dataclass
class ModeResult:
    name: str
    step_s: float
    wall_s: float
    phase_s: dict[str, float]
    plans: float
    couples: float
    paths: float
    failed: float
    replans: float
    forced: float
    windows: float
    crates_s: float


def linear_lod(rank: FloatArray, full_nearest: bool) -> list[PlannerLOD]:
    """Budget by normalised camera distance ``rank`` in [0, 1] (0 = nearest): couples after
    the first valid one from 3 down to 0, slices from 10 cm up to none (thesis §3.7)."""
    out = []
    for r in rank.tolist():
        couples: int | None = round(3.0 * (1.0 - r))
        if full_nearest and r < 0.1:
            couples = None
        slice_size = None if r > 0.8 else 0.10 + 0.10 * r
        out.append(PlannerLOD(max_couples_after_first=couples, slice_size=slice_size))
    return out


def camera_setup(mode: str, xy: FloatArray) -> tuple[list[PlannerLOD], npt.NDArray[np.bool_]]:
    """Per-character planner LOD and IK flags for a camera set-up."""
    n = xy.shape[0]
    if mode == "No LOD":
        return [PlannerLOD(None, 0.1)] * n, np.ones(n, dtype=bool)
    if mode == "LOD":
        camera = xy.min(axis=0) - 5.0  # a corner of the crowd, everyone in view
        d = np.linalg.norm(xy - camera, axis=1)
        rank = (d - d.min()) / max(float(np.ptp(d)), 1e-9)
        return linear_lod(rank, full_nearest=False), np.ones(n, dtype=bool)
    # zoomed on character 0: the nearest half is on screen
    d = np.linalg.norm(xy - xy[0], axis=1)
    order = np.argsort(d, kind="stable")
    on_screen = np.zeros(n, dtype=bool)
    on_screen[order[: (n + 1) // 2]] = True
    rank = np.zeros(n)
    rank[order[: (n + 1) // 2]] = np.linspace(0.0, 1.0, (n + 1) // 2)
    lods = linear_lod(rank, full_nearest=True)
    off = PlannerLOD(max_couples_after_first=0, slice_size=None)
    return [lod if on else off for lod, on in zip(lods, on_screen, strict=True)], on_screen


def build(args: argparse.Namespace, mode: str) -> tuple[CrowdScene, Simulation]:
    scene = make_crowd_scene(seed=args.seed)
    xy, heading = spawn_points(scene, args.chars, seed=args.seed + 1, spread=args.spread)
    spider = morphology.spider(args.scale)
    gait = find_gait_preset("octopod_alternating_tetrapod").gait(spider.labels)
    gait = gait.with_cycle_time(0.7 * float(np.sqrt(args.scale)))
    lod, ik = camera_setup(mode, xy)
    controls = Controls(speed=0.3 * args.scale, heading=heading, step_height=0.05 * args.scale, ik=ik)
    sim = Simulation(
        scene.env,
        [spider] * args.chars,
        gait,
        start_xy=xy,
        start_yaw=heading,
        controls=controls,
        phase="random",
        seed=args.seed,
        params=ControllerParams(window_cells=70, window_cell=0.07, clock=time.process_time),
        lod=lod,
        avoid=[True] * args.chars if args.avoid else None,
    )
    return scene, sim


def run_mode(args: argparse.Namespace, mode: str) -> ModeResult:
    scene, sim = build(args, mode)
    for _ in range(args.warmup):
        scene.advance(sim.dt)
        sim.step()
    totals = dict.fromkeys(PHASES, 0.0)
    counts = {"plans": 0, "couples": 0, "paths": 0, "failed": 0, "replans": 0, "forced": 0, "windows": 0}
    step_time = 0.0
    wall_time = 0.0
    crates = 0.0
    profiler = cProfile.Profile() if args.profile else None
    for _ in range(args.steps):
        t0 = time.process_time()
        scene.advance(sim.dt)
        t1 = time.process_time()
        w1 = time.perf_counter()
        if profiler is not None:
            profiler.enable()
        stats = sim.step()
        if profiler is not None:
            profiler.disable()
        t2 = time.process_time()
        wall_time += time.perf_counter() - w1
        crates += t1 - t0
        step_time += t2 - t1
        for k in PHASES:
            totals[k] += stats.seconds.get(k, 0.0) + (
                stats.seconds.get("physics", 0.0) if k == "rest" else 0.0
            )
        counts["plans"] += stats.n_plans
        counts["couples"] += stats.n_couples
        counts["paths"] += stats.n_paths
        counts["failed"] += stats.n_failed
        counts["replans"] += stats.n_replans
        counts["forced"] += stats.n_forced
        counts["windows"] += stats.n_windows
    n = args.steps
    # what the controller's timers did not see (the loop, recording) goes to "rest"
    measured = sum(totals.values())
    totals["rest"] += max(step_time - measured, 0.0)
    if profiler is not None:
        print(f"\n--- profile: {mode} ({n} steps) ---")
        pstats.Stats(profiler).sort_stats("tottime").print_stats(args.top)
        if args.profile_out:
            profiler.dump_stats(f"{args.profile_out}.{mode.replace(' ', '_')}.prof")
    return ModeResult(
        name=mode,
        step_s=step_time / n,
        wall_s=wall_time / n,
        phase_s={k: v / n for k, v in totals.items()},
        plans=counts["plans"] / n,
        couples=counts["couples"] / n,
        paths=counts["paths"] / n,
        failed=counts["failed"] / n,
        replans=counts["replans"] / n,
        forced=counts["forced"] / n,
        windows=counts["windows"] / n,
        crates_s=crates / n,
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--chars", type=int, default=100)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--warmup", type=int, default=15)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scale", type=float, default=2.0)
    parser.add_argument("--avoid", action="store_true", help="the spiders see each other")
    parser.add_argument("--spread", type=float, default=0.8, help="share of the world they start in")
    parser.add_argument("--profile", action="store_true", help="print the hottest functions of each mode")
    parser.add_argument(
        "--profile-out", default="", help="with --profile: also save each mode's stats to PREFIX.<mode>.prof"
    )
    parser.add_argument("--top", type=int, default=18, help="functions listed per profile")
    parser.add_argument(
        "--modes", default="LOD,LOD zoomed,No LOD", help="comma-separated camera set-ups (default: all three)"
    )
    args = parser.parse_args()

    print(
        f"crowd benchmark: {args.chars} spiders (scale {args.scale:g}), Table 3.1 scene, "
        f"{args.steps} steps of 1/30 s after {args.warmup} warm-up steps"
    )
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}, one process, one thread"
    )
    results = [run_mode(args, mode.strip()) for mode in args.modes.split(",")]

    print()
    header = (
        f"{'mode':<11} {'step s':>8} {'maps':>8} {'planning':>9} {'IK':>8} {'rest':>8} {'wall s':>8}"
        f"   {'thesis':>7} {'maps':>6} {'IK':>6}"
    )
    print("seconds per step; 'step s' and its parts are CPU time of this process, 'wall s' the wall")
    print("time (they differ only when other work shares the machine)")
    print(header)
    print("-" * len(header))
    for r in results:
        t_total, t_maps, t_ik = THESIS[r.name]
        ph = r.phase_s
        print(
            f"{r.name:<11} {r.step_s:8.4f} {ph['maps']:8.4f} {ph['planning']:9.4f} {ph['ik']:8.4f} "
            f"{ph['rest']:8.4f} {r.wall_s:8.4f}   {t_total:7.3f} {t_maps:6.3f} {t_ik:6.3f}"
        )
    print()
    print(
        f"{'mode':<11} {'plans':>7} {'couples':>8} {'paths':>7} {'failed':>7} {'replans':>8} {'forced':>7} "
        f"{'windows':>8} {'ms/plan':>8} {'crates s':>9}   (per step)"
    )
    for r in results:
        per_plan = 1000.0 * r.phase_s["planning"] / max(r.plans, 1e-9)
        print(
            f"{r.name:<11} {r.plans:7.1f} {r.couples:8.1f} {r.paths:7.1f} {r.failed:7.2f} {r.replans:8.2f} "
            f"{r.forced:7.2f} {r.windows:8.1f} {per_plan:8.2f} {r.crates_s:9.4f}"
        )
    by = {r.name: r.step_s for r in results}
    print()
    keys = {"LOD": "lod", "LOD zoomed": "zlod", "No LOD": "nolod"}
    print("RESULT crowd " + " ".join(f"step_s_{keys[name]}={s:.4f}" for name, s in by.items()))


if __name__ == "__main__":
    main()
