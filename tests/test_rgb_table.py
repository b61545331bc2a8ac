"""core.physics.rgb_table: the Jakob–Hanika coefficient table for texels."""

from __future__ import annotations

import math
import re

import colour
import numpy as np
import pytest
from numba import njit

from relray.core.physics import rgb_table as rt
from relray.core.physics import sigmoid as sg
from relray.core.physics import spectrum as sp

WP_D65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
#: the issue's bound on the round trip RGB -> table spectrum -> RGB under D65
MAX_DELTA_E00 = 0.5


@pytest.fixture(scope="module")
def table():
    return rt.coefficient_table()


def film_rgb(coeffs: np.ndarray) -> np.ndarray:
    """Linear Rec.709 the film sees of the reflectances ``coeffs`` under D65_ext."""
    refl = sg.evaluate(coeffs, sp.grid_nm(), sp.SIGMOID_BAND_NM)
    return sp.rgb_of(refl * sp.d65_ext()[None, :].astype(np.float64))


def lab(rgb: np.ndarray) -> np.ndarray:
    xyz = np.asarray(rgb) @ np.linalg.inv(sp.sensor_to_rgb("cie1931")).T
    return colour.XYZ_to_Lab(xyz, WP_D65)


def test_z_nodes_are_a_double_smoothstep():
    z = rt.z_nodes(5)
    s = lambda t: t * t * (3 - 2 * t)  # noqa: E731
    assert np.allclose(z, s(s(np.linspace(0, 1, 5)))) and z[0] == 0 and z[-1] == 1


def test_table_is_finite_cached_and_shaped(table):
    assert table.data.shape == (3, rt.RES, rt.RES, rt.RES, 3) and table.data.dtype == np.float32
    assert np.all(np.isfinite(table.data)) and np.abs(table.data[:, 1:]).max() <= rt.C_MAX
    assert rt.coefficient_table() is table


@njit
def _blend(scale, data, rgb, lams, out):
    for i in range(rgb.shape[0]):
        cell = rt.table_cell(scale, data, rgb[i, 0], rgb[i, 1], rgb[i, 2])
        for k in range(lams.shape[0]):
            out[i, k] = rt.cell_reflectance(data, cell, lams[k])


def colours() -> np.ndarray:
    """Random in-gamut colours, dark ones, the cube's edges and corners, near black/white."""
    rng = np.random.default_rng(7)
    edges = np.array([[a, b, c] for a in (0, 0.5, 1) for b in (0, 0.5, 1) for c in (0, 1)])
    near = np.concatenate([rng.uniform(0.0, 0.02, (200, 3)), rng.uniform(0.97, 1.0, (600, 3))])
    return np.concatenate([rng.uniform(0.0, 1.0, (3000, 3)), rng.uniform(0, 1, (500, 3)) ** 4,
                           edges, near])


def test_kernel_blend_round_trip_delta_e_below_half(table):
    """What the kernels use (:func:`table_reflectance`: the nodes' spectra blended): the
    colour under D65 is the target's within ΔE00 < 0.5 over the whole cube."""
    rgb = colours()
    grid = sp.grid_nm()
    lo, hi = np.searchsorted(grid, [300.0, 900.0])
    refl = np.zeros((len(rgb), sp.GRID_N))
    part = np.empty((len(rgb), hi - lo))
    _blend(table.scale, table.data, rgb, grid[lo:hi], part)
    refl[:, lo:hi] = part
    refl[:, :lo], refl[:, hi:] = part[:, :1], part[:, -1:]   # constant outside the band
    got = sp.rgb_of(refl * sp.d65_ext()[None, :].astype(np.float64))
    de = colour.delta_E(lab(rgb), lab(got), method="CIE 2000")
    assert np.max(de) < MAX_DELTA_E00, (np.max(de), rgb[np.argmax(de)])


def test_coefficients_round_trip_delta_e_below_half(table):
    """Per-texel coefficients (:func:`coefficients`): ΔE00 < 0.5 over the whole cube."""
    rgb = colours()
    got = film_rgb(rt.coefficients(rgb, table))
    de = colour.delta_E(lab(rgb), lab(got), method="CIE 2000")
    assert np.max(de) < MAX_DELTA_E00, (np.max(de), rgb[np.argmax(de)])


def test_nodes_agree_with_the_per_colour_fit(table):
    """At a table node the coefficients are the fit's (the interpolation weights are 1)."""
    k = 40
    rgb = rt.node_colours(1, float(table.scale[k]))[[65, 1000, 3000]]
    got = rt.coefficients(rgb, table)
    want = sp.sigmoid_coefficients(rgb)
    assert np.allclose(film_rgb(got), film_rgb(want), atol=2e-6)


