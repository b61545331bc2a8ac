"""The Jakob–Hanika 2019 sigmoid-polynomial reflectance model and its batched fit.

Helpers for :mod:`relray.core.spectrum` (which owns the public API: ``rgb_reflectance``,
``rgb_illuminant``); this module is pure numpy maths and knows nothing about CMFs or D65.

Model (Jakob and Hanika 2019, "A Low-Dimensional Function Space for Efficient Spectral
Upsampling")::

    s(λ) = ½ + ½ x / sqrt(1 + x²),     x = c0 t² + c1 t + c2,
    t    = (clip(λ, lo, hi) - lo) / (hi - lo)            (dimensionless, in [0, 1])

so the coefficients ``c = (c0, c1, c2)`` act on the wavelength normalised to the clamp band
``[lo, hi]`` nm.  Clamping the argument keeps the reflectance constant (at its band-edge
values) outside the band, where RGB carries no information (physics.md, "Outside the
visible"); a material may instead override the value below (UV) or above (IR) the band.

The fit is a batched Levenberg–Marquardt solve of the square 3×3 system
``B · v(c) = rgb_target`` for every colour at once, where ``B`` maps the reflectance values
on a set of nodes to linear RGB (it contains the CMFs, D65, the XYZ→RGB matrix and the
quadrature).  Greys are solved in closed form (constant reflectance), black is exactly 0.
Measured: 0.4–0.8 ms per colour in batches of 1e3–1e4, about 14 ms for a single colour; the
whole sRGB cube [0, 1]³ converges (residual < 1e-12), including its corners.

Also here: :class:`FitModel` (the lumped forward model), :class:`CoefficientCache` (the
in-memory / on-disk cache of fitted coefficients), and the compiled per-colour fit
:func:`fit_one` (the same Levenberg–Marquardt steps, for millions of colours from a close
start: :func:`..rgb_table.coefficients`, about 2.5 µs of CPU per colour where the numpy
batches take 50–200 µs).
"""

from __future__ import annotations

import hashlib
import logging
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import user_cache_dir
from ..jit import INLINE, njit

# A colour counts as converged when every RGB residual is below this (absolute, linear RGB).
# 1e-12 is ~1e4 float64 ulps of a unit value and far below what any ΔE00 can resolve
# (ΔE00 ≈ 1e-9 even at L* = 1).
FIT_TOL = 1e-12
FIT_MAX_ITER = 200


def sigmoid(x: np.ndarray) -> np.ndarray:
    """s(x) = ½ + ½ x/sqrt(1+x²), evaluated without cancellation or NaN for any x (±inf too).

    For x < 0 the identity ½(1 + x/r) = ½ / (r (r - x)) with r = sqrt(1+x²) avoids the
    cancellation; s(x) = 1 - s(-x) gives the other half.  Result in [0, 1].
    """
    x = np.asarray(x, dtype=np.float64)
    y = -np.abs(x)
    with np.errstate(over="ignore"):
        r = np.sqrt(1.0 + y * y)
        low = 0.5 / (r * (r - y))  # s(-|x|), in [0, ½]
    return np.where(x < 0.0, low, 1.0 - low)


def sigmoid_derivative(x: np.ndarray) -> np.ndarray:
    """ds/dx = ½ (1 + x²)^(-3/2); 0 at x = ±inf."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(over="ignore"):
        r = np.sqrt(1.0 + x * x)
        return 0.5 / (r * r * r)


@njit(cache=True, nogil=True, error_model="numpy")
def _sigmoid_pair(x, s, ds):
    """s(x) (as :func:`sigmoid`) and ds/dx (as :func:`sigmoid_derivative`) in one pass."""
    flat, fs, fds = x.ravel(), s.ravel(), ds.ravel()
    for i in range(flat.shape[0]):
        v = flat[i]
        y = -abs(v)
        r = math.sqrt(1.0 + y * y)
        low = 0.5 / (r * (r - y))
        fs[i] = low if v < 0.0 else 1.0 - low
        fds[i] = 0.5 / (r * r * r)


def sigmoid_and_derivative(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s(x), ds/dx) for a float64 array, fused (the fit's inner loop)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    s, ds = np.empty_like(x), np.empty_like(x)
    _sigmoid_pair(x, s, ds)
    return s, ds


def grey_coefficients(g: np.ndarray) -> np.ndarray:
    """Coefficients (0, 0, c2) of the constant reflectance g ∈ [0, 1]: s(c2) = g.

    c2 = (2g - 1) / (2 sqrt(g (1 - g))); g = 0 gives -inf and g = 1 gives +inf (exact 0 / 1).
    """
    g = np.clip(np.asarray(g, dtype=np.float64), 0.0, 1.0)
    with np.errstate(divide="ignore"):
        c2 = (2.0 * g - 1.0) / (2.0 * np.sqrt(g * (1.0 - g)))
    out = np.zeros(g.shape + (3,))
    out[..., 2] = c2
    return out


def band_t(lam_nm: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Normalised, clamped wavelength t = (clip(λ, lo, hi) - lo)/(hi - lo) ∈ [0, 1]."""
    lo, hi = band
    return (np.clip(np.asarray(lam_nm, dtype=np.float64), lo, hi) - lo) / (hi - lo)


