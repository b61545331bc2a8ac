"""Spectra: the lab-wavelength grid, the sensor, hero-wavelength sampling and every table.

What it provides (docs/interfaces.md, "core/physics/spectrum.py"; physics.md, "Spectral model"):

* the global **lab-wavelength grid**, log-spaced from 1 nm to 100 µm (``GRID_*``,
  :func:`grid_nm`, :func:`lookup`).  All tables here are float32 rest-frame spectra in the
  LAB frame (or an object's rest frame) tabulated on this grid; the integrator looks them
  up at ``λ_lab = D · λ_camera`` and applies the D⁵ searchlight factor itself.  On the log
  grid a Doppler shift is a constant index offset ``ln(D) · INV_DLOG``.
* the **sensor** (camera frame, 360–830 nm, 1 nm): :func:`sensor_response`,
  :func:`sensor_to_rgb` for ``spectral = "cie1931" | "seed-gaussian" | "rgb"``;
* **hero-wavelength sampling** (Wilkie et al. 2014): :class:`WavelengthSampler`,
  :func:`make_sampler` (an inverse-CDF table, with a uniform part for ``spectral_bands``);
  :meth:`WavelengthSampler.lanes` is a wavefront's whole spectral camera stage in one
  kernel pass (hero λ, pdf, Doppler-shifted table coordinates, D⁵, D's range);
* **tables** for the job keys:

  ==========================================  ==============================================
  job key                                      function
  ==========================================  ==============================================
  ``base_color`` (+ ``reflectance_uv/_ir``)   :func:`rgb_reflectance` (Jakob–Hanika 2019)
  ``emission``, ``scene.background``,         :func:`rgb_illuminant` (scale·s(λ)·D65_ext)
  ``lights.color``
  ``emission_blackbody``                      :func:`blackbody` (Planck, Y = 1)
  ``emission_line``                           :func:`gaussian_line` (unit area)
  ``emission_spectrum``                       :func:`tabulated`
  ``spectral = "seed-gaussian"``              :func:`seed_reflectance`, :func:`flat_emission`
  ==========================================  ==============================================

* helpers: :func:`d65_ext`, :func:`planck`, :func:`y_of`, :func:`rgb_of`,
  :func:`blackbody_rgb`, :func:`sigmoid_coefficients`, :func:`normalised_primary_matrix`.

The CIE source data (CMFs, D65, the sRGB primaries) come from colour-science but are
embedded in :mod:`.cie_tables` (a test keeps them equal), so no render imports
colour-science (1.3 s per process); every derived table is built lazily, in ms.

Conventions.  Wavelengths are in nm.  Sensor integrals are ``∫ r(λ) L(λ) dλ`` over 360–830 nm,
evaluated (here and for every normalisation) as the 1 nm trapezoid rule with the float32
sensor tables and :func:`lookup` of the table, which is what the film's Monte Carlo estimate
converges to.  Emitters are normalised to luminance ``Y = ∫ ȳ L dλ = 1``, so the film maps
an RGB (1, 1, 1) emitter to RGB (1, 1, 1).  The XYZ→Rec.709 matrix is built from the sRGB
primaries and the white point of *our* D65_ext (as pbrt-v4 and Mitsuba 3 do), so a white
reflector under D65 is exactly (1, 1, 1) (the textbook matrix, white 0.3127/0.3290, would
leave it 0.014 ΔE00 off).

Outside the visible.  RGB says nothing about reflectance outside roughly 400–700 nm, yet a
Doppler factor D maps camera wavelengths to ``D·λ``.  The sigmoid's wavelength argument is
clamped to ``SIGMOID_BAND_NM = (380, 720)`` nm: below and above the band the reflectance keeps
its band-edge value, or takes the material's ``reflectance_uv`` / ``reflectance_ir``.  The
band is where the CIE 1931 functions carry essentially all of their weight (380 nm: z̄ =
0.0065 of a 1.78 peak; 720 nm: x̄ = 0.0029 of 1.06), so the clamp costs no reachable colour,
and the fit includes the clamped / overridden tails, so the rest-frame colour still
round-trips exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from ..jit import INLINE, njit
from . import cie_tables as _cie
from . import sigmoid as _sig

# --------------------------------------------------------------------------- the grid
GRID_MIN_NM = 1.0
GRID_MAX_NM = 1.0e5
GRID_N = 16384
LOG_GRID_MIN = math.log(GRID_MIN_NM)
INV_DLOG = (GRID_N - 1) / math.log(GRID_MAX_NM / GRID_MIN_NM)

SENSOR_MIN_NM = 360.0
SENSOR_MAX_NM = 830.0
#: Where spectral-exr bands may lie (camera frame): UV to IR. Its lower end keeps the
#: sampler's 1 nm bins narrow in log λ ((λ - lo)/lo ≤ 1/100, :func:`_lanes_kernel`).
BANDS_RANGE_NM = (100.0, 10000.0)

#: Clamp band of the sigmoid's wavelength argument, nm (see the module docstring).
SIGMOID_BAND_NM = (380.0, 720.0)
#: Sampler floor: no 1 nm bin has a pdf below this fraction of the mean bin value.
SAMPLER_FLOOR = 0.01
#: Default uniform-mix weight when spectral bands are given.
BANDS_UNIFORM_MIX = 0.25
#: Largest value a normalised blackbody table may hold (see blackbody()).
TABLE_CAP = 1.0e20

MODES = ("cie1931", "seed-gaussian", "rgb")

# Physical constants (CODATA 2018, exact SI values).
_H = 6.62607015e-34  # J s
_C = 299792458.0  # m / s
_K = 1.380649e-23  # J / K
_C1 = 2.0 * _H * _C * _C  # W m² / sr
_C2_NM_K = _H * _C / _K * 1e9  # nm K  (hc/k)

# Seed report: eye responses (R, G, B).
SEED_MU_NM = (600.0, 550.0, 450.0)
SEED_SIGMA_NM = (25.0, 25.0, 15.0)

_FIT_VERSION = "jh2019-v1"


def grid_nm() -> np.ndarray:
    """Lab-wavelength grid λ_k = GRID_MIN_NM·(GRID_MAX_NM/GRID_MIN_NM)^(k/(GRID_N-1)), nm (f64)."""
    return _grid().copy()


@lru_cache(maxsize=1)
def _grid() -> np.ndarray:
    k = np.arange(GRID_N, dtype=np.float64)
    return GRID_MIN_NM * (GRID_MAX_NM / GRID_MIN_NM) ** (k / (GRID_N - 1))


def lookup(table: np.ndarray, lam_nm: np.ndarray | float) -> np.ndarray:
    """Linear lookup of grid table(s) (..., GRID_N) at wavelengths λ (nm) -> (..., *λ.shape).

    Fractional index u = (ln λ - LOG_GRID_MIN)·INV_DLOG, clamped to [0, GRID_N-1] (so values
    beyond the grid take the end values; λ ≤ 0 or NaN maps to index 0).  This is the numpy
    reference of the integrator's numba kernel.  Returns float64.
    """
    table = np.asarray(table)
    lam = np.asarray(lam_nm, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (np.log(lam) - LOG_GRID_MIN) * INV_DLOG
    u = np.clip(np.nan_to_num(u, nan=0.0, neginf=0.0, posinf=GRID_N - 1.0), 0.0, GRID_N - 1.0)
    i = np.minimum(u.astype(np.int64), GRID_N - 2)
    f = u - i
    lo = table[..., i].astype(np.float64)
    hi = table[..., i + 1].astype(np.float64)
    return lo + f * (hi - lo)


@lru_cache(maxsize=1)
def _hat_weights() -> np.ndarray:
    """w_k = ∫ φ_k(u(λ)) dλ (nm) for the lookup's hat functions, so ∫ lookup(T) dλ = Σ T_k w_k.

    On a cell λ = λ_k e^{ξδ}, δ = 1/INV_DLOG: ∫₀¹(1-ξ)λ_k e^{ξδ}δ dξ = λ_k (e^δ-1-δ)/δ and
    ∫₀¹ ξ λ_k e^{ξδ}δ dξ = λ_k (δe^δ-e^δ+1)/δ.
    """
    lam = _grid()
    d = 1.0 / INV_DLOG
    left = lam[:-1] * (math.expm1(d) - d) / d  # to node k from cell [k, k+1]
    right = lam[:-1] * (d * math.exp(d) - math.expm1(d)) / d  # to node k+1
    w = np.zeros(GRID_N)
    w[:-1] += left
    w[1:] += right
    return w


# --------------------------------------------------------------------------- the sensor
def sensor_nm() -> np.ndarray:
    """Sensor (camera-frame) wavelengths 360, 361, …, 830 nm (471 values), float64."""
    return np.arange(SENSOR_MIN_NM, SENSOR_MAX_NM + 0.5, 1.0)


def _check_mode(mode: str) -> None:
    if mode not in MODES:
        raise ValueError(f"unknown spectral mode {mode!r}; expected one of {MODES}")


@lru_cache(maxsize=4)
def _sensor_response(mode: str) -> np.ndarray:
    lam = sensor_nm()
    if mode == "cie1931":  # colour-science's table, embedded (see cie_tables)
        return np.ascontiguousarray(_cie.CMF_CIE1931_2.T, dtype=np.float32)
    if mode == "seed-gaussian":
        mu = np.asarray(SEED_MU_NM)[:, None]
        sd = np.asarray(SEED_SIGMA_NM)[:, None]
        g = np.exp(-0.5 * ((lam[None, :] - mu) / sd) ** 2)
        g /= (g @ _trapezoid_1nm())[:, None]  # unit area under the film's 1 nm trapezoid rule
        return g.astype(np.float32)
    raise ValueError(f"spectral mode {mode!r} has no sensor response (expected cie1931 or "
                     "seed-gaussian)")


def sensor_response(mode: str) -> np.ndarray:
    """Channel responses r_c(λ) on :func:`sensor_nm`, float32 (3, 471), per nm.

    "cie1931": CIE 1931 2° x̄ ȳ z̄ (colour-science).  "seed-gaussian": the seed report's eye
    responses, Gaussians μ = (600, 550, 450) nm, σ = (25, 25, 15) nm, each of unit area
    (1 nm trapezoid), so a flat spectrum L = 1 gives (1, 1, 1).
    """
    _check_mode(mode)
    return _sensor_response(mode).copy()


def _trapezoid_1nm() -> np.ndarray:
    w = np.ones(471)
    w[0] = w[-1] = 0.5
    return w


@lru_cache(maxsize=4)
def _sensor_weights(mode: str) -> np.ndarray:
    """Quadrature rows (3, 471): sensor value = Σ_i W[c, i] L(λ_i)."""
    return _sensor_response(mode).astype(np.float64) * _trapezoid_1nm()[None, :]


@lru_cache(maxsize=4)
def _sensor_to_rgb(mode: str) -> np.ndarray:
    if mode != "cie1931":
        return np.eye(3)
    xyz_w = _sensor_weights("cie1931") @ lookup(_d65_ext32(), sensor_nm())
    white_xy = xyz_w[:2] / np.sum(xyz_w)
    rgb_to_xyz = normalised_primary_matrix(_cie.PRIMARIES_SRGB_XY, white_xy)
    return np.linalg.inv(rgb_to_xyz)


def normalised_primary_matrix(primaries_xy: np.ndarray, white_xy: np.ndarray) -> np.ndarray:
    """RGB → XYZ matrix (3, 3) of primaries xy (3, 2) and a white point xy (Y_white = 1).

    colour-science's ``normalised_primary_matrix`` step by step (the same float64 operations,
    so the same bits): columns P = (x, y, 1-x-y) of the primaries, scaled by S = P⁻¹ W with
    W = (x/y, 1, (1-x-y)/y) of the white.
    """
    p = np.asarray(primaries_xy, np.float64).reshape(3, 2)
    prim = np.transpose(np.hstack([p, (1 - p[:, 0] - p[:, 1])[:, None]]))
    x, y = (float(c) for c in np.asarray(white_xy, np.float64))
    y_y = 1.0 / y
    white = np.array([x * y_y, 1.0, (1 - x - y) * y_y])
    return np.dot(prim, np.diagflat(np.dot(np.linalg.inv(prim), white)))


def sensor_to_rgb(mode: str) -> np.ndarray:
    """Matrix (3, 3) float64 from sensor values to linear Rec.709.

    "cie1931": XYZ → linear Rec.709 built by :func:`normalised_primary_matrix` (the same
    bits as colour-science's) from the sRGB primaries and the white point of
    :func:`d65_ext` (its own chromaticity under the 1 nm CMFs, x ≈ 0.31272, y ≈ 0.32903),
    so D65_ext maps to exactly (1, 1, 1).
    Its entries differ from colour-science's sRGB matrix (white 0.3127, 0.3290) by < 1e-3.
    "seed-gaussian" and "rgb": identity.
    """
    _check_mode(mode)
    return _sensor_to_rgb(mode).copy()


def _sensor_values(table: np.ndarray, mode: str) -> np.ndarray:
    return lookup(table, sensor_nm()) @ _sensor_weights(mode).T


def y_of(table: np.ndarray) -> np.ndarray | float:
    """Luminance Y = ∫ ȳ(λ) L(λ) dλ of rest-frame table(s) (..., GRID_N) (CIE 1931 ȳ).

    1 nm trapezoid over 360–830 nm with :func:`lookup`.  Units: those of L times nm.
    """
    y = lookup(table, sensor_nm()) @ _sensor_weights("cie1931")[1]
    return float(y) if np.ndim(y) == 0 else y


def rgb_of(table: np.ndarray, mode: str = "cie1931") -> np.ndarray:
    """Linear Rec.709 (..., 3) of rest-frame table(s) (..., GRID_N): M · ∫ r(λ) L(λ) dλ.

    Evaluated as the film does (1 nm trapezoid, :func:`lookup`); for "seed-gaussian" the
    seed's Gaussian responses with the identity matrix.
    """
    if mode == "rgb":
        raise ValueError("rgb_of: spectral mode 'rgb' has no spectra")
    _check_mode(mode)
    return _sensor_values(table, mode) @ _sensor_to_rgb(mode).T


# --------------------------------------------------------------------------- sampling
INVERSE_CELLS = 8192
"""Cells of the wavelength sampler's inverse-CDF table (u = g / 8192, g = 0 … 8192)."""
_FAST_MATH = {"contract"}
"""The hero kernels' LLVM flag: fused multiply-adds (about 5 ns per path). No
reassociation, which would turn λ_g + f (λ_(g+1) − λ_g) into a difference of products."""
_SERIES_MAX = 0.05
"""Largest (λ − λ_g)/λ_g for which the lanes take ln λ − ln λ_g from a series
(:func:`_lanes_kernel`): its error x⁷/7 < 1.2e-10; wider cells call log1p."""


class HeroLanes(NamedTuple):
    """The spectral part of a wavefront's camera stage (:meth:`WavelengthSampler.lanes`).

    ``lam`` camera-frame hero wavelengths (N, 4) nm, ``pdf`` their pdfs (N, 4) 1/nm (both
    float64, as :meth:`WavelengthSampler.hero`), ``lamu`` the lab-table coordinates (N, 4)
    float32 (as :func:`grid_coordinates`), ``w_d`` the searchlight weight D⁵ or 1 (N,),
    ``d_min`` / ``d_max`` the extremes of D over the rows (inf / 0 for N = 0).
    """

    lam: np.ndarray
    pdf: np.ndarray
    lamu: np.ndarray
    w_d: np.ndarray
    d_min: float
    d_max: float


@dataclass(frozen=True, eq=False)
class WavelengthSampler:
    """Hero-wavelength sampling by an inverse-CDF table (camera frame).

    The *target* pdf is piecewise constant over 1 nm bins: those of [360, 830], or wider
    for UV/IR spectral bands (:func:`sampler_edges`). ``edges_nm`` (K+1,), ``cdf`` (K+1,)
    with cdf[0] = 0, cdf[-1] = 1, ``pdf`` (K,) in 1/nm (K = 470 without bands),
    ∫ pdf dλ = 1.

    The *sampled* pdf is that of its inverse-CDF table: ``inv_nm`` (G+1,) holds
    λ_g = CDF⁻¹(g/G) of the bins (G = :data:`INVERSE_CELLS`), and u ∈ [g/G, (g+1)/G) maps
    linearly to λ ∈ [λ_g, λ_(g+1)), so λ is uniform on that cell with probability 1/G:

        p(λ) = (1/G) / (λ_(g+1) − λ_g)   (``cell_pdf[g]``, :meth:`pdf_at`).

    A cell inside one bin has the bin's pdf (to rounding); a cell across bin edges has a
    value between those of the bins it covers. A lookup is two gathers and no search
    (the renderer's spectral camera stage, :meth:`lanes`: about 23 ns per path against
    42 for the bins' guided search). Arrays are read-only; ``wide`` says whether a cell
    is too wide for :meth:`lanes`' log series (a gap between spectral bands).
    """

    edges_nm: np.ndarray
    cdf: np.ndarray
    pdf: np.ndarray
    inv_nm: np.ndarray = field(init=False, repr=False)
    cell_pdf: np.ndarray = field(init=False, repr=False)
    cell_u: np.ndarray = field(init=False, repr=False)
    cell_rw: np.ndarray = field(init=False, repr=False)
    wide: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        g = INVERSE_CELLS
        # λ_g = the bins' inverse CDF at u = g/G (linear inside a bin; the last node the
        # upper edge of the last bin with mass)
        u = np.arange(g) / g
        b = np.searchsorted(self.cdf, u, side="right") - 1  # cdf[b] ≤ u < cdf[b + 1]
        c0 = self.cdf[b]
        t = np.clip((u - c0) / (self.cdf[b + 1] - c0), 0.0, 1.0)
        top = self.edges_nm[np.flatnonzero(self.pdf > 0.0)[-1] + 1]
        inv = np.append(self.edges_nm[b] + t * (self.edges_nm[b + 1] - self.edges_nm[b]), top)
        width = np.diff(inv)
        if not np.all(width > 0.0):
            raise ValueError("WavelengthSampler: a cell of the inverse-CDF table is empty")
        lo = inv[:-1]
        tables = {"inv_nm": inv, "cell_pdf": (1.0 / g) / width,
                  # for lanes(): the grid coordinate of each cell's lower edge and its
                  # width / edge, so ln λ = ln λ_g + log1p((λ - λ_g)/λ_g) needs no log
                  "cell_u": (np.log(lo) - LOG_GRID_MIN) * INV_DLOG, "cell_rw": width / lo}
        for name, a in tables.items():
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "wide", bool(self.cell_rw.max() > _SERIES_MAX))

    def sample(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Inverse CDF: u ∈ [0, 1] -> (λ nm, p(λ) 1/nm), float64, same shape as u.

        Cell g = ⌊u G⌋ of the table, λ = λ_g + (u G − g)(λ_(g+1) − λ_g), kept below
        λ_(g+1); the returned pdf is exactly ``cell_pdf[g]`` (= :meth:`pdf_at` (λ)).
        """
        u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
        x = u * INVERSE_CELLS
        g = np.minimum(np.floor(x).astype(np.int64), INVERSE_CELLS - 1)
        lo, hi = self.inv_nm[g], self.inv_nm[g + 1]
        lam = np.minimum(lo + (x - g) * (hi - lo), hi * (1.0 - 2.0**-52))
        return lam, self.cell_pdf[g]

    def pdf_at(self, lam_nm: np.ndarray) -> np.ndarray:
        """The sampled pdf (1/nm) at camera wavelengths λ: its cell's; 0 outside
        [λ_0, λ_G)."""
        lam = np.asarray(lam_nm, dtype=np.float64)
        g = np.searchsorted(self.inv_nm, lam, side="right") - 1
        inside = (g >= 0) & (g < INVERSE_CELLS)
        return np.where(inside, self.cell_pdf[np.clip(g, 0, INVERSE_CELLS - 1)], 0.0)

    def hero(self, u: np.ndarray, n: int = 4) -> tuple[np.ndarray, np.ndarray]:
        """n hero wavelengths per u: λ_j = sample((u + j/n) mod 1), -> (λ, pdf), each (N, n).

        The same table lookup as :meth:`sample`, in a numba kernel.
        """
        u = np.ascontiguousarray(np.asarray(u, dtype=np.float64).reshape(-1))
        lam = np.empty((u.shape[0], n))
        pdf = np.empty((u.shape[0], n))
        _hero_kernel(self.inv_nm, self.cell_pdf, u, lam, pdf)
        return lam, pdf

    def lanes(self, u: np.ndarray, D: np.ndarray | None = None, doppler: bool = True,
              searchlight: bool = False,
              out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
              ) -> HeroLanes:
        """A wavefront's spectral camera stage in one pass: :meth:`hero` (4 lanes) fused
        with :func:`grid_coordinates` and the searchlight weight.

        ``u`` (N,) offsets in [0, 1); ``D`` (N,) Doppler factors (None: all 1).  λ and pdf
        equal ``hero(u)`` bit for bit; ``lamu`` equals ``grid_coordinates(λ, D if doppler
        else None)`` up to float32 rounding (ln λ comes from the cell's lower edge and a
        series of degree 6 in (λ - λ_g)/λ_g, error < 1.2e-10, instead of a log per lane);
        ``w_d`` = D⁵ (as D²·D²·D) when ``searchlight``, else 1; and the min / max of D.
        ``out = (lam, pdf, lamu, w_d)``: preallocated C-contiguous outputs ((≥N, 4) f64,
        (≥N, 4) f64, (≥N, 4) f32, (≥N,) f64) whose first N rows are written and returned
        (so a caller can reuse its buffers across wavefronts).
        """
        u = np.ascontiguousarray(u, dtype=np.float64).reshape(-1)
        n = u.shape[0]
        if out is None:
            lam, pdf = np.empty((n, 4)), np.empty((n, 4))
            lamu, w_d = np.empty((n, 4), np.float32), np.empty(n)
        else:
            if any(a.shape[0] < n for a in out) or any(a.shape[1:] != (4,) for a in out[:3]):
                raise ValueError(f"lanes: out buffers too small for {n} rows or not (·, 4)")
            lam, pdf, lamu, w_d = (a[:n] for a in out)
        if D is None:
            d, use_d = u, False  # any float64 (N,) array: not read
        else:
            d, use_d = np.ascontiguousarray(D, dtype=np.float64).reshape(-1), True
            if d.shape[0] != n:
                raise ValueError(f"lanes: D has {d.shape[0]} rows, u has {n}")
        d_min, d_max = _lanes_kernel(self.inv_nm, self.cell_pdf, self.cell_u, self.cell_rw,
                                     self.wide, u, d, use_d,
                                     use_d and doppler, use_d and searchlight,
                                     lam, pdf, lamu, w_d)
        return HeroLanes(lam, pdf, lamu, w_d, d_min, d_max)


def guide_table(cdf: np.ndarray, size: int | None = None) -> np.ndarray:
    """The guide table of a CDF of n bins (``cdf`` (n + 1,), cdf[0] = 0, non-decreasing)
    for :func:`guided_bin`: ``size`` entries (default n), entry g the bin where the
    search for u ≥ g/size may start, the last k with cdf[k] ≤ (g/size)(1 − 2⁻⁴⁰) (clamped
    to [0, n − 1]; the factor keeps it at or below the answer when u·size rounds up to g,
    which a power-of-two size never does). Devroye's indexed search: the environment
    map's sampler."""
    n = len(cdf) - 1
    size = n if size is None else size
    edges = np.arange(size) / size * (1.0 - 2.0**-40)
    return np.clip(np.searchsorted(cdf, edges, side="right") - 1, 0, n - 1).astype(np.int32)


@njit(**INLINE)
def guided_bin(cdf, guide, u):
    """The bin k of a CDF of n bins with cdf[k] ≤ u < cdf[k + 1] (the last such k where
    steps are empty; clamped to [0, n − 1]), u ∈ [0, 1): from the guide table's entry
    for u (:func:`guide_table`) up while cdf[k + 1] ≤ u. Equal to
    ``min(max(searchsorted(cdf, u, "right") - 1, 0), n - 1)``
    (``tests/test_environment.py``), in about n / size steps instead of log₂ n
    dependent loads."""
    n = cdf.shape[0] - 1
    g = guide.shape[0]
    k = np.int64(guide[min(max(int(u * g), 0), g - 1)])
    while k + 1 < n and cdf[k + 1] <= u:
        k += 1
    return k


@njit(**INLINE)
def _cell_lambda(inv_nm, v):
    """(cell g, fraction f in it, λ) of the inverse-CDF table at v ∈ [0, 1)
    (:meth:`WavelengthSampler.sample`'s arithmetic; compiled with a fused multiply-add,
    so λ may differ from it by one ulp, in the same cell with the same pdf). λ is kept
    below the cell's upper node by hi (1 - 2^-52), cheaper than nextafter."""
    cells = np.uint64(inv_nm.shape[0] - 1)
    x = v * cells
    g = min(np.uint64(x), cells - np.uint64(1))  # (unsigned: no negative-index fix-up)
    lo = inv_nm[g]
    hi = inv_nm[g + np.uint64(1)]
    f = x - g
    return g, f, min(lo + f * (hi - lo), hi * (1.0 - 2.0**-52))


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST_MATH)
def _hero_kernel(inv_nm, cell_pdf, u, lam_out, pdf_out):
    """λ_j = the table's λ at (u + j/n) mod 1 for every u (:func:`_cell_lambda`); the
    exact pdf of its cell."""
    n = lam_out.shape[1]
    for i in range(u.shape[0]):
        for j in range(n):
            v = u[i] + j / n
            v = v - math.floor(v)
            g, _, lam_out[i, j] = _cell_lambda(inv_nm, v)
            pdf_out[i, j] = cell_pdf[g]


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST_MATH)
def _lanes_kernel(inv_nm, cell_pdf, cell_u, cell_rw, wide, u, D, use_d, shift_d, searchlight,
                  lam_out, pdf_out, lamu_out, w_d):
    """:func:`_hero_kernel` (n = 4) + :func:`_grid_coordinates` + D⁵ + min/max of D."""
    d_min = math.inf
    d_max = 0.0
    shift = 0.0
    for i in range(u.shape[0]):
        if use_d:
            d = D[i]
            d_min = min(d_min, d)
            d_max = max(d_max, d)
            if shift_d:
                shift = math.log(d)
            if searchlight:
                d2 = d * d
                w_d[i] = d2 * d2 * d
            else:
                w_d[i] = 1.0
        else:
            d_min = min(d_min, 1.0)
            d_max = 1.0
            w_d[i] = 1.0
        ui = u[i]
        if not (ui >= 0.0 and ui < 1.0):  # rare: the kernel's lanes assume u in [0, 1)
            ui = ui - math.floor(ui)
            if not ui < 1.0:
                ui = 0.0
        for j in range(4):
            v = ui + 0.25 * j  # (u + j/4) mod 1, exactly as _hero_kernel
            if v >= 1.0:
                v -= 1.0
            g, f, lam_out[i, j] = _cell_lambda(inv_nm, v)
            pdf_out[i, j] = cell_pdf[g]
            # ln λ - ln λ_g = log1p(x), x = f (λ_(g+1) - λ_g)/λ_g: the series to x⁶ is off
            # by < x⁷/7 < 1.2e-10 for x ≤ 0.05 (the clamp of λ just below the upper node
            # moves it by ~1e-16); a wider cell (``wide``: a gap between spectral bands)
            # takes log1p
            x = f * cell_rw[g]
            l1p = x * (1.0 - x * (0.5 - x * (1.0 / 3.0 - x * (0.25 - x * (0.2 - x / 6.0)))))
            if wide and x > _SERIES_MAX:
                l1p = math.log1p(x)
            lamu_out[i, j] = cell_u[g] + (l1p + shift) * INV_DLOG
    return d_min, d_max


