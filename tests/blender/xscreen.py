"""Screens captured with ``xwd`` from a virtual display (viewport_probe.py)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np


def read_xwd(path: Path) -> np.ndarray:
    """An X window dump (ZPixmap, 24/32 bits, little-endian BGRX) as (h, w, 3) uint8 RGB,
    row 0 at the top."""
    raw = Path(path).read_bytes()
    header = struct.unpack(">25I", raw[:100])
    size, width, height, bytes_per_line, ncolors = (header[0], header[4], header[5],
                                                    header[12], header[19])
    start = size + 12 * ncolors
    rows = np.frombuffer(raw[start:start + bytes_per_line * height], np.uint8)
    px = rows.reshape(height, bytes_per_line)[:, :width * 4].reshape(height, width, 4)
    return px[..., [2, 1, 0]].copy()


def crop(screen: np.ndarray, rect, window_height: int) -> np.ndarray:
    """The rectangle (x, y, w, h; Blender's window coordinates, y up from the bottom) of
    a screen captured with row 0 at the top."""
    x, y, w, h = rect
    top = window_height - (y + h)
    return screen[top:top + h, x:x + w]
