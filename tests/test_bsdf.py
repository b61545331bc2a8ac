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
        wi = bsdf.reflect(wo, h, wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2])
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


# ------------------------------------------------------------------ chi-square per lobe
# As Mitsuba 3 tests each BSDF: draw N directions with a lobe's sampler, bin them in
# (cos θ, φ) about n = +z, and compare the counts with N × the lobe's pdf integrated over
# each bin (a SUB×SUB midpoint rule inside every bin). Bins expecting fewer than 5 samples
# are pooled; directions the sampler refuses or puts below the horizon form one more bin
# expecting N (1 - ∫ pdf). The samples are a fixed deterministic set, so a test does not
# flicker. Pearson's statistic is compared with the χ² distribution (scipy): a correct
# sampler passes at the significance SIGNIFICANCE (a false failure once in 1000 sample
# sets), a sampler checked against a wrong pdf fails (test_chi_square_detects_*).

SIGNIFICANCE = 1e-3
SUB = 24  # midpoint rule per bin side: resolves the peak of α = 0.15 at grazing wo
N_COS, N_PHI, N_SAMPLES = 16, 32, 200_000
LAMBERT, GGX, MIXTURE, UNIFORM = 0, 1, 2, 3
W_D, W_M = 0.4, 0.6  # the mixture's lobe weights


@njit(cache=True)
def _sample_lobe(kind, wo, alpha, ul, u1, u2):
    """Directions from a lobe's sampler (NaN where the sampler refuses): Lambert, GGX, or
    the material's one-sample mixture (principled_sample, w_d 0.4, w_m 0.6, lobe by ul)."""
    n = (0.0, 0.0, 1.0)
    out = np.empty((len(u1), 3))
    for i in range(len(u1)):
        if kind == LAMBERT:
            wi = bsdf.lambert_sample(n, u1[i], u2[i])
        elif kind == GGX:
            wi = bsdf.ggx_sample(wo, n, alpha, u1[i], u2[i])
        else:
            wi, _, _, delta, _, ok = bsdf.principled_sample(wo, n, n, True, W_D, W_M, 0.0,
                                                            alpha, 1.5, ul[i], u1[i], u2[i])
            if not ok or delta:
                wi = (math.nan, math.nan, math.nan)
        out[i, 0], out[i, 1], out[i, 2] = wi
    return out


@njit(cache=True)
def _lobe_pdf(kind, wo, alpha, wi):
    """The pdf the product gives each lobe (UNIFORM: a deliberately wrong one)."""
    n = (0.0, 0.0, 1.0)
    if wi[2] <= 0.0:
        return 0.0
    if kind == LAMBERT:
        return bsdf.lambert_eval(wi[2])[1]
    if kind == GGX:
        h = (wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2])
        return bsdf.ggx_eval(wo[2], wi[2], h[2] / math.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2),
                             alpha * alpha)[1]
    if kind == UNIFORM:
        return 1.0 / (2.0 * math.pi)
    return bsdf.principled_eval(wo, wi, n, W_D, W_M, alpha * alpha, W_D, W_M)[3]


@njit(cache=True)
def _bin_integrals(kind, wo, alpha, n_cos, n_phi, sub):
    """∫ pdf dω over each (cos θ, φ) bin of the upper hemisphere (midpoint rule)."""
    out = np.zeros((n_cos, n_phi))
    dc, dp = 1.0 / n_cos, 2.0 * math.pi / n_phi
    for a in range(n_cos):
        for b in range(n_phi):
            acc = 0.0
            for i in range(sub):
                c = (a + (i + 0.5) / sub) * dc
                s = math.sqrt(max(0.0, 1.0 - c * c))
                for j in range(sub):
                    ph = (b + (j + 0.5) / sub) * dp
                    acc += _lobe_pdf(kind, wo, alpha, (s * math.cos(ph), s * math.sin(ph), c))
            out[a, b] = acc * dc * dp / (sub * sub)
    return out


