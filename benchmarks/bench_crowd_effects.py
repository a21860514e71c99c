# SPDX-License-Identifier: GPL-3.0-or-later
"""What chapter 4's effects cost in the crowd: pelvis pseudo-physics and the flexible spine.

    python benchmarks/bench_crowd_effects.py [--chars 100] [--steps 60] [--warmup 15] [--seed 0]
                                             [--profile]

The scene and camera are the crowd benchmark's (``bench_crowd.py``: the thesis's Table 3.1
scene, 100 m heightmap, 3000 crates of which 40 % move, 70 × 70 planning cells of 7 cm,
everyone in view with the linear LOD of thesis §3.7). Two crowds, as in thesis §4.4:

- **spiders** (figure 4.20): ``--chars`` eight-legged spiders (``morphology.spider(2)``,
  legs 1.08 m), alternating tetrapod, without and with pelvis pseudo-physics (§4.1);
- **quadrupeds** (figure 4.21): half wolf-like quadrupeds (``morphology.quadruped(2,
  spine=True)``: 7 spine joints, 3 virtual pelvis nodes, legs 0.96–1.07 m, walk) and half
  lizards (``morphology.lizard(4)``: 9 spine joints, 3 nodes, legs 0.9 m, trot): rigid
  (base), rigid with pseudo-physics, and with the flexible spine plus pseudo-physics, then
  the spine alone.

Every setting runs its own copy of the scene with the same seeds; the settings take turns
step by step so that other work on a shared machine slows them alike. Times are CPU seconds
of this process (``time.process_time``) per step; the crates' motion is not counted. The
table gives each setting's mean step time, its ratio to the base of its crowd (the thesis
reports +9 % for pseudo-physics and +30–40 % for the spine with pseudo-physics, C++), and
the controller's phases. The last line is
``RESULT crowd_effects step_s_base=<s> step_s_physics=<s> step_s_spine=<s>`` for the
quadruped crowd (base, pseudo-physics, spine with pseudo-physics).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import platform
import pstats
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.bench_crowd import camera_setup
from benchmarks.scenes import CrowdScene, make_crowd_scene, spawn_points
from procloco_addon.core.locomotion import morphology
from procloco_addon.core.locomotion.gait import Gait, find_gait_preset
from procloco_addon.core.locomotion.morphology import Morphology
from procloco_addon.core.locomotion.sim import Controls, Simulation
from procloco_addon.core.locomotion.spine import SpineParams
from procloco_addon.core.locomotion.types import ControllerParams

PHASES = ("maps", "planning", "ik", "physics", "spine", "rest")
#: The thesis's cost of each effect relative to the base (figures 4.20, 4.21), as text.
THESIS_RATIO = {"physics": "1.09", "spine + physics": "1.30-1.40"}


@dataclass
class Setting:
    crowd: str
    name: str
    physics: bool
    spine: bool
    step_s: list[float] = field(default_factory=list)
    phase_s: dict[str, float] = field(default_factory=dict)
    plans: int = 0
    forced: int = 0


def crowd_of(kind: str, n: int) -> tuple[list[Morphology], list[Gait], np.ndarray]:
    """Morphologies, gaits and speeds (m/s) of ``n`` characters of a crowd."""
    if kind == "spiders":
        spider = morphology.spider(2.0)
        gait = find_gait_preset("octopod_alternating_tetrapod").gait(spider.labels)
        gait = gait.with_cycle_time(0.7 * float(np.sqrt(2.0)))
        return [spider] * n, [gait] * n, np.full(n, 0.6)
    wolf = morphology.quadruped(2.0, spine=True)
    lizard = morphology.lizard(4.0)
    walk = find_gait_preset("quadruped_walk").gait(wolf.labels).with_cycle_time(float(np.sqrt(2.0)))
    trot = find_gait_preset("quadruped_trot").gait(lizard.labels).with_cycle_time(0.6 * 2.0)
    morphs = [wolf if i % 2 == 0 else lizard for i in range(n)]
    gaits = [walk if i % 2 == 0 else trot for i in range(n)]
    return morphs, gaits, np.full(n, 0.6)


def build(args: argparse.Namespace, setting: Setting) -> tuple[CrowdScene, Simulation]:
    scene = make_crowd_scene(seed=args.seed)
    xy, heading = spawn_points(scene, args.chars, seed=args.seed + 1)
    morphs, gaits, speed = crowd_of(setting.crowd, args.chars)
    lod, ik = camera_setup("LOD", xy)
    controls = Controls(speed=speed, heading=heading, step_height=0.1, ik=ik, pelvis_physics=setting.physics)
    sim = Simulation(
        scene.env,
        morphs,
        gaits,
        start_xy=xy,
        start_yaw=heading,
        controls=controls,
        phase="random",
        seed=args.seed,
        params=ControllerParams(window_cells=70, window_cell=0.07, clock=time.process_time),
        lod=lod,
        spine=SpineParams() if setting.spine else None,
    )
    return scene, sim


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--chars", type=int, default=100)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--warmup", type=int, default=15)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--profile", action="store_true", help="print the hottest functions of the spine setting"
    )
    args = parser.parse_args()

    settings = [
        Setting("spiders", "base", physics=False, spine=False),
        Setting("spiders", "physics", physics=True, spine=False),
        Setting("quadrupeds", "base", physics=False, spine=False),
        Setting("quadrupeds", "physics", physics=True, spine=False),
        Setting("quadrupeds", "spine + physics", physics=True, spine=True),
        Setting("quadrupeds", "spine", physics=False, spine=True),
    ]
    print(
        f"crowd effects benchmark: {args.chars} characters per crowd, Table 3.1 scene, LOD camera, "
        f"{args.steps} steps of 1/30 s after {args.warmup} warm-up steps"
    )
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}, one process, one thread"
    )
    runs = [build(args, s) for s in settings]
    for _ in range(args.warmup):
        for scene, sim in runs:
            scene.advance(sim.dt)
            sim.step()
    profiler = cProfile.Profile() if args.profile else None
    for _ in range(args.steps):
        for setting, (scene, sim) in zip(settings, runs, strict=True):
            scene.advance(sim.dt)
            spine_profile = profiler is not None and setting.name == "spine + physics"
            t0 = time.process_time()
            if spine_profile:
                profiler.enable()  # type: ignore[union-attr]
            stats = sim.step()
            if spine_profile:
                profiler.disable()  # type: ignore[union-attr]
            setting.step_s.append(time.process_time() - t0)
            for k in PHASES:
                setting.phase_s[k] = setting.phase_s.get(k, 0.0) + stats.seconds.get(k, 0.0)
            setting.plans += stats.n_plans
            setting.forced += stats.n_forced

    print()
    print("CPU seconds per step; ratio to the base of the same crowd; phases of the controller's step;")
    print("footstep plans and forced steps per step (the effects change where feet land, so the planner's")
    print("share moves with them)")
    header = (
        f"{'crowd':<11} {'setting':<16} {'step s':>8} {'ratio':>6} {'thesis':>10}"
        + "".join(f" {k:>8}" for k in PHASES)
        + f" {'plans':>6} {'forced':>6}"
    )
    print(header)
    print("-" * len(header))
    base: dict[str, float] = {}
    mean: dict[tuple[str, str], float] = {}
    for s in settings:
        step = float(np.mean(s.step_s))
        mean[(s.crowd, s.name)] = step
        base.setdefault(s.crowd, step)
        ratio = step / base[s.crowd]
        thesis_txt = THESIS_RATIO.get(s.name, "")
        n = len(s.step_s)
        measured = sum(s.phase_s.values())
        phases = dict(s.phase_s)
        phases["rest"] = phases.get("rest", 0.0) + max(sum(s.step_s) - measured, 0.0)
        print(
            f"{s.crowd:<11} {s.name:<16} {step:8.4f} {ratio:6.2f} {thesis_txt:>10}"
            + "".join(f" {phases.get(k, 0.0) / n:8.4f}" for k in PHASES)
            + f" {s.plans / n:6.1f} {s.forced / n:6.2f}"
        )
    if profiler is not None:
        print("\n--- profile: quadrupeds, spine + physics ---")
        pstats.Stats(profiler).sort_stats("tottime").print_stats(20)
        pstats.Stats(profiler).sort_stats("cumtime").print_stats("spine.py|locomotion|hull.py")
    q_base = mean[("quadrupeds", "base")]
    q_phys = mean[("quadrupeds", "physics")]
    q_spine = mean[("quadrupeds", "spine + physics")]
    print()
    print(
        f"RESULT crowd_effects step_s_base={q_base:.4f} step_s_physics={q_phys:.4f} "
        f"step_s_spine={q_spine:.4f}"
    )


if __name__ == "__main__":
    main()
