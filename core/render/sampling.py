"""Random numbers and warps for the path tracer (numba device functions).

Every random number is a pure function of (seed, frame, pixel, sample) and a dimension
index, so an image never depends on the thread count, the tiling or the batch size
(architecture.md, "Determinism").  A path's 64-bit key packs a per-pixel scramble word
(high 32 bits, a bijective hash of the pixel index under a hash of seed and frame, so no
two pixels of a frame share it) and the sample index (low 32 bits).

Two kinds of numbers are drawn from a key:

- :func:`rand` — an independent uniform per (key, dimension): SplitMix64's finaliser.
- :func:`sobol2` / :func:`sobol1` — *padded, Owen-scrambled Sobol* points (Burley 2020,
  "Practical hash-based Owen scrambling"; pbrt-v4's PaddedSobolSampler).  For each
  dimension (pair) the pixel's sample index s is shuffled by a nested uniform
  scramble, i' = N_h(s), and the point (Sobol_0(i'), Sobol_1(i')) is Owen-scrambled per
  coordinate.  Owen scrambling makes every point uniform on [0,1)² (unbiased), the
  shuffle decorrelates different dimension pairs of one path, and any aligned block of
  2^k samples of a pixel — in particular every power-of-two prefix — is a (0, k, 2)-net:
  one point in each of the 2^k elementary rectangles of area 2^-k.  The integrator uses
  them for the pixel position, the light sample and the BSDF direction of every bounce,
  which is where stratification pays; 1-D decisions (roulette, lobe) use :func:`rand`.

Warps map uniform numbers on [0,1)² to directions with known pdfs (solid angle):

- cosine hemisphere about n:   p(ω) = cos θ / π
- uniform sphere:              p(ω) = 1 / (4π)
- uniform point on a triangle: p(y) = 1 / area   (u' = sqrt(u1): b0 = 1 - u', b1 = u' (1 - u2))
"""

from __future__ import annotations

import math

import numpy as np

from ..jit import INLINE, njit

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S40 = np.uint64(40)
_S32 = np.uint64(32)
_S16 = np.uint64(16)
_S15 = np.uint64(15)
_H1 = np.uint64(0x7FEB352D)
_H2 = np.uint64(0x846CA68B)
_MASK32 = np.uint64(0xFFFFFFFF)
_INV24 = np.float32(1.0 / 16777216.0)
_INV32 = 1.0 / 4294967296.0
INV_PI = np.float32(1.0 / math.pi)
ONE_MINUS = 1.0 - 2.0**-53
"""The largest float64 below 1: keeps a rescaled uniform inside [0, 1)."""

# The sample-dimension layout: the one place that says which dimension index each random
# number of a path uses (:func:`sobol2` takes a pair's index, :func:`rand` a scalar's;
# they share one index space, so no two consumers draw the same numbers).
DIM_PIXEL = 0
"""sobol2: the pixel jitter (x, y) of the camera ray."""
DIM_WAVELENGTH = 2
"""rand, of the pixel's own key: the hero-wavelength rotation (:func:`progressive_offsets`)."""
DIMS_CAMERA = 3
"""Dimensions before the first bounce's."""
DIM_LIGHT = 0
"""Per bounce, sobol2: the light pick (reused inside its cdf interval) and the point on it."""
DIM_LOBE = 3
"""Per bounce, rand: the lobe of the continuation."""
DIM_BSDF = 4
"""Per bounce, sobol2: the continuation direction."""
DIM_ROULETTE = 6
"""Per bounce, rand: Russian roulette."""
DIMS_PER_BOUNCE = 8
"""Dimensions per bounce (1, 2, 5 and 7 are spare)."""


@njit(**INLINE)
def bounce_dim(depth, offset):
    """The dimension of ``offset`` (``DIM_LIGHT`` ...) at bounce ``depth`` (0: the camera
    ray's hit)."""
    return DIMS_CAMERA + depth * DIMS_PER_BOUNCE + offset


