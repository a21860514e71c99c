# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate Locomotion end to end in Blender (the ``bpy`` module), and bulk keyframe writing
against a per-frame ``keyframe_insert`` baseline, in the same run.

    python benchmarks/bench_blender.py [--frames 250] [--repeat 3]

Scene: the Rigify wolf metarig (skinned with capsules) on a 12 m × 12 m wavy heightmap mesh
(18k triangles) with ten crates. Rows:

* read — rig, legs, morphology and terrain (``generate.prepare``);
* simulate — the core character controller, one step per frame;
* write — pose solving (``rig.solve_pose``) plus keys written in bulk (``actions``:
  ``keyframe_points.add`` + ``foreach_set``), i.e. ``generate.write``;
* the same write step with every key inserted by ``pose_bone.keyframe_insert`` frame by
  frame (the usual way scripts key a pose), on a copy of the rig, and the key writing alone
  both ways;
* the operator ``procloco.generate_locomotion`` timed as a whole;
* heavy terrain: the wolf on a 1M-triangle grid, static and then moved by 1 mm over the
  range (keyed location), ``--heavy-frames`` frames: time of reading (``generate.prepare``)
  and simulating, and the peak memory numpy allocates meanwhile (``tracemalloc``), once each.
* Key Reduction: the keys of the wolf's walk before and after, the time the reduction takes
  and the worst posed-rig errors it measured, at the default tolerances (1 mm, 0.5°) and
  looser ones, and on the example wolf of ``examples.blend`` (``--keys-only`` runs only this
  table), once each.

Every row of the first table is the best of ``--repeat`` runs. ``--heavy-only`` runs only the
heavy-terrain table.

``--baseline REV`` compares the simulation of one wolf (the ``simulate`` row: ms per frame)
with the code of git revision ``REV`` (``git archive`` into a temporary folder), in the same
invocation: ``--rounds`` alternating fresh processes of each code (the same script, the same
scene), best of ``--repeat`` simulations in each, so both figures see the same load; prints
both figures and their ratio. ``--sim-only`` prints only that comparison (or, without
``--baseline``, only this code's simulate figure), skipping the other tables.

Ends with
``RESULT blender total_s=<s> write_s=<s> keyframe_insert_s=<s> heavy_static_s=<s> heavy_animated_s=<s>
keys_before=<n> keys_after=<n> reduction_s=<s>`` (the default tolerances on the benchmark wolf).
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
import tracemalloc
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def _code_root() -> Path:
    """The source tree to import the add-on from: this checkout, or ``--code-root DIR`` (the
    baseline's tree when ``--baseline`` runs this script on another revision's code)."""
    if "--code-root" in sys.argv:
        return Path(sys.argv[sys.argv.index("--code-root") + 1]).resolve()
    return ROOT


CODE = _code_root()
sys.path.insert(0, str(CODE))
_HOME = Path(tempfile.mkdtemp(prefix="procloco-bench-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_HOME / "config"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import procloco_addon  # noqa: E402
from procloco_addon.blender import actions, rig  # noqa: E402
from procloco_addon.blender.locomotion import generate, simulation  # noqa: E402
from tools.examples import creatures  # noqa: E402


def build_scene(n_frames: int) -> bpy.types.Object:
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, n_frames
    scene.render.fps = 24
    n = 96
    xs = np.linspace(-6.0, 6.0, n)
    gx, gy = np.meshgrid(xs, xs - 4.0)
    gz = 0.05 * np.sin(gx / 0.9) * np.cos(gy / 1.3)
    gz[np.hypot(gx, gy) < 0.9] = 0.0
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j)
             for i in range(n - 1) for j in range(n - 1)]
    mesh = bpy.data.meshes.new("Ground")
    mesh.from_pydata(np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()]).tolist(), [], faces)
    ground = bpy.data.objects.new("Ground", mesh)
    scene.collection.objects.link(ground)
    rng = np.random.default_rng(1)
    for k in range(10):
        x, y = rng.uniform(-2.0, 2.0), rng.uniform(-9.0, -1.5)
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(x, y, 0.04))
        crate = bpy.context.active_object
        crate.name = f"Crate{k}"
        crate.scale = (0.4, 0.3, 0.1)
        crate.procloco_role = "STEP_OVER"
    wolf = creatures.build_wolf(scene)
    wolf.procloco.speed = 1.0
    wolf.procloco.step_height = 0.1
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    wolf.select_set(True)
    bpy.context.view_layer.objects.active = wolf
    return wolf