def test_greys_are_exact_and_black_and_white_finite(table):
    g = np.array([[0.0] * 3, [0.18] * 3, [0.5] * 3, [1.0] * 3])
    c = rt.coefficients(g, table)
    assert np.all(np.isfinite(c)) and np.all(c[:, :2] == 0)
    s = sg.sigmoid(c[:, 2].astype(np.float64))
    assert np.allclose(s, [rt.GREY_EPS, 0.18, 0.5, 1 - rt.GREY_EPS], rtol=1e-5)


@njit
def _device(c, lam):
    return rt.sigmoid_reflectance(c[0], c[1], c[2], lam)


@njit
def _node(scale, data, rgb):
    return rt.table_coefficients(scale, data, rgb[0], rgb[1], rgb[2])


def test_device_functions_match_numpy(table):
    c = rt.coefficients(np.array([0.8, 0.3, 0.1]), table).astype(np.float64)
    for lam in (300.0, 380.0, 455.5, 600.0, 720.0, 900.0):
        want = sg.evaluate(c[None], np.array([lam]), sp.SIGMOID_BAND_NM)[0, 0]
        assert _device(c, lam) == pytest.approx(want, rel=1e-12)
    k, y, x = 30, 20, 50  # a node of the green table: its own coefficients
    rgb = rt.node_colours(1, float(table.scale[k])).reshape(rt.RES, rt.RES, 3)[y, x]
    assert np.allclose(_node(table.scale, table.data, rgb), table.data[1, k, y, x], rtol=1e-5)


def test_lambda_of_column_inverts_the_grid():
    grid = sp.grid_nm()
    for u in (0, 1234, 9000, sp.GRID_N - 1):
        assert rt.lambda_of_column(float(u)) == pytest.approx(grid[u], rel=1e-9)
    u = (np.log(550.0) - sp.LOG_GRID_MIN) * sp.INV_DLOG
    assert rt.lambda_of_column(u) == pytest.approx(550.0, rel=1e-12)


def polish_colours() -> np.ndarray:
    """Colours for the polish: random ones, near white, saturated ones (a channel near 0
    or exactly 0) and HDR texels as the environment normalises them (max channel ½)."""
    rng = np.random.default_rng(11)
    saturated = rng.random((600, 3)) ** 6
    saturated[np.arange(200), rng.integers(0, 3, 200)] = 0.0
    hdr = rng.lognormal(0.0, 1.5, (1200, 3))
    return np.concatenate([rng.random((1200, 3)), rng.uniform(0.97, 1.0, (500, 3)),
                           saturated, hdr / (2.0 * hdr.max(axis=1))[:, None]])


def test_polish_matches_the_reference_fit(table):
    """The compiled polish of :func:`coefficients` against the numpy Levenberg–Marquardt
    fit (:func:`sigmoid.fit`) from the same table start, to the same tolerance: where the
    reference reaches POLISH_TOL the polish does too (in the fit's forward model, which
    is the film's to ≈ 1e-6), up to the float32 rounding of the returned coefficients
    (first-order bound Σ_j |∂rgb/∂c_j| |c_j| 2⁻²⁴, up to 1e-6 for |c| ≈ 1000), and the
    two colours agree within ΔE00 0.01."""
    rgb = polish_colours()
    grey = np.ptp(rgb, axis=1) == 0.0
    rgb = rgb[~grey]
    got = rt.coefficients(rgb, table).astype(np.float64)
    start = np.array([_node(table.scale, table.data, c) for c in rgb])
    model = sp.reflectance_fit_model()
    none = np.full(len(rgb), np.nan)
    ref, ref_resid = sg.fit(rgb, model.t_band, model.B_band, model.b_uv, model.b_ir, none,
                            none, start, tol=rt.POLISH_TOL, max_iter=rt.POLISH_ITER)
    basis = np.stack([model.t_band ** 2, model.t_band, np.ones_like(model.t_band)], axis=1)
    got_rgb, J = sg._model(got, model.t_band, basis, model.B_band, model.b_uv, model.b_ir,
                           none, none)   # the fit's own forward model (numpy)
    rounding = np.max(np.abs(J) @ np.abs(got)[:, :, None], axis=(1, 2)) * 2.0 ** -24
    got_resid = np.abs(got_rgb - rgb).max(axis=1)
    reached = ref_resid <= rt.POLISH_TOL
    assert reached.mean() > 0.99   # the comparison covers (nearly) all colours
    excess = got_resid - (rt.POLISH_TOL + rounding + 1e-12)
    assert np.all(excess[reached] <= 0.0), (excess.max(), rgb[np.argmax(excess)])
    de = colour.delta_E(lab(film_rgb(got)), lab(film_rgb(ref)), method="CIE 2000")
    assert np.max(de) < 0.01, (np.max(de), rgb[np.argmax(de)])


