"""BSDFs as numba device functions: Lambert, GGX conductor, smooth dielectric.

Every lobe answers the same questions (Mitsuba 3's ``eval``/``pdf``/``sample``) with
world-space unit vectors in the frame where the surface is at rest (the lab for static
scenes); ``n`` is the shading normal turned towards ``wo`` (surfaces are two-sided).
Spectral dependence enters only through the reflectance ρ(λ) of each hero lane, so the
functions return scalar factors and the integrator forms, per lane j,

    f_j = k_d ρ_j + k_m (ρ_j + (1 - ρ_j) s)          (s = (1 - wi·h)⁵, Schlick)

Job-format keys served (``[[materials]]``): ``base_color`` → ρ; ``metallic`` m,
``transmission`` t → lobe weights w_d = (1-m)(1-t), w_m = m, w_g = (1-m)t (they sum to 1,
a simplified Principled BSDF without the dielectric coat); ``roughness`` r → GGX
α = r² (clamped to ≥ 1e-3; below ``DELTA_ALPHA`` the conductor is a perfect mirror);
``ior`` → the smooth dielectric (wavelength-independent IOR, so no dispersion; the
glass lobe ignores roughness).

Every lobe, as Mitsuba 3's ``BSDF`` (all directions in the surface's rest frame):

| lobe | sample | eval (f without ρ and F) and pdf (solid angle) |
|---|---|---|
| Lambert | :func:`lambert_sample` | :func:`lambert_eval`: 1/π, cos θ_i/π |
| GGX conductor | :func:`ggx_sample` | :func:`ggx_eval`: the formulas below |
| mirror | :func:`mirror_sample` | delta lobe: 0, 0 for any pair of directions |
| dielectric | :func:`dielectric_sample` | delta lobe: 0, 0 for any pair of directions |

:func:`principled_eval` is the non-delta mixture of a material (NEE, and the
continuation's MIS pdf), :func:`principled_sample` the material's one-sample choice of
a lobe and its direction (the continuation); :func:`reflect` and :func:`refract` are
the one home of the mirror and Snell directions.

Formulas (Trowbridge–Reitz/GGX, height-correlated Smith, Heitz 2018 VNDF sampling):

    D(h)   = α² / (π (cos²θ_h (α² - 1) + 1)²)
    Λ(ω)   = (sqrt(1 + α² tan²θ) - 1) / 2,   G1 = 1/(1+Λ(ωo)),  G2 = 1/(1+Λ(ωo)+Λ(ωi))
    f_m    = F D G2 / (4 cosθo cosθi),        p(ωi) = G1(ωo) D(h) / (4 cosθo)
    Lambert: f = ρ/π,  p = cosθi/π
    Mirror: ωi = 2 (ωo·n) n - ωo, throughput ρ + (1 - ρ)(1 - cosθo)⁵ (Schlick)
    Dielectric: exact Fresnel F(cosθ, η); reflect with probability F, else refract and
    scale radiance by 1/η² (pbrt-v4's TransportMode::Radiance).
"""

from __future__ import annotations

import math

from ..jit import INLINE_FAST, njit
from .sampling import INV_PI, cosine_hemisphere, onb, sincos_2pi, to_world

DELTA_ALPHA = 1e-3


@njit(**INLINE_FAST)
def ggx_d(cos_h, a2):
    """Trowbridge–Reitz normal distribution D(h)."""
    c2 = cos_h * cos_h
    t = c2 * (a2 - 1.0) + 1.0
    return a2 / (math.pi * t * t)


@njit(**INLINE_FAST)
def ggx_lambda(cos_t, a2):
    """Smith Λ(ω) for GGX."""
    c2 = cos_t * cos_t
    if c2 <= 0.0:
        return 1e30
    tan2 = max(0.0, 1.0 - c2) / c2
    return 0.5 * (math.sqrt(1.0 + a2 * tan2) - 1.0)


@njit(**INLINE_FAST)
def ggx_eval(cos_o, cos_i, cos_h, a2):
    """The conductor lobe without Fresnel and its pdf: (D G2 / (4 cos_o cos_i), pdf)."""
    if cos_o <= 0.0 or cos_i <= 0.0 or cos_h <= 0.0:
        return 0.0, 0.0
    d = ggx_d(cos_h, a2)
    lo = ggx_lambda(cos_o, a2)
    li = ggx_lambda(cos_i, a2)
    f = d / (4.0 * cos_o * cos_i * (1.0 + lo + li))
    pdf = d / (4.0 * cos_o * (1.0 + lo))
    return f, pdf


