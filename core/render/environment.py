"""Environment maps: lab radiance at infinity from an equirectangular image.

Directions (lab frame, job-format.md "Skies", as Blender's Environment Texture): the unit
vector ω = (sin θ cos φ, sin θ sin φ, cos θ), θ from +Z, φ from +X towards +Y, looks at
the map coordinates

    u = (π + ρ − φ) / 2π  (mod 1),    v = 1 − θ/π            (ρ = rotation_z)

and back φ = π + ρ − 2πu, θ = π(1 − v): the centre column (u = ½) looks along +X when
ρ = 0, u = ¼ along +Y, the top row (v = 1) up +Z. The image's row 0 is its bottom row
(v = 0, :func:`..scene.images.read_image`). Texel (r, c) of an H × W map covers
v ∈ [r/H, (r+1)/H], u ∈ [c/W, (c+1)/W]; a direction sees the texel it falls in
(nearest lookup, Blender's "Closest" interpolation): radiance is piecewise constant,
exactly the density the sampler draws from (below). Where no light sampling competes
— camera rays, and rays after a delta (mirror, glass) bounce, whose MIS weight is 1 —
the map is interpolated bilinearly between texel centres instead (Blender's "Linear"),
so a map seen directly or in a mirror shows no texel blocks; that path's estimate is
unbiased for either lookup, and the light a diffuse or glossy surface receives is the
nearest map's, which its two techniques (NEE and BSDF sampling) agree on.

Radiance (lab frame): a texel of linear Rec.709 value rgb (× ``strength``; negative
components clamped to 0) is an RGB emitter (physics.md, "Spectral model"):

    L(λ) = k · s(λ; c) · E(λ),   k = 2 max(rgb),  c = rgb_table.coefficients(rgb / k),

E = D65_ext (cie1931). The seed-gaussian mode's RGB emitter is flat, L = mean(rgb): there
c = 0 (s = ½), k = 2 mean(rgb), E = 1. In the rgb mode a lane is the texel's channel.
Per texel the kernels read (c0, c1, c2, k) (or (r, g, b, 1)), E is a row of the
emission table looked up at the lane's lab column (:data:`KernelEnvironment.row`).
An escaping ray's lanes are lab wavelengths, so the camera sees D⁵ L_lab(D λ), the
aberration coming from the lab direction.

Spectral maps (a Fichet-layout spectral EXR, :func:`..scene.images.read_spectral_image`):
texel t holds lab spectral radiance L_t,b at the file's wavelengths λ_b (× strength,
clamped to ≥ 0), in the units of ``emission_spectrum``, and

    L_t(λ) = L_t,b + (λ − λ_b)/(λ_b+1 − λ_b) · (L_t,b+1 − L_t,b)   for λ_b ≤ λ ≤ λ_b+1,

0 outside [λ_0, λ_B−1] (as ``emission_spectrum``'s table, but interpolated exactly at the
lane's wavelength). The kernels read the bands (``tex`` (H, W, B)) and their wavelengths
(:data:`KernelEnvironment.nm`, empty for a colour map). In the rgb mode the map becomes
its rest-frame Rec.709 colour, Σ_b L_t,b · rgb(hat_b) (:func:`band_rgb`). A blackbody map,
L_t = B(λ, T), is seen by a camera with Doppler factor D as D⁵ B(Dλ, T) = B(λ, D·T).

Importance sampling (next-event estimation): piecewise constant over texels, the
probability of texel t proportional to its power, Y_t ΔΩ_t (Y the Rec.709 luminance of
its rgb, ΔΩ_t = (2π/W)(cos θ_top − cos θ_bottom) its solid angle; a spectral texel adds
:data:`SPECTRAL_FLOOR` · Ȳ · mean_b L_t,b · ΔΩ_t, Ȳ = ∫ ȳ dλ, so a texel that shines only
outside the visible, where a moving camera may see it, is sampled too): a row from the
marginal CDF over rows, a column from that row's conditional CDF (each searched from a
guide table, :func:`..physics.spectrum.guided_bin`), (u, v) uniform inside the texel.
The density per unit (u, v) is p_t·H·W and dΩ = 2π² sin θ du dv, so

    pdf(ω) = p_t · H · W / (2π² sin θ).

Robustness: a texel with non-zero radiance has Y > 0 (rgb ≥ 0, not all 0) and ΔΩ > 0,
so its probability is positive: with the nearest lookup the sampler covers every
direction the map lights, which MIS needs to stay unbiased (no uniform mix is needed;
a bilinear lookup would need one, since it spreads a texel's light into neighbours of
weight 0). A map that is black everywhere is no light (power 0).

``prepare(..., env_nee=False)`` (:mod:`.frames`; ``bench/environment.py``, not a job key)
leaves the map out of the light table, so it is reached by BSDF sampling only.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import INLINE_IR, njit
from ..physics import spectrum
from ..physics.rgb_table import coefficients, lambda_of_column, sigmoid_reflectance
from ..physics.spectrum import guide_table, guided_bin
from ..scene.sky import EnvironmentImage
from .arcs import arccos, arctan2
from .sampling import sincos_2pi

LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec.709 luminance weights
#: A spectral texel's sampling weight beside its luminance: this share of its mean band
#: radiance (× Ȳ), so bands outside the visible are sampled (module docstring).
SPECTRAL_FLOOR = 0.01
TWO_PI_SQ = 2.0 * math.pi * math.pi
INV_PI = 1.0 / math.pi
INV_TWO_PI = 0.5 / math.pi


class KernelEnvironment(NamedTuple):
    """What the kernels read of a map (:func:`kernel_environment`)."""

    on: bool
    tex: np.ndarray    # float32 (H, W, 4): (c0, c1, c2, k), rgb mode (r, g, b, 1)
    marg: np.ndarray   # float64 (H + 1,): CDF over rows
    cond: np.ndarray   # float64 (H, W + 1): CDF over the columns of each row
    mguide: np.ndarray  # int32 (H,): the marginal CDF's guide table (spectrum.guide_table)
    cguide: np.ndarray  # int32 (H, W): each row's conditional CDF's guide table
    pmf: np.ndarray    # float32 (H, W): probability of each texel
    rot: float         # rotation_z in radians
    row: int           # the emission-table row of E(λ) (rgb: ones)
    nm: np.ndarray     # float64 (B,): a spectral map's band wavelengths (colour map: empty)
    power: float       # Σ_t of the texels' sampling weights (:func:`texel_weights`)


class Texels(NamedTuple):
    """A map's texels, read once per :func:`kernel_environment` (:func:`texels`)."""

    rgb: np.ndarray            # float64 (H, W, 3): linear Rec.709 radiance × strength, ≥ 0
    bands: np.ndarray | None   # float64 (H, W, B): a spectral map's bands (colour map: None)


