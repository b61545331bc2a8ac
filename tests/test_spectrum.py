"""Tests of core/physics/spectrum.py: grid, sensor, sampler, emitters and RGB -> spectrum fits.

Every tolerance is stated next to where it comes from (float32 storage, the grid's linear
interpolation, Monte Carlo standard errors, or the reference's own accuracy).
"""

from __future__ import annotations

import math

import colour
import numpy as np
import pytest

from relray.core.physics import sigmoid
from relray.core.physics import spectrum as sp
from relray.core.physics.sigmoid import CoefficientCache

LAM1 = sp.sensor_nm()  # 360..830, 1 nm
WP_D65 = np.array([0.3127, 0.3290])  # Lab reference white for ΔE00
#: Relative to a table's largest value, how far colour-science's interpolated tables may
#: differ between CPUs (summation order, FMA): 64 float64 ulps (seen: 11).
CIE_ROUNDING = 64 * np.finfo(np.float64).eps


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    """Keep the fit's disk cache out of the user's home directory."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path_factory.getbasetemp() / "xdg"))
    monkeypatch.delenv("RELRAY_DISK_CACHE", raising=False)


def xyz_under_d65(refl: np.ndarray) -> np.ndarray:
    """XYZ (n, 3) of reflectances under D65_ext, integrated as the film does (1 nm, lookup)."""
    light = sp.lookup(sp.d65_ext(), LAM1)
    w = sp.sensor_response("cie1931").astype(np.float64)
    w[:, [0, -1]] *= 0.5  # trapezoid
    return (sp.lookup(refl, LAM1) * light) @ w.T


def lab_of_rgb(rgb: np.ndarray) -> np.ndarray:
    xyz = np.asarray(rgb) @ np.linalg.inv(sp.sensor_to_rgb("cie1931")).T
    return colour.XYZ_to_Lab(xyz, WP_D65)


def delta_e(rgb_a: np.ndarray, rgb_b: np.ndarray) -> np.ndarray:
    return colour.delta_E(lab_of_rgb(rgb_a), lab_of_rgb(rgb_b), method="CIE 2000")


def integrate_table(table: np.ndarray) -> float:
    """∫ lookup(table) dλ over the grid, exactly (hat-function weights, float64)."""
    return float(np.asarray(table, np.float64) @ sp._hat_weights())


# --------------------------------------------------------------------------- grid
def test_grid_formula_and_lookup():
    lam = sp.grid_nm()
    k = np.arange(sp.GRID_N)
    assert lam.shape == (sp.GRID_N,) and lam.dtype == np.float64
    np.testing.assert_allclose(lam, 1.0 * (1e5 / 1.0) ** (k / (sp.GRID_N - 1)), rtol=1e-15)
    assert lam[0] == sp.GRID_MIN_NM and lam[-1] == pytest.approx(sp.GRID_MAX_NM, rel=1e-14)
    assert sp.LOG_GRID_MIN == math.log(sp.GRID_MIN_NM)
    assert sp.INV_DLOG == (sp.GRID_N - 1) / math.log(sp.GRID_MAX_NM / sp.GRID_MIN_NM)
    i550 = np.searchsorted(lam, 550.0)
    assert lam[i550] - lam[i550 - 1] == pytest.approx(0.3866, abs=1e-3)  # brief: ≈ 0.39 nm
    table = np.random.default_rng(0).random(sp.GRID_N).astype(np.float32)
    # At the nodes the lookup returns the node values (u is exact to ~1e-12 of an index).
    np.testing.assert_allclose(sp.lookup(table, lam[1:-1:97]), table[1:-1:97], rtol=1e-7)
    # Linear in the fractional index u; a Doppler factor is a constant index offset.
    u = 1234.25
    lam_u = math.exp(sp.LOG_GRID_MIN + u / sp.INV_DLOG)
    assert sp.lookup(table, lam_u) == pytest.approx(0.75 * table[1234] + 0.25 * table[1235])
    d = math.exp(10.5 / sp.INV_DLOG)  # shifts u by 10.5
    assert sp.lookup(table, lam_u * d) == pytest.approx(0.25 * table[1244] + 0.75 * table[1245])
    # Clamped outside the grid, and no NaN for λ <= 0 or NaN.
    assert sp.lookup(table, 0.1) == table[0] and sp.lookup(table, 1e7) == table[-1]
    assert np.all(np.isfinite(sp.lookup(table, np.array([0.0, -5.0, np.nan, np.inf]))))
    # Batched tables: (n, GRID_N) at λ (2, 3) -> (n, 2, 3).
    assert sp.lookup(np.stack([table, table]), np.full((2, 3), 500.0)).shape == (2, 2, 3)


# --------------------------------------------------------------------------- sensor
def test_sensor_response_cie1931_matches_colour_science():
    assert LAM1.shape == (471,) and LAM1[0] == 360.0 and LAM1[-1] == 830.0
    r = sp.sensor_response("cie1931")
    assert r.shape == (3, 471) and r.dtype == np.float32
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    ref = cmfs[LAM1].T
    # float32 rounding (half an ulp: 2^-24 relative), plus colour-science's own rounding:
    # its 5 nm -> 1 nm interpolation sums in an order that depends on the CPU, so values
    # near zero differ by a few ulps of their largest neighbour (CIE_ROUNDING).
    np.testing.assert_allclose(r, ref, rtol=2.0**-24, atol=CIE_ROUNDING * np.abs(ref).max())


def test_sensor_response_seed_gaussian_unit_area():
    r = sp.sensor_response("seed-gaussian").astype(np.float64)
    assert r.shape == (3, 471)
    # Unit area under the film's trapezoid rule, up to float32 rounding.
    np.testing.assert_allclose(np.trapz(r, LAM1, axis=1), 1.0, rtol=1e-6)
    np.testing.assert_array_equal(LAM1[np.argmax(r, axis=1)], [600.0, 550.0, 450.0])
    # Each is the continuous Gaussian, whose area inside 360-830 is 1 - O(e^-40).
    expected = np.exp(-0.5 * ((LAM1 - 450.0) / 15.0) ** 2) / (15.0 * math.sqrt(2 * math.pi))
    np.testing.assert_allclose(r[2], expected, rtol=1e-6, atol=1e-12)
    # A flat spectrum gives RGB (1, 1, 1).
    np.testing.assert_allclose(sp.rgb_of(sp.flat_emission(), "seed-gaussian"), 1.0, rtol=1e-6)


def test_sensor_to_rgb():
    m = sp.sensor_to_rgb("cie1931")
    std = colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB
    # Same primaries; only the white point is D65_ext's own (differs in the 5th decimal).
    np.testing.assert_allclose(m, std, atol=2e-3)
    np.testing.assert_array_equal(sp.sensor_to_rgb("seed-gaussian"), np.eye(3))
    np.testing.assert_array_equal(sp.sensor_to_rgb("rgb"), np.eye(3))
    with pytest.raises(ValueError):
        sp.sensor_to_rgb("nonsense")


# --------------------------------------------------------------------------- D65
def test_d65_ext_shape_normalisation_and_white():
    d = sp.d65_ext()
    lam = sp.grid_nm()
    assert d.dtype == np.float32 and np.all(np.isfinite(d)) and np.all(d >= 0.0)
    assert np.all(d[lam < 300.0] == 0.0)
    # Y = 1 up to float32 rounding of the table (6e-8 relative per value).
    assert sp.y_of(d) == pytest.approx(1.0, abs=1e-6)
    # The CIE values at the 5 nm nodes, up to the common scale.
    ref = colour.SDS_ILLUMINANTS["D65"]
    wl = np.arange(300.0, 781.0, 5.0)
    v = ref[wl]
    # The lookup is linear in ln λ: on a function linear in λ (D65 between its 5 nm nodes)
    # it is off by at most δ²/8 · λ|g'| (δ = 1/INV_DLOG), plus float32 rounding (6e-8).
    slope = np.diff(v) / 5.0
    wl_mid = wl[:-1] + 2.5
    v_mid = 0.5 * (v[:-1] + v[1:])
    rel = (0.125 / sp.INV_DLOG**2) * wl_mid * np.abs(slope) / v_mid + 2e-7
    mid = sp.lookup(d, wl_mid) / v_mid
    best = np.argmin(rel[20:]) + 20  # the best-determined segment fixes the scale
    scale = mid[best]
    assert np.all(np.abs(mid[20:] / scale - 1.0) <= rel[20:] + rel[best])  # from 400 nm
    # At the 5 nm nodes the log grid misses the kinks: off by at most h/4 · |slope change|.
    got = sp.lookup(d, wl)
    h = wl[1:-1] / sp.INV_DLOG
    curve = (0.125 / sp.INV_DLOG**2) * wl[1:-1] * np.maximum(np.abs(slope[:-1]), np.abs(slope[1:]))
    bound = (h / 4.0 * np.abs(np.diff(slope)) + curve + (2 * rel[best] + 2e-7) * v[1:-1]) * scale
    assert np.all(np.abs(got[1:-1] - scale * v[1:-1]) <= bound)
    # Continuous at 830 nm: the jump across it is no bigger than one grid cell's change.
    i = np.searchsorted(lam, 830.0)
    left, right = d[i - 1], d[i]
    assert abs(right / left - 1.0) < 5e-3
    # Planck 6504 K shape above 830 nm.
    tail = lam > 900.0
    b = sp.planck(lam[tail], 6504.0)
    np.testing.assert_allclose(d[tail] / b, d[tail][0] / b[0], rtol=1e-6)
    # A white reflector under D65_ext is exactly white (no pink cast).
    rgb = xyz_under_d65(np.ones(sp.GRID_N, np.float32)) @ sp.sensor_to_rgb("cie1931").T
    np.testing.assert_allclose(rgb, 1.0, atol=1e-6)
    assert delta_e(rgb, np.ones(3)) < 0.01


# --------------------------------------------------------------------------- reflectance
EDGE_RGB = np.array(
    [
        [0.65, 0.05, 0.05], [0.05, 0.65, 0.05], [0.05, 0.05, 0.65], [0.9, 0.9, 0.9],
        [0.5, 0.5, 0.5], [0.18, 0.18, 0.18], [0.001, 0.001, 0.001], [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [1.0, 0.0, 1.0],
        [0.95, 0.95, 0.02], [0.02, 0.02, 0.02], [0.001, 0.002, 0.003], [0.8, 0.6, 0.4],
    ]
)


def test_reflectance_round_trip_delta_e():
    rgb = np.concatenate([EDGE_RGB, np.random.default_rng(7).random((150, 3))])
    refl = sp.rgb_reflectance(rgb)
    assert refl.shape == (len(rgb), sp.GRID_N) and refl.dtype == np.float32
    out = xyz_under_d65(refl) @ sp.sensor_to_rgb("cie1931").T
    # The fit converges to 1e-12 in RGB; what is left is float32 storage (6e-8 relative).
    assert np.max(delta_e(out, rgb)) < 0.01
    np.testing.assert_allclose(out, rgb, atol=1e-6)


def test_sigmoid_function_is_stable():
    x = np.array([-np.inf, -1e200, -1e8, -1.0, 0.0, 1.0, 1e8, 1e200, np.inf])
    s = sigmoid.sigmoid(x)
    assert np.all(np.isfinite(s)) and s[0] == 0.0 and s[-1] == 1.0 and s[4] == 0.5
    np.testing.assert_allclose(s[3], 0.5 - 0.5 / math.sqrt(2.0), rtol=1e-15)
    # No cancellation in the far tail: s(x) ≈ 1/(4x²) for x -> -inf.
    assert s[2] == pytest.approx(0.25e-16, rel=1e-12)
    np.testing.assert_allclose(s + sigmoid.sigmoid(-x), 1.0, rtol=1e-15)
    g = np.array([0.0, 1e-6, 0.25, 0.5, 0.9, 1.0])
    c = sigmoid.grey_coefficients(g)
    np.testing.assert_allclose(sigmoid.sigmoid(c[:, 2]), g, rtol=1e-12, atol=1e-300)


def test_reflectance_edge_cases():
    lam = sp.grid_nm()
    refl = sp.rgb_reflectance(
        [[0, 0, 0], [0.5, 0.5, 0.5], [1, 1, 1], [2, 2, 2], [2, -1, 0.5], [1, 0, 0], [1e-9, 0, 1]]
    )
    assert np.all(np.isfinite(refl)) and refl.min() >= 0.0 and refl.max() <= 1.0
    assert np.all(refl[0] == 0.0)  # black is exactly 0
    assert np.all(refl[1] == 0.5)  # greys are constant (closed form)
    assert np.all(refl[2] == 1.0) and np.array_equal(refl[3], refl[2])  # clamped to [0, 1]
    np.testing.assert_array_equal(refl[4], sp.rgb_reflectance([[1, 0, 0.5]])[0])
    # Outside the band the reflectance keeps its band-edge values.
    lo, hi = sp.SIGMOID_BAND_NM
    i_lo, i_hi = np.searchsorted(lam, lo), np.searchsorted(lam, hi) - 1  # first/last inside
    for r in refl:
        assert np.all(r[lam < lo] == r[0]) and np.all(r[lam > hi] == r[-1])
        # continuous at the band edges (one grid step of a sigmoid with |dx/dt| <= ~1e3)
        assert abs(r[0] - r[i_lo]) < 1e-2 and abs(r[-1] - r[i_hi]) < 1e-2
    with pytest.raises(ValueError):
        sp.rgb_reflectance([[np.nan, 0, 0]])


def test_reflectance_matches_colour_science_jakob2019():
    """Same sigmoid family: the in-band curve agrees with colour-science's reference fit.

    colour-science stops at ΔE 0.023 (its max_error) and is unclamped and fitted with the
    rounded sRGB white point: both shift s(λ) by well under 0.5 % in 400-700 nm.
    """
    from colour.recovery import find_coefficients_Jakob2019

    lam = np.arange(400.0, 701.0)
    for rgb in ([0.65, 0.05, 0.05], [0.2, 0.5, 0.8]):
        c, _ = find_coefficients_Jakob2019(colour.RGB_to_XYZ(np.array(rgb), "sRGB"))
        x = (c[0] * lam + c[1]) * lam + c[2]
        ref = 0.5 + 0.5 * x / np.sqrt(1 + x * x)
        ours = sp.lookup(sp.rgb_reflectance([rgb])[0], lam)
        assert np.max(np.abs(ours - ref)) < 5e-3


def test_uv_ir_overrides():
    lam = sp.grid_nm()
    lo, hi = sp.SIGMOID_BAND_NM
    below, above = lam < lo, lam > hi
    inside = ~(below | above)
    rgb = np.array([[0.65, 0.05, 0.05], [0.1, 0.3, 0.7], [0.4, 0.4, 0.4]])
    plain = sp.rgb_reflectance(rgb).astype(np.float64)
    over = sp.rgb_reflectance(rgb, uv=[0.0, 1.0, 0.2], ir=np.array([1.0, np.nan, 0.9]))
    over = over.astype(np.float64)
    assert np.all(over[0, below] == 0.0) and np.all(over[0, above] == 1.0)
    assert np.all(over[1, below] == 1.0) and np.all(over[1, above] == over[1, -1])
    assert np.all(over[2, below] == np.float32(0.2)) and np.all(over[2, above] == np.float32(0.9))
    # Inside the band the override does not act; the fit only re-balances the colour for
    # the changed tails, which carry 0.1 % of white's RGB weight: allow 20x that per unit
    # change of the tail (the 3x3 fit is not perfectly conditioned).
    tail = np.abs(_fit_tail_weight())
    assert np.max(np.abs(over[:, inside] - plain[:, inside])) < 20.0 * tail
    # The rest-frame colour still round-trips.
    out = xyz_under_d65(over.astype(np.float32)) @ sp.sensor_to_rgb("cie1931").T
    assert np.max(delta_e(out, rgb)) < 0.01
    # An override equal to the free edge value changes nothing at all.
    same = sp.rgb_reflectance(rgb, uv=plain[:, 0], ir=plain[:, -1]).astype(np.float64)
    np.testing.assert_allclose(same, plain, atol=1e-6)


def _fit_tail_weight() -> float:
    model = sp._fit_model()
    return float(np.sum(np.abs(model.b_uv)) + np.sum(np.abs(model.b_ir)))


def test_coefficient_disk_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(sp, "_CACHE", CoefficientCache(sp._FIT_VERSION))
    rgb = [[0.31, 0.62, 0.23]]
    c1 = sp.sigmoid_coefficients(rgb)
    files = list((tmp_path / "relray").glob("*.npz"))
    assert len(files) == 1
    # A fresh process (empty memory cache) reads the disk instead of fitting.
    monkeypatch.setattr(sp, "_CACHE", CoefficientCache(sp._FIT_VERSION))
    monkeypatch.setattr(sigmoid, "fit_colours", lambda *a: pytest.fail("refitted, cache unread"))
    np.testing.assert_array_equal(sp.sigmoid_coefficients(rgb), c1)
    monkeypatch.undo()
    # An unwritable cache directory is tolerated.
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("x")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    monkeypatch.setattr(sp, "_CACHE", CoefficientCache(sp._FIT_VERSION))
    np.testing.assert_allclose(sp.sigmoid_coefficients(rgb), c1, rtol=1e-12)


# --------------------------------------------------------------------------- emitters
def test_rgb_illuminant():
    d = sp.d65_ext()
    white = sp.rgb_illuminant([1.0, 1.0, 1.0])
    assert white.dtype == np.float32 and np.array_equal(white, d)
    np.testing.assert_allclose(sp.rgb_of(white), 1.0, atol=1e-3)
    assert np.all(sp.rgb_illuminant([0.0, 0.0, 0.0]) == 0.0)
    np.testing.assert_array_equal(sp.rgb_illuminant([-1.0, 0.0, 0.0]), np.zeros(sp.GRID_N))
    # A coloured emitter: the film interpolates the product s·D65 where the fit assumed the
    # product of interpolants; they differ by ≤ ¼ Δs ΔD per grid cell (≈ 1e-4 relative).
    for rgb in ([3.0, 0.5, 0.2], [0.1, 0.2, 0.9], [0.0, 2.0, 0.0]):
        e = sp.rgb_illuminant(rgb)
        assert np.all(np.isfinite(e)) and e.min() >= 0.0
        out = sp.rgb_of(e)
        np.testing.assert_allclose(out, rgb, rtol=1e-3, atol=1e-4)
        assert delta_e(out / max(rgb), np.array(rgb) / max(rgb)) < 0.01


def test_planck_doppler_identity_and_wien_peak():
    lam = sp.grid_nm()[::7]
    for T in (300.0, 2700.0, 5800.0, 40000.0):
        for D in (0.1, 0.5, 1.0 / math.sqrt(3.0), 1.7, 10.0):
            lhs = D**5 * sp.planck(D * lam, T)
            rhs = sp.planck(lam, D * T)
            ok = rhs > 1e-250  # away from the underflow to 0
            np.testing.assert_allclose(lhs[ok], rhs[ok], rtol=1e-12)
            assert np.all(lhs[~ok] < 1e-240)
    fine = np.arange(450.0, 550.0, 0.001)
    peak = fine[np.argmax(sp.planck(fine, 5800.0))]
    assert abs(peak - 2.897771955e6 / 5800.0) < 1.0
    # Absolute value (W m^-2 sr^-1 nm^-1), against the formula with the SI constants.
    h, c, k = 6.62607015e-34, 299792458.0, 1.380649e-23
    lam_m = 500e-9
    ref = 2 * h * c**2 / lam_m**5 / math.expm1(h * c / (lam_m * k * 5800.0)) * 1e-9
    assert sp.planck(500.0, 5800.0) == pytest.approx(ref, rel=1e-13)
    # No overflow / NaN at the extremes, and λ <= 0 gives 0.
    assert np.all(np.isfinite(sp.planck(sp.grid_nm(), 1.0)))
    assert sp.planck(0.0, 5800.0) == 0.0 and sp.planck(-1.0, 5800.0) == 0.0


def test_blackbody_tables():
    for T in (100.0, 300.0, 1000.0, 5800.0, 1e6):
        b = sp.blackbody(T)
        assert b.dtype == np.float32 and np.all(np.isfinite(b)) and np.all(b >= 0.0)
        assert b.max() <= sp.TABLE_CAP * (1 + 1e-6)
    for T in (1000.0, 5800.0, 1e6):
        assert sp.y_of(sp.blackbody(T)) == pytest.approx(1.0, abs=1e-6)  # float32 storage


def test_blackbody_colour_matches_colour_science():
    sd = colour.sd_blackbody(5800.0, colour.SpectralShape(360.0, 830.0, 1.0))
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz_ref = colour.sd_to_XYZ(sd, cmfs, method="Integration", k=1.0)
    xyz_ref = xyz_ref / xyz_ref[1]
    rgb = sp.blackbody_rgb(5800.0)
    xyz = rgb @ np.linalg.inv(sp.sensor_to_rgb("cie1931")).T
    # colour-science's Planck uses 7-digit c1/c2 (8e-5 relative in the shape); the grid's
    # interpolation adds ~1e-6: ΔE00 of order 1e-3.
    de = colour.delta_E(colour.XYZ_to_Lab(xyz, WP_D65), colour.XYZ_to_Lab(xyz_ref, WP_D65))
    assert de < 0.01
    assert xyz[1] == pytest.approx(1.0, abs=1e-6)


def test_blackbody_seen_ahead_is_hotter_blackbody():
    """physics.md: 5800 K seen straight ahead at β = 0.5 (D = √3) looks like 10046 K."""
    D = math.sqrt(3.0)
    table = sp.blackbody(5800.0)
    w = sp.sensor_response("cie1931").astype(np.float64)
    w[:, [0, -1]] *= 0.5
    seen = D**5 * sp.lookup(table, D * LAM1) @ w.T  # camera-frame XYZ
    hot = sp.lookup(sp.blackbody(5800.0 * D), LAM1) @ w.T
    # Same spectrum up to a scale: chromaticities agree to the grid interpolation (~1e-6).
    np.testing.assert_allclose(seen / seen.sum(), hot / hot.sum(), atol=1e-5)


def test_gaussian_line():
    fine = np.linspace(500.0, 600.0, 400001)
    for sigma in (1.0, 2.0, 5.0):
        g = sp.gaussian_line(550.0, sigma)
        assert g.dtype == np.float32 and np.all(np.isfinite(g))
        assert integrate_table(g) == pytest.approx(1.0, abs=1e-6)  # float32 storage
        v = sp.lookup(g, fine)
        area = np.trapz(v, fine)
        assert area == pytest.approx(1.0, abs=1e-5)  # fine trapezoid of a piecewise linear
        mean = np.trapz(v * fine, fine) / area
        sd = math.sqrt(np.trapz(v * (fine - mean) ** 2, fine) / area)
        h = 550.0 / sp.INV_DLOG  # grid spacing at 550 nm
        assert abs(mean - 550.0) < 0.01 * h  # symmetric up to the slow change of h
        # Linear interpolation adds h²/6 to the variance (plus the log grid's asymmetry).
        assert sd == pytest.approx(math.sqrt(sigma**2 + h * h / 6.0), rel=2e-3)
        assert v.max() == pytest.approx(1.0 / (sigma * math.sqrt(2 * math.pi)), rel=0.02)
    # Narrower than the grid: still finite, unit area, centred.
    for sigma in (0.01, 0.1, 0.3):
        g = sp.gaussian_line(550.0, sigma)
        assert np.all(np.isfinite(g)) and integrate_table(g) == pytest.approx(1.0, abs=1e-6)
        v = sp.lookup(g, fine)
        assert np.trapz(v * fine, fine) / np.trapz(v, fine) == pytest.approx(550.0, abs=0.05)
    with pytest.raises(ValueError):
        sp.gaussian_line(550.0, 0.0)


def test_tabulated():
    t = sp.tabulated([500.0, 400.0, 600.0], [2.0, 1.0, 0.0])
    assert t.dtype == np.float32 and t.shape == (sp.GRID_N,)
    assert sp.lookup(t, 450.0) == pytest.approx(1.5, rel=1e-4)  # linear between the points
    lam = sp.grid_nm()
    assert np.all(t[(lam < 400.0) | (lam > 600.0)] == 0.0)
    for bad in (([500.0], [1.0]), ([500.0, 500.0], [1.0, 2.0]), ([400.0, 500.0], [1.0, np.nan])):
        with pytest.raises(ValueError):
            sp.tabulated(*bad)


def test_seed_reflectance_and_flat_emission():
    lam = sp.grid_nm()
    rgb = np.array([[1, 1, 1], [1, 0, 0], [0, 0, 1], [0.5, 0.5, 0.5], [0, 0, 0], [0.2, 0.9, 0.1]])
    f = sp.seed_reflectance(rgb)
    assert f.dtype == np.float32 and np.all(np.isfinite(f))
    assert f.min() >= 0.0 and f.max() <= 1.0 and np.all(f[4] == 0.0)
    # White reflects 1 around the three peaks.
    for mu in sp.SEED_MU_NM:
        assert sp.lookup(f[0], mu) == pytest.approx(1.0)
    # The red channel alone peaks at 600 nm; the formula before the clamp (check at 640 nm,
    # where f ≈ K f_r² N(λ; 600, 25) / |f|^½ < 1).
    red = sp.lookup(f[1], lam)
    k = math.sqrt(2 * math.pi) * 25.0 * 3**0.25
    expected = k * math.exp(-0.5 * (40.0 / 25.0) ** 2) / (25.0 * math.sqrt(2 * math.pi))
    assert sp.lookup(f[1], 640.0) == pytest.approx(expected, rel=1e-4)
    assert red.max() == 1.0
    assert np.all(sp.flat_emission() == 1.0) and sp.flat_emission().shape == (sp.GRID_N,)
    out = sp.rgb_of(f * sp.flat_emission(), "seed-gaussian")
    assert np.all(out[0] > 0.8) and out[1, 0] > 5 * out[1, 2]


# --------------------------------------------------------------------------- sampling
@pytest.fixture(scope="module")
def sampler():
    return sp.make_sampler("cie1931")


def test_sampler_tables(sampler):
    assert sampler.edges_nm.shape == (471,) and sampler.pdf.shape == (470,)
    assert sampler.cdf[0] == 0.0 and sampler.cdf[-1] == 1.0
    assert np.sum(sampler.pdf * np.diff(sampler.edges_nm)) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(np.diff(sampler.cdf), sampler.pdf, atol=1e-15)
    # Shape ∝ |r̄|+|ḡ|+|b̄| with the 1 % floor.
    f = np.abs(sp.sensor_to_rgb("cie1931") @ sp.sensor_response("cie1931").astype(float)).sum(0)
    fb = 0.5 * (f[:-1] + f[1:])
    fb = np.maximum(fb, 0.01 * fb.mean())
    np.testing.assert_allclose(sampler.pdf, fb / fb.sum(), rtol=1e-12)
    assert sampler.pdf.min() > 0.0
    seed = sp.make_sampler("seed-gaussian")
    # ∝ the sum of unit-area Gaussians: the narrow blue one (σ = 15 nm) is the tallest.
    assert seed.edges_nm[np.argmax(seed.pdf)] in (449.0, 450.0)
    with pytest.raises(ValueError):
        sp.make_sampler("rgb")


def test_sampler_sample_exact_pdf_and_histogram(sampler):
    n = 1_000_000
    u = np.random.default_rng(3).random(n)
    lam, pdf = sampler.sample(u)
    assert lam.min() >= 360.0 and lam.max() < 830.0
    np.testing.assert_array_equal(pdf, sampler.pdf_at(lam))  # exact, bin for bin
    edge_u = np.array([0.0, 1.0, np.nextafter(1.0, 0.0), 1e-300])
    lam_e, pdf_e = sampler.sample(edge_u)
    assert np.all((lam_e >= 360.0) & (lam_e < 830.0))
    np.testing.assert_array_equal(pdf_e, sampler.pdf_at(lam_e))
    counts = np.histogram(lam, bins=sampler.edges_nm)[0]
    expected = n * table_mass(sampler, sampler.edges_nm)  # 1 nm bins
    assert np.all(np.abs(counts - expected) < 5.0 * np.sqrt(expected))
    # … and on a finer histogram, where a bin sees the cells' own steps
    fine = np.linspace(360.0, 830.0, 4701)
    counts = np.histogram(lam, bins=fine)[0]
    expected = n * table_mass(sampler, fine)
    assert np.all(np.abs(counts - expected) < 5.0 * np.sqrt(expected) + 1.0)


def table_mass(sampler, edges):
    """∫ pdf_at over each interval of ``edges``: the table's CDF is linear on every cell
    (u = (g + (λ - λ_g)/(λ_(g+1) - λ_g))/G), so np.interp is exact."""
    nodes = np.arange(sampler.inv_nm.shape[0]) / sp.INVERSE_CELLS
    return np.diff(np.interp(edges, sampler.inv_nm, nodes))


@pytest.mark.parametrize("kind", ["cie1931", "seed-gaussian", "bands-only", "ir-bands"])
def test_inverse_table_follows_the_bins(kind):
    """The sampled pdf is the bins' where a cell lies inside one bin, and between the
    covered bins' values where it straddles edges; it integrates to 1 over [λ_0, λ_G],
    whose ends are those of the bins with mass."""
    s = {"cie1931": lambda: sp.make_sampler("cie1931"),
         "seed-gaussian": lambda: sp.make_sampler("seed-gaussian"),
         "bands-only": lambda: sp.make_sampler("cie1931", bands=(380.0, 780.0, 5.0),
                                               uniform_mix=1.0),
         "ir-bands": lambda: sp.make_sampler("cie1931", bands=(1000.0, 5000.0, 100.0))}[kind]()
    inv, cp = s.inv_nm, s.cell_pdf
    assert inv.shape == (sp.INVERSE_CELLS + 1,) and np.all(np.diff(inv) > 0.0)
    assert np.sum(cp * np.diff(inv)) == pytest.approx(1.0, abs=1e-12)
    mass = np.flatnonzero(s.pdf > 0.0)
    assert inv[0] == s.edges_nm[mass[0]] and inv[-1] == s.edges_nm[mass[-1] + 1]
    b_lo = np.searchsorted(s.edges_nm, inv[:-1], side="right") - 1
    b_hi = np.searchsorted(s.edges_nm, inv[1:], side="left") - 1
    one = b_lo == b_hi
    assert one.mean() > 0.5
    np.testing.assert_allclose(cp[one], s.pdf[b_lo[one]], rtol=1e-9)
    gaps = 0
    for g in np.flatnonzero(~one):
        covered = s.pdf[b_lo[g]:b_hi[g] + 1]
        # a cell across a gap of empty bins (IR bands away from the sensor): one per gap
        gaps += covered.min() == 0.0
        low = covered.min() * (1 - 1e-9) if covered.min() > 0.0 else 1e-300
        assert low <= cp[g] <= covered.max() * (1 + 1e-9)
    assert gaps == (1 if kind == "ir-bands" else 0)
    # the target's mass per bin is the table's, up to the cells across its edges
    assert np.max(np.abs(table_mass(s, s.edges_nm) - s.pdf * np.diff(s.edges_nm))) \
        < 1.0 / sp.INVERSE_CELLS


def test_hero_lanes_marginal(sampler):
    n = 250_000
    lam, pdf = sampler.hero(np.random.default_rng(4).random(n))
    assert lam.shape == (n, 4) and pdf.shape == (n, 4)
    np.testing.assert_array_equal(pdf, sampler.pdf_at(lam))
    expected = n * table_mass(sampler, sampler.edges_nm)
    for j in range(4):
        counts = np.histogram(lam[:, j], bins=sampler.edges_nm)[0]
        assert np.all(np.abs(counts - expected) < 5.0 * np.sqrt(expected))
    # Lanes are the stratified rotations u + j/4, each sample()'s λ (to the one ulp of a
    # fused multiply-add) in sample()'s cell, with its pdf
    u = np.random.default_rng(7).random(100_000)
    lam2, pdf2 = sampler.hero(u)
    lam_s, pdf_s = sampler.sample(np.mod(u + 0.25, 1.0))
    assert np.all(np.abs(lam2[:, 1] - lam_s) <= np.spacing(lam_s))
    np.testing.assert_array_equal(pdf2[:, 1], pdf_s)


def test_sampler_with_bands():
    bands = (380.0, 780.0, 10.0)
    s = sp.make_sampler("cie1931", bands=bands)
    base = sp.make_sampler("cie1931")
    lo, hi = 375.0, 785.0
    inside = (s.edges_nm[:-1] >= lo) & (s.edges_nm[1:] <= hi)
    uniform = np.where(inside, 1.0 / (hi - lo), 0.0)
    np.testing.assert_allclose(s.pdf, 0.75 * base.pdf + 0.25 * uniform, rtol=1e-12)
    assert np.all(s.pdf[inside] >= 0.25 / (hi - lo))
    for c in np.arange(380.0, 781.0, 10.0):  # every band has samples
        assert np.all(s.pdf_at(np.linspace(c - 5.0, c + 4.99, 11)) > 0.0)
    explicit = sp.make_sampler("cie1931", bands=bands, uniform_mix=0.5)
    np.testing.assert_allclose(explicit.pdf, 0.5 * base.pdf + 0.5 * uniform, rtol=1e-12)
    # Partial bins at the range ends (step 5: 377.5 ... 782.5) keep ∫ pdf = 1.
    odd = sp.make_sampler("cie1931", bands=(380.0, 780.0, 5.0), uniform_mix=1.0)
    assert np.sum(odd.pdf) == pytest.approx(1.0, abs=1e-12)
    assert odd.pdf_at(377.6) == pytest.approx(0.5 / 405.0) and odd.pdf_at(378.5) > odd.pdf_at(377.6)
    with pytest.raises(ValueError):
        sp.make_sampler("cie1931", bands=(90.0, 1000.0, 10.0))


@pytest.mark.parametrize("bands", [(200.0, 2000.0, 50.0), (1000.0, 5000.0, 100.0),
                                   (120.0, 300.0, 20.0)])
def test_sampler_with_uv_and_ir_bands(bands):
    """Bands anywhere in BANDS_RANGE_NM: the bins widen to cover them, every band has
    samples, the sensor range keeps its CMF-shaped part, and ∫ pdf = 1."""
    s = sp.make_sampler("cie1931", bands=bands)
    start, stop, step = bands
    lo, hi = start - step / 2, stop + step / 2
    assert s.edges_nm[0] <= min(lo, 360.0) and s.edges_nm[-1] >= max(hi, 830.0)
    assert np.sum(s.pdf * np.diff(s.edges_nm)) == pytest.approx(1.0, abs=1e-12)
    for c in np.arange(start, stop + step / 2, step):
        assert np.all(s.pdf_at(np.linspace(c - step / 2, c + step / 2 * 0.999, 7)) > 0.0)
    base = sp.make_sampler("cie1931")
    inside = (s.edges_nm[:-1] >= 360.0) & (s.edges_nm[1:] <= 830.0)
    sensor_part = s.pdf[inside] - 0.25 * np.where(
        (s.edges_nm[:-1][inside] >= lo) & (s.edges_nm[1:][inside] <= hi), 1 / (hi - lo), 0.0)
    np.testing.assert_allclose(sensor_part, 0.75 * base.pdf, rtol=1e-9, atol=1e-15)
    lam, pdf = s.hero(np.random.default_rng(3).random(20000))
    assert np.all((lam >= s.edges_nm[0]) & (lam < s.edges_nm[-1]))
    np.testing.assert_array_equal(pdf, s.pdf_at(lam))
    lanes = s.lanes(np.random.default_rng(3).random(20000))
    want = (np.log(lanes.lam) - sp.LOG_GRID_MIN) * sp.INV_DLOG
    np.testing.assert_allclose(lanes.lamu, want, rtol=0, atol=2e-3)


def test_hero_estimator_reproduces_integral(sampler):
    """E[cmf(λ) L(λ)/pdf(λ)] over 4 hero wavelengths = ∫ cmf L dλ, within 5 standard errors."""
    n = 200_000
    lam, pdf = sampler.hero(np.random.default_rng(5).random(n))
    d65 = sp.d65_ext()
    cmf = sp.sensor_response("cie1931").astype(np.float64)
    L = sp.lookup(d65, lam)
    for c in range(3):
        f = np.interp(lam, LAM1, cmf[c]) * L / pdf
        per_path = f.mean(axis=1)  # lanes of a path are correlated: average them first
        est = per_path.mean()
        se = per_path.std(ddof=1) / math.sqrt(n)
        exact = np.trapz(cmf[c] * sp.lookup(d65, LAM1), LAM1)
        # (trapezoid vs the exact integral of the interpolants: ~1e-5, far below se)
        assert abs(est - exact) < 5.0 * se, (c, est, exact, se)


# --------------------------------------------------------------------------- finiteness
def test_every_table_finite_on_whole_grid():
    tables = [
        sp.d65_ext(), sp.flat_emission(), sp.blackbody(100.0), sp.blackbody(1e6),
        sp.gaussian_line(550.0, 0.01), sp.gaussian_line(36.0, 0.5), sp.gaussian_line(8000.0, 50.0),
        sp.rgb_illuminant([1e6, 0.0, 1e-9]), sp.tabulated([1.0, 1e5], [1.0, 1.0]),
        *sp.rgb_reflectance([[1e-12, 1, 0], [1, 1, 1e-12], [0.3, 0.0, 0.0]], uv=0.0, ir=1.0),
        *sp.seed_reflectance([[1, 1, 1], [1e-9, 0, 0]]),
    ]
    for t in tables:
        assert t.shape == (sp.GRID_N,) and np.all(np.isfinite(t)) and t.min() >= 0.0
    # The Doppler range of β = 0.98 (D from 0.1 to 10) hits finite values on every table.
    lam = np.geomspace(36.0, 8300.0, 1001)
    for t in tables:
        assert np.all(np.isfinite(sp.lookup(t, lam)))


# --------------------------------------------------------------------------- fused lanes
@pytest.mark.parametrize("kind", ["cie1931", "seed-gaussian", "bands-only"])
def test_lanes_equal_hero_then_grid_coordinates(kind):
    """The fused camera-side kernel = hero() + grid_coordinates() + D⁵ + D's range."""
    s = (sp.make_sampler("cie1931", bands=(380.0, 780.0, 5.0), uniform_mix=1.0)
         if kind == "bands-only" else sp.make_sampler(kind))  # bands-only: zero-pdf bins
    rng = np.random.default_rng(11)
    n = 100_000
    u = rng.random(n)
    u[:4] = [0.0, np.nextafter(1.0, 0.0), 0.25, 0.75]
    D = np.exp(rng.normal(0.0, 1.5, n))  # D from ~0.003 to ~300
    lam_ref, pdf_ref = s.hero(u)
    for doppler in (True, False):
        for searchlight in (True, False):
            h = s.lanes(u, D, doppler=doppler, searchlight=searchlight)
            np.testing.assert_array_equal(h.lam, lam_ref)
            np.testing.assert_array_equal(h.pdf, pdf_ref)
            ref = sp.grid_coordinates(lam_ref, D if doppler else None)
            assert h.lamu.dtype == np.float32 and h.lamu.shape == (n, 4)
            # ln λ from the bin edge + a series (error < 1e-13 grid cells) instead of a log:
            # the float32 results may differ by one rounding at most
            ulp = np.spacing(np.abs(ref))
            assert np.all(np.abs(h.lamu - ref) <= ulp)
            assert np.mean(h.lamu == ref) > 0.999
            w_ref = D**5 if searchlight else np.ones(n)
            np.testing.assert_allclose(h.w_d, w_ref, rtol=1e-15, atol=0.0)  # D²·D²·D vs pow
            assert h.d_min == D.min() and h.d_max == D.max()
    # no D: no shift, weight 1, D taken as 1
    h = s.lanes(u)
    np.testing.assert_array_equal(h.lamu, sp.grid_coordinates(lam_ref))
    assert np.all(h.w_d == 1.0) and (h.d_min, h.d_max) == (1.0, 1.0)