def chi_square_p(kind_sample: int, kind_pdf: int, wo, alpha: float, alpha_pdf=None) -> float:
    """The p-value of Pearson's χ² for the sampler ``kind_sample`` against the pdf
    ``kind_pdf`` (of roughness ``alpha_pdf``, by default the sampler's)."""
    from scipy import stats

    u1, u2 = _uniforms(N_SAMPLES, 11)
    ul, _ = _uniforms(N_SAMPLES, 13)
    wi = _sample_lobe(kind_sample, wo, alpha, ul, u1, u2)
    above = wi[:, 2] > 0.0  # False for NaN (refused) too
    cos_t = np.clip(wi[above, 2], 0.0, 1.0 - 1e-12)
    phi = np.mod(np.arctan2(wi[above, 1], wi[above, 0]), 2 * math.pi)
    observed, _, _ = np.histogram2d(cos_t, phi, bins=(N_COS, N_PHI),
                                    range=((0, 1), (0, 2 * math.pi)))
    expected = N_SAMPLES * _bin_integrals(kind_pdf, wo, alpha if alpha_pdf is None
                                          else alpha_pdf, N_COS, N_PHI, SUB)
    obs = np.append(observed.ravel(), (~above).sum())
    exp = np.append(expected.ravel(), max(N_SAMPLES - expected.sum(), 0.0))
    order = np.argsort(exp)  # pool the smallest bins until each pooled bin expects >= 5
    pooled_o, pooled_e, acc_o, acc_e = [], [], 0.0, 0.0
    for k in order:
        acc_o += obs[k]
        acc_e += exp[k]
        if acc_e >= 5.0:
            pooled_o.append(acc_o)
            pooled_e.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0.0 and pooled_e:
        pooled_o[-1] += acc_o
        pooled_e[-1] += acc_e
    o, e = np.array(pooled_o), np.array(pooled_e)
    chi2 = float(((o - e) ** 2 / e).sum())
    return float(stats.chi2.sf(chi2, len(o) - 1))


def test_chi_square_lambert():
    assert chi_square_p(LAMBERT, LAMBERT, (0.0, 0.6, 0.8), 0.0) > SIGNIFICANCE


@pytest.mark.parametrize("alpha", [0.15, 0.4, 0.8])
@pytest.mark.parametrize("theta_o", [0.2, 0.9, 1.4])
def test_chi_square_ggx_conductor(alpha, theta_o):
    wo = (math.sin(theta_o), 0.0, math.cos(theta_o))
    assert chi_square_p(GGX, GGX, wo, alpha) > SIGNIFICANCE


@pytest.mark.parametrize("theta_o", [0.3, 1.1])
def test_chi_square_lobe_mixture_matches_principled_eval(theta_o):
    """principled_sample's one-sample lobe choice has the density principled_eval returns."""
    wo = (math.sin(theta_o), 0.0, math.cos(theta_o))
    assert chi_square_p(MIXTURE, MIXTURE, wo, 0.3) > SIGNIFICANCE


def test_chi_square_detects_a_wrong_pdf():
    """The test can fail: Lambert samples against a uniform-hemisphere pdf, and GGX
    samples of α = 0.4 against the pdf of α = 0.44 (10 % off)."""
    assert chi_square_p(LAMBERT, UNIFORM, (0.0, 0.0, 1.0), 0.0) < 1e-12
    wo = (math.sin(0.9), 0.0, math.cos(0.9))
    assert chi_square_p(GGX, GGX, wo, 0.4, alpha_pdf=0.44) < SIGNIFICANCE


@pytest.mark.parametrize("kind, alpha, theta_o", [(LAMBERT, 0.0, 0.0), (GGX, 0.15, 1.4),
                                                  (GGX, 0.8, 0.2), (MIXTURE, 0.3, 1.1)])
def test_pdfs_integrate_to_at_most_one(kind, alpha, theta_o):
    """∫ pdf dω over the hemisphere: 1 for Lambert (the midpoint rule is exact for cos θ;
    1/π is a float32, 4e-8 low);
    at most 1 for GGX and the mixture, whose missing mass is the share of samples the
    sampler puts below the horizon (the chi-square's extra bin)."""
    wo = (math.sin(theta_o), 0.0, math.cos(theta_o))
    total = _bin_integrals(kind, wo, alpha, N_COS, N_PHI, SUB).sum()
    if kind == LAMBERT:
        assert total == pytest.approx(1.0, abs=1e-7)
    else:
        assert 0.5 < total <= 1.0 + 2e-3