def keyframe_insert_write(job: generate.Job, obj: bpy.types.Object) -> tuple[float, float, float]:
    """The write step done twice on ``obj`` (a copy of the rig): pose solving, then the same
    channels keyed in bulk and keyed by per-frame ``keyframe_insert``. Returns the three times."""
    t0 = time.perf_counter()
    body, joints = simulation.world_tracks(job)
    leg_frames, spine_rotation, spine_joints = simulation.spine_tracks(job)
    tracks = rig.solve_pose(job.info, body, joints, ground=simulation.ground_function(job),
                            spine_rotation=spine_rotation, spine_joints=spine_joints, leg_frames=leg_frames)
    t1 = time.perf_counter()
    bulk = actions.new_action(obj, "Bulk")
    frames = job.frames.astype(np.float64)
    actions.write_pose_bone_transforms(bulk, obj, frames, tracks.bones, rotations=tracks.rotations)
    loc = [i for i, k in enumerate(tracks.keyed_location) if k]
    actions.write_pose_bone_transforms(bulk, obj, frames, [tracks.bones[i] for i in loc],
                                       locations=tracks.locations[:, loc])
    t2 = time.perf_counter()
    bpy.data.actions.remove(bulk)
    t3 = time.perf_counter()
    pbones = [obj.pose.bones[name] for name in tracks.bones]
    for f, frame in enumerate(job.frames):
        for b, pb in enumerate(pbones):
            prop, values = actions.rotation_channels(pb.rotation_mode, tracks.rotations[f:f + 1, b])
            setattr(pb, prop, values[0])
            pb.keyframe_insert(prop, frame=int(frame))
            if tracks.keyed_location[b]:
                pb.location = tracks.locations[f, b]
                pb.keyframe_insert("location", frame=int(frame))
    t4 = time.perf_counter()
    return t1 - t0, t2 - t1, t4 - t3


def heavy_terrain(n_frames: int, animated: bool) -> tuple[float, float, float]:
    """The wolf on a 1M-triangle grid (moved 1 mm up over the range when ``animated``):
    seconds to read, seconds to simulate, peak MB numpy allocated."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, n_frames
    scene.render.fps = 24
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=708, y_subdivisions=708, size=20.0)  # 1,002,528 triangles
    ground = bpy.context.active_object
    ground.name = "Heavy"
    if animated:
        ground.keyframe_insert("location", frame=1)
        ground.location.z = 0.001
        ground.keyframe_insert("location", frame=n_frames)
    wolf = creatures.build_wolf(scene)
    wolf.procloco.speed = 1.0
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    wolf.select_set(True)
    bpy.context.view_layer.objects.active = wolf
    tracemalloc.start()
    t0 = time.perf_counter()
    job = generate.prepare(bpy.context, wolf)
    t1 = time.perf_counter()
    for _fraction in generate.simulate(job):
        pass
    t2 = time.perf_counter()
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return t1 - t0, t2 - t1, peak


def long_range(n_frames: int) -> dict[str, tuple[float, float]]:
    """Generate Locomotion and then Bake Secondary Motion (the tail, on the generated walk)
    over ``n_frames`` frames, the Rigify wolf on a flat 400 m plane: per stage seconds and
    the peak MB numpy allocated in it (``tracemalloc``), once each."""
    from procloco_addon.blender.secondary import bake

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, n_frames
    scene.render.fps = 24
    bpy.ops.mesh.primitive_plane_add(size=400.0)
    wolf = creatures.build_wolf(scene)
    wolf.procloco.speed = 0.5
    wolf.procloco.turn_rate = 0.05  # in circles of 10 m: the walk stays on the plane
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    wolf.select_set(True)
    bpy.context.view_layer.objects.active = wolf
    rows: dict[str, tuple[float, float]] = {}

    def stage(name: str, work: Any) -> Any:
        tracemalloc.start()
        t0 = time.perf_counter()
        out = work()
        rows[name] = (time.perf_counter() - t0, tracemalloc.get_traced_memory()[1] / 1e6)
        tracemalloc.stop()
        return out

    def drain(steps: Any) -> None:
        for _fraction in steps:
            pass

    job = stage("generate: read", lambda: generate.prepare(bpy.context, wolf))
    stage("generate: simulate", lambda: drain(generate.simulate(job)))
    stage("generate: write", lambda: generate.write(bpy.context, job))
    bake.suggest_into_settings(wolf)
    for chain in wolf.procloco_secondary.chains:  # the tail only
        chain.enabled = chain.root == "spine.003"
    bjob = stage("bake: read", lambda: bake.prepare(bpy.context, wolf))
    stage("bake: play the animation", lambda: drain(bake.sample(bpy.context, bjob)))
    stage("bake: pendulums", lambda: drain(bake.simulate_steps(bjob)))
    stage("bake: write", lambda: bake.write(bpy.context, bjob))
    return rows


def simulate_times(n_frames: int, repeat: int) -> list[tuple[float, float]]:
    """(wall, CPU) seconds of ``generate.simulate`` on the benchmark scene, ``repeat`` times
    (a fresh ``generate.prepare`` each time, not timed)."""
    wolf = build_scene(n_frames)
    out = []
    for _ in range(repeat):
        job = generate.prepare(bpy.context, wolf)
        t0, c0 = time.perf_counter(), time.process_time()
        for _fraction in generate.simulate(job):
            pass
        out.append((time.perf_counter() - t0, time.process_time() - c0))
    return out


def _simulate_in_process(code_root: Path, n_frames: int, repeat: int) -> list[tuple[float, float]]:
    """:func:`simulate_times` in a fresh process importing the add-on from ``code_root``."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--code-root", str(code_root), "--simulate-times",
           "--frames", str(n_frames), "--repeat", str(repeat)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("SIMULATE ")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"simulation of {code_root} failed:\n{done.stdout[-2000:]}\n{done.stderr[-4000:]}")
    return [(float(w), float(c)) for w, c in json.loads(lines[-1][len("SIMULATE "):])]


