# SPDX-License-Identifier: GPL-3.0-or-later
"""Batch mode: ``blender --background scene.blend --command procloco ...``.

The same entry is callable from Python with the ``bpy`` module: ``main(argv)`` returns the
exit status. Commands::

    procloco info
        list the armatures of the scene, the legs ProcLoco finds on each and the chains
        it would swing (tails, antennae, ears)
    procloco generate --rig NAME [--rig NAME ...] | --rigs A,B,... | --all
                      [--frames START END] [--speed M_PER_S] [--heading DEG] [--step-height M]
                      [--seed N] [--spine | --no-spine] [--visual-yaw | --no-visual-yaw]
                      [--no-avoid] [--bake-secondary | --no-bake-secondary]
                      [--cycle N [--root-motion in-place|root-bone] [--root-bone NAME]]
                      [OUTPUT OPTIONS]
        generate locomotion for the rigs (settings saved on each rig, overridden by the
        options given), all of them in one simulation where they can (each keeping off
        the others, unless --no-avoid); with --bake-secondary, then bake secondary motion on every rig
        that has (or is suggested) pendulum chains; with --cycle, Make Cycle instead: a
        loop of N whole gait cycles on flat ground (cycle/make.py)
    procloco bake-secondary --rig NAME [--rig NAME ...] | --all [--frames START END]
                      [OUTPUT OPTIONS]
        bake secondary motion (Bake Secondary Motion) on the rigs' current animation; a rig
        with no chain listed gets the suggested ones first. A rig named with --rig must have
        a chain; with --all, rigs without one are skipped

    OUTPUT OPTIONS: [--render DIR] [--frame-step N] [--resolution W H] [--contact-sheet PNG]
                    [--gif GIF] [--save BLEND]
        render Workbench PNG frames of the rigs' frame range into DIR, tile them into a
        contact sheet, make them a looping animated GIF, and save the .blend (a new file:
        the opened one is left as it was)
    procloco render --frames A-B [--output PATH] [--format FORMAT]
        render a chunk of frames (1-10, 1..10, 7) of the open file with the scene's engine
        and output settings, as render farms do (see render_chunk.py)

Progress lines go to stdout (``ProcLoco: ...``); errors to stderr with a non-zero status
(1: the work failed, 2: bad command line; ``--help`` prints the usage and returns 0). Numbers
are checked on the command line (finite, in range) and never clamped silently. A command
that fails before writing anything leaves the rigs' settings as they were.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import bpy
import numpy as np

from ..core.locomotion import gait as core_gait
from . import actions, gif, render_chunk, rig
from .gait import rig_gait
from .keys.reduce import last_reduction
from .locomotion import generate
from .locomotion import property_group as locomotion_props
from .quality import measure as quality
from .secondary import bake

__all__ = ["contact_sheet", "image_pixels", "main", "register", "render_frames", "unregister"]

COMMAND = "procloco"
_handle: Any = None


class CliError(RuntimeError):
    """A failure reported to the user with exit status 1."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # argparse would sys.exit; the caller needs a status
        raise _UsageError(f"{self.prog}: error: {message}")

    def exit(self, status: int = 0, message: str | None = None) -> Any:  # --help: a status, no SystemExit
        if message:
            print(message, file=sys.stderr if status else sys.stdout, end="", flush=True)
        raise _Exit(status)


class _UsageError(Exception):
    pass


class _Exit(Exception):  # noqa: N818 - argparse's exit, as a status
    def __init__(self, status: int) -> None:
        super().__init__(status)
        self.status = status


_INT_MAX = 2**31 - 1