@njit(**INLINE_FAST)
def ggx_sample_h(wo, n, alpha, u1, u2):
    """A microfacet normal h (world) drawn from the visible normals of wo (Heitz 2018)."""
    t, b = onb(n[0], n[1], n[2])
    ox = wo[0] * t[0] + wo[1] * t[1] + wo[2] * t[2]
    oy = wo[0] * b[0] + wo[1] * b[1] + wo[2] * b[2]
    oz = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
    vx, vy, vz = alpha * ox, alpha * oy, oz
    inv = 1.0 / math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx * inv, vy * inv, vz * inv
    lensq = vx * vx + vy * vy
    if lensq > 0.0:
        il = 1.0 / math.sqrt(lensq)
        t1x, t1y, t1z = -vy * il, vx * il, 0.0
    else:
        t1x, t1y, t1z = 1.0, 0.0, 0.0
    t2x = vy * t1z - vz * t1y
    t2y = vz * t1x - vx * t1z
    t2z = vx * t1y - vy * t1x
    r = math.sqrt(u1)
    c, sn = sincos_2pi(u2)
    p1 = r * c
    p2 = r * sn
    s = 0.5 * (1.0 + vz)
    p2 = (1.0 - s) * math.sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    hx = p1 * t1x + p2 * t2x + p3 * vx
    hy = p1 * t1y + p2 * t2y + p3 * vy
    hz = p1 * t1z + p2 * t2z + p3 * vz
    hx, hy, hz = alpha * hx, alpha * hy, max(1e-7, hz)
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    return to_world(hx * inv, hy * inv, hz * inv, t, b, n[0], n[1], n[2])


@njit(**INLINE_FAST)
def schlick_weight(cos_d):
    """(1 - cos)⁵ of Schlick's Fresnel: F = F0 + (1 - F0)·weight."""
    m = min(1.0, max(0.0, 1.0 - cos_d))
    m2 = m * m
    return m2 * m2 * m


@njit(**INLINE_FAST)
def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance and cos θ_t for relative IOR eta = n_t / n_i."""
    sin2_t = max(0.0, 1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0, 0.0
    cos_t = math.sqrt(1.0 - sin2_t)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp), cos_t


@njit(**INLINE_FAST)
def lambert_eval(cos_i):
    """The Lambert lobe without ρ, and its pdf: (1/π, cos θ_i/π) for cos θ_i = wi·n > 0
    (the caller checks the hemisphere)."""
    return INV_PI, cos_i * INV_PI


@njit(**INLINE_FAST)
def principled_eval(wo, wi, n, wd, wm, a2, sel_d, sel_m):
    """Non-delta part of the material: (k_d, k_m, s, pdf) for the lane formula above.

    ``sel_d``/``sel_m`` are the lobe-selection probabilities used when sampling, so the
    returned pdf is the one-sample-MIS mixture pdf of the directions the sampler makes.
    """
    cos_o = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
    cos_i = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
    if cos_i <= 0.0 or cos_o <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    f_l, p_l = lambert_eval(cos_i)
    kd = wd * f_l
    pdf = sel_d * p_l
    km = 0.0
    s = 0.0
    if wm > 0.0 and a2 > DELTA_ALPHA * DELTA_ALPHA:
        hx, hy, hz = wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]
        inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
        hx, hy, hz = hx * inv, hy * inv, hz * inv
        cos_h = hx * n[0] + hy * n[1] + hz * n[2]
        f, p = ggx_eval(cos_o, cos_i, cos_h, a2)
        km = wm * f
        s = schlick_weight(wi[0] * hx + wi[1] * hy + wi[2] * hz)
        pdf += sel_m * p
    return kd, km, s, pdf


@njit(**INLINE_FAST)
def reflect(wo, n, cos_o):
    """The mirror direction of ``wo`` about unit ``n`` (``cos_o`` = wo·n): 2 cos_o n - wo."""
    return (2.0 * cos_o * n[0] - wo[0], 2.0 * cos_o * n[1] - wo[1],
            2.0 * cos_o * n[2] - wo[2])


@njit(**INLINE_FAST)
def refract(wo, n, eta, cos_o, cos_t):
    """Snell's transmitted direction for relative IOR ``eta`` (``cos_o`` = wo·n > 0,
    ``cos_t`` from :func:`fresnel_dielectric`): -wo/η + (cos_o/η - cos_t) n."""
    k = cos_o / eta - cos_t
    return (-wo[0] / eta + k * n[0], -wo[1] / eta + k * n[1], -wo[2] / eta + k * n[2])


@njit(**INLINE_FAST)
def lambert_sample(n, u1, u2):
    """A direction about ``n`` with the Lambert lobe's pdf cos θ_i / π."""
    t, b = onb(n[0], n[1], n[2])
    lx, ly, lz = cosine_hemisphere(u1, u2)
    return to_world(lx, ly, lz, t, b, n[0], n[1], n[2])


