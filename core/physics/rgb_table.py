"""RGB → reflectance spectrum for texels: the Jakob–Hanika 2019 coefficient table.

A texture has up to millions of colours, far too many for the per-colour fit of
:func:`spectrum.sigmoid_coefficients` (about a millisecond each). As in Jakob and
Hanika 2019 ("A Low-Dimensional Function Space for Efficient Spectral Upsampling",
section 4) and pbrt-v4's ``RGBToSpectrumTable``, the fit is tabulated once over the RGB
cube and interpolated:

- the cube is split by the largest channel l ∈ {R, G, B} into three tables;
- in table l a colour is (z, x, y) with z = rgb[l] (the largest value) and
  x = rgb[l+1]/z, y = rgb[l+2]/z (indices mod 3), all in [0, 1];
- x and y are sampled uniformly at RES points, z at z_k = S(S(k/(RES-1))) with the
  smoothstep S(t) = t²(3 - 2t), which crowds the nodes near black and white where the
  sigmoid's coefficients change fastest;
- each node holds the coefficients (c0, c1, c2) of the fit, and a lookup interpolates
  them trilinearly.

The coefficients are those of :mod:`.spectrum` (the same forward model: the film's
estimate of linear Rec.709 under D65_ext, the sigmoid's argument clamped to
``SIGMOID_BAND_NM``), in the rest frame of the surface::

    s(λ) = ½ + ½ x/√(1 + x²),   x = (c0 t + c1) t + c2,   t = (clip(λ, 380, 720) - 380)/340

so a texel of colour rgb reflects the spectrum a constant ``base_color = rgb`` would, up
to the interpolation (ΔE00 below 0.5 over the cube: ``tests/test_rgb_table.py``).

The fit runs once per machine, one z slice of 64² colours at a time, each slice
starting from the previous slice's solution (Levenberg–Marquardt, :func:`sigmoid.fit`),
and is cached on disk (:func:`coefficient_table`; 9.4 MB). Greys are exact in closed
form; their infinite coefficients (black, white) are clamped to ±:data:`C_MAX`
(reflectance 1e-6 from 0 or 1; the table's white node: :data:`TABLE_WHITE`; its black
nodes: :data:`BLACK_C2`), so every coefficient is finite.
"""

from __future__ import annotations

import logging
import math
import os
import tempfile
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import user_cache_dir
from ..jit import INLINE, njit
from ..resources import usable_cores
from . import sigmoid as _sig
from .spectrum import INV_DLOG, LOG_GRID_MIN, SIGMOID_BAND_NM, reflectance_fit_model

_DLOG = 1.0 / INV_DLOG  # the grid's step in ln λ (a product in the kernels, not a quotient)

RES = 64
#: Greys are clamped to reflectances in [GREY_EPS, 1 - GREY_EPS] (|c2| ≤ C_MAX ≈ 500)
GREY_EPS = 1e-6
#: The white node of the table reflects this, not 1 - GREY_EPS: its neighbours (1, 0.98,
#: 0.98) have c2 ≈ 5, and a corner of c2 ≈ 500 would whiten every colour interpolated
#: next to it (measured: ΔE00 0.61 at (0.992, 0.990, 1.0)). Exact greys, white included,
#: never use the table (:func:`table_coefficients`).
TABLE_WHITE = 1.0 - 1e-3
#: c2 of the table's black nodes (z = 0), whose reflectance is then exactly 0, so blends
#: towards black keep their colour (a 1e-6 grey there: ΔE00 2 at rgb ≈ 1e-6)
BLACK_C2 = -1e30
C_MAX = float(_sig.grey_coefficients(np.array(1.0 - GREY_EPS))[2])
#: the table's fit stops at this RGB residual relative to the slice's largest channel z
#: (an absolute bound would leave the darkest slices, z ≈ 1e-6, unfitted)
FIT_TOL = 1e-8
_VERSION = "jh-table-v4"
#: :func:`coefficients` polishes each colour to this RGB residual, in at most POLISH_ITER
#: steps (ΔE00 < 0.01)
POLISH_TOL = 1e-6
POLISH_ITER = 60
#: the polish's initial Marquardt damping (:func:`sigmoid.fit_one`)
POLISH_MU = 1e-9
_BAND_LO, _BAND_HI = SIGMOID_BAND_NM
_INV_BAND = 1.0 / (_BAND_HI - _BAND_LO)