def grid_coordinates(lam_cam: np.ndarray, doppler: np.ndarray | None = None) -> np.ndarray:
    """Fractional grid indices u = (ln λ_lab - LOG_GRID_MIN)·INV_DLOG, float32 (N, k).

    λ_lab = D·λ_cam per row when ``doppler`` (D, (N,)) is given (physics.md: the lab
    wavelength a camera wavelength came from), else λ_lab = λ_cam.
    """
    out = np.empty(lam_cam.shape, np.float32)
    d = np.ones(lam_cam.shape[0]) if doppler is None else np.asarray(doppler, np.float64)
    _grid_coordinates(np.ascontiguousarray(lam_cam, np.float64), d, out)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _grid_coordinates(lam, d, out):
    for i in range(lam.shape[0]):
        shift = math.log(d[i])
        for j in range(lam.shape[1]):
            out[i, j] = (math.log(lam[i, j]) + shift - LOG_GRID_MIN) * INV_DLOG


def sampler_edges(bands: tuple[float, float, float] | None = None) -> np.ndarray:
    """The sampler's 1 nm bin edges: the sensor's [360, 830] nm, widened to whole nm
    around the bands' range [start - step/2, stop + step/2] when ``bands`` are given."""
    lo, hi = SENSOR_MIN_NM, SENSOR_MAX_NM
    if bands is not None:
        start, stop, step = (float(b) for b in bands)
        lo = min(lo, math.floor(start - 0.5 * step))
        hi = max(hi, math.ceil(stop + 0.5 * step))
    return np.arange(lo, hi + 0.5, 1.0)