def compare_baseline(rev: str, n_frames: int, repeat: int, rounds: int) -> str:
    """The wolf's simulation with this code and with revision ``rev``'s, in alternating fresh
    processes; prints both and the ratio, returns the RESULT fields."""
    git = ["git", "-C", str(ROOT)]
    found = subprocess.run([*git, "rev-parse", "--short", "--verify", f"{rev}^{{commit}}"],
                           capture_output=True, text=True, check=False)
    if found.returncode != 0:
        raise SystemExit(f"--baseline {rev}: not a revision of the repository at {ROOT}")
    sha = found.stdout.strip()
    with tempfile.TemporaryDirectory(prefix="procloco-baseline-") as tmp:
        archive = subprocess.run([*git, "archive", "--format=tar", rev], capture_output=True,
                                 check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        times: dict[str, list[tuple[float, float]]] = {"this": [], "base": []}
        for _ in range(rounds):
            times["base"] += _simulate_in_process(Path(tmp), n_frames, repeat)
            times["this"] += _simulate_in_process(ROOT, n_frames, repeat)
    print(f"Simulation of one Rigify wolf, {n_frames} frames: {rounds} rounds of alternating processes, "
          f"best of {rounds * repeat} each (CPU: the process's CPU time, steadier on a loaded machine)")
    print(f"{'code':24s} {'wall s':>8s} {'ms/frame':>9s} {'CPU s':>8s} {'CPU ms/frame':>13s}")
    best = {}
    for key, name in (("base", f"baseline {sha}"), ("this", "this checkout")):
        wall = min(w for w, _ in times[key])
        cpu = min(c for _, c in times[key])
        best[key] = (wall, cpu)
        print(f"{name:24s} {wall:8.3f} {1000 * wall / n_frames:9.2f} "
              f"{cpu:8.3f} {1000 * cpu / n_frames:13.2f}")
    wall_ratio = best["base"][0] / best["this"][0]
    cpu_ratio = best["base"][1] / best["this"][1]
    print(f"speed-up (baseline / this, best of each): wall {wall_ratio:.2f}x, CPU {cpu_ratio:.2f}x")
    return (f"sim_ms_per_frame={1000 * best['this'][0] / n_frames:.3f} "
            f"baseline_sim_ms_per_frame={1000 * best['base'][0] / n_frames:.3f} sim_speedup={wall_ratio:.2f} "
            f"sim_cpu_speedup={cpu_ratio:.2f}")


#: Key Reduction rows: (foot tolerance m, bone tolerance degrees).
KEY_TOLERANCES = ((0.001, 0.5), (0.002, 1.0), (0.005, 2.0))


def key_reduction(n_frames: int) -> list[tuple[str, Any]]:
    """Generate with Key Reduction on: the benchmark wolf at each of :data:`KEY_TOLERANCES`,
    then the example wolf of ``examples.blend`` at the defaults. Per row a label and the
    :class:`procloco_addon.blender.keys.reduce.Reduction`."""
    rows: list[tuple[str, Any]] = []

    def run(wolf: bpy.types.Object, foot: float, angle: float) -> Any:
        wolf.procloco_keys.use_key_reduction = True
        wolf.procloco_keys.foot_tolerance = foot
        wolf.procloco_keys.angle_tolerance = np.radians(angle)
        job = generate.prepare(bpy.context, wolf)
        for _fraction in generate.simulate(job):
            pass
        generate.write(bpy.context, job)
        return job.key_reduction

    for foot, angle in KEY_TOLERANCES:
        rows.append((f"bench wolf, {n_frames} fr, {1000 * foot:g} mm {angle:g} deg",
                     run(build_scene(n_frames), foot, angle)))
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "examples.blend"))
    wolf = bpy.data.objects["Wolf"]
    start, end = generate.property_group.frame_range(wolf.procloco, bpy.context.scene)
    rows.append((f"example wolf, {end - start + 1} fr, 1 mm 0.5 deg", run(wolf, 0.001, 0.5)))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=250)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--baseline", metavar="REV", help="compare the simulation with revision REV's code")
    parser.add_argument("--rounds", type=int, default=3, help="alternating processes per code (--baseline)")
    parser.add_argument("--sim-only", action="store_true", help="only the one-wolf simulation figure(s)")
    parser.add_argument("--code-root", help=argparse.SUPPRESS)
    parser.add_argument("--simulate-times", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--heavy-frames", type=int, default=48)
    parser.add_argument("--heavy-only", action="store_true")
    parser.add_argument("--long-frames", type=int, default=10_000)
    parser.add_argument("--long-only", action="store_true")
    parser.add_argument("--keys-only", action="store_true")
    args = parser.parse_args()

    procloco_addon.register()
    if args.simulate_times:
        print("SIMULATE " + json.dumps(simulate_times(args.frames, args.repeat)))
        return 0
    if args.sim_only:
        if args.baseline:
            result = compare_baseline(args.baseline, args.frames, args.repeat, args.rounds)
        else:
            best_s = min(w for w, _ in simulate_times(args.frames, args.repeat))
            print(f"simulate, one Rigify wolf, {args.frames} frames: {best_s:.3f} s, "
                  f"{1000 * best_s / args.frames:.2f} ms/frame (best of {args.repeat})")
            result = f"sim_ms_per_frame={1000 * best_s / args.frames:.3f}"
        print(f"RESULT blender {result}")
        return 0
    keys = key_reduction(args.frames)
    print("Key Reduction: keys before and after, posed-rig errors measured, once each")
    print(f"{'walk, tolerances':42s} {'before':>8s} {'after':>8s} {'ratio':>6s} {'reduce s':>9s} "
          f"{'feet mm':>8s} {'bones deg':>9s}")
    for label, r in keys:
        print(f"{label:42s} {r.keys_before:8d} {r.keys_after:8d} {r.ratio:6.2f} {r.seconds:9.2f} "
              f"{1000 * r.foot_error:8.3f} {np.degrees(r.angle_error):9.3f}")
    default = keys[0][1]
    keys_result = (f"keys_before={default.keys_before} keys_after={default.keys_after} "
                   f"reduction_s={default.seconds:.3f}")
    if args.keys_only:
        print(f"RESULT blender {keys_result}")
        return 0
    long = long_range(args.long_frames)
    print(f"Long range: Rigify wolf, Generate then Bake Secondary Motion (tail), {args.long_frames} frames, "
          "once each")
    print(f"{'stage':28s} {'seconds':>9s} {'ms/frame':>9s} {'peak MB':>8s}")
    for name, (sec, peak) in long.items():
        print(f"{name:28s} {sec:9.2f} {1000 * sec / args.long_frames:9.3f} {peak:8.0f}")
    gen_s = sum(sec for name, (sec, _) in long.items() if name.startswith("generate"))
    bake_s = sum(sec for name, (sec, _) in long.items() if name.startswith("bake"))
    long_result = f"long_generate_s={gen_s:.3f} long_bake_s={bake_s:.3f}"
    if args.long_only:
        print(f"RESULT blender {long_result} {keys_result}")
        return 0
    heavy = {kind: heavy_terrain(args.heavy_frames, kind == "animated") for kind in ("static", "animated")}
    print(f"Heavy terrain: Rigify wolf on a 1M-triangle grid, {args.heavy_frames} frames, once each")
    print(f"{'ground':24s} {'read s':>8s} {'simulate s':>11s} {'total s':>8s} {'peak MB':>8s}")
    for kind, (read_s, sim_s, peak) in heavy.items():
        print(f"{kind:24s} {read_s:8.2f} {sim_s:11.2f} {read_s + sim_s:8.2f} {peak:8.0f}")
    (rs, ss, ps), (ra, sa, pa) = heavy["static"], heavy["animated"]
    print(f"animated / static: time {(ra + sa) / (rs + ss):.2f}x, peak memory {pa / ps:.2f}x")
    heavy_result = f"heavy_static_s={rs + ss:.3f} heavy_animated_s={ra + sa:.3f}"
    if args.heavy_only:
        print(f"RESULT blender {heavy_result} {long_result} {keys_result}")
        return 0
    best: dict[str, float] = {}

    def keep(name: str, seconds: float) -> None:
        best[name] = min(best.get(name, np.inf), seconds)

    n_channels = n_keys = 0
    for _ in range(args.repeat):
        wolf = build_scene(args.frames)
        t0 = time.perf_counter()
        job = generate.prepare(bpy.context, wolf)
        t1 = time.perf_counter()
        for _fraction in generate.simulate(job):
            pass
        t2 = time.perf_counter()
        action = generate.write(bpy.context, job)
        t3 = time.perf_counter()
        keep("read", t1 - t0)
        keep("simulate", t2 - t1)
        keep("write", t3 - t2)
        n_channels = len(actions.channels_of(action, wolf))
        n_keys = n_channels * args.frames
        # Baseline on a copy of the rig that shares its armature.
        twin = wolf.copy()
        twin.animation_data_clear()
        bpy.context.scene.collection.objects.link(twin)
        solve_s, bulk_s, insert_s = keyframe_insert_write(job, twin)
        keep("solve", solve_s)
        keep("bulk_keys", bulk_s)
        keep("insert_keys", insert_s)
        keep("keyframe_insert", solve_s + insert_s)
        baseline = twin.animation_data.action
        bpy.data.objects.remove(twin)
        bpy.data.actions.remove(baseline)
        # The operator as a whole (a new Action each time).
        t0 = time.perf_counter()
        assert bpy.ops.procloco.generate_locomotion() == {"FINISHED"}
        keep("operator", time.perf_counter() - t0)

    f = args.frames
    print(f"ProcLoco Blender benchmark: Rigify wolf metarig, {f} frames at 24 fps, best of {args.repeat}")
    print(f"bpy {bpy.app.version_string}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}, {os.cpu_count()} cores")
    print(f"written: {n_channels} F-curves, {n_keys} keys")
    print(f"{'stage':40s} {'seconds':>9s} {'ms/frame':>9s}")
    rows = [
        ("read (rig, legs, terrain)", best["read"]),
        ("simulate (core controller)", best["simulate"]),
        ("write (solve pose + bulk keys)", best["write"]),
        ("sum of the stages", best["read"] + best["simulate"] + best["write"]),
        ("operator generate_locomotion (total)", best["operator"]),
        ("write with per-frame keyframe_insert", best["keyframe_insert"]),
        ("  pose solving alone", best["solve"]),
        ("  keys alone, bulk foreach_set", best["bulk_keys"]),
        ("  keys alone, per-frame keyframe_insert", best["insert_keys"]),
    ]
    for name, sec in rows:
        print(f"{name:40s} {sec:9.3f} {1000 * sec / f:9.2f}")
    print(f"write step {best['keyframe_insert'] / best['write']:.1f}x faster than with keyframe_insert; "
          f"keys alone {best['insert_keys'] / best['bulk_keys']:.0f}x")
    base_result = ""
    if args.baseline:
        base_result = " " + compare_baseline(args.baseline, args.frames, args.repeat, args.rounds)
    print(f"RESULT blender total_s={best['operator']:.3f} write_s={best['write']:.3f} "
          f"keyframe_insert_s={best['keyframe_insert']:.3f} {heavy_result} {long_result} {keys_result}"
          f"{base_result}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
