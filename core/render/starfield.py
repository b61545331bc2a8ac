"""The star layer of a frame: each visible star as a sharp splat of its camera-frame flux.

Stars are point sources at infinity in the lab (core/scene/stars.py). They are not a
texture and no path samples them: once per frame, independent of ``spp`` and of adaptive
sampling, every star is

1. aberrated into the camera frame: d' = ``relativity.aberrate_inverse(n, β)`` for its
   lab viewing direction n (cos θ' = (cos θ + β)/(1 + β cos θ) about β̂), with the
   Doppler factor D = ``relativity.doppler_factor_lab(n, β)`` = γ (1 + β·n);
2. projected by the pinhole camera (:meth:`.camera.PinholeCamera.project`) to a
   continuous image position; stars behind the camera or outside the image are dropped;
3. tested for occlusion: the lab ray from the shutter event along n against the
   scene's accelerator (the static BVH, or :meth:`.rest_frames.MovingScene.occluded`
   with the ray's lab event, so moving bodies hide stars where they are when the light
   passes); any geometry hides a star, glass too (stars are not traced through
   transmissive surfaces, nor seen in mirrors: they reach the camera only directly);
   the area lights' quads are no geometry and hide nothing;
4. given its camera-frame flux F_cam(λ) = (Ω/D²) B(λ, D T) through the sensor
   (:func:`..physics.starlight.sensor_flux`, which also documents what ``doppler``,
   ``searchlight`` and ``spectral = "rgb"`` do to it) and, when the job writes
   ``spectral-exr``, per band (:func:`..physics.starlight.band_flux`);
5. splatted through the pixel filter. The film's filter is the one-pixel box (primary
   rays are jittered uniformly over their pixel and count for that pixel only), so a
   point at image position (col, row) has weight 1 in the pixel that contains it and 0
   elsewhere; the box-filtered radiance of a point of flux F is F / Ω_px, with Ω_px the
   pixel's solid angle at that point (:meth:`.camera.PinholeCamera.pixel_solid_angle`),
   so that Σ_pixels value × Ω_px = F. That is exactly what the film would converge to
   for a star of tiny but finite disc, at any β.

The result is added to the film as a sample-free radiance layer (:meth:`.film.Film.add_layer`):
not clamped, not part of the noise estimates. A transparent film (``render.transparent``)
shows no stars, as it shows no background. Stars light nothing (core/scene/stars.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..physics import relativity, starlight
from ..scene.stars import StarField
from .accel import MISS_DISTANCE, Accel
from .camera import PinholeCamera
from .rest_frames import MovingScene

__all__ = ["StarSplats", "star_splats", "occlusion_test"]


@dataclass(frozen=True, eq=False)
class StarSplats:
    """The visible stars of a frame (K of them): flat pixel index (row·W + col, row 0 at
    the top), continuous image position, Doppler factor, the pixel's radiance as sensor
    values (K, 3) and, with bands, the mean spectral radiance per band (K, nb)."""

    pixel: np.ndarray
    col: np.ndarray
    row: np.ndarray
    doppler: np.ndarray
    sensor: np.ndarray
    bands: np.ndarray | None = None


def star_splats(stars: StarField, camera: PinholeCamera, beta: np.ndarray, *, mode: str,
                doppler: bool = True, searchlight: bool = True,
                bands: tuple[np.ndarray, float] | None = None,
                blocked: Callable[[np.ndarray], np.ndarray] | None = None) -> StarSplats:
    """The splats of ``stars`` seen by ``camera`` moving at ``beta`` (module docstring).

    ``mode``, ``doppler``, ``searchlight``: the renderer's effective switches;
    ``bands``: (band centres nm, band width nm) of the spectral output, or None;
    ``blocked``: lab viewing directions (K, 3) -> bool (K,), True where geometry hides
    the sky (None: nothing does).
    """
    n_lab = stars.directions
    d_cam = relativity.aberrate_inverse(n_lab, beta)
    col, row, front = camera.project(d_cam)
    with np.errstate(invalid="ignore"):
        inside = front & (col >= 0.0) & (col < camera.width) & (row >= 0.0) & \
            (row < camera.height)
    idx = np.flatnonzero(inside)
    if blocked is not None and len(idx):
        idx = idx[~np.asarray(blocked(n_lab[idx]), bool)]
    col, row = col[idx], row[idx]
    D = np.asarray(relativity.doppler_factor_lab(n_lab[idx], beta), np.float64).reshape(-1)
    inv_px = 1.0 / camera.pixel_solid_angle(col, row)
    omega, temp = stars.omega[idx], stars.temperature[idx]
    sensor = starlight.sensor_flux(omega, temp, D, mode, doppler, searchlight) * inv_px[:, None]
    band = None
    if bands is not None:
        centres, width = bands
        band = starlight.band_flux(omega, temp, D, centres, width, doppler, searchlight) \
            * inv_px[:, None]
    pixel = (np.floor(row).astype(np.int64) * camera.width + np.floor(col).astype(np.int64))
    return StarSplats(pixel, col, row, D, sensor, band)


def occlusion_test(tracer: Accel | MovingScene | None, origin: np.ndarray, radius: float,
                   event: relativity.ShutterEvent) -> Callable[[np.ndarray], np.ndarray]:
    """``blocked`` for :func:`star_splats`: True where the lab ray from the shutter event
    along a direction hits geometry (``tracer``, its accelerator coordinates about the lab
    point ``origin``). For a static scene (a finite bounding sphere of ``radius``) seen
    from outside, a ray that misses the sphere is free without a trace, and the others
    start where they enter it (float64, as the primary rays do), so a far camera keeps
    its precision."""
    x0 = np.asarray(event.x, np.float64) - np.asarray(origin, np.float64)

    def blocked(d: np.ndarray) -> np.ndarray:
        n = len(d)
        out = np.zeros(n, bool)
        if tracer is None or n == 0:
            return out
        rows = np.arange(n)
        t_in = np.zeros(n)
        c = float(x0 @ x0) - radius * radius
        if math.isfinite(radius) and c > 0.0:
            b = d @ x0
            perp = x0[None, :] - b[:, None] * d
            disc = radius * radius - np.einsum("ij,ij->i", perp, perp)
            root = np.sqrt(np.maximum(disc, 0.0))
            reach = (disc > 0.0) & (root - b > 0.0)  # the sphere is crossed ahead
            rows, b, root = rows[reach], b[reach], root[reach]
            t_in = np.maximum(0.0, -b - root)
        if len(rows) == 0:
            return out
        dr = d[rows]
        o = np.ascontiguousarray(x0[None, :] + t_in[:, None] * dr, np.float32)
        dirs = np.ascontiguousarray(dr, np.float32)
        tmax = np.full(len(rows), MISS_DISTANCE, np.float32)
        if isinstance(tracer, MovingScene):
            hit = tracer.occluded(o, dirs, tmax, float(event.t) - t_in)
        else:
            hit = tracer.occluded(o, dirs, tmax)
        out[rows] = np.asarray(hit, bool)
        return out

    return blocked