def make_sampler(
    mode: str = "cie1931",
    bands: tuple[float, float, float] | None = None,
    uniform_mix: float | None = None,
) -> WavelengthSampler:
    """Wavelength sampler for the spectral mode, over the 1 nm bins of
    :func:`sampler_edges` (camera frame).

    Shape: "cie1931": ∝ |r̄|+|ḡ|+|b̄|, the linear-Rec.709 matching functions M·(x̄, ȳ, z̄);
    "seed-gaussian": ∝ the sum of the seed's eye responses; bin value = mean of its two
    end values, floored at ``SAMPLER_FLOOR`` (1 %) of the mean bin value over
    [360, 830] nm so no sensor bin is 0, and 0 outside the sensor's range.
    ``bands = (start, stop, step)`` nm (job key ``spectral_bands``, anywhere in
    ``BANDS_RANGE_NM``, physics.md: UV and IR bands too): the pdf is mixed, with weight
    ``uniform_mix`` (default ``BANDS_UNIFORM_MIX`` = 0.25 when bands are given, else 0),
    with a uniform pdf over [start - step/2, stop + step/2], so every band has samples;
    without bands the domain is the sensor's range.
    """
    _check_mode(mode)
    if mode == "rgb":
        raise ValueError("make_sampler: spectral mode 'rgb' samples no wavelengths")
    if uniform_mix is None:
        uniform_mix = BANDS_UNIFORM_MIX if bands is not None else 0.0
    if not 0.0 <= uniform_mix <= 1.0:
        raise ValueError(f"make_sampler: uniform_mix must be in [0, 1], got {uniform_mix}")
    mixed = bands is not None and uniform_mix > 0.0
    if mixed:
        start, stop, step = (float(b) for b in bands)
        if not (step > 0.0 and stop >= start and start - 0.5 * step >= BANDS_RANGE_NM[0]
                and stop + 0.5 * step <= BANDS_RANGE_NM[1]):
            raise ValueError(f"make_sampler: bad spectral bands {bands} (they must lie in "
                             f"{BANDS_RANGE_NM[0]:g}..{BANDS_RANGE_NM[1]:g} nm)")
    edges = sampler_edges(bands if mixed else None)
    sensor = sensor_nm()
    if mode == "cie1931":
        f = np.sum(np.abs(_sensor_to_rgb(mode) @ _sensor_response(mode).astype(np.float64)), 0)
    else:
        f = np.sum(_sensor_response(mode).astype(np.float64), axis=0)
    f_bin = 0.5 * (f[:-1] + f[1:])
    f_bin = np.maximum(f_bin, SAMPLER_FLOOR * np.mean(f_bin))
    first = int(round(sensor[0] - edges[0]))
    p_sensor = np.zeros(len(edges) - 1)
    p_sensor[first:first + len(f_bin)] = f_bin
    widths = np.diff(edges)
    p = p_sensor / np.sum(p_sensor * widths)
    if mixed:
        lo, hi = start - 0.5 * step, stop + 0.5 * step
        overlap = np.clip(np.minimum(edges[1:], hi) - np.maximum(edges[:-1], lo), 0.0, None)
        p = (1.0 - uniform_mix) * p + uniform_mix * overlap / widths / (hi - lo)
    cdf = np.concatenate([[0.0], np.cumsum(p * widths)])
    p = p / cdf[-1]
    cdf = cdf / cdf[-1]
    cdf[-1] = 1.0
    for a in (edges, cdf, p):
        a.setflags(write=False)
    return WavelengthSampler(edges_nm=edges, cdf=cdf, pdf=p)


