# SPDX-License-Identifier: GPL-3.0-or-later
"""``procloco render --frames A-B``: render a chunk of frames of the open .blend.

Render farms split a shot into chunks of frames and name a chunk ``1-10`` (Flamenco, Open
Job Description's ``CHUNK[INT]`` task parameters), while Blender's own ``--render-frame``
wants ``1..10``. This command takes either spelling, then renders exactly like
``--render-frame``: the scene's engine, camera, resolution, samples and output settings,
through ``bpy.ops.render.render(animation=True)``, which writes each frame to the scene's
output path (``#`` replaced by the frame number) and prints Blender's ``Saved: '...'``
lines that farm software reads. Nothing of the file is saved; the settings changed for
the render are put back.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator, Sequence
from typing import Any

import bpy

__all__ = ["RenderError", "add_parser", "frame_runs", "parse_frames", "run"]

# Formats that write one movie instead of one image a frame: chunks cannot be joined.
_MOVIE_FORMATS = ("FFMPEG", "AVI_JPEG", "AVI_RAW")
_PART = re.compile(r"\s*(-?\d+)\s*(?:\.\.|-)\s*(-?\d+)\s*|\s*(-?\d+)\s*")


class RenderError(RuntimeError):
    """A render refused or failed; the message is meant for the user (exit status 1)."""


def parse_frames(text: str) -> list[int]:
    """Frames of ``text``: ``"1-10"``, ``"1..10"``, ``"7"`` or comma-separated parts of
    those (``"1-3,8"``); sorted, each once. Raises :class:`RenderError` on bad text."""
    frames: set[int] = set()
    for part in text.split(","):
        match = _PART.fullmatch(part)
        if match is None:
            raise RenderError(f"bad frame range {text!r}: write START-END, START..END or one frame "
                              "(parts separated by commas)")
        if match.group(3) is not None:
            frames.add(int(match.group(3)))
            continue
        start, end = int(match.group(1)), int(match.group(2))
        if start > end:
            raise RenderError(f"frame range {part.strip()!r} is reversed: the first frame comes first")
        frames.update(range(start, end + 1))
    return sorted(frames)


def frame_runs(frames: Sequence[int]) -> Iterator[tuple[int, int]]:
    """Consecutive runs ``(first, last)`` of sorted, distinct ``frames``."""
    if not frames:
        return
    first = prev = frames[0]
    for frame in frames[1:]:
        if frame != prev + 1:
            yield first, prev
            first = frame
        prev = frame
    yield first, prev


def add_parser(sub: Any) -> None:
    """Add the ``render`` command to the batch command's subparsers ``sub``."""
    cmd = sub.add_parser("render", help="render a chunk of frames of the open file with the scene's engine")
    cmd.add_argument("--frames", required=True, metavar="A-B",
                     help="frames to render: 1-10, 1..10, 7 or parts separated by commas")
    cmd.add_argument("--output", metavar="PATH",
                     help="output path instead of the scene's (# for the frame number, "
                          "// for the .blend's folder)")
    cmd.add_argument("--format", metavar="FORMAT",
                     help="image format instead of the scene's (PNG, OPEN_EXR, JPEG, ...)")


def _say(text: str) -> None:
    print(f"ProcLoco: {text}", flush=True)


def run(args: argparse.Namespace) -> int:
    """Render ``args.frames`` of the current scene; returns 0 or raises :class:`RenderError`."""
    frames = parse_frames(args.frames)
    if frames[0] < 0:  # a scene's frame range, through which frames are rendered, starts at 0
        raise RenderError(f"frames {args.frames!r}: negative frames cannot be rendered by this command")
    scene = bpy.context.scene
    r = scene.render
    if scene.camera is None:
        raise RenderError(f"scene '{scene.name}' has no camera to render from")
    formats = [item.identifier for item in r.image_settings.bl_rna.properties["file_format"].enum_items]
    if args.format is not None and args.format not in formats:
        raise RenderError(f"unknown image format {args.format!r} (this Blender has {', '.join(formats)})")
    fmt = args.format if args.format is not None else r.image_settings.file_format
    if fmt in _MOVIE_FORMATS:
        raise RenderError(f"the output format is {fmt}, a movie: render chunks as images "
                          "(--format PNG, OPEN_EXR, ...) and join them afterwards")
    saved = (scene.frame_start, scene.frame_end, scene.frame_step, scene.frame_current, r.filepath,
             r.image_settings.file_format)
    try:
        if args.output is not None:
            r.filepath = args.output
        r.image_settings.file_format = fmt
        _say(f"rendering frames {args.frames} of scene '{scene.name}' with {r.engine} "
             f"into {bpy.path.abspath(r.filepath)}")
        scene.frame_step = 1
        for first, last in frame_runs(frames):
            # frame_end first: a run may lie after the scene's range (start <= end is kept).
            if first > scene.frame_end:
                scene.frame_end, scene.frame_start = last, first
            else:
                scene.frame_start, scene.frame_end = first, last
            bpy.ops.render.render(animation=True)
            # (a frame Blender cannot write raises RuntimeError here: exit status 1)
        _say(f"rendered {len(frames)} frame{'' if len(frames) == 1 else 's'}")
        return 0
    finally:
        (scene.frame_start, scene.frame_end, scene.frame_step, frame, r.filepath,
         r.image_settings.file_format) = saved
        scene.frame_set(frame)
