"""Material and emitter tables for the kernels: rest-frame spectra on the lab grid.

Every reflectance ρ(λ) and every emitted radiance L_e(λ) of the scene becomes one row of
a float32 table sampled on :mod:`spectrum`'s log-spaced lab-wavelength grid, so a
kernel looks any of them up at a Doppler-shifted wavelength with one linear
interpolation.  In ``spectral = "rgb"`` mode the "grid" has three columns (R, G, B) and
each hero lane j < 3 looks up column j directly.

Which spectrum each job key gives (physics.md, "Spectral model"):

| key | cie1931 | seed-gaussian | rgb |
|---|---|---|---|
| base_color | Jakob–Hanika sigmoid (clamped band, UV/IR overrides) | the seed's Gaussians | RGB |
| emission × emission_strength | RGB × D65_ext | flat × mean(emission) | RGB |
| emission_blackbody (K) | Planck, rest-frame Y = 1, × strength | same | its RGB |
| emission_line [μ, σ] nm | unit-area Gaussian × strength | same | its RGB |
| emission_spectrum | tabulated × strength | same | its RGB |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics import spectrum
from ..scene.description import MaterialSpec


@dataclass
class SpectralTables:
    """Rows of rest-frame spectra and the per-material BSDF parameters."""

    refl: np.ndarray          # float32 (M, G): reflectance ρ(λ) of each material
    emit: np.ndarray          # float32 (E, G): emitted radiance rows
    mat_weights: np.ndarray   # float32 (M, 3): lobe weights w_d, w_m, w_g
    mat_alpha: np.ndarray     # float32 (M,): GGX α = roughness²
    mat_ior: np.ndarray       # float32 (M,)
    mat_emit_row: np.ndarray  # int32 (M,): row in ``emit`` or -1
    mat_one_sided: np.ndarray  # int32 (M,): 1 = emits from the front face only
    mode: str
    base_rgb: np.ndarray | None = None  # float32 (M, 3): base colour, linear Rec.709 in
    #                                     [0, 1] (the denoising albedo AOV, not the spectra)

    def add_emission_row(self, row: np.ndarray) -> int:
        """Append one emitted-radiance row (float32 (G,)) and return its index."""
        self.emit = np.vstack([self.emit, row[None, :].astype(np.float32)])
        return len(self.emit) - 1


def grid_size(mode: str) -> int:
    """Columns of a table row: the lab grid, or 3 for the ``rgb`` mode."""
    return 3 if mode == "rgb" else spectrum.GRID_N


def emission_rgb(m: MaterialSpec) -> np.ndarray:
    """The emitted radiance of a material as linear Rec.709 (for the ``rgb`` mode)."""
    s = m.emission_strength
    if m.emission_blackbody is not None:
        return spectrum.rgb_of(spectrum.blackbody(m.emission_blackbody)) * s
    if m.emission_line is not None:
        return spectrum.rgb_of(spectrum.gaussian_line(*m.emission_line)) * s
    if m.emission_spectrum is not None:
        return spectrum.rgb_of(spectrum.tabulated(*m.emission_spectrum)) * s
    return np.asarray(m.emission, np.float64) * s


def emission_spectrum(m: MaterialSpec, mode: str) -> np.ndarray | None:
    """The emitted radiance row of a material, or None if it does not emit (or emits
    through an emission texture: the kernel looks that up per texel, :mod:`.textures`)."""
    s = float(m.emission_strength)
    if s == 0.0 or m.emission_texture is not None:
        return None
    if mode == "rgb":
        rgb = emission_rgb(m)
        return None if not np.any(rgb) else rgb.astype(np.float32)
    if m.emission_blackbody is not None:
        return spectrum.blackbody(m.emission_blackbody) * s
    if m.emission_line is not None:
        return spectrum.gaussian_line(*m.emission_line) * s
    if m.emission_spectrum is not None:
        return spectrum.tabulated(*m.emission_spectrum) * s
    if not np.any(m.emission):
        return None
    if mode == "seed-gaussian":
        return spectrum.flat_emission() * s * float(np.mean(m.emission))
    return spectrum.rgb_illuminant(np.asarray(m.emission, np.float64)) * s


def light_spectrum(color: np.ndarray, mode: str) -> np.ndarray:
    """Spectral shape of an analytic light of linear-RGB ``color`` (Y of white = 1)."""
    color = np.asarray(color, np.float64)
    if mode == "rgb":
        return color.astype(np.float32)
    if mode == "seed-gaussian":
        return spectrum.flat_emission() * float(np.mean(color))
    return spectrum.rgb_illuminant(color)


def reflectance_rows(materials: list[MaterialSpec], mode: str) -> np.ndarray:
    """ρ(λ) of every material's base colour, one row each."""
    rgb = np.array([m.base_color for m in materials], np.float64).reshape(-1, 3)
    if mode == "rgb":
        return np.clip(rgb, 0.0, 1.0).astype(np.float32)
    if mode == "seed-gaussian":
        return spectrum.seed_reflectance(rgb).astype(np.float32)
    uv = np.array([np.nan if m.reflectance_uv is None else m.reflectance_uv for m in materials])
    ir = np.array([np.nan if m.reflectance_ir is None else m.reflectance_ir for m in materials])
    return spectrum.rgb_reflectance(
        rgb,
        uv=None if np.all(np.isnan(uv)) else uv,
        ir=None if np.all(np.isnan(ir)) else ir,
    ).astype(np.float32)


def build_tables(materials: list[MaterialSpec], mode: str) -> SpectralTables:
    """Tabulate every material for the kernels (see the module table)."""
    if mode not in spectrum.MODES:
        raise ValueError(f"unknown spectral mode {mode!r}")
    g = grid_size(mode)
    refl = reflectance_rows(materials, mode) if materials else np.zeros((0, g), np.float32)
    weights = np.array(
        [[(1 - m.metallic) * (1 - m.transmission), m.metallic, (1 - m.metallic) * m.transmission]
         for m in materials], np.float32).reshape(-1, 3)
    alpha = np.array([max(m.roughness**2, 1e-4) for m in materials], np.float32)
    ior = np.array([m.ior for m in materials], np.float32)
    one_sided = np.array([int(m.one_sided_emission) for m in materials], np.int32)
    base_rgb = np.clip(np.array([m.base_color for m in materials], np.float32).reshape(-1, 3),
                       0.0, 1.0)
    tables = SpectralTables(refl, np.zeros((0, g), np.float32), weights, alpha, ior,
                            np.full(len(materials), -1, np.int32), one_sided, mode, base_rgb)
    for i, m in enumerate(materials):
        row = emission_spectrum(m, mode)
        if row is not None:
            tables.mat_emit_row[i] = tables.add_emission_row(np.asarray(row))
    return tables