class CoefficientTable(NamedTuple):
    """The tabulated fit: ``scale`` float32 (RES,), the z nodes; ``data`` float32
    (3, RES, RES, RES, 3), indexed [largest channel, z, y, x, coefficient]."""

    scale: np.ndarray
    data: np.ndarray


def z_nodes(res: int = RES) -> np.ndarray:
    """z_k = S(S(k/(res-1))), S(t) = t²(3 - 2t): the table's nodes of the largest channel."""
    t = np.linspace(0.0, 1.0, res)
    for _ in range(2):
        t = t * t * (3.0 - 2.0 * t)
    return t


def node_colours(largest: int, z: float, res: int = RES) -> np.ndarray:
    """The linear RGB (res², 3) of table ``largest``'s nodes at height z, row-major (y, x)."""
    x = np.linspace(0.0, 1.0, res)
    xx, yy = np.meshgrid(x, x)  # [y, x]
    rgb = np.empty((res * res, 3))
    rgb[:, largest] = z
    rgb[:, (largest + 1) % 3] = (xx * z).ravel()
    rgb[:, (largest + 2) % 3] = (yy * z).ravel()
    return rgb


def build_table(res: int = RES) -> CoefficientTable:
    """Fit every node (module docstring): slices of constant z from z_{res/5} upwards,
    then downwards, each warm-started from its neighbour's solution."""
    model = reflectance_fit_model()
    scale = z_nodes(res)
    data = np.zeros((3, res, res, res, 3))
    none = np.full(res * res, np.nan)
    start = res // 5
    for largest in range(3):
        prev = None
        for k in [*range(start, res), *range(start - 1, -1, -1)]:
            if k == start - 1:
                prev = data[largest, start].reshape(-1, 3)
            rgb = node_colours(largest, scale[k], res)
            grey = np.ptp(rgb, axis=1) == 0.0
            c = np.empty((res * res, 3))
            c[grey] = _sig.grey_coefficients(np.clip(rgb[grey, 0], GREY_EPS, TABLE_WHITE))
            todo = ~grey
            if prev is None:
                c[todo] = _sig.fit_colours(rgb[todo], none[todo], none[todo], model)
            else:
                init = np.clip(prev[todo], -C_MAX, C_MAX)
                c[todo], _ = _sig.fit(rgb[todo], model.t_band, model.B_band, model.b_uv,
                                      model.b_ir, none[todo], none[todo], init,
                                      tol=FIT_TOL * scale[k])
            c = np.clip(np.nan_to_num(c, nan=0.0, posinf=C_MAX, neginf=-C_MAX), -C_MAX, C_MAX)
            if scale[k] == 0.0:  # black: exactly 0 (s(-1e30) = 0 in float64)
                c[:] = (0.0, 0.0, BLACK_C2)
            data[largest, k] = c.reshape(res, res, 3)
            prev = c
    return CoefficientTable(scale.astype(np.float32), data.astype(np.float32))


def _cache_path(res: int) -> Path | None:
    if os.environ.get("RELRAY_DISK_CACHE", "1") == "0":
        return None
    return Path(user_cache_dir()) / f"{_VERSION}-{reflectance_fit_model().tag}-{res}.npz"


@lru_cache(maxsize=2)
def coefficient_table(res: int = RES) -> CoefficientTable:
    """The table, from the disk cache (``user_cache_dir()``; off with
    ``RELRAY_DISK_CACHE=0``) or built by :func:`build_table` (a few minutes, once) and
    stored there atomically. A broken or unwritable cache only costs a rebuild."""
    path = _cache_path(res)
    if path is not None:
        try:
            with np.load(path, allow_pickle=False) as z:
                table = CoefficientTable(z["scale"], z["data"])
            if table.data.shape == (3, res, res, res, 3) and np.all(np.isfinite(table.data)):
                return table
        except Exception:  # noqa: BLE001 - missing or broken: rebuild
            pass
    log = logging.getLogger("relray")
    log.info("building the RGB-to-spectrum table for textures (once per machine) ...")
    table = build_table(res)
    if path is not None:
        _store(path, table)
    return table


def _store(path: Path, table: CoefficientTable) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, scale=table.scale, data=table.data)
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    except OSError as e:
        logging.getLogger("relray").warning(
            "warning: cannot write the RGB-to-spectrum table %s (%s): it is built again "
            "on every run", path, e.strerror or e)


@njit(**INLINE)
def _interval(scale, z):
    """k with scale[k] ≤ z < scale[k+1] (0 ≤ k ≤ len-2; z clamped), by bisection."""
    lo, hi = 0, scale.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if scale[mid] <= z:
            lo = mid
        else:
            hi = mid
    return lo


