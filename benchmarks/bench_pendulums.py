# SPDX-License-Identifier: GPL-3.0-or-later
"""3D pendulums (thesis §5.5.3): cost of secondary motion for a crowd, and a Blender bake.

    python benchmarks/bench_pendulums.py [--chars 110] [--repeat 300] [--no-blender]
                                         [--baseline REV] [--current REV]

Core section (numpy only): the thesis's figure 5.14 setting, 110 characters with 3 trees of
pendulums each (a 6-bone tail, a head with two 2-bone antennae, a 3- or 4-bone body chain;
1550 pendulums for 110 characters), every body walking with a bob and a yaw sway so that
every tree is perturbed. Rows: one internal step of all pendulums (target update, both
passes, all spring steps); the same with son pursuit active (impulses on 10 % of the tips);
the same with the bodies' frames given (``anchor_frame``: the sway turns the tails too); and
the cost per 30 fps animation frame of a whole ``simulate`` run (sub-steps at the internal
rate, interpolation and output poses included), without and with the bodies' frames. CPU
time of the process and wall time, best of three rounds (the machine is shared). The thesis
reports ≈3 ms per step in C++.

``--baseline REV`` also times ``core/secondary/pendulum.py`` of git revision ``REV`` (loaded from a
temporary copy) in the same rounds, on the same inputs, and reports the speed-up and the
largest difference between the two ``simulate`` runs' errors (rad). ``--current REV`` times
that revision's module in place of the working tree's (to compare two commits).

Blender section (needs the ``bpy`` module, skipped with ``--no-blender``): Bake Secondary
Motion on the Rigify wolf metarig's tail over 250 frames, the body animated by keyframes,
timed end to end (evaluating the rig, simulating, writing the new Action).

Ends with ``RESULT pendulums step_ms=<ms> n=<count> ...``.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import importlib.util
import inspect
import io
import os
import platform
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from procloco_addon.core.secondary import pendulum as pend

FloatArray = npt.NDArray[np.float64]


def crowd_forest(n_chars: int) -> tuple[pend.PendulumForest, FloatArray, list[int]]:
    """Three trees per character; returns the forest, per-pendulum rest offsets from the
    character's origin (n, 3) and the character index of each pendulum."""
    parent: list[int] = []
    length: list[float] = []
    offset: list[list[float]] = []
    owner: list[int] = []

    def chain(
        start_parent: int, n: int, bone: float, origin: list[float], direction: list[float], c: int
    ) -> int:
        last = start_parent
        pos = np.array(origin, dtype=float)
        for _ in range(n):
            parent.append(last)
            length.append(bone)
            offset.append(pos.tolist())
            owner.append(c)
            last = len(parent) - 1
            pos = pos + bone * np.asarray(direction)
        return last

    for c in range(n_chars):
        chain(-1, 6, 0.08, [-0.3, 0.0, 0.4], [-0.8, 0.0, -0.6], c)  # tail
        head = chain(-1, 1, 0.05, [0.3, 0.0, 0.45], [1.0, 0.0, 0.0], c)  # head + antennae
        chain(head, 2, 0.06, [0.35, 0.02, 0.45], [0.6, 0.4, 0.7], c)
        chain(head, 2, 0.06, [0.35, -0.02, 0.45], [0.6, -0.4, 0.7], c)
        chain(-1, 4 if c < 10 else 3, 0.1, [0.2, 0.0, 0.4], [-1.0, 0.0, 0.0], c)  # body
    forest = pend.PendulumForest(parent, length, 0.6, 0.35)
    return forest, np.asarray(offset), owner


