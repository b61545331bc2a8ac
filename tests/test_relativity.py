"""Tests of core/physics/relativity.py: the analytic cases of physics.md, and invariants.

Tolerances are derived from floating point, never tuned:
- EPS is the float64 machine epsilon (2.2e-16). A formula evaluated in k correctly rounded
  operations is off by at most about k/2 ulps, so "a few ulps" means a small multiple of EPS.
- Near b = 1 an error in a direction is amplified by the aberration map by at most
  max(D, 1/D) <= γ(1+b) <= 2γ, and boost entries are O(γ²); those tolerances scale so.
- Printed table values (e.g. 25.84°) are checked by rounding the exact result to the
  printed number of digits.
"""

from __future__ import annotations

import dataclasses
import math
import re
from decimal import Decimal, localcontext

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from relray.core.errors import UserError
from relray.core.jit import FAST_MATH
from relray.core.physics import relativity as rel

EPS = float(np.finfo(np.float64).eps)
X, Y, Z = np.eye(3)
ETA = np.diag([1.0, -1.0, -1.0, -1.0])
SPEEDS = [0.0, 1e-300, 1e-8, 0.5, 0.99, 1.0 - 1e-9]


def angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between vectors, accurate at 0 and π (atan2 of |u×v| and u·v)."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, axis=-1))


def exact_gamma(b: float) -> Decimal:
    """γ of the float b, in 50-digit decimal arithmetic (Decimal(b) is exact)."""
    with localcontext() as ctx:
        ctx.prec = 50
        B = Decimal(b)
        return 1 / ((1 - B) * (1 + B)).sqrt()


# --------------------------------------------------------------------------- γ, speed, φ


def test_gamma_simple_values():
    assert rel.gamma(0.0) == 1.0
    assert rel.gamma(np.zeros(3)) == 1.0
    # γ(0.6) = 1.25: 4 rounded operations -> within 4 ulps.
    assert rel.gamma(0.6) == pytest.approx(1.25, rel=4 * EPS, abs=0)
    assert rel.gamma([0.0, 0.6, 0.0]) == rel.gamma(0.6)
    assert rel.gamma([0.5, 0.0, 0.0]) == pytest.approx(2 / math.sqrt(3), rel=4 * EPS, abs=0)


def test_gamma_vectorised_over_leading_axes():
    betas = np.array([[[0.5, 0, 0], [0, 0.6, 0]], [[0, 0, 0], [0.3, 0.4, 0]]])
    g = rel.gamma(betas)
    assert isinstance(g, np.ndarray) and g.shape == (2, 2)
    expected = [[rel.gamma(b) for b in row] for row in betas]
    np.testing.assert_array_equal(g, expected)


def test_gamma_precision_near_light_speed():
    # The literal 1 - 1e-15 is stored as 1 - 9·2^-53 = 1 - 9.992e-16, so γ of the stored
    # number differs from 1/sqrt(2e-15 - 1e-30) by ~4e-4 (representation, not arithmetic).
    # We check γ of the number actually stored against a 50-digit reference: 1 - b is
    # exact (Sterbenz), then 1+b, the product, sqrt and the division round once each.
    b = 1.0 - 1e-15
    g = rel.gamma(b)
    assert math.isfinite(g)
    assert abs(Decimal(g) / exact_gamma(b) - 1) <= 4 * EPS
    delta = 1.0 - b  # exact
    assert g == pytest.approx(1.0 / math.sqrt(2 * delta - delta * delta), rel=4 * EPS, abs=0)
    assert g == pytest.approx(1.0 / math.sqrt(2e-15 - 1e-30), rel=5e-4)  # representation
    # Along an axis the 3-vector path is the same computation.
    assert rel.gamma([0.0, 0.0, -b]) == g


@pytest.mark.parametrize("b", [1 - math.pi * 1e-13, 1 - math.e * 1e-9, 0.999999999987654321])
def test_gamma_keeps_precision_where_one_minus_b_squared_cancels(b):
    # For a b with a full mantissa, b² rounds by ~1e-16 absolute, so 1/sqrt(1 - b²) loses
    # about log10(ulp/(1-b)) digits; the factored form stays within 4 ulps.
    exact = exact_gamma(b)
    assert abs(Decimal(rel.gamma(b)) / exact - 1) <= 4 * EPS
    naive = 1.0 / math.sqrt(1.0 - b * b)
    assert abs(Decimal(naive) / exact - 1) > 100 * EPS  # the test can tell the difference


@pytest.mark.parametrize("b", [1.0, 1.5, -1.0, math.nan, math.inf])
def test_gamma_rejects_invalid_speeds(b):
    with pytest.raises(ValueError):
        rel.gamma(b)
    with pytest.raises(ValueError):
        rel.gamma([b, 0.0, 0.0])


def test_gamma_rejects_unit_vector_and_bad_shapes():
    with pytest.raises(ValueError):
        rel.gamma([0.6, 0.8, 0.0])  # hypot gives exactly 1
    with pytest.raises(ValueError):
        rel.gamma([0.1, 0.2])


def test_speed_does_not_underflow_or_overflow():
    assert rel.speed([1e-300, 0.0, 0.0]) == 1e-300
    assert rel.speed([3e-200, 4e-200, 0.0]) == pytest.approx(5e-200, rel=4 * EPS)
    assert rel.speed([3e200, 4e200, 0.0]) == pytest.approx(5e200, rel=4 * EPS)
    assert rel.speed(-0.25) == 0.25
    np.testing.assert_array_equal(rel.speed(np.zeros((4, 3))), np.zeros(4))


