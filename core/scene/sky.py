"""The sky of a scene: an environment map's image, read when the scene is built.

The map (``scene.environment``, :class:`.description.EnvironmentSpec`) is read with
:func:`.images.read_image` (``encoding="auto"``: EXR/HDR linear, PNG/JPEG sRGB-decoded)
while the scene is built, before anything is rendered or written, so a missing,
unreadable, empty or non-finite image is one :class:`..errors.UserError` naming
``scene.environment.file`` and the job file. What the renderer makes of it (lab radiance
at infinity, sampling) is :mod:`..render.environment`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .description import EnvironmentSpec
from .images import read_image

KEY = "scene.environment.file"


@dataclass(frozen=True)
class EnvironmentImage:
    """An environment map as read: ``pixels`` float32 (H, W, C) linear, row 0 the
    bottom row (v = 0); ``strength`` scales it, ``rotation_z`` (degrees) turns it."""

    pixels: np.ndarray
    strength: float = 1.0
    rotation_z: float = 0.0


def load_environment(spec: EnvironmentSpec | None,
                     job_file: Path | str | None) -> EnvironmentImage | None:
    """The image of ``spec`` (None: no map)."""
    if spec is None:
        return None
    image = read_image(spec.file, key=KEY, file=job_file, encoding="auto")
    return EnvironmentImage(image.pixels, spec.strength, spec.rotation_z)
