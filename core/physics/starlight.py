"""Starlight: a star's temperature, its flux at rest and the flux a moving camera receives.

A star is a point source at infinity: it has a spectral *flux* F(λ) (W·m⁻²·nm⁻¹, in
the renderer's units: radiance × steradian), not a radiance. Every star is modelled as
a blackbody of temperature T seen under a tiny lab solid angle Ω:

    F_lab(λ) = Ω · B(λ, T)                                    (lab frame S)

Temperature from the colour index (Ballesteros 2012, EPL 97, 34008, eq. 14, a blackbody
fitted to the Johnson B and V filters):

    T = 4600 K · ( 1 / (0.92 (B−V) + 1.7) + 1 / (0.92 (B−V) + 0.62) )

B−V is clamped to [:data:`BV_MIN`, :data:`BV_MAX`] (the formula has a pole at
B−V = −0.674; the Hipparcos catalogue spans −0.40 .. 5.46).

Photometric zero point (lab frame). The catalogue's magnitude m (Hipparcos Hp, within
a few tenths of Johnson V for most stars) is taken as a luminance magnitude: the star's
luminous flux, CIE 1931 Y of F_lab in the renderer's units (the units in which an RGB
(1, 1, 1) emitter has luminance Y = 1), is

    Y_lab = brightness · Y0 · 10^(−0.4 m),      Y0 = :data:`ZERO_POINT_Y` = 2.5e-4,

so Ω = Y_lab / Y[B(·, T)]. A magnitude-0 star carries the luminous flux of a patch of
luminance-1 sky of 2.5e-4 sr (a disc of 0.9° radius). Drawn into a pixel of solid angle
Ω_px it adds the radiance Y/Ω_px: a 256-pixel-high image with a 40° field has
Ω_px ≈ 8.1e-6 sr, so at the default exposure (0 stops, radiance 1 = white) a
magnitude-8 star adds Y ≈ 0.02 (a faint grey dot, sRGB ~ 40/255), magnitude 4 Y ≈ 0.8
and everything brighter than about magnitude 3.7 is white. ``brightness`` multiplies
every star's flux (1 = the zero point above).

Camera frame (physics.md, "Skies"). The specific intensity I_ν/ν³ is invariant, so per
unit wavelength radiance transforms as L_cam(λ) = D⁵ L_lab(D λ), D = ν_cam/ν_lab =
γ (1 + β·n) for the lab viewing direction n. Aberration maps a small patch of lab solid
angle dΩ_lab onto dΩ_cam = dΩ_lab / D² (the Jacobian of cos θ' = (cos θ + β)/(1 + β cos θ):
d cos θ'/d cos θ = 1/(γ² (1 + β cos θ)²) = 1/D², and φ is unchanged). The flux of the
star is its radiance integrated over its (tiny) image, so

    F_cam(λ) = ∫ L_cam dΩ_cam = D⁵ L_lab(Dλ) · Ω/D² = D³ F_lab(D λ),

and for a blackbody, since D⁵ B(Dλ, T) = B(λ, D T):

    F_cam(λ) = (Ω / D²) · B(λ, D·T)

a blackbody of temperature D·T seen under the solid angle Ω/D²; the bolometric flux goes
as D² (σT⁴ Ω: D⁴ from T, D⁻² from Ω).

The renderer's switches act on stars as on every other source
(core/render/frames.py, core/physics/spectrum.WavelengthSampler.lanes):

* ``doppler = false``: wavelengths are not shifted, B(λ, T) instead of B(Dλ, T);
* ``searchlight = false`` (and always in ``seed-gaussian``): no D⁵ radiance factor;
* aberration (the star's position and its solid angle Ω/D²) is geometry and always on,
  so in general  F_cam(λ) = (Ω / D²) · [D⁵ if searchlight] · B([D if doppler] · λ, T);
* ``spectral = "rgb"``: no wavelengths and no D⁵ (as for every RGB source): the star's
  lab colour M·∫ c̄ B(λ, T) dλ (CIE 1931 → linear Rec.709) times Ω/D².

Sensor values are ∫ r_c(λ) F_cam(λ) dλ by the 1 nm trapezoid rule over 360–830 nm
(what the film's Monte Carlo estimate converges to, :mod:`.spectrum`), here with exact
Planck values rather than the float32 grid tables.
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import INLINE, njit
from . import spectrum

__all__ = ["BV_MIN", "BV_MAX", "ZERO_POINT_Y", "temperature_from_bv", "luminous_flux",
           "lab_solid_angle", "camera_factors", "sensor_flux", "band_flux"]

#: Range of B−V fed to :func:`temperature_from_bv` (the formula's pole is at −0.674).
BV_MIN = -0.4
BV_MAX = 5.5
#: Luminous flux (CIE Y × sr, the renderer's units) of a magnitude-0 star at brightness 1.
ZERO_POINT_Y = 2.5e-4
#: Gauss–Legendre nodes on [-1, 1] and weights of the spectral-band averages.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)


def temperature_from_bv(bv: np.ndarray | float) -> np.ndarray:
    """Blackbody temperature (K) of a star of colour index B−V (Ballesteros 2012):

        T = 4600 K (1/(0.92 (B−V) + 1.7) + 1/(0.92 (B−V) + 0.62)),

    B−V clamped to [BV_MIN, BV_MAX]. The Sun (B−V = 0.65) gives 5778 K, Vega (0.0) 10125 K.
    """
    x = np.clip(np.asarray(bv, np.float64), BV_MIN, BV_MAX)
    return 4600.0 * (1.0 / (0.92 * x + 1.7) + 1.0 / (0.92 * x + 0.62))


def luminous_flux(magnitude: np.ndarray | float, brightness: float = 1.0) -> np.ndarray:
    """Lab luminous flux Y = brightness · ZERO_POINT_Y · 10^(−0.4 m) (renderer units × sr)."""
    return brightness * ZERO_POINT_Y * 10.0 ** (-0.4 * np.asarray(magnitude, np.float64))


#: Planck's law per nm with λ in nm: B = _C1_NM / (λ⁵ (e^{c2/(λT)} − 1)), W·m⁻²·sr⁻¹·nm⁻¹.
_C1_NM = spectrum._C1 * 1e36
_C2_NM_K = spectrum._C2_NM_K


@njit(**INLINE)
def _planck(lam_nm, T):
    """B_λ(λ, T) (W·m⁻²·sr⁻¹·nm⁻¹), as :func:`spectrum.planck`; 0 where e^x overflows."""
    x = _C2_NM_K / (lam_nm * T)
    if x > 709.0:
        return 0.0
    l2 = lam_nm * lam_nm
    return _C1_NM / (l2 * l2 * lam_nm * math.expm1(x))


@njit(cache=True, nogil=True, error_model="numpy")
def _weighted_planck(lam, w, scale, temp, out):  # pragma: no cover - compiled
    """out[i, c] = Σ_j w[c, j] B(scale[i] λ_j, temp[i]) (quadrature rows w over λ)."""
    for i in range(out.shape[0]):
        s, t = scale[i], temp[i]
        for c in range(w.shape[0]):
            out[i, c] = 0.0
        for j in range(lam.shape[0]):
            b = _planck(s * lam[j], t)
            if b != 0.0:
                for c in range(w.shape[0]):
                    out[i, c] += w[c, j] * b


@njit(cache=True, nogil=True, error_model="numpy")
def _grouped_planck(lam, w, scale, temp, out):  # pragma: no cover - compiled
    """out[i, g] = Σ_k w[k] B(scale[i] λ[g, k], temp[i]) (one quadrature per group g)."""
    for i in range(out.shape[0]):
        s, t = scale[i], temp[i]
        for g in range(lam.shape[0]):
            acc = 0.0
            for k in range(lam.shape[1]):
                acc += w[k] * _planck(s * lam[g, k], t)
            out[i, g] = acc


def _sensor_rows(mode: str) -> np.ndarray:
    """(3, 471) quadrature rows W[c, i] at :func:`spectrum.sensor_nm`: s_c = Σ_i W[c,i] F(λ_i)."""
    return spectrum._sensor_weights("cie1931" if mode == "rgb" else mode)


def lab_solid_angle(magnitude: np.ndarray, temperature: np.ndarray,
                    brightness: float = 1.0) -> np.ndarray:
    """Ω (sr) with Y[Ω B(·, T)] = :func:`luminous_flux` (m): the lab flux is Ω·B(λ, T)."""
    t = np.ascontiguousarray(np.atleast_1d(temperature), np.float64)
    y = np.empty((len(t), 1))
    _weighted_planck(spectrum.sensor_nm(), _sensor_rows("cie1931")[1:2].copy(),
                     np.ones(len(t)), t, y)
    return luminous_flux(magnitude, brightness) / y[:, 0].reshape(np.shape(temperature))


def camera_factors(D: np.ndarray, doppler: bool, searchlight: bool
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(k, s): F_cam(λ) = k · Ω · B(s·λ, T) with k = D⁻² (aberrated solid angle) times D⁵
    when ``searchlight``, and s = D when ``doppler`` (else 1). Module docstring."""
    D = np.asarray(D, np.float64)
    k = D**3 if searchlight else 1.0 / (D * D)
    return k, (D if doppler else np.ones_like(D))


