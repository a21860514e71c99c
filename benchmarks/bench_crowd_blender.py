# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate Locomotion on many selected rigs at once, in Blender (the ``bpy`` module).

    python benchmarks/bench_crowd_blender.py [--counts 1,10,100] [--frames 120] [--baseline REV]

Scene: ``--counts`` Rigify wolf metarigs (capsule skins, ``tools.examples.creatures``) in a
grid 3 m apart, all selected, on a flat, gently bumpy heightmap mesh large enough for the
whole herd; 120 frames at 24 fps, 1 m/s, default settings otherwise. For each count the
scene is built afresh, then ``procloco.generate_locomotion`` runs once (straight through,
as in background mode) and is timed as a whole, and stage by stage: the functions the
operator calls are wrapped with timers for that run (``read``: the rigs and their settings;
``terrain``: the scene's meshes; ``simulate``; ``write``: solving poses and keying the
Actions; ``quality``: measuring the figures on the posed rigs; ``other``: the rest).

Prints seconds, seconds per rig and the ratio to one rig. Ends with
``RESULT crowd_blender one_s=<s> hundred_s=<s> ratio=<r>`` (the largest count stands for
"hundred" when ``--counts`` does not reach 100).

``--baseline REV`` runs every count with revision ``REV``'s code too, in alternating fresh
processes (this script measuring both), and prints the stage times of both and their ratios;
the RESULT line is this code's.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Generator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
# The source tree to import the add-on from: this checkout, or ``--code-root DIR`` (the
# baseline's tree when ``--baseline`` runs this script on another revision's code).
CODE = Path(sys.argv[sys.argv.index("--code-root") + 1]).resolve() if "--code-root" in sys.argv else ROOT
sys.path.insert(0, str(CODE))
_HOME = Path(tempfile.mkdtemp(prefix="procloco-bench-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_HOME / "config"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import procloco_addon  # noqa: E402
from tools.examples import creatures  # noqa: E402

SPACING = 3.0  # m between neighbouring wolves


def build_scene(count: int, n_frames: int) -> list[bpy.types.Object]:
    """``count`` wolves on bumpy ground, all selected (the first active)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, n_frames
    scene.render.fps = 24
    side = int(np.ceil(np.sqrt(count)))
    half = 0.5 * side * SPACING + 1.0 + n_frames / 24.0 * 1.2  # the herd plus a walk either way
    n = int(np.clip(2 * half / 0.12, 32, 400))
    xs = np.linspace(-half, half, n)
    ys = xs
    gx, gy = np.meshgrid(xs, ys)
    gz = 0.02 * np.sin(gx / 0.7) * np.cos(gy / 0.9)
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j)
             for i in range(n - 1) for j in range(n - 1)]
    mesh = bpy.data.meshes.new("Ground")
    mesh.from_pydata(np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()]).tolist(), [], faces)
    scene.collection.objects.link(bpy.data.objects.new("Ground", mesh))
    wolves = []
    for k in range(count):
        x = (k % side - 0.5 * (side - 1)) * SPACING
        y = (k // side - 0.5 * (side - 1)) * SPACING
        wolf = creatures.build_wolf(scene, name=f"Wolf{k:03d}", location=(x, y, 0.0))
        wolf.procloco.speed = 1.0
        wolves.append(wolf)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for wolf in wolves:
        wolf.select_set(True)
    bpy.context.view_layer.objects.active = wolves[0]
    # The scene evaluated once, as the viewport has it before the click (else the operator's
    # first view layer update evaluates every new rig and skin, a cost of building the scene)
    bpy.context.view_layer.update()
    return wolves


#: The stages of the breakdown: (stage, module, function) wrapped with a timer for the
#: operator's run (those a revision does not have are skipped; a stage's function called
#: inside another of the same stage is counted once). ``write`` is timed around
#: ``write_all_steps``, which also measures: its ``quality`` share is taken out of it.
STAGES = (
    ("read", "procloco_addon.blender.locomotion.generate", "read"),
    ("read", "procloco_addon.blender.locomotion.crowd", "read_all"),
    ("read", "procloco_addon.blender.locomotion.crowd", "read_all_steps"),
    ("terrain", "procloco_addon.blender.locomotion.generate", "read_terrain"),
    ("terrain", "procloco_addon.blender.locomotion.crowd", "read_terrain"),
    ("simulate", "procloco_addon.blender.locomotion.generate", "simulate"),
    ("simulate", "procloco_addon.blender.locomotion.crowd", "simulate"),
    ("write", "procloco_addon.blender.locomotion.generate", "write_all_steps"),
    ("quality", "procloco_addon.blender.quality.measure", "measure_steps"),
    ("quality", "procloco_addon.blender.quality.measure", "measure_all_steps"),
)
COLUMNS = ("read", "terrain", "simulate", "write", "quality", "other")


def _timed(fn: Callable[..., Any], stage: str, spent: dict[str, float],
           depth: dict[str, int]) -> Callable[..., Any]:
    """``fn`` adding its wall and CPU time to ``spent[stage]`` and ``spent[stage + "_cpu"]``
    (unless it runs inside another timed function of its stage: ``depth``); a generator's
    time is its steps' (the time its caller spends between them is not counted)."""

    def timed_call(call: Callable[[], Any]) -> Any:
        t0, c0 = time.perf_counter(), time.process_time()
        depth[stage] = depth.get(stage, 0) + 1
        try:
            return call()
        finally:
            depth[stage] -= 1
            if not depth[stage]:
                spent[stage] += time.perf_counter() - t0
                spent[stage + "_cpu"] += time.process_time() - c0

    def steps(gen: Generator[Any, Any, Any]) -> Generator[Any, Any, Any]:
        while True:
            try:
                value = timed_call(lambda: next(gen))
            except StopIteration as done:
                return done.value
            yield value

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        out = timed_call(lambda: fn(*args, **kwargs))
        return steps(out) if isinstance(out, Generator) else out

    return wrapper


def run(count: int, n_frames: int) -> dict[str, float]:
    """Generate Locomotion on ``count`` wolves: total and per-stage seconds."""
    import importlib

    wolves = build_scene(count, n_frames)
    spent = dict.fromkeys([*COLUMNS, *(c + "_cpu" for c in COLUMNS)], 0.0)
    patched = []
    depth: dict[str, int] = {}
    for stage, module_name, name in STAGES:
        try:
            module = importlib.import_module(module_name)
        except ImportError:
            continue
        fn = getattr(module, name, None)
        if fn is not None:
            patched.append((module, name, fn))
            setattr(module, name, _timed(fn, stage, spent, depth))
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
        total, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        for module, name, fn in patched:
            setattr(module, name, fn)
    assert all(w.animation_data is not None and w.animation_data.action is not None for w in wolves)
    for cpu_ in ("", "_cpu"):
        spent["write" + cpu_] -= spent["quality" + cpu_]  # (measured inside write_all_steps)
        staged = sum(spent[c + cpu_] for c in COLUMNS if c != "other")
        spent["other" + cpu_] = (cpu if cpu_ else total) - staged
    return {"total": total, "cpu": cpu, **spent}


def table(rows: dict[int, dict[str, float]]) -> None:
    """Wall seconds, then CPU seconds (steadier on a shared machine), stage by stage."""
    first = min(rows)
    for key, what in (("total", "wall"), ("cpu", "CPU")):
        cpu_ = "_cpu" if key == "cpu" else ""
        one = rows[first][key] / first
        print(f"{'rigs':>6} {what + ' s':>9} {'per rig s':>10} {'x one':>7} | "
              + " ".join(f"{c + ' s':>10}" for c in COLUMNS))
        for count, r in rows.items():
            print(f"{count:>6} {r[key]:>9.2f} {r[key] / count:>10.3f} {r[key] / one:>7.1f} | "
                  + " ".join(f"{r[c + cpu_]:>10.2f}" for c in COLUMNS))


def _in_process(code_root: Path, count: int, n_frames: int) -> dict[str, float]:
    """:func:`run` in a fresh process importing the add-on from ``code_root``."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--code-root", str(code_root), "--one-run",
           "--counts", str(count), "--frames", str(n_frames)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("RUN ")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"run of {code_root} failed (exit {done.returncode}):\n{done.stdout[-2000:]}\n"
                           f"{done.stderr[-4000:]}")
    out: dict[str, float] = json.loads(lines[-1][len("RUN "):])
    return out


def compare(rev: str, counts: list[int], n_frames: int) -> dict[int, dict[str, float]]:
    """Every count with revision ``rev``'s code and this code, alternating fresh processes;
    prints both tables and the ratios; returns this code's rows."""
    git = ["git", "-C", str(ROOT)]
    found = subprocess.run([*git, "rev-parse", "--short", "--verify", f"{rev}^{{commit}}"],
                           capture_output=True, text=True, check=False)
    if found.returncode != 0:
        raise SystemExit(f"--baseline {rev}: not a revision of the repository at {ROOT}")
    sha = found.stdout.strip()
    base: dict[int, dict[str, float]] = {}
    this: dict[int, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(prefix="procloco-baseline-") as tmp:
        archive = subprocess.run([*git, "archive", "--format=tar", rev], capture_output=True,
                                 check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        for count in counts:
            base[count] = _in_process(Path(tmp), count, n_frames)
            this[count] = _in_process(CODE, count, n_frames)
    print(f"\nbaseline {sha}:")
    table(base)
    print("this checkout:")
    table(this)
    print("baseline / this (times faster), wall then CPU:")
    for key, cpu_ in (("total", ""), ("cpu", "_cpu")):
        print(f"{'rigs':>6} {key:>9} | " + " ".join(f"{c:>10}" for c in COLUMNS))
        for count in counts:
            b, t = base[count], this[count]
            print(f"{count:>6} {b[key] / t[key]:>9.2f} | "
                  + " ".join(f"{b[c + cpu_] / t[c + cpu_]:>10.2f}" if t[c + cpu_] > 1e-3 else f"{'-':>10}"
                             for c in COLUMNS))
    return this


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", default="1,10,100", help="comma-separated numbers of wolves")
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--baseline", default="", help="git revision to compare with, stage by stage")
    ap.add_argument("--code-root", default="", help=argparse.SUPPRESS)
    ap.add_argument("--one-run", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    counts = [int(c) for c in args.counts.split(",")]
    header = (f"\nGenerate Locomotion on N selected wolves, {args.frames} frames; "
              f"Blender {bpy.app.version_string}, {platform.processor() or platform.machine()}, "
              f"{os.cpu_count()} cores")
    if args.baseline:
        print(header)
        rows = compare(args.baseline, counts, args.frames)
    else:
        procloco_addon.register()
        try:
            rows = {count: run(count, args.frames) for count in counts}
        finally:
            procloco_addon.unregister()
        if args.one_run:
            # (on a line of its own: Blender cuts a long report, such as the Generated line
            # naming a hundred Actions, before its line break)
            print("\nRUN " + json.dumps(rows[counts[0]]))
            return
        # (the table after every run: the operator prints its progress while it works)
        print(header)
        table(rows)
    first, last = counts[0], counts[-1]
    one_s = rows[first]["total"] / first
    print(f"RESULT crowd_blender one_s={one_s:.3f} hundred_s={rows[last]['total']:.3f} "
          f"ratio={rows[last]['total'] / one_s:.1f}")


if __name__ == "__main__":
    main()