@njit(**INLINE)
def table_cell(scale, data, r, g, b):
    """Where the linear Rec.709 reflectance (r, g, b) (each clamped to [0, 1]) falls in
    the table: (grey c2 or NaN, largest channel, z, y, x node indices, fz, fy, fx
    fractions). An exact grey returns its closed-form c2 (c0 = c1 = 0) and no cell."""
    r = min(max(r, 0.0), 1.0)
    g = min(max(g, 0.0), 1.0)
    b = min(max(b, 0.0), 1.0)
    if r == g and g == b:
        v = min(max(r, GREY_EPS), 1.0 - GREY_EPS)
        return (2.0 * v - 1.0) / (2.0 * math.sqrt(v * (1.0 - v))), 0, 0, 0, 0, 0.0, 0.0, 0.0
    if r >= g and r >= b:
        big, z, p, q = 0, r, g, b
    elif g >= b:
        big, z, p, q = 1, g, b, r
    else:
        big, z, p, q = 2, b, r, g
    top = data.shape[1] - 1
    x = p / z * top
    y = q / z * top
    xi = min(int(x), top - 1)
    yi = min(int(y), top - 1)
    zi = _interval(scale, z)
    fz = min(max((z - scale[zi]) / (scale[zi + 1] - scale[zi]), 0.0), 1.0)
    return math.nan, big, zi, yi, xi, fz, y - yi, x - xi


@njit(**INLINE)
def table_coefficients(scale, data, r, g, b):
    """(c0, c1, c2) of (r, g, b) interpolated trilinearly in the table (exact for greys).

    An approximation near white, where neighbouring nodes hold sigmoids of different
    shape (a peak against a rising edge: ΔE00 up to ≈ 1); :func:`table_reflectance`
    blends the nodes' spectra instead and is exact. Used as a fit's starting point.
    """
    c2g, big, zi, yi, xi, fz, fy, fx = table_cell(scale, data, r, g, b)
    if not math.isnan(c2g):
        return 0.0, 0.0, c2g
    out0 = out1 = out2 = 0.0
    for dz in range(2):
        wz = fz if dz else 1.0 - fz
        for dy in range(2):
            wy = fy if dy else 1.0 - fy
            for dx in range(2):
                w = wz * wy * (fx if dx else 1.0 - fx)
                out0 += w * data[big, zi + dz, yi + dy, xi + dx, 0]
                out1 += w * data[big, zi + dz, yi + dy, xi + dx, 1]
                out2 += w * data[big, zi + dz, yi + dy, xi + dx, 2]
    return out0, out1, out2


@njit(cache=True, nogil=True, forceinline=True, error_model="numpy", fastmath=False)
def cell_reflectance(data, cell, lam_nm):
    """ρ(λ) of a :func:`table_cell` result: the trilinear blend of its 8 nodes' spectra,

        ρ(λ) = Σ_k w_k s(c_k, λ),

    whose colour is exactly the blend of the nodes' colours, and so exactly (r, g, b):
    the node colours (z, x z, y z) are multilinear in the cell's coordinates, which
    trilinear weights reproduce. Rest frame of the surface. Exact IEEE arithmetic (no
    fast-math, in every kernel too), so that :func:`.textures.cell_reflectance4` gives
    the same values."""
    c2g, big, zi, yi, xi, fz, fy, fx = cell
    if not math.isnan(c2g):
        return sigmoid_reflectance(0.0, 0.0, c2g, lam_nm)
    out = 0.0
    for dz in range(2):
        wz = fz if dz else 1.0 - fz
        for dy in range(2):
            wy = fy if dy else 1.0 - fy
            for dx in range(2):
                w = wz * wy * (fx if dx else 1.0 - fx)
                out += w * sigmoid_reflectance(data[big, zi + dz, yi + dy, xi + dx, 0],
                                               data[big, zi + dz, yi + dy, xi + dx, 1],
                                               data[big, zi + dz, yi + dy, xi + dx, 2], lam_nm)
    return out


@njit(**INLINE)
def table_reflectance(scale, data, r, g, b, lam_nm):
    """ρ(λ) of the reflectance (r, g, b) (:func:`table_cell`, :func:`cell_reflectance`)."""
    return cell_reflectance(data, table_cell(scale, data, r, g, b), lam_nm)