@pytest.mark.parametrize("b", [1e-8, 0.5, 0.99])
def test_rapidity(b):
    phi = rel.rapidity([0.0, b, 0.0])
    # tanh, cosh: a few ulps each (atanh is well conditioned at these b).
    assert math.tanh(phi) == pytest.approx(b, rel=8 * EPS)
    assert math.cosh(phi) == pytest.approx(rel.gamma(b), rel=8 * EPS)


# --------------------------------------------------------------------------- Lorentz boost


@pytest.mark.parametrize("b", SPEEDS)
def test_boost_preserves_minkowski_metric_and_inverts(b):
    rng = np.random.default_rng(1)
    n_hat = rng.normal(size=3)
    n_hat /= np.linalg.norm(n_hat)
    beta = b * n_hat
    L = rel.lorentz_boost(beta)
    g = rel.gamma(beta)
    # Entries are O(γ); products O(γ²) cancel to O(1), so errors are a few ulps of γ².
    tol = 16 * g * g * EPS
    np.testing.assert_allclose(L @ ETA @ L.T, ETA, rtol=0, atol=tol)
    np.testing.assert_allclose(L @ rel.lorentz_boost(-beta), np.eye(4), rtol=0, atol=tol)
    np.testing.assert_array_equal(L, L.T)


def test_boost_is_exactly_identity_at_rest():
    L = rel.lorentz_boost(np.zeros(3))
    np.testing.assert_array_equal(L, np.eye(4))
    assert not np.any(np.signbit(L))  # no -0.0 either
    assert np.array_equal(rel.lorentz_boost([-0.0, 0.0, -0.0]), np.eye(4))


def test_boost_vectorised_matches_single():
    betas = np.array([[0.5, 0, 0], [0, 0, 0], [0.1, -0.2, 0.3]])
    Ls = rel.lorentz_boost(betas)
    assert Ls.shape == (3, 4, 4)
    for beta, L in zip(betas, Ls, strict=True):
        np.testing.assert_array_equal(L, rel.lorentz_boost(beta))


def test_boost_of_a_lab_event():
    # Standard form along x: t' = γ(t - βx), x' = γ(x - βt).
    b = 0.6
    L = rel.lorentz_boost([b, 0, 0])
    ev = np.array([2.0, 1.0, 3.0, -4.0])
    np.testing.assert_allclose(
        L @ ev, [1.25 * (2 - 0.6), 1.25 * (1 - 1.2), 3.0, -4.0], rtol=8 * EPS, atol=8 * EPS
    )


@pytest.mark.parametrize("b", [0.3, 0.5, 0.99])
def test_snapshot_camera_is_at_rest_at_its_origin(b):
    # The snapshot camera moved inertially from (0, position): in its rest frame the
    # shutter event is (τ, 0, 0, 0). Boost entries O(γ) times coordinates O(γτ) -> tol γ²τ ulps.
    beta = b * np.array([0.6, 0.0, -0.8])
    pos = np.array([1.0, -2.0, 0.5])
    tau = 3.0
    ev = rel.snapshot_event(pos, beta, tau)
    rel4 = ev.four_position() - np.concatenate(([0.0], pos))
    out = rel.lorentz_boost(ev.beta) @ rel4
    g = rel.gamma(beta)
    np.testing.assert_allclose(out, [tau, 0, 0, 0], rtol=0, atol=16 * g * g * tau * EPS)
    # Interval: t² - |Δx|² = τ².
    assert rel4[0] ** 2 - rel4[1:] @ rel4[1:] == pytest.approx(tau**2, rel=16 * g * g * EPS)


@pytest.mark.parametrize(("ahead", "factor"), [(True, math.sqrt(3)), (False, 1 / math.sqrt(3))])
def test_rod_along_line_of_sight(ahead, factor):
    # Camera at the lab origin at t = 0 moving with β = 0.5 x̂; a rod at rest in the lab on
    # the x axis. Its ends are seen at emission events on the past light cone
    # (t = -distance). In the camera frame the rod appears √((1+β)/(1-β)) as long when
    # approaching (1.732) and √((1-β)/(1+β)) when receding (0.577).
    a, length = 2.0, 1.0
    sign = 1.0 if ahead else -1.0
    L = rel.lorentz_boost([0.5, 0.0, 0.0])
    near = L @ np.array([-a, sign * a, 0.0, 0.0])
    far = L @ np.array([-(a + length), sign * (a + length), 0.0, 0.0])
    apparent = abs(far[1] - near[1])
    assert round(apparent / length, 3) == round(factor, 3)
    # Coordinates of size ~(a + L)γ(1+β) subtract to ~L: error a few ulps of a + L.
    assert apparent == pytest.approx(factor * length, rel=16 * EPS * (a + length) / length)


def test_terrell_cube():
    # A distant cube of side a seen at 90° in the camera frame (β = 0.5 x̂): its face
    # towards the camera looks a/γ wide and its trailing face (+x, the cube moves along -x
    # in the camera frame) shows with width βa. Orthographic widths from the camera-frame
    # positions of emission events; perspective (parallax) corrections are O(a/R).
    b, a, R = 0.5, 1.0, 1e6
    g = rel.gamma(b)
    beta = np.array([b, 0.0, 0.0])
    centre = R * rel.aberrate(Y, beta)  # lab direction seen at camera-frame 90° (ŷ)
    L = rel.lorentz_boost(beta)

    def seen_x(corner: np.ndarray) -> float:
        return (L @ np.concatenate(([-np.linalg.norm(corner)], corner)))[1]

    h = a / 2
    facing = abs(seen_x(centre + [h, -h, 0]) - seen_x(centre + [-h, -h, 0]))
    trailing = abs(seen_x(centre + [h, h, 0]) - seen_x(centre + [h, -h, 0]))
    assert facing == pytest.approx(a / g, rel=4 * a / R)
    assert trailing == pytest.approx(b * a, rel=4 * a / R)


