"""End-to-end physics: physics.md's "Analytic validation cases", checked on rendered images.

Every test renders a small job through the real pipeline (job dict -> parse_job ->
build_scene -> prepare -> FrameRenderer -> Film.resolve; see render_helpers.py) and
compares what is visible in the image (alpha coverage, luminance, colour, spectral bands,
the "doppler" / "depth" / "lab_time" AOVs) with formulas written out here by hand from
physics.md, not with core's own functions.

Tolerances are derived, and the derivation sits next to each assert:
- pixel size -> angular resolution (a pixel of tangent-plane size p subtends at most p
  radians: the gnomonic projection only stretches distances);
- a pixel value is a mean over jittered samples, so it lies between the minimum and the
  maximum of the sampled quantity over the pixel (exact bounds, no statistics);
- Monte Carlo standard errors come from the film's per-pixel variance (``rel_error``),
  from the Bernoulli variance α(1-α)/n of a coverage fraction, or from the scatter of
  equivalent pixels; the bound is 5σ (6σ where σ itself is estimated from few samples).
The renders use fixed seeds, so a test is deterministic: it either passes or fails.

Each test notes a wrong physics it would catch (wrong sign of β, D instead of 1/D, D⁴
instead of D⁵, Galilean aberration, ...).

Coverage of the table "Analytic validation cases" of physics.md:

=============================  ==================================================================
row                            tests
=============================  ==================================================================
aberration                     test_aberration_of_a_small_sphere[0.5-60, 0.9-25.84] (centroid of
                               the coverage, and its solid angle ∝ 1/D²)
Doppler of a 550 nm line       test_doppler_shifted_line[ahead, behind] (spectral bands)
transverse Doppler             test_transverse_doppler (AOV at 90° in the camera and in the lab)
D = 1 ring                     test_doppler_ring (where the AOV crosses 1, row by row);
                               test_doppler_aov_map (the whole D map)
searchlight (bolometric 81)    test_bolometric_searchlight_ratio and test_line_flux_is_d4
                               (camera-frame line flux ∝ D⁴); test_searchlight_d5_ratio_is_exact
                               (spectral radiance ∝ D⁵, exact per pixel)
blackbody                      test_moving_blackbody_renders_as_hotter_blackbody[ahead, behind]
                               (sample for sample, same seed, against a rest render at D·T);
                               test_blackbody_colour_ahead_behind[ahead, behind] (10046 K / 3349 K
                               chromaticity and luminance from spectrum.planck)
Penrose–Terrell                test_penrose_terrell_outline (cone fit of the outline)
rod along the line of sight    not rendered: relray's scenes are static in the lab and its
                               outputs are lab distances (depth) and D; the rod's apparent length
                               is the camera-frame distance D·depth of its two ends, i.e. exactly
                               the product of two AOVs tested here (depth in
                               test_rest_camera_is_the_pinhole / test_constant_acceleration_job,
                               D in test_doppler_aov_map). Moving objects are not implemented yet.
Terrell cube                   test_terrell_cube (widths of the facing and trailing faces)
constant acceleration          test_constant_acceleration_job (job -> frame_events -> render)
=============================  ==================================================================

Integrator-level checks: test_rest_camera_is_the_pinhole, test_beta_zero_ignores_shutter_time,
test_white_furnace[rest, moving], test_uniform_sky_d5[doppler-off, doppler-on],
test_direct_lighting_of_a_floor[area, point, sun, area-moving] (analytic irradiance),
test_seeds_agree_within_error_bars, test_threads_do_not_change_the_image.

Regression: test_nee_shadow_ray_reaches_its_light (a shadow ray towards an emissive
triangle used to count the light itself as its occluder in large scenes: its length was
measured from the unlifted origin).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from render_helpers import (
    aberrate,
    base_job,
    camera_axes,
    directions,
    doppler,
    make_job,
    ndc,
    pixel_average,
    pixel_to_pixelcoords,
    rectangle_form_factor,
    render,
    zscore,
)

from relray.core.physics import spectrum
from relray.core.scene.motion import frame_events

B = 0.5
GAMMA = 1.0 / math.sqrt(1.0 - B * B)
SQRT3 = math.sqrt(3.0)
X_HAT = np.array([1.0, 0.0, 0.0])
EPS32 = float(np.finfo(np.float32).eps)
EPS64 = float(np.finfo(np.float64).eps)
CORNELL = Path(__file__).resolve().parents[1] / "presets" / "cornell.toml"


def grey(name: str = "grey", **kw) -> dict:
    return {"name": name, "base_color": [0.5, 0.5, 0.5], "roughness": 1.0, **kw}


def enclosing_emitter(material: str, radius: float = 20.0) -> dict:
    """A sphere around the camera (surfaces are two-sided: seen from inside)."""
    return {"shape": "sphere", "center": [0.0, 0.0, 0.0], "radius": radius,
            "subdivisions": 2, "material": material}


FAR_SPECK = {"shape": "sphere", "center": [0.0, -1000.0, 0.0], "radius": 0.01,
             "subdivisions": 0, "material": "grey"}
"""A tiny object far behind the camera (a job needs an object; no ray hits it)."""


def pixel_grid(width: int, height: int, fov: float):
    """Tangent-plane coordinates (x, y) of the pixel centres, (h, w) each."""
    rows, cols = np.mgrid[0:height, 0:width] + 0.5
    return ndc(cols, rows, width, height, fov)


def pixel_range(f, col: int, row: int, width: int, height: int, fov: float, axes,
                n: int = 33):
    """(min, max) of f(d_cam) over pixel (col, row), edges included (n x n grid).

    n is odd so the grid contains the pixel centre and its edges: for the smooth, monotone
    functions used here the extremes are at the corners, on the edges or at the centre.
    """
    u = np.linspace(0.0, 1.0, n)
    cc, rr = np.meshgrid(col + u, row + u)
    x, y = ndc(cc, rr, width, height, fov)
    v = f(directions(x, y, axes))
    return float(v.min()), float(v.max())


def angle_deg(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1),
                                 np.sum(u * v, axis=-1)))


# =========================================================================== β = 0: pinhole

TILT = np.array([-0.3, 1.0, -0.2])
"""Plane n·P = 5: y = 5 + 0.3x + 0.2z. Tilted in x and z so a mirrored image shows."""


def test_rest_camera_is_the_pinhole(tmp_path):
    """At β = 0 the depth AOV of a tilted plane is the hand-made pinhole's, pixel by pixel.

    Hand camera: right = forward × up, x = (2col/W - 1)·tan(fov/2)·W/H, y = (1 - 2row/H)·
    tan(fov/2), row 0 at the top. A flipped row or column order, a wrong aspect or fov, or
    a vertical (not horizontal) fov would change the depths by several % (the plane's tilt
    makes depth differ by 7 % between top and bottom), far above the tolerance.
    """
    W, H, fov, spp = 24, 16, 40.0, 16
    corners = [[x, 5.0 + 0.3 * x + 0.2 * z, z] for x, z in
               ((-10, -10), (10, -10), (10, 10), (-10, 10))]
    job = base_job(render={"width": W, "height": H, "spp": spp, "spectral": "rgb"},
                   camera={"fov": fov}, materials=[grey()],
                   objects=[{"shape": "quad", "corners": corners, "material": "grey"}])
    r = render(job, tmp_path)
    axes = camera_axes([0, 0, 0], [0, 1, 0], [0, 0, 1])

    # The camera's own directions equal the hand ones (float64: a few ulps).
    cols = np.array([0.0, 3.25, 12.0, 24.0])
    rows = np.array([0.0, 15.5, 8.0, 16.0])
    hand = directions(*ndc(cols, rows, W, H, fov), axes)
    np.testing.assert_allclose(r.camera.directions_cam(cols, rows), hand, rtol=0, atol=8 * EPS64)

    def depth(d):
        return 5.0 / (d @ TILT)

    mean, std = pixel_average(depth, W, H, fov, axes)
    got = r.image.aovs["depth"].astype(np.float64)
    # The AOV is the mean of spp i.i.d. uniform-jitter samples: standard error std/sqrt(spp)
    # (std over the pixel from the 16x16 sub-grid); plus float32 hit distances (Embree) and
    # storage, a few ulps: 1e-5 relative.
    tol = 5.0 * std / math.sqrt(spp) + 1e-5 * mean
    assert np.all(np.abs(got - mean) <= tol), np.max(np.abs(got - mean) / tol)
    assert np.all(r.alpha == 1.0)
    assert np.all(r.image.aovs["doppler"] == 1.0)  # β = 0: D = 1 exactly


def cornell_job(**sections) -> dict:
    """presets/cornell.toml as a dict, shrunk and with ``sections`` merged in."""
    data = tomllib.loads(CORNELL.read_text())
    data["output"] = {"formats": ["exr"], "aovs": ["depth", "doppler", "lab_time"]}
    data["render"].update({"width": 32, "height": 32, "spp": 8, "max_depth": 4,
                           "threads": 2})
    for name, value in sections.items():
        data.setdefault(name, {}).update(value)
    return data


def test_beta_zero_ignores_shutter_time(tmp_path):
    """At β = 0 the camera does not move: a snapshot at ct = 5 is bit-identical to ct = 0.

    (Only lab_time = t - depth moves, by exactly t = γ·ct = 5.) A shutter event that
    wrongly moved the camera (e.g. x = position + ct·(something non-zero)) or a sampler
    keyed on time would change the image.
    """
    r0 = render(cornell_job(motion={"beta": [0.0, 0.0, 0.0], "ct": 0.0}), tmp_path)
    r5 = render(cornell_job(motion={"beta": [0.0, 0.0, 0.0], "ct": 5.0}), tmp_path)
    assert r5.event.t == 5.0 and np.all(r5.event.x == r0.event.x)
    np.testing.assert_array_equal(r0.image.rgba, r5.image.rgba)
    np.testing.assert_array_equal(r0.image.rel_error, r5.image.rel_error)
    for k in ("depth", "doppler"):
        np.testing.assert_array_equal(r0.image.aovs[k], r5.image.aovs[k])
    hit = r0.alpha == 1.0
    assert hit.sum() > 100
    dt = r5.image.aovs["lab_time"][hit].astype(np.float64) - r0.image.aovs["lab_time"][hit]
    # lab_time values are below 10 in magnitude: float32 storage rounds each by <= 0.5 ulp(16)
    np.testing.assert_allclose(dt, 5.0, rtol=0, atol=2 * 16 * EPS32)


# =========================================================================== aberration

ABERRATION_CAMERA = {"position": [0.0, 0.0, 0.0], "look_at": [1.0, 1.0, 0.0],
                     "up": [0.0, 0.0, 1.0], "fov": 20.0}
"""Looks 45° from the motion (x̂): angles 10°..80° from x̂ are in view (±35.2°)."""


@pytest.mark.parametrize("b, printed", [(0.5, 60.0), (0.9, 25.84)])
def test_aberration_of_a_small_sphere(tmp_path, b, printed):
    """A small sphere at 90° to the motion in the lab is seen at asin(1/γ) from the motion.

    Camera at the origin at the shutter (snapshot, ct = 0), β = b x̂, sphere at (0, 10, 0)
    of radius 0.3 (1.72°). Its coverage (alpha) centroid, converted to a camera-frame
    direction, must lie at asin(1/γ) from x̂ (60° / 25.84°), and its solid angle must be
    the lab one divided by D² (D = γ: things at 90° in the lab shrink by 1/D).
    Wrong physics: no aberration 90°, Galilean aberration atan(1/b) = 63.4° / 48.0°, sign
    of β flipped 120° / 154°; D instead of 1/D for sizes changes the solid angle by D⁴.
    """
    W, H, spp, R, dist = 256, 64, 32, 0.3, 10.0
    fov = ABERRATION_CAMERA["fov"]
    job = base_job(render={"width": W, "height": H, "spp": spp, "spectral": "rgb"},
                   camera=ABERRATION_CAMERA, motion={"beta": [b, 0.0, 0.0], "ct": 0.0},
                   materials=[grey()],
                   objects=[{"shape": "sphere", "center": [0.0, dist, 0.0], "radius": R,
                             "material": "grey"}])
    r = render(job, tmp_path)
    g = 1.0 / math.sqrt(1.0 - b * b)
    expected = math.degrees(math.asin(1.0 / g))
    assert round(expected, 2) == printed

    axes = camera_axes(ABERRATION_CAMERA["position"], ABERRATION_CAMERA["look_at"],
                       ABERRATION_CAMERA["up"])
    x, y = pixel_grid(W, H, fov)
    a = r.alpha
    m = a.sum()
    cx, cy = (a * x).sum() / m, (a * y).sum() / m
    theta = float(angle_deg(directions(cx, cy, axes), X_HAT))

    p = 2.0 * math.tan(math.radians(fov) / 2.0) / H  # pixel size, tangent-plane units
    # (1) Discretisation: Σα_p x_p / Σα_p differs from the true centroid Σα_p x̄_p / Σα_p
    #     (x̄_p: centroid of the covered part of pixel p) by a weighted mean of
    #     |x_p - x̄_p| <= p/2 per axis, so by <= p/√2 in the plane, hence in angle.
    # (2) Monte Carlo: α_p is the mean of spp Bernoulli hits, var α_p(1-α_p)/spp;
    #     linearised, var(cx) = Σ (x_p - cx)² var(α_p) / m².
    var_a = a * (1.0 - a) / spp
    sigma = math.sqrt((((x - cx) ** 2 + (y - cy) ** 2) * var_a).sum()) / m
    # (3) Bias of the centroid of a disc of angular radius ρ vs its centre direction: the
    #     tangent-plane projection and the Penrose–Terrell shift are both O(ρ²) (0.22ρ²
    #     and 0.41ρ² here); ρ² with ρ = the lab radius (larger than the camera one) bounds
    #     them.
    rho = math.asin(R / dist)
    tol = math.degrees(p / math.sqrt(2.0) + 5.0 * sigma + rho**2)
    assert abs(theta - expected) <= tol, (theta, expected, tol)
    galilean = math.degrees(math.atan(1.0 / b))  # 63.4° / 48.0°
    assert abs(galilean - expected) > 10.0 * tol  # the test can tell them apart

    # Solid angle: Ω_cam = Ω_lab / D², D = γ(1 + β·ŷ) = γ at the sphere's lab direction.
    omega_p = p * p / (1.0 + x * x + y * y) ** 1.5  # pixel solid angle at its centre
    omega = (a * omega_p).sum()
    omega_lab = 2.0 * math.pi * (1.0 - math.cos(rho))
    expected_omega = omega_lab / g**2
    sigma_omega = math.sqrt((omega_p**2 * var_a).sum())
    # relative error budget: pixel solid angle taken at the pixel centre (density varies
    # by <= 3r/(1+r²)·p/2 <= 0.4 % across half a pixel, only edge pixels see it: 0.4 %);
    # 1/D² varies over the disc, second order: 3 b² ρ²; inscribed icosphere (level 5,
    # edges ≈ 2°): radius short by <= 1 - cos 1° = 1.5e-4, area by 3e-4.
    rel = 0.004 + 3.0 * b * b * rho**2 + 3e-4
    assert abs(omega - expected_omega) <= 5.0 * sigma_omega + rel * expected_omega, (
        omega / expected_omega)


# =========================================================================== Doppler: AOV map


@pytest.fixture(scope="module")
def aov_render(tmp_path_factory):
    """β = 0.5 x̂, camera looking along +ŷ (90° to the motion), wide horizontal view.

    W, H odd so the centre pixel's centre is the optical axis; horizontal half-angle 34.6°.
    """
    job = base_job(render={"width": 129, "height": 33, "spp": 16, "spectral": "rgb"},
                   camera={"fov": 20.0}, motion={"beta": [B, 0.0, 0.0]},
                   materials=[grey()], objects=[FAR_SPECK])
    return render(job, tmp_path_factory.mktemp("aov"))


AOV_AXES = camera_axes([0, 0, 0], [0, 1, 0], [0, 0, 1])


def _d_of(beta):
    return lambda d: doppler(d, beta)


def test_doppler_aov_map(aov_render):
    """The doppler AOV equals the pixel mean of D = 1/(γ(1 - β·d')) everywhere.

    The AOV is the mean of D over spp i.i.d. uniform jitter positions, so its standard
    error is std_pixel(D)/sqrt(spp) (std from the 16 x 16 sub-grid). 5σ; 4257 pixels of
    lighter-than-Gaussian tails (a mean of bounded uniforms). Float32 storage: 1 ulp.
    Catches D vs 1/D, the sign of β, γ(1 + β·d') (lab formula on camera directions).
    """
    r = aov_render
    W, H, spp = 129, 33, 16
    mean, std = pixel_average(_d_of([B, 0, 0]), W, H, 20.0, AOV_AXES)
    got = r.image.aovs["doppler"].astype(np.float64)
    tol = 5.0 * std / math.sqrt(spp) + 2.0 * EPS32 * mean
    assert np.all(np.abs(got - mean) <= tol), np.max(np.abs(got - mean) / tol)


def test_transverse_doppler(aov_render):
    """At 90° in the camera frame D = 1/γ = 0.866; at 90° in the lab D = γ = 1.155.

    The centre pixel looks along ŷ ⊥ β (camera frame). The lab direction ŷ is seen (hand
    aberration, inverted numerically) at d' = (β, 1/γ, 0), 30° right of the axis. A pixel
    value is a mean over the pixel, so it lies in [min D, max D] over the pixel, and so
    does the exact D at the point inside it: |AOV - D| <= max - min (exact bound).
    """
    r = aov_render
    W, H, fov = 129, 33, 20.0
    D = r.image.aovs["doppler"].astype(np.float64)
    f = _d_of([B, 0, 0])

    lo, hi = pixel_range(f, 64, 16, W, H, fov, AOV_AXES)
    assert lo <= 1.0 / GAMMA <= hi and hi - lo < 0.01
    assert abs(D[16, 64] - 1.0 / GAMMA) <= hi - lo, D[16, 64]
    assert round(1.0 / GAMMA, 3) == 0.866

    d_cam = np.array([B, 1.0 / GAMMA, 0.0])
    np.testing.assert_allclose(aberrate(d_cam, [B, 0, 0]), [0.0, 1.0, 0.0], atol=1e-15)
    col, row = pixel_to_pixelcoords(d_cam[0] / d_cam[1], 0.0, W, H, fov)
    c, rw = int(col), int(row)
    lo, hi = pixel_range(f, c, rw, W, H, fov, AOV_AXES)
    assert lo <= GAMMA <= hi and hi - lo < 0.02
    assert abs(D[rw, c] - GAMMA) <= hi - lo, (D[rw, c], GAMMA)
    assert round(GAMMA, 3) == 1.155


def test_doppler_ring(aov_render):
    """The doppler AOV crosses 1 on the cone cos θ' = β/(1 + sqrt(1-β²)): 74.46° from β̂.

    The ring is 15.5° right of the optical axis and crosses every row. Per row: the sign
    change of AOV - 1 between adjacent pixels, linearly interpolated, converted to a
    camera-frame direction, compared with 74.46°. Error budget in D (then divided by the
    slope |dD/dθ| between the two pixel centres): pixel mean vs centre value, linear
    interpolation (|second difference|/8) and 5 standard errors of each AOV value.
    Wrong sign of β puts the ring at 105.5°; γ(1 + β·d') instead of 1/(γ(1 - β·d')) too.
    """
    r = aov_render
    W, H, fov, spp = 129, 33, 20.0, 16
    expected = math.degrees(math.acos(B / (1.0 + math.sqrt(1.0 - B * B))))
    assert round(expected, 2) == 74.46
    f = _d_of([B, 0, 0])
    mean, std = pixel_average(f, W, H, fov, AOV_AXES)
    x, y = pixel_grid(W, H, fov)
    dirs = directions(x, y, AOV_AXES)
    centre = f(dirs)
    theta_c = angle_deg(dirs, X_HAT)
    D = r.image.aovs["doppler"].astype(np.float64)
    for row in range(H):
        s = D[row] - 1.0
        idx = np.flatnonzero(np.sign(s[:-1]) != np.sign(s[1:]))
        assert len(idx) == 1, (row, idx)
        c = int(idx[0])
        assert s[c] < 0.0 < s[c + 1]  # D > 1 towards the motion (right), blueshift
        frac = s[c] / (s[c] - s[c + 1])
        xr, yr = ndc(c + 0.5 + frac, row + 0.5, W, H, fov)
        theta = float(angle_deg(directions(xr, yr, AOV_AXES), X_HAT))
        cs = slice(c - 1, c + 3)
        bias = np.max(np.abs(mean[row, cs] - centre[row, cs]))
        interp = np.max(np.abs(np.diff(centre[row, cs], 2))) / 8.0
        noise = 5.0 * np.max(std[row, c:c + 2]) / math.sqrt(spp)
        slope = abs(centre[row, c + 1] - centre[row, c]) / abs(theta_c[row, c + 1]
                                                               - theta_c[row, c])
        tol = (bias + interp + noise) / slope  # degrees
        assert abs(theta - expected) <= tol, (row, theta, expected, tol)


# =========================================================================== Doppler: lines

LINE_SIGMA = 2.0
BANDS = [500.0, 600.0, 2.0]


@pytest.fixture(scope="module")
def line_renders(tmp_path_factory):
    """Camera inside a sphere emitting a Gaussian line, looking ahead / behind, β = 0.5 x̂.

    The lab line is placed where the camera sees it at 550 nm: 550·√3 nm ahead (D = √3),
    550/√3 nm behind (D = 1/√3). Narrow view (2°) so D is nearly constant over the image.
    """
    out = {}
    for name, look, lam_lab in (("ahead", [1.0, 0.0, 0.0], 550.0 * SQRT3),
                                ("behind", [-1.0, 0.0, 0.0], 550.0 / SQRT3)):
        job = base_job(render={"width": 8, "height": 8, "spp": 64},
                       output={"formats": ["spectral-exr"], "spectral_bands": BANDS},
                       camera={"look_at": look, "up": [0.0, 0.0, 1.0], "fov": 2.0},
                       motion={"beta": [B, 0.0, 0.0]},
                       materials=[{"name": "line", "emission_line": [lam_lab, LINE_SIGMA],
                                   "emission_strength": 1.0}],
                       objects=[enclosing_emitter("line")])
        r = render(job, tmp_path_factory.mktemp(name))
        mean4, _ = pixel_average(lambda d: doppler(d, [B, 0, 0]) ** 4, 8, 8, 2.0,
                                 camera_axes([0, 0, 0], look, [0, 0, 1]))
        mean3, _ = pixel_average(lambda d: doppler(d, [B, 0, 0]) ** 3, 8, 8, 2.0,
                                 camera_axes([0, 0, 0], look, [0, 0, 1]))
        out[name] = (r, lam_lab, mean3, mean4)
    return out


@pytest.mark.parametrize("name", ["ahead", "behind"])
def test_doppler_shifted_line(line_renders, name):
    """A lab line at 952.6 nm seen ahead / 317.5 nm seen behind appears at 550 nm.

    (physics.md's row read backwards: a 550 nm lab line would appear at 317.5 / 952.6 nm,
    outside the sensor.) Measured: the centroid of the pixel-summed band spectrum.
    Expected: a sample of Doppler factor D sees the line at λ_lab/D with flux weight D⁴,
    so the centroid is λ_lab Σ<D³> / Σ<D⁴> (pixel means by quadrature; = 550 nm to 0.2 nm).
    Tolerance: each band's own centroid lies within ±step/2 = 1 nm of its centre (exact
    bound; the line is 14σ inside the band range), plus 5 standard errors from the
    pixel-to-pixel scatter (ratio estimator, linearised).
    Wrong physics: no Doppler, D instead of 1/D, or the Galilean factor (1 ± β) put the
    line outside 500–600 nm: no line at all.
    """
    r, lam_lab, mean3, mean4 = line_renders[name]
    S = r.image.spectral.astype(np.float64)  # (h, w, nb)
    lam = r.image.band_centers_nm
    A = (S * lam).sum(axis=2).ravel()
    Bp = S.sum(axis=2).ravel()
    centroid = A.sum() / Bp.sum()
    expected = lam_lab * mean3.sum() / mean4.sum()
    assert abs(expected - 550.0) < 0.2
    assert (round(550.0 * SQRT3, 1), round(550.0 / SQRT3, 1)) == (952.6, 317.5)  # the table
    n = len(A)
    sigma = math.sqrt(n) * np.std(A - centroid * Bp, ddof=1) / Bp.sum()
    tol = BANDS[2] / 2.0 + 5.0 * sigma
    assert abs(centroid - expected) <= tol, (centroid, expected, tol)
    # Width: the camera sees σ_lab/D (1.15 nm ahead, 3.46 nm behind). The table's linear
    # interpolation on the log grid (node spacing h = λ_lab(e^{1/INV_DLOG} - 1)) widens the
    # lab variance by h²/6 (spectrum.gaussian_line), and 2 nm bands add step²/12 (Sheppard;
    # its residual for σ >= step/2 is < e^{-2π²σ²/step²} < 2e-3 of the variance).
    D = lam_lab / 550.0
    h = lam_lab * math.expm1(1.0 / spectrum.INV_DLOG)
    var_expected = (LINE_SIGMA**2 + h * h / 6.0) / D**2 + BANDS[2] ** 2 / 12.0
    A2 = (S * (lam - centroid) ** 2).sum(axis=2).ravel()
    var = A2.sum() / Bp.sum()
    sigma_var = math.sqrt(n) * np.std(A2 - var * Bp, ddof=1) / Bp.sum()  # as for the centroid
    assert abs(var - var_expected) <= 5.0 * sigma_var + 2e-3 * var_expected, (var, var_expected)


def _line_flux(r):
    """Per-pixel camera-frame band-integrated radiance ∫ L_cam dλ (flattened)."""
    return r.image.spectral.astype(np.float64).sum(axis=2).ravel() * BANDS[2]


@pytest.mark.parametrize("name", ["ahead", "behind"])
def test_line_flux_is_d4(line_renders, name):
    """∫ L_cam dλ = ∫ D⁵ L_lab(Dλ) dλ = D⁴ ∫ L_lab: the bolometric searchlight law.

    The line has unit area (strength 1), so the mean band-integrated radiance must equal
    the image mean of <D⁴> (9 ahead, 1/9 behind). 5 standard errors of the pixel mean
    (pixel scatter; the true pixel values differ by < 1e-3, which only inflates σ).
    D⁵ instead of D⁴ (i.e. D⁶ weighting) or the seed's η would miss by a factor √3 or more.
    """
    r, _, _, mean4 = line_renders[name]
    F = _line_flux(r)
    expected = mean4.ravel()
    sigma = np.std(F - expected, ddof=1) / math.sqrt(len(F))
    assert abs(F.mean() - expected.mean()) <= 5.0 * sigma, (F.mean(), expected.mean(), sigma)
    assert expected.mean() == pytest.approx(9.0 if name == "ahead" else 1.0 / 9.0, rel=2e-3)


def test_bolometric_searchlight_ratio(line_renders):
    """Ahead / behind bolometric ratio ((1+β)/(1-β))⁴ = 81 at β = 0.5.

    Measured on the two line renders (flux ahead / flux behind); the expected ratio uses
    each image's <D⁴> (81 × (1 ± 2e-4)); σ of the ratio from the two relative standard
    errors in quadrature. D⁵ law mistaken for D⁴ per unit frequency (i.e. D³ bolometric)
    gives 27, D⁵ bolometric gives 243.
    """
    ra, _, _, m4a = line_renders["ahead"]
    rb, _, _, m4b = line_renders["behind"]
    Fa, Fb = _line_flux(ra), _line_flux(rb)
    ratio = Fa.mean() / Fb.mean()
    expected = m4a.mean() / m4b.mean()
    assert expected == pytest.approx(((1 + B) / (1 - B)) ** 4, rel=1e-3)
    assert round(((1 + B) / (1 - B)) ** 4) == 81
    rel_a = np.std(Fa, ddof=1) / math.sqrt(len(Fa)) / Fa.mean()
    rel_b = np.std(Fb, ddof=1) / math.sqrt(len(Fb)) / Fb.mean()
    assert abs(ratio / expected - 1.0) <= 5.0 * math.hypot(rel_a, rel_b), ratio


# =========================================================================== searchlight


def test_searchlight_d5_ratio_is_exact(tmp_path):
    """With doppler = false and searchlight = true only the weight D⁵ differs.

    Camera inside a white (D65) emitter, looking along +x, rendered with β = +0.5 x̂
    (looking ahead) and β = -0.5 x̂ (looking behind). Same seed and camera -> the same
    jitter and hero wavelengths per sample, and (doppler off, uniform emitter) the same
    L_lab; so each sample's luminance ratio is (D₊(d')/D₋(d'))⁵ exactly, and a pixel's
    ratio of means lies between the min and max of that ratio over the pixel (all
    sample luminances are >= 0). On the axis: D₊ = √3, D₋ = 1/√3, ratio ((1+β)/(1-β))⁵ =
    243. D⁴ instead of D⁵ would give 81 on the axis, no searchlight 1.
    """
    W, H, fov = 9, 9, 10.0
    renders = {}
    for s in (1.0, -1.0):
        job = base_job(render={"width": W, "height": H, "spp": 8, "doppler": False,
                               "searchlight": True},
                       camera={"look_at": [1.0, 0.0, 0.0], "fov": fov},
                       motion={"beta": [s * B, 0.0, 0.0]},
                       materials=[{"name": "white", "emission": [1.0, 1.0, 1.0],
                                   "emission_strength": 1.0}],
                       objects=[enclosing_emitter("white")])
        renders[s] = render(job, tmp_path)
    ratio = renders[1.0].luminance / renders[-1.0].luminance
    axes = camera_axes([0, 0, 0], [1, 0, 0], [0, 0, 1])

    def f(d):
        return (doppler(d, [B, 0, 0]) / doppler(d, [-B, 0, 0])) ** 5

    for row in range(H):
        for col in range(W):
            lo, hi = pixel_range(f, col, row, W, H, fov, axes)
            # float32 radiance and RGB storage: a few ulps each, 1e-6 relative
            assert lo * (1 - 1e-6) <= ratio[row, col] <= hi * (1 + 1e-6), (row, col)
    lo, hi = pixel_range(f, 4, 4, W, H, fov, axes)
    # the axis is the centre pixel's centre, where the ratio is largest: a few ulps slack
    assert lo <= ((1 + B) / (1 - B)) ** 5 <= hi * (1 + 8 * EPS64)
    assert ((1 + B) / (1 - B)) ** 5 == 243.0


# =========================================================================== blackbody

T_SUN = 5800.0


def y_planck(T: float) -> float:
    """Rest-frame luminance of Planck's B_λ(·, T) (the blackbody table's normaliser)."""
    return float(spectrum.y_of(spectrum.planck(spectrum.grid_nm(), T)))


@pytest.fixture(scope="module")
def blackbody_renders(tmp_path_factory):
    """5800 K emitter around a camera at β = 0.5 looking ahead / behind, plus rest renders.

    The rest render has T = D₀·5800 K and the strength Y(D₀T)/Y(T) that makes
    s·B(λ, D₀T)/Y(D₀T) equal to B(λ, D₀T)/Y(T) (the blackbody table has Y = 1 at rest).
    Very narrow view (0.5°): D varies by < 2e-5 over the image.
    """
    out = {}
    W = H = 8
    fov = 0.5
    for name, look, D0 in (("ahead", [1.0, 0.0, 0.0], SQRT3),
                           ("behind", [-1.0, 0.0, 0.0], 1.0 / SQRT3)):
        tmp = tmp_path_factory.mktemp(name)
        common = {"render": {"width": W, "height": H, "spp": 64},
                  "camera": {"look_at": look, "fov": fov},
                  "objects": [enclosing_emitter("bb")]}
        moving = render(base_job(**common, motion={"beta": [B, 0.0, 0.0]},
                                 materials=[{"name": "bb", "emission_blackbody": T_SUN,
                                             "emission_strength": 1.0}]), tmp)
        strength = y_planck(D0 * T_SUN) / y_planck(T_SUN)
        rest = render(base_job(**common, materials=[{"name": "bb",
                                                     "emission_blackbody": D0 * T_SUN,
                                                     "emission_strength": strength}]), tmp)
        Dmin, Dmax = pixel_range(lambda d: doppler(d, [B, 0, 0]), 0, 0, W, H, fov,
                                 camera_axes([0, 0, 0], look, [0, 0, 1]))
        # the whole image: corners are the farthest from the axis, the centre the nearest
        Dc = doppler(np.array(look, float), [B, 0, 0])
        out[name] = (moving, rest, D0, min(Dmin, Dc), max(Dmax, Dc))
    return out


@pytest.mark.parametrize("name", ["ahead", "behind"])
def test_moving_blackbody_renders_as_hotter_blackbody(blackbody_renders, name):
    """D⁵ B_λ(Dλ, T) = B_λ(λ, D·T): the moving render equals a rest render at D·T.

    Same seed -> same jitter and hero wavelengths, so sample by sample the two renders
    differ only by B(λ, D_s T)/B(λ, D₀T) where D_s is the sample's D (D₀ on the axis).
    XYZ sample values are sums of non-negative lane terms, so each pixel's XYZ ratio lies
    within the extreme values of that ratio over λ in 360–830 nm and D over the image,
    plus table interpolation (linear on the log grid, measured here on the two tables)
    and float32 (100 ulps). No statistics: D⁴ instead of D⁵ is off by a factor D.
    """
    moving, rest, D0, Dmin, Dmax = blackbody_renders[name]
    lam = spectrum.sensor_nm()
    ratios = [spectrum.planck(lam, D * T_SUN) / spectrum.planck(lam, D0 * T_SUN)
              for D in (Dmin, Dmax)]
    spread = max(float(np.max(np.abs(q - 1.0))) for q in ratios)
    # table-level check of the identity on the sensor grid: what the kernels look up
    y_t, y_dt = y_planck(T_SUN), y_planck(D0 * T_SUN)
    lhs = D0**5 * spectrum.lookup(spectrum.blackbody(T_SUN), D0 * lam) * y_t
    rhs = spectrum.lookup(spectrum.blackbody(D0 * T_SUN), lam) * y_dt
    interp = float(np.max(np.abs(lhs / rhs - 1.0)))
    assert interp < 1e-4
    rtol = spread + interp + 100 * EPS32
    np.testing.assert_allclose(moving.sensor, rest.sensor, rtol=rtol, atol=0)


UV_IR_BANDS = [200.0, 5000.0, 200.0]


@pytest.mark.parametrize("look, D0", [([1.0, 0.0, 0.0], SQRT3), ([-1.0, 0.0, 0.0], 1 / SQRT3)])
def test_uv_and_ir_bands_of_a_moving_blackbody(tmp_path, look, D0):
    """Spectral-exr bands from 100 nm to 5.1 µm (camera frame), far outside the sensor: a
    5800 K emitter around a camera at β = 0.5 is, band by band, the mean over the band of
    D⁵ L_lab(Dλ) (= B(λ, D·T) up to the table's normalisation; physics.md, "Skies").

    Expected: the blackbody table looked up at Dλ, times D⁵, averaged over each band by
    a 400-point midpoint rule (D on the axis; it varies by < 2e-5 over the 0.5° view).
    Tolerance: 5 standard errors of the pixel mean (pixel-to-pixel scatter of 64 pixels)
    plus 1e-3 for the quadrature and the table's interpolation. Without UV/IR bands in
    the sampler every band outside 360–830 nm would be 0; without the Doppler shift the
    peak would sit at 500 nm instead of 500/D.
    """
    W = H = 8
    job = base_job(render={"width": W, "height": H, "spp": 64},
                   output={"formats": ["spectral-exr"], "spectral_bands": UV_IR_BANDS},
                   camera={"look_at": look, "fov": 0.5},
                   motion={"beta": [B, 0.0, 0.0]},
                   materials=[{"name": "bb", "emission_blackbody": T_SUN,
                               "emission_strength": 1.0}],
                   objects=[enclosing_emitter("bb")])
    r = render(job, tmp_path)
    S = r.image.spectral.astype(np.float64).reshape(W * H, -1)
    centres = r.image.band_centers_nm
    start, stop, step = UV_IR_BANDS
    assert len(centres) == 25 and centres[0] == start and centres[-1] == stop
    table = spectrum.blackbody(T_SUN)
    k = (np.arange(400) + 0.5) / 400.0
    expected = np.array([np.mean(D0**5 * spectrum.lookup(table, D0 * (c + (k - 0.5) * step)))
                         for c in centres])
    mean = S.mean(axis=0)
    sem = S.std(axis=0, ddof=1) / math.sqrt(W * H)
    assert np.all(expected[[0, -1]] > 0.0)  # both ends carry light to measure
    tol = 5.0 * sem + 1e-3 * expected
    assert np.all(np.abs(mean - expected) <= tol), np.c_[centres, mean, expected, tol]


@pytest.mark.parametrize("name, printed", [("ahead", 10046), ("behind", 3349)])
def test_blackbody_colour_ahead_behind(blackbody_renders, name, printed):
    """5800 K seen ahead / behind at β = 0.5 has the colour of a 10046 K / 3349 K blackbody.

    Rendered chromaticity xy (image mean of XYZ) against spectrum.blackbody_rgb(D₀T), and
    luminance against Y(D₀T)/Y(T) (Planck integrated here). Tolerance: 5 standard errors
    from the pixel scatter (all pixels see the same thing: D varies by < 2e-5), plus the
    change of xy and Y over that D range. Catches: no Doppler (5800 K colour, Δxy ≈ 0.05),
    D ↔ 1/D (colours swapped), and (luminance) D⁴ vs D⁵ — xy alone cannot, because
    D⁴ B(Dλ, T) = B(λ, DT)/D has the same chromaticity.
    """
    moving, _, D0, Dmin, Dmax = blackbody_renders[name]
    assert round(D0 * T_SUN) == printed
    M_inv = np.linalg.inv(moving.to_rgb)

    def xy_of(xyz):
        return xyz[:2] / xyz.sum()

    def expected_xyz(T):
        return M_inv @ spectrum.blackbody_rgb(T) * y_planck(T) / y_planck(T_SUN)

    XYZ = moving.sensor.reshape(-1, 3)
    n = len(XYZ)
    m = XYZ.mean(axis=0)
    xy = xy_of(m)
    S = XYZ.sum(axis=1)
    sig_xy = np.array([np.std(XYZ[:, k] - xy[k] * S, ddof=1) for k in (0, 1)]) / (
        math.sqrt(n) * S.mean())
    exp0 = expected_xyz(D0 * T_SUN)
    drift = max(np.max(np.abs(xy_of(expected_xyz(D * T_SUN)) - xy_of(exp0)))
                for D in (Dmin, Dmax))
    assert np.all(np.abs(xy - xy_of(exp0)) <= 5.0 * sig_xy + drift), (xy, xy_of(exp0), sig_xy)
    rest_xy = xy_of(M_inv @ spectrum.blackbody_rgb(T_SUN))
    assert np.max(np.abs(rest_xy - xy_of(exp0))) > 20 * np.max(5.0 * sig_xy + drift)

    sig_y = np.std(XYZ[:, 1], ddof=1) / math.sqrt(n)
    y_drift = max(abs(expected_xyz(D * T_SUN)[1] - exp0[1]) for D in (Dmin, Dmax))
    assert abs(m[1] - exp0[1]) <= 5.0 * sig_y + y_drift, (m[1], exp0[1])


# =========================================================================== Penrose–Terrell


def test_penrose_terrell_outline(tmp_path):
    """A sphere of 10° angular radius at 90° (lab) looks like a circle of 8.682° at 60.378°.

    Sphere of radius 10·sin 10° at (0, 10, 0), β = 0.5 x̂, camera aimed at 60.378° from x̂.
    Outline: the α = ½ contour (linear interpolation between neighbouring pixels on either
    side). Fit: the outline is a cone about a unit axis c with half-angle ρ: d·c = cos ρ,
    linear least squares for v = c/cos ρ. Compare angle(c, x̂) with 60.378° and ρ with
    8.682° (the aberrated lab edges at 80° and 100°; rounded to the printed digits).
    Tolerance: half a pixel (each outline point lies on the segment between a pixel centre
    inside and one outside the edge, and its error alternates in sign with the edge's
    sub-pixel phase, so the fitted circle is biased by far less than a pixel) plus 5
    standard errors of the fit from the residual scatter. The naive centre (60°) is 2.7
    tolerances away; Galilean or wrong-sign aberration much further.
    """
    W = H = 160
    fov, spp = 22.0, 16
    R = 10.0 * math.sin(math.radians(10.0))

    def aberr_deg(theta_lab):
        c = math.cos(math.radians(theta_lab))
        return math.degrees(math.acos((c + B) / (1.0 + B * c)))

    lo, hi = aberr_deg(80.0), aberr_deg(100.0)
    centre, radius = 0.5 * (lo + hi), 0.5 * (hi - lo)
    assert (round(centre, 3), round(radius, 3)) == (60.378, 8.682)
    look = [math.cos(math.radians(centre)), math.sin(math.radians(centre)), 0.0]
    job = base_job(render={"width": W, "height": H, "spp": spp, "spectral": "rgb"},
                   camera={"look_at": look, "fov": fov}, motion={"beta": [B, 0.0, 0.0]},
                   materials=[grey()],
                   objects=[{"shape": "sphere", "center": [0.0, 10.0, 0.0], "radius": R,
                             "subdivisions": 6, "material": "grey"}])
    r = render(job, tmp_path)
    # α is a multiple of 1/spp, so α = ½ exactly is common: such a pixel's centre is on
    # the edge (for a locally straight edge), and the +1e-9 puts the point there.
    s = r.alpha - 0.5 + 1e-9
    cols, rows = [], []
    for axis in (0, 1):
        a0 = s[:, :-1] if axis == 1 else s[:-1, :]
        a1 = s[:, 1:] if axis == 1 else s[1:, :]
        ii, jj = np.nonzero(a0 * a1 < 0.0)
        frac = a0[ii, jj] / (a0[ii, jj] - a1[ii, jj])
        cols.append(jj + 0.5 + (frac if axis == 1 else 0.0))
        rows.append(ii + 0.5 + (frac if axis == 0 else 0.0))
    x, y = ndc(np.concatenate(cols), np.concatenate(rows), W, H, fov)
    d = directions(x, y, camera_axes([0, 0, 0], look, [0, 0, 1]))
    v = np.linalg.lstsq(d, np.ones(len(d)), rcond=None)[0]
    c_axis = v / np.linalg.norm(v)
    rho = math.degrees(math.acos(1.0 / np.linalg.norm(v)))
    got_centre = float(angle_deg(c_axis, X_HAT))
    resid = angle_deg(d, c_axis) - rho
    n = len(d)
    assert n > 6 * radius / (fov / H)  # ≈ 8 r (r in pixels): the whole outline was found
    p = math.degrees(2.0 * math.tan(math.radians(fov) / 2.0) / H)  # >= pixel's angle
    tol_r = 0.5 * p + 5.0 * np.std(resid) / math.sqrt(n)
    tol_c = 0.5 * p + 5.0 * np.std(resid) * math.sqrt(2.0 / n)
    assert abs(rho - radius) <= tol_r, (rho, radius, tol_r)
    assert abs(got_centre - centre) <= tol_c, (got_centre, centre, tol_c)
    assert abs(c_axis[2]) <= math.radians(tol_c)  # in the plane of β and the sphere
    assert abs(60.0 - centre) > 2.5 * tol_c


# =========================================================================== Terrell cube


def test_terrell_cube(tmp_path):
    """A distant cube seen at 90° in the camera frame: facing side a/γ, trailing side βa.

    Camera at rest in S' moving with β = 0.5 x̂ past a static cube (edge a = 1) at lab
    distance L = 200 in the lab direction (-β, 1/γ, 0), i.e. seen along ŷ in the camera
    frame. In S' the cube moves along -x̂ at distance L' = D·L = L/γ (camera-frame distance
    of an emission event = D × lab distance); Terrell: its facing (-y) face looks a/γ wide
    and its trailing (+x) face βa wide, i.e. angular widths a/(γL') and βa/L'.
    Rendered: the two faces are separate emitters, red and green (rgb mode: a sample is
    exactly (1,0,0), (0,1,0) or 0), and on the image row through the cube's centre the sum
    of R (G) over pixels is the face's width in pixels. Expected widths: the three vertical
    edges at mid-height, projected by hand (lab direction -> inverse aberration).
    Tolerance: Bernoulli coverage noise Σ α(1-α)/spp at the edges (5σ) plus the edges'
    curvature over the row's height (measured). The Terrell limit holds up to O(a/L).
    Without aberration (the lab view) the widths would be a/(γL) and βa/L: the same ratio
    βγ but γ times smaller; with the sign of β flipped the cube is aberrated out of this
    0.7°-wide view (both sums 0).
    """
    a, L = 1.0, 200.0
    W, H, spp = 256, 5, 16
    p = 5e-5  # pixel size in tangent units
    fov = 2.0 * math.degrees(math.atan(p * H / 2.0))
    beta = np.array([B, 0.0, 0.0])
    C = L * np.array([-B, 1.0 / GAMMA, 0.0])
    xm, xp = C[0] - a / 2, C[0] + a / 2
    ym, yp = C[1] - a / 2, C[1] + a / 2
    zm, zp = -a / 2, a / 2
    facing = [[xm, ym, zm], [xp, ym, zm], [xp, ym, zp], [xm, ym, zp]]
    trailing = [[xp, ym, zm], [xp, yp, zm], [xp, yp, zp], [xp, ym, zp]]
    job = base_job(render={"width": W, "height": H, "spp": spp, "spectral": "rgb"},
                   camera={"look_at": [0.0, 1.0, 0.0], "fov": fov},
                   motion={"beta": beta.tolist()},
                   materials=[{"name": "red", "emission": [1, 0, 0], "emission_strength": 1.0},
                              {"name": "green", "emission": [0, 1, 0],
                               "emission_strength": 1.0}],
                   objects=[{"shape": "quad", "corners": facing, "material": "red"},
                            {"shape": "quad", "corners": trailing, "material": "green"}])
    r = render(job, tmp_path)
    row = H // 2
    red, green = r.rgb[row, :, 0], r.rgb[row, :, 1]
    assert np.all(red[[0, -1]] == 0) and np.all(green[[0, -1]] == 0)  # fully in view

    def to_cam(P):
        d_lab = P / np.linalg.norm(P, axis=-1, keepdims=True)
        d_cam = aberrate(d_lab, -beta)  # inverse aberration: the lab moves at -β in S'
        np.testing.assert_allclose(aberrate(d_cam, beta), d_lab, atol=1e-14)
        return d_cam

    def x_img(P):
        d = to_cam(np.asarray(P, float))
        return d[..., 0] / d[..., 1]

    edges = [np.array([xm, ym]), np.array([xp, ym]), np.array([xp, yp])]
    xs = [float(x_img([e[0], e[1], 0.0])) for e in edges]
    w_face = abs(xs[1] - xs[0]) / p
    w_trail = abs(xs[2] - xs[1]) / p
    # curvature: x of each edge's image over the row's height |y_img| <= p/2
    curv = 0.0
    for e in edges:
        zz = np.linspace(-a / 2, a / 2, 4001)
        P = np.stack([np.full_like(zz, e[0]), np.full_like(zz, e[1]), zz], axis=1)
        d = to_cam(P)
        inrow = np.abs(d[:, 2] / d[:, 1]) <= p / 2
        curv += float(np.ptp(d[inrow, 0] / d[inrow, 1])) / p
    for got, want, q in ((red.sum(), w_face, red), (green.sum(), w_trail, green)):
        sigma = math.sqrt(np.sum(q * (1.0 - q)) / spp)
        assert abs(got - want) <= 5.0 * sigma + curv, (got, want, sigma, curv)

    Lp = L / GAMMA
    D = GAMMA * (1.0 + beta @ (C / L))
    assert D == pytest.approx(1.0 / GAMMA, rel=1e-15)
    limit_face = a / GAMMA / Lp / p
    limit_trail = B * a / Lp / p
    assert w_face == pytest.approx(limit_face, rel=3 * a / L)
    assert w_trail == pytest.approx(limit_trail, rel=3 * a / L)
    assert w_face / w_trail == pytest.approx(1.0 / (GAMMA * B), rel=6 * a / L)


# =========================================================================== furnace and sky


@pytest.mark.parametrize("beta, ct", [([0.0, 0.0, 0.0], 0.0), ([0.3, 0.4, 0.0], 2.0)],
                         ids=["rest", "moving"])
def test_white_furnace(tmp_path, beta, ct):
    """Albedo-1 diffuse objects under a uniform sky of radiance 1 have radiance 1 everywhere.

    L = 1 solves the rendering equation for ρ = 1 and L_sky = 1 (white = D65, Y = 1), so
    every pixel's luminance is 1 (hit or not). A sphere on a floor gives interreflections;
    max_depth 64 makes truncation negligible (open scene: a path survives k bounces with
    probability < 0.5^k). In motion with doppler = false and searchlight = false every
    sample still sees L = 1. σ_p from the film's per-pixel variance (rel_error):
    every pixel within 6σ_p (σ estimated from 32 samples: t-tails), the image mean within
    5σ of the mean. Catches MIS/NEE weighting errors, energy loss or gain per bounce, and
    a D⁵ or wavelength shift applied although switched off.
    """
    W = H = 24
    job = base_job(render={"width": W, "height": H, "spp": 32, "max_depth": 64,
                           "doppler": False, "searchlight": False},
                   camera={"position": [0.0, -6.0, 2.5], "look_at": [0.0, 0.0, 0.8],
                           "fov": 40.0},
                   motion={"beta": beta, "ct": ct},
                   scene={"background": [1.0, 1.0, 1.0]},
                   materials=[{"name": "white", "base_color": [1.0, 1.0, 1.0],
                               "roughness": 1.0}],
                   objects=[{"shape": "sphere", "center": [0.0, 0.0, 1.0], "radius": 1.0,
                             "material": "white"},
                            {"shape": "quad", "material": "white",
                             "corners": [[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]]}])
    r = render(job, tmp_path)
    Y = r.luminance
    sig = r.sigma_y
    assert 0.2 < r.alpha.mean() < 0.95  # both objects and sky in view
    assert np.all(np.abs(zscore(Y, 1.0, sig)) <= 6.0), np.max(np.abs(zscore(Y, 1.0, sig)))
    sig_mean = math.sqrt(np.sum(sig**2)) / Y.size
    assert abs(Y.mean() - 1.0) <= 5.0 * sig_mean, (Y.mean(), sig_mean)
    rgb = r.rgb.reshape(-1, 3)
    sig_rgb = np.std(rgb, axis=0, ddof=1) / math.sqrt(len(rgb))
    assert np.all(np.abs(rgb.mean(axis=0) - 1.0) <= 5.0 * sig_rgb), rgb.mean(axis=0)


LIGHT_H = 1.5
LIGHT_A = 0.6  # half side of the square area light
RHO = 0.5


def floor_radiance(P: np.ndarray, kind: str) -> np.ndarray:
    """Radiance Y of a grey (ρ = 0.5) Lambertian floor z = 0 at points P, lit by one light.

    area: a one-sided square of radiance Y = 3 at height h facing down:
          L = ρ L_e F (F: form factor, corner decomposition with signs);
    point: power 50 W at (0, 0, h): I = P/(4π) (Blender's W, lights.py), L = ρ/π I cosθ/r²;
    sun: 2 W/m² along (0.3, 0.2, -1): L = ρ/π E cosθ.
    (Light colours are white: D65 with Y = 1.)
    """
    x, y = P[..., 0], P[..., 1]
    if kind == "area":
        h, a = LIGHT_H, LIGHT_A
        return RHO * 3.0 * rectangle_form_factor(x, y, h, -a, a, -a, a)
    if kind == "point":
        r2 = x * x + y * y + LIGHT_H**2
        return RHO / np.pi * 50.0 / (4.0 * np.pi) * (LIGHT_H / np.sqrt(r2)) / r2
    d = np.array([0.3, 0.2, -1.0])
    return RHO / np.pi * 2.0 * (-d[2] / np.linalg.norm(d)) * np.ones_like(x)


@pytest.mark.parametrize("kind, beta", [
    pytest.param("area", [0.0, 0.0, 0.0], id="area"),
    pytest.param("point", [0.0, 0.0, 0.0], id="point"),
    pytest.param("sun", [0.0, 0.0, 0.0], id="sun"),
    pytest.param("area", [0.3, 0.5, 0.0], id="area-moving")])
def test_direct_lighting_of_a_floor(tmp_path, kind, beta):
    """Next-event estimation + BSDF sampling (MIS) reproduce analytic direct lighting.

    A grey floor (ρ = 0.5, constant: the sigmoid fit of a grey is flat) lit by one light
    (see floor_radiance), max_depth 2 (camera -> floor -> light). Every pixel sees the
    floor; expected: the pixel mean (16 x 16 sub-grid) of the analytic radiance at the
    floor point hit by the lab ray (aberrated by hand in the moving case, where doppler
    and searchlight are off, so only the geometry moves). σ_p from rel_error: every
    pixel within 6σ_p, the z-score sum within 5√N. Catches: wrong light units (π, 4π),
    wrong area-to-solid-angle pdf, MIS weights not summing to 1, one-sidedness errors,
    aberration applied to the wrong rays.
    """
    W = H = 24
    fov = 30.0
    cam = np.array([0.0, -3.0, 1.0])
    look = [0.0, 0.0, 0.0]
    lights, objects = [], [{"shape": "quad", "material": "floor", "corners":
                            [[-40, -40, 0], [40, -40, 0], [40, 40, 0], [-40, 40, 0]]}]
    mats = [{"name": "floor", "base_color": [RHO] * 3, "roughness": 1.0}]
    if kind == "area":
        a, h = LIGHT_A, LIGHT_H
        mats.append({"name": "lamp", "base_color": [0.0, 0.0, 0.0], "emission": [1, 1, 1],
                     "emission_strength": 3.0, "one_sided_emission": True})
        objects.append({"shape": "quad", "material": "lamp",  # normal (c1-c0)x(c2-c0) = -z
                        "corners": [[-a, -a, h], [-a, a, h], [a, a, h], [a, -a, h]]})
    elif kind == "point":
        lights.append({"type": "point", "position": [0.0, 0.0, LIGHT_H], "power": 50.0})
    else:
        lights.append({"type": "sun", "direction": [0.3, 0.2, -1.0], "power": 2.0})
    job = base_job(render={"width": W, "height": H, "spp": 32, "max_depth": 2,
                           "doppler": False, "searchlight": False},
                   camera={"position": cam.tolist(), "look_at": look, "fov": fov},
                   motion={"beta": beta, "ct": 0.0}, materials=mats, objects=objects,
                   lights=lights)
    r = render(job, tmp_path)
    assert np.all(r.alpha == 1.0)
    axes = camera_axes(cam, look, [0, 0, 1])

    def f(d_cam):
        d = aberrate(d_cam, beta) if any(beta) else d_cam
        t = -cam[2] / d[..., 2]
        return floor_radiance(cam + t[..., None] * d, kind)

    expected, _ = pixel_average(f, W, H, fov, axes)
    z = zscore(r.luminance, expected, r.sigma_y)
    assert np.all(np.abs(z) <= 6.0), np.max(np.abs(z))
    assert abs(z.sum()) <= 5.0 * math.sqrt(z.size), z.mean()
    assert expected.max() / expected.min() > 1.5 or kind == "sun"  # a real light pattern


def test_nee_shadow_ray_reaches_its_light(tmp_path):
    """Minimal demonstration of the NEE self-hit bug (core/render/integrator.py, shade()).

    One pixel looking straight down at the floor point (0, 2, 0) of an 80 m floor (scene
    extent 80 -> eps = 1e-5·80 = 8e-4), lit by a 1.2 m square one-sided lamp 1.5 m up.
    Every shadow ray towards the lamp leaves 8e-4 above the floor, so it meets the lamp's
    plane 8e-4/cos θ ≈ 1.3e-3 earlier than ``dist``, but tmax = dist - 1e-4·dist - eps is
    only ≈ 1.0e-3 shorter: Embree reports the lamp itself as the occluder. The analytic
    radiance is ρ L_e F = 0.0422; the render gives ~0 (only the rare BSDF-sampled hits,
    MIS-weighted down). Tolerance 6σ from rel_error (256 samples).
    Proposed fix: aim the shadow ray from the offset origin sh_o at the light point moved
    by eps along the light's normal towards sh_o, with direction and tmax = |target - sh_o|
    ·(1 - 1e-4) computed from those two points (keep p_l and cos_l from the unshifted ones).
    """
    a, h = LIGHT_A, LIGHT_H
    job = base_job(render={"width": 1, "height": 1, "spp": 256, "max_depth": 2,
                           "doppler": False, "searchlight": False},
                   camera={"position": [0.0, 2.0, 1.0], "look_at": [0.0, 2.0, 0.0],
                           "up": [0.0, 1.0, 0.0], "fov": 0.01},
                   materials=[{"name": "floor", "base_color": [RHO] * 3, "roughness": 1.0},
                              {"name": "lamp", "base_color": [0.0, 0.0, 0.0],
                               "emission": [1, 1, 1], "emission_strength": 3.0,
                               "one_sided_emission": True}],
                   objects=[{"shape": "quad", "material": "floor", "corners":
                             [[-40, -40, 0], [40, -40, 0], [40, 40, 0], [-40, 40, 0]]},
                            {"shape": "quad", "material": "lamp",
                             "corners": [[-a, -a, h], [-a, a, h], [a, a, h], [a, -a, h]]}])
    r = render(job, tmp_path)
    expected = float(floor_radiance(np.array([0.0, 2.0, 0.0]), "area"))
    assert abs(expected - 0.0422) < 1e-4
    assert abs(r.luminance[0, 0] - expected) <= 6.0 * r.sigma_y[0, 0], r.luminance[0, 0]


def sky_expectation(D: np.ndarray) -> np.ndarray:
    """Y of the sky seen with Doppler factor D: D⁵ ∫ ȳ(λ) D65_ext(Dλ) dλ (white sky).

    The film's estimator converges to the integral of the sensor response, linearly
    interpolated between its 1 nm nodes (as sensor_values does), times the table looked up
    at the lab wavelength: evaluated here with a 0.05 nm midpoint rule over 360–830 nm.
    """
    resp = spectrum.sensor_response("cie1931")[1].astype(np.float64)
    lam = np.arange(360.0, 830.0, 0.05) + 0.025
    ybar = np.interp(lam, spectrum.sensor_nm(), resp)
    table = spectrum.d65_ext()
    D = np.asarray(D, float)
    L = spectrum.lookup(table, D[..., None] * lam)
    return D**5 * (L * ybar).sum(axis=-1) * 0.05


@pytest.mark.parametrize("dop", [False, True], ids=["doppler-off", "doppler-on"])
def test_uniform_sky_d5(tmp_path, dop):
    """A uniform white sky seen by a moving camera: Y = <D⁵ ∫ ȳ L_sky(Dλ) dλ> per pixel.

    doppler = false: L_sky(λ) is not shifted, so Y = <D⁵> (the sky has Y = 1 at rest).
    doppler = true: the whole Doppler path (λ_lab = Dλ on the lab grid) against the sensor
    integral computed here. β = 0.5 at 37° from the view's side, fov 60°: D spans 0.8–1.7.
    Expected per pixel: mean over the pixel's area (16 x 16 sub-grid) of the function of D
    (tabulated on 801 D values, interpolated: error < 1e-6 relative).
    Tolerance: σ_p from rel_error, every pixel within 6σ_p; the sum of the z-scores over
    the 1536 pixels within 5√N (a systematic error of 1e-3 would fail it).
    Catches D⁴ / D⁶, D ↔ 1/D in the wavelength shift, the sign of β.
    """
    W, H, fov = 48, 32, 60.0
    beta = [0.4, 0.3, 0.0]
    job = base_job(render={"width": W, "height": H, "spp": 32, "doppler": dop,
                           "searchlight": True},
                   camera={"fov": fov}, motion={"beta": beta},
                   scene={"background": [1.0, 1.0, 1.0]},
                   materials=[grey()], objects=[FAR_SPECK])
    r = render(job, tmp_path)
    assert np.all(r.alpha == 0.0)
    axes = camera_axes([0, 0, 0], [0, 1, 0], [0, 0, 1])
    if dop:
        Dgrid = np.linspace(0.5, 2.0, 801)
        fgrid = sky_expectation(Dgrid)

        def f(d):
            return np.interp(doppler(d, beta), Dgrid, fgrid)
    else:
        def f(d):
            return doppler(d, beta) ** 5
    expected, _ = pixel_average(f, W, H, fov, axes)
    Y = r.luminance
    sig = r.sigma_y
    z = zscore(Y, expected, sig)
    assert np.all(np.abs(z) <= 6.0), np.max(np.abs(z))
    assert abs(z.sum()) <= 5.0 * math.sqrt(z.size), z.mean()
    assert expected.max() / expected.min() > 5.0  # D really varies over the image


# =========================================================================== seeds, threads


def test_seeds_agree_within_error_bars(tmp_path):
    """Two seeds give statistically consistent images: different noise, same expectation.

    Moving Cornell box (β = (0.2, 0.3, 0.1), full Doppler path). Per pixel
    z = (Y₁ - Y₂)/sqrt(σ₁² + σ₂²) with σ from rel_error. z is symmetric about 0 for
    independent, unbiased renders, so mean z is within 5·sqrt(<z²>/N); <z²> is ≈ 1
    (σ from 16 samples: E t² = 15/13) — below 0.5 would mean correlated seeds (identical
    images give 0), above 2 error bars too small. The image-mean luminances agree within
    5 combined standard errors.
    """
    renders = []
    for seed in (0, 1):
        job = cornell_job(render={"seed": seed, "spp": 16},
                          motion={"beta": [0.2, 0.3, 0.1], "ct": 1.0})
        renders.append(render(job, tmp_path))
    Y1, Y2 = renders[0].luminance, renders[1].luminance
    s1, s2 = renders[0].sigma_y, renders[1].sigma_y
    assert not np.array_equal(Y1, Y2)
    keep = (s1 > 0) | (s2 > 0)
    z = (Y1 - Y2)[keep] / np.hypot(s1, s2)[keep]
    n = z.size
    assert n > Y1.size // 2  # most pixels see the box
    z2 = float(np.mean(z**2))
    assert abs(z.mean()) <= 5.0 * math.sqrt(z2 / n), (z.mean(), z2)
    assert 0.5 <= z2 <= 2.0, z2
    sig = math.sqrt(np.sum(s1**2) + np.sum(s2**2)) / Y1.size
    assert abs(Y1.mean() - Y2.mean()) <= 5.0 * sig


def test_threads_do_not_change_the_image(tmp_path):
    """Same seed, threads = 1 vs 2: bit-identical (tiles differ; per-pixel order doesn't)."""
    out = []
    for threads in (1, 2):
        job = cornell_job(render={"threads": threads, "width": 64, "height": 48, "spp": 4},
                          motion={"beta": [0.2, 0.3, 0.1], "ct": 1.0},
                          output={"formats": ["spectral-exr"],
                                  "spectral_bands": [400.0, 700.0, 10.0]})
        out.append(render(job, tmp_path).image)
    a, b = out
    np.testing.assert_array_equal(a.rgba, b.rgba)
    np.testing.assert_array_equal(a.spectral, b.spectral)
    np.testing.assert_array_equal(a.rel_error, b.rel_error)
    np.testing.assert_array_equal(a.spp, b.spp)
    for k in a.aovs:
        np.testing.assert_array_equal(a.aovs[k], b.aovs[k])


# =========================================================================== acceleration


def test_constant_acceleration_job(tmp_path):
    """a = 1, τ = 1 through a worldline job: β = tanh 1, t = sinh 1, x = cosh 1 - 1.

    Checked on frame_events (several frames) and on the render of τ = 1: on the axis
    (looking along the motion) D = sqrt((1+β)/(1-β)) = e^{aτ} = e; the depth of a wall at
    x = 5 is (5 - x_cam)/d_lab,x; lab_time = t - depth. Pixel values are means over the
    pixel, so they lie within the min/max over the pixel (float32: 1e-6 relative).
    Events: closed forms in ~10 float64 operations: 16 ulps.
    """
    job = base_job(render={"width": 5, "height": 5, "spp": 8, "spectral": "rgb"},
                   camera={"look_at": [1.0, 0.0, 0.0], "fov": 2.0},
                   motion={"mode": "worldline", "proper_acceleration": [1.0, 0.0, 0.0],
                           "ct": 0.5, "frames": [1, 3], "ct_per_frame": 0.25},
                   materials=[grey()],
                   objects=[{"shape": "quad", "material": "grey",
                             "corners": [[5, -5, -5], [5, 5, -5], [5, 5, 5], [5, -5, 5]]}])
    events = frame_events(make_job(job, tmp_path))
    assert [f for f, _ in events] == [1, 2, 3]
    for (_, ev), tau in zip(events, (0.5, 0.75, 1.0), strict=True):
        tol = 16 * EPS64
        assert ev.tau == tau
        assert ev.beta[0] == pytest.approx(math.tanh(tau), rel=tol)
        assert ev.t == pytest.approx(math.sinh(tau), rel=tol)
        assert ev.x[0] == pytest.approx(math.cosh(tau) - 1.0, rel=tol)
        assert ev.beta[1] == ev.beta[2] == ev.x[1] == ev.x[2] == 0.0

    r = render(job, tmp_path, frame=3)
    b = math.tanh(1.0)
    x_cam = math.cosh(1.0) - 1.0
    axes = camera_axes([0, 0, 0], [1, 0, 0], [0, 0, 1])

    def depth(d):
        return (5.0 - x_cam) / aberrate(d, [b, 0, 0])[..., 0]

    lo, hi = pixel_range(lambda d: doppler(d, [b, 0, 0]), 2, 2, 5, 5, 2.0, axes)
    assert lo <= math.e <= hi * (1 + 8 * EPS64)  # D is largest on the axis: ulps slack
    assert lo * (1 - 1e-6) <= r.image.aovs["doppler"][2, 2] <= hi * (1 + 1e-6)
    for row in range(5):
        for col in range(5):
            lo, hi = pixel_range(depth, col, row, 5, 5, 2.0, axes)
            assert lo * (1 - 1e-6) <= r.image.aovs["depth"][row, col] <= hi * (1 + 1e-6)
    lab_time = r.image.aovs["lab_time"].astype(np.float64)
    depth_aov = r.image.aovs["depth"].astype(np.float64)
    np.testing.assert_allclose(lab_time + depth_aov, math.sinh(1.0), rtol=0, atol=8 * EPS32)
    assert pixel_range(depth, 2, 2, 5, 5, 2.0, axes)[0] <= 5.0 - x_cam  # on the axis