# --------------------------------------------------------------------------- emitters
def planck(lam_nm: np.ndarray | float, T_kelvin: float) -> np.ndarray:
    """Planck's law B_λ(λ, T) in W·m⁻²·sr⁻¹·nm⁻¹ (unnormalised), float64.

    B_λ = 2hc²/λ⁵ / (exp(hc/(λkT)) - 1), via ``expm1``; the exponential overflows to inf
    at short λ / low T, which gives exactly 0 (no warning, no NaN).  λ ≤ 0 gives 0.
    Satisfies D⁵ B_λ(Dλ, T) = B_λ(λ, D·T).
    """
    if not T_kelvin > 0.0 or not math.isfinite(T_kelvin):
        raise ValueError(f"planck: temperature must be finite and > 0 K, got {T_kelvin}")
    lam = np.asarray(lam_nm, dtype=np.float64)
    pos = lam > 0.0
    lam_s = np.where(pos, lam, 1.0)
    with np.errstate(over="ignore"):
        x = _C2_NM_K / (lam_s * T_kelvin)
        b = _C1 / (lam_s * 1e-9) ** 5 / np.expm1(x) * 1e-9
    return np.where(pos, b, 0.0)


def blackbody(T_kelvin: float) -> np.ndarray:
    """Rest-frame Planck spectrum at T (K) on the grid, float32 (GRID_N,), normalised to Y = 1.

    Exact Planck shape (float64, then normalised).  A blackbody below about 600 K is
    practically invisible: normalising it to Y = 1 would need values beyond float32, so the
    scale is min(1/Y, TABLE_CAP/max B) (the peak is then TABLE_CAP = 1e20 and Y < 1).
    """
    b = planck(_grid(), T_kelvin)
    peak = float(np.max(b))
    if peak <= 0.0:
        return np.zeros(GRID_N, np.float32)
    y = y_of(b)
    scale = TABLE_CAP / peak if y <= 0.0 else min(1.0 / y, TABLE_CAP / peak)
    return (b * scale).astype(np.float32)