def _number(kind: str, low: float | None = None, high: float | None = None) -> Any:
    """An argparse type: a finite float (``kind`` "float") or an int within ``[low, high]``."""

    def parse(text: str) -> float | int:
        try:
            value: float | int = int(text) if kind == "int" else float(text)
        except ValueError:
            what = "an integer" if kind == "int" else "a number"
            raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if low is not None and value < low:
            raise argparse.ArgumentTypeError(f"{text} is below {low:g}")
        if high is not None and value > high:
            raise argparse.ArgumentTypeError(f"{text} is above {high:g}")
        return value

    parse.__name__ = kind  # argparse names the type in its messages
    return parse


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=COMMAND, description="ProcLoco batch mode")
    rigs = _Parser(add_help=False)
    rigs.add_argument("--rig", action="append", default=[], metavar="NAME",
                      help="armature to animate (repeatable)")
    rigs.add_argument("--all", action="store_true", help="every armature of the scene")
    rigs.add_argument("--rigs", metavar="A,B,...",
                      help="armatures as one comma-separated list, '*' for all (for job templates)")
    rigs.add_argument("--frames", nargs=2, type=_number("int", -1_048_574, 1_048_574),
                      metavar=("START", "END"), help="frame range")
    output = _Parser(add_help=False)
    output.add_argument("--render", metavar="DIR", help="render Workbench PNG frames into DIR")
    output.add_argument("--frame-step", type=_number("int", 1, _INT_MAX), default=1,
                        help="render every N-th frame")
    output.add_argument("--resolution", nargs=2, type=_number("int", 4, 16384), default=(640, 360),
                        metavar=("W", "H"))
    output.add_argument("--contact-sheet", metavar="PNG", help="tile rendered frames into one image")
    output.add_argument("--gif", metavar="GIF", help="make the rendered frames a looping animated GIF")
    output.add_argument("--save", metavar="BLEND", help="save the .blend file there")
    keys = _Parser(add_help=False)
    keys.add_argument("--key-reduction", action=argparse.BooleanOptionalAction, default=None,
                      help="keep keys only where needed, Bezier handles fitted (Generate > Key Reduction)")
    keys.add_argument("--foot-tolerance", type=_number("float", 1e-6), metavar="METRES",
                      help="Key Reduction: how far a foot may move from the key-per-frame result")
    keys.add_argument("--angle-tolerance", type=_number("float", 1e-4, 180.0), metavar="DEGREES",
                      help="Key Reduction: how far any other bone may turn from it")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    sub.add_parser("info", help="list armatures, their detected legs and their swinging chains")
    gen = sub.add_parser("generate", parents=[rigs, output, keys],
                         help="generate locomotion (and bake secondary motion, render a preview)")
    gen.add_argument("--speed", type=_number("float", 0.0), help="speed in metres per second")
    gen.add_argument("--heading", type=_number("float", -1e6, 1e6),
                     help="heading in degrees relative to where the rig faces")
    gen.add_argument("--step-height", type=_number("float", 0.0), help="step height in metres")
    gen.add_argument("--seed", type=_number("int", 0, _INT_MAX), help="random seed")
    gen.add_argument("--gait", metavar="auto|circles|PRESET",
                     help="Gait: auto (follows the speed), circles, or a gait preset (file stem or name)")
    gen.add_argument("--spine", action=argparse.BooleanOptionalAction, default=None,
                     help="flexible spine on or off (Effects > Flexible Spine)")
    gen.add_argument("--visual-yaw", action=argparse.BooleanOptionalAction, default=None,
                     help="the body sways with the feet, lizard-like (Effects > Visual Yaw)")
    gen.add_argument("--no-avoid", action="store_true",
                     help="the rigs walk through each other (Generate > Crowd > Avoid Other Rigs off)")
    gen.add_argument("--bake-secondary", action=argparse.BooleanOptionalAction, default=False,
                     help="then bake secondary motion on the rigs that have (or are suggested) chains")
    gen.add_argument("--cycle", type=_number("int", 1, 64), metavar="N",
                     help="Make Cycle: a loop of N whole gait cycles on flat ground instead of the walk")
    gen.add_argument("--root-motion", choices=("in-place", "root-bone"),
                     help="with --cycle: walk in place, or carry the root motion on the root bone")
    gen.add_argument("--root-bone", metavar="NAME", help="with --cycle --root-motion root-bone: the bone")
    sub.add_parser("bake-secondary", parents=[rigs, output, keys],
                   help="bake secondary motion (tails, antennae, ears) on the rigs' current animation")
    render_chunk.add_parser(sub)
    return parser