@njit(**INLINE)
def mix64(z):
    """SplitMix64 finaliser: a bijective avalanche hash of a uint64."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(**INLINE)
def hash32(x):
    """A bijective avalanche hash of a 32-bit word (in a uint64; Wellons' lowbias32)."""
    x = x & _MASK32
    x ^= x >> _S16
    x = (x * _H1) & _MASK32
    x ^= x >> _S15
    x = (x * _H2) & _MASK32
    return x ^ (x >> _S16)


@njit(cache=True, nogil=True, error_model="numpy")
def pixel_word(seed, frame, pixel):
    """The pixel's 32-bit scramble word: distinct for every pixel of a frame."""
    salt = mix64(np.uint64(seed) * _GOLDEN + np.uint64(frame))
    return hash32((np.uint64(pixel) ^ salt) & _MASK32) ^ ((salt >> _S32) & _MASK32)


@njit(cache=True, nogil=True, error_model="numpy")
def path_key(seed, frame, pixel, sample):
    """The key of one path: pixel_word(seed, frame, pixel) << 32 | sample (32 bits)."""
    return (pixel_word(seed, frame, pixel) << _S32) | (np.uint64(sample) & _MASK32)


@njit(cache=True, nogil=True, error_model="numpy")
def path_keys(seed, frame, pixels, samples, out=None):
    """Vector form of :func:`path_key` for a wavefront (into ``out``'s first N rows if
    given: a caller's buffer reused across wavefronts)."""
    if out is None:
        out = np.empty(len(pixels), np.uint64)
    out = out[:len(pixels)]
    for i in range(len(pixels)):
        out[i] = path_key(seed, frame, pixels[i], samples[i])
    return out


@njit(**INLINE)
def rand(key, dim):
    """Uniform float32 in [0, 1) for dimension ``dim`` of the path with ``key``."""
    x = mix64(key + np.uint64(dim + 1) * _GOLDEN)
    return np.float32(x >> _S40) * _INV24


_R1 = np.uint64(0x55555555)
_R2 = np.uint64(0x33333333)
_R4 = np.uint64(0x0F0F0F0F)
_R8 = np.uint64(0x00FF00FF)
_U1 = np.uint64(1)
_U2 = np.uint64(2)
_U4 = np.uint64(4)
_U8 = np.uint64(8)
_LK = (np.uint64(0x6C50B47C), np.uint64(0xB82F1E52), np.uint64(0xC7AFE638),
       np.uint64(0x8D22F6E6))


@njit(**INLINE)
def reverse32(x):
    """The 32 low bits of x in reverse order."""
    x = ((x >> _U1) & _R1) | ((x & _R1) << _U1)
    x = ((x >> _U2) & _R2) | ((x & _R2) << _U2)
    x = ((x >> _U4) & _R4) | ((x & _R4) << _U4)
    x = ((x >> _U8) & _R8) | ((x & _R8) << _U8)
    return ((x >> _S16) | (x << _S16)) & _MASK32


@njit(**INLINE)
def laine_karras(x, seed):
    """A random permutation of 32-bit words in which bit k depends only on bits ≤ k.

    Applied to bit-reversed numbers it is an Owen (nested uniform) scramble: each
    digit of the binary fraction is flipped by a hash of the digits before it
    (Burley 2020's constants).
    """
    x = (x + seed) & _MASK32
    x ^= (x * _LK[0]) & _MASK32
    x ^= (x * _LK[1]) & _MASK32
    x ^= (x * _LK[2]) & _MASK32
    x ^= (x * _LK[3]) & _MASK32
    return x


@njit(**INLINE)
def sobol1_reversed(i):
    """Sobol's dimension 1 of a 32-bit index i, bit-reversed: bit j of the result is the
    fraction's digit of weight 2^-(j+1).

    Its direction numbers (primitive polynomial x + 1: v_0 = 1/2, v_k = v_(k-1) xor
    v_(k-1)/2) are the rows of Pascal's triangle mod 2: v_k has the digit of weight
    2^-(j+1) iff C(k, j) is odd, that is (Lucas) iff the bits of j are a subset of those
    of k. So digit j of x_i = xor of v_k over the set bits k of i is the xor of i's bits
    k ⊇ j: the superset transform over GF(2), five shift-and-xor steps (one per bit of
    j), no table. In the SIMD lanes this replaced a byte table's four gathers per point
    (each a 64-bit gather in every lane)."""
    i = i & _MASK32
    i ^= (i >> _U1) & _R1
    i ^= (i >> _U2) & _R2
    i ^= (i >> _U4) & _R4
    i ^= (i >> _U8) & _R8
    return i ^ (i >> _S16)


@njit(**INLINE)
def _dim_seeds(key, dim):
    h = mix64((key >> _S32) * _GOLDEN + np.uint64(dim + 1) * _M2)
    return h & _MASK32, h >> _S32


@njit(**INLINE)
def sobol2(key, dim):
    """The Owen-scrambled, shuffled Sobol point (u1, u2) ∈ [0,1)² of a path (float64).

    Pair ``dim`` of the pixel's sample ``key & 0xffffffff``; see the module docstring.
    """
    h_shuffle, h_x = _dim_seeds(key, dim)
    i = reverse32(laine_karras(reverse32(key & _MASK32), h_shuffle))
    # x: Sobol_0(i) = reverse(i); its Owen scramble is reverse(LK(reverse(reverse(i))))
    x = reverse32(laine_karras(i, h_x))
    y = reverse32(laine_karras(sobol1_reversed(i), mix64(h_x) & _MASK32))
    return np.float64(x) * _INV32, np.float64(y) * _INV32


@njit(**INLINE)
def sobol1(key, dim):
    """The Owen-scrambled, shuffled van der Corput number of dimension ``dim`` (float64)."""
    h_shuffle, h_x = _dim_seeds(key, dim)
    i = reverse32(laine_karras(reverse32(key & _MASK32), h_shuffle))
    return np.float64(reverse32(laine_karras(i, h_x))) * _INV32


@njit(cache=True, nogil=True, error_model="numpy")
def sobol2_dims(keys, dim):
    """sobol2(key, dim) for every key of a wavefront: (N, 2) float64."""
    out = np.empty((len(keys), 2), np.float64)
    for k in range(len(keys)):
        out[k, 0], out[k, 1] = sobol2(keys[k], dim)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def rand_dims(keys, dim):
    """rand(key, dim) for every key of a wavefront (float64)."""
    out = np.empty(len(keys), np.float64)
    for i in range(len(keys)):
        out[i] = rand(keys[i], dim)
    return out


@njit(**INLINE)
def onb(nx, ny, nz):
    """An orthonormal basis (t, b) perpendicular to unit n (Duff et al. 2017)."""
    s = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (s + nz)
    b = nx * ny * a
    return (1.0 + s * nx * nx * a, s * b, -s * nx), (b, s + ny * ny * a, -ny)


_HALF_PI = 0.5 * math.pi
_SQRT_HALF = math.sqrt(0.5)


@njit(**INLINE)
def sincos_2pi(u):
    """(cos 2πu, sin 2πu) for u ∈ [0, 1), to about 4e-16, without libm's sincos.

    4u = q + r (quadrant q, r ∈ [0, 1)); θ = (r - ½)·π/2 ∈ [-π/4, π/4) by Taylor series
    through θ¹⁶ (truncation ≤ (π/4)¹⁷/17! ≈ 5e-17); then the angle q·π/2 + π/4 + θ by
    exact rotations.  libm's sincos was about a fifth of the shading kernel's time; the
    environment map's directions (:func:`.environment.uv_to_direction`) need the full
    accuracy: near its poles sin θ comes back as √(1 − cos²θ), which a 2e-9 error in
    cos θ moved by up to 5e-5 relative (the series stopped at θ¹⁰ before 2026-11-27).
    """
    x = 4.0 * u
    q = math.floor(x)
    t = (x - q - 0.5) * _HALF_PI
    t2 = t * t
    s = t * (1.0 + t2 * (-1.0 / 6.0 + t2 * (1.0 / 120.0 + t2 * (-1.0 / 5040.0 + t2 * (
        1.0 / 362880.0 + t2 * (-1.0 / 39916800.0 + t2 * (1.0 / 6227020800.0 + t2 * (
            -1.0 / 1307674368000.0))))))))
    c = 1.0 + t2 * (-0.5 + t2 * (1.0 / 24.0 + t2 * (-1.0 / 720.0 + t2 * (1.0 / 40320.0 + t2 * (
        -1.0 / 3628800.0 + t2 * (1.0 / 479001600.0 + t2 * (-1.0 / 87178291200.0 + t2 * (
            1.0 / 20922789888000.0))))))))
    # rotate by π/4: (cos, sin)(π/4 + θ)
    c, s = _SQRT_HALF * (c - s), _SQRT_HALF * (c + s)
    # the quadrant by selects, not branches (so a loop over SIMD lanes vectorises): odd
    # quadrants turn (c, s) by π/2, the upper two by π
    odd = q == 1.0 or q == 3.0
    c, s = (-s, c) if odd else (c, s)
    sign = -1.0 if q >= 2.0 else 1.0
    return sign * c, sign * s


@njit(**INLINE)
def cosine_hemisphere(u1, u2):
    """Local direction (x, y, z) with z ≥ 0 and pdf cos θ / π."""
    r = math.sqrt(u1)
    c, s = sincos_2pi(u2)
    return r * c, r * s, math.sqrt(max(0.0, 1.0 - u1))


@njit(**INLINE)
def uniform_sphere(u1, u2):
    """Unit direction with pdf 1/(4π)."""
    z = 1.0 - 2.0 * u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    c, s = sincos_2pi(u2)
    return r * c, r * s, z


@njit(**INLINE)
def uniform_triangle(u1, u2):
    """Barycentrics (b1, b2) of a uniform point on a triangle (pdf 1/area)."""
    su = math.sqrt(u1)
    return su * (1.0 - u2), su * u2


@njit(**INLINE)
def to_world(x, y, z, t, b, nx, ny, nz):
    """Local (x, y, z) in the frame (t, b, n) -> world vector."""
    return (x * t[0] + y * b[0] + z * nx,
            x * t[1] + y * b[1] + z * ny,
            x * t[2] + y * b[2] + z * nz)


@njit(**INLINE)
def rescale_uniform(u, lo, width):
    """A uniform u known to lie in [lo, lo + width), mapped back to [0, 1): (u - lo)/width
    (below 1; 0 for an empty interval). A discrete choice made with u thus leaves a
    fresh uniform number for the next decision (pbrt-v4's SampleDiscrete)."""
    return min((u - lo) / width, ONE_MINUS) if width > 0.0 else 0.0


@njit(**INLINE)
def power_heuristic(pa, pb):
    """Veach's power heuristic (β = 2): pa² / (pa² + pb²)."""
    a = pa * pa
    b = pb * pb
    return a / (a + b) if a + b > 0.0 else 0.0


_SWAP_MASKS = np.array([0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF, 0x0000FFFF], np.uint64)


@njit(cache=True, nogil=True, error_model="numpy")
def radical_inverse2(i):
    """Van der Corput radical inverse in base 2 of a sample index (32 bits), in [0, 1)."""
    b = np.uint64(i) & _MASK32
    for k in range(5):
        sh = np.uint64(1 << k)
        mask = _SWAP_MASKS[k]
        b = ((b & mask) << sh) | ((b >> sh) & mask)
    return np.float64(b) * (1.0 / 4294967296.0)


@njit(cache=True, nogil=True, error_model="numpy")
def progressive_offsets(seed, frame, pixels, samples, out=None):
    """Per-sample offsets u = frac(vdc(sample) + r_pixel) for the hero wavelengths.

    Any prefix of a pixel's samples is well stratified (van der Corput), and the random
    per-pixel rotation r_pixel (Cranley–Patterson) keeps each u uniform, so a pixel that
    stops early (adaptive sampling) or renders a sample batch stays unbiased. ``out``:
    a buffer of at least N rows to fill (its first N are returned).
    """
    if out is None:
        out = np.empty(len(pixels), np.float64)
    out = out[:len(pixels)]
    for i in range(len(pixels)):
        r = rand(path_key(seed, frame, pixels[i], np.uint64(0xFFFFFFFF)), DIM_WAVELENGTH)
        v = radical_inverse2(samples[i]) + r
        out[i] = v - math.floor(v)
    return out
