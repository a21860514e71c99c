# SPDX-License-Identifier: GPL-3.0-or-later
"""Live Preview's latency on the Rigify wolf, with Generate Locomotion beside it in the same run.

    python benchmarks/bench_live_preview.py [--frames 120] [--repeat 3]

Scene: ``bench_blender``'s (the Rigify wolf metarig on a wavy 18k-triangle heightmap with ten
crates), ``--frames`` frames. Live Preview is switched on and its timer callback is called
as Blender would call it (each call works at most ``BUDGET_S``, the timer's own waits are
slept). Then the speed is edited, the current frame being the first, the middle or the last
of the range, and the rows are, from the edit:

* current frame: until the current frame's pose is on the rig (the one-frame Action), or
  the whole walk when the current frame is the last;
* whole walk: until the whole range is written;
* longest call: the longest single timer call (how long the interface is held at most);
* pose, CPU and whole, CPU: this process's CPU time to the current frame's pose and to the
  whole walk (a loaded machine stretches the wall times; the CPU times much less);

then (row "later") a Gait Change at three quarters of the range is added and its speed edited, the
current frame the last (Live Preview re-simulates only from the frame the edit changes), and (row
"crate") a crate the walk reaches at about frame 80 is moved sideways after a quiet time (re-simulated
from the first frame that looked near it); with, last,
``generate_locomotion`` run straight through on the same edit (read, simulate,
write). Times are the best of ``--repeat`` edits. The edit comes after a quiet time, so the
regeneration starts at once (edits in a burst wait ``DEBOUNCE_S`` after the last one; add
it to these figures for them). Ends with
``RESULT live_preview first_s=<middle frame> whole_s=<middle frame> first_cpu_s=<first frame, CPU>
last_s=<last frame> later_s=<later edit> crate_s=<crate moved> generate_s=<s> generate_cpu_s=<s>
longest_call_s=<s>``.
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
_HOME = Path(tempfile.mkdtemp(prefix="procloco-bench-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_HOME / "config"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402

import procloco_addon  # noqa: E402
from benchmarks import bench_blender  # noqa: E402
from procloco_addon.blender.live_preview import handler, preview  # noqa: E402
from procloco_addon.blender.locomotion import generate  # noqa: E402


def _inputs(obj: bpy.types.Object) -> tuple[str, object, object] | None:
    action = obj.animation_data.action if obj.animation_data else None
    return None if action is None else (action.name, action.get(preview.INPUTS_TAG),
                                        action.get(preview.PARTIAL_TAG))


def _drive(obj: bpy.types.Object) -> tuple[float, float, float, float, float]:
    """Call the timer until the preview is done: (to the current frame's pose, to the whole
    walk, longest call: wall seconds; the current frame's pose and the whole walk in this
    process's CPU seconds)."""
    t0, c_start = time.perf_counter(), time.process_time()
    before = _inputs(obj)
    first = first_cpu = None
    longest = 0.0
    while True:
        c0 = time.perf_counter()
        wait = handler.tick()
        longest = max(longest, time.perf_counter() - c0)
        now = _inputs(obj)
        if first is None and now != before and now is not None and now[1] is not None:
            first = time.perf_counter() - t0  # the one-frame Action, or the whole walk
            first_cpu = time.process_time() - c_start
        if wait is None or (handler._state.run is None
                            and all(w.due is None for w in handler._state.watches.values())):
            whole, whole_cpu = time.perf_counter() - t0, time.process_time() - c_start
            return (whole if first is None else first, whole, longest,
                    whole_cpu if first_cpu is None else first_cpu, whole_cpu)
        if wait > 0.0:  # (a timer asking for no wait is called again at once, as Blender does)
            time.sleep(wait)


def _edits(obj: bpy.types.Object, label: str, edits: list[Callable[[], object]]
           ) -> tuple[float, float, float, float, float]:
    """Make each edit after a quiet time and drive the preview to its end; print and return
    the best of each of :func:`_drive`'s figures (the longest call: the worst)."""
    best = (float("inf"), float("inf"), 0.0, float("inf"), float("inf"))
    for edit in edits:
        time.sleep(handler.DEBOUNCE_S)  # a quiet time before the edit
        edit()
        got = _drive(obj)
        best = (min(best[0], got[0]), min(best[1], got[1]), max(best[2], got[2]), min(best[3], got[3]),
                min(best[4], got[4]))
    print(f"{label:>14} {best[0]:11.3f}s {best[1]:10.3f}s {best[2]:12.3f}s {best[3]:9.3f}s {best[4]:10.3f}s")
    return best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    procloco_addon.register()
    wolf = bench_blender.build_scene(args.frames)
    generate.detect_into_settings(wolf)
    scene = bpy.context.scene
    wolf.procloco.live_preview = True
    _drive(wolf)
    print(f"Live Preview, Rigify wolf, {args.frames} frames; {platform.processor() or platform.machine()}, "
          f"Blender {bpy.app.version_string}")
    print(f"{'current frame':>14} {'to its pose':>12} {'whole walk':>11} {'longest call':>13} "
          f"{'pose, CPU':>10} {'whole, CPU':>11}")
    speeds = iter([1.05, 0.95] * (3 * args.repeat + 2))
    rows = {}
    for where, frame in (("first", 1), ("middle", args.frames // 2), ("last", args.frames)):
        scene.frame_set(frame)
        _drive(wolf)
        rows[where] = _edits(wolf, f"{where} ({frame})",
                             [lambda: setattr(wolf.procloco, "speed", next(speeds))] * args.repeat)
    # A later edit: a Gait Change at three quarters of the range (its speed below the rig's,
    # so Auto's planning window stays) edited, the current frame the last.
    scene.frame_set(3 * args.frames // 4)
    bpy.context.view_layer.objects.active = wolf
    bpy.ops.procloco.add_gait_change()
    change = wolf.procloco.gait_changes[0]
    change.speed = 0.5
    scene.frame_set(args.frames)
    _drive(wolf)
    rows["later"] = _edits(wolf, f"later ({args.frames})",
                           [functools.partial(setattr, change, "speed", speed)
                            for speed in [0.45, 0.5] * args.repeat])
    wolf.procloco.gait_changes.clear()
    _drive(wolf)
    # A crate the walk reaches late (about frame 80 of 120) moved sideways by 0.3 m and back.
    crate = bpy.data.objects["Crate3"]

    def move(dx: float) -> None:
        crate.location.x += dx
        bpy.context.view_layer.update()  # (the depsgraph handler sees the move)

    rows["crate"] = _edits(wolf, f"crate ({args.frames})",
                           [functools.partial(move, dx) for dx in [0.3, -0.3] * args.repeat])
    wolf.procloco.live_preview = False
    _drive(wolf)
    scene.frame_set(1)
    generate_s = generate_cpu = float("inf")
    for _ in range(args.repeat):
        wolf.procloco.speed = next(speeds)
        t0, c0 = time.perf_counter(), time.process_time()
        bpy.ops.procloco.generate_locomotion()
        generate_s = min(generate_s, time.perf_counter() - t0)
        generate_cpu = min(generate_cpu, time.process_time() - c0)
    print(f"Generate Locomotion straight through (same edits): {generate_s:.3f}s, CPU {generate_cpu:.3f}s")
    longest = max(r[2] for r in rows.values())
    print(f"RESULT live_preview first_s={rows['middle'][0]:.3f} whole_s={rows['middle'][1]:.3f} "
          f"first_cpu_s={rows['first'][3]:.3f} last_s={rows['last'][0]:.3f} later_s={rows['later'][0]:.3f} "
          f"crate_s={rows['crate'][0]:.3f} "
          f"generate_s={generate_s:.3f} generate_cpu_s={generate_cpu:.3f} "
          f"longest_call_s={longest:.3f}")
    sys.stdout.flush()
    os._exit(0)  # (Blender's own exit handlers are not needed here)


if __name__ == "__main__":
    raise SystemExit(main())