def blackbody_rgb(T_kelvin: float) -> np.ndarray:
    """Linear Rec.709 (3,) of :func:`blackbody` at T (K), at rest (Y = 1 where possible)."""
    return rgb_of(blackbody(T_kelvin))


# CIE D65, 300–830 nm at 5 nm: colour-science's table to 780 nm and, from 785 nm, the CIE
# D-series with the CIE 015 convention (CCT 6500·1.4388/1.4380, M1/M2 rounded), which
# reproduces the tabulated standard to < 1e-3 everywhere.
# The table is embedded in cie_tables (generated from colour-science; importing colour-science
# at run time cost 1.3 s per process).
@lru_cache(maxsize=1)
def _d65_5nm() -> tuple[np.ndarray, np.ndarray]:
    wl = np.arange(300.0, 831.0, 5.0)
    return wl, np.array(_cie.D65_5NM, dtype=np.float64)


@lru_cache(maxsize=1)
def _d65_ext32() -> np.ndarray:
    lam = _grid()
    wl, v = _d65_5nm()
    out = np.zeros(GRID_N)
    mid = (lam >= wl[0]) & (lam <= wl[-1])
    out[mid] = np.interp(lam[mid], wl, v)  # CIE: interpolate the D series linearly
    tail = lam > wl[-1]
    out[tail] = v[-1] * planck(lam[tail], 6504.0) / planck(wl[-1], 6504.0)
    out /= y_of(out)
    out = out.astype(np.float32)
    out.setflags(write=False)
    return out