def _say(text: str) -> None:
    print(f"ProcLoco: {text}", flush=True)


def _context() -> Any:
    return bpy.context


def _cmd_info(_args: argparse.Namespace) -> int:
    scene = bpy.context.scene
    arms = sorted((o for o in scene.objects if o.type == "ARMATURE"), key=lambda o: o.name)
    if not arms:
        _say(f"scene '{scene.name}' has no armature")
        return 0
    for obj in arms:
        try:
            legs = rig.detect_legs(obj)
            desc = ", ".join(f"{leg.label}: {leg.hip} > {leg.end}" for leg in legs)
            _say(f"{obj.name}: {len(legs)} legs ({desc})")
        except rig.RigError as err:
            _say(f"{obj.name}: {err}")
        listed = [c.name for c in obj.procloco_secondary.chains]
        if listed:
            _say(f"{obj.name}: secondary chains {', '.join(listed)}")
        else:
            found = [c.label for c in bake.suggest_chains(obj)]
            _say(f"{obj.name}: " + (f"suggested secondary chains {', '.join(found)}" if found
                                    else "no tail, antenna or ear chain"))
    return 0


def _group_values(group: Any) -> dict[str, Any]:
    """Every writable property of a property group, its collections' items included."""
    out: dict[str, Any] = {}
    for prop in group.bl_rna.properties:
        name = prop.identifier
        if name == "rna_type":
            continue
        value = getattr(group, name)
        if prop.type == "COLLECTION":
            out[name] = [_group_values(item) for item in value]
        elif prop.type == "POINTER" and isinstance(value, bpy.types.PropertyGroup):
            out[name] = _group_values(value)
        elif not prop.is_readonly:
            out[name] = tuple(value) if getattr(prop, "array_length", 0) else value
    return out


def _set_group_values(group: Any, values: dict[str, Any]) -> None:
    for name, value in values.items():
        prop = group.bl_rna.properties[name]
        if prop.type == "COLLECTION":
            items = getattr(group, name)
            items.clear()
            for item_values in value:
                _set_group_values(items.add(), item_values)
        elif prop.type == "POINTER" and isinstance(value, dict):
            _set_group_values(getattr(group, name), value)
        else:
            setattr(group, name, value)


def _saved_settings(objs: Sequence[Any], args: argparse.Namespace) -> list[tuple[Any, dict[str, Any]]]:
    """Each rig's settings as they are now, all of them (an override such as --gait also
    fills the legs list), and its Key Reduction settings when an option changes them (Blender
    4.2 stores a property group in the object once it is read): see :func:`_put_back`."""
    attrs = ("procloco", "procloco_keys") if _changes_key_reduction(args) else ("procloco",)
    return [(obj, {attr: _group_values(getattr(obj, attr)) for attr in attrs}) for obj in objs]


def _changes_key_reduction(args: argparse.Namespace) -> bool:
    return any(getattr(args, name, None) is not None
               for name in ("key_reduction", "foot_tolerance", "angle_tolerance"))


def _put_back(saved: list[tuple[Any, dict[str, Any]]]) -> None:
    for obj, groups in saved:
        for attr, values in groups.items():
            _set_group_values(getattr(obj, attr), values)


def _apply_key_reduction(obj: Any, args: argparse.Namespace) -> None:
    """``--key-reduction``, ``--foot-tolerance`` and ``--angle-tolerance`` on the rig's Key
    Reduction settings (saved with ``--save``)."""
    if not _changes_key_reduction(args):
        return
    s = obj.procloco_keys
    if args.key_reduction is not None:
        s.use_key_reduction = bool(args.key_reduction)
    if args.foot_tolerance is not None:
        s.foot_tolerance = float(args.foot_tolerance)
    if args.angle_tolerance is not None:
        s.angle_tolerance = math.radians(float(args.angle_tolerance))


def _say_key_reduction(obj: Any) -> None:
    reduced = last_reduction(obj)
    if reduced is not None:
        _say(f"{obj.name}: {reduced.describe()}")


