"""The counter-based RNG and the warps."""

import math

import numpy as np
from numba import njit

from relray.core import sampling


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
