# SPDX-License-Identifier: GPL-3.0-or-later
"""Biped footprint planner (biped thesis, table 4.1): time per stage of the whole pipeline.

    python benchmarks/bench_biped.py [--repeat 5] [--fps 60] [--baseline REV]

Scenes: the thesis' "Jumps" (walk, bend, run, jump a gap, sharp bend, jump, stop; stretched
to about 51 footprints and 1400 frames like the thesis' run) and "Turns" (bends and a
curved platform, walking only), with the synthesised clip library. Each scene is planned
``--repeat`` times from the same seed; the table shows the median time of each stage next
to the thesis' C# numbers (Unity, i7-4790K). Stage mapping: "Trace body trajectory" is our
two playbacks (§3.4) plus the two trajectory transfers (§3.6); the thesis leaves the graph
search out of its table, so we print it on its own row.

Then three comparisons that justify choices made beyond the thesis:

* the leg swivel: the thesis' one-variable search against the closed form (time of the IK
  stage and the rotation change each leaves);
* the blend point: how far a planted foot drifts when the weights jump from walk to run
  at mid-stance, with the blend point and with the naive weighted root motion;
* the heading anchor: how much planted feet pivot during playback of the Jumps plan with
  the root turned to keep the blend point's foot heading, and with the thesis' blended
  rotation increments only;
* footprint re-spacing (the thesis' future work): how well the footprints' strides fit the
  blended clips, and how far the legs must correct the clips, with and without it.

``--baseline REV`` also plans Jumps and Turns with the planner of git revision ``REV`` (its
``procloco_addon`` extracted to a temporary folder and imported under another name, its own
clip library), alternating with ours run by run, and prints both sets of medians side by
side: a before/after in the same run on the same machine load.

Ends with ``RESULT biped total_ms=<ms> per_frame_ms=<ms> search_ms=<ms>`` for Jumps.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import io
import platform
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from procloco_addon.core.biped import quat, synth
from procloco_addon.core.biped.blending import Plan, play
from procloco_addon.core.biped.clip import ClipRole
from procloco_addon.core.biped.database import ClipDatabase
from procloco_addon.core.biped.ik import IKSettings, solve
from procloco_addon.core.biped.planner import BipedMotion, PlannerSettings, plan_biped
from procloco_addon.core.biped.respace import clip_strides
from procloco_addon.core.biped.scenarios import Scenario, corridor, curve, jumps, turns
from procloco_addon.core.biped.skeleton import RIGHT

FloatArray = NDArray[np.float64]

THESIS = {  # table 4.1, milliseconds
    "Jumps": {
        "footprints": 51,
        "frames": 1384,
        "smoothing": 1.0,
        "refinement": 11.0,
        "trace": 30.0,
        "blend_groups": 3.0,
        "ik": 159.0,
        "total": 204.0,
        "per_frame": 0.15,
    },
    "Turns": {
        "footprints": 43,
        "frames": 1314,
        "smoothing": 1.0,
        "refinement": 7.0,
        "trace": 52.0,
        "blend_groups": 3.0,
        "ik": 185.0,
        "total": 248.0,
        "per_frame": 0.19,
    },
}


def run(
    db: ClipDatabase, sc: Scenario, settings: PlannerSettings, repeat: int
) -> tuple[BipedMotion, dict[str, float]]:
    surf = sc.surface()
    runs = []
    motion = None
    for _ in range(repeat):
        motion = plan_biped(
            db, surf, sc.start_pos, sc.start_yaw, sc.goal, settings=settings, rng=np.random.default_rng(0)
        )
        runs.append(motion.timings)
    assert motion is not None
    med = {k: 1e3 * statistics.median(r[k] for r in runs) for k in runs[0]}
    med["trace"] = med["playback"] + med["body_trajectory"]
    med["total"] = sum(v for k, v in med.items() if k not in ("search", "trace"))
    med["per_frame"] = med["total"] / motion.n_frames
    return motion, med


def stage_table(results: dict[str, tuple[BipedMotion, dict[str, float]]]) -> None:
    rows = [
        ("Number of footprints", "footprints"),
        ("Number of frames", "frames"),
        ("Smoothing", "smoothing"),
        ("Refinement (x2)", "refinement"),
        ("Trace body trajectory", "trace"),
        ("  of which playback (x2)", "playback"),
        ("  of which transfer (x2)", "body_trajectory"),
        ("Blend groups", "blend_groups"),
        ("Inverse kinematics", "ik"),
        ("Total time", "total"),
        ("Average time/frame", "per_frame"),
        ("Graph search (not in 4.1)", "search"),
    ]
    names = list(results)
    head = f"{'stage':<28}" + "".join(f"{n + ' ours':>14}{n + ' C#':>12}" for n in names)
    print(head)
    print("-" * len(head))
    for label, key in rows:
        line = f"{label:<28}"
        for n in names:
            motion, med = results[n]
            if key == "footprints":
                ours = f"{len(motion.footprints)}"
            elif key == "frames":
                ours = f"{motion.n_frames}"
            elif key == "per_frame":
                ours = f"{med[key]:.3f} ms"
            else:
                ours = f"{med[key]:.1f} ms"
            ref = THESIS[n].get(key)
            if ref is None:
                theirs = "-"
            elif key in ("footprints", "frames"):
                theirs = f"{ref:.0f}"
            elif key == "smoothing":
                theirs = "< 1 ms"
            elif key == "per_frame":
                theirs = f"{ref:.2f} ms"
            else:
                theirs = f"{ref:.0f} ms"
            line += f"{ours:>14}{theirs:>12}"
        print(line)


def swivel_table(
    db: ClipDatabase, motion: BipedMotion, surf_height: Callable[[FloatArray], FloatArray], repeat: int
) -> None:
    pb = motion.playback
    body_pos = motion.ik.root_pos - motion.ik.body_offset
    body_yaw = motion.ik.root_yaw - motion.ik.body_turn
    fp = motion.footprints
    print(f"\n{'leg swivel (Jumps)':<28}{'IK stage':>12}{'mean cost':>14}{'max |diff|':>14}")
    results = {}
    for method in ("search", "analytic"):
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            res = solve(
                db.skeleton, pb, body_pos, body_yaw, fp.pos, fp.yaw, IKSettings(swivel=method), surf_height
            )
            times.append(time.perf_counter() - t0)
        results[method] = (1e3 * statistics.median(times), res.swivel_cost)
    base = results["search"][1]
    for method, (ms, cost) in results.items():
        print(f"{method:<28}{ms:>9.1f} ms{cost.mean():>14.2e}{np.abs(cost - base).max():>14.2e}")
    print("  cost: squared rotation change of thigh and shin from the animation (rad^2), per leg and frame")


def blend_point_table(db: ClipDatabase) -> None:
    idx = {i.role: i.index for i in db.infos}
    walk = idx[ClipRole.WALK_FORWARD]
    print(f"\n{'weights jump walk -> X':<28}{'blend point':>14}{'naive':>14}   (planted right foot drift)")
    for other in (ClipRole.RUN_FORWARD, ClipRole.RUN_LEFT, ClipRole.WALK_LEFT):
        s = 65
        w = np.zeros((3, s, len(db.clips)))
        w[:, :, walk] = 1.0
        after = np.linspace(0.0, 1.0, s) >= 0.12
        w[1, after, walk] = 0.0
        w[1, after, idx[other]] = 1.0
        w[2, :, walk] = 0.0
        w[2, :, idx[other]] = 1.0
        plan = Plan(np.array([walk, walk, walk]), w, np.zeros(3), 0.0)
        drift = []
        for bp in (True, False):
            pb = play(db, plan, 1.0 / 120.0, blend_point=bp)
            frames = np.flatnonzero((pb.u > 1.05) & (pb.u < 1.18))
            low = np.argmin(pb.points_local[frames, RIGHT, :, 2], axis=1)
            same = low == low[len(low) // 2]
            p = pb.points[frames, RIGHT, low][same]
            drift.append(1e3 * float(np.linalg.norm(p[:, :2] - p[0, :2], axis=1).max()))
        print(f"{other.value.lower():<28}{drift[0]:>11.2f} mm{drift[1]:>11.2f} mm")


def respace_table(db: ClipDatabase) -> None:
    """Strides that fit their clips: with and without adding/removing footprints."""
    strides = clip_strides(db)
    print(f"\n{'footprint re-spacing':<22}{'footprints':>11}{'stride misfit':>15}{'leg correction':>16}")
    for name, sc in (
        ("Jumps", jumps(1.3)),
        ("Turns", turns()),
        ("curve", curve()),
        ("corridor", corridor()),
    ):
        surf = sc.surface()
        for on in (False, True):
            m = plan_biped(
                db,
                surf,
                sc.start_pos,
                sc.start_yaw,
                sc.goal,
                rng=np.random.default_rng(0),
                settings=PlannerSettings(allow_run=sc.allow_run, respace=on),
            )
            fp = m.footprints
            fam = [db.infos[int(c)].role.family for c in m.clips]
            right = [
                int(np.flatnonzero((fp.segment == k) & (fp.side == RIGHT))[0]) for k in range(len(m.clips))
            ]
            misfit = []
            for k in range(len(m.clips) - 1):
                if fam[k] in ("walk", "run"):
                    want = np.linalg.norm(fp.pos[right[k + 1], :2] - fp.pos[right[k], :2])
                    misfit.append(abs(np.log(want / (m.weights[k, m.weights.shape[1] // 2] @ strides))))
            pb = m.playback
            pts = m.root_pos[:, None, None, :] + quat.rot2(m.root_yaw[:, None, None], pb.points_local)
            f, s = np.nonzero(m.ik.ik_point >= 0)
            err = np.linalg.norm(pts[f, s, m.ik.ik_point[f, s]] - m.ik_targets[f, s], axis=1)
            label = f"{name} {'on' if on else 'off'}"
            print(f"{label:<22}{len(fp):>11}{100 * np.mean(misfit):>13.1f} %{100 * err.mean():>13.2f} cm")
    print("  misfit: mean |log(footprint stride / blended clips' stride)| over walk/run strides")
    print("  leg correction: mean distance the legs move a planted point from where the played clips put it")


def heading_table(db: ClipDatabase, motion: BipedMotion) -> None:
    pb0 = motion.playback
    plan = Plan(motion.clips, motion.weights, pb0.root_pos[0], float(pb0.root_yaw[0]))
    print(f"\n{'planted-foot pivot in playback':<28}{'max':>10}{'mean':>10}")
    for label, anchor in (("heading anchored (ours)", True), ("blended turns (thesis)", False)):
        pb = play(db, plan, pb0.dt, anchor_heading=anchor)
        twist = []
        for s in (0, 1):
            head = pb.points[:, s, 1, :2] - pb.points[:, s, 0, :2]
            yaw = np.unwrap(np.arctan2(head[:, 1], head[:, 0]))
            for i in np.unique(pb.contact[:, s]):
                if i >= 0:
                    y = yaw[pb.contact[:, s] == i]
                    twist.append(float(y.max() - y.min()))
        tw = np.degrees(np.array(twist))
        print(f"{label:<28}{tw.max():>7.2f} deg{tw.mean():>7.2f} deg")


def load_baseline(rev: str) -> ModuleType:
    """The ``core.biped`` package of git revision ``rev``, from a temporary copy of its
    ``procloco_addon`` renamed so that both versions live in this process."""
    root = Path(__file__).resolve().parent.parent
    archive = subprocess.run(
        ["git", "-C", str(root), "archive", rev, "procloco_addon"], check=True, capture_output=True
    ).stdout
    tmp = Path(tempfile.mkdtemp(prefix="procloco-baseline-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(tmp, filter="data")
    shutil.move(str(tmp / "procloco_addon"), str(tmp / "procloco_baseline"))
    sys.path.insert(0, str(tmp))
    return importlib.import_module("procloco_baseline.core.biped")


def baseline_table(rev: str, fps: float, repeat: int) -> None:
    """Jumps and Turns planned by revision ``rev`` and by this tree, alternately."""
    base = load_baseline(rev)
    mods: dict[str, Any] = {}
    for tag, pkg in (("ours", "procloco_addon.core.biped"), ("base", base.__name__)):
        synth_m = importlib.import_module(f"{pkg}.synth")
        skel = synth_m.make_skeleton()
        db = importlib.import_module(f"{pkg}.database").ClipDatabase(
            skel, synth_m.standard_library(skel, fps=fps)
        )
        mods[tag] = (
            importlib.import_module(f"{pkg}.planner"),
            importlib.import_module(f"{pkg}.scenarios"),
            db,
        )
    stages = ("search", "smoothing", "refinement", "trace", "blend_groups", "ik", "total", "per_frame")
    print(
        f"\n{'before/after (' + rev + ')':<28}" + "".join(f"{n:>13}" for n in ("ours", "baseline", "ratio"))
    )
    for name, allow_run in (("Jumps", True), ("Turns", False)):
        times: dict[str, list[dict[str, float]]] = {"ours": [], "base": []}
        frames: dict[str, int] = {}
        expansions: dict[str, int] = {}
        for _ in range(repeat):
            for tag in ("ours", "base"):
                planner, scenarios, db = mods[tag]
                sc = scenarios.jumps(1.3) if name == "Jumps" else scenarios.turns()
                settings = planner.PlannerSettings(dt=1.0 / fps, allow_run=allow_run)
                m = planner.plan_biped(
                    db,
                    sc.surface(),
                    sc.start_pos,
                    sc.start_yaw,
                    sc.goal,
                    settings=settings,
                    rng=np.random.default_rng(0),
                )
                t = dict(m.timings)
                t["trace"] = t["playback"] + t["body_trajectory"]
                t["total"] = sum(v for k, v in m.timings.items() if k != "search")
                t["per_frame"] = t["total"] / m.n_frames
                times[tag].append(t)
                frames[tag], expansions[tag] = m.n_frames, m.expansions
        for key in stages:
            ours = 1e3 * statistics.median(t[key] for t in times["ours"])
            theirs = 1e3 * statistics.median(t[key] for t in times["base"])
            unit = "ms"
            line = f"{name + ' ' + key:<28}{ours:>10.3f} {unit}{theirs:>10.3f} {unit}{ours / theirs:>12.2f}x"
            print(line)
        print(
            f"{name + ' frames, A* expansions':<28}{frames['ours']:>7} {expansions['ours']:>5}"
            f"{frames['base']:>7} {expansions['base']:>5}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--fps", type=float, default=60.0)
    ap.add_argument("--baseline", default="", help="git revision whose planner is timed too")
    args = ap.parse_args()
    print(
        f"# biped planner benchmark — {platform.node()} {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, numpy {np.__version__}, {time.strftime('%Y-%m-%d')}"
    )
    t0 = time.perf_counter()
    skel = synth.make_skeleton()
    clips = synth.standard_library(skel, fps=args.fps)
    t1 = time.perf_counter()
    db = ClipDatabase(skel, clips)
    t2 = time.perf_counter()
    synth_ms, db_ms = 1e3 * (t1 - t0), 1e3 * (t2 - t1)
    print(
        f"clip synthesis {synth_ms:.0f} ms ({len(clips)} clips), clip database {db_ms:.0f} ms; "
        f"output {args.fps:.0f} fps; median of {args.repeat} runs\n"
    )
    settings = PlannerSettings(dt=1.0 / args.fps)
    results = {
        "Jumps": run(db, jumps(1.3), settings, args.repeat),
        "Turns": run(db, turns(), PlannerSettings(dt=1.0 / args.fps, allow_run=False), args.repeat),
    }
    stage_table(results)
    sc = jumps(1.3)
    swivel_table(db, results["Jumps"][0], sc.surface().height_at, args.repeat)
    blend_point_table(db)
    heading_table(db, results["Jumps"][0])
    respace_table(db)
    motion, med = results["Jumps"]
    goal = float(np.linalg.norm(motion.root_pos[-1, :2] - sc.goal[:2]))
    print(
        f"\nJumps: goal reached within {1e3 * goal:.1f} mm, {motion.expansions} footprints expanded by A*, "
        f"yaw at the end {quat.wrap_angle(motion.root_yaw[-1]):.2f} rad"
    )
    if args.baseline:
        baseline_table(args.baseline, args.fps, args.repeat)
    total, per_frame, search = med["total"], med["per_frame"], med["search"]
    print(f"RESULT biped total_ms={total:.1f} per_frame_ms={per_frame:.3f} search_ms={search:.1f}")


if __name__ == "__main__":
    main()