def _apply_overrides(obj: Any, args: argparse.Namespace) -> None:
    s = obj.procloco
    _set_frames(obj, args)
    _apply_key_reduction(obj, args)
    # The gait first: a preset sets its own speed, which an explicit --speed then overrides.
    if args.gait is not None:
        try:
            if args.gait.lower() not in ("auto", "circles") and not len(s.legs):
                core_gait.find_gait_preset(args.gait)  # an unknown preset changes nothing
                generate.detect_into_settings(obj)  # a preset is set on the legs
            rig_gait.choose_gait(obj, args.gait)
        except (core_gait.GaitError, rig.RigError) as err:
            raise CliError(f"--gait {args.gait} for {obj.name}: {err}") from err
    if args.speed is not None:
        s.speed = float(args.speed)
    if args.heading is not None:
        s.heading = math.radians(float(args.heading))
    if args.step_height is not None:
        s.step_height = float(args.step_height)
    if args.seed is not None:
        s.seed = int(args.seed)
    if args.spine is not None:
        s.use_spine = bool(args.spine)
    if args.visual_yaw is not None:
        s.use_visual_yaw = bool(args.visual_yaw)
    if getattr(args, "no_avoid", False):
        s.use_avoid_others = False


def _set_frames(obj: Any, args: argparse.Namespace) -> None:
    if args.frames is not None:
        s = obj.procloco
        s.use_scene_range = False
        s.frame_start, s.frame_end = int(args.frames[0]), int(args.frames[1])


def _rigs_of(args: argparse.Namespace, what: str) -> list[Any]:
    scene = bpy.context.scene
    arms = {o.name: o for o in scene.objects if o.type == "ARMATURE"}
    listed = [n.strip() for n in (args.rigs or "").split(",") if n.strip()]
    if listed == ["*"]:
        args.all = True  # the same as --all everywhere (bake-secondary then skips rigs without chains)
        listed = []
    names = sorted(arms) if args.all else [*args.rig, *listed]
    if not names:
        known = f"; armatures: {', '.join(sorted(arms))}" if arms else "; the scene has no armature"
        raise CliError(f"say which rigs to {what}: --rig NAME (repeatable), --rigs A,B or --all" + known)
    missing = [n for n in names if n not in arms]
    if missing:
        raise CliError(f"no armature named {', '.join(repr(n) for n in missing)} in scene '{scene.name}'"
                       + (f" (armatures: {', '.join(sorted(arms))})" if arms else " (it has no armature)"))
    return [arms[n] for n in names]


def _progress_printer() -> Any:
    last: dict[str, int] = {}

    def progress(name: str, fraction: float) -> None:
        tenth = int(10 * fraction)
        if last.get(name) != tenth:
            last[name] = tenth
            _say(f"  {name}: {int(100 * fraction)}%")

    return progress


def _bake_jobs(objs: Sequence[Any], required: bool, quiet: bool = False) -> list[bake.Job]:
    """Check the secondary-motion bake of each rig (a rig with no chain listed gets the
    suggested ones); returns the prepared jobs. Rigs without any chain are an error when
    ``required``, else skipped. On an error the suggested chains are taken back."""
    context = bpy.context
    suggested: list[Any] = []
    jobs: list[bake.Job] = []
    try:
        for obj in objs:
            chains = obj.procloco_secondary.chains
            if not len(chains):
                found = bake.suggest_into_settings(obj)
                if found:
                    suggested.append(obj)
                    if not quiet:
                        _say(f"{obj.name}: suggested chains {', '.join(c.label for c in found)}")
            if not len(chains):
                if required:
                    raise CliError(f"'{obj.name}' has no tail, antenna or ear chain to swing: add one in "
                                   "the Secondary Motion panel")
                if not quiet:
                    _say(f"{obj.name}: no chain for secondary motion, not baked")
                continue
            jobs.append(bake.prepare(context, obj))
    except bake.BakeError as err:
        for obj in suggested:
            obj.procloco_secondary.chains.clear()
        raise CliError(str(err)) from err
    except CliError:
        for obj in suggested:
            obj.procloco_secondary.chains.clear()
        raise
    return jobs


