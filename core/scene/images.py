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

Spectral images (:func:`read_spectral_image`): an OpenEXR file in the layout of Fichet et
al. 2021 ("An OpenEXR layout for spectral images", JCGT 10(3)), whose emissive channels
``S0.<value><unit>`` hold spectral radiance at one wavelength each (the value with a
decimal comma, e.g. ``S0.550,000000nm``, the layout relray's own ``spectral-exr`` output
writes; units nm, um, mm, m or, as frequencies, Hz … PHz with λ = c/ν). Other channels
(RGB, polarisation ``S1``–``S3``, reflective ``T``) are ignored. Values are linear;
at most :data:`MAX_SPECTRAL_VALUES` float32 values in all.
"""

from __future__ import annotations

import os
import re
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
MAX_SPECTRAL_VALUES = 2**29
"""Largest spectral image accepted: texels × bands ≤ 2^29 (2 GiB as float32)."""
SPEED_OF_LIGHT = 299792458.0  # m/s: a frequency band's wavelength λ = c/ν
_FICHET = re.compile(r"^S0\.(\d+(?:,\d*)?)(nm|um|mm|m|Hz|kHz|MHz|GHz|THz|PHz)$")
_NM_PER_UNIT = {"nm": 1.0, "um": 1e3, "mm": 1e6, "m": 1e9}
_HZ_PER_UNIT = {"Hz": 1.0, "kHz": 1e3, "MHz": 1e6, "GHz": 1e9, "THz": 1e12, "PHz": 1e15}

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


@dataclass(frozen=True, eq=False)
class SpectralImage:
    """Spectral radiance of one Fichet-layout EXR (module docstring).

    ``pixels``: float32 (H, W, B), band b at ``wavelengths_nm[b]`` (increasing, > 0),
    row 0 = the bottom row of the picture.
    """

    pixels: np.ndarray
    wavelengths_nm: np.ndarray
    path: Path


_MEMO: dict[tuple, Image | SpectralImage | None] = {}


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


def fichet_wavelength_nm(name: str) -> float | None:
    """The wavelength (nm) of a Fichet 2021 emissive channel name (``S0.550,000000nm``:
    550; ``S0.600THz``: c/600 THz = 499.65), None for any other channel."""
    m = _FICHET.match(name)
    if m is None:
        return None
    value = float(m.group(1).replace(",", "."))
    unit = m.group(2)
    if unit in _NM_PER_UNIT:
        return value * _NM_PER_UNIT[unit]
    hz = value * _HZ_PER_UNIT[unit]
    return SPEED_OF_LIGHT / hz * 1e9 if hz > 0.0 else None


def read_spectral_image(path: Path | str, *, key: str, file: Path | str | None,
                        base: Path | None = None) -> SpectralImage | None:
    """The spectral radiance of ``path`` if it is a Fichet-layout spectral EXR (module
    docstring), else None (then :func:`read_image` reads its colour).

    Raises :class:`UserError` naming ``key`` and ``file`` for a missing or unreadable file,
    an empty image, fewer than two bands or two at one wavelength, more than
    :data:`MAX_SPECTRAL_VALUES` values, or NaN/infinite values. Negative values are kept
    (the caller clamps radiance).
    """
    resolved = resolve_path(path, base, key, file)
    check_readable(resolved, key, file)
    info = os.stat(resolved)
    memo_key = (str(resolved), info.st_size, info.st_mtime_ns, "spectral")
    if memo_key not in _MEMO:
        _MEMO[memo_key] = _read_spectral(resolved, key, file)
    image = _MEMO[memo_key]
    return image if isinstance(image, SpectralImage) else None


def _read_spectral(path: Path, key: str, file: Path | str | None) -> SpectralImage | None:
    if png_size(path) is not None:
        return None
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise UserError(f"{path}: cannot read the image ({_oiio_error()})", key=key, file=file)
    try:
        spec = inp.spec()
        names = list(spec.channelnames)
        bands = [(lam, k) for k, name in enumerate(names)
                 if (lam := fichet_wavelength_nm(name)) is not None]
        if not bands:
            return None
        w, h = spec.width, spec.height
        if w <= 0 or h <= 0:
            raise UserError(f"{path}: the image is empty ({w}×{h})", key=key, file=file)
        if len(bands) < 2:
            raise UserError(f"{path}: a spectral image needs at least 2 bands (S0.<λ> "
                            f"channels), it has {len(bands)}", key=key, file=file)
        bands.sort()
        lam = np.array([b[0] for b in bands])
        if np.any(np.diff(lam) <= 0.0):
            raise UserError(f"{path}: two spectral channels are at the same wavelength",
                            key=key, file=file)
        if w * h * len(bands) > MAX_SPECTRAL_VALUES:
            raise UserError(f"{path}: {w}×{h} texels × {len(bands)} bands is more than "
                            f"{MAX_SPECTRAL_VALUES} values", key=key, file=file)
        pixels = inp.read_image(0, 0, 0, len(names), oiio.FLOAT)
        if pixels is None or getattr(pixels, "size", 0) != w * h * len(names):
            raise UserError(f"{path}: cannot read the image's pixels ({_oiio_error(inp)})",
                            key=key, file=file)
    finally:
        inp.close()
    cube = np.asarray(pixels, np.float32).reshape(h, w, len(names))[..., [b[1] for b in bands]]
    if not np.all(np.isfinite(cube)):
        bad = int(np.count_nonzero(~np.isfinite(cube)))
        raise UserError(f"{path}: the image has {bad} NaN or infinite values",
                        key=key, file=file)
    return SpectralImage(np.ascontiguousarray(cube[::-1]), lam, path)


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