def texels(image: EnvironmentImage) -> Texels:
    """The map's linear Rec.709 radiance per texel, × strength, negative components
    clamped to 0 (a grey image gives its value on all three; a spectral map its bands'
    rest-frame colour, :func:`band_rgb`), and a spectral map's band radiance × strength,
    clamped to ≥ 0."""
    if image.spectral:
        bands = np.clip(np.asarray(image.pixels, np.float64), 0.0, None) * image.strength
        return Texels(np.clip(bands @ band_rgb(image.wavelengths_nm), 0.0, None), bands)
    px = np.asarray(image.pixels, np.float64)
    rgb = px[..., :3] if px.shape[2] >= 3 else np.repeat(px[..., :1], 3, axis=2)
    return Texels(np.clip(rgb, 0.0, None) * image.strength, None)


def band_rgb(nm: np.ndarray) -> np.ndarray:
    """(B, 3): the rest-frame linear Rec.709 (cie1931 sensor) of each band's hat function
    (1 at λ_b, falling linearly to 0 at its neighbours), so Σ_b L_b · band_rgb[b] is the
    colour of the interpolated spectrum."""
    out = np.zeros((len(nm), 3))
    for b in range(len(nm)):
        one = np.zeros(len(nm))
        one[b] = 1.0
        out[b] = spectrum.rgb_of(spectrum.tabulated(nm, one))
    return out


def solid_angles(height: int, width: int) -> np.ndarray:
    """ΔΩ of a texel of each row (H,), row 0 at the bottom: (2π/W)(cos θ_top − cos θ_bot)
    with θ = π(1 − v)."""
    v = np.arange(height + 1) / height
    cos_t = np.cos(math.pi * (1.0 - v))  # row r spans cos θ from cos_t[r] to cos_t[r + 1]
    return (2.0 * math.pi / width) * (cos_t[1:] - cos_t[:-1])