def _run_bakes(jobs: Sequence[bake.Job]) -> None:
    context = bpy.context
    progress = _progress_printer()
    for job in jobs:
        try:
            for fraction in bake.sample(context, job):
                progress(job.obj_name, fraction)
            action = bake.write(context, job)
        except (bake.BakeError, actions.ActionError) as err:
            raise CliError(str(err)) from err
        for warning in job.warnings:
            _say(f"{job.obj_name}: warning: {warning}")
        _say(f"{job.obj_name}: baked {len(job.bones)} swinging bones into Action '{action.name}'")
        _say_key_reduction(bpy.data.objects[job.obj_name])


def _outputs(objs: Sequence[Any], args: argparse.Namespace) -> None:
    scene = bpy.context.scene
    if args.render:
        start, end = locomotion_props.frame_range(objs[0].procloco, scene)
        files = render_frames(scene, Path(args.render), range(start, end + 1, max(1, args.frame_step)),
                              tuple(args.resolution), focus=objs)
        _say(f"rendered {len(files)} frames into {args.render}")
        if args.contact_sheet:
            contact_sheet(files, Path(args.contact_sheet))
            _say(f"contact sheet {args.contact_sheet}")
        if args.gif:
            fps = scene.render.fps / scene.render.fps_base
            animated_gif(files, Path(args.gif), max(1, args.frame_step) / fps)
            _say(f"animated GIF {args.gif}")
    elif args.contact_sheet or args.gif:
        raise CliError("--contact-sheet and --gif need --render DIR")
    if args.save:
        path = str(Path(args.save).resolve())
        Path(path).parent.mkdir(parents=True, exist_ok=True)  # a farm's output folder may be new
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=False)
        _say(f"saved {path}")


def _cmd_generate(args: argparse.Namespace) -> int:
    objs = _rigs_of(args, "animate")
    if (args.contact_sheet or args.gif) and not args.render:
        raise CliError("--contact-sheet and --gif need --render DIR")
    if args.cycle is not None and args.bake_secondary:
        raise CliError("--cycle and --bake-secondary do not go together: a bake on a loop would not loop")
    if args.cycle is None and (args.root_motion is not None or args.root_bone is not None):
        raise CliError("--root-motion and --root-bone go with --cycle N")
    saved = _saved_settings(objs, args)
    unset = [o for o in objs if not len(o.procloco_secondary.chains)]
    cycle_saved = [(o, _group_values(o.procloco_cycle)) for o in objs]
    try:
        for obj in objs:
            _apply_overrides(obj, args)
        if args.bake_secondary:
            _bake_jobs(objs, required=False)  # refuse bad chains before anything is written
        if args.cycle is not None:
            made: list[Any] | None = _make_cycles(objs, args)
        else:
            _say(f"generating {', '.join(o.name for o in objs)}")
            made = generate.generate(bpy.context, objs, progress=_progress_printer(), measure=True)
    except BaseException as err:
        # Nothing was written: the overrides and the chains suggested above are taken back.
        for obj in unset:
            obj.procloco_secondary.chains.clear()
        _put_back(saved)
        for obj, values in cycle_saved:
            _set_group_values(obj.procloco_cycle, values)
        if isinstance(err, generate.GenerateError | rig.RigError):
            raise CliError(str(err)) from err
        raise
    assert made is not None
    for obj, action in zip(objs, made, strict=True):
        _say(f"{obj.name}: wrote Action '{action.name}'")
        _say_key_reduction(obj)
        if args.cycle is None:  # (a loop is not measured: an in-place loop's feet slide by design)
            _say(quality.summary_line(obj))
    if args.bake_secondary:
        _run_bakes(_bake_jobs(objs, required=False, quiet=True))
    _outputs(objs, args)
    return 0


