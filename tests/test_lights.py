"""Light sampling against analytic solid angles and irradiances (each light kind).

``sample_light`` is called with a hand-made light record (:func:`lights.light_record`'s
tuple), so each test knows the exact geometry, and once through the light table a job's
area light becomes (select → rescale_uniform → light_record → sample_light, as the
integrator calls them). Monte Carlo checks compare with the exact value within 5
standard errors of the estimate (the error the estimator itself reports, not a tuned
tolerance: a correct estimator fails about once in 2 million sample sets, a normal
deviate beyond 5σ); the sample sets are deterministic.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from relray.core.render import lights
from relray.core.render.frames import prepare
from relray.core.render.sampling import path_keys, rand_dims, rescale_uniform
from relray.core.scene.geometry import build_scene
from relray.core.scene.job import parse_job

X = (0.1, -0.2, 0.05)   # the shading point
N_UP = (0.0, 0.0, 1.0)  # its normal
TRI = np.array([[-0.5, -0.4, 1.0], [0.7, -0.3, 1.2], [0.1, 0.8, 0.9]])  # above X


def uniforms(n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    keys = path_keys(3, 0, np.arange(n), np.zeros(n, np.int64))
    return rand_dims(keys, dim), rand_dims(keys, dim + 1)


def record(kind, pos=(0.0, 0.0, 0.0), dirn=(0.0, 0.0, -1.0), scale=1.0, spot=(0.0, 0.0),
           tri=TRI, one_sided=0):
    v0, e1, e2 = tri[0], tri[1] - tri[0], tri[2] - tri[0]
    c = np.cross(e1, e2)
    return (kind, tuple(pos), tuple(dirn), scale, tuple(spot), tuple(v0), tuple(e1), tuple(e2),
            tuple(c / np.linalg.norm(c)), 0.5 * float(np.linalg.norm(c)), one_sided)


@njit(cache=True)
def _draw(light, p_sel, u1, u2, x, n):
    """(1/p, cos θ_i scale / p, direction) per sample."""
    out = np.empty((len(u1), 5))
    for i in range(len(u1)):
        wi, p_l, scale, delta, finite, target, ok = lights.sample_light(
            light, p_sel, u1[i], u2[i], x[0], x[1], x[2], 0.0)
        cos_i = max(0.0, wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2])
        out[i, 0] = 1.0 / p_l if ok else 0.0
        out[i, 1] = cos_i * scale / p_l if ok else 0.0
        out[i, 2], out[i, 3], out[i, 4] = wi
    return out


def triangle_solid_angle(x, tri) -> float:
    """Van Oosterom & Strackee (1983): tan(Ω/2) = |a·(b×c)| / (abc + (a·b)c + (a·c)b + (b·c)a)."""
    a, b, c = (np.asarray(v, float) - np.asarray(x, float) for v in tri)
    la, lb, lc = (np.linalg.norm(v) for v in (a, b, c))
    num = abs(np.dot(a, np.cross(b, c)))
    den = la * lb * lc + np.dot(a, b) * lc + np.dot(a, c) * lb + np.dot(b, c) * la
    return 2.0 * math.atan2(num, den)


def polygon_irradiance(x, n, poly) -> float:
    """Lambert's formula for a unit-radiance polygon: E = ½ Σ γ_i n·(r_i × r_{i+1})/|…|."""
    r = [(np.asarray(v, float) - np.asarray(x, float)) for v in poly]
    r = [v / np.linalg.norm(v) for v in r]
    e = 0.0
    for i in range(len(r)):
        a, b = r[i], r[(i + 1) % len(r)]
        cr = np.cross(a, b)
        gamma = math.acos(np.clip(np.dot(a, b), -1, 1))
        e += gamma * np.dot(np.asarray(n, float), cr / np.linalg.norm(cr))
    return 0.5 * abs(e)


def within_mc_error(values: np.ndarray, exact: float, k: float = 5.0) -> None:
    se = values.std(ddof=1) / math.sqrt(len(values))
    assert abs(values.mean() - exact) < k * se + 1e-12, (values.mean(), exact, se)


def test_triangle_pdf_integrates_to_the_solid_angle():
    """E[1/p] over light samples = ∫ dω = Ω (p_sel = 1): the pdf is the exact
    solid-angle density of a uniform point on the triangle."""
    u1, u2 = uniforms(100_000, 0)
    s = _draw(record(lights.TRIANGLE), 1.0, u1, u2, np.array(X), np.array(N_UP))
    within_mc_error(s[:, 0], triangle_solid_angle(X, TRI))
    wrong = list(record(lights.TRIANGLE))
    wrong[9] *= 1.02  # a pdf 2 % off is caught: the check can fail
    s = _draw(tuple(wrong), 1.0, u1, u2, np.array(X), np.array(N_UP))
    with pytest.raises(AssertionError):
        within_mc_error(s[:, 0], triangle_solid_angle(X, TRI))