@njit(cache=True, nogil=True, forceinline=True, error_model="numpy", fastmath=False)
def sigmoid_reflectance(c0, c1, c2, lam_nm):
    """s(λ) = ½ + ½ x/√(1+x²), x = (c0 t + c1) t + c2, t = (clip(λ, 380, 720) - 380)/340
    (rest frame of the surface; module docstring)."""
    t = band_coordinate(lam_nm)
    x = (c0 * t + c1) * t + c2
    return 0.5 + 0.5 * x / math.sqrt(1.0 + x * x)


@njit(cache=True, nogil=True, forceinline=True, error_model="numpy", fastmath=False)
def band_coordinate(lam_nm):
    """t = (clip(λ, 380, 720) - 380)/340: where the wavelength λ (nm) falls in the
    sigmoid's band (:func:`sigmoid_reflectance`)."""
    return (min(max(lam_nm, _BAND_LO), _BAND_HI) - _BAND_LO) * _INV_BAND


@njit(**INLINE)
def lambda_of_column(u):
    """λ in nm of the fractional column u of :mod:`.spectrum`'s log-spaced lab grid
    (the kernels' ``lamu``): exp(ln λ_min + u / INV_DLOG)."""
    return math.exp(LOG_GRID_MIN + u * _DLOG)


# exp(x) = 2ⁿ e^r for lambda_of_grid_column: ln 2 in two parts (Cody–Waite: n·_LN2_HI is
# exact for |n| < 2¹¹) and the Taylor coefficients 1/k!, k = 0 … 13
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.0 / math.log(2.0)
_EXP_TAYLOR = tuple(1.0 / math.factorial(k) for k in range(14))


@njit(cache=True, nogil=True, forceinline=True, error_model="numpy",
      fastmath={"contract"})
def lambda_of_grid_column(u):
    """:func:`lambda_of_column` as straight-line code, for u on the grid (0 ≤ u ≤
    GRID_N − 1, λ from 1 nm to 100 µm): x = ln λ_min + u / INV_DLOG ∈ [0, ln 10⁵],
    n = round(x / ln 2) ∈ [0, 17], r = x − n ln 2 (|r| ≤ ln 2 / 2, ln 2 in two parts),
    e^r by its Taylor series through r¹³ (remainder < 4e-18) and 2ⁿ as a product of
    selects over n's five bits (exact), so λ = 2ⁿ e^r within 4e-16 of libm's ``exp``
    (``tests/test_rgb_table.py``). libm's ``exp`` is a call that leaves a loop over the
    SIMD lanes scalar; this one vectorises (the lanes' refill, :mod:`..render.lane_paths`).
    Contractions only (no reassociation, which would merge ln 2's two parts), in the
    lanes too."""
    x = LOG_GRID_MIN + u * _DLOG
    n = np.int64(x * _INV_LN2 + 0.5)
    fn = np.float64(n)
    r = (x - fn * _LN2_HI) - fn * _LN2_LO
    p = _EXP_TAYLOR[13]
    for k in range(12, -1, -1):
        p = p * r + _EXP_TAYLOR[k]
    two_n = (2.0 if n & 1 else 1.0) * (4.0 if n & 2 else 1.0) * (16.0 if n & 4 else 1.0) \
        * (256.0 if n & 8 else 1.0) * (65536.0 if n & 16 else 1.0)
    return two_n * p


# ln m = 2 atanh(s), s = (m - 1)/(m + 1), |s| ≤ 3 - 2√2 for m in [1/√2, √2]: the series'
# coefficients 1/(2k + 1), k = 0 … 10 (the next term is below 2⁻⁵⁷ of the sum)
_ATANH_SERIES = tuple(1.0 / (2 * k + 1) for k in range(11))
_SQRT2 = math.sqrt(2.0)


@njit(**INLINE)
def _exponent_step(m, e, k):
    """m · 2⁻ᵏ, e + k where m ≥ 2ᵏ; m · 2ᵏ, e − k where m < 2⁻ᵏ; else m, e (selects)."""
    big, small = 2.0 ** k, 2.0 ** -k
    up = m >= big
    m = m * small if up else m
    e = e + k if up else e
    down = m < small
    return (m * big if down else m), (e - k if down else e)


@njit(cache=True, nogil=True, forceinline=True, error_model="numpy",
      fastmath={"contract"})
