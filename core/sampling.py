"""Random numbers and warps for the path tracer (numba device functions).

Counter-based RNG: every random number is a hash of (seed, frame, pixel, sample) and a
dimension index, so an image never depends on the thread count, the tiling or the
batch size (architecture.md, "Determinism").  The hash is SplitMix64's finaliser.

Warps map uniform numbers on [0,1)² to directions with known pdfs (solid angle):

- cosine hemisphere about n:   p(ω) = cos θ / π
- uniform sphere:              p(ω) = 1 / (4π)
- uniform point on a triangle: p(y) = 1 / area   (u' = sqrt(u1): b0 = 1 - u', b1 = u' (1 - u2))
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S40 = np.uint64(40)
_INV24 = np.float32(1.0 / 16777216.0)
INV_PI = np.float32(1.0 / math.pi)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def mix64(z):
    """SplitMix64 finaliser: a bijective avalanche hash of a uint64."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, nogil=True, error_model="numpy")
def path_key(seed, frame, pixel, sample):
    """The RNG key of one path: hash of (seed, frame, pixel, sample)."""
    k = mix64(np.uint64(seed) * _GOLDEN + np.uint64(frame))
    k = mix64(k + np.uint64(pixel) * _GOLDEN)
    return mix64(k ^ (np.uint64(sample) * _M2))


@njit(cache=True, nogil=True, error_model="numpy")
def path_keys(seed, frame, pixels, samples):
    """Vector form of :func:`path_key` for a wavefront."""
    out = np.empty(len(pixels), np.uint64)
    for i in range(len(pixels)):
        out[i] = path_key(seed, frame, pixels[i], samples[i])
    return out


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def rand(key, dim):
    """Uniform float32 in [0, 1) for dimension ``dim`` of the path with ``key``."""
    x = mix64(key + np.uint64(dim + 1) * _GOLDEN)
    return np.float32(x >> _S40) * _INV24


@njit(cache=True, nogil=True, error_model="numpy")
def rand_dims(keys, dim):
    """rand(key, dim) for every key of a wavefront (float64)."""
    out = np.empty(len(keys), np.float64)
    for i in range(len(keys)):
        out[i] = rand(keys[i], dim)
    return out


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def onb(nx, ny, nz):
    """An orthonormal basis (t, b) perpendicular to unit n (Duff et al. 2017)."""
    s = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (s + nz)
    b = nx * ny * a
    return (1.0 + s * nx * nx * a, s * b, -s * nx), (b, s + ny * ny * a, -ny)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def cosine_hemisphere(u1, u2):
    """Local direction (x, y, z) with z ≥ 0 and pdf cos θ / π."""
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    return r * math.cos(phi), r * math.sin(phi), math.sqrt(max(0.0, 1.0 - u1))


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def uniform_sphere(u1, u2):
    """Unit direction with pdf 1/(4π)."""
    z = 1.0 - 2.0 * u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u2
    return r * math.cos(phi), r * math.sin(phi), z


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def uniform_triangle(u1, u2):
    """Barycentrics (b1, b2) of a uniform point on a triangle (pdf 1/area)."""
    su = math.sqrt(u1)
    return su * (1.0 - u2), su * u2


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def to_world(x, y, z, t, b, nx, ny, nz):
    """Local (x, y, z) in the frame (t, b, n) -> world vector."""
    return (x * t[0] + y * b[0] + z * nx,
            x * t[1] + y * b[1] + z * ny,
            x * t[2] + y * b[2] + z * nz)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def power_heuristic(pa, pb):
    """Veach's power heuristic (β = 2): pa² / (pa² + pb²)."""
    a = pa * pa
    b = pb * pb
    return a / (a + b) if a + b > 0.0 else 0.0


_MASK32 = np.uint64(0xFFFFFFFF)
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
def progressive_offsets(seed, frame, pixels, samples):
    """Per-sample offsets u = frac(vdc(sample) + r_pixel) for the hero wavelengths.

    Any prefix of a pixel's samples is well stratified (van der Corput), and the random
    per-pixel rotation r_pixel (Cranley–Patterson) keeps each u uniform, so a pixel that
    stops early (adaptive sampling) or renders a sample batch stays unbiased.
    """
    out = np.empty(len(pixels), np.float64)
    for i in range(len(pixels)):
        r = rand(path_key(seed, frame, pixels[i], np.uint64(0xFFFFFFFF)), 2)
        v = radical_inverse2(samples[i]) + r
        out[i] = v - math.floor(v)
    return out
