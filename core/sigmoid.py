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
"""

from __future__ import annotations

import numpy as np

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
        return 0.5 / (1.0 + x * x) ** 1.5


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


def _model(c, t, basis, B_band, b_uv, b_ir, uv, ir):
    """rgb(c) (k, 3) and its Jacobian (k, 3, 3) for the lumped node model (see fit())."""
    x = c @ basis.T  # (k, m): c0 t² + c1 t + c2 on the band nodes
    s = sigmoid(x)
    ds = sigmoid_derivative(x)
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