def doppler_columns(D):
    """The columns of :mod:`.spectrum`'s log-spaced lab grid by which a Doppler factor D
    shifts a lane, ln(D) · INV_DLOG (the kernels' frame changes,
    ``integrator.frame_change``), as straight-line code: D = 2ᵉ m with e an integer
    taken out by selects (steps of 2³², 2¹⁶, …, 2 each way, exact) and m in [1/√2, √2],
    then ln m = 2 atanh s, s = (m − 1)/(m + 1) (|s| ≤ 0.172), by its series through
    s²¹, and e ln 2 with ln 2 in two parts: within a few units in the last place of libm's
    ``log`` (``tests/test_rgb_table.py``). D must lie in [2⁻⁶³, 2⁶³]: a Doppler factor
    of |β| < 1 in float64 lies within [1e-8, 1e8], the product of two within 2^±54.
    libm's ``log`` is a call that leaves a loop over the SIMD lanes scalar; this one
    vectorises (the moving bodies' lanes, :mod:`..render.lane_paths`). Contractions only
    (no reassociation, which would merge ln 2's two parts), in the lanes too."""
    m, e = _exponent_step(np.float64(D), 0.0, 32.0)
    m, e = _exponent_step(m, e, 16.0)
    m, e = _exponent_step(m, e, 8.0)
    m, e = _exponent_step(m, e, 4.0)
    m, e = _exponent_step(m, e, 2.0)
    m, e = _exponent_step(m, e, 1.0)
    # m in [2⁻¹, 2): into [1/√2, √2]
    hi = m > _SQRT2
    m = m * 0.5 if hi else m
    e = e + 1.0 if hi else e
    lo = m < 1.0 / _SQRT2
    m = m * 2.0 if lo else m
    e = e - 1.0 if lo else e
    s = (m - 1.0) / (m + 1.0)
    s2 = s * s
    p = _ATANH_SERIES[10]
    for k in range(9, -1, -1):
        p = p * s2 + _ATANH_SERIES[k]
    return ((e * _LN2_HI + 2.0 * s * p) + e * _LN2_LO) * INV_DLOG


