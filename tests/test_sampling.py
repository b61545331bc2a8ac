"""The counter-based RNG and the warps."""

import math

import numpy as np
from numba import njit

from relray.core.render import sampling


def test_rng_is_deterministic_and_uniform():
    keys = sampling.path_keys(3, 2, np.arange(200_000), np.zeros(200_000, np.int64))
    u = sampling.rand_dims(keys, 4)
    assert np.array_equal(u, sampling.rand_dims(keys.copy(), 4))
    assert u.min() >= 0.0 and u.max() < 1.0
    counts, _ = np.histogram(u, bins=20, range=(0, 1))
    expected = len(u) / 20
    assert np.all(np.abs(counts - expected) < 5 * math.sqrt(expected))


def test_rng_keys_differ_by_every_component():
    base = sampling.path_key(0, 1, 2, 3)
    others = [sampling.path_key(1, 1, 2, 3), sampling.path_key(0, 2, 2, 3),
              sampling.path_key(0, 1, 3, 3), sampling.path_key(0, 1, 2, 4)]
    assert len({int(base), *(int(k) for k in others)}) == 5


def test_dimensions_are_uncorrelated():
    keys = sampling.path_keys(0, 0, np.arange(100_000), np.zeros(100_000, np.int64))
    a, b = sampling.rand_dims(keys, 0), sampling.rand_dims(keys, 1)
    r = np.corrcoef(a, b)[0, 1]
    assert abs(r) < 5 / math.sqrt(len(a))


@njit(cache=True)
def _onb_check(n):
    t, b = sampling.onb(n[0], n[1], n[2])
    return np.array([t[0], t[1], t[2]]), np.array([b[0], b[1], b[2]])


def test_orthonormal_basis():
    rng = np.random.default_rng(1)
    for _ in range(100):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        t, b = _onb_check((n[0], n[1], n[2]))
        m = np.stack([t, b, n])
        assert np.allclose(m @ m.T, np.eye(3), atol=1e-12)


def test_uniform_triangle_barycentrics_are_uniform():
    keys = sampling.path_keys(0, 0, np.arange(100_000), np.zeros(100_000, np.int64))
    u1, u2 = sampling.rand_dims(keys, 0), sampling.rand_dims(keys, 1)
    b = np.array([sampling.uniform_triangle(a, c) for a, c in zip(u1, u2, strict=True)])
    assert np.all(b.sum(1) <= 1 + 1e-12) and np.all(b >= 0)
    # the mean of a uniform point in a triangle is its centroid: each barycentric 1/3
    se = b.std(0) / math.sqrt(len(b))
    assert np.all(np.abs(b.mean(0) - 1 / 3) < 5 * se)


def test_power_heuristic():
    assert sampling.power_heuristic(1.0, 1.0) == 0.5
    assert sampling.power_heuristic(0.0, 0.0) == 0.0
    assert math.isclose(sampling.power_heuristic(3.0, 1.0) + sampling.power_heuristic(1.0, 3.0), 1)


def test_radical_inverse_is_the_bit_reversal():
    assert [sampling.radical_inverse2(i) for i in range(4)] == [0.0, 0.5, 0.25, 0.75]
    assert sampling.radical_inverse2(2**31) == 2.0**-32
    assert sampling.radical_inverse2(2**32 - 1) == 1.0 - 2.0**-32


def test_progressive_offsets_stratify_every_power_of_two_prefix():
    """The first 2^k samples of a pixel put one offset in each of 2^k equal strata."""
    for k in (2, 4, 6):
        n = 2**k
        u = sampling.progressive_offsets(3, 1, np.full(n, 77, np.int64), np.arange(n))
        strata = np.floor(np.sort(u - u.min()) * n).astype(int)
        assert np.array_equal(np.sort(np.floor(((u - u[0]) % 1.0) * n)), np.arange(n))
        assert len(set(strata.tolist())) == n


def test_progressive_offsets_are_uniform_over_pixels():
    """For a fixed sample index the per-pixel rotation makes u uniform (unbiased)."""
    n = 100_000
    u = sampling.progressive_offsets(0, 0, np.arange(n), np.full(n, 5, np.int64))
    counts, _ = np.histogram(u, bins=20, range=(0, 1))
    assert np.all(np.abs(counts - n / 20) < 5 * math.sqrt(n / 20))


def _is_net(u: np.ndarray) -> bool:
    """Is the point set (n = 2^m points in [0,1)²) a (0, m, 2)-net in base 2: one point
    in every elementary rectangle 2^-a x 2^-(m-a)?"""
    m = int(math.log2(len(u)))
    for a in range(m + 1):
        cells = np.floor(u[:, 0] * 2**a).astype(np.int64) * 2 ** (m - a) \
            + np.floor(u[:, 1] * 2 ** (m - a)).astype(np.int64)
        if len(np.unique(cells)) != len(u):
            return False
    return True


def test_sobol_pairs_are_nets_in_every_aligned_power_of_two_block():
    """Progressive stratification: prefixes and aligned blocks of a pixel's samples."""
    n = 1024
    for dim in (0, 3, 11):
        keys = sampling.path_keys(5, 2, np.full(n, 1234, np.int64), np.arange(n))
        u = sampling.sobol2_dims(keys, dim)
        assert u.min() >= 0.0 and u.max() < 1.0
        for m in (1, 2, 4, 6, 8, 10):
            assert _is_net(u[: 2**m]), (dim, m)
        assert _is_net(u[256:512]) and _is_net(u[64:128])


