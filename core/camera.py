"""The relativistic pinhole camera.

A pixel sample becomes a viewing direction ``d_cam`` in the camera's rest frame S'
(from the job's camera axes, which are the same numeric vectors in S' and the lab
because the boost is pure), then the aberrated lab direction ``d_lab`` along which the
integrator traces backwards from the shutter event, and the Doppler factor

    D = ν_cam / ν_lab = 1 / (γ (1 - β·d_cam)) = γ (1 + β·d_lab)

with which the integrator shifts wavelengths (λ_lab = D λ_cam) and weights radiance
(L_cam(λ) = D⁵ L_lab(Dλ)).  See physics.md, "Aberration" and "Doppler factor".

Image convention (job-format.md): row 0 is the top of the picture, right = forward × up,
``fov`` is the full vertical angle; ``shift`` moves the image window in units of the
larger image side, as Blender's lens shift does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import relativity
from .job import CameraSettings


@dataclass(frozen=True)
class PinholeCamera:
    """Camera axes (lab = camera-frame numbers) and the image window.

    ``rotation`` columns are right, up, backward (the camera looks along -column 2).
    """

    rotation: np.ndarray
    tan_half_fov: float
    width: int
    height: int
    shift: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def from_settings(cls, cam: CameraSettings, width: int, height: int) -> PinholeCamera:
        tan_half = math.tan(math.radians(cam.fov) / 2.0)
        return cls(np.asarray(cam.rotation, np.float64), tan_half, width, height,
                   tuple(cam.shift))

    def directions_cam(self, col: np.ndarray, row: np.ndarray) -> np.ndarray:
        """Unit camera-frame viewing directions d_cam through image points.

        ``col`` and ``row`` are continuous pixel coordinates (pixel centre = index + 0.5),
        row 0 at the top.  x_ndc = (2 col/W - 1)·tan(fov/2)·W/H, y_ndc = (1 - 2 row/H)·tan(fov/2).
        """
        aspect = self.width / self.height
        scale = max(self.width, self.height) / self.height
        x = ((2.0 * col / self.width - 1.0) * aspect + 2.0 * self.shift[0] * scale)
        y = ((1.0 - 2.0 * row / self.height) + 2.0 * self.shift[1] * scale)
        x = x * self.tan_half_fov
        y = y * self.tan_half_fov
        r = self.rotation
        d = x[:, None] * r[:, 0] + y[:, None] * r[:, 1] - r[:, 2]
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def lab_rays(d_cam: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Aberrate camera-frame viewing directions into the lab and give their Doppler factors.

    Returns (d_lab (N,3) float64 unit, D (N,) float64).  At β = 0 this is exactly
    (d_cam, 1).
    """
    beta = np.asarray(beta, np.float64)
    if not np.any(beta):
        return d_cam, np.ones(len(d_cam))
    return relativity.aberrate(d_cam, beta), relativity.doppler_factor(d_cam, beta)
