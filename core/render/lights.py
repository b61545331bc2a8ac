"""Light sources for next-event estimation: emissive triangles, point, spot, sun, sky.

One table lists every light that exists in the scene (and nothing else: NEE is never
spent on lights a scene lacks).  A light is chosen with a probability that mixes a power
estimate with a uniform share (:func:`selection_pmf`), then a point or direction on it is sampled:

| kind | sample | pdf (solid angle at the shading point x) | radiance term |
|---|---|---|---|
| triangle | uniform point y | p_sel · |x-y|² / (A |cos θ_y|) | L_e(λ) of its material |
| point | its position | delta (p_sel) | I(λ)/r², I = P/(4π) (Blender's W) |
| spot | its position | delta | point × smoothstep cone mask (size, blend) |
| sun | its direction | delta | E(λ), the irradiance in W/m² |
| sky | uniform sphere | p_sel / (4π) | the background's L(λ) |

Positions are in the accelerator's local coordinates (lab minus ``Accel.origin``).
Spectral shapes are rows of :class:`materials.SpectralTables` ``emit``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..physics import spectrum
from .materials import SpectralTables, light_spectrum

TRIANGLE, POINT, SPOT, SUN, SKY = 0, 1, 2, 3, 4
UNIFORM_SHARE = 0.5


@dataclass
class LightTable:
    kind: np.ndarray     # int32 (K,)
    prim: np.ndarray     # int32 (K,) triangle index for TRIANGLE lights, else -1
    pos: np.ndarray      # float32 (K, 3) local position (point/spot)
    dir: np.ndarray      # float32 (K, 3) unit direction the light points (spot/sun)
    row: np.ndarray      # int32 (K,) emission row
    scale: np.ndarray    # float32 (K,) radiometric factor (I = P/4π, E, or 1)
    spot: np.ndarray     # float32 (K, 2): cos(size/2), smoothing width
    cdf: np.ndarray      # float64 (K+1,)
    tri_pmf: np.ndarray  # float32 (T,) selection probability of each emissive triangle
    sky_pmf: float
    sky_row: int

    @property
    def count(self) -> int:
        return len(self.kind)


def row_luminance(row: np.ndarray, mode: str) -> float:
    """Rest-frame luminance Y of an emission row (a power estimate, not an exact value)."""
    if mode == "rgb":
        return float(np.dot([0.2126, 0.7152, 0.0722], row))
    return float(spectrum.y_of(row))


def build_lights(scene, tables: SpectralTables, origin: np.ndarray, area: np.ndarray,
                 radius: float) -> LightTable:
    """The light table of ``scene`` (see the module table); ``radius`` bounds the scene."""
    mode = tables.mode
    kinds, prims, pos, dirs, rows, scales, spots, power = [], [], [], [], [], [], [], []
    emit_rows = tables.mat_emit_row[scene.material_ids]
    lum = {r: row_luminance(tables.emit[r], mode) for r in np.unique(emit_rows[emit_rows >= 0])}
    for t in np.flatnonzero(emit_rows >= 0):
        m = scene.material_ids[t]
        sides = 1.0 if tables.mat_one_sided[m] else 2.0
        p = area[t] * math.pi * sides * lum[emit_rows[t]]
        if p <= 0.0:
            continue
        kinds.append(TRIANGLE), prims.append(t), pos.append((0, 0, 0)), dirs.append((0, 0, 1))
        rows.append(emit_rows[t]), scales.append(1.0), spots.append((0, 0)), power.append(p)
    for light in scene.lights:
        row = tables.add_emission_row(light_spectrum(light.color, mode))
        y = row_luminance(tables.emit[row], mode)
        if light.type in ("point", "spot"):
            kind = POINT if light.type == "point" else SPOT
            scale = light.power / (4.0 * math.pi)
            est = light.power * y
            cos_half = math.cos(0.5 * light.spot_size) if kind == SPOT else -1.0
            smooth = (1.0 - cos_half) * light.spot_blend if kind == SPOT else 0.0
        elif light.type == "sun":
            kind, scale, cos_half, smooth = SUN, light.power, -1.0, 0.0
            est = light.power * y * math.pi * radius**2
        else:
            raise ValueError(f"light type {light.type!r} must be converted to geometry first")
        if est <= 0.0:
            continue
        kinds.append(kind), prims.append(-1)
        pos.append(np.asarray(light.position, np.float64) - origin)
        dirs.append(np.asarray(light.direction, np.float64))
        rows.append(row), scales.append(scale), spots.append((cos_half, smooth)), power.append(est)
    sky_row = -1
    if np.any(np.asarray(scene.background) > 0):
        sky_row = tables.add_emission_row(light_spectrum(scene.background, mode))
        est = row_luminance(tables.emit[sky_row], mode) * 4.0 * math.pi**2 * radius**2
        kinds.append(SKY), prims.append(-1), pos.append((0, 0, 0)), dirs.append((0, 0, 1))
        rows.append(sky_row), scales.append(1.0), spots.append((0, 0)), power.append(est)
    pmf = selection_pmf(np.asarray(power, np.float64))
    cdf = np.concatenate([[0.0], np.cumsum(pmf)])
    if len(cdf) > 1:
        cdf[-1] = 1.0
    tri_pmf = np.zeros(len(scene.material_ids), np.float32)
    kinds_a = np.asarray(kinds, np.int32)
    prims_a = np.asarray(prims, np.int32)
    tri_pmf[prims_a[kinds_a == TRIANGLE]] = pmf[kinds_a == TRIANGLE]
    sky_pmf = float(pmf[kinds_a == SKY].sum()) if len(pmf) else 0.0
    return LightTable(kinds_a, prims_a, np.asarray(pos, np.float32).reshape(-1, 3),
                      np.asarray(dirs, np.float32).reshape(-1, 3), np.asarray(rows, np.int32),
                      np.asarray(scales, np.float32), np.asarray(spots, np.float32).reshape(-1, 2),
                      cdf, tri_pmf, sky_pmf, sky_row)


def selection_pmf(power: np.ndarray, uniform_share: float = UNIFORM_SHARE) -> np.ndarray:
    """Light-selection probabilities: power-proportional, mixed with a uniform share.

    p_k = (1 - u) P_k / ΣP + u / K.  Pure power sampling starves small, close lights next
    to a bright sky (the sky's power estimate is huge but a point inside a box cannot see
    it), which turns their light into BSDF-sampled fireflies; the uniform share bounds
    every light's probability from below.
    """
    if len(power) == 0:
        return power
    return (1.0 - uniform_share) * power / power.sum() + uniform_share / len(power)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def select(cdf, u):
    """Index k with cdf[k] <= u < cdf[k+1], and its probability."""
    k = np.searchsorted(cdf, u, side="right") - 1
    k = min(max(k, 0), len(cdf) - 2)
    return k, cdf[k + 1] - cdf[k]


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def spot_mask(cos_a, cos_half, smooth):
    """Blender's spot cone: smoothstep((cos a - cos(size/2)) / smooth)."""
    if cos_a <= cos_half:
        return 0.0
    if smooth <= 0.0:
        return 1.0
    t = min(1.0, (cos_a - cos_half) / smooth)
    return t * t * (3.0 - 2.0 * t)
