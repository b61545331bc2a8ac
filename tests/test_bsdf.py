"""BSDF kernels against their analytic properties (normalisation, reciprocity, Fresnel)."""

import math

import numpy as np
import pytest
from numba import njit

from relray.core.render import bsdf
from relray.core.render.sampling import cosine_hemisphere, onb, rand_dims, to_world


@njit(cache=True)
def _ggx_samples(wo, alpha, u1, u2):
    n = (0.0, 0.0, 1.0)
    a2 = alpha * alpha
    out = np.empty((len(u1), 5))
    for i in range(len(u1)):
        h = bsdf.ggx_sample_h(wo, n, alpha, u1[i], u2[i])
        c = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        wi = (2 * c * h[0] - wo[0], 2 * c * h[1] - wo[1], 2 * c * h[2] - wo[2])
        f, p = bsdf.ggx_eval(wo[2], wi[2], h[2], a2)
        out[i, 0], out[i, 1], out[i, 2] = wi
        out[i, 3], out[i, 4] = f, p
    return out


def _uniforms(n, dim0):
    from relray.core.render.sampling import path_keys

    keys = path_keys(7, 0, np.arange(n), np.zeros(n, np.int64))
    return rand_dims(keys, dim0), rand_dims(keys, dim0 + 1)


@pytest.mark.parametrize("alpha", [0.1, 0.3, 0.7])
@pytest.mark.parametrize("theta_o", [0.0, 0.6, 1.3])
def test_ggx_visible_normal_sampling_matches_pdf(alpha, theta_o):
    """E[g(wi)/p(wi)] over VNDF samples equals ∫ g dω for g = cos θ_i on the hemisphere.

    With g = 1 on the upper hemisphere the estimator is the fraction of the lobe above
    the horizon ∫_{H+} p dω ≤ 1; with g = p it checks p against its own samples.  We use
    the exact identity E[1/p · p] = P(wi in H+), estimated two ways: the sample fraction
    above the horizon, and a Monte Carlo integral of p over the hemisphere with uniform
    directions.  Both agree within 5 standard errors.
    """
    wo = (math.sin(theta_o), 0.0, math.cos(theta_o))
    n = 200_000
    u1, u2 = _uniforms(n, 0)
    s = _ggx_samples(wo, alpha, u1, u2)
    above = s[:, 2] > 0
    frac = above.mean()
    # Monte Carlo integral of the pdf over the upper hemisphere (uniform directions)
    v1, v2 = _uniforms(n, 5)
    z = v1
    r = np.sqrt(1 - z * z)
    wi = np.stack([r * np.cos(2 * np.pi * v2), r * np.sin(2 * np.pi * v2), z], 1)
    h = wi + np.array(wo)
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    a2 = alpha * alpha
    pdf = np.array([bsdf.ggx_eval(wo[2], wi[i, 2], h[i, 2], a2)[1] for i in range(0, n, 20)])
    integral = pdf * 2 * np.pi
    se = integral.std() / math.sqrt(len(integral))
    assert abs(integral.mean() - frac) < 5 * se + 5 * math.sqrt(frac * (1 - frac) / n) + 1e-3


@pytest.mark.parametrize("alpha", [0.2, 0.5])
def test_ggx_importance_sampled_albedo_matches_uniform_integral(alpha):
    """The directional albedo ∫ f cos dω, estimated with VNDF samples (f cos / p) and with
    uniform hemisphere directions (2π f cos), agrees within 5 combined standard errors,
    and stays below 1 (single scattering loses energy, never gains it)."""
    wo = (0.0, 0.0, 1.0)
    n = 100_000
    u1, u2 = _uniforms(n, 0)
    s = _ggx_samples(wo, alpha, u1, u2)
    ok = (s[:, 2] > 0) & (s[:, 4] > 0)
    w_is = np.where(ok, s[:, 3] * s[:, 2] / np.where(ok, s[:, 4], 1), 0)
    v1, v2 = _uniforms(n, 5)
    r = np.sqrt(1 - v1 * v1)
    wi = np.stack([r * np.cos(2 * np.pi * v2), r * np.sin(2 * np.pi * v2), v1], 1)
    h = wi + np.array(wo)
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    f = np.array([bsdf.ggx_eval(1.0, wi[i, 2], h[i, 2], alpha**2)[0] for i in range(n)])
    w_un = 2 * np.pi * f * wi[:, 2]
    se = math.hypot(w_is.std() / math.sqrt(n), w_un.std() / math.sqrt(n))
    assert abs(w_is.mean() - w_un.mean()) < 5 * se
    assert w_is.mean() < 1.0


def test_ggx_reciprocity():
    a2 = 0.2
    for co, ci, ch in [(0.3, 0.8, 0.9), (0.9, 0.5, 0.95)]:
        assert bsdf.ggx_eval(co, ci, ch, a2)[0] == pytest.approx(bsdf.ggx_eval(ci, co, ch, a2)[0])


def test_fresnel_dielectric_normal_incidence_and_tir():
    f, cos_t = bsdf.fresnel_dielectric(1.0, 1.5)
    assert f == pytest.approx(((1.5 - 1) / (1.5 + 1)) ** 2, rel=1e-12)
    assert cos_t == pytest.approx(1.0)
    # inside glass beyond the critical angle: total internal reflection
    f, _ = bsdf.fresnel_dielectric(math.cos(math.radians(60)), 1 / 1.5)
    assert f == 1.0


def test_schlick_weight_limits():
    assert bsdf.schlick_weight(1.0) == 0.0
    assert bsdf.schlick_weight(0.0) == 1.0


@njit(cache=True)
def _lambert_furnace(u1, u2):
    n = (0.0, 0.0, 1.0)
    wo = (0.0, 0.6, 0.8)
    acc = 0.0
    for i in range(len(u1)):
        t, b = onb(n[0], n[1], n[2])
        x, y, z = cosine_hemisphere(u1[i], u2[i])
        wi = to_world(x, y, z, t, b, n[0], n[1], n[2])
        kd, km, s, pdf = bsdf.principled_eval(wo, wi, n, 1.0, 0.0, 0.25, 1.0, 0.0)
        acc += kd * wi[2] / pdf
    return acc / len(u1)


def test_lambert_white_furnace_is_exactly_one():
    """For a white Lambertian surface f cos / p = 1 for every cosine-weighted sample."""
    u1, u2 = _uniforms(10_000, 0)
    assert _lambert_furnace(u1, u2) == pytest.approx(1.0, rel=1e-6)