def test_triangle_irradiance_converges_to_lamberts_formula():
    u1, u2 = uniforms(100_000, 2)
    s = _draw(record(lights.TRIANGLE), 1.0, u1, u2, np.array(X), np.array(N_UP))
    within_mc_error(s[:, 1], polygon_irradiance(X, N_UP, TRI))


def test_triangle_pdf_of_a_bsdf_direction_matches_the_light_sample():
    """For MIS the pdf of a direction found by BSDF sampling (triangle_light_pdf at the
    hit) equals the pdf sample_light gives the same point."""
    u1, u2 = uniforms(50, 4)
    rec = record(lights.TRIANGLE)
    ng = np.array(rec[8])
    for a, b in zip(u1, u2, strict=True):
        wi, p_l, *_ = lights.sample_light(rec, 0.25, a, b, *X, 0.0)
        b1, b2 = math.sqrt(a) * (1 - b), math.sqrt(a) * b
        y = TRI[0] + b1 * (TRI[1] - TRI[0]) + b2 * (TRI[2] - TRI[0])
        dist = np.linalg.norm(y - np.array(X))
        cos_l = -float(np.dot(ng, np.array(wi)))
        assert lights.triangle_light_pdf(0.25, rec[9], dist, cos_l) == pytest.approx(p_l,
                                                                                     rel=1e-9)


def test_one_sided_triangle_seen_from_behind_is_refused():
    rec = record(lights.TRIANGLE, tri=TRI, one_sided=1)
    assert rec[8][2] > 0  # TRI's normal (v1-v0)×(v2-v0) faces up, away from X below it
    *_, ok = lights.sample_light(rec, 1.0, 0.3, 0.6, *X, 0.0)
    assert not ok
    *_, ok = lights.sample_light(record(lights.TRIANGLE, tri=TRI[[0, 2, 1]], one_sided=1),
                                 1.0, 0.3, 0.6, *X, 0.0)
    assert ok
    *_, ok = lights.sample_light(record(lights.TRIANGLE, tri=TRI, one_sided=0), 1.0, 0.3,
                                 0.6, *X, 0.0)
    assert ok  # two-sided: seen from either side


def test_sky_is_uniform_over_the_sphere():
    """p = p_sel/(4π) for every sample (E[1/p] = 4π exactly), directions uniform: each
    z slab of the sphere gets its share (chi-square, 20 slabs)."""
    from scipy import stats

    u1, u2 = uniforms(100_000, 6)
    s = _draw(record(lights.SKY), 0.5, u1, u2, np.array(X), np.array(N_UP))
    assert np.allclose(s[:, 0], 4 * math.pi / 0.5)
    assert lights.sky_light_pdf(0.5) == pytest.approx(0.5 / (4 * math.pi))
    counts, _ = np.histogram(s[:, 4], bins=20, range=(-1, 1))
    assert stats.chisquare(counts).pvalue > 1e-3
    within_mc_error(s[:, 1] * 0.5, math.pi)  # ∫ cos⁺ dω over the sphere = π


def test_point_light_is_inverse_square():
    pos = (1.0, 2.0, 3.0)
    wi, p_l, scale, delta, finite, target, ok = lights.sample_light(
        record(lights.POINT, pos=pos, scale=7.0), 0.3, 0.1, 0.2, *X, 0.0)
    r = np.array(pos) - np.array(X)
    assert delta and finite and ok and p_l == 0.3 and target == pos
    assert scale == pytest.approx(7.0 / np.dot(r, r))
    assert np.allclose(wi, r / np.linalg.norm(r))


@pytest.mark.parametrize("angle_deg, expected", [(0.0, 1.0), (10.0, 1.0), (40.0, 0.0),
                                                 (19.0, None)])
def test_spot_cone_is_blenders_smoothstep(angle_deg, expected):
    """Size 40° (half-angle 20°), blend 0.5: full inside the blend, zero outside the cone,
    smoothstep((cos a - cos 20°) / ((1 - cos 20°) 0.5)) in between."""
    cos_half = math.cos(math.radians(20))
    smooth = (1 - cos_half) * 0.5
    a = math.radians(angle_deg)
    light_pos = np.array(X) + 2.0 * np.array([math.sin(a), 0.0, math.cos(a)])
    rec = record(lights.SPOT, pos=tuple(light_pos), dirn=(0.0, 0.0, -1.0), scale=1.0,
                 spot=(cos_half, smooth))
    _, _, scale, *_ = lights.sample_light(rec, 1.0, 0.5, 0.5, *X, 0.0)
    mask = scale * 4.0  # r = 2
    if expected is None:
        t = (math.cos(a) - cos_half) / smooth
        expected = t * t * (3 - 2 * t)
    assert mask == pytest.approx(expected, abs=1e-12)


def test_sun_is_a_direction_with_irradiance():
    wi, p_l, scale, delta, finite, _, ok = lights.sample_light(
        record(lights.SUN, dirn=(0.0, 0.6, -0.8), scale=3.0), 0.2, 0.5, 0.5, *X, 0.0)
    assert delta and not finite and ok and p_l == 0.2 and scale == 3.0
    assert np.allclose(wi, (0.0, -0.6, 0.8))