def test_principled_sample_picks_lobes_by_weight_with_their_throughput():
    """ul picks glass, metal, diffuse with probabilities w_g, w_m, w_d (χ²); glass gives
    the factor 1 (reflected) or 1/η² (transmitted), the mirror ρ + (1 - ρ)(1 - cos θ_o)⁵,
    a smooth lobe f cos θ_i / pdf of principled_eval."""
    from scipy import stats

    wo, n = (0.6, 0.0, 0.8), (0.0, 0.0, 1.0)
    wd, wm, wg, rho = 0.2, 0.3, 0.5, 0.7
    ul, u1 = _uniforms(30_000, 17)
    _, u2 = _uniforms(30_000, 19)
    counts = np.zeros(3)
    for a, b, c in zip(ul, u1, u2, strict=True):
        wi, w, pdf, delta, transmitted, ok = bsdf.principled_sample(
            wo, n, n, True, wd, wm, wg, 1e-4, 1.5, a, b, c)
        assert ok
        if a < wg:
            counts[0] += 1
            assert delta and pdf == 0.0
            assert bsdf.lane_weight(w, rho) == (1 / 1.5**2 if transmitted else 1.0)
        elif a < wg + wm:
            counts[1] += 1
            assert delta and wi == pytest.approx((-0.6, 0.0, 0.8))
            assert bsdf.lane_weight(w, rho) == pytest.approx(rho + (1 - rho) * 0.2**5)
        else:
            counts[2] += 1
            kd, km, s, p = bsdf.principled_eval(wo, wi, n, wd, wm, 1e-8, wd, wm)
            assert not delta and pdf == pytest.approx(p)
            assert bsdf.lane_weight(w, rho) == pytest.approx(
                bsdf.lane_value(kd, km, s, rho) * wi[2] / p)
    assert stats.chisquare(counts, 30_000 * np.array([wg, wm, wd])).pvalue > SIGNIFICANCE


@pytest.mark.parametrize("cos_o, eta", [(0.9, 1.5), (0.3, 1.5), (0.8, 1 / 1.5), (0.2, 1 / 1.5)])
def test_dielectric_reflects_with_probability_fresnel_and_obeys_snell(cos_o, eta):
    """Delta lobes: the reflected fraction is F (binomial, 5 standard errors); the
    reflection is the mirror direction and the refraction obeys Snell's law."""
    sin_o = math.sqrt(1 - cos_o * cos_o)
    wo, n = (sin_o, 0.0, cos_o), (0.0, 0.0, 1.0)
    f, _ = bsdf.fresnel_dielectric(cos_o, eta)
    u, _ = _uniforms(20_000, 3)
    results = [bsdf.dielectric_sample(wo, n, eta, x) for x in u]
    refl = np.array([not t for _, t in results])
    assert abs(refl.mean() - f) < 5 * math.sqrt(max(f * (1 - f), 1e-12) / len(u)) + 1e-12
    for wi, transmitted in results[:50]:
        if transmitted:
            assert wi[2] < 0 and math.hypot(wi[0], wi[1]) == pytest.approx(sin_o / eta)
            assert math.hypot(*wi) == pytest.approx(1.0)
        else:
            assert wi == pytest.approx((-sin_o, 0.0, cos_o))


def test_mirror_and_shared_reflect():
    wo, n = (0.6, 0.0, 0.8), (0.0, 0.0, 1.0)
    wi, s = bsdf.mirror_sample(wo, n)
    assert wi == pytest.approx((-0.6, 0.0, 0.8)) and s == bsdf.schlick_weight(0.8)
    h = (0.0, 0.6, 0.8)
    assert bsdf.reflect(wo, h, 0.64) == pytest.approx((-0.6, 0.768, 0.224))
    wt = bsdf.refract(wo, n, 1.5, 0.8, math.sqrt(1 - 0.36 / 2.25))
    assert wt[0] == pytest.approx(-0.4) and wt[2] < 0