def evaluate(
    coeffs: np.ndarray,
    lam_nm: np.ndarray,
    band: tuple[float, float],
    uv: np.ndarray | None = None,
    ir: np.ndarray | None = None,
) -> np.ndarray:
    """Reflectance s(λ) for coefficients (n, 3) at wavelengths λ (m,) nm -> (n, m) float64.

    ``uv``/``ir`` (n,) replace the value strictly below ``lo`` / strictly above ``hi`` where
    they are finite (NaN means no override).  Coefficients may be ±inf only in c2 (greys 0/1).
    """
    c = np.asarray(coeffs, dtype=np.float64).reshape(-1, 3)
    lam = np.asarray(lam_nm, dtype=np.float64)
    t = band_t(lam, band)
    # Horner form; c0 = c1 = 0 for the infinite grey coefficients, so no inf*0 appears.
    x = (c[:, 0:1] * t + c[:, 1:2]) * t + c[:, 2:3]
    s = sigmoid(x)
    for value, mask in ((uv, lam < band[0]), (ir, lam > band[1])):
        if value is None:
            continue
        v = np.asarray(value, dtype=np.float64).reshape(-1, 1)
        v = np.broadcast_to(v, (c.shape[0], 1))
        s = np.where(mask[None, :] & np.isfinite(v), v, s)
    return s


@dataclass(frozen=True, eq=False)
class FitModel:
    """Forward model of the fit: rgb = B_band · s(t_band) + b_uv · v_uv + b_ir · v_ir.

    t_band (m,) normalised wavelengths of the grid nodes inside the band, B_band (3, m) their
    RGB weights; b_uv, b_ir (3,) the summed weights of the nodes below / above the band
    (which all hold one value: the band-edge value or the override).  ``tag`` hashes the
    weights, band and version (the disk-cache key).
    """

    t_band: np.ndarray
    B_band: np.ndarray
    b_uv: np.ndarray
    b_ir: np.ndarray
    tag: str

    @classmethod
    def from_node_weights(
        cls, B: np.ndarray, lam_nodes: np.ndarray, band: tuple[float, float], version: str
    ) -> FitModel:
        """Lump per-node RGB weights B (N, 3) on nodes at λ (N,) nm into a FitModel."""
        used = np.flatnonzero(np.any(B != 0.0, axis=1))
        lam = lam_nodes[used]
        below, above = lam < band[0], lam > band[1]
        inside = ~(below | above)
        tag = hashlib.sha1(B.tobytes() + repr((band, version)).encode()).hexdigest()[:16]
        return cls(
            t_band=band_t(lam[inside], band),
            B_band=np.ascontiguousarray(B[used[inside]].T),
            b_uv=B[used[below]].sum(axis=0),
            b_ir=B[used[above]].sum(axis=0),
            tag=tag,
        )


def fit_colours(target: np.ndarray, uv: np.ndarray, ir: np.ndarray, model: FitModel) -> np.ndarray:
    """Coefficients (n, 3) for linear-RGB targets (n, 3) in [0, 1] under ``model``.

    Greys without overrides are exact in closed form (black -> c2 = -inf, white -> +inf);
    the others start from the grey of their luminance and go through :func:`fit`.
    uv, ir (n,): overrides, NaN = none.
    """
    target = np.asarray(target, dtype=np.float64)
    coeffs = np.zeros((target.shape[0], 3))
    no_override = np.isnan(uv) & np.isnan(ir)
    grey = (target[:, 0] == target[:, 1]) & (target[:, 1] == target[:, 2]) & no_override
    coeffs[grey] = grey_coefficients(target[grey, 0])
    todo = np.flatnonzero(~grey)
    if todo.size:
        y = target[todo] @ np.array([0.2126, 0.7152, 0.0722])
        init = grey_coefficients(np.clip(y, 1e-3, 1.0 - 1e-3))
        coeffs[todo], _ = fit(
            target[todo], model.t_band, model.B_band, model.b_uv, model.b_ir,
            uv[todo], ir[todo], init,
        )
    return coeffs