def d65_ext() -> np.ndarray:
    """D65_ext on the grid, float32 (GRID_N,), normalised to Y = ∫ ȳ D65_ext dλ = 1.

    0 below 300 nm; CIE D65 from 300 to 830 nm (5 nm data, linear in between, as CIE 015
    prescribes for the D series); above 830 nm a Planck 6504 K tail scaled to be continuous
    at 830 nm.
    """
    return _d65_ext32().copy()


def flat_emission() -> np.ndarray:
    """The seed's flat emitter: L(λ) = 1 on the whole grid, float32 (GRID_N,)."""
    return np.ones(GRID_N, np.float32)


def _project(f, lo_nm: float, hi_nm: float, scale_nm: float) -> np.ndarray:
    """Hat-function projection T_k = ∫ f φ_k dλ / ∫ φ_k dλ of f (zero outside [lo, hi]).

    Exactly area-preserving (Σ T_k w_k = ∫ f dλ up to quadrature) and free of aliasing for
    features narrower than the grid: each cell is split into sub-cells no wider than
    scale_nm/4 and integrated with 4-point Gauss–Legendre.
    """
    lo_nm = max(lo_nm, GRID_MIN_NM)
    hi_nm = min(hi_nm, GRID_MAX_NM)
    out = np.zeros(GRID_N)
    if not hi_nm > lo_nm:
        return out
    k0 = max(int(math.floor((math.log(lo_nm) - LOG_GRID_MIN) * INV_DLOG)), 0)
    k1 = min(int(math.ceil((math.log(hi_nm) - LOG_GRID_MIN) * INV_DLOG)), GRID_N - 1)
    k1 = max(k1, k0 + 1)
    lam = _grid()
    h_max = lam[k1] - lam[k1 - 1]
    sub = int(min(max(math.ceil(4.0 * h_max / scale_nm), 1), 4096))
    xg, wg = np.polynomial.legendre.leggauss(4)
    xi = ((np.arange(sub)[:, None] + 0.5 * (xg[None, :] + 1.0)) / sub).ravel()  # in (0, 1)
    wi = np.tile(0.5 * wg / sub, sub)
    d = 1.0 / INV_DLOG
    cells = np.arange(k0, k1)
    lam_q = lam[cells][:, None] * np.exp(xi[None, :] * d)  # (cells, q)
    fq = f(lam_q) * lam_q * d * wi[None, :]  # f dλ
    np.add.at(out, cells, np.sum(fq * (1.0 - xi)[None, :], axis=1))
    np.add.at(out, cells + 1, np.sum(fq * xi[None, :], axis=1))
    return out / _hat_weights()


