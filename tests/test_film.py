"""Film accumulation: exact means, bands, determinism, merge, non-finite samples, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relray.core.render.film import (
    REL_ERROR_UNKNOWN,
    Film,
    band_centers,
    clamp_samples,
    window_mean,
)

AOVS = ("depth", "doppler", "lab_time")


def _stream(n: int, n_pix: int, seed: int = 0, bands: bool = True) -> dict:
    """A random sample stream (float32 like the integrator's)."""
    rng = np.random.default_rng(seed)
    s = {
        "pixel": rng.integers(0, n_pix, n),
        "sensor": rng.normal(1.0, 0.5, (n, 3)).astype(np.float32),
        "alpha": (rng.random(n) < 0.7).astype(np.float32),
        "aov": {k: rng.random(n).astype(np.float32) * 10 for k in AOVS},
    }
    if bands:
        s["lam_cam"] = (360.0 + 470.0 * rng.random((n, 4))).astype(np.float32)
        s["lam_weight"] = rng.random((n, 4)).astype(np.float32)
    return s


def _slice(s: dict, a: int, b: int) -> dict:
    out = {k: v[a:b] for k, v in s.items() if k != "aov"}
    out["aov"] = {k: v[a:b] for k, v in s["aov"].items()}
    return out


def _sums(f: Film) -> list[np.ndarray]:
    return [f.sum_sensor, f.sum_sq, f.sum_alpha, f.sum_aov, f.count, f.sum_band]


def test_band_centers_inclusive():
    c = band_centers((380, 780, 10))
    assert len(c) == 41 and c[0] == 380.0 and c[-1] == 780.0
    with pytest.raises(ValueError):
        band_centers((500, 400, 10))


def test_exact_means_and_layout():
    # 3 x 2 film; dyadic values so every mean is exact.
    f = Film(3, 2, aovs=("depth", "doppler"), bands=(400.0, 500.0, 10.0))
    pixel = np.array([0, 0, 5, 5, 5])  # (row 0, col 0) twice; (row 1, col 2) three times
    sensor = np.array(
        [[1.0, 2.0, 3.0], [3.0, 4.0, 5.0], [0.5, 0.25, 0.125], [1.5, 0.75, 0.375], [1, 2, 3]]
    )
    alpha = np.array([1.0, 0.0, 1.0, 1.0, 1.0])
    aov = {"depth": np.array([2.0, 4.0, 1.0, 2.0, 3.0]), "doppler": np.full(5, 1.5)}
    # Band of a lane: floor((λ - 395) / 10). Lanes at 400 (band 0), 404.5 (band 0),
    # 455 (band 6), 390 / 900 (outside: ignored).
    lam = np.array(
        [[400, 404.5, 455, 390], [400, 900, 900, 900], [455, 455, 455, 455], [900] * 4, [900] * 4]
    )
    w = np.array([[1.0, 2.0, 4.0, 8.0], [16.0, 1, 1, 1], [1.0, 1.0, 1.0, 1.0], [1.0] * 4, [1] * 4])
    f.add_samples(pixel, sensor, alpha, aov, lam, w)
    img = f.resolve(np.eye(3))

    assert img.rgba.shape == (2, 3, 4) and img.rgba.dtype == np.float32
    np.testing.assert_array_equal(img.rgba[0, 0], [2.0, 3.0, 4.0, 0.5])
    np.testing.assert_array_equal(
        img.rgba[1, 2, :3], np.mean(sensor[2:], axis=0).astype(np.float32)
    )
    assert img.rgba[1, 2, 3] == 1.0
    assert img.aovs["depth"][0, 0] == 3.0 and img.aovs["depth"][1, 2] == 2.0
    assert img.aovs["doppler"][1, 2] == 1.5
    np.testing.assert_array_equal(img.spp, [[2, 0, 0], [0, 0, 3]])

    assert img.spectral.shape == (2, 3, 11)
    np.testing.assert_array_equal(img.band_centers_nm, np.arange(400.0, 501.0, 10.0))
    # pixel 0: band 0 gets (1 + 2 + 16) / (2 samples * 10 nm); band 6 gets 4 / 20.
    expect0 = np.zeros(11)
    expect0[0] = 19.0 / 20.0
    expect0[6] = 4.0 / 20.0
    np.testing.assert_allclose(img.spectral[0, 0], expect0, rtol=1e-7)
    expect5 = np.zeros(11)
    expect5[6] = 4.0 / 30.0
    np.testing.assert_allclose(img.spectral[1, 2], expect5, rtol=1e-7)
    assert img.nonfinite_values == 0 and f.nonfinite_samples == 0


def test_resolve_uses_matrix():
    s = _stream(4000, 12, seed=3, bands=False)
    f = Film(4, 3)
    f.add_samples(s["pixel"], s["sensor"], s["alpha"])
    m = np.random.default_rng(1).normal(size=(3, 3))
    img = f.resolve(m)
    mean = np.zeros((12, 3))
    for p in range(12):
        mean[p] = s["sensor"][s["pixel"] == p].astype(np.float64).mean(axis=0)
    np.testing.assert_allclose(img.rgba[..., :3].reshape(12, 3), mean @ m.T, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError):
        f.resolve(np.eye(4))


def test_float32_and_float64_inputs_agree():
    s = _stream(3000, 20, seed=4)
    f32 = Film(5, 4, aovs=AOVS, bands=(380, 780, 10))
    f64 = Film(5, 4, aovs=AOVS, bands=(380, 780, 10))
    f32.add_samples(**s)
    s64 = {k: (v.astype(np.float64) if k not in ("aov", "pixel") else v) for k, v in s.items()}
    s64["aov"] = {k: v.astype(np.float64) for k, v in s["aov"].items()}
    f64.add_samples(**s64)
    for a, b in zip(_sums(f32), _sums(f64), strict=True):
        np.testing.assert_array_equal(a, b)


@settings(max_examples=25, deadline=None)
@given(cuts=st.lists(st.integers(0, 2000), max_size=6))
def test_batch_split_is_bit_identical(cuts):
    s = _stream(2000, 30, seed=5)
    whole = Film(6, 5, aovs=AOVS, bands=(380, 780, 10))
    whole.add_samples(**s)
    split = Film(6, 5, aovs=AOVS, bands=(380, 780, 10))
    edges = [0, *sorted(cuts), 2000]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        split.add_samples(**_slice(s, a, b))
    for x, y in zip(_sums(whole), _sums(split), strict=True):
        np.testing.assert_array_equal(x, y)


def test_merge_equals_one_film():
    s = _stream(5000, 30, seed=6)
    whole = Film(6, 5, aovs=AOVS, bands=(380, 780, 10))
    whole.add_samples(**s)
    parts = [Film(6, 5, aovs=AOVS, bands=(380, 780, 10)) for _ in range(3)]
    for part, (a, b) in zip(parts, [(0, 1000), (1000, 3500), (3500, 5000)], strict=True):
        part.add_samples(**_slice(s, a, b))
    merged = parts[0]
    merged.merge(parts[1])
    merged.merge(parts[2])
    np.testing.assert_array_equal(merged.count, whole.count)
    for x, y in zip(_sums(whole), _sums(merged), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError):
        merged.merge(Film(6, 5, aovs=AOVS))


def test_merge_exact_for_dyadic_values():
    rng = np.random.default_rng(7)
    n = 400
    pix = rng.integers(0, 4, n)
    sensor = rng.integers(-8, 8, (n, 3)) / 4.0
    a, b = Film(2, 2), Film(2, 2)
    a.add_samples(pix[:150], sensor[:150], np.ones(150))
    b.add_samples(pix[150:], sensor[150:], np.ones(n - 150))
    a.merge(b)
    whole = Film(2, 2)
    whole.add_samples(pix, sensor, np.ones(n))
    for x, y in zip(_sums(whole), _sums(a), strict=True):
        np.testing.assert_array_equal(x, y)


def test_nonfinite_samples_dropped_and_counted():
    s = _stream(500, 6, seed=8)
    bad = {
        k: (v.copy() if k != "aov" else {n: a.copy() for n, a in v.items()}) for k, v in s.items()
    }
    bad["sensor"][3, 0] = np.inf
    bad["alpha"][10] = np.nan
    bad["aov"]["depth"][20] = -np.inf
    bad["lam_weight"][30, 2] = np.nan
    bad["lam_cam"][40, 1] = np.inf
    f = Film(3, 2, aovs=AOVS, bands=(380, 780, 10))
    f.add_samples(**bad)
    assert f.nonfinite_samples == 5
    keep = np.ones(500, bool)
    keep[[3, 10, 20, 30, 40]] = False
    ref = Film(3, 2, aovs=AOVS, bands=(380, 780, 10))
    ref.add_samples(
        s["pixel"][keep],
        s["sensor"][keep],
        s["alpha"][keep],
        {k: v[keep] for k, v in s["aov"].items()},
        s["lam_cam"][keep],
        s["lam_weight"][keep],
    )
    for x, y in zip(_sums(f), _sums(ref), strict=True):
        np.testing.assert_array_equal(x, y)
    img = f.resolve(np.eye(3))
    for arr in (img.rgba, img.spectral, img.rel_error, *img.aovs.values()):
        assert np.isfinite(arr).all()


def test_all_nonfinite_batch_and_overflow_resolve_finite():
    f = Film(2, 1, aovs=("depth",))
    f.add_samples(np.array([0, 1]), np.full((2, 3), np.nan), np.ones(2), {"depth": np.ones(2)})
    assert f.nonfinite_samples == 2 and f.total_samples == 0
    # Finite float64 samples whose mean overflows float32: set to 0 and counted.
    f.add_samples(np.array([1]), np.array([[1e300, 1.0, 1.0]]), np.ones(1), {"depth": [1e300]})
    img = f.resolve(np.eye(3))
    assert np.isfinite(img.rgba).all() and np.isfinite(img.aovs["depth"]).all()
    assert img.rgba[0, 1, 0] == 0.0 and img.nonfinite_values == 2


def test_empty_pixels_resolve_to_zero():
    f = Film(4, 4, aovs=AOVS, bands=(380, 780, 20))
    f.add_samples(
        np.array([5]),
        np.ones((1, 3)),
        np.ones(1),
        {k: np.ones(1) for k in AOVS},
        np.full((1, 4), 550.0),
        np.ones((1, 4)),
    )
    with np.errstate(all="raise"):
        img = f.resolve(np.eye(3))
    empty = img.spp == 0
    assert empty.sum() == 15
    assert (img.rgba[empty] == 0).all()
    assert (img.spectral[empty] == 0).all()
    for a in img.aovs.values():
        assert (a[empty] == 0).all()
    assert (img.rel_error[empty] == np.float32(REL_ERROR_UNKNOWN)).all()
    assert img.rel_error[1, 1] == np.float32(REL_ERROR_UNKNOWN)  # one sample: unknown
    assert np.isfinite(img.rel_error).all()


def test_relative_error_matches_statistics():
    rng = np.random.default_rng(9)
    n_pix, n, c, sigma = 64, 2000, 2.0, 0.5
    pixel = np.repeat(np.arange(n_pix), n)
    y = c + sigma * rng.standard_normal(n_pix * n)
    sensor = np.stack([np.zeros_like(y), y, np.zeros_like(y)], axis=1)
    f = Film(8, 8)
    f.add_samples(pixel, sensor, np.ones(n_pix * n))
    rel = f.relative_error().reshape(-1).astype(np.float64)
    # Exactly the textbook estimator, per pixel ...
    yy = y.reshape(n_pix, n)
    direct = yy.std(axis=1, ddof=1) / np.sqrt(n) / yy.mean(axis=1)
    np.testing.assert_allclose(rel, direct, rtol=1e-5)
    # ... and close to the analytic σ/(√n c): the sample sd has relative spread
    # 1/√(2(n-1)) ≈ 1.6% per pixel, so the mean of 64 pixels is within 0.2% (1σ).
    analytic = sigma / np.sqrt(n) / c
    assert abs(rel.mean() / analytic - 1.0) < 0.01
    assert np.all(np.abs(rel / analytic - 1.0) < 6.0 / np.sqrt(2 * (n - 1)))


def test_relative_error_of_constant_and_black_pixels_is_zero():
    f = Film(2, 1)
    f.add_samples(
        np.array([0, 0, 0, 1, 1]), np.array([[0, 3.0, 0]] * 3 + [[0, 0, 0]] * 2), np.ones(5)
    )
    np.testing.assert_array_equal(f.relative_error(), [[0.0, 0.0]])


def test_input_validation():
    f = Film(2, 2, aovs=("depth",), bands=(400, 700, 10))
    ok = dict(sensor=np.ones((1, 3)), alpha=np.ones(1), aov={"depth": np.ones(1)})
    lam = dict(lam_cam=np.full((1, 4), 500.0), lam_weight=np.ones((1, 4)))
    with pytest.raises(ValueError):
        f.add_samples(np.array([4]), **ok, **lam)  # out of range
    with pytest.raises(ValueError):
        f.add_samples(np.array([-1]), **ok, **lam)
    with pytest.raises(ValueError):
        f.add_samples(np.array([0]), np.ones((1, 3)), np.ones(1), {}, **lam)  # AOV missing
    with pytest.raises(ValueError):
        f.add_samples(np.array([0]), **ok)  # bands need wavelengths
    f.add_samples(np.array([0]), **ok, **lam)
    f.add_samples(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), {"depth": np.zeros(0)})
    assert f.total_samples == 1


