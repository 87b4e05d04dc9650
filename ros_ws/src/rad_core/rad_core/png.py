"""A tiny PNG writer (zlib + struct), so rendering needs no imaging library.

Writes 8-bit greyscale, RGB or RGBA images, unfiltered rows, one IDAT chunk:
enough for scene snapshots, and any PNG reader opens them.
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


def encode_png(image, level: int = 6) -> bytes:
    """PNG bytes of an (H, W), (H, W, 3) or (H, W, 4) uint8 array."""
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f'expected a uint8 image, got dtype {a.dtype}')
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in _COLOUR_TYPE or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f'expected an (H, W), (H, W, 3) or (H, W, 4) image, got shape {np.shape(image)}')
    height, width, channels = a.shape
    header = struct.pack('>IIBBBBB', width, height, 8, _COLOUR_TYPE[channels], 0, 0, 0)
    rows = np.empty((height, 1 + width * channels), dtype=np.uint8)
    rows[:, 0] = 0                                   # filter type 0 (None) on every row
    rows[:, 1:] = np.ascontiguousarray(a).reshape(height, width * channels)
    return (SIGNATURE + _chunk(b'IHDR', header) + _chunk(b'IDAT', zlib.compress(rows.tobytes(), level))
            + _chunk(b'IEND', b''))


def write_png(path: str | Path, image, level: int = 6) -> Path:
    """Write an (H, W[, 3|4]) uint8 array as a PNG file; returns the path."""
    path = Path(path)
    path.write_bytes(encode_png(image, level))
    return path