def gaussian_line(mu_nm: float, sigma_nm: float) -> np.ndarray:
    """Unit-area Gaussian line exp(-(λ-μ)²/2σ²)/(σ√(2π)) on the grid, float32 (GRID_N,).

    When σ is at least the grid spacing at μ (≈ 0.39 nm at 550 nm) the nodes hold point
    values (linear interpolation then widens the variance by only ≈ h²/6: σ = 1 nm reads as
    1.012 nm); narrower lines are tabulated by hat-function projection, so they keep their
    area and centre instead of aliasing.  Either way the table is renormalised so that
    ∫ lookup(table, λ) dλ = 1.  Requires σ > 0 and μ inside the grid.
    """
    mu, sd = float(mu_nm), float(sigma_nm)
    if not (sd > 0.0 and math.isfinite(sd) and GRID_MIN_NM < mu < GRID_MAX_NM):
        raise ValueError(f"gaussian_line: need sigma > 0 and mu inside the grid, got {mu}, {sd}")

    def g(lam):
        return np.exp(-0.5 * ((lam - mu) / sd) ** 2) / (sd * math.sqrt(2.0 * math.pi))

    if sd >= mu * math.expm1(1.0 / INV_DLOG):  # resolved: point values at the nodes
        t = g(_grid())
    else:
        t = _project(g, mu - 12.0 * sd, mu + 12.0 * sd, sd)
    area = float(t @ _hat_weights())
    if not area > 0.0:
        raise ValueError(f"gaussian_line: line ({mu}, {sd}) has no area on the grid")
    return (t / area).astype(np.float32)