def test_vector_aovs_are_three_columns_each_and_resolve_to_h_w_3():
    """``albedo`` and ``normal`` take (N, 3) per sample, three sum columns each, and
    resolve to (h, w, 3) per-pixel means, next to the scalar AOVs; merge adds them."""
    f = Film(2, 1, aovs=("depth", "albedo", "normal"))
    assert f.sum_aov.shape == (2, 7)
    assert f.aov_columns == {"depth": (0, 1), "albedo": (1, 3), "normal": (4, 3)}
    pixel = np.array([0, 0, 1])
    albedo = np.array([[0.25, 0.5, 1.0], [0.75, 0.5, 0.0], [0.125, 0.0, 0.5]])
    normal = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    f.add_samples(pixel, np.ones((3, 3)), np.ones(3),
                  {"depth": np.array([1.0, 3.0, 2.0]), "albedo": albedo, "normal": normal})
    img = f.resolve(np.eye(3))
    assert img.aovs["depth"].shape == (1, 2) and img.aovs["albedo"].shape == (1, 2, 3)
    np.testing.assert_array_equal(img.aovs["depth"], [[2.0, 2.0]])
    np.testing.assert_array_equal(img.aovs["albedo"][0, 0], [0.5, 0.5, 0.5])
    np.testing.assert_array_equal(img.aovs["albedo"][0, 1], albedo[2])
    # the mean normal is not renormalised (Cycles, OIDN: averaged over the samples)
    np.testing.assert_array_equal(img.aovs["normal"][0, 0], [0.5, -0.5, 0.0])
    np.testing.assert_array_equal(img.aovs["normal"][0, 1], [0.0, 0.0, 0.0])
    other = Film(2, 1, aovs=("depth", "albedo", "normal"))
    other.add_samples(np.array([1]), np.ones((1, 3)), np.ones(1),
                      {"depth": np.array([4.0]), "albedo": np.array([[0.875, 1.0, 0.5]]),
                       "normal": np.array([[0.0, 0.0, 1.0]])})
    f.merge(other)
    img = f.resolve(np.eye(3))
    np.testing.assert_array_equal(img.aovs["albedo"][0, 1], [0.5, 0.5, 0.5])
    np.testing.assert_array_equal(img.aovs["normal"][0, 1], [0.0, 0.0, 0.5])
    # a scalar where a vector is due (and the reverse) is refused
    with pytest.raises(ValueError, match="albedo"):
        f.add_samples(np.array([0]), np.ones((1, 3)), np.ones(1),
                      {"depth": np.ones(1), "albedo": np.ones(1), "normal": np.ones((1, 3))})
    with pytest.raises(ValueError, match="depth"):
        f.add_samples(np.array([0]), np.ones((1, 3)), np.ones(1), {
            "depth": np.ones((1, 3)), "albedo": np.ones((1, 3)), "normal": np.ones((1, 3))})