def crowd_pose(
    t: float, rest: FloatArray, owner: npt.NDArray[np.int64], frames0: FloatArray, phase: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Animated heads (n, 3), frames (n, 3, 3) and body frames (n, 3, 3) of every pendulum at
    time ``t``: bodies walk, bob and sway (a yaw about their origin)."""
    ph = phase[owner]
    x = 1.2 * t + 0.4 * ph
    bob = 0.02 * np.sin(2 * np.pi * 2.0 * t + ph)
    sway = 0.15 * np.sin(2 * np.pi * 0.5 * t + ph)
    c, s = np.cos(sway), np.sin(sway)
    px, py = rest[:, 0], rest[:, 1]
    heads = np.stack([x + c * px - s * py, 3.0 * owner + s * px + c * py, rest[:, 2] + bob], axis=-1)
    rot = np.zeros((rest.shape[0], 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s, s, c, 1.0
    return heads, rot @ frames0, rot


def load_revision(rev: str, name: str = "pendulum_baseline") -> ModuleType:
    """The pendulum module of git revision ``rev`` (``core/secondary/pendulum.py``, or
    ``core/pendulum.py`` before it moved), imported from a temporary copy of that revision's
    ``procloco_addon`` renamed ``name`` (the module imports its neighbours, numpy only)."""
    root = Path(__file__).resolve().parent.parent
    archive = subprocess.run(["git", "-C", str(root), "archive", rev, "procloco_addon"],
                             capture_output=True)
    if archive.returncode != 0:
        raise SystemExit(f"--baseline/--current {rev}: not a revision of the repository at {root}")
    tmp = Path(tempfile.mkdtemp(prefix="procloco-baseline-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
        tar.extractall(tmp, filter="data")
    shutil.move(str(tmp / "procloco_addon"), str(tmp / name))
    sys.path.insert(0, str(tmp))
    moved = (tmp / name / "core" / "secondary" / "pendulum.py").exists()
    return importlib.import_module(f"{name}.core.secondary.pendulum" if moved else f"{name}.core.pendulum")


def _takes_anchors(module: ModuleType) -> bool:
    return "anchor_frame" in inspect.signature(module.simulate).parameters


def core_section(
    n_chars: int, repeat: int, baseline: ModuleType | None, rev: str, current: ModuleType = pend
) -> dict[str, float]:
    forest, rest, owner_list = crowd_forest(n_chars)
    owner = np.asarray(owner_list)
    rng = np.random.default_rng(0)
    phase = rng.uniform(0.0, 2 * np.pi, n_chars)
    # Rest frames: bone y along each chain; built from consecutive rest offsets.
    dirs = np.zeros_like(rest)
    for i, p in enumerate(forest.parent):
        if p >= 0:
            dirs[p] = rest[i] - rest[p]
    dirs[np.linalg.norm(dirs, axis=1) == 0] = [-1.0, 0.0, -0.2]
    frames0 = np.zeros((forest.n, 3, 3))
    frames0[:, :, 1] = dirs
    frames0[:, :, 0] = np.cross(dirs, [0.0, 0.0, 1.0]) + np.array([1e-9, 0.0, 0.0])
    frames0 = pend.orthonormalize_frames(frames0)

    modules: dict[str, Any] = {"current": current}
    if baseline is not None:
        modules["baseline"] = baseline
    forests = {k: m.PendulumForest(forest.parent, forest.length, 0.6, 0.35) for k, m in modules.items()}
    sims = {k: m.PendulumSimulator(forests[k]) for k, m in modules.items()}
    h = sims["current"].h
    head, frame, body = crowd_pose(0.0, rest, owner, frames0, phase)
    velocity = (crowd_pose(1e-4, rest, owner, frames0, phase)[0] - head) / 1e-4
    spin = np.tile([0.0, 0.0, 1.0], (forest.n, 1)) * (
        0.15 * 2 * np.pi * 0.5 * np.cos(phase[owner]))[:, None]  # the sway's yaw rate at t = 0
    poses = [crowd_pose(k * h, rest, owner, frames0, phase) for k in range(1, repeat + 1)]
    impulse = np.zeros((forest.n, 3))
    hit = rng.choice(forest.n, forest.n // 10, replace=False)
    impulse[hit] = rng.normal(0.0, 0.01, (hit.size, 3))

    def plain(k: str) -> None:
        sims[k].reset(head, frame, velocity)  # every round replays the same walk from its start
        for hd, fr, _body in poses:
            sims[k].step(hd, fr)

    def kicked(k: str) -> None:
        sims[k].reset(head, frame, velocity)
        for hd, fr, _body in poses:
            sims[k].step(hd, fr, impulse)

    def turning(k: str) -> None:
        sims[k].reset(head, frame, velocity, anchor_frame=body, anchor_angular_velocity=spin)
        for hd, fr, bd in poses:
            sims[k].step(hd, fr, anchor_frame=bd)

    fps, seconds = 30.0, 4.0
    times = np.arange(int(seconds * fps) + 1) / fps
    anim = [crowd_pose(t, rest, owner, frames0, phase) for t in times]
    heads = np.stack([a[0] for a in anim])
    frames = np.stack([a[1] for a in anim])
    bodies = np.stack([a[2] for a in anim])
    results: dict[str, Any] = {}

    def whole(k: str) -> None:
        results[k] = modules[k].simulate(forests[k], times, heads, frames)

    def whole_turning(k: str) -> None:
        results[k + " turning"] = modules[k].simulate(forests[k], times, heads, frames, anchor_frame=bodies)

    rows = [
        ("one internal step, all pendulums (father pursuit, reactions, springs)", plain, repeat),
        ("one internal step with son pursuit on 10 % of the tips", kicked, repeat),
        ("one internal step, the bodies' turning felt (anchor frames)", turning, repeat),
        (f"per 30 fps frame, whole `simulate` ({1.0 / (h * fps):.0f} sub-steps + I/O)", whole, times.size),
        ("per 30 fps frame, whole `simulate` with anchor frames", whole_turning, times.size),
    ]
    anchored = {plain: False, kicked: False, turning: True, whole: False, whole_turning: True}
    # (CPU ms, wall ms) per item, best of three rounds; the versions alternate within a round.
    best: dict[tuple[int, str], tuple[float, float]] = {}
    for _ in range(3):
        for r, (_label, run, count) in enumerate(rows):
            for k, m in modules.items():
                if anchored[run] and not _takes_anchors(m):
                    continue
                c0, w0 = time.process_time(), time.perf_counter()
                run(k)
                cpu = (time.process_time() - c0) / count * 1e3
                wall = (time.perf_counter() - w0) / count * 1e3
                old = best.get((r, k), (np.inf, np.inf))
                best[(r, k)] = (min(old[0], cpu), min(old[1], wall))
    swing = float(np.degrees(np.abs(results["current"].theta).max()))
    swing_turning = float(np.degrees(np.abs(results["current turning"].theta).max()))

    print(f"## Core: {n_chars} characters × 3 trees = {forest.n} pendulums, "
          f"{forest.n_trees} trees, depth {len(forest.levels)}")
    print(f"internal rate {1.0 / h:.0f} Hz (h = {h * 1e3:.2f} ms); largest swing {swing:.1f}°, "
          f"{swing_turning:.1f}° with the bodies' turning felt")
    print()
    extra = " baseline CPU ms | speed-up |" if baseline is not None else ""
    print(f"| measure | CPU ms | wall ms |{extra}")
    print("|---|---:|---:|" + ("---:|---:|" if baseline is not None else ""))
    for r, (label, _run, _count) in enumerate(rows):
        cpu, wall = best[(r, "current")]
        line = f"| {label} | {cpu:.3f} | {wall:.3f} |"
        if baseline is not None:
            if (r, "baseline") in best:
                base = best[(r, "baseline")][0]
                line += f" {base:.3f} | {base / cpu:.2f}× |"
            else:
                line += " — | — |"
        print(line)
    thesis = "| thesis §5.5.3 (C++, 2012 hardware), per step | | ≈3 |"
    print(thesis + (" | |" if baseline is not None else ""))
    print()
    out = {"step_ms": best[(0, "current")][0], "n": forest.n, "pursuit_ms": best[(1, "current")][0],
           "turning_step_ms": best[(2, "current")][0], "frame_ms": best[(3, "current")][0]}
    if baseline is not None:
        diff = float(np.abs(results["current"].theta - results["baseline"].theta).max())
        print(f"Baseline: `core/secondary/pendulum.py` of revision {rev}, timed in the same rounds on the "
              "same inputs. "
              f"Largest difference of the errors θ over the 4 s `simulate` run: {diff:.2e} rad "
              f"(θ reaches {np.radians(swing):.3f} rad).")
        print()
        out["baseline_step_ms"] = best[(0, "baseline")][0]
        out["baseline_frame_ms"] = best[(3, "baseline")][0]
        out["max_dtheta"] = diff
    return out


def blender_section(frames: int) -> dict[str, float]:
    """Bake the Rigify wolf's tail over ``frames`` frames; returns timings (s)."""
    home = Path(tempfile.mkdtemp(prefix="procloco-bench-"))
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(home / "resources"))
    os.environ.setdefault("XDG_CACHE_HOME", str(home / "cache"))
    os.environ.setdefault("XDG_CONFIG_HOME", str(home / "config"))
    import addon_utils
    import bpy

    import procloco_addon
    from procloco_addon.blender.secondary import ops as secondary_ops

    procloco_addon.register()
    try:
        bpy.ops.wm.read_homefile(use_empty=True)
        addon_utils.enable("rigify", default_set=True)
        bpy.ops.object.armature_wolf_metarig_add()
        rig = bpy.context.active_object
        scene = bpy.context.scene
        scene.frame_start, scene.frame_end = 1, frames
        scene.render.fps = 24
        _animate_body(rig, frames)
        t0 = time.perf_counter()
        found = secondary_ops.suggest_chains(rig)
        suggest_s = time.perf_counter() - t0
        for chain in rig.procloco_secondary.chains:  # the tail only
            chain.enabled = chain.root == "spine.003"
        t0 = time.perf_counter()
        result = bpy.ops.procloco.bake_secondary_motion()
        bake_s = time.perf_counter() - t0
        assert result == {"FINISHED"}, result
        chains = ", ".join(f"{c.root} > {c.tip}" for c in rig.procloco_secondary.chains if c.enabled)
        print(f"## Blender {bpy.app.version_string}: Rigify wolf metarig, {frames} frames at 24 fps")
        print(f"chains: {chains} (suggested: {found})")
        print()
        print("| measure | s |")
        print("|---|---:|")
        print(f"| suggest chains | {suggest_s:.3f} |")
        print(f"| Bake Secondary Motion, tail, {frames} frames (evaluate, simulate, write) | {bake_s:.3f} |")
        print()
        return {"wolf_tail_bake_s": bake_s}
    finally:
        procloco_addon.unregister()