def _make_cycles(objs: Sequence[Any], args: argparse.Namespace) -> list[Any]:
    """``generate --cycle N``: Make Cycle on every rig; prints each loop's summary."""
    from .cycle import make

    for obj in objs:
        settings = obj.procloco_cycle
        settings.cycles = int(args.cycle)
        if args.root_motion is not None:
            settings.root_motion = "ROOT_BONE" if args.root_motion == "root-bone" else "IN_PLACE"
        if args.root_bone is not None:
            settings.root_bone = args.root_bone
    _say(f"making {args.cycle}-cycle loops of {', '.join(o.name for o in objs)}")
    printer = _progress_printer()
    jobs = make.make_cycles(bpy.context, objs, progress=lambda text, fraction: printer(text, fraction))
    for cj in jobs:
        _say(f"{cj.obj_name}: {cj.summary()}")
    return [cj.action for cj in jobs]


def _cmd_bake_secondary(args: argparse.Namespace) -> int:
    objs = _rigs_of(args, "bake")
    if (args.contact_sheet or args.gif) and not args.render:
        raise CliError("--contact-sheet and --gif need --render DIR")
    saved = _saved_settings(objs, args)
    try:
        for obj in objs:
            _set_frames(obj, args)
            _apply_key_reduction(obj, args)
        jobs = _bake_jobs(objs, required=not args.all)
    except BaseException:
        _put_back(saved)
        raise
    _say(f"baking secondary motion on {', '.join(j.obj_name for j in jobs) or 'no rig'}")
    _run_bakes(jobs)
    _outputs(objs, args)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ProcLoco command; returns the exit status (0 success, 1 failure, 2 usage)."""
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        args = _parser().parse_args(list(argv))
    except _UsageError as err:
        print(str(err), file=sys.stderr, flush=True)
        return 2
    except _Exit as done:
        return done.status
    try:
        if args.command == "info":
            return _cmd_info(args)
        if args.command == "bake-secondary":
            return _cmd_bake_secondary(args)
        if args.command == "render":
            return render_chunk.run(args)  # its RenderError is a RuntimeError: status 1
        return _cmd_generate(args)
    except (CliError, OSError, RuntimeError) as err:
        print(f"{COMMAND}: error: {err}", file=sys.stderr, flush=True)
        return 1
    except Exception as err:
        print(f"{COMMAND}: error: ProcLoco failed ({type(err).__name__}: {err})", file=sys.stderr, flush=True)
        return 1


# ---------------------------------------------------------------------------------------
# Rendering


def _look_at(location: np.ndarray, target: np.ndarray) -> tuple[float, float, float]:
    """Euler XYZ rotation of a camera at ``location`` looking at ``target`` (Z up)."""
    d = target - location
    yaw = math.atan2(d[1], d[0]) - math.pi / 2
    pitch = math.atan2(math.hypot(d[0], d[1]), -d[2])
    return (pitch, 0.0, yaw)


def _focus_points(objs: Sequence[Any], frames: Sequence[int]) -> np.ndarray:
    scene = bpy.context.scene
    pts: list[np.ndarray] = []
    old = scene.frame_current
    for frame in (frames[0], frames[len(frames) // 2], frames[-1]):
        scene.frame_set(frame)
        for obj in objs:
            m = np.array(obj.matrix_world)
            pts.extend(m[:3, :3] @ np.array(pb.head) + m[:3, 3] for pb in obj.pose.bones)
    scene.frame_set(old)
    return np.array(pts) if pts else np.zeros((1, 3))


def render_frames(
    scene: Any,
    out_dir: Path,
    frames: Sequence[int],
    resolution: tuple[int, int] = (640, 360),
    focus: Sequence[Any] = (),
) -> list[Path]:
    """Render ``frames`` with Workbench into ``out_dir/frame_####.png``; returns the files.

    Uses the scene camera, or a temporary camera framing ``focus`` objects over the range.
    The scene's render settings are restored afterwards.
    """
    frames = list(frames)
    out_dir.mkdir(parents=True, exist_ok=True)
    r = scene.render
    saved = (r.engine, r.filepath, r.resolution_x, r.resolution_y, r.resolution_percentage,
             r.image_settings.file_format, scene.camera, scene.frame_current)
    temp_cam = None
    try:
        r.engine = "BLENDER_WORKBENCH"
        r.resolution_x, r.resolution_y = int(resolution[0]), int(resolution[1])
        r.resolution_percentage = 100
        r.image_settings.file_format = "PNG"
        if scene.camera is None:
            pts = _focus_points(focus, frames) if focus else np.zeros((1, 3))
            center = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
            size = float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]), np.ptp(pts[:, 2]), 0.1))
            data = bpy.data.cameras.new("ProcLoco Preview")
            temp_cam = bpy.data.objects.new("ProcLoco Preview", data)
            scene.collection.objects.link(temp_cam)
            loc = center + np.array([1.2, -1.6, 0.9]) * size * 1.3
            temp_cam.location = tuple(loc)
            temp_cam.rotation_euler = _look_at(loc, center)
            scene.camera = temp_cam
        files = []
        for i, frame in enumerate(frames):
            scene.frame_set(int(frame))
            path = out_dir / f"frame_{int(frame):04d}.png"
            r.filepath = str(path)
            bpy.ops.render.render(write_still=True)
            files.append(path)
            if i % max(1, len(frames) // 10) == 0:
                _say(f"  rendered frame {frame} ({i + 1}/{len(frames)})")
        return files
    finally:
        (r.engine, r.filepath, r.resolution_x, r.resolution_y, r.resolution_percentage,
         r.image_settings.file_format, scene.camera, frame) = saved
        scene.frame_set(frame)
        if temp_cam is not None:
            data = temp_cam.data
            bpy.data.objects.remove(temp_cam)
            bpy.data.cameras.remove(data)


def image_pixels(path: Path) -> np.ndarray:
    """The RGBA pixels ``(h, w, 4)`` of the image file at ``path`` (row 0 at the bottom),
    read through Blender."""
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)


def animated_gif(files: Sequence[Path], out: Path, delay_s: float) -> Path:
    """The rendered frames ``files`` as a looping animated GIF at ``out``, each shown for
    ``delay_s`` seconds (see :mod:`.gif`)."""
    if not files:
        raise CliError("no frames to make an animated GIF of")
    frames = [image_pixels(f)[::-1] for f in files]  # rows top-down, as a viewer shows them
    if len({f.shape for f in frames}) != 1:
        raise CliError("frames of an animated GIF must have one size")
    return gif.write_gif(np.stack(frames), out, delay_s)


def contact_sheet(files: Sequence[Path], out: Path, columns: int = 4, max_tiles: int = 12) -> Path:
    """Tile up to ``max_tiles`` evenly spaced images of ``files`` into one PNG at ``out``."""
    if not files:
        raise CliError("no frames to tile into a contact sheet")
    idx = np.unique(np.linspace(0, len(files) - 1, min(max_tiles, len(files))).round().astype(int))
    tiles = []
    size = None
    for k in idx:
        tile = image_pixels(files[k])
        h, w = tile.shape[:2]
        if size is None:
            size = (w, h)
        if (w, h) != size:
            raise CliError("frames of a contact sheet must have one size")
        tiles.append(tile)
    assert size is not None
    w, h = size
    cols = min(columns, len(tiles))
    rows = math.ceil(len(tiles) / cols)
    sheet = np.ones((rows * h, cols * w, 4), dtype=np.float32)
    for n, tile in enumerate(tiles):
        r, c = divmod(n, cols)
        # Image rows are stored bottom-up: the first tile goes at the top of the sheet.
        y0 = (rows - 1 - r) * h
        sheet[y0:y0 + h, c * w:(c + 1) * w] = tile
    out.parent.mkdir(parents=True, exist_ok=True)
    img = bpy.data.images.new("ProcLoco contact sheet", cols * w, rows * h, alpha=True)
    try:
        img.pixels.foreach_set(sheet.ravel())
        img.filepath_raw = str(out)
        img.file_format = "PNG"
        img.save()
    finally:
        bpy.data.images.remove(img)
    return out


# ---------------------------------------------------------------------------------------
# Registration


def _execute(argv: list[str]) -> int:
    return main(argv)


def register() -> None:
    global _handle
    if _handle is None and hasattr(bpy.utils, "register_cli_command"):
        _handle = bpy.utils.register_cli_command(COMMAND, _execute)


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