def test_a_non_finite_normal_drops_the_whole_sample():
    f = Film(1, 1, aovs=("normal",))
    f.add_samples(np.array([0, 0]), np.ones((2, 3)), np.ones(2),
                  {"normal": np.array([[0.0, np.nan, 0.0], [0.0, 1.0, 0.0]])})
    assert f.nonfinite_samples == 1 and f.total_samples == 1
    np.testing.assert_array_equal(f.resolve(np.eye(3)).aovs["normal"][0, 0], [0, 1, 0])


# ----------------------------------------------------------------------------- clamp
M_XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314],
                            [-0.9692660, 1.8760108, 0.0415560],
                            [0.0556434, -0.2040259, 1.0572252]])


def test_clamp_bounds_the_largest_rgb_component_and_keeps_the_colour():
    rng = np.random.default_rng(5)
    s = np.abs(rng.standard_normal((4000, 3))) * rng.choice([0.1, 1.0, 1e3], (4000, 1))
    s[7] = [np.inf, 1.0, 1.0]  # non-finite samples are left for the film to drop
    s[8] = [np.nan, 1.0, 1.0]
    lanes = rng.random((4000, 4))
    before, lanes_before = s.copy(), lanes.copy()
    limit = 5.0
    n = clamp_samples(s, M_XYZ_TO_REC709, limit, lanes)
    rgb_before = before @ M_XYZ_TO_REC709.T
    big = np.abs(rgb_before).max(axis=1)
    over = big > limit
    assert n == int(over.sum()) and 100 < n < 3000
    rgb = s @ M_XYZ_TO_REC709.T
    finite = np.isfinite(big)
    assert np.abs(rgb[finite]).max() <= limit * (1 + 1e-12)
    # samples over the limit end up exactly on it, scaled by one factor k = limit / max
    np.testing.assert_allclose(np.abs(rgb[over & finite]).max(axis=1), limit, rtol=1e-12)
    k = limit / big[over & finite]
    np.testing.assert_allclose(s[over & finite], before[over & finite] * k[:, None], rtol=1e-12)
    np.testing.assert_allclose(lanes[over & finite], lanes_before[over & finite] * k[:, None],
                               rtol=1e-12)
    # the others are untouched, bit for bit (the NaN row too)
    np.testing.assert_array_equal(s[~over], before[~over])
    np.testing.assert_array_equal(lanes[~over], lanes_before[~over])
    assert np.isnan(s[8, 0]) and not np.isfinite(s[7]).all()
    # without band weights; a clamp of 0 is "off" and not a limit
    t = before[:100].copy()
    clamp_samples(t, np.eye(3), 1.0)
    assert np.abs(t[np.isfinite(t).all(1)]).max() <= 1.0
    with pytest.raises(ValueError):
        clamp_samples(before.copy(), np.eye(3), 0.0)