# --------------------------------------------------------------------------- aberration table


def test_aberration_check_value():
    d = rel.aberrate(Y, [0.5, 0.0, 0.0])
    # exact result (-1/2, √3/2, 0); a handful of roundings -> a few ulps.
    np.testing.assert_allclose(d, [-0.5, math.sqrt(3) / 2, 0.0], rtol=0, atol=4 * EPS)
    assert round(d[1], 3) == 0.866


@pytest.mark.parametrize(("b", "deg"), [(0.5, 60.0), (0.9, 25.84)])
def test_lab_source_at_90_degrees(b, deg):
    # sin θ' = 1/γ (equivalently cos θ' = β).
    d_cam = rel.aberrate_inverse(Y, [b, 0.0, 0.0])
    theta = angle(d_cam, X)
    assert theta == pytest.approx(math.asin(1 / rel.gamma(b)), abs=8 * EPS)
    assert math.cos(theta) == pytest.approx(b, abs=8 * EPS)
    assert round(math.degrees(theta), 2) == deg


def test_lab_source_at_120_degrees_appears_at_90():
    d_lab = np.array([math.cos(math.radians(120)), math.sin(math.radians(120)), 0.0])
    d_cam = rel.aberrate_inverse(d_lab, [0.5, 0.0, 0.0])
    np.testing.assert_allclose(d_cam, Y, rtol=0, atol=8 * EPS)


def test_penrose_terrell_sphere_outline_is_a_shifted_circle():
    # A sphere of 10° angular radius at 90° in the lab, β = 0.5 x̂: in the camera frame its
    # outline is a circle (aberration is conformal) of radius 8.682° centred at 60.378°.
    beta = np.array([0.5, 0.0, 0.0])
    r = math.radians(10.0)
    phi = np.linspace(0.0, 2 * math.pi, 361)
    ring_lab = math.cos(r) * Y + math.sin(r) * (np.cos(phi)[:, None] * X + np.sin(phi)[:, None] * Z)
    ring_cam = rel.aberrate_inverse(ring_lab, beta)
    t1, t2 = angle(ring_cam[0], X), angle(ring_cam[180], X)  # the in-plane extremes
    centre_angle, radius = 0.5 * (t1 + t2), 0.5 * (t2 - t1)
    assert round(math.degrees(centre_angle), 3) == 60.378
    assert round(math.degrees(radius), 3) == 8.682
    centre = np.array([math.cos(centre_angle), math.sin(centre_angle), 0.0])
    # Every direction carries a few ulps; atan2 angles then err by a few ulps of 1.
    np.testing.assert_allclose(angle(ring_cam, centre), radius, rtol=0, atol=32 * EPS)


# --------------------------------------------------------------------------- Doppler table


def test_doppler_550nm_line_ahead_and_behind():
    beta = [0.5, 0.0, 0.0]
    d_ahead, d_behind = rel.doppler_factor(X, beta), rel.doppler_factor(-X, beta)
    assert d_ahead == pytest.approx(math.sqrt(3), rel=4 * EPS)
    assert d_behind == pytest.approx(1 / math.sqrt(3), rel=4 * EPS)
    # λ_lab = D λ_cam: a 550 nm lab line is seen at 550/D.
    assert round(550.0 / d_ahead, 1) == 317.5
    assert round(550.0 / d_behind, 1) == 952.6


def test_transverse_doppler():
    beta = [0.5, 0.0, 0.0]
    g = rel.gamma(0.5)
    assert rel.doppler_factor(Y, beta) == pytest.approx(1 / g, rel=4 * EPS)
    assert rel.doppler_factor_lab(Y, beta) == pytest.approx(g, rel=4 * EPS)
    assert round(rel.doppler_factor(Y, beta), 3) == 0.866
    assert round(rel.doppler_factor_lab(Y, beta), 3) == 1.155


def test_doppler_ring():
    theta = rel.doppler_ring_angle(0.5)
    assert round(math.degrees(theta), 2) == 74.46
    for b in [1e-300, 1e-8, 0.5, 0.99, 1 - 1e-9]:
        t = rel.doppler_ring_angle(b)
        d_cam = np.array([math.cos(t), math.sin(t), 0.0])
        # Near θ' = 0, arccos fixes θ' only to ulp(cos θ')/sin θ', and at D = 1
        # d ln D/dθ' = -γ b sin θ', so D = 1 holds to about γ b ulps (a few, times γ).
        tol = 8 * rel.gamma(b) * EPS
        assert rel.doppler_factor(d_cam, [b, 0.0, 0.0]) == pytest.approx(1.0, abs=tol)
    assert rel.doppler_ring_angle(0.0) == pytest.approx(math.pi / 2, abs=EPS)
    np.testing.assert_allclose(
        rel.doppler_ring_angle(np.array([0.0, 0.5])), [math.pi / 2, theta], rtol=0, atol=0
    )
    with pytest.raises(ValueError):
        rel.doppler_ring_angle(1.0)