def _animate_body(rig: Any, frames: int) -> None:
    """Key the wolf object: trots forward (-Y) with a bob and a sway, then stops at 5 s."""
    for f in range(1, frames + 1, 3):
        t = (f - 1) / 24.0
        moving = 1.0 if t < 5.0 else 0.0
        y = -0.9 * min(t, 5.0) - 0.45 * (1.0 - np.exp(-2.0 * max(t - 5.0, 0.0)))
        rig.location = (0.0, y, 0.03 * np.sin(2 * np.pi * 2.0 * t) * moving)
        rig.rotation_euler = (0.0, 0.0, 0.1 * np.sin(2 * np.pi * 0.7 * t) * moving)
        rig.keyframe_insert("location", frame=f)
        rig.keyframe_insert("rotation_euler", frame=f)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--chars", type=int, default=110)
    parser.add_argument("--repeat", type=int, default=300)
    parser.add_argument("--frames", type=int, default=250)
    parser.add_argument("--no-blender", action="store_true")
    parser.add_argument("--baseline", default="", help="git revision whose pendulum module is timed too")
    parser.add_argument("--current", default="", help="time this git revision's pendulum module instead "
                        "of the working tree's (e.g. to compare two commits)")
    args = parser.parse_args()
    print(f"# bench_pendulums — {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, numpy {np.__version__}, {time.strftime('%Y-%m-%d')}")
    print()
    baseline = load_revision(args.baseline) if args.baseline else None
    current = load_revision(args.current, "pendulum_current") if args.current else pend
    if args.current:
        print(f"(core section: `core/secondary/pendulum.py` of revision {args.current})")
        print()
    core = core_section(args.chars, args.repeat, baseline, args.baseline, current)
    extra = ""
    if baseline is not None:
        extra += (f" baseline_step_ms={core['baseline_step_ms']:.3f} baseline_frame_ms_30fps="
                  f"{core['baseline_frame_ms']:.3f} max_dtheta={core['max_dtheta']:.2e}")
    if not args.no_blender:
        try:
            import bpy  # noqa: F401
        except ImportError:
            print("## Blender: skipped (no bpy module)")
        else:
            blender = blender_section(args.frames)
            extra += f" wolf_tail_bake_s={blender['wolf_tail_bake_s']:.3f}"
    print(f"RESULT pendulums step_ms={core['step_ms']:.3f} n={core['n']} "
          f"frame_ms_30fps={core['frame_ms']:.3f} turning_step_ms={core['turning_step_ms']:.3f}{extra}")


if __name__ == "__main__":
    main()
