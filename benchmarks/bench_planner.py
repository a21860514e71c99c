# SPDX-License-Identifier: GPL-3.0-or-later
"""Footprint planner throughput on the thesis's Table 3.1 scene.

    python benchmarks/bench_planner.py [--plans N] [--chars N] [--seed S] [--repeat R]
                                       [--crowd-steps N] [--baseline REV]

The scene (benchmarks/scenes.py): a 100 m heightmap with 3000 crates, 40 % moving; windows of
70 × 70 cells of 7 cm around each character. Characters are eight-legged (spider-like: feet
0.35 m to the side, 0.3 m steps, 0.6 m leg reach). For every plan one foot of one character
swings from behind its rest position to a preferred footprint ahead of it, with the seven other
feet near their rest positions.

Rows: window preparation for all characters (first step, then the median of 10 steps with the
moving crates advancing 1/30 s each), then plans per second for one foot with the LOD of
thesis §3.7 (stop at the first valid couple, no slices), a zoomed-LOD-like setting (3 couples
after the first valid one, 15 cm slices), no LOD (full best-couple search with 10 cm slices)
and every couple (exhaustive). Then the wavefront comparison the issue asks for, with the
line-of-sight shortcut off so that every couple needs a wavefront: one wavefront per slice
grown from the foot against one per (target, slice) as the thesis does, in the pruned and in
the exhaustive search.

Last, **batched, as the crowd does it**: the crowd benchmark's simulation (benchmarks/
bench_crowd.py, LOD and no-LOD camera set-ups) runs ``--crowd-steps`` steps while every plan
its controller asks for is recorded (the planner it calls is wrapped); those plans are then
replayed step by step, one foot at a time (the one-foot reference planner of the tests,
``tests/core/reference_planner.py``) and all of a step's feet in one ``plan_footsteps`` call
(the product, what the controller calls), and the answers compared (decisions exactly,
floats to 1e-12). The rows above plan one foot per ``plan_footsteps`` call.

``--baseline REV`` also times the planner of git revision ``REV`` (its ``procloco_addon``
extracted to a temporary folder and imported under another name) in the same rounds, on the
same situations and recorded crowd plans, and compares its answers: before/after ratios from
one run.

Times are CPU time of this process (single-threaded; the machine is shared, so wall time
varies with the neighbours' load), the best of ``--repeat`` rounds in which the settings take
turns. Ends with ``RESULT planner plans_per_s_lod=<n> plans_per_s_nolod=<n>`` (one foot at a
time, the situations above).
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.scenes import CrowdScene, make_crowd_scene, spawn_points
from procloco_addon.core.locomotion.footprints import Couple, FootRequest, plan_footsteps
from procloco_addon.core.world.terrain import WindowGrids, WindowParams
from tests.core.reference_planner import FlatSettings
from tests.core.reference_planner import plan_footstep as reference_plan

FloatArray = npt.NDArray[np.float64]

# Spider layout in the body frame (x forward, y left), legs L1 R1 L2 R2 ... front to back.
REST_X = np.array([0.30, 0.30, 0.10, 0.10, -0.10, -0.10, -0.30, -0.30])
REST_Y = np.array([0.35, -0.35, 0.38, -0.38, 0.38, -0.38, 0.35, -0.35])
HIP_X = np.array([0.08, 0.08, 0.03, 0.03, -0.03, -0.03, -0.08, -0.08])
HIP_Y = np.array([0.06, -0.06, 0.07, -0.07, 0.07, -0.07, 0.06, -0.06])
STEP = 0.30
FOOT_HALF = (0.025, 0.025)


@dataclass
class Row:
    name: str
    n: int
    per_s: float
    ms: float
    ok: float
    targets: float
    couples: float
    paths: float
    wavefronts: float
    sweeps: float


@dataclass
class Situation:
    char: int
    start: FloatArray
    preferred: FloatArray
    hip: FloatArray
    other_hips: FloatArray
    other_feet: FloatArray
    yaw: float


def _rot(heading: float, x: FloatArray, y: FloatArray) -> FloatArray:
    c, s = np.cos(heading), np.sin(heading)
    return np.column_stack([c * x - s * y, s * x + c * y])


def make_situations(scene: CrowdScene, centres: FloatArray, headings: FloatArray, n: int,
                    rng: np.random.Generator) -> list[Situation]:
    out = []
    env = scene.env
    for i in range(n):
        c = i % centres.shape[0]
        leg = int(rng.integers(0, 8))
        h = float(headings[c])
        centre = centres[c]
        jitter = rng.uniform(-0.05, 0.05, (8, 2))
        feet = centre + _rot(h, REST_X + jitter[:, 0], REST_Y + jitter[:, 1])
        hips = centre + _rot(h, HIP_X + 0.5 * STEP, HIP_Y)
        start_xy = centre + _rot(h, REST_X[leg:leg + 1] - 0.5 * STEP, REST_Y[leg:leg + 1])[0]
        pref = centre + _rot(h, REST_X[leg:leg + 1] + 0.5 * STEP, REST_Y[leg:leg + 1])[0]
        z = float(env.height_at(start_xy[None, :])[0])
        others = np.arange(8) != leg
        out.append(Situation(c, np.array([start_xy[0], start_xy[1], z]), pref, hips[leg], hips[others],
                             feet[others], h))
    return out


def plan_one(rq: FootRequest) -> Couple:
    """The product planner asked for one foot."""
    return plan_footsteps([rq])[0]


def run_plans(
    grids: list[WindowGrids], sits: list[Situation], params: FlatSettings,
    planner: Callable[[FootRequest], Couple] = plan_one,
) -> tuple[float, list[Couple]]:
    """CPU time of this process for one run over all situations, and its results."""
    requests = [params.request(grids[s.char], s.start, s.preferred, s.hip, s.other_hips, s.other_feet, s.yaw)
                for s in sits]
    t0 = time.process_time()
    res = [planner(rq) for rq in requests]
    return time.process_time() - t0, res


def mean(values: list[int]) -> float:
    return float(np.mean(values))


Step = list[FootRequest]


def record_crowd_plans(mode: str, steps: int, warmup: int, seed: int) -> list[Step]:
    """The plans the crowd benchmark's controller asks for, step by step: its planner is
    wrapped for ``steps`` steps after ``warmup`` ones, and the inputs of every call copied
    (the windows are kept as they are: nothing writes into them)."""
    from benchmarks import bench_crowd
    from procloco_addon.core.locomotion import planning as controller  # where the planner is called

    args = argparse.Namespace(chars=100, steps=steps, warmup=warmup, seed=seed, scale=2.0, profile=False,
                              avoid=False, spread=0.8)
    scene, sim = bench_crowd.build(args, mode)
    for _ in range(warmup):
        scene.advance(sim.dt)
        sim.step()
    recorded: list[Step] = []

    def own(v: npt.ArrayLike) -> FloatArray:
        return np.array(v, dtype=np.float64)  # a copy: the controller's arrays change

    def keep(rq: FootRequest) -> None:
        recorded[-1].append(replace(rq, foot_start=own(rq.foot_start), preferred_xy=own(rq.preferred_xy),
                                    hip_xy=own(rq.hip_xy), other_hips_xy=own(rq.other_hips_xy),
                                    other_feet_xy=own(rq.other_feet_xy)))

    # The controller calls plan_footsteps (every foot of a step, then its retries): wrap it.
    many = controller.plan_footsteps

    def record_many(requests: list[FootRequest]) -> list[Couple]:
        for rq in requests:
            keep(rq)
        return many(requests)

    controller.plan_footsteps = record_many  # type: ignore[assignment]
    try:
        for _ in range(steps):
            recorded.append([])
            scene.advance(sim.dt)
            sim.step()
    finally:
        controller.plan_footsteps = many
    return recorded


def load_baseline(rev: str) -> Callable[..., Any]:
    """The planner of git revision ``rev`` asked for one foot of a request, imported from a
    temporary copy of its ``procloco_addon`` (renamed so that both versions live in this
    process): its ``plan_footstep`` where it has one, else its ``plan_footsteps``; the request
    is given in that revision's types (one flat ``PlannerParams`` in older revisions)."""
    import io
    import tarfile

    root = Path(__file__).resolve().parent.parent
    archive = subprocess.run(["git", "-C", str(root), "archive", rev, "procloco_addon"], check=True,
                             capture_output=True).stdout
    tmp = Path(tempfile.mkdtemp(prefix="procloco-baseline-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(tmp, filter="data")
    shutil.move(str(tmp / "procloco_addon"), str(tmp / "procloco_baseline"))
    sys.path.insert(0, str(tmp))
    # (the planner moved into core/locomotion/ when the core was grouped by product)
    where = ("procloco_baseline.core.locomotion.footprints"
             if (tmp / "procloco_baseline" / "core" / "locomotion" / "footprints.py").exists()
             else "procloco_baseline.core.footprints")
    module: ModuleType = importlib.import_module(where)
    def values(*parts: Any) -> dict[str, Any]:
        return {f.name: getattr(part, f.name) for part in parts for f in fields(part)}

    split = hasattr(module, "LegGeometry")

    def convert(rq: FootRequest) -> Any:
        if split:
            return module.FootRequest(
                rq.grids, rq.foot_start, rq.preferred_xy, rq.hip_xy, rq.other_hips_xy, rq.other_feet_xy,
                module.PlannerParams(**values(rq.params)), rq.foot_yaw, rq.hip_z,
                module.LegGeometry(**values(rq.leg)), module.SearchSwitches(**values(rq.search)),
                leg_reach=rq.leg_reach, reach_sweep=rq.reach_sweep, reach_sink=rq.reach_sink)
        flat = values(rq.params, rq.leg, rq.search)
        flat.update(reach_sweep=rq.reach_sweep, reach_sink=rq.reach_sink)
        if rq.leg_reach is not None:
            flat["leg_reach"] = rq.leg_reach
        names = {f.name for f in fields(module.PlannerParams)}
        params = module.PlannerParams(**{k: v for k, v in flat.items() if k in names})
        return module.FootRequest(rq.grids, rq.foot_start, rq.preferred_xy, rq.hip_xy, rq.other_hips_xy,
                                  rq.other_feet_xy, params, rq.foot_yaw, rq.hip_z)

    if hasattr(module, "plan_footstep"):  # revisions with a one-foot planner in the product
        def one(rq: FootRequest) -> Any:
            r = convert(rq)
            return module.plan_footstep(r.grids, r.foot_start, r.preferred_xy, r.hip_xy, r.other_hips_xy,
                                        r.other_feet_xy, r.params, r.foot_yaw, r.hip_z)
        return one
    return lambda rq: module.plan_footsteps([convert(rq)])[0]


def same_couple(a: Couple, b: Couple) -> bool:
    """The same answer: the same decisions (success, target, counts) exactly, the footprint,
    scores and trajectory to 1e-12 (two code paths may round differently in the last bits;
    see tests/core/cross_path.py)."""
    exact = ("ok", "message", "n_couples", "n_paths", "n_targets", "n_wavefronts", "wavefront_iterations",
             "first_valid_couple", "target_index")
    if any(getattr(a, f) != getattr(b, f) for f in exact):
        return False
    if (a.slice_level is None) != (b.slice_level is None):
        return False

    def close(x: object, y: object) -> bool:
        xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        return bool(np.allclose(xa, ya, rtol=1e-12, atol=1e-12))

    if not all(close(getattr(a, f), getattr(b, f)) for f in ("score", "target_score", "path_score")):
        return False
    if not close(a.footprint, b.footprint):
        return False
    if a.slice_level is not None and not close(a.slice_level, b.slice_level):
        return False
    if a.trajectory is None or b.trajectory is None:
        return a.trajectory is None and b.trajectory is None
    return all(close(getattr(a.trajectory, f), getattr(b.trajectory, f))
               for f in ("points", "waypoints", "waypoints_2d", "arc", "arc_2d"))


def replay(steps: list[Step], one: Callable[[FootRequest], Couple] | None) -> tuple[float, list[Couple]]:
    """CPU time to plan every recorded step: one foot at a time with ``one``, or all of a
    step's feet in one :func:`plan_footsteps` call (``one`` None)."""
    t0 = time.process_time()
    out: list[Couple] = []
    for reqs in steps:
        if one is None:
            out += plan_footsteps(reqs)
        else:
            out += [one(r) for r in reqs]
    return time.process_time() - t0, out


def crowd_section(args: argparse.Namespace, baseline: Callable[..., Couple] | None) -> None:
    """The "batched, as the crowd does it" table."""
    print()
    print(f"batched, as the crowd does it: the plans of {args.crowd_steps} crowd steps (bench_crowd.py scene "
          f"and camera set-ups, after 15 warm-up steps), replayed")
    print(f"{'camera':8s} {'plans/step':>10s} {'per foot':>12s} {'batched':>12s} {'ratio':>6s} {'same':>7s}"
          + (f" {'baseline':>12s} {'vs per foot':>11s} {'vs batched':>10s} {'same':>7s}" if baseline else ""))
    for mode in ("LOD", "No LOD"):
        steps = record_crowd_plans(mode, args.crowd_steps, 15, args.seed)
        n_steps = len(steps)
        n_plans = sum(len(r) for r in steps)
        runners: list[tuple[str, Callable[..., Couple] | None]] = [("per foot", reference_plan),
                                                                    ("batched", None)]
        if baseline is not None:
            runners.append(("baseline", baseline))
        best = dict.fromkeys((name for name, _ in runners), np.inf)
        answers: dict[str, list[Couple]] = {}
        for _ in range(args.repeat):
            for name, one in runners:
                dt, answers[name] = replay(steps, one)
                best[name] = min(best[name], dt)
        ms = {k: 1e3 * v / n_steps for k, v in best.items()}
        pairs = zip(answers["per foot"], answers["batched"], strict=True)
        same = np.mean([same_couple(a, b) for a, b in pairs])
        line = (f"{mode:8s} {n_plans / n_steps:10.1f} {ms['per foot']:9.2f} ms {ms['batched']:9.2f} ms "
                f"{ms['per foot'] / ms['batched']:5.2f}x {same:7.1%}")
        if baseline is not None:
            same_b = np.mean([same_couple(a, b) for a, b in zip(answers["baseline"], answers["per foot"],
                                                                 strict=True)])
            line += (f" {ms['baseline']:9.2f} ms {ms['baseline'] / ms['per foot']:10.2f}x "
                     f"{ms['baseline'] / ms['batched']:9.2f}x {same_b:7.1%}")
        print(line)
    print("(times per crowd step; per foot: the one-foot reference planner of the tests "
          "(tests/core/reference_planner.py); 'same': answers equal to its ones (to 1e-12)"
          + (f"; baseline: revision {args.baseline}, one foot at a time" if baseline else "") + ")")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", type=int, default=400, help="plans per setting")
    ap.add_argument("--chars", type=int, default=100, help="characters (windows per step)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3, help="timing runs per setting (best is kept)")
    ap.add_argument("--crowd-steps", type=int, default=20, help="crowd steps recorded and replayed (0: skip)")
    ap.add_argument("--baseline", default="", help="git revision whose planner is replayed too")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    scene = make_crowd_scene(seed=args.seed)
    t_scene = time.perf_counter() - t0
    centres, headings = spawn_points(scene, args.chars, seed=args.seed + 1)
    wp = WindowParams(n_cells=70, cell=0.07, foot_half_extents=FOOT_HALF)

    # Window preparation: first step fills the static tile cache, later steps reuse it.
    t0 = time.process_time()
    grids = scene.env.windows(centres, wp)
    t_first = time.process_time() - t0
    steps = 10
    t_steps = []
    for _ in range(steps):
        scene.advance(1.0 / 30.0)
        t0 = time.process_time()
        grids = scene.env.windows(centres, wp)
        t_steps.append(time.process_time() - t0)
    t_window = float(np.median(t_steps))

    rng = np.random.default_rng(args.seed + 2)
    sits = make_situations(scene, centres, headings, args.plans, rng)
    full = FlatSettings(step_height=0.1, leg_reach=0.6, candidate_radius=0.21, fixed_distance=0.3,
                         foot_half_extents=FOOT_HALF, max_couples_after_first=None, slice_size=0.1)
    raw = replace(full, los_shortcut=False)
    settings = [
        ("LOD (first valid couple, no slices)", replace(full, max_couples_after_first=0, slice_size=None)),
        ("zoomed LOD (3 after first, 15 cm slices)",
         replace(full, max_couples_after_first=3, slice_size=0.15)),
        ("no LOD (best couple, 10 cm slices)", full),
        ("every couple (exhaustive, 10 cm slices)", replace(full, exhaustive=True)),
        ("no LOD, no line-of-sight shortcut", raw),
        ("  same, one wavefront per target (thesis)", replace(raw, shared_wavefront=False)),
        ("exhaustive, no line-of-sight shortcut", replace(raw, exhaustive=True)),
        ("  same, one wavefront per target (thesis)", replace(raw, exhaustive=True, shared_wavefront=False)),
    ]
    # The machine is shared: settings take turns in every round and each keeps its best time.
    sizes = [len(sits) if not prm.exhaustive else max(40, len(sits) // 4) for _, prm in settings]
    best = [np.inf] * len(settings)
    best_base = [np.inf] * len(settings)
    baseline = load_baseline(args.baseline) if args.baseline else None
    results: list[list[Couple]] = [[] for _ in settings]
    same_as_base = [1.0] * len(settings)
    for _ in range(args.repeat):
        for k, (_, prm) in enumerate(settings):
            dt, results[k] = run_plans(grids, sits[: sizes[k]], prm)
            best[k] = min(best[k], dt)
            if baseline is not None:
                dt, base = run_plans(grids, sits[: sizes[k]], prm, baseline)
                best_base[k] = min(best_base[k], dt)
                pairs = zip(results[k], base, strict=True)
                same_as_base[k] = float(np.mean([same_couple(a, b) for a, b in pairs]))
    rows: list[Row] = []
    for (name, _), n, dt, res in zip(settings, sizes, best, results, strict=True):
        ok = np.array([r.ok for r in res])
        rows.append(Row(name, n, n / dt, 1e3 * dt / n, float(ok.mean()), mean([r.n_targets for r in res]),
                        mean([r.n_couples for r in res]), mean([r.n_paths for r in res]),
                        mean([r.n_wavefronts for r in res]), mean([r.wavefront_iterations for r in res])))

    def same_choice(a: list[Couple], b: list[Couple]) -> float:
        return float(np.mean([x.ok == y.ok and (not x.ok or np.allclose(x.footprint, y.footprint))
                              for x, y in zip(a, b, strict=False)]))

    print(f"# bench_planner  {platform.platform()}  python {platform.python_version()}  "
          f"numpy {np.__version__}  cpus {os.cpu_count()}  {time.strftime('%Y-%m-%d')}")
    print(f"scene: {scene.size:.0f} m heightmap, {len(scene.env.boxes)} crates ({scene.moving.size} moving), "
          f"built in {t_scene:.2f} s; {args.chars} characters, windows {wp.n_cells}x{wp.n_cells} "
          f"@ {wp.cell} m")
    print()
    print(f"{'window preparation':46s} {'first step':>12s} {'later steps':>12s} {'per window':>12s}")
    print(f"{'(all characters, one step)':46s} {t_first * 1e3:10.1f}ms {t_window * 1e3:10.1f}ms "
          f"{t_window / args.chars * 1e3:10.3f}ms")
    print()
    print(f"{'setting':46s} {'plans':>6s} {'plans/s':>9s} {'ms/plan':>8s} {'ok':>6s} {'targets':>8s} "
          f"{'couples':>8s} {'3D paths':>9s} {'wavefr.':>8s} {'sweeps':>7s}"
          + (f" {'baseline/s':>10s} {'speed-up':>8s} {'same':>6s}" if baseline is not None else ""))
    for k, r in enumerate(rows):
        print(f"{r.name:46s} {r.n:6d} {r.per_s:9.1f} {r.ms:8.2f} {r.ok:6.1%} {r.targets:8.1f} "
              f"{r.couples:8.2f} {r.paths:9.2f} {r.wavefronts:8.2f} {r.sweeps:7.1f}"
              + (f" {r.n / best_base[k]:10.1f} {best_base[k] / best[k]:7.2f}x {same_as_base[k]:6.1%}"
                 if baseline is not None else ""))
    if baseline is not None:
        print(f"(baseline: the planner of revision {args.baseline}, timed in the same rounds; 'same': its "
              f"answers equal to 1e-12)")
    print()
    for k, label in ((4, "best-couple search"), (6, "exhaustive search")):
        ratio = rows[k].per_s / rows[k + 1].per_s
        print(f"{label}: one wavefront per slice from the foot gives {ratio:.2f}x the plans/s of "
              f"one wavefront per (target, slice) "
              f"({rows[k + 1].sweeps / max(rows[k].sweeps, 1e-9):.1f}x fewer sweeps); "
              f"same footprint in {same_choice(results[k], results[k + 1]):.1%} of plans")
    print(f"pruned best-couple search picks the exhaustive search's footprint in "
          f"{same_choice(results[2], results[3]):.1%} of plans; the line-of-sight shortcut changes "
          f"{1.0 - same_choice(results[2], results[4]):.1%} of choices")
    if args.crowd_steps > 0:
        crowd_section(args, baseline)
    print(f"RESULT planner plans_per_s_lod={rows[0].per_s:.1f} plans_per_s_nolod={rows[2].per_s:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