def test_clamp_uses_absolute_values_of_negative_rgb():
    """A saturated spectral sample can have a negative Rec.709 channel: its magnitude counts."""
    s = np.array([[0.0, 10.0, 10.0]])  # outside Rec.709: R = -20.4, G = 19.2, B = 8.5
    clamp_samples(s, M_XYZ_TO_REC709, 2.0)
    rgb = s @ M_XYZ_TO_REC709.T
    np.testing.assert_allclose(rgb[0, 0], -2.0, rtol=1e-12)  # the largest is |R|, not G
    assert 1.8 < rgb[0, 1] < 2.0


# ----------------------------------------------------------------------------- adaptive
def _grid_stream(per_pixel, n, seed=0):
    """n samples for every pixel; ``per_pixel(p, rng, n)`` returns its (n, 3) sensor values."""
    rng = np.random.default_rng(seed)
    pixels = len(per_pixel)
    pix = np.repeat(np.arange(pixels), n)
    sensor = np.concatenate([f(p, rng, n) for p, f in enumerate(per_pixel)])
    return pix, sensor


def test_sum_sq_holds_every_channel_and_sum_y2_is_its_luminance_column():
    s = _stream(3000, 12, seed=11, bands=False)
    f = Film(4, 3)
    f.add_samples(s["pixel"], s["sensor"], s["alpha"])
    x = s["sensor"].astype(np.float64)
    for p in range(12):
        np.testing.assert_allclose(f.sum_sq[p], (x[s["pixel"] == p] ** 2).sum(0), rtol=1e-12)
    np.testing.assert_array_equal(f.sum_y2, f.sum_sq[:, 1])