@njit(cache=True, nogil=True, error_model="numpy")
def _coefficients_kernel(scale, data, rgb, out):
    for i in range(rgb.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = table_coefficients(scale, data, rgb[i, 0],
                                                             rgb[i, 1], rgb[i, 2])


@njit(cache=True, nogil=True, error_model="numpy")
def _clamped_rows(rgb, out):
    """out (n, 3) = rgb clamped to [0, 1], NaN (and -0.0) as 0."""
    for i in range(rgb.shape[0]):
        for j in range(3):
            v = rgb[i, j]
            out[i, j] = min(max(v, 0.0), 1.0) + 0.0 if v == v else 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def _first_occurrence(rows, bits, first, inverse):
    """Open-addressing hash of the rows (n, 3) (``bits``: their uint64 view): the distinct
    rows' first indices in ``first`` (returns how many), each row's distinct index in
    ``inverse``. Equal values have equal bits here (no NaN, no -0.0). The table holds
    distinct index + 1 (0: empty) in ≥ 2n uint32 slots (≤ 16 bytes per row)."""
    n = rows.shape[0]
    size = 1
    while size < 2 * n:
        size *= 2
    mask = np.uint64(size - 1)
    slots = np.zeros(size, np.uint32)
    count = 0
    for i in range(n):
        h = bits[i, 0] * np.uint64(0x9E3779B97F4A7C15)
        h = (h ^ (h >> np.uint64(29))) + bits[i, 1] * np.uint64(0xBF58476D1CE4E5B9)
        h = (h ^ (h >> np.uint64(31))) + bits[i, 2] * np.uint64(0x94D049BB133111EB)
        k = (h ^ (h >> np.uint64(32))) & mask
        while True:
            d = np.int64(slots[k]) - 1
            if d < 0:
                slots[k] = np.uint32(count + 1)
                first[count] = i
                inverse[i] = count
                count += 1
                break
            j = first[d]
            if rows[j, 0] == rows[i, 0] and rows[j, 1] == rows[i, 1] \
                    and rows[j, 2] == rows[i, 2]:
                inverse[i] = d
                break
            k = (k + np.uint64(1)) & mask
    return count


def distinct_rows(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distinct, inverse) of rgb (n, 3) clamped to [0, 1] (NaN as 0): the distinct
    clamped rows (in order of first appearance) and each row's index among them, so
    clamped[i] == distinct[inverse[i]].

    One pass through a hash table (:func:`_first_occurrence`), where
    ``np.unique(axis=0)`` sorts the rows (7 s for 2 M rows; 2 s through a void view)."""
    a = np.ascontiguousarray(rgb, np.float64)
    clamped = np.empty(a.shape)
    _clamped_rows(a, clamped)
    first = np.empty(a.shape[0], np.int64)
    inverse = np.empty(a.shape[0], np.int64)
    count = _first_occurrence(clamped, clamped.view(np.uint64), first, inverse)
    return clamped[first[:count]], inverse


@njit(cache=True, nogil=True, error_model="numpy")
def _polish_range(target, coeffs, lo, hi, t_band, B_band, t32, B32, b_uv, b_ir):
    """:func:`sigmoid.fit_one` (no overrides; :data:`POLISH_TOL`, :data:`POLISH_ITER`) of
    rows lo..hi-1 of target (n, 3), starting from and overwriting coeffs (n, 3); exact
    greys (r = g = b) are left as they are. First nearly undamped (μ0 =
    :data:`POLISH_MU`); a colour that misses the tolerance so (a start far off, e.g. a
    saturated colour whose table start sits at the ±C_MAX clamp, where undamped steps
    run away) starts again from the table with :func:`sigmoid.fit`'s μ0 = 1e-3, and the
    better of the two is kept."""
    c = np.empty(3)
    d = np.empty(3)
    for i in range(lo, hi):
        if target[i, 0] == target[i, 1] and target[i, 1] == target[i, 2]:
            continue
        c[0], c[1], c[2] = coeffs[i, 0], coeffs[i, 1], coeffs[i, 2]
        err = _sig.fit_one(target[i], t_band, B_band, t32, B32, b_uv, b_ir, math.nan,
                           math.nan, c, POLISH_TOL, POLISH_ITER, POLISH_MU)
        if err > POLISH_TOL:
            d[0], d[1], d[2] = coeffs[i, 0], coeffs[i, 1], coeffs[i, 2]
            if _sig.fit_one(target[i], t_band, B_band, t32, B32, b_uv, b_ir, math.nan,
                            math.nan, d, POLISH_TOL, POLISH_ITER, 1e-3) < err:
                c[:] = d
        coeffs[i, 0], coeffs[i, 1], coeffs[i, 2] = c[0], c[1], c[2]


def _polish(target: np.ndarray, coeffs: np.ndarray, chunk: int = 16384) -> None:
    """:func:`_polish_range` over all rows, in chunks on the usable cores (the kernel
    releases the GIL)."""
    m = reflectance_fit_model()
    t32, B32 = m.t_band.astype(np.float32), m.B_band.astype(np.float32)

    def run(lo: int) -> None:
        _polish_range(target, coeffs, lo, min(lo + chunk, len(target)), m.t_band, m.B_band,
                      t32, B32, m.b_uv, m.b_ir)

    starts = range(0, len(target), chunk)
    workers = min(usable_cores(), len(starts))
    if workers <= 1:
        for lo in starts:
            run(lo)
        return
    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(run, starts))


def coefficients(rgb: np.ndarray, table: CoefficientTable | None = None) -> np.ndarray:
    """Sigmoid coefficients (..., 3) float32 of linear Rec.709 reflectances rgb (..., 3)
    (clamped to [0, 1]; NaN counts as 0), for per-texel precomputation (environment
    maps, emission): :func:`table_coefficients` as the start of a compiled
    Levenberg–Marquardt polish (:func:`sigmoid.fit_one`, μ0 = :data:`POLISH_MU`: in
    effect Gauss–Newton) to an RGB residual of :data:`POLISH_TOL` (ΔE00 < 0.01), so near
    white too the colour is right. Only the distinct colours are fitted
    (:func:`distinct_rows`), on every usable core.

    Measured (``bench/env_prepare.py``, a 2048 × 1024 map of 2 M distinct colours):
    7 s of CPU in all (≈ 2.5 µs per colour for the polish, two float64 model evaluations
    and one float32 Jacobian), where the numpy :func:`sigmoid.fit` polish took 190 s.
    Every table start misses POLISH_TOL (its residual is ≈ 2e-4); ~90 % of the colours
    converge in one step, nearly all in two."""
    a = np.asarray(rgb, np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"coefficients: rgb needs a last axis of 3, got {a.shape}")
    t = coefficient_table() if table is None else table
    distinct, inverse = distinct_rows(a.reshape(-1, 3))
    out = np.empty(distinct.shape, np.float64)
    _coefficients_kernel(t.scale, t.data, distinct, out)
    _polish(distinct, out)
    return out.astype(np.float32)[inverse].reshape(a.shape)
