"""The sky of a scene: an environment map's image, read when the scene is built.

The map (``scene.environment``, :class:`.description.EnvironmentSpec`) is read with
:func:`.images.read_spectral_image` when it is a spectral EXR (Fichet et al. 2021 layout:
texels of lab spectral radiance at the file's wavelengths), else with
:func:`.images.read_image` (``encoding="auto"``: EXR/HDR linear, PNG/JPEG sRGB-decoded),
while the scene is built, before anything is rendered or written, so a missing,
unreadable, empty or non-finite image, or one whose sampling tables would not fit in
memory, is one :class:`..errors.UserError` naming ``scene.environment.file`` and the
job file. What the renderer makes of it (lab radiance
at infinity, sampling) is :mod:`..render.environment`'s.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import resources
from ..errors import UserError
from .description import EnvironmentSpec
from .images import read_image, read_spectral_image

KEY = "scene.environment.file"
#: Peak memory per texel of the renderer's tables of a map and their construction
#: (render/environment.py: texel table 16 B, pmf 4 B, conditional CDF 8 B kept; float64
#: RGB, luminance, power and the coefficient fit's distinct colours while building).
TABLE_BYTES_PER_TEXEL = 128
GIB = 2.0**30


@dataclass(frozen=True)
class EnvironmentImage:
    """An environment map as read: ``pixels`` float32 (H, W, C) linear, row 0 the
    bottom row (v = 0); ``strength`` scales it, ``rotation_z`` (degrees) turns it.
    A spectral map has ``wavelengths_nm`` (C,): channel c is the lab spectral radiance
    at that wavelength (None: C ≤ 4 colour channels, linear Rec.709)."""

    pixels: np.ndarray
    strength: float = 1.0
    rotation_z: float = 0.0
    wavelengths_nm: np.ndarray | None = None
    #: the file it was read from, as "path:size:mtime_ns" ("" when made in memory): what
    #: identifies its content cheaply (the viewport's scene hash)
    source: str = ""

    @property
    def spectral(self) -> bool:
        return self.wavelengths_nm is not None


def load_environment(spec: EnvironmentSpec | None,
                     job_file: Path | str | None) -> EnvironmentImage | None:
    """The image of ``spec`` (None: no map)."""
    if spec is None:
        return None
    spectral = read_spectral_image(spec.file, key=KEY, file=job_file)
    st = os.stat(spec.file)  # readable: the reader above has checked it
    source = f"{spec.file}:{st.st_size}:{st.st_mtime_ns}"
    if spectral is not None:
        h, w, bands = spectral.pixels.shape
        check_table_memory(h, w, job_file, 4 * bands)
        return EnvironmentImage(spectral.pixels, spec.strength, spec.rotation_z,
                                spectral.wavelengths_nm, source)
    image = read_image(spec.file, key=KEY, file=job_file, encoding="auto")
    check_table_memory(image.pixels.shape[0], image.pixels.shape[1], job_file)
    return EnvironmentImage(image.pixels, spec.strength, spec.rotation_z, source=source)


def check_table_memory(height: int, width: int, job_file: Path | str | None,
                       extra_per_texel: int = 0) -> None:
    """Refuse a map whose tables (:data:`TABLE_BYTES_PER_TEXEL`, plus ``extra_per_texel``:
    a spectral map's float32 bands) alone would not fit in the memory this process may
    use (:func:`..resources.memory_limit`)."""
    limit = resources.memory_limit()
    need = height * width * (TABLE_BYTES_PER_TEXEL + extra_per_texel)
    if limit is not None and need > limit.bytes:
        raise UserError(f"a {width} x {height} environment map needs about "
                        f"{need / GIB:.1f} GiB for its sampling tables, more than "
                        f"{limit.source} allows ({limit.bytes / GIB:.1f} GiB); use a smaller "
                        "map", key=KEY, file=job_file)