def test_adaptive_error_is_the_documented_estimator():
    """se = sqrt(Σ_c var_c / n) over the three channels, divided by sqrt(I · Ī) with
    I = |mean sensor vector| and Ī its image mean (core/render/film.py docstring)."""
    rng = np.random.default_rng(12)
    n_pix, n = 20, 300
    scale = rng.uniform(0.1, 3.0, (n_pix, 1, 3))
    noise = rng.uniform(0.0, 1.0, (n_pix, 1, 3))
    x = scale * (1.0 + noise * rng.standard_normal((n_pix, n, 3)))
    f = Film(5, 4)
    f.add_samples(np.repeat(np.arange(n_pix), n), x.reshape(-1, 3), np.ones(n_pix * n))
    m = x.mean(axis=1)
    se = np.sqrt((x.var(axis=1, ddof=1) / n).sum(axis=1))
    bright = np.linalg.norm(m, axis=1)
    expect = se / np.sqrt(bright * bright.mean())
    np.testing.assert_allclose(f.adaptive_error().ravel(), expect, rtol=1e-9)


def test_adaptive_error_properties():
    # scale-free: multiplying every sample by k leaves it unchanged
    s = _stream(4000, 12, seed=13, bands=False)
    a, b = Film(4, 3), Film(4, 3)
    a.add_samples(s["pixel"], s["sensor"].astype(np.float64), s["alpha"])
    b.add_samples(s["pixel"], s["sensor"].astype(np.float64) * 1024.0, s["alpha"])
    np.testing.assert_allclose(a.adaptive_error(), b.adaptive_error(), rtol=1e-12)
    # a pixel as bright as the image mean reports its relative standard error; darker
    # pixels with the same relative noise report less (by sqrt of the brightness ratio)
    rng = np.random.default_rng(14)
    n = 4000
    levels = np.array([1.0, 0.25, 1.75])       # mean of the image = 1.0
    rel = 0.5
    x = levels[:, None, None] * (1.0 + rel * rng.standard_normal((3, n, 1))) * np.ones(3)
    f = Film(3, 1)
    f.add_samples(np.repeat(np.arange(3), n), x.reshape(-1, 3), np.ones(3 * n))
    err = f.adaptive_error().ravel()
    assert abs(err[0] / (rel / np.sqrt(n)) - 1.0) < 0.06
    assert abs(err[1] / err[0] - 0.5) < 0.05     # sqrt(0.25 / 1)
    # black pixels: 0; fewer than 2 samples: unknown; nothing non-finite
    g = Film(3, 1)
    g.add_samples(np.array([0, 0, 1, 2, 2]), np.array([[0.0] * 3] * 2 + [[1.0] * 3] * 3),
                  np.ones(5))
    e = g.adaptive_error().ravel()
    assert e[0] == 0.0 and e[1] == REL_ERROR_UNKNOWN and e[2] == 0.0
    with np.errstate(all="raise"):
        empty = Film(2, 2).adaptive_error()
    assert (empty == REL_ERROR_UNKNOWN).all()