def tabulated(nm: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Tabulated spectrum (job key ``emission_spectrum``) on the grid, float32 (GRID_N,).

    Linear interpolation of (nm, values) at the grid nodes, 0 outside [nm[0], nm[-1]].
    Points are sorted; wavelengths must be distinct, positive and finite.  Units are kept
    (W·m⁻²·sr⁻¹·nm⁻¹ by the job format).  Features narrower than the grid spacing
    (0.07 % of λ) are sampled, not averaged.
    """
    x = np.asarray(nm, dtype=np.float64).ravel()
    y = np.asarray(values, dtype=np.float64).ravel()
    if x.shape != y.shape or x.size < 2:
        raise ValueError("tabulated: nm and values need the same length, at least 2")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(x > 0.0)):
        raise ValueError("tabulated: nm must be positive and nm, values finite")
    order = np.argsort(x, kind="stable")
    x, y = x[order], y[order]
    if np.any(np.diff(x) <= 0.0):
        raise ValueError("tabulated: wavelengths must be distinct")
    return np.interp(_grid(), x, y, left=0.0, right=0.0).astype(np.float32)


# --------------------------------------------------------------------------- RGB -> spectrum
@lru_cache(maxsize=1)
def _fit_model() -> _sig.FitModel:
    """The fit's forward model: the film's 1 nm estimate of linear RGB under D65_ext.

    rgb = Σ_i W_i lookup(s, λ_i), W = M · (cmf · lookup(D65_ext) · trapezoid); lookup is
    linear in the table, so rgb = B · s_nodes over the ≈ 940 grid nodes it touches.  Nodes
    below / above the band carry one value each (edge value or override): lumped columns.
    """
    lam1 = sensor_nm()
    W = _sensor_to_rgb("cie1931") @ (_sensor_weights("cie1931") * lookup(_d65_ext32(), lam1))
    u = (np.log(lam1) - LOG_GRID_MIN) * INV_DLOG
    i = np.minimum(u.astype(np.int64), GRID_N - 2)
    f = u - i
    B = np.zeros((GRID_N, 3))
    np.add.at(B, i, (W * (1.0 - f)).T)
    np.add.at(B, i + 1, (W * f).T)
    return _sig.FitModel.from_node_weights(B, _grid(), SIGMOID_BAND_NM, _FIT_VERSION)


def reflectance_fit_model() -> _sig.FitModel:
    """The forward model every reflectance fit uses (:func:`_fit_model`; also the
    texture table's, :mod:`.rgb_table`)."""
    return _fit_model()


#: Fitted coefficients, in memory and in $XDG_CACHE_HOME/relray (see sigmoid_coefficients).
_CACHE = _sig.CoefficientCache(_FIT_VERSION)


def _per_colour(value, n: int, name: str) -> np.ndarray:
    """uv/ir argument -> (n,) float64, NaN = no override, else clamped to [0, 1]."""
    if value is None:
        return np.full(n, np.nan)
    v = np.asarray(value, dtype=np.float64)
    v = np.broadcast_to(v.ravel() if v.ndim else v, (n,)).copy()
    if np.any(np.isinf(v)):
        raise ValueError(f"rgb_reflectance: {name} must be finite or NaN/None")
    return np.where(np.isnan(v), np.nan, np.clip(v, 0.0, 1.0))


def _as_rgb(rgb, name: str) -> np.ndarray:
    a = np.asarray(rgb, dtype=np.float64)
    if a.shape[-1:] != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: rgb must be finite with a last axis of 3, got {a.shape}")
    return a.reshape(-1, 3)


def sigmoid_coefficients(
    rgb: np.ndarray, uv: np.ndarray | float | None = None, ir: np.ndarray | float | None = None
) -> np.ndarray:
    """Jakob–Hanika coefficients (n, 3) for linear Rec.709 reflectances rgb (n, 3) ∈ [0, 1].

    The model s(λ) = ½ + ½x/√(1+x²), x = c0 t² + c1 t + c2, t = (clip(λ, 380, 720) - 380)/340,
    is fitted (batched Levenberg–Marquardt) so that the film's estimate of its colour under
    D65_ext equals rgb (residual < 1e-12 for reachable colours; greys are solved in closed
    form).  rgb is clamped to [0, 1] and rounded to 1e-9 (the cache key).  Results are cached
    in memory and on disk (``$XDG_CACHE_HOME/relray`` or ``~/.cache/relray``; set
    ``RELRAY_DISK_CACHE=0`` to disable; an unwritable cache is ignored).
    """
    a = np.round(np.clip(_as_rgb(rgb, "sigmoid_coefficients"), 0.0, 1.0), 9)
    n = a.shape[0]
    uv_a, ir_a = _per_colour(uv, n, "uv"), _per_colour(ir, n, "ir")
    model = _fit_model()
    tag = model.tag
    _CACHE.load(tag)
    keys = [
        (tag, *a[j], -1.0 if np.isnan(uv_a[j]) else round(float(uv_a[j]), 9),
         -1.0 if np.isnan(ir_a[j]) else round(float(ir_a[j]), 9))
        for j in range(n)
    ]
    missing = sorted({k for k in keys if k not in _CACHE.memory})
    if missing:
        m = np.array([k[1:] for k in missing])
        m_uv = np.where(m[:, 3] < 0.0, np.nan, m[:, 3])
        m_ir = np.where(m[:, 4] < 0.0, np.nan, m[:, 4])
        coeffs = _sig.fit_colours(m[:, :3], m_uv, m_ir, model)
        _CACHE.memory.update(zip(missing, coeffs, strict=True))
        _CACHE.store(tag)
    return np.array([_CACHE.memory[k] for k in keys]).reshape(n, 3)


def rgb_reflectance(
    rgb: np.ndarray, uv: np.ndarray | float | None = None, ir: np.ndarray | float | None = None
) -> np.ndarray:
    """Reflectance spectra for linear Rec.709 albedos (job key ``base_color``), (n, GRID_N) f32.

    Jakob–Hanika 2019 sigmoid s(λ) (see :func:`sigmoid_coefficients`), rest frame of the
    surface.  rgb is clamped to [0, 1] (a reflectance cannot exceed 1); all-zero gives 0,
    greys give the constant grey.  The sigmoid's argument is clamped to SIGMOID_BAND_NM =
    [380, 720] nm; ``uv`` / ``ir`` (scalar or (n,), None/NaN = no override, job keys
    ``reflectance_uv`` / ``reflectance_ir``) replace the value strictly below 380 nm / above
    720 nm.  The fit accounts for the tails, so the colour under D65_ext is rgb either way.
    Every value is finite and in [0, 1] on the whole grid.
    """
    a = _as_rgb(rgb, "rgb_reflectance")
    n = a.shape[0]
    uv_a, ir_a = _per_colour(uv, n, "uv"), _per_colour(ir, n, "ir")
    c = sigmoid_coefficients(a, uv_a, ir_a)
    return _sig.evaluate(c, _grid(), SIGMOID_BAND_NM, uv_a, ir_a).astype(np.float32)


def rgb_illuminant(rgb: np.ndarray) -> np.ndarray:
    """Emission spectrum of an RGB emitter (job keys ``emission``, ``color``), (GRID_N,) f32.

    L(λ) = scale · s(λ) · D65_ext(λ) with scale = 2·max(rgb) and s the sigmoid fit of
    rgb/scale (pbrt-v4's RGBIlluminantSpectrum), so the film sees rgb (Y of white = 1).
    (1, 1, 1) gives exactly D65_ext; negative components are clamped to 0; zero gives 0.
    """
    a = np.clip(_as_rgb(rgb, "rgb_illuminant").reshape(3), 0.0, None)
    scale = 2.0 * float(np.max(a))
    if scale == 0.0:
        return np.zeros(GRID_N, np.float32)
    c = sigmoid_coefficients(a / scale)
    s = _sig.evaluate(c, _grid(), SIGMOID_BAND_NM)[0]
    return (scale * s * _d65_ext32()).astype(np.float32)


def seed_reflectance(rgb: np.ndarray) -> np.ndarray:
    """The seed report's per-channel Gaussian reflectance, (n, GRID_N) float32, in [0, 1].

    f(λ) = min(1, K Σ_i f_i g_i(λ, f_i) / |f|^½),  g_i = N(μ_i, σ_i/f_i) (unit-area Gaussian
    of width σ_i/f_i), |f| the Euclidean norm of rgb, μ = (600, 550, 450) nm,
    σ = (25, 25, 15) nm.  The seed leaves K open; K = √(2π)·25·3^¼ makes each of white's
    red and green terms peak at exactly 1, and the clamp at 1 keeps it a reflectance
    (white is then 1 over 435–465 nm and 541–609 nm, with a dip to 0.1 at 490 nm, and ≈ 0
    beyond ≈ 700 nm; single channels would exceed 1 by 3^¼ without the clamp).
    rgb is clamped to [0, 1]; a zero channel contributes nothing; black gives 0.
    """
    a = np.clip(_as_rgb(rgb, "seed_reflectance"), 0.0, 1.0)
    lam = _grid()
    k = math.sqrt(2.0 * math.pi) * 25.0 * 3.0**0.25
    norm = np.sqrt(np.linalg.norm(a, axis=1))
    out = np.zeros((a.shape[0], GRID_N))
    for ch in range(3):
        f = a[:, ch : ch + 1]
        sd = SEED_SIGMA_NM[ch] / np.where(f > 0.0, f, 1.0)
        g = np.exp(-0.5 * ((lam[None, :] - SEED_MU_NM[ch]) / sd) ** 2) / sd
        out += np.where(f > 0.0, f * g / math.sqrt(2.0 * math.pi), 0.0)
    out = k * out / np.where(norm > 0.0, norm, 1.0)[:, None]
    return np.minimum(out, 1.0).astype(np.float32)
