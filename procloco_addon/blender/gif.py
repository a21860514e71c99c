# SPDX-License-Identifier: GPL-3.0-or-later
"""Animated GIF files from rendered frames, with numpy alone (no imaging library).

Blender cannot write animated GIFs or WebPs, and ProcLoco depends on nothing beyond what
Blender ships, so this is a small GIF89a writer: one palette of 255 colours chosen from all
frames (the most used colours at 5 bits per channel), every pixel mapped to its nearest
palette colour, and each frame after the first stored as the rectangle that changed, with
the pixels that did not change transparent (they show the frame below), LZW-compressed as
the format requires. Workbench renders of walking creatures compress to a few kilobytes per
frame this way, since the camera and most of the scene stand still.

Shapes: ``frames`` is ``(n, h, w, 3)`` or ``(n, h, w, 4)`` floats in 0..1 with row 0 at the
top (as a viewer shows it).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["encode_gif", "lzw_encode", "palette_of", "write_gif"]

#: The palette index kept for "unchanged since the frame before" (transparent).
TRANSPARENT = 255


def palette_of(frames: np.ndarray, colours: int = 255) -> tuple[np.ndarray, np.ndarray]:
    """A palette ``(colours, 3)`` uint8 for ``frames`` ``(n, h, w, 3)`` uint8, and the lookup
    ``(32768,)`` uint8 from a pixel's 5-bit-per-channel bin to its nearest palette index."""
    bins = _bins(frames)
    count = np.bincount(bins.ravel(), minlength=32768)
    used = np.flatnonzero(count)
    top = used[np.argsort(-count[used], kind="stable")[:colours]]
    palette = _bin_colour(top)
    # Every bin to its nearest palette colour (32768 x <= 255 distances, in slices).
    every = _bin_colour(np.arange(32768)).astype(np.int32)
    lookup = np.empty(32768, dtype=np.uint8)
    pal = palette.astype(np.int32)
    for start in range(0, 32768, 4096):
        d = ((every[start:start + 4096, None, :] - pal[None]) ** 2).sum(axis=2)
        lookup[start:start + 4096] = np.argmin(d, axis=1)
    return palette, lookup


def _bins(rgb: np.ndarray) -> np.ndarray:
    q = rgb.astype(np.int32) >> 3
    return (q[..., 0] << 10) | (q[..., 1] << 5) | q[..., 2]


def _bin_colour(bins: np.ndarray) -> np.ndarray:
    """The centre colour ``(k, 3)`` uint8 of 5-bit bins ``(k,)``."""
    q = np.stack([(bins >> 10) & 31, (bins >> 5) & 31, bins & 31], axis=-1)
    return (q * 8 + 4).astype(np.uint8)


def lzw_encode(indices: np.ndarray, min_code_size: int = 8) -> bytes:
    """GIF's LZW compression of ``indices`` ``(k,)`` uint8 palette indices: the image data
    bytes (without the minimum code size byte and the sub-block framing)."""
    clear = 1 << min_code_size
    stop = clear + 1
    out = bytearray()
    bits = 0  # pending bits, least significant first
    n_bits = 0
    size = min_code_size + 1

    def emit(code: int) -> None:
        nonlocal bits, n_bits
        bits |= code << n_bits
        n_bits += size
        while n_bits >= 8:
            out.append(bits & 0xFF)
            bits >>= 8
            n_bits -= 8

    emit(clear)
    table: dict[tuple[int, int], int] = {}
    next_code = stop + 1
    data = indices.tolist()
    if not data:
        emit(stop)
        if n_bits:
            out.append(bits & 0xFF)
        return bytes(out)
    prefix = data[0]
    for value in data[1:]:
        key = (prefix, value)
        code = table.get(key)
        if code is not None:
            prefix = code
            continue
        emit(prefix)
        if next_code < 4096:
            table[key] = next_code
            next_code += 1
            # The decoder widens its codes one code later than the encoder adds them.
            if next_code > (1 << size) and size < 12:
                size += 1
        else:
            emit(clear)
            table.clear()
            next_code = stop + 1
            size = min_code_size + 1
        prefix = value
    emit(prefix)
    emit(stop)
    if n_bits:
        out.append(bits & 0xFF)
    return bytes(out)


def _sub_blocks(data: bytes) -> bytes:
    parts = [bytes([len(data[i:i + 255])]) + data[i:i + 255] for i in range(0, len(data), 255)]
    return b"".join(parts) + b"\x00"


def encode_gif(frames: np.ndarray, delay_s: float, loop: bool = True) -> bytes:
    """The bytes of an animated GIF showing ``frames`` ``(n, h, w, 3|4)`` (floats 0..1, row 0
    at the top), each for ``delay_s`` seconds (GIF counts in hundredths), looping forever
    when ``loop``."""
    if frames.ndim != 4 or frames.shape[0] == 0 or frames.shape[-1] not in (3, 4):
        raise ValueError("frames must be (n, h, w, 3) or (n, h, w, 4) with n >= 1")
    n, h, w = frames.shape[:3]
    if not (0 < w < 65536 and 0 < h < 65536):
        raise ValueError("a GIF frame is at most 65535 pixels on a side")
    rgb = (np.clip(np.nan_to_num(frames[..., :3]), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    palette, lookup = palette_of(rgb)
    table = np.zeros((256, 3), dtype=np.uint8)
    table[: palette.shape[0]] = palette
    delay = max(1, round(delay_s * 100.0))
    out = bytearray(b"GIF89a")
    out += struct.pack("<HHBBB", w, h, 0xF7, 0, 0)  # global table of 256 colours
    out += table.tobytes()
    if loop:
        out += b"\x21\xff\x0bNETSCAPE2.0\x03\x01\x00\x00\x00"
    previous: np.ndarray | None = None
    for k in range(n):
        index = lookup[_bins(rgb[k])]
        if previous is None:
            x0, y0, x1, y1 = 0, 0, w, h
            shown = index
            flags = 0x04  # disposal: leave the frame in place
        else:
            changed = index != previous
            if changed.any():
                rows = np.flatnonzero(changed.any(axis=1))
                cols = np.flatnonzero(changed.any(axis=0))
                y0, y1, x0, x1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
            else:
                y0, y1, x0, x1 = 0, 1, 0, 1
            shown = np.where(changed, index, TRANSPARENT)[y0:y1, x0:x1]
            flags = 0x05  # leave in place, with a transparent index
        previous = index
        out += struct.pack("<BBBBHBB", 0x21, 0xF9, 4, flags, delay, TRANSPARENT, 0)
        out += struct.pack("<BHHHHB", 0x2C, x0, y0, x1 - x0, y1 - y0, 0)
        out += bytes([8]) + _sub_blocks(lzw_encode(np.ascontiguousarray(shown).ravel()))
    out += b"\x3b"
    return bytes(out)


def write_gif(frames: Sequence[np.ndarray] | np.ndarray, path: Path, delay_s: float,
              loop: bool = True) -> Path:
    """Write ``frames`` (see :func:`encode_gif`) as an animated GIF at ``path``; returns it."""
    data = encode_gif(np.asarray(frames), delay_s, loop)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    return path