def test_adaptive_error_sees_colour_noise_that_luminance_misses():
    """X and Z fluctuate in opposite directions while Y is constant (spectral colour
    noise): the luminance error is 0, the adaptive error is not."""
    rng = np.random.default_rng(15)
    n = 500
    u = rng.standard_normal(n)
    x = np.stack([1.0 + 0.5 * u, np.ones(n), 1.0 - 0.5 * u], axis=1)
    f = Film(1, 1)
    f.add_samples(np.zeros(n, np.int64), x, np.ones(n))
    assert f.relative_error()[0, 0] == 0.0
    assert f.adaptive_error()[0, 0] > 0.01


def test_window_mean_clips_at_the_border():
    a = np.arange(12, dtype=np.float64).reshape(3, 4)
    w = window_mean(a)
    for y in range(3):
        for x in range(4):
            nb = a[max(0, y - 1):y + 2, max(0, x - 1):x + 2]
            assert w[y, x] == pytest.approx(nb.mean())
    np.testing.assert_array_equal(window_mean(np.full((1, 1), 7.0)), [[7.0]])


def test_converged_flat_region_stops_noisy_region_and_its_border_do_not():
    """A 9x6 film: the left half constant (no noise), columns 6-8 noisy. Flat pixels
    stop unless a noisy pixel is in their 3x3 window; noisy pixels do not stop."""
    w, h, n = 9, 6, 64

    def flat(p, rng, n):
        return np.full((n, 3), 0.5)

    def noisy(p, rng, n):
        return 0.5 * (1.0 + 2.0 * rng.standard_normal((n, 1))) * np.ones(3)

    per_pixel = [noisy if p % w >= 6 else flat for p in range(w * h)]
    pix, sensor = _grid_stream(per_pixel, n, seed=16)
    f = Film(w, h)
    f.add_samples(pix, sensor, np.ones(len(pix)))
    err = f.adaptive_error()
    assert (err[:, :6] == 0.0).all() and (err[:, 6:] > 0.1).all()
    conv = f.converged(0.05)         # noisy pixels: ~0.25; window of column 5: ~0.08
    assert conv[:, :5].all()           # flat, all neighbours flat
    assert not conv[:, 5].any()        # flat, but next to the noisy columns
    assert not conv[:, 6:].any()       # noisy
    assert f.converged(1e3).all()


