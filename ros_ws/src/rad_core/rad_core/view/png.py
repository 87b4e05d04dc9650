"""A tiny PNG writer (zlib + struct), so rendering needs no imaging library.

Writes 8-bit greyscale, RGB or RGBA images, unfiltered rows, one IDAT chunk:
enough for scene snapshots, and any PNG reader opens them. `encode_apng` writes
animated PNGs (APNG: an acTL chunk, then an fcTL chunk before each frame's
data): every browser plays them, and a viewer that does not shows the still.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

SIGNATURE = b'\x89PNG\r\n\x1a\n'
_COLOUR_TYPE = {1: 0, 3: 2, 4: 6}       # channels -> PNG colour type (grey, RGB, RGBA)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack('>I', len(data)) + kind + data + struct.pack('>I', zlib.crc32(kind + data) & 0xFFFFFFFF)


def _image(image) -> np.ndarray:
    """The image as an (H, W, channels) uint8 array; ValueError for anything PNG cannot hold."""
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f'expected a uint8 image, got dtype {a.dtype}')
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in _COLOUR_TYPE or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f'expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {np.shape(image)}')
    return a


def _header(a: np.ndarray) -> bytes:
    height, width, channels = a.shape
    return _chunk(b'IHDR', struct.pack('>IIBBBBB', width, height, 8, _COLOUR_TYPE[channels], 0, 0, 0))


def _compressed_rows(a: np.ndarray, level: int) -> bytes:
    height, width, channels = a.shape
    rows = np.empty((height, 1 + width * channels), dtype=np.uint8)
    rows[:, 0] = 0                                   # filter type 0 (None) on every row
    rows[:, 1:] = np.ascontiguousarray(a).reshape(height, width * channels)
    return zlib.compress(rows.tobytes(), level)


def encode_png(image, level: int = 6) -> bytes:
    """PNG bytes of an (H, W), (H, W, 3) or (H, W, 4) uint8 array."""
    a = _image(image)
    return SIGNATURE + _header(a) + _chunk(b'IDAT', _compressed_rows(a, level)) + _chunk(b'IEND', b'')


def write_png(path: str | Path, image, level: int = 6) -> Path:
    """Write an (H, W[, 3|4]) uint8 array as a PNG file; returns the path."""
    path = Path(path)
    path.write_bytes(encode_png(image, level))
    return path


def _changed(a: np.ndarray, b: np.ndarray) -> tuple[int, int, int, int]:
    """(x, y, width, height) of the smallest rectangle holding every pixel where b differs
    from a; one pixel when none does (a frame still needs a region to show its delay)."""
    rows, cols = np.nonzero(np.any(a != b, axis=2))
    if len(rows) == 0:
        return 0, 0, 1, 1
    return int(cols.min()), int(rows.min()), int(cols.max() - cols.min() + 1), int(rows.max() - rows.min() + 1)


def encode_apng(frames, delays_s, still=None, plays: int = 0, level: int = 6) -> bytes:
    """Animated PNG bytes: frames (equal-sized uint8 images) shown in order, frame k for
    delays_s[k] seconds (a number: the same for all), looping `plays` times (0: forever).

    still: what a viewer without APNG support shows (an image of the frames' size, not
    part of the animation); None shows the first frame. After the first, each frame
    stores only the rectangle where it differs from the frame before (drawn over it).
    """
    frames = [_image(f) for f in frames]
    if not frames:
        raise ValueError('an animation needs at least one frame')
    if any(f.shape != frames[0].shape for f in frames):
        raise ValueError(f'frames differ in shape: {sorted({f.shape for f in frames})}')
    delays = [delays_s] * len(frames) if np.isscalar(delays_s) else list(delays_s)
    if len(delays) != len(frames) or not all(0 <= float(d) <= 65.535 for d in delays):
        raise ValueError(f'expected one delay of 0..65.535 s per frame ({len(frames)}), got {delays_s!r}')
    if not (isinstance(plays, int) and 0 <= plays < 2 ** 31):
        raise ValueError(f'plays must be a count >= 0, got {plays!r}')
    out = [SIGNATURE, _header(frames[0]), _chunk(b'acTL', struct.pack('>II', len(frames), plays))]
    if still is not None:
        still = _image(still)
        if still.shape != frames[0].shape:
            raise ValueError(f'the still is {still.shape}, the frames {frames[0].shape}')
        out.append(_chunk(b'IDAT', _compressed_rows(still, level)))
    sequence = 0
    for k, frame in enumerate(frames):
        height, width = frame.shape[:2]
        x, y, w, h = (0, 0, width, height) if k == 0 else _changed(frames[k - 1], frame)
        # dispose_op 0 (leave the frame), blend_op 0 (replace the rectangle's pixels).
        out.append(_chunk(b'fcTL', struct.pack('>IIIIIHHBB', sequence, w, h, x, y,
                                                round(float(delays[k]) * 1000), 1000, 0, 0)))
        sequence += 1
        data = _compressed_rows(frame[y:y + h, x:x + w], level)
        if k == 0 and still is None:
            out.append(_chunk(b'IDAT', data))
        else:
            out.append(_chunk(b'fdAT', struct.pack('>I', sequence) + data))
            sequence += 1
    out.append(_chunk(b'IEND', b''))
    return b''.join(out)


def write_apng(path: str | Path, frames, delays_s, still=None, plays: int = 0, level: int = 6) -> Path:
    """Write an animated PNG (arguments as for `encode_apng`); returns the path."""
    path = Path(path)
    path.write_bytes(encode_apng(frames, delays_s, still, plays, level))
    return path