def test_a_random_point_set_is_not_a_net():
    """The net check can fail: i.i.d. points are (almost surely) not a 64-point net."""
    keys = sampling.path_keys(5, 2, np.full(64, 1234, np.int64), np.arange(64))
    u = np.stack([sampling.rand_dims(keys, 0), sampling.rand_dims(keys, 1)], 1)
    assert not _is_net(u)


def test_sobol_points_are_uniform_over_pixels():
    """For a fixed sample index the per-pixel Owen scramble makes the point uniform on
    [0,1)² (unbiasedness): a 10 x 10 chi-square over 200k pixels."""
    n = 200_000
    for s in (0, 7):
        keys = sampling.path_keys(1, 0, np.arange(n), np.full(n, s, np.int64))
        u = sampling.sobol2_dims(keys, 4)
        h, _, _ = np.histogram2d(u[:, 0], u[:, 1], bins=10, range=[[0, 1], [0, 1]])
        chi2 = float(np.sum((h - n / 100) ** 2 / (n / 100)))
        assert chi2 < 99 + 5 * math.sqrt(2 * 99), chi2   # df = 99


def test_sobol_dimension_pairs_are_decorrelated():
    """The per-dimension index shuffle (padding): pairs 3 and 4 of one pixel's samples
    are uncorrelated, whereas without the shuffle they would be the same points."""
    n = 4096
    keys = sampling.path_keys(0, 0, np.full(n, 99, np.int64), np.arange(n))
    a, b = sampling.sobol2_dims(keys, 3), sampling.sobol2_dims(keys, 4)
    for i in range(2):
        for j in range(2):
            assert abs(np.corrcoef(a[:, i], b[:, j])[0, 1]) < 5 / math.sqrt(n)


def test_sobol1_stratifies_prefixes():
    n = 256
    keys = sampling.path_keys(0, 3, np.full(n, 7, np.int64), np.arange(n))
    u = np.array([sampling.sobol1(k, 9) for k in keys])
    for m in (2, 5, 8):
        assert np.array_equal(np.sort(np.floor(u[: 2**m] * 2**m)), np.arange(2**m))


def test_pixel_words_are_distinct_within_a_frame():
    """Every pixel of a frame gets its own scramble (no two pixels share a sequence)."""
    n = 1 << 20
    keys = sampling.path_keys(42, 7, np.arange(n), np.zeros(n, np.int64))
    assert len(np.unique(keys >> np.uint64(32))) == n
    assert np.all(keys & np.uint64(0xFFFFFFFF) == 0)


def sobol1_by_direction_numbers(i: int) -> int:
    """Sobol's dimension 1 of i as a 32-bit binary fraction, from its definition: the
    xor of v_k over the set bits k of i, v_0 = 2^31, v_k = v_(k-1) xor (v_(k-1) >> 1)."""
    v, x = 1 << 31, 0
    for k in range(32):
        if i >> k & 1:
            x ^= v
        v ^= v >> 1
    return x


def test_sobol1_matches_its_direction_numbers():
    """Sobol's dimension 1 in index (not Gray-code) order, x = 1/2, 3/4, 1/4, 5/8 ...:
    the superset transform (bit-reversed) against the xor of the direction numbers, at
    the first indices, at every single bit and at random 32-bit indices (the high bits
    of a 64-bit word are ignored)."""
    ref = [0.0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875]
    first = [sampling.reverse32(sampling.sobol1_reversed(np.uint64(i))) / 2**32
             for i in range(8)]
    assert first == ref
    rng = np.random.default_rng(5)
    idx = [1 << k for k in range(32)] + [0xFFFFFFFF] + list(
        rng.integers(0, 2**32, 2000, dtype=np.uint64))
    for i in idx:
        got = int(sampling.reverse32(sampling.sobol1_reversed(np.uint64(i) | _HIGH)))
        assert got == sobol1_by_direction_numbers(int(i)), i


_HIGH = np.uint64(0xDEADBEEF) << np.uint64(32)


@njit(cache=True)
def _sincos_all(u):
    c = np.empty(len(u))
    s = np.empty(len(u))
    for i in range(len(u)):
        c[i], s[i] = sampling.sincos_2pi(u[i])
    return c, s


def test_sincos_2pi_matches_libm():
    """The polynomial sincos agrees with long-double libm to 5e-16 over [0, 1), quadrant
    edges included (its series: 5e-17; the angle's rotations: a few ulp)."""
    u = np.concatenate([np.linspace(0.0, 1.0, 400_001)[:-1],
                        [0.25, 0.5, 0.75, 1.0 - 2.0**-53, 0.25 - 2.0**-54, 2.0**-60]])
    c, s = _sincos_all(u)
    angle = 2 * np.pi * u.astype(np.longdouble)  # x87's 64-bit mantissa: 2πu not rounded
    assert np.max(np.abs(c - np.cos(angle))) < 5e-16
    assert np.max(np.abs(s - np.sin(angle))) < 5e-16


def test_the_dimension_layout_gives_every_decision_its_own_index():
    """sampling's named layout: the camera's indices lie below DIMS_CAMERA, each bounce's
    below DIMS_PER_BOUNCE, and bounce_dim never gives two decisions of a path (camera or
    any bounce) the same index."""
    camera = [sampling.DIM_PIXEL, sampling.DIM_WAVELENGTH]
    bounce = [sampling.DIM_LIGHT, sampling.DIM_LOBE, sampling.DIM_BSDF, sampling.DIM_ROULETTE]
    assert len(set(camera)) == len(camera) and max(camera) < sampling.DIMS_CAMERA
    assert len(set(bounce)) == len(bounce) and max(bounce) < sampling.DIMS_PER_BOUNCE
    used = camera + [sampling.bounce_dim(depth, off) for depth in range(64) for off in bounce]
    assert len(set(used)) == len(used)