def sensor_flux(omega: np.ndarray, temperature: np.ndarray, D: np.ndarray, mode: str,
                doppler: bool = True, searchlight: bool = True) -> np.ndarray:
    """Sensor values (N, 3) of the camera-frame flux of N stars: ∫ r_c(λ) F_cam(λ) dλ.

    ``mode``: "cie1931" (XYZ), "seed-gaussian" (the seed's responses) or "rgb" (linear
    Rec.709 of the lab spectrum; no wavelength shift and no D⁵, only Ω/D²). ``omega``,
    ``temperature``, ``D``: (N,) lab solid angle, lab temperature, Doppler factor.
    """
    omega = np.asarray(omega, np.float64)
    rgb = mode == "rgb"
    k, s = camera_factors(D, doppler and not rgb, searchlight and not rgb)
    out = np.empty((len(omega), 3))
    _weighted_planck(spectrum.sensor_nm(), np.ascontiguousarray(_sensor_rows(mode)),
                     np.ascontiguousarray(s, np.float64),
                     np.ascontiguousarray(temperature, np.float64), out)
    out *= (k * omega)[:, None]
    if rgb:
        out = out @ spectrum.sensor_to_rgb("cie1931").T
    return out


def band_flux(omega: np.ndarray, temperature: np.ndarray, D: np.ndarray,
              centers_nm: np.ndarray, step_nm: float, doppler: bool = True,
              searchlight: bool = True) -> np.ndarray:
    """Mean camera-frame flux over each spectral band, (N, nb):
    (1/Δ) ∫_{λ_b − Δ/2}^{λ_b + Δ/2} F_cam(λ) dλ by 4-point Gauss–Legendre per band."""
    omega = np.asarray(omega, np.float64)
    lam = np.ascontiguousarray(np.asarray(centers_nm, np.float64)[:, None]
                               + 0.5 * float(step_nm) * _GL_X[None, :])
    k, s = camera_factors(D, doppler, searchlight)
    out = np.empty((len(omega), len(lam)))
    _grouped_planck(lam, 0.5 * _GL_W, np.ascontiguousarray(s, np.float64),
                    np.ascontiguousarray(temperature, np.float64), out)
    out *= (k * omega)[:, None]
    return out