def texel_power(rgb: np.ndarray) -> np.ndarray:
    """Y_t ΔΩ_t per texel (H, W): the sampling weights and the map's power."""
    h, w = rgb.shape[:2]
    return (rgb @ LUMA) * solid_angles(h, w)[:, None]


def texel_weights(tx: Texels) -> np.ndarray:
    """The sampling weight of each texel (H, W): Y_t ΔΩ_t, plus a spectral texel's
    :data:`SPECTRAL_FLOOR` term (module docstring)."""
    power = texel_power(tx.rgb)
    if tx.bands is not None:
        h, w = power.shape
        y_flat = float(spectrum.y_of(np.ones(spectrum.GRID_N, np.float32)))
        power = power + (SPECTRAL_FLOOR * y_flat * tx.bands.mean(axis=2)
                         * solid_angles(h, w)[:, None])
    return power


def distribution(power: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(marginal CDF over rows (H+1,), conditional CDFs (H, W+1), texel pmf (H, W)) of
    the piecewise-constant density ∝ ``power``; all zeros stay a valid (unused) table."""
    h, w = power.shape
    total = float(power.sum())
    rows = power.sum(axis=1)
    marg = np.zeros(h + 1)
    cond = np.zeros((h, w + 1))
    if total <= 0.0:
        marg[1:] = np.arange(1, h + 1) / h
        cond[:, 1:] = np.arange(1, w + 1) / w
        return marg, cond, np.zeros((h, w), np.float32)
    marg[1:] = np.cumsum(rows) / total
    marg[-1] = 1.0
    safe = np.where(rows > 0.0, rows, 1.0)
    cond[:, 1:] = np.cumsum(power, axis=1) / safe[:, None]
    cond[rows <= 0.0, 1:] = np.arange(1, w + 1) / w  # never chosen: any valid CDF
    cond[:, -1] = 1.0
    return marg, cond, (power / total).astype(np.float32)


def texel_table(rgb: np.ndarray, mode: str) -> np.ndarray:
    """(c0, c1, c2, k) per texel (module docstring), float32 (H, W, 4); rgb mode
    (r, g, b, 1)."""
    h, w = rgb.shape[:2]
    out = np.zeros((h, w, 4), np.float32)
    if mode == "rgb":
        out[..., :3] = rgb
        out[..., 3] = 1.0
    elif mode == "seed-gaussian":
        out[..., 3] = 2.0 * rgb.mean(axis=2)
    else:
        k = 2.0 * rgb.max(axis=2)
        out[..., :3] = coefficients(rgb / np.where(k > 0.0, k, 1.0)[..., None])
        out[..., 3] = k
    return out


def base_row(mode: str) -> np.ndarray:
    """E(λ) as an emission-table row: D65_ext, the seed's flat emitter, or rgb ones."""
    if mode == "rgb":
        return np.ones(3, np.float32)
    if mode == "seed-gaussian":
        return spectrum.flat_emission()
    return spectrum.d65_ext()


def power_estimate(env: KernelEnvironment, radius: float) -> float:
    """The map's power through the scene's bounding sphere, Σ Y_t ΔΩ_t · π r² (as the
    constant sky's L · 4π · π r²; the sum is ``env.power``): its share in light
    selection."""
    return env.power * math.pi * radius * radius


def kernel_environment(image: EnvironmentImage | None, mode: str, row: int) -> KernelEnvironment:
    """The kernel tables of ``image`` (None: an unused 1×1 placeholder, ``on`` False);
    ``row`` is where :func:`base_row` went in the emission table."""
    if image is None:
        return KernelEnvironment(False, np.zeros((1, 1, 4), np.float32), np.array([0.0, 1.0]),
                                 np.array([[0.0, 1.0]]), np.zeros(1, np.int32),
                                 np.zeros((1, 1), np.int32), np.zeros((1, 1), np.float32), 0.0,
                                 max(row, 0), np.zeros(0), 0.0)
    tx = texels(image)
    weights = texel_weights(tx)
    marg, cond, pmf = distribution(weights)
    mguide = guide_table(marg)
    cguide = np.stack([guide_table(c) for c in cond])
    if tx.bands is not None and mode != "rgb":
        tex = tx.bands.astype(np.float32)
        nm = np.asarray(image.wavelengths_nm, np.float64)
    else:
        tex, nm = texel_table(tx.rgb, mode), np.zeros(0)
    return KernelEnvironment(True, tex, marg, cond, mguide, cguide, pmf,
                             math.radians(image.rotation_z), row, nm, float(weights.sum()))


# ------------------------------------------------------------------ device functions
# Compiled apart from the shade kernel (its compile time), and without reference counting
# (``_nrt=False``: they allocate nothing and only read their caller's arrays), so a call
# costs no atomic operation per array argument or view (measured: a bilinear lookup of
# the map 250 -> 175 ns, a light sample 185 -> 140 ns).


@njit(**INLINE_IR)
def uv_of(x, y, z, rot):
    """Map coordinates (u, v) ∈ [0, 1)² × [0, 1] of the unit lab direction (x, y, z)
    (polynomial ``acos``/``atan2``, :mod:`.arcs`: straight-line code that the SIMD lanes
    vectorise)."""
    cz = min(max(np.float64(z), -1.0), 1.0)
    v = 1.0 - arccos(cz) * INV_PI
    u = (math.pi + rot - arctan2(np.float64(y), np.float64(x))) * INV_TWO_PI
    return u - math.floor(u), v


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def direction_to_uv(x, y, z, rot):
    """:func:`uv_of`, compiled apart (one path at a time)."""
    return uv_of(x, y, z, rot)


@njit(**INLINE_IR)
def direction_of(u, v, rot):
    """The unit lab direction of map coordinates (u, v) and its sin θ: θ = π(1 − v),
    φ = π + ρ − 2πu, by :func:`.sampling.sincos_2pi` of θ/2π and φ/2π (mod 1)."""
    ct, st = sincos_2pi(0.5 * (1.0 - v))
    f = 0.5 + rot * INV_TWO_PI - u
    cp, sp = sincos_2pi(f - math.floor(f))
    return (st * cp, st * sp, ct), st


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def uv_to_direction(u, v, rot):
    """:func:`direction_of`, compiled apart."""
    return direction_of(u, v, rot)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_bilinear(tex, rot, x, y, z):
    """The 2 × 2 texels around the lab direction (x, y, z) and its weights, for the
    bilinear lookup of the map seen directly (:func:`bilinear_of`)."""
    u, v = uv_of(x, y, z, rot)
    return bilinear_of(tex.shape[0], tex.shape[1], u, v)


@njit(**INLINE_IR)
def bilinear_of(h, w, u, v):
    """The 2 × 2 texels of an H × W map around the map coordinates (u, v) ∈ [0, 1]² and
    their weights (texel centres at ((c + ½)/W, (r + ½)/H); columns wrap around, rows
    clamp at the poles): (r0, r1, c0, c1, fy, fx), the value being
    (1−fy)((1−fx) L[r0,c0] + fx L[r0,c1]) + fy((1−fx) L[r1,c0] + fx L[r1,c1]).
    Straight-line code (the wrap of c0 ∈ [−1, W − 1] by selects)."""
    cx = u * w - 0.5
    ry = min(max(v * h - 0.5, 0.0), h - 1.0)
    c0 = int(math.floor(cx))
    fx = cx - c0
    r0 = min(int(ry), h - 1)
    c1 = c0 + 1
    return (r0, min(r0 + 1, h - 1), c0 + w if c0 < 0 else c0, c1 - w if c1 >= w else c1,
            ry - r0, fx)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_lanes(tex, r, c, rgb, nm, lamu, base):
    """Texel (r, c)'s radiance for the four lanes, a 4-tuple: rgb mode its channels
    (the fourth 0), a spectral map (``nm`` not empty) its bands interpolated at each
    lane's lab wavelength λ, else k · s(λ; c) · E. ``lamu``: the lanes' table columns,
    ``base``: E(λ) at them (the emission row), both 4-tuples. One call per lookup (not one per
    lane and texel), each lane's λ computed once."""
    return _texel_lanes(tex, r, c, rgb, nm, lane_lambdas(lamu, rgb), base)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_lanes_bilinear(tex, q, rgb, nm, lamu, base):
    """:func:`env_lanes` interpolated over the texels ``q`` of :func:`env_bilinear`:
    (1−fy)((1−fx) L[r0,c0] + fx L[r0,c1]) + fy((1−fx) L[r1,c0] + fx L[r1,c1]) per lane."""
    return env_bilinear_at(tex, q, rgb, nm, lane_lambdas(lamu, rgb), base)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_texel_at(tex, r, c, rgb, nm, lam, base):
    """:func:`env_lanes` with the lanes' wavelengths ``lam`` (nm, :func:`lane_lambdas`)
    given: for a caller whose lanes do not change from lookup to lookup."""
    return _texel_lanes(tex, r, c, rgb, nm, lam, base)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_bilinear_at(tex, q, rgb, nm, lam, base):
    """:func:`env_lanes_bilinear` with the lanes' wavelengths ``lam`` given."""
    r0, r1, c0, c1, fy, fx = q
    a = _mix(_texel_lanes(tex, r0, c0, rgb, nm, lam, base),
             _texel_lanes(tex, r0, c1, rgb, nm, lam, base), fx)
    b = _mix(_texel_lanes(tex, r1, c0, rgb, nm, lam, base),
             _texel_lanes(tex, r1, c1, rgb, nm, lam, base), fx)
    return _mix(a, b, fy)


@njit(**INLINE_IR)
def _mix(a, b, f):
    """:func:`mix` per lane of two 4-tuples."""
    return (mix(a[0], b[0], f), mix(a[1], b[1], f), mix(a[2], b[2], f), mix(a[3], b[3], f))


@njit(**INLINE_IR)
def mix(a, b, f):
    """(1 − f) a + f b: the bilinear lookup's blend (:func:`env_bilinear_at`)."""
    return (1.0 - f) * a + f * b


@njit(**INLINE_IR)
def lane_lambdas(lamu, rgb):
    """λ (nm) of the four lanes' table columns (rgb lanes: unused zeros)."""
    if rgb:
        return (0.0, 0.0, 0.0, 0.0)
    return (lambda_of_column(lamu[0]), lambda_of_column(lamu[1]),
            lambda_of_column(lamu[2]), lambda_of_column(lamu[3]))


@njit(**INLINE_IR)
def _texel_lanes(tex, r, c, rgb, nm, lam, base):
    """:func:`env_lanes` of texel (r, c) at the lanes' wavelengths ``lam`` (nm)."""
    if rgb:
        return (np.float64(tex[r, c, 0]), np.float64(tex[r, c, 1]), np.float64(tex[r, c, 2]),
                0.0)
    if nm.shape[0] > 0:
        return (band_value(tex, r, c, nm, lam[0]), band_value(tex, r, c, nm, lam[1]),
                band_value(tex, r, c, nm, lam[2]), band_value(tex, r, c, nm, lam[3]))
    row = (np.float64(tex[r, c, 0]), np.float64(tex[r, c, 1]), np.float64(tex[r, c, 2]),
           np.float64(tex[r, c, 3]))
    return (row_value(row, False, 0, lam[0], base[0]), row_value(row, False, 1, lam[1], base[1]),
            row_value(row, False, 2, lam[2], base[2]), row_value(row, False, 3, lam[3], base[3]))


@njit(**INLINE_IR)
def row_value(row, rgb, j, lam, base):
    """Lane ``j``'s radiance of a colour map's texel whose (c0, c1, c2, k) (rgb mode
    (r, g, b, 1)) are ``row`` (the SIMD lanes' form of :func:`env_lanes`, no bands): the
    rgb mode its channel j, else k · E(λ) · s(λ; c) at the lane's λ (nm) and E(λ)
    ``base``; straight-line code."""
    value = row[3] * base * sigmoid_reflectance(row[0], row[1], row[2], lam)
    channel = row[0] if j == 0 else (row[1] if j == 1 else row[2])  # (static indices)
    return channel if rgb else value


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def band_value(tex, r, c, nm, lam):
    """Texel (r, c)'s spectral radiance at λ (nm): its bands at ``nm`` interpolated
    linearly, 0 outside [nm[0], nm[-1]] (module docstring)."""
    n = nm.shape[0]
    if not (nm[0] <= lam <= nm[n - 1]):
        return 0.0
    k = min(max(np.searchsorted(nm, lam), 1), n - 1)
    f = (lam - nm[k - 1]) / (nm[k] - nm[k - 1])
    return (1.0 - f) * np.float64(tex[r, c, k - 1]) + f * np.float64(tex[r, c, k])


@njit(**INLINE_IR)
def texel_pdf_of(pmf, u, v, z):
    """(row, column, solid-angle density) at map coordinates (u, v) of a lab direction
    whose z component is ``z``: the texel they fall in and p_t H W / (2π² sin θ),
    sin θ = √(1 − z²) (0 at the poles); straight-line code."""
    h, w = pmf.shape[0], pmf.shape[1]
    r, c = min(int(v * h), h - 1), min(int(u * w), w - 1)
    cz = min(max(np.float64(z), -1.0), 1.0)
    st = math.sqrt(max(0.0, 1.0 - cz * cz))  # (numba's ** 2 is a loop: not vectorised)
    pdf = np.float64(pmf[r, c]) * h * w / (TWO_PI_SQ * st)
    return r, c, pdf if st > 0.0 else 0.0


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_texel_pdf(pmf, rot, x, y, z):
    """(row, column, :func:`env_pdf`) of the lab direction (x, y, z): the texel it sees
    and the solid-angle density there, from one (u, v) (:func:`texel_pdf_of`)."""
    u, v = uv_of(x, y, z, rot)
    return texel_pdf_of(pmf, u, v, z)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_pdf(pmf, rot, x, y, z):
    """Solid-angle density of :func:`env_sample` at the lab direction (x, y, z):
    p_t H W / (2π² sin θ) (0 at the poles)."""
    return env_texel_pdf(pmf, rot, x, y, z)[2]


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _pick(cdf, guide, u):
    """(k, fraction) with cdf[k] <= u < cdf[k + 1] and u's place inside it."""
    k = guided_bin(cdf, guide, u)
    return k, place(cdf[k], cdf[k + 1], u)


@njit(**INLINE_IR)
def place(lo, hi, u):
    """u's place inside the CDF's step [lo, hi): (u − lo)/(hi − lo) (½ for an empty
    step), clamped to [0, 1 − 1e-7]."""
    f = (u - lo) / (hi - lo) if hi > lo else 0.5
    return min(max(f, 0.0), 1.0 - 1e-7)


@njit(**INLINE_IR)
def sample_pdf(pmf, r, c, st):
    """The solid-angle density of :func:`env_sample` at texel (r, c) where sin θ = st:
    p_t H W / (2π² st) (0 at a pole)."""
    h, w = pmf.shape[0], pmf.shape[1]
    pdf = np.float64(pmf[r, c]) * h * w / (TWO_PI_SQ * st)
    return pdf if st > 0.0 else 0.0


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_sample(marg, cond, mguide, cguide, pmf, rot, u1, u2):
    """A lab direction drawn ∝ texel power (module docstring), its solid-angle pdf (0
    when it fell on a pole: then refuse the sample) and the texel (row, column) it lies
    in: the row by the marginal CDF at u1, the column by that row's conditional CDF at
    u2 (each searched from its guide table, :func:`..physics.spectrum.guided_bin`)."""
    h, w = pmf.shape[0], pmf.shape[1]
    r, fv = _pick(marg, mguide, u1)
    c, fu = _pick(cond[r], cguide[r], u2)
    wi, st = direction_of((c + fu) / w, (r + fv) / h, rot)
    return wi, sample_pdf(pmf, r, c, st), r, c


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def env_light_sample(marg, cond, mguide, cguide, pmf, rot, p_sel, u1, u2):
    """Next-event estimation towards the map, picked with probability ``p_sel``: the
    tuple of :func:`.lights.sample_light` (wi, p_sel · pdf, scale 1, not delta, at
    infinity: no target point, accepted when the pdf is positive), and the sampled
    texel (row, column) for :func:`env_lanes` (no second lookup of wi's texel)."""
    wi, pdf, r, c = env_sample(marg, cond, mguide, cguide, pmf, rot, u1, u2)
    p_l = p_sel * pdf
    return (wi, p_l, 1.0, False, False, (0.0, 0.0, 0.0), p_l > 0.0), (r, c)