def test_distinct_rows_is_unique_of_the_clamped_rows():
    rng = np.random.default_rng(2)
    rows = rng.integers(0, 4, (5000, 3)) / 3.0 - 0.2   # many repeats, some out of [0, 1]
    rows[:7] = [[np.nan, 0.5, 0.5], [0.0, 0.5, 0.5], [-0.0, 0.5, 0.5], [-1.0, 0.5, 0.5],
                [0.5, 2.0, 0.0], [0.5, 1.0, -0.0], [0.5, 1.0, 0.0]]
    distinct, inverse = rt.distinct_rows(rows)
    clamped = np.clip(np.nan_to_num(rows, nan=0.0), 0.0, 1.0)
    assert np.array_equal(distinct[inverse], clamped)
    assert len(distinct) == len(np.unique(clamped, axis=0))
    assert inverse[0] == inverse[1] == inverse[2] == inverse[3] and inverse[4] == inverse[6]
    assert not np.signbit(distinct).any()


@njit(cache=True, fastmath={"contract"})
def _grid_lambdas(u, out):
    for i in range(u.shape[0]):
        out[i] = rt.lambda_of_grid_column(u[i])


@njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _doppler_columns(d, out):
    for i in range(d.shape[0]):
        out[i] = rt.doppler_columns(d[i])


def test_doppler_columns_are_libms_log_and_vector_code():
    """The straight-line ln(D) · INV_DLOG (2ᵉ by selects, atanh's series) within 4 units
    in the last place of libm's log times INV_DLOG: log-uniform D over its whole range
    2^±62 and over the Doppler factors of |β| ≤ 0.999 (e^±3.8), D near 1 (|ln D| ~
    1e-6, where the result is small and its ulp fine), exact at 1 and within 1 ulp at
    the reduction's edges (2ᵏ, √2, 1/√2); and a loop of it is packed double code without
    a call to ``log`` (the moving bodies' lanes)."""
    rng = np.random.default_rng(4)
    d = np.concatenate([np.exp(rng.uniform(-43.0, 43.0, 100_000)),
                        np.exp(rng.uniform(-3.8, 3.8, 100_000)),
                        1.0 + rng.uniform(-1e-6, 1e-6, 10_000),
                        [1.0, 2.0 ** -62, 2.0 ** 62, 0.5, 2.0, 2.0 ** 32, 2.0 ** -33,
                         math.sqrt(2.0), 1.0 / math.sqrt(2.0), np.nextafter(math.sqrt(2.0), 2)]])
    got = np.empty_like(d)
    _doppler_columns(d, got)
    want = np.log(d) * sp.INV_DLOG
    assert got[-10] == 0.0
    ulps = np.abs(got - want) / np.spacing(np.abs(want) + 1e-300)
    assert np.max(ulps) <= 4.0
    assert np.max(ulps[-9:]) <= 1.0
    ir = "\n".join(_doppler_columns.inspect_llvm().values())
    assert "@log(" not in ir and "llvm.log" not in ir
    assert re.search(r"<(2|4|8) x double>", ir)


def test_lambda_of_grid_column_is_libms_exp_and_vector_code():
    """The straight-line λ of a grid column (2ⁿ times a Taylor series) within 4e-16 of
    :func:`lambda_of_column`'s libm ``exp`` over the whole grid (its nodes, its ends and
    1e5 uniform columns), 1 nm and 100 µm at the ends; and a loop of it is packed double
    code without a call to ``exp`` (what the SIMD lanes' refill needs)."""
    u = np.concatenate([np.arange(sp.GRID_N, dtype=np.float64),
                        np.random.default_rng(2).uniform(0.0, sp.GRID_N - 1.0, 100_000)])
    got = np.empty_like(u)
    _grid_lambdas(u, got)
    want = np.array([rt.lambda_of_column(x) for x in u])
    assert np.max(np.abs(got / want - 1.0)) < 4e-16
    assert abs(got[0] - 1.0) < 1e-15 and abs(got[sp.GRID_N - 1] / 1e5 - 1.0) < 4e-16
    ir = "\n".join(_grid_lambdas.inspect_llvm().values())
    assert "@exp(" not in ir and "llvm.exp" not in ir
    assert re.search(r"<(2|4|8) x double>", ir)