def test_converged_needs_the_pixel_itself_below_the_threshold():
    """One noisy pixel amid flat ones: its window mean is 1/9 of its error, but it must
    not stop while its own error is above the threshold."""
    w = h = 5
    centre = 12

    def px(p, rng, n):
        if p == centre:
            return (1.0 + rng.standard_normal((n, 1))) * np.ones(3)
        return np.ones((n, 3))

    pix, sensor = _grid_stream([px] * (w * h), 100, seed=17)
    f = Film(w, h)
    f.add_samples(pix, sensor, np.ones(len(pix)))
    e = f.adaptive_error()[2, 2]
    conv = f.converged(0.5 * e)      # window mean e/9 < threshold < e
    assert not conv[2, 2] and conv.sum() == w * h - 1
    conv = f.converged(0.05 * e)     # below e/9: the neighbours wait too
    assert not conv[1:4, 1:4].any()
    assert conv[0].all() and conv[4].all() and conv[:, 0].all() and conv[:, 4].all()


def test_merge_adds_the_squares():
    s = _stream(2000, 12, seed=18, bands=False)
    whole, a, b = Film(4, 3), Film(4, 3), Film(4, 3)
    whole.add_samples(s["pixel"], s["sensor"], s["alpha"])
    a.add_samples(s["pixel"][:700], s["sensor"][:700], s["alpha"][:700])
    b.add_samples(s["pixel"][700:], s["sensor"][700:], s["alpha"][700:])
    a.merge(b)
    np.testing.assert_allclose(a.sum_sq, whole.sum_sq, rtol=1e-12)
    np.testing.assert_allclose(a.adaptive_error(), whole.adaptive_error(), rtol=1e-9)


def test_sample_free_layer_adds_to_the_pixel_means_once():
    """add_layer: radiance added to the resolved means (not to spp or the errors); merge
    appends it, a batch without it adds nothing; non-finite splats are dropped."""
    m = np.array([[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.5]])
    film = Film(3, 2, bands=(400.0, 500.0, 50.0))
    film.add_samples(np.arange(6), np.ones((6, 3)), np.zeros(6), {},
                     np.full((6, 4), 450.0), np.full((6, 4), 0.25))
    with pytest.raises(ValueError):
        film.add_layer(np.array([1]), np.ones((1, 3)))  # the film has bands
    film.add_layer(np.array([1, 4, 4, 5]), np.array([[1.0, 2.0, 3.0], [1.0, 1.0, 1.0],
                                                     [1.0, 1.0, 1.0], [np.nan, 0.0, 0.0]]),
                   np.array([[1.0, 2.0, 3.0]] * 4))
    assert film.nonfinite_samples == 1
    other = Film(3, 2, bands=(400.0, 500.0, 50.0))
    film.merge(other)
    img = film.resolve(m)
    np.testing.assert_allclose(img.rgba[0, 1, :3], m @ [2.0, 3.0, 4.0])
    np.testing.assert_allclose(img.rgba[1, 1, :3], m @ [3.0, 3.0, 3.0])
    np.testing.assert_allclose(img.rgba[1, 2, :3], m @ [1.0, 1.0, 1.0])
    np.testing.assert_allclose(img.spectral[0, 1], [1.0, 2.0 + 1.0 / 50.0, 3.0])
    np.testing.assert_allclose(img.spectral[1, 1], [2.0, 4.0 + 1.0 / 50.0, 6.0])
    assert np.all(img.spp == 1)