def test_lanes_write_into_given_buffers():
    s = sp.make_sampler("cie1931")
    cap = 64
    out = (np.empty((cap, 4)), np.empty((cap, 4)), np.empty((cap, 4), np.float32), np.empty(cap))
    u = np.linspace(0.0, 0.99, 10)
    D = np.linspace(0.5, 2.0, 10)
    h = s.lanes(u, D, searchlight=True, out=out)
    for got, buf in zip(h[:4], out, strict=True):
        assert got.shape[0] == 10 and np.shares_memory(got, buf)
    np.testing.assert_array_equal(out[0][:10], s.hero(u)[0])
    empty = s.lanes(np.empty(0), np.empty(0), out=out)
    assert empty.lam.shape == (0, 4) and (empty.d_min, empty.d_max) == (math.inf, 0.0)
    with pytest.raises(ValueError):
        s.lanes(u, D[:5])
    with pytest.raises(ValueError):  # never write past a buffer
        s.lanes(np.zeros(cap + 1), out=out)


# --------------------------------------------------------------------------- embedded data
def test_embedded_cie_tables_match_colour_science():
    """core/physics/cie_tables.py holds colour-science's tables (regenerate on upgrade), up to the
    CPU-dependent rounding of colour-science's interpolation (seen: 11 ulps of the largest
    value on AMD EPYC against the Intel machine that generated them)."""
    from relray.core.physics import cie_tables

    ref = cie_tables.from_colour()
    for name in ("CMF_CIE1931_2", "D65_5NM", "PRIMARIES_SRGB_XY"):
        table = np.asarray(ref[name])
        np.testing.assert_allclose(getattr(cie_tables, name), table, rtol=0.0,
                                   atol=CIE_ROUNDING * np.abs(table).max(), err_msg=name)
    assert cie_tables.CMF_CIE1931_2.shape == (471, 3) and cie_tables.D65_5NM.shape == (107,)


def test_normalised_primary_matrix_is_colour_sciences():
    rng = np.random.default_rng(2)
    for _ in range(20):
        prim = np.array([[0.64, 0.33], [0.3, 0.6], [0.15, 0.06]]) + rng.normal(0, 0.02, (3, 2))
        white = np.array([0.3127, 0.329]) + rng.normal(0, 0.01, 2)
        np.testing.assert_allclose(sp.normalised_primary_matrix(prim, white),
                                   colour.normalised_primary_matrix(prim.ravel(), white),
                                   rtol=1e-12, atol=1e-14)


def test_tables_need_no_colour_science_import():
    """Building the sensor, D65, the fit model and a reflectance does not import colour."""
    import subprocess
    import sys

    code = ("import sys; from relray.core.physics import spectrum as sp; "
            "sp.make_sampler('cie1931'); sp.sensor_to_rgb('cie1931'); sp.d65_ext(); "
            "sp.rgb_reflectance([[0.7, 0.2, 0.1]]); sp.rgb_illuminant([1.0, 0.5, 0.2]); "
            "assert 'colour' not in sys.modules, 'colour imported'")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=600)