@njit(**INLINE_FAST)
def ggx_sample(wo, n, alpha, u1, u2):
    """A direction from the GGX conductor lobe (visible normals, then :func:`reflect`):
    its pdf is :func:`ggx_eval`'s. May lie below the surface (the caller rejects it)."""
    h = ggx_sample_h(wo, n, alpha, u1, u2)
    return reflect(wo, h, wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2])


@njit(**INLINE_FAST)
def mirror_sample(wo, n):
    """The perfect conductor (α below ``DELTA_ALPHA``): (direction, Schlick weight s);
    the lane factor is ρ + (1 - ρ) s (a delta lobe: no pdf)."""
    cos_o = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
    return reflect(wo, n, cos_o), schlick_weight(cos_o)


@njit(**INLINE_FAST)
def dielectric_sample(wo, n, eta, u):
    """The smooth dielectric (relative IOR ``eta`` = n_t / n_i, ``n`` on the side of wo):
    reflect with probability F, else refract. Returns (direction, transmitted); the
    radiance factor of a transmission is 1/η² (a delta lobe: no pdf)."""
    cos_o = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
    fr, cos_t = fresnel_dielectric(cos_o, eta)
    if u < fr:
        return reflect(wo, n, cos_o), False
    return refract(wo, n, eta, cos_o, cos_t), True


@njit(**INLINE_FAST)
def lane_value(kd, km, s, rho):
    """The BSDF of one hero lane from :func:`principled_eval`'s factors and ρ(λ):
    k_d ρ + k_m (ρ + (1 - ρ) s)."""
    return kd * rho + km * (rho + (1.0 - rho) * s)


@njit(**INLINE_FAST)
def has_smooth_lobe(wd, wm, alpha):
    """Whether a material with lobe weights w_d, w_m and GGX α has a non-delta lobe (one
    that next-event estimation can serve): diffuse, or a metal rougher than
    ``DELTA_ALPHA``."""
    return wd + (0.0 if wm > 0.0 and alpha < DELTA_ALPHA else wm) > 0.0


@njit(**INLINE_FAST)
def principled_sample(wo, n, g, front, wd, wm, wg, alpha, ior, ul, u1, u2):
    """The continuation from a material: ``ul`` picks a lobe by its weight ([0, w_g)
    glass, [w_g, w_g + w_m) metal, the rest diffuse), (u1, u2) its direction.

    ``n`` is the shading normal towards ``wo``, ``g`` the geometric one (a direction below
    g is refused), ``front`` whether the ray met g's front face (glass is entered from
    the front, relative IOR η = ior, else 1/ior), ``alpha`` the GGX α (below
    ``DELTA_ALPHA`` the metal is a mirror). The non-delta lobes are one-sample MIS: their
    density is the mixture's, w_d p_d + w_m p_m (:func:`principled_eval`).

    Returns ``(wi, weight, pdf, delta, transmitted, ok)``; ``weight`` = (k_0, k_d, k_m, s,
    c) gives each hero lane's throughput factor f cos θ_i / pdf = (k_0 + k_d ρ + k_m (ρ +
    (1 - ρ) s)) c (:func:`lane_weight`): 1 or 1/η² through glass, ρ + (1 - ρ) s off the
    mirror; ``pdf`` is 0 for the delta lobes; ``ok`` is False for a refused direction.
    """
    if ul < wg:
        eta = ior if front else 1.0 / ior
        wi, transmitted = dielectric_sample(wo, n, eta, u1)
        c = 1.0 / (eta * eta) if transmitted else 1.0
        return wi, (1.0, 0.0, 0.0, 0.0, c), 0.0, True, transmitted, True
    if wm > 0.0 and alpha < DELTA_ALPHA and ul < wg + wm:
        wi, s = mirror_sample(wo, n)
        return wi, (0.0, 0.0, 1.0, s, 1.0), 0.0, True, False, True
    if ul >= wg + wm:
        wi = lambert_sample(n, u1, u2)
    else:
        wi = ggx_sample(wo, n, alpha, u1, u2)
    if wi[0] * g[0] + wi[1] * g[1] + wi[2] * g[2] <= 0.0:
        return wi, (0.0, 0.0, 0.0, 0.0, 0.0), 0.0, False, False, False
    kd, km, s, pdf = principled_eval(wo, wi, n, wd, wm, alpha * alpha, wd, wm)
    if pdf <= 0.0:
        return wi, (0.0, 0.0, 0.0, 0.0, 0.0), 0.0, False, False, False
    c = (wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]) / pdf
    return wi, (0.0, kd, km, s, c), pdf, False, False, True


@njit(**INLINE_FAST)
def lane_weight(weight, rho):
    """The throughput factor of one hero lane from :func:`principled_sample`'s
    ``weight`` and ρ(λ): (k_0 + k_d ρ + k_m (ρ + (1 - ρ) s)) c."""
    k0, kd, km, s, c = weight
    return (k0 + lane_value(kd, km, s, rho)) * c
