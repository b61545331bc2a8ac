"""core.physics.sigmoid: the compiled per-colour fit against the numpy batched one."""

from __future__ import annotations

import numpy as np
import pytest

from relray.core.physics import sigmoid as sg
from relray.core.physics import spectrum as sp


@pytest.fixture(scope="module")
def model():
    return sp.reflectance_fit_model()


def coefficient_samples() -> np.ndarray:
    rng = np.random.default_rng(4)
    c = rng.normal(0.0, 20.0, (200, 3))
    c[:20, 2] = rng.choice([-1e30, 1e30, -600.0, 600.0], 20)   # saturated, clamped greys
    return c


@pytest.mark.parametrize("uv, ir", [(np.nan, np.nan), (0.3, np.nan), (np.nan, 0.9)])
def test_compiled_model_and_jacobian_match_numpy(model, uv, ir):
    """model_rgb (float64) to 1e-14; model_jacobian (float32 band sum) to 1e-6 of the
    Jacobian's scale, against :func:`sigmoid._model` (numpy, float64). Where |x| passes
    _X32_MAX the float32 sum holds s'(_X32_MAX) ≈ 5e-37 per unit weight instead of
    a smaller value: an absolute 1e-36 covers it (both are flat)."""
    c = coefficient_samples()
    n = len(c)
    uvs, irs = np.full(n, uv), np.full(n, ir)
    basis = np.stack([model.t_band ** 2, model.t_band, np.ones_like(model.t_band)], axis=1)
    want_rgb, want_j = sg._model(c, model.t_band, basis, model.B_band, model.b_uv,
                                 model.b_ir, uvs, irs)
    t32, B32 = model.t_band.astype(np.float32), model.B_band.astype(np.float32)
    for k in range(n):
        rgb = sg.model_rgb(*c[k], model.t_band, model.B_band, model.b_uv, model.b_ir, uv, ir)
        assert np.allclose(rgb, want_rgb[k], rtol=0.0, atol=1e-14)
        J = np.reshape(sg.model_jacobian(*c[k], t32, B32, model.b_uv, model.b_ir, uv, ir),
                       (3, 3))
        scale = max(np.abs(want_j[k]).max(), 1e-300)
        assert np.allclose(J, want_j[k], rtol=0.0, atol=1e-6 * scale + 1e-36), (c[k], J, want_j[k])


def test_fit_one_converges_where_fit_does(model):
    """From a grey start far from the target, fit_one (μ0 = 1e-3, as fit) reaches the
    same tolerance as :func:`sigmoid.fit` on the colours fit reaches it on."""
    rng = np.random.default_rng(5)
    target = np.concatenate([rng.random((150, 3)), rng.uniform(0.95, 1.0, (50, 3))])
    init = sg.grey_coefficients(np.clip(target @ [0.2126, 0.7152, 0.0722], 1e-3, 1 - 1e-3))
    none = np.full(len(target), np.nan)
    _, ref_resid = sg.fit(target, model.t_band, model.B_band, model.b_uv, model.b_ir, none,
                          none, init, tol=1e-9)
    t32, B32 = model.t_band.astype(np.float32), model.B_band.astype(np.float32)
    for k in np.flatnonzero(ref_resid <= 1e-9):
        c = init[k].copy()
        resid = sg.fit_one(target[k], model.t_band, model.B_band, t32, B32, model.b_uv,
                           model.b_ir, np.nan, np.nan, c, 1e-9, sg.FIT_MAX_ITER, 1e-3)
        rgb = np.array(sg.model_rgb(*c, model.t_band, model.B_band, model.b_uv, model.b_ir,
                                    np.nan, np.nan))
        assert resid <= 1e-9 and np.abs(rgb - target[k]).max() == resid