def _model(c, t, basis, B_band, b_uv, b_ir, uv, ir):
    """rgb(c) (k, 3) and its Jacobian (k, 3, 3) for the lumped node model (see fit())."""
    x = c @ basis.T  # (k, m): c0 t² + c1 t + c2 on the band nodes
    s, ds = sigmoid_and_derivative(x)
    rgb = s @ B_band.T
    J = np.einsum("km,cm,mj->kcj", ds, B_band, basis, optimize=True)
    # UV lump: nodes below the band carry s(t = 0) = s(c2) unless overridden.
    for b_lump, override, dxdc in ((b_uv, uv, (0.0, 0.0, 1.0)), (b_ir, ir, (1.0, 1.0, 1.0))):
        free = ~np.isfinite(override)
        x_edge = c @ np.asarray(dxdc)
        val = np.where(free, sigmoid(x_edge), override)
        rgb += val[:, None] * b_lump[None, :]
        d_edge = np.where(free, sigmoid_derivative(x_edge), 0.0)
        J += (d_edge[:, None, None] * b_lump[None, :, None]) * np.asarray(dxdc)[None, None, :]
    return rgb, J


def fit(
    target: np.ndarray,
    t_band: np.ndarray,
    B_band: np.ndarray,
    b_uv: np.ndarray,
    b_ir: np.ndarray,
    uv: np.ndarray,
    ir: np.ndarray,
    init: np.ndarray,
    tol: float = FIT_TOL,
    max_iter: int = FIT_MAX_ITER,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched Levenberg–Marquardt fit of sigmoid coefficients to linear-RGB targets.

    The forward model is ``rgb = B_band · s(x(t_band)) + b_uv · v_uv + b_ir · v_ir`` with
    ``v_uv = uv`` where finite else s(t=0), ``v_ir = ir`` where finite else s(t=1).

    target (n, 3); t_band (m,) normalised band wavelengths of the nodes; B_band (3, m);
    b_uv, b_ir (3,) the lumped weights of the nodes below / above the band; uv, ir (n,)
    overrides (NaN = none); init (n, 3) starting coefficients.
    Returns (coeffs (n, 3), max-abs RGB residual (n,)).  Unreachable targets (for example a
    channel exactly 0 next to a non-zero one) end at the least-squares best after max_iter.
    """
    target = np.asarray(target, dtype=np.float64)
    c = np.array(init, dtype=np.float64, copy=True)
    n = target.shape[0]
    basis = np.stack([t_band * t_band, t_band, np.ones_like(t_band)], axis=1)  # (m, 3)
    mu = np.full(n, 1e-3)
    resid = np.full(n, np.inf)
    active = np.arange(n)
    rgb, J = _model(c, t_band, basis, B_band, b_uv, b_ir, uv, ir)
    r = rgb - target
    cost = np.sum(r * r, axis=1)
    eye = np.eye(3)
    for _ in range(max_iter):
        err = np.max(np.abs(r), axis=1)
        resid[active] = err
        keep = err > tol
        if not np.any(keep):
            break
        active, r, J, cost = active[keep], r[keep], J[keep], cost[keep]
        ca = c[active]
        JT = np.swapaxes(J, 1, 2)
        JTJ = JT @ J
        g = np.einsum("kji,kj->ki", J, r)
        diag = np.einsum("kii->ki", JTJ)
        # Marquardt scaling (damp each parameter by its own curvature), plus a tiny
        # absolute term so a flat direction (saturated sigmoid) never makes A singular.
        A = JTJ + (mu[active][:, None] * diag + 1e-300)[:, :, None] * eye[None]
        A += 1e-14 * np.max(diag, axis=1)[:, None, None] * eye[None]
        delta = -np.linalg.solve(A, g[:, :, None])[:, :, 0]
        c_new = ca + delta
        ok = np.all(np.isfinite(c_new), axis=1)
        c_new[~ok] = ca[~ok]
        rgb_n, J_n = _model(
            c_new, t_band, basis, B_band, b_uv, b_ir, uv[active], ir[active]
        )
        r_n = rgb_n - target[active]
        cost_n = np.sum(r_n * r_n, axis=1)
        better = ok & (cost_n < cost)
        c[active[better]] = c_new[better]
        r = np.where(better[:, None], r_n, r)
        J = np.where(better[:, None, None], J_n, J)
        cost = np.where(better, cost_n, cost)
        mu[active] = np.where(better, np.maximum(mu[active] / 3.0, 1e-12),
                              np.minimum(mu[active] * 4.0, 1e12))
        # A colour whose damping ran away has stalled (an unreachable target): stop it.
        stalled = mu[active] >= 1e12
        if np.any(stalled):
            resid[active[stalled]] = np.max(np.abs(r[stalled]), axis=1)
            live = ~stalled
            active, r, J, cost = active[live], r[live], J[live], cost[live]
    else:
        resid[active] = np.max(np.abs(r), axis=1)
    return c, resid


class CoefficientCache:
    """Fitted coefficients in memory, mirrored to one ``.npz`` file per model tag on disk.

    Keys are tuples ``(tag, r, g, b, uv, ir)`` (uv/ir = -1 for no override), values (3,)
    coefficients.  The file is ``<version>-<tag>.npz`` in ``relray.core.user_cache_dir()``
    (``$XDG_CACHE_HOME``, ``%LOCALAPPDATA%`` or ``~/.cache``, then ``relray``), disabled by
    ``RELRAY_DISK_CACHE=0``.  Writes are atomic (temp file, then rename); a missing, broken
    or unwritable cache only costs a refit, never an error.
    """

    def __init__(self, version: str):
        self.version = version
        self.memory: dict[tuple, np.ndarray] = {}
        self._loaded: set[str] = set()
        self._warned = False

    def path(self, tag: str) -> Path | None:
        """The cache file for a model tag, or None when the disk cache is disabled."""
        if os.environ.get("RELRAY_DISK_CACHE", "1") == "0":
            return None
        return Path(user_cache_dir()) / f"{self.version}-{tag}.npz"

    def load(self, tag: str) -> None:
        """Merge the file for ``tag`` into memory (once per path)."""
        path = self.path(tag)
        if path is None or str(path) in self._loaded:
            return
        self._loaded.add(str(path))
        try:
            with np.load(path, allow_pickle=False) as z:
                keys, coeffs = z["keys"], z["coeffs"]
            for k, c in zip(keys, coeffs, strict=True):
                self.memory.setdefault((tag, *map(float, k)), np.asarray(c, np.float64))
        except Exception:  # noqa: BLE001 - a missing or broken cache is simply refitted
            pass

    def store(self, tag: str) -> None:
        """Write every in-memory entry of ``tag`` to its file (atomically)."""
        path = self.path(tag)
        if path is None:
            return
        items = [(k[1:], v) for k, v in self.memory.items() if k[0] == tag]
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            keys = np.array([k for k, _ in items], dtype=np.float64).reshape(-1, 5)
            coeffs = np.array([v for _, v in items], dtype=np.float64).reshape(-1, 3)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
            try:
                with os.fdopen(fd, "wb") as fh:
                    np.savez(fh, keys=keys, coeffs=coeffs)
                os.replace(tmp, path)
            finally:
                if os.path.exists(tmp):
                    os.unlink(tmp)
        except Exception as e:  # noqa: BLE001 - an unwritable cache only costs a refit
            if not self._warned:
                self._warned = True
                why = getattr(e, "strerror", None) or " ".join(str(e).split())
                logging.getLogger("relray").warning(
                    "warning: cannot write the spectrum cache %s (%s): spectra are fitted "
                    "again on every run", path, why)


# ------------------------------------------------------------ compiled per-colour fit
#: The compiled fit's sums over the band nodes may be reordered (vectorised); the
#: sigmoid itself is evaluated exactly as :func:`sigmoid` (no fast reciprocals).
_SUMS = {"reassoc", "contract"}
#: |x| bound of the single-precision Jacobian (q³ = (1 + x²)^{3/2} stays finite in float32;
#: s'(x) ≈ 5e-37 there, as good as 0)
_X32_MAX = 1e12


@njit(**INLINE)
def _sigmoid_one(x):
    """(s(x), ds/dx) of one value, as :func:`sigmoid` and :func:`sigmoid_derivative`."""
    a = abs(x)
    q = math.sqrt(1.0 + a * a)
    low = 0.5 / (q * (q + a))  # s(-|x|) without cancellation
    return (low if x < 0.0 else 1.0 - low), 0.5 / (q * q * q)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_SUMS)
def model_rgb(c0, c1, c2, t_band, B_band, b_uv, b_ir, uv, ir):
    """rgb (r, g, b) of the coefficients (c0, c1, c2) under the lumped node model of
    :func:`fit` (float64): Σ_m B_band[:, m] s(x_m), x_m = (c0 t_m + c1) t_m + c2, plus
    the lumps b_uv · s(c2) below the band and b_ir · s(c0 + c1 + c2) above it (or the
    overrides uv, ir where finite). Rest frame of the surface."""
    r0 = r1 = r2 = 0.0
    for m in range(t_band.shape[0]):
        t = t_band[m]
        s = _sigmoid_one((c0 * t + c1) * t + c2)[0]
        r0 += B_band[0, m] * s
        r1 += B_band[1, m] * s
        r2 += B_band[2, m] * s
    su = uv if math.isfinite(uv) else _sigmoid_one(c2)[0]
    si = ir if math.isfinite(ir) else _sigmoid_one(c0 + c1 + c2)[0]
    return (r0 + su * b_uv[0] + si * b_ir[0], r1 + su * b_uv[1] + si * b_ir[1],
            r2 + su * b_uv[2] + si * b_ir[2])


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_SUMS)
def model_jacobian(c0, c1, c2, t32, B32, b_uv, b_ir, uv, ir):
    """J = ∂rgb_i/∂c_j of :func:`model_rgb`, row-major (J00, J01, …, J22), analytic:

        J = Σ_m B_band[:, m] s'(x_m) (t_m², t_m, 1) + b_uv s'(c2) (0, 0, 1)
            + b_ir s'(c0 + c1 + c2) (1, 1, 1)

    (a lump's term is 0 where it is overridden). The band sum runs in single precision
    (``t32``, ``B32``: t_band, B_band as float32; relative error ≈ 1e-7, twice the SIMD
    width): it only steers the steps, the residual that decides is :func:`model_rgb`'s."""
    f0, f1, f2 = np.float32(c0), np.float32(c1), np.float32(c2)
    lim = np.float32(_X32_MAX)
    one, half = np.float32(1.0), np.float32(0.5)
    j00 = j01 = j02 = j10 = j11 = j12 = j20 = j21 = j22 = np.float32(0.0)
    for m in range(t32.shape[0]):
        t = t32[m]
        x = min(max((f0 * t + f1) * t + f2, -lim), lim)
        q = np.float32(math.sqrt(one + x * x))
        d = half / (q * q * q)
        w0, w1, w2 = B32[0, m] * d, B32[1, m] * d, B32[2, m] * d
        t2 = t * t
        j00 += w0 * t2
        j01 += w0 * t
        j02 += w0
        j10 += w1 * t2
        j11 += w1 * t
        j12 += w1
        j20 += w2 * t2
        j21 += w2 * t
        j22 += w2
    du = 0.0 if math.isfinite(uv) else _sigmoid_one(c2)[1]
    di = 0.0 if math.isfinite(ir) else _sigmoid_one(c0 + c1 + c2)[1]
    e0, e1, e2 = di * b_ir[0], di * b_ir[1], di * b_ir[2]
    return (j00 + e0, j01 + e0, j02 + e0 + du * b_uv[0],
            j10 + e1, j11 + e1, j12 + e1 + du * b_uv[1],
            j20 + e2, j21 + e2, j22 + e2 + du * b_uv[2])


@njit(**INLINE)
def _lm_step(J, r0, r1, r2, mu):
    """The Levenberg–Marquardt step δ = -(JᵀJ + μ diag(JᵀJ) + ε)⁻¹ Jᵀr of :func:`fit`
    (ε: 1e-300 + 1e-14 max diag, so a flat direction never makes it singular), by the
    LDLᵀ factorisation of the symmetric positive definite 3×3 matrix."""
    j00, j01, j02, j10, j11, j12, j20, j21, j22 = J
    a00 = j00 * j00 + j10 * j10 + j20 * j20
    a11 = j01 * j01 + j11 * j11 + j21 * j21
    a22 = j02 * j02 + j12 * j12 + j22 * j22
    a10 = j00 * j01 + j10 * j11 + j20 * j21
    a20 = j00 * j02 + j10 * j12 + j20 * j22
    a21 = j01 * j02 + j11 * j12 + j21 * j22
    g0 = j00 * r0 + j10 * r1 + j20 * r2
    g1 = j01 * r0 + j11 * r1 + j21 * r2
    g2 = j02 * r0 + j12 * r1 + j22 * r2
    eps = 1e-300 + 1e-14 * max(a00, a11, a22)
    a00 += mu * a00 + eps
    a11 += mu * a11 + eps
    a22 += mu * a22 + eps
    l10 = a10 / a00
    l20 = a20 / a00
    d1 = a11 - l10 * a10
    b21 = a21 - l20 * a10
    l21 = b21 / d1
    d2 = a22 - l20 * a20 - l21 * b21
    y1 = g1 - l10 * g0
    y2 = g2 - l20 * g0 - l21 * y1
    x2 = y2 / d2
    x1 = y1 / d1 - l21 * x2
    x0 = g0 / a00 - l10 * x1 - l20 * x2
    return -x0, -x1, -x2


@njit(cache=True, nogil=True, error_model="numpy")
def fit_one(target, t_band, B_band, t32, B32, b_uv, b_ir, uv, ir, c, tol, max_iter, mu0):
    """:func:`fit` for one colour, compiled: the same Levenberg–Marquardt steps on
    ``rgb(c) = target`` (Marquardt scaling, μ ÷3 on success down to 1e-12, ×4 on failure,
    stalled at μ ≥ 1e12) and the same stop (every RGB residual of :func:`model_rgb`
    ≤ ``tol``, or ``max_iter`` steps), but μ starts at ``mu0`` (:func:`fit`: 1e-3) and
    the Jacobian is :func:`model_jacobian`'s (single-precision band sum). From a close
    start (the coefficient table, :func:`..rgb_table.coefficients`) a tiny μ0 makes the
    first steps Gauss–Newton's, which converge in one or two steps where μ = 1e-3 takes
    about six (the 3×3 system is ill-conditioned, so even that damping shortens it).

    ``c`` (3,) is the start and is overwritten with the result; returns the max-abs RGB
    residual. The Jacobian is evaluated only where a step was accepted and another
    follows."""
    t0, t1, t2 = target[0], target[1], target[2]
    c0, c1, c2 = c[0], c[1], c[2]
    m0, m1, m2 = model_rgb(c0, c1, c2, t_band, B_band, b_uv, b_ir, uv, ir)
    r0, r1, r2 = m0 - t0, m1 - t1, m2 - t2
    cost = r0 * r0 + r1 * r1 + r2 * r2
    mu = mu0
    J = model_jacobian(c0, c1, c2, t32, B32, b_uv, b_ir, uv, ir)
    fresh = True  # is J the Jacobian at c?
    for _ in range(max_iter):
        if not max(abs(r0), abs(r1), abs(r2)) > tol:
            break
        if not fresh:
            J = model_jacobian(c0, c1, c2, t32, B32, b_uv, b_ir, uv, ir)
            fresh = True
        d0, d1, d2 = _lm_step(J, r0, r1, r2, mu)
        n0, n1, n2 = c0 + d0, c1 + d1, c2 + d2
        better = False
        e0 = e1 = e2 = cost_n = 0.0
        if math.isfinite(n0) and math.isfinite(n1) and math.isfinite(n2):
            m0, m1, m2 = model_rgb(n0, n1, n2, t_band, B_band, b_uv, b_ir, uv, ir)
            e0, e1, e2 = m0 - t0, m1 - t1, m2 - t2
            cost_n = e0 * e0 + e1 * e1 + e2 * e2
            better = cost_n < cost
        if better:
            c0, c1, c2 = n0, n1, n2
            r0, r1, r2 = e0, e1, e2
            cost = cost_n
            mu = max(mu / 3.0, 1e-12)
            fresh = False
        else:
            mu = min(mu * 4.0, 1e12)
            if mu >= 1e12:  # the damping ran away: an unreachable target has stalled
                break
    c[0], c[1], c[2] = c0, c1, c2
    return max(abs(r0), abs(r1), abs(r2))