def test_doppler_is_one_at_rest_and_vectorised():
    d = np.random.default_rng(2).normal(size=(5, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_array_equal(rel.doppler_factor(d, np.zeros(3)), np.ones(5))
    np.testing.assert_array_equal(rel.doppler_factor_lab(d, np.zeros(3)), np.ones(5))
    beta = np.array([0.2, -0.3, 0.4])
    D = rel.doppler_factor(d, beta)
    assert D.shape == (5,)
    np.testing.assert_array_equal(D, [rel.doppler_factor(di, beta) for di in d])


def test_doppler_precision_near_light_speed_slightly_off_axis():
    # b = 1 - 1e-9, θ' = 1e-5: 1 - β·d' ≈ 1e-9 + 5e-11. Computed directly, 1 - b cos θ'
    # would lose ~7 digits; the chord form keeps a few ulps. Reference: 50-digit decimals
    # for the normalised stored direction.
    b = 1.0 - 1e-9
    s = 1e-5
    c = math.sqrt(1.0 - s * s)
    with localcontext() as ctx:
        ctx.prec = 50
        cos_true = Decimal(c) / (Decimal(c) ** 2 + Decimal(s) ** 2).sqrt()
        d_ref = 1 / (exact_gamma(b) * (1 - Decimal(b) * cos_true))
    D = rel.doppler_factor([c, s, 0.0], [b, 0.0, 0.0])
    assert abs(Decimal(D) / d_ref - 1) <= 16 * EPS
    # Looking backwards in the lab, 1 + β·d has the same problem, solved the same way.
    D_lab = rel.doppler_factor_lab([-c, s, 0.0], [b, 0.0, 0.0])
    with localcontext() as ctx:
        ctx.prec = 50
        d_lab_ref = exact_gamma(b) * (1 - Decimal(b) * cos_true)
        ahead = 1 / (exact_gamma(b) * (1 - Decimal(b)))  # straight ahead: sqrt((1+b)/(1-b))
        assert abs(Decimal(D_lab) / d_lab_ref - 1) <= 16 * EPS
        assert abs(Decimal(rel.doppler_factor(X, [b, 0, 0])) / ahead - 1) <= 8 * EPS


# --------------------------------------------------------------------------- properties


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


finite = st.floats(-1.0, 1.0, allow_nan=False)
vec3 = st.tuples(finite, finite, finite).map(np.array).filter(lambda v: np.linalg.norm(v) > 0.1)
unit3 = vec3.map(unit)
speeds = st.one_of(st.sampled_from(SPEEDS), st.floats(0.0, 1.0 - 1e-12))


@st.composite
def camera_cases(draw):
    """(β, d') with β of any speed in SPEEDS or random, and d' random, or near ±β̂."""
    b = draw(speeds)
    beta_hat = draw(unit3)
    kind = draw(st.sampled_from(["random", "near_forward", "near_backward", "exact"]))
    if kind == "random":
        d = draw(unit3)
    else:
        sign = -1.0 if kind == "near_backward" else 1.0
        tilt = 0.0 if kind == "exact" else draw(st.sampled_from([1e-12, 1e-8, 1e-4, 1e-2]))
        d = unit(sign * beta_hat + tilt * draw(unit3))
    return b * beta_hat, d


def round_trip_tol(beta: np.ndarray) -> float:
    """The inverse map magnifies direction errors by at most max(D, 1/D) <= γ(1+b) <= 2γ;
    each evaluation commits a few ulps."""
    return 16 * EPS * (1 + 2 * rel.gamma(beta))


@settings(max_examples=200, deadline=None)
@given(camera_cases())
def test_aberration_unit_length_and_round_trip(case):
    beta, d_cam = case
    d_lab = rel.aberrate(d_cam, beta)
    # Renormalised in float64: |d| = 1 within a few ulps.
    assert abs(np.linalg.norm(d_lab) - 1.0) <= 4 * EPS
    back = rel.aberrate_inverse(d_lab, beta)
    assert abs(np.linalg.norm(back) - 1.0) <= 4 * EPS
    assert np.max(np.abs(back - d_cam)) <= round_trip_tol(beta)


@settings(max_examples=200, deadline=None)
@given(camera_cases())
def test_doppler_camera_and_lab_forms_agree(case):
    beta, d_cam = case
    D = rel.doppler_factor(d_cam, beta)
    D_lab = rel.doppler_factor_lab(rel.aberrate(d_cam, beta), beta)
    # ln D_lab changes by at most γb per radian of direction error (a few ulps).
    assert D_lab == pytest.approx(D, rel=round_trip_tol(beta), abs=0)
    # Independently, from the boost: the photon's lab 4-wavevector (1, -d_lab) becomes
    # (D, -D d_cam) in the camera frame. Entries of Λ are O(γ) and the components are sums
    # of terms up to γ(1+b) <= 2γ, so absolute errors are a few ulps of 2γ.
    k_cam = rel.lorentz_boost(beta) @ np.concatenate(([1.0], -rel.aberrate(d_cam, beta)))
    tol = 32 * rel.gamma(beta) * EPS
    np.testing.assert_allclose(k_cam, D * np.concatenate(([1.0], -d_cam)), rtol=0, atol=tol)


@settings(max_examples=50, deadline=None)
@given(unit3)
def test_aberration_is_bit_exact_identity_at_rest(d):
    for zero in (np.zeros(3), [-0.0, 0.0, 0.0]):
        assert np.array_equal(rel.aberrate(d, zero), d)
        assert np.array_equal(rel.aberrate_inverse(d, zero), d)
    batch = np.stack([d, -d]).astype(np.float32)
    out = rel.aberrate(batch, np.zeros(3))
    assert out.dtype == np.float64 and np.array_equal(out, batch)
    assert out is not batch


@pytest.mark.parametrize("b", SPEEDS[1:])
def test_aberration_angle_is_increasing(b):
    # In a plane containing β̂, the lab angle θ(θ') is strictly increasing on [0, π]:
    # dθ/dθ' = D >= 1/(γ(1+b)). On this grid the true steps (>= 3e-8 rad) exceed the
    # direction errors (<= 2γ ulps, < 1e-11 rad) by far, so ties would be a bug.
    rng = np.random.default_rng(3)
    beta_hat = unit(rng.normal(size=3))
    e = unit(np.cross(beta_hat, rng.normal(size=3)))
    theta_cam = np.linspace(0.0, math.pi, 2001)
    d_cam = np.cos(theta_cam)[:, None] * beta_hat + np.sin(theta_cam)[:, None] * e
    theta_lab = angle(rel.aberrate(d_cam, b * beta_hat), beta_hat)
    assert np.all(np.diff(theta_lab) > 0.0)
    assert theta_lab[0] == pytest.approx(0.0, abs=1e-7)
    assert theta_lab[-1] == pytest.approx(math.pi, abs=1e-7)
    # Things crowd towards the motion: θ' <= θ (up to rounding).
    assert np.all(theta_cam <= theta_lab + 1e-12)


def test_subnormal_beta_and_acceleration():
    # |(0, 5e-324, 5e-324)| rounds to 5e-324, so a naive β/|β| is (0, 1, 1), not a unit
    # vector (found by hypothesis). At such speeds everything is the identity to rounding.
    tiny = np.array([0.0, 5e-324, 5e-324])
    d = unit(np.array([0.3, -0.4, 0.5]))
    np.testing.assert_allclose(rel.aberrate(d, tiny), d, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(rel.aberrate_inverse(d, tiny), d, rtol=0, atol=4 * EPS)
    assert rel.doppler_factor(d, tiny) == pytest.approx(1.0, abs=4 * EPS)
    assert rel.doppler_factor_lab(d, tiny) == pytest.approx(1.0, abs=4 * EPS)
    ev = rel.constant_acceleration_event(np.zeros(3), tiny, 1.0)
    assert ev.t == pytest.approx(1.0, abs=4 * EPS)
    np.testing.assert_allclose(ev.beta, tiny, rtol=0, atol=1e-323)


def test_aberration_rejects_bad_input():
    with pytest.raises(ValueError):
        rel.aberrate(Y, [1.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        rel.aberrate([0.0, 1.0], [0.5, 0.0, 0.0])
    with pytest.raises(ValueError):
        rel.doppler_factor(Y, [math.nan, 0.0, 0.0])


# --------------------------------------------------------------------------- worldlines


def test_constant_acceleration_table_row():
    ev = rel.constant_acceleration_event(np.zeros(3), [1.0, 0.0, 0.0], 1.0)
    # A few rounded operations on sinh/cosh of 1/2 -> within 8 ulps.
    np.testing.assert_allclose(ev.beta, [math.tanh(1.0), 0, 0], rtol=8 * EPS, atol=0)
    assert ev.t == pytest.approx(math.sinh(1.0), rel=8 * EPS)
    np.testing.assert_allclose(ev.x, [math.cosh(1.0) - 1.0, 0, 0], rtol=8 * EPS, atol=0)
    assert ev.tau == 1.0


def test_constant_acceleration_small_and_zero():
    a, tau = 1e-10, 1.0
    ev = rel.constant_acceleration_event([1.0, 2.0, 3.0], [0.0, a, 0.0], tau)
    u = a * tau
    # Taylor: x = aτ²/2 (1 + (aτ)²/12 + ...), t = τ (1 + (aτ)²/6 + ...): truncation ~1e-40.
    assert ev.x[1] - 2.0 == pytest.approx(0.5 * a * tau**2 * (1 + u * u / 12), rel=1e-6)
    assert ev.t == pytest.approx(tau, rel=2 * EPS)
    assert ev.beta[1] == pytest.approx(u, rel=2 * EPS)
    # The displacement itself (before adding the position) is accurate to a few ulps.
    ev0 = rel.constant_acceleration_event(np.zeros(3), [0.0, a, 0.0], tau)
    assert ev0.x[1] == pytest.approx(0.5 * a * tau**2, rel=8 * EPS)
    rest = rel.constant_acceleration_event([1.0, 2.0, 3.0], np.zeros(3), 2.5)
    assert rest.t == 2.5 and np.array_equal(rest.x, [1.0, 2.0, 3.0])
    assert np.array_equal(rest.beta, np.zeros(3))


def test_constant_acceleration_with_initial_velocity_matches_rk4():
    # β0 = -0.6 ẑ, a = 0.8 ẑ (braking, then reversing): β(τ) = tanh(φ0 + aτ) ẑ.
    phi0, a, tau = math.atanh(-0.6), 0.8, 2.0
    ev = rel.constant_acceleration_event(np.zeros(3), [0, 0, a], tau, beta0=[0, 0, -0.6])
    ref = rel.integrate_worldline(
        np.zeros(3), lambda s: np.array([0.0, 0.0, math.tanh(phi0 + a * s)]), tau, steps=512
    )
    # Simpson bound τ h⁴ max|f''''|/2880 with f'''' <= a⁴ cosh(max|φ|) ~ 0.4*1.3: ~1e-14.
    assert ev.t == pytest.approx(ref.t, abs=1e-12)
    np.testing.assert_allclose(ev.x, ref.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ev.beta, ref.beta, rtol=0, atol=4 * EPS)
    with pytest.raises(ValueError):
        rel.constant_acceleration_event(np.zeros(3), [0, 0, a], tau, beta0=[0.1, 0, 0])
    with pytest.raises(ValueError):  # β rounds to 1
        rel.constant_acceleration_event(np.zeros(3), [1.0, 0, 0], 40.0)


def test_rk4_reproduces_hyperbolic_motion():
    def beta_of_tau(s: float) -> np.ndarray:
        return np.array([math.tanh(s), 0.0, 0.0])

    steps = 256
    ev = rel.integrate_worldline(np.zeros(3), beta_of_tau, 1.0, steps=steps)
    # RK4 with a τ-only right-hand side is Simpson: error <= τ h⁴ max|f''''|/2880,
    # f'''' = cosh or sinh <= cosh 1; plus rounding of ~2·steps terms (~1e-13).
    bound = (1.0 / steps) ** 4 * math.cosh(1.0) / 2880 + 1e-13
    assert bound < 1e-10
    assert abs(ev.t - math.sinh(1.0)) <= bound
    assert abs(ev.x[0] - (math.cosh(1.0) - 1.0)) <= bound
    assert ev.beta[0] == math.tanh(1.0) and ev.tau == 1.0
    # Fourth order: halving h divides the error by ~16.
    e8 = abs(rel.integrate_worldline(np.zeros(3), beta_of_tau, 1.0, steps=8).t - math.sinh(1))
    e16 = abs(rel.integrate_worldline(np.zeros(3), beta_of_tau, 1.0, steps=16).t - math.sinh(1))
    assert 14 < e8 / e16 < 18


def test_rk4_rejects_superluminal_samples():
    with pytest.raises(ValueError):
        rel.integrate_worldline(np.zeros(3), lambda s: np.array([s, 0.0, 0.0]), 2.0, steps=4)
    with pytest.raises(ValueError):
        rel.integrate_worldline(np.zeros(3), lambda s: np.zeros(3), 1.0, steps=0)


def test_snapshot_mode():
    pos = np.array([0.0, 1.0, 2.0])
    beta = np.array([0.3, 0.0, -0.4])
    events = rel.worldline_events(pos, (3, 6), 5.0, 0.5, beta_const=beta)
    assert [e.tau for e in events] == [5.0, 5.5, 6.0, 6.5]
    for e in events:
        ref = rel.snapshot_event(pos, beta, e.tau)
        assert e.t == ref.t and np.array_equal(e.x, ref.x)
    g = rel.gamma(beta)
    assert events[0].t == pytest.approx(g * 5.0, rel=2 * EPS)
    np.testing.assert_allclose(events[0].x, pos + g * beta * 5.0, rtol=2 * EPS)
    rest = rel.worldline_events(pos, (1, 1), 2.0, 0.0)
    assert rest[0].t == 2.0 and np.array_equal(rest[0].x, pos)


def test_proper_acceleration_mode():
    a = np.array([0.0, 0.2, 0.0])
    events = rel.worldline_events(np.zeros(3), (0, 4), 0.0, 1.5, proper_acceleration=a)
    for e in events:
        ref = rel.constant_acceleration_event(np.zeros(3), a, e.tau)
        assert e.t == ref.t and np.array_equal(e.x, ref.x)
        assert np.array_equal(e.beta, ref.beta)


BETA_C = [0.3, -0.5, 0.6]


@pytest.mark.parametrize("keys", [[(4, BETA_C)], [(2, BETA_C), (9, BETA_C)]])
def test_keyframes_with_constant_beta_reproduce_snapshots(keys):
    pos = np.array([1.0, 0.0, -1.0])
    beta = np.array(keys[0][1])
    events = rel.worldline_events(pos, (1, 10), 0.3, 0.7, keyframes=keys)
    g = rel.gamma(beta)
    for e in events:
        ref = rel.snapshot_event(pos, beta, e.tau)
        # Sum of ≲ 12 per-segment increments, each a few ulps: (n + 2)·4 ulps of γτ.
        tol = 4 * (len(events) + 2) * EPS * g * e.tau
        assert abs(e.t - ref.t) <= tol
        np.testing.assert_allclose(e.x, ref.x, rtol=0, atol=tol)
        np.testing.assert_array_equal(e.beta, beta)
        # The camera is at rest at its own spatial origin in its comoving frame.
        out = rel.lorentz_boost(e.beta) @ (e.four_position() - np.concatenate(([0.0], pos)))
        np.testing.assert_allclose(out, [e.tau, 0, 0, 0], rtol=0, atol=tol + 16 * g * g * EPS)


def reference_by_pieces(key_frames, key_betas, f0, ct0, ct_per_frame, tau_end, steps):
    """Independent reference: RK4 on each smooth piece of the keyframed β(τ), summed."""
    key_frames = np.asarray(key_frames, dtype=float)
    key_betas = np.asarray(key_betas, dtype=float)

    def beta_of_tau(s: float) -> np.ndarray:
        f = f0 + (s - ct0) / ct_per_frame
        return np.array([np.interp(f, key_frames, key_betas[:, i]) for i in range(3)])

    knots = ct0 + (key_frames - f0) * ct_per_frame
    cuts = [0.0] + sorted(k for k in knots if 0.0 < k < tau_end) + [tau_end]
    t, x = 0.0, np.zeros(3)
    for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
        ev = rel.integrate_worldline(
            np.zeros(3), lambda s, lo=lo: beta_of_tau(lo + s), hi - lo, steps=steps
        )
        t, x = t + ev.t, x + ev.x
    return t, x


def test_keyframed_ramp_matches_rk4_reference():
    # A general (non-collinear) piecewise-linear β(τ), clamped before the first key and
    # after the last; the first key comes after frame 0, so β is held on [0, its τ].
    key_frames = [2, 5, 9]
    key_betas = [[0.1, 0.2, 0.0], [0.7, -0.4, 0.2], [-0.3, 0.5, -0.6]]
    f0, ct0, cpf = 0, 0.25, 0.3
    pos = np.array([0.5, 0.5, 0.5])
    events = rel.worldline_events(
        pos, (f0, 12), ct0, cpf, keyframes=list(zip(key_frames, key_betas, strict=True))
    )
    assert len(events) == 13
    for e in events[::3] + [events[-1]]:
        t_n, x_n = reference_by_pieces(key_frames, key_betas, f0, ct0, cpf, e.tau, 256)
        t_2n, x_2n = reference_by_pieces(key_frames, key_betas, f0, ct0, cpf, e.tau, 512)
        # Richardson: the 512-step error is ~|ref256 - ref512|/15; we allow the full
        # difference, plus rounding of the ~4000 summed terms.
        tol_t = abs(t_n - t_2n) + 64 * EPS * t_2n
        tol_x = np.abs(x_n - x_2n) + 64 * EPS * (1 + np.abs(x_2n))
        assert abs(e.t - t_2n) <= tol_t
        assert np.all(np.abs(e.x - pos - x_2n) <= tol_x)
        assert tol_t < 1e-9  # the check has teeth
    np.testing.assert_array_equal(events[-1].beta, key_betas[-1])
    np.testing.assert_array_equal(events[5].beta, key_betas[1])


def test_keyframed_reversal_through_rest_is_exact():
    # β(τ) = 0.9 (1 - 2τ) x̂ for τ in [0, 1] (keys at frames 0 and 10, 0.1 per frame):
    # t = (asin 0.9 - asin β)/1.8,  x = (sqrt(1-β²) - sqrt(0.19))/1.8.
    events = rel.worldline_events(
        np.zeros(3), (0, 10), 0.0, 0.1, keyframes=[(0, [0.9, 0, 0]), (10, [-0.9, 0, 0])]
    )
    for e in events:
        b = 0.9 * (1 - 2 * e.tau)
        t_ref = (math.asin(0.9) - math.asin(b)) / 1.8
        x_ref = (math.sqrt(1 - b * b) - math.sqrt(0.19)) / 1.8
        # 11 accumulated segments of a few ulps each; reference a few ulps too.
        assert e.t == pytest.approx(t_ref, abs=64 * EPS)
        assert e.x[0] == pytest.approx(x_ref, abs=64 * EPS)
        assert e.x[1] == 0.0 and e.x[2] == 0.0


def test_keyframed_ramp_to_near_light_speed_is_exact():
    # β = (b/2) τ x̂ on [0, 2], b = 1 - 1e-9: t = 2 asin(b)/b, x = 2 (1 - sqrt(1-b²))/b.
    b = 1.0 - 1e-9
    events = rel.worldline_events(
        np.zeros(3), (0, 1), 0.0, 2.0, keyframes=[(0, [0, 0, 0]), (1, [b, 0, 0])]
    )
    e = events[1]
    inv_g = math.sqrt((1 - b) * (1 + b))
    # atan2 vs asin of the same exact b: a few ulps (1/γ enters with a tiny weight).
    assert e.t == pytest.approx(2 * math.asin(b) / b, rel=8 * EPS)
    assert e.x[0] == pytest.approx(2 * (1 - inv_g) / b, rel=8 * EPS)


def test_keyframed_worldline_before_proper_time_zero():
    # ct0 < 0: frames before τ = 0 are reached by integrating backwards from the origin.
    # β(τ) = 0.5 (τ + 1) x̂ on [-1, 0]: t(-1) = -asin(0.5)/0.5 = -π/3,
    # x(-1) = -(1 - sqrt(0.75))/0.5.
    events = rel.worldline_events(
        np.zeros(3), (0, 10), -1.0, 0.1, keyframes=[(0, [0, 0, 0]), (10, [0.5, 0, 0])]
    )
    # 11 accumulated segments of a few ulps each.
    assert events[0].t == pytest.approx(-math.pi / 3, abs=64 * EPS)
    assert events[0].x[0] == pytest.approx(-(1 - math.sqrt(0.75)) / 0.5, abs=64 * EPS)
    assert events[-1].tau == 0.0
    assert events[-1].t == pytest.approx(0.0, abs=64 * EPS)
    assert events[-1].x[0] == pytest.approx(0.0, abs=64 * EPS)


def test_keyframes_with_zero_ct_per_frame_are_independent_snapshots():
    keys = [(1, [0.0, 0.0, 0.0]), (3, [0.0, 0.8, 0.0])]
    events = rel.worldline_events(np.zeros(3), (1, 4), 2.0, 0.0, keyframes=keys)
    betas = [[0, 0, 0], [0, 0.4, 0], [0, 0.8, 0], [0, 0.8, 0]]
    for e, beta in zip(events, betas, strict=True):
        ref = rel.snapshot_event(np.zeros(3), beta, 2.0)
        assert e.tau == 2.0 and e.t == ref.t
        np.testing.assert_array_equal(e.x, ref.x)


def test_worldline_events_rejects_bad_arguments():
    with pytest.raises(ValueError):
        rel.worldline_events(np.zeros(3), (5, 4), 0.0, 1.0)
    with pytest.raises(ValueError):
        rel.worldline_events(np.zeros(3), (1, 4), 0.0, -1.0)
    with pytest.raises(ValueError):
        rel.worldline_events(
            np.zeros(3), (1, 4), 0.0, 1.0, keyframes=[(1, [0.1, 0, 0])], beta_const=[0.1, 0, 0]
        )
    with pytest.raises(ValueError):
        rel.worldline_events(
            np.zeros(3), (1, 4), 0.0, 1.0, keyframes=[(1, [0.1, 0, 0]), (1, [0.2, 0, 0])]
        )
    with pytest.raises(ValueError):
        rel.worldline_events(np.zeros(3), (1, 4), 0.0, 1.0, keyframes=[(1, [1.0, 0, 0])])


def test_shutter_event_is_immutable():
    ev = rel.snapshot_event(np.zeros(3), [0.5, 0, 0], 1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        ev.t = 2.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        ev.x[0] = 1.0
    with pytest.raises(ValueError):
        rel.ShutterEvent(t=0.0, x=np.zeros(3), beta=[1.0, 0, 0], tau=0.0)
    np.testing.assert_array_equal(ev.four_position(), [ev.t, *ev.x])


# --------------------------------------------------------------------------- check_beta


@pytest.mark.parametrize(
    ("beta", "fragment"),
    [
        ([1.0, 0.0, 0.0], "|beta| = 1.0 must be below 1 (the speed of light)"),
        ([0.0, 1.5, 0.0], "|beta| = 1.5 must be below 1"),
        ([0.6, 0.8, 0.0], "must be below 1"),
        ([math.nan, 0.0, 0.0], "finite"),
        ([0.0, 0.0, math.inf], "finite"),
        ([0.5, 0.0], "3 numbers"),
        ("fast", "3 numbers"),
        ([[0.1, 0, 0]], "3 numbers"),
    ],
)
def test_check_beta_rejects(beta, fragment):
    with pytest.raises(UserError) as info:
        rel.check_beta(beta, key="motion.keyframes[2].beta")
    assert info.value.key == "motion.keyframes[2].beta"
    assert "motion.keyframes[2].beta" in str(info.value)
    assert fragment in str(info.value)


def test_check_beta_accepts_and_copies():
    src = [0.1, -0.2, 0.3]
    out = rel.check_beta(src)
    assert out.dtype == np.float64 and out.shape == (3,)
    np.testing.assert_array_equal(out, src)
    arr = np.array(src)
    assert rel.check_beta(arr) is not arr
    with pytest.raises(UserError, match="key 'motion.beta'"):
        rel.check_beta([2.0, 0.0, 0.0])


@pytest.mark.parametrize("b", [1e-8, 0.5, 0.99, 1 - 1e-9])
def test_per_ray_kernel_matches_the_vector_forms(b):
    """aberrate_doppler_ray (numba, per ray) agrees with aberrate/doppler_factor to a few ulp."""
    rng = np.random.default_rng(5)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    beta = b * np.array([0.6, 0.0, 0.8])
    args = rel.beta_kernel_args(beta)
    got = np.array([rel.aberrate_doppler_ray(*row, *args) for row in d])
    np.testing.assert_allclose(got[:, :3], rel.aberrate(d, beta), rtol=0, atol=4e-15)
    np.testing.assert_allclose(got[:, 3], rel.doppler_factor(d, beta), rtol=1e-14)


@njit(fastmath=FAST_MATH, error_model="numpy")
def _lane_aberrations(d, h, b, omb, inv_g, out):
    for i in range(d.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = rel.aberrate_doppler_lane(
            d[i, 0], d[i, 1], d[i, 2], h[0], h[1], h[2], b, omb, inv_g)


@pytest.mark.parametrize("b", [1e-8, 0.5, 0.99, 1 - 1e-9, 1 - 1e-12])
def test_the_lane_form_keeps_its_accuracy_under_reassociation(b):
    """aberrate_doppler_lane inlined into a loop compiled with the SIMD lanes' fast-math
    flags (reassociation included) and given 1 − b: aberrate_doppler_ray's values within
    the per-ray test's tolerances, on random directions and on directions within 1e-6 rad
    of u (where 1 − cos θ' is small) and of −u, up to b = 1 − 1e-12; inlined, without a
    call (a call would leave the lanes' loops scalar)."""
    rng = np.random.default_rng(6)
    h = np.array([0.6, 0.0, 0.8])
    near = h + rng.normal(scale=1e-6, size=(200, 3))
    d = np.concatenate([rng.normal(size=(500, 3)), near, -near])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    args = rel.beta_kernel_args(b * h)  # (the unit h and |β| as the kernels get them)
    want = np.array([rel.aberrate_doppler_ray(*row, *args) for row in d])
    got = np.empty((len(d), 4))
    _lane_aberrations(d, np.array(args[:3]), args[3], 1.0 - args[3], args[4], got)
    np.testing.assert_allclose(got[:, :3], want[:, :3], rtol=0, atol=4e-15)
    np.testing.assert_allclose(got[:, 3], want[:, 3], rtol=1e-14)
    ir = "\n".join(_lane_aberrations.inspect_llvm().values())
    assert not re.search(r"call [^\n]*aberrate", ir)
