"""Image files for textures and environment maps (OpenImageIO), as linear float texels.

An image is read once per process and path (memoised by the resolved path, its size and
modification time, and the encoding), so a texture shared by several materials, frames
or farm tasks in one worker costs one read.

Encodings (job-format.md, "Textures"):

- ``"auto"``: integer formats (8- and 16-bit PNG, JPEG, TIFF ...) hold sRGB-encoded colour
  and are decoded to linear; float formats (EXR, HDR, float TIFF) are linear already.
- ``"srgb"``: decode whatever the format; ``"linear"``: take the values as they are
  (roughness, metallic and normal maps).

The sRGB decoding is the IEC 61966-2-1 transfer function,

    c_lin = c / 12.92                     for c ≤ 0.04045
    c_lin = ((c + 0.055) / 1.055)^2.4     otherwise,

applied to the colour channels only (an alpha channel, the 2nd of a grey-alpha or the
4th of an RGBA image, stays linear).

Orientation: row 0 of :attr:`Image.pixels` is the *bottom* row of the picture, so a
texel's row index grows with v, as Blender's UV origin (0, 0) at the bottom-left corner.

Limits: at most :data:`MAX_TEXELS` texels per image (checked from the header, before any
pixel is read); the caller stores :data:`BYTES_PER_TEXEL` bytes per texel of up to four
float32 channels.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import OpenImageIO as oiio

from ..errors import UserError
from ..files import check_readable, resolve_path

MAX_TEXELS = 2**27
"""Largest image accepted: 134 M texels (16384 × 8192), 2 GiB as float32 RGBA."""
BYTES_PER_TEXEL = 16
"""Memory of one stored texel: four float32 channels (fewer channels are padded)."""

Encoding = Literal["auto", "srgb", "linear"]
_ENCODINGS = ("auto", "srgb", "linear")


@dataclass(frozen=True, eq=False)
class Image:
    """Linear texels of one image file.

    ``pixels``: float32 (H, W, C), C in 1..4, row 0 = the bottom row of the picture.
    """

    pixels: np.ndarray
    path: Path

    @property
    def width(self) -> int:
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        return int(self.pixels.shape[0])

    def channels(self) -> int:
        return int(self.pixels.shape[2])


_MEMO: dict[tuple, Image] = {}


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The IEC 61966-2-1 sRGB decoding (module docstring), elementwise, float32."""
    c = np.asarray(c, np.float32)
    lo = c / np.float32(12.92)
    hi = ((np.maximum(c, 0.04045) + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4)
    return np.where(c <= 0.04045, lo, hi).astype(np.float32)


def colour_channels(n: int) -> int:
    """How many leading channels of an n-channel image are colour (the rest: alpha)."""
    return {1: 1, 2: 1, 3: 3}.get(n, 3)


def read_image(path: Path | str, *, key: str, file: Path | str | None,
               encoding: Encoding = "auto", base: Path | None = None) -> Image:
    """The image at ``path`` (relative to ``base``, e.g. the job's folder) as linear texels.

    Raises :class:`UserError` naming ``key`` and ``file`` for a missing, unreadable or
    empty (0×0) image, one of more than :data:`MAX_TEXELS` texels, or NaN/infinite values.
    Only the first four channels are kept.
    """
    if encoding not in _ENCODINGS:
        raise ValueError(f"encoding must be one of {_ENCODINGS}, not {encoding!r}")
    resolved = resolve_path(path, base, key, file)
    check_readable(resolved, key, file)
    info = os.stat(resolved)
    memo_key = (str(resolved), info.st_size, info.st_mtime_ns, encoding)
    image = _MEMO.get(memo_key)
    if image is None:
        image = Image(_read_pixels(resolved, key, file, encoding), resolved)
        _MEMO[memo_key] = image
    return image


def png_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR chunk, or None for another format. Read before
    OpenImageIO opens the file: libpng prints its own error line for a 0×0 header."""
    with open(path, "rb") as f:
        head = f.read(24)
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def _read_pixels(path: Path, key: str, file: Path | str | None, encoding: Encoding
                 ) -> np.ndarray:
    """float32 (H, W, C ≤ 4), bottom row first, decoded as ``encoding`` says."""
    size = png_size(path)
    if size is not None and 0 in size:
        raise UserError(f"{path}: the image is empty ({size[0]}×{size[1]})", key=key,
                        file=file)
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # colour as stored, not × alpha
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise UserError(f"{path}: cannot read the image ({_oiio_error()})", key=key, file=file)
    try:
        spec = inp.spec()
        w, h, n = spec.width, spec.height, spec.nchannels
        if w <= 0 or h <= 0 or n <= 0:
            raise UserError(f"{path}: the image is empty ({w}×{h}, {n} channels)",
                            key=key, file=file)
        if w * h > MAX_TEXELS:
            raise UserError(f"{path}: the image has {w}×{h} = {w * h} texels; at most "
                            f"{MAX_TEXELS} are accepted", key=key, file=file)
        keep = min(n, 4)
        pixels = inp.read_image(0, 0, 0, keep, oiio.FLOAT)
        if pixels is None or getattr(pixels, "size", 0) != w * h * keep:
            raise UserError(f"{path}: cannot read the image's pixels ({_oiio_error(inp)})",
                            key=key, file=file)
        is_float = spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
    finally:
        inp.close()
    pixels = np.asarray(pixels, np.float32).reshape(h, w, keep)
    if not np.all(np.isfinite(pixels)):
        bad = int(np.count_nonzero(~np.isfinite(pixels)))
        raise UserError(f"{path}: the image has {bad} NaN or infinite values",
                        key=key, file=file)
    if encoding == "srgb" or (encoding == "auto" and not is_float):
        c = colour_channels(keep)
        pixels[..., :c] = srgb_to_linear(pixels[..., :c])
    return np.ascontiguousarray(pixels[::-1])


def _oiio_error(inp=None) -> str:
    text = (inp.geterror() if inp is not None else "") or oiio.geterror() or "unknown format"
    return " ".join(text.split())