def test_light_selection_and_its_reused_number_are_uniform():
    """select picks k with probability cdf[k+1] - cdf[k]; the same number rescaled in
    the interval is again uniform (what shade reuses for the point on the light)."""
    from scipy import stats

    cdf = np.array([0.0, 0.1, 0.5, 1.0])
    u, _ = uniforms(60_000, 8)
    picks = np.array([lights.select(cdf, x)[0] for x in u])
    counts = np.bincount(picks, minlength=3)
    assert stats.chisquare(counts, 60_000 * np.diff(cdf)).pvalue > 1e-3
    k = 2
    rescaled = []
    for x in u:
        kk, p_sel, lo = lights.select(cdf, x)
        if kk == k:
            assert p_sel == cdf[k + 1] - cdf[k] and lo == cdf[k]
            rescaled.append(rescale_uniform(x, lo, p_sel))
    hist, _ = np.histogram(rescaled, bins=20, range=(0, 1))
    assert len(rescaled) == counts[k] and stats.chisquare(hist).pvalue > 1e-3


def test_light_record_reads_the_table():
    table_kind = np.array([lights.SPOT], np.int32)
    v0 = np.zeros((2, 3), np.float32)
    rec = lights.light_record(0, table_kind, np.array([-1], np.int32),
                              np.array([[1, 2, 3]], np.float32), np.array([[0, 0, -1]],
                                                                           np.float32),
                              np.array([5.0], np.float32), np.array([[0.9, 0.05]], np.float32),
                              v0, v0, v0, v0, np.ones(2, np.float32), np.zeros(2, np.int32),
                              np.zeros(1, np.int32))
    assert rec[0] == lights.SPOT and rec[1] == (1, 2, 3) and rec[3] == 5.0
    assert rec[4] == pytest.approx((0.9, 0.05))


@njit(cache=True)
def _draw_from_table(sc, u_a, u2, x, n):
    """(1/p, cos θ_i / p) per sample, the light picked from the kernel's light table."""
    out = np.empty((len(u_a), 2))
    for i in range(len(u_a)):
        k, p_sel, lo = lights.select(sc.l_cdf, u_a[i])
        light = lights.light_record(k, sc.l_kind, sc.l_prim, sc.l_pos, sc.l_dir, sc.l_scale,
                                    sc.l_spot, sc.v0, sc.e1, sc.e2, sc.ng, sc.area,
                                    sc.tri_mat, sc.mat_one_sided)
        wi, p_l, scale, delta, finite, target, ok = lights.sample_light(
            light, p_sel, rescale_uniform(u_a[i], lo, p_sel), u2[i], x[0], x[1], x[2], 0.0)
        cos_i = max(0.0, wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2])
        out[i, 0] = 1.0 / p_l if ok else 0.0
        out[i, 1] = cos_i * scale / p_l if ok else 0.0
    return out


def test_area_light_through_the_light_table_sees_the_rectangles_solid_angle(tmp_path):
    """A job's a × b area light (two triangles in the light table) seen from a point on
    its axis at height h: E[1/p] is the rectangle's solid angle
    Ω = 4 asin(ab / sqrt((a² + 4h²)(b² + 4h²))) and E[cos θ/p] Lambert's polygon
    irradiance (both independent of the rectangle's turn about its axis)."""
    a, b, h = 1.0, 0.5, 1.5
    job = parse_job({
        "render": {"width": 4, "height": 4, "spp": 1},
        "camera": {"position": [0, -5, 1], "look_at": [0, 0, 1]},
        "materials": [{"name": "grey", "base_color": [0.5, 0.5, 0.5]}],
        "objects": [{"shape": "sphere", "center": [3, 3, 0], "radius": 0.2,
                     "material": "grey"}],
        "lights": [{"type": "area", "position": [0, 0, 2], "direction": [0, 0, -1],
                    "size": [a, b], "power": 10}]}, tmp_path / "job.toml")
    prep = prepare(build_scene(job), "rgb")
    assert list(prep.kernel.l_kind) == [lights.TRIANGLE, lights.TRIANGLE]
    x = np.array([0.0, 0.0, 2.0 - h]) - prep.accel.origin
    u_a, u2 = uniforms(100_000, 10)
    s = _draw_from_table(prep.kernel, u_a, u2, x, np.array(N_UP))
    omega = 4 * math.asin(a * b / math.sqrt((a * a + 4 * h * h) * (b * b + 4 * h * h)))
    within_mc_error(s[:, 0], omega)
    rect = [(-a / 2, -b / 2, 2.0), (a / 2, -b / 2, 2.0), (a / 2, b / 2, 2.0), (-a / 2, b / 2, 2.0)]
    within_mc_error(s[:, 1], polygon_irradiance((0.0, 0.0, 2.0 - h), N_UP, rect))
