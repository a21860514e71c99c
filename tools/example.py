# SPDX-License-Identifier: GPL-3.0-or-later
"""The README's main job: every creature of ``examples.blend`` walks, swings and is rendered.

    python3 tools/dev.py example [--blend examples.blend] [--out out/example] [--rig NAME ...]
                                 [--frame-step N] [--resolution W H] [--close-up-frames F ...]
                                 [--no-biped] [--update-docs] [--info]
    python3 tools/dev.py example --crowd [--blend examples_crowd.blend] [--out out/example_crowd] ...

Runs Blender headless (the ``bpy`` module), enables ProcLoco the way Blender does — as an
extension from a repository that points at this checkout — opens ``examples.blend`` (built
first by ``tools/build_examples.py`` when it is missing) and, printing its progress:

1. runs the extension's batch command ``procloco generate --all --bake-secondary``:
   Generate Locomotion on every creature, then Bake Secondary Motion on every rig with
   pendulum chains (the wolf's tail and ears, the ant's antennae and gaster, the spider's
   palps and abdomen, the lizard's tail);
2. walks the human up and down its stairs with Plan Biped Footsteps (its clips and goal
   are set up in ``examples.blend``; ``--no-biped`` keeps its Generate Locomotion walk);
3. renders with Workbench and saves, into ``--out``:

   * ``frames/frame_####.png`` — the scene camera's view, every ``--frame-step``-th frame,
   * ``contact_sheet.png`` — twelve of those frames tiled,
   * ``walk.gif`` — those frames as a looping animated GIF in real time (written with
     numpy: Blender writes no GIF),
   * ``creatures.png`` — a close-up of each creature (columns) at ``--close-up-frames`` (rows),
   * ``examples_generated.blend`` — the scene with the new Actions.

``--update-docs`` also writes the README's pictures: ``docs/images/example_walk.gif`` (the
loop), ``docs/images/example_contact_sheet.png`` (six of the frames, three to a row) and
``docs/images/example_creatures.png`` (the close-ups). ``--info`` only lists the rigs, their
legs and their chains.

``--crowd`` does the same for the crowd example ``examples_crowd.blend`` (built first by
``tools/build_crowd_example.py`` when missing): 40 spiders and 20 ants, each its own rig,
walk through each other's ranks over a log and crates. It runs ``procloco generate --all``
(no secondary motion, no biped, no close-ups) and writes ``frames/``, ``contact_sheet.png``,
``crowd.png`` (the last frame at twice the resolution), ``walk.gif`` and
``examples_crowd_generated.blend`` into ``out/example_crowd``; with ``--update-docs``,
``docs/images/example_crowd.png`` and ``docs/images/example_crowd.gif``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
_HOME = Path(tempfile.mkdtemp(prefix="procloco-example-"))
os.environ.setdefault("BLENDER_USER_RESOURCES", str(_HOME / "resources"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_HOME / "config"))
os.environ.setdefault("XDG_CACHE_HOME", str(_HOME / "cache"))

import bpy  # noqa: E402

# Blender's own modules are importable once bpy is.
addon_utils = importlib.import_module("addon_utils")

REPO_MODULE = "procloco_example"
PACKAGE = f"bl_ext.{REPO_MODULE}.procloco"


def enable_extension() -> str:
    """Enable ProcLoco as an extension from this checkout; returns its package name."""
    repo_dir = _HOME / "extensions"
    repo_dir.mkdir(parents=True, exist_ok=True)
    link = repo_dir / "procloco"
    if not link.exists():
        link.symlink_to(ROOT, target_is_directory=True)
    bpy.context.preferences.extensions.repos.new(name="ProcLoco example", module=REPO_MODULE,
                                                 custom_directory=str(repo_dir), source="USER")
    addon_utils.enable(PACKAGE, default_set=True, handle_error=None)
    if not addon_utils.check(PACKAGE)[1]:
        sys.exit("could not enable the ProcLoco extension")
    return PACKAGE


def _say(text: str) -> None:
    print(f"[example] {text}", flush=True)


def plan_biped(obj: bpy.types.Object) -> str:
    """Plan Biped Footsteps on ``obj`` (its clips and goal as saved); returns what happened."""
    settings = obj.procloco_biped
    if settings.goal is None or not len(settings.clips):
        return f"{obj.name}: no biped goal or clips, kept its walk"
    with bpy.context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        result = bpy.ops.procloco.plan_biped_footsteps()
    if result != {"FINISHED"}:
        raise RuntimeError(f"Plan Biped Footsteps refused {obj.name}")
    action = obj.animation_data.action
    start, end = (round(v) for v in action.frame_range)
    return (f"{obj.name}: walked to '{settings.goal.name}' with Plan Biped Footsteps, "
            f"Action '{action.name}' (frames {start}-{end})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--crowd", action="store_true",
                        help="the crowd example examples_crowd.blend instead (out/example_crowd)")
    parser.add_argument("--blend", type=Path, default=None, help="default: examples.blend")
    parser.add_argument("--out", type=Path, default=None, help="default: out/example")
    parser.add_argument("--rig", action="append", default=[], help="only these rigs (default: all)")
    parser.add_argument("--frame-step", type=int, default=4, help="render every N-th frame")
    parser.add_argument("--resolution", nargs=2, type=int, default=(640, 360), metavar=("W", "H"))
    parser.add_argument("--close-up-frames", nargs="+", type=int, default=[12, 60, 108], metavar="F",
                        help="frames of the creature close-ups (one row each)")
    parser.add_argument("--no-biped", action="store_true",
                        help="keep the human's Generate Locomotion walk instead of Plan Biped Footsteps")
    parser.add_argument("--update-docs", action="store_true",
                        help="also write the README's pictures docs/images/example_*.png")
    parser.add_argument("--info", action="store_true", help="only list the rigs, their legs and chains")
    args = parser.parse_args(argv)
    if args.crowd:
        return crowd_main(args)
    args.blend = args.blend or ROOT / "examples.blend"
    args.out = args.out or ROOT / "out" / "example"

    t0 = time.perf_counter()
    if not args.blend.exists():
        _say(f"{args.blend.name} is missing: building it with tools/build_examples.py")
        build = importlib.import_module("tools.build_examples")
        build.build(args.blend)
        bpy.ops.wm.read_homefile(use_empty=True)
    package = enable_extension()
    _say(f"enabled {package} (Blender {bpy.app.version_string})")
    bpy.ops.wm.open_mainfile(filepath=str(args.blend))
    cli = importlib.import_module(f"{package}.procloco_addon.blender.cli")
    if args.info:
        return int(cli.main(["info"]))
    examples = importlib.import_module("tools.examples.scene")
    scene = bpy.context.scene
    names = args.rig or sorted(o.name for o in scene.objects if o.type == "ARMATURE")
    out = args.out.resolve()

    command = ["generate", *[x for name in names for x in ("--rig", name)], "--bake-secondary"]
    _say("1/4 procloco " + " ".join(command))
    status = int(cli.main(command))
    if status:
        return status
    _say(f"    generated and baked in {time.perf_counter() - t0:.1f} s")
    rigs = [bpy.data.objects[name] for name in names]
    if not args.no_biped:
        t1 = time.perf_counter()
        for obj in rigs:
            if len(obj.procloco_biped.clips):
                _say(f"2/4 {plan_biped(obj)} in {time.perf_counter() - t1:.1f} s")

    t1 = time.perf_counter()
    frames = range(scene.frame_start, scene.frame_end + 1, max(1, args.frame_step))
    _say(f"3/4 rendering {len(frames)} frames ({args.resolution[0]}x{args.resolution[1]}, Workbench)")
    files = cli.render_frames(scene, out / "frames", frames, tuple(args.resolution), focus=rigs)
    sheet = cli.contact_sheet(files, out / "contact_sheet.png")
    _say(f"    {sheet} ({time.perf_counter() - t1:.1f} s)")
    fps = scene.render.fps / scene.render.fps_base
    walk_gif = cli.animated_gif(files, out / "walk.gif", max(1, args.frame_step) / fps)
    _say(f"    {walk_gif}: {len(files)} frames, {walk_gif.stat().st_size / 1e6:.2f} MB")
    t1 = time.perf_counter()
    # Close-ups in lane order (the scene's creatures), then any other rig.
    order = {name: i for i, name in enumerate(examples.CREATURE_NAMES.values())}
    in_lanes = sorted(rigs, key=lambda o: order.get(o.name, len(order)))
    kinds = {str(o.get("procloco_kind", o.name)): o for o in in_lanes}
    _say(f"4/4 close-ups of {len(kinds)} creatures at frames {' '.join(map(str, args.close_up_frames))}")
    close_ups = examples.render_contact_sheet(scene, kinds, out / "creatures.png", tile=(320, 200),
                                              frames=args.close_up_frames)
    _say(f"    {close_ups} ({time.perf_counter() - t1:.1f} s)")
    saved = out / "examples_generated.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(saved), copy=True)
    _say(f"saved {saved}")
    if args.update_docs:
        docs = ROOT / "docs" / "images"
        # The README's overview: six of the frames, three to a row.
        cli.contact_sheet(files, docs / "example_contact_sheet.png", columns=3, max_tiles=6)
        shutil.copyfile(close_ups, docs / "example_creatures.png")
        shutil.copyfile(walk_gif, docs / "example_walk.gif")
        _say("updated docs/images/example_walk.gif, example_contact_sheet.png and example_creatures.png")
    _say(f"done in {time.perf_counter() - t0:.1f} s; results in {out}")
    return 0


def crowd_main(args: argparse.Namespace) -> int:
    """``--crowd``: build (when missing), generate and render the crowd example."""
    t0 = time.perf_counter()
    blend = args.blend or ROOT / "examples_crowd.blend"
    out = (args.out or ROOT / "out" / "example_crowd").resolve()
    if not blend.exists():
        _say(f"{blend.name} is missing: building it with tools/build_crowd_example.py")
        importlib.import_module("tools.build_crowd_example").build(blend)
        bpy.ops.wm.read_homefile(use_empty=True)
    package = enable_extension()
    _say(f"enabled {package} (Blender {bpy.app.version_string})")
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    cli = importlib.import_module(f"{package}.procloco_addon.blender.cli")
    if args.info:
        return int(cli.main(["info"]))
    scene = bpy.context.scene
    names = args.rig or sorted(o.name for o in scene.objects if o.type == "ARMATURE")
    command = ["generate", *([x for name in names for x in ("--rig", name)] if args.rig else ["--all"])]
    span = f"frames {scene.frame_start}-{scene.frame_end}"
    _say(f"1/3 procloco {' '.join(command)}   ({len(names)} rigs, {span})")
    status = int(cli.main(command))
    if status:
        return status
    generate_s = time.perf_counter() - t0
    _say(f"    generated {len(names)} rigs in {generate_s:.1f} s")
    t1 = time.perf_counter()
    frames = range(scene.frame_start, scene.frame_end + 1, max(1, args.frame_step))
    _say(f"2/3 rendering {len(frames)} frames ({args.resolution[0]}x{args.resolution[1]}, Workbench)")
    files = cli.render_frames(scene, out / "frames", frames, tuple(args.resolution))
    sheet = cli.contact_sheet(files, out / "contact_sheet.png")
    fps = scene.render.fps / scene.render.fps_base
    walk_gif = cli.animated_gif(files, out / "walk.gif", max(1, args.frame_step) / fps)
    size_mb = walk_gif.stat().st_size / 1e6
    _say(f"    {sheet}, {walk_gif} ({size_mb:.2f} MB) in {time.perf_counter() - t1:.1f} s")
    still_frame = scene.frame_start + int(0.6 * (scene.frame_end - scene.frame_start))
    _say(f"3/3 the crossing at frame {still_frame} at twice the resolution")
    big = (2 * args.resolution[0], 2 * args.resolution[1])
    still = cli.render_frames(scene, out / "still", [still_frame], big)[0]
    shutil.copyfile(still, out / "crowd.png")
    saved = out / "examples_crowd_generated.blend"
    bpy.context.preferences.filepaths.save_version = 0  # no .blend1 beside it
    bpy.ops.wm.save_as_mainfile(filepath=str(saved), copy=True)
    _say(f"saved {saved}")
    if args.update_docs:
        docs = ROOT / "docs" / "images"
        shutil.copyfile(out / "crowd.png", docs / "example_crowd.png")
        shutil.copyfile(walk_gif, docs / "example_crowd.gif")
        _say("updated docs/images/example_crowd.png and example_crowd.gif")
    _say(f"done in {time.perf_counter() - t0:.1f} s (generate {generate_s:.1f} s); results in {out}")
    return 0


if __name__ == "__main__":
    from tools.bpy_exit import exit_process

    exit_process(main())
