# SPDX-License-Identifier: GPL-3.0-or-later
"""blender/gif.py: the animated GIFs written from rendered frames decode, by a decoder
written here from the GIF89a specification, to the frames given (to the palette's 5-bit
precision), with their delays, looping, and only the changed rectangle stored."""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from procloco_addon.blender.gif import encode_gif, lzw_encode


def _lzw_decode(data: bytes, min_code_size: int) -> list[int]:
    clear, stop = 1 << min_code_size, (1 << min_code_size) + 1
    pos = 0  # bit position
    size = min_code_size + 1
    table: list[list[int]] = []
    out: list[int] = []
    prev: list[int] | None = None

    def reset() -> None:
        nonlocal table, size, prev
        table = [[i] for i in range(clear)] + [[], []]
        size = min_code_size + 1
        prev = None

    reset()
    total = len(data) * 8
    while pos + size <= total:
        code = int.from_bytes(data[pos // 8: pos // 8 + 3].ljust(3, b"\0"), "little") >> (pos % 8)
        code &= (1 << size) - 1
        pos += size
        if code == clear:
            reset()
            continue
        if code == stop:
            break
        if code < len(table):
            entry = table[code]
            if prev is not None and len(table) < 4096:
                table.append(prev + entry[:1])
        else:  # the code being defined: prev + prev's first
            assert prev is not None
            assert code == len(table), (code, len(table))
            entry = prev + prev[:1]
            table.append(entry)
        out += entry
        prev = entry
        if len(table) == (1 << size) and size < 12:
            size += 1
    return out


def _sub_blocks(gif: bytes, pos: int) -> tuple[bytes, int]:
    """The data of the sub-blocks starting at ``pos``, and the position after their end."""
    data = b""
    while gif[pos]:
        data += gif[pos + 1:pos + 1 + gif[pos]]
        pos += 1 + gif[pos]
    return data, pos + 1


def decode(gif: bytes) -> dict[str, Any]:
    """Frames ``(n, h, w, 3)`` uint8 as a viewer composes them, delays, loop flag, rectangles."""
    assert gif[:6] == b"GIF89a"
    w, h, flags, _bg, _aspect = struct.unpack("<HHBBB", gif[6:13])
    pos = 13
    assert flags & 0x80
    n_colours = 2 ** ((flags & 7) + 1)
    palette = np.frombuffer(gif[pos:pos + 3 * n_colours], dtype=np.uint8).reshape(-1, 3)
    pos += 3 * n_colours
    canvas = np.zeros((h, w, 3), dtype=np.uint8)
    frames, delays, rects, loop = [], [], [], False
    transparent: int | None = None
    while True:
        block = gif[pos]
        if block == 0x3B:
            break
        if block == 0x21:
            label = gif[pos + 1]
            body, pos = _sub_blocks(gif, pos + 2)
            if label == 0xF9:
                packed, delay, tindex = struct.unpack("<BHB", body[:4])
                transparent = tindex if packed & 1 else None
                delays.append(delay)
            elif label == 0xFF and body.startswith(b"NETSCAPE2.0"):
                loop = True
            continue
        assert block == 0x2C
        x0, y0, fw, fh, fflags = struct.unpack("<HHHHB", gif[pos + 1:pos + 10])
        assert fflags == 0  # no local table, not interlaced
        pos += 10
        min_code = gif[pos]
        data, pos = _sub_blocks(gif, pos + 1)
        idx = np.array(_lzw_decode(data, min_code), dtype=np.int64)
        assert idx.size == fw * fh, (idx.size, fw, fh)
        idx = idx.reshape(fh, fw)
        region = canvas[y0:y0 + fh, x0:x0 + fw]
        shown = idx != transparent if transparent is not None else np.ones_like(idx, dtype=bool)
        region[shown] = palette[idx[shown]]
        frames.append(canvas.copy())
        rects.append((x0, y0, fw, fh))
    return {"frames": np.array(frames), "delays": delays, "loop": loop, "rects": rects, "size": (w, h)}


def _walking_squares(n: int, h: int, w: int, seed: int) -> np.ndarray:
    """A still background of a few flat colours with a small square moving across it."""
    rng = np.random.default_rng(seed)
    colours = rng.uniform(0.0, 1.0, size=(6, 3))
    bands = (np.arange(h)[:, None] * 6 // h).repeat(w, axis=1)
    frames = np.repeat(colours[bands][None], n, axis=0).copy()
    for k in range(n):
        x = (k * 3) % max(w - 4, 1)
        frames[k, 2:6, x:x + 4] = (1.0, 0.1, 0.1)
    return frames


def test_an_animation_decodes_to_its_frames_with_only_the_changes_stored() -> None:
    frames = _walking_squares(8, 24, 40, seed=1)
    gif = encode_gif(frames, delay_s=4 / 24)
    got = decode(gif)
    assert got["size"] == (40, 24)
    assert got["loop"]
    assert got["delays"] == [17] * 8  # 4 frames at 24 fps, in hundredths
    want = (frames * 255.0 + 0.5).astype(np.int64)
    # Seven flat colours: each is its own palette entry, the centre of its 5-bit bin.
    assert np.abs(got["frames"].astype(np.int64) - want).max() <= 4
    # After the first, each frame stores only the rectangle around the square's move.
    assert got["rects"][0] == (0, 0, 40, 24)
    assert all(fh <= 4 and fw <= 7 for _x, _y, fw, fh in got["rects"][1:]), got["rects"]


def test_a_still_frame_and_the_loop_flag() -> None:
    frames = _walking_squares(1, 10, 10, seed=2)
    frames = np.concatenate([frames, frames])
    got = decode(encode_gif(frames, delay_s=0.5, loop=False))
    assert not got["loop"]
    assert got["delays"] == [50, 50]
    np.testing.assert_array_equal(got["frames"][0], got["frames"][1])


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 20000), st.integers(1, 256))
def test_lzw_round_trips_any_indices_across_table_resets(seed: int, n: int, alphabet: int) -> None:
    """Noise over up to 256 symbols (tables fill and are cleared), runs and single values."""
    rng = np.random.default_rng(seed)
    values = rng.integers(0, alphabet, size=n).astype(np.uint8)
    values[: n // 3] = values[0]  # a long run too
    assert _lzw_decode(lzw_encode(values), 8) == values.tolist()


def test_noise_frames_use_the_nearest_of_255_colours() -> None:
    rng = np.random.default_rng(3)
    frames = rng.uniform(0.0, 1.0, size=(2, 30, 50, 4))
    got = decode(encode_gif(frames, delay_s=0.1))
    want = (frames[..., :3] * 255.0 + 0.5).astype(np.int64)
    err = np.abs(got["frames"].astype(np.int64) - want)
    # 3000 random colours in 255: no pixel lands far from its own colour on average.
    assert err.mean() < 40.0
    assert got["frames"].shape == (2, 30, 50, 3)
