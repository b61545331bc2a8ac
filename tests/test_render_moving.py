"""Moving objects rendered end to end, against physics.md's analytic cases.

Penrose–Terrell (the outline of a moving sphere), Einstein's moving mirror (line position
and k⁴), the principle of relativity (a moving camera past a resting scene against a
resting camera with the scene moving the other way) and finiteness near c. Tolerances
come from the pixel-to-pixel scatter (standard errors) or from the pixel size, as each
test says; the pixel directions are written out by hand (tests/render_helpers.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from render_helpers import base_job, camera_axes, directions, ndc, render

# ------------------------------------------------------------------ Penrose–Terrell

W = 160
FOV = 90.0


def cap_of(alpha: np.ndarray, axes, width: int, fov: float):
    """(axis, angular radius, σ of the radius) of the spherical cap that the coverage
    ``alpha`` (mean hit fraction per pixel) covers: Ω = Σ α_i ω_i = 2π (1 - cos ρ), the
    axis along Σ α_i ω_i d_i. σ from α's sampling error per pixel, √(α(1-α)/spp)."""
    rows, cols = np.mgrid[0:width, 0:width] + 0.5
    x, y = ndc(cols, rows, width, width, fov)
    d = directions(x, y, axes)
    t = math.tan(math.radians(fov) / 2.0)
    px = 2.0 * t / width                                   # tangent-plane pixel size
    omega = px * px / (1.0 + x * x + y * y) ** 1.5         # solid angle of each pixel
    solid = float((alpha * omega).sum())
    axis = (alpha[..., None] * omega[..., None] * d).sum(axis=(0, 1))
    rho = math.acos(1.0 - solid / (2.0 * math.pi))
    return axis / np.linalg.norm(axis), rho, omega


def terrell_prediction(b: float, seen_at_deg: float, radius_deg: float):
    """The circle a camera at rest sees of a sphere moving at b, when in the sphere's rest
    frame the camera (moving at -b) sees it at ``seen_at_deg`` from its own motion with
    angular radius ``radius_deg``: aberration maps the rest-frame cap edges θ ± ρ by
    cos θ' = (cos θ + b)/(1 + b cos θ); returns (centre, radius) in degrees from -u."""
    def ab(theta):
        c = math.cos(math.radians(theta))
        return math.degrees(math.acos((c + b) / (1.0 + b * c)))
    lo, hi = ab(seen_at_deg - radius_deg), ab(seen_at_deg + radius_deg)
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


def test_terrell_prediction_is_physics_md_s_row():
    centre, radius = terrell_prediction(0.5, 90.0, 10.0)
    assert (round(centre, 3), round(radius, 3)) == (60.378, 8.682)


def test_a_moving_sphere_stays_a_circle_where_light_travel_time_puts_it(tmp_path):
    """physics.md: a sphere of 10° angular radius at 90° in its rest frame, b = 0.5, is a
    circle of radius 8.682° centred 60.378° from -u (not at 60°). The sphere's pivot is
    straight ahead at lab time 0 at D = R / sin 10°: then in its rest frame the camera's
    event is at 90° from u at that distance.

    Measured: the cap that the coverage fills (its solid angle gives the radius, its
    weighted mean direction the axis). Tolerance: 4 σ of the coverage's sampling error
    plus the icosphere's flattening (its inscribed radius is R(1 - 2e-4) at 6
    subdivisions: 0.002° here) and a quarter of the float32 ray precision, 1e-4°.
    """
    b, R = 0.5, 1.0
    D = R / math.sin(math.radians(10.0))
    spp = 64
    job = base_job(render={"width": W, "height": W, "spp": spp},
                   camera={"fov": FOV},
                   materials=[{"name": "glow", "base_color": [0, 0, 0],
                               "emission": [1, 1, 1], "emission_strength": 1.0}],
                   objects=[{"shape": "sphere", "center": [0.0, D, 0.0], "radius": R,
                             "subdivisions": 6, "material": "glow",
                             "velocity": [b, 0.0, 0.0]}])
    r = render(job, tmp_path)
    axes = camera_axes([0, 0, 0], [0, 1, 0], [0, 0, 1])
    axis, rho, omega = cap_of(r.alpha, axes, W, FOV)
    centre, radius = terrell_prediction(b, 90.0, 10.0)
    from_minus_u = math.degrees(math.acos(float(-axis[0])))
    # σ(ρ): dΩ = 2π sin ρ dρ, σ_Ω² = Σ ω² α(1-α)/spp
    a = r.alpha
    sigma_omega = math.sqrt(float((omega**2 * a * (1 - a)).sum()) / spp)
    sigma_rho = math.degrees(sigma_omega / (2 * math.pi * math.sin(rho)))
    tol = 4.0 * sigma_rho + 0.002 + 1e-4
    assert abs(math.degrees(rho) - radius) <= tol, (math.degrees(rho), radius, tol)
    assert abs(from_minus_u - centre) <= tol, (from_minus_u, centre, tol)
    assert abs(from_minus_u - 60.0) > 10 * tol  # the naive aberrated centre is wrong
    assert abs(axis[2]) < 1e-3  # in the plane of u and the line of sight


# ------------------------------------------------------------ Einstein's moving mirror

BANDS = [400.0, 760.0, 2.0]


def mirror_render(tmp_path, b: float):
    """A static camera looks along +y at a mirror 10 away moving at b along +y (receding
    for b > 0); behind the camera a static wall glows in a 550 nm line."""
    return mirror_render_switch(tmp_path, b, doppler=True)


def mirror_render_switch(tmp_path, b: float, doppler: bool):
    """:func:`mirror_render` with the ``doppler`` switch."""
    job = base_job(render={"width": 8, "height": 8, "spp": 64, "max_depth": 2,
                           "doppler": doppler},
                   output={"formats": ["spectral-exr"], "spectral_bands": BANDS},
                   camera={"fov": 2.0},
                   materials=[{"name": "line", "base_color": [0, 0, 0],
                               "emission_line": [550.0, 3.0], "emission_strength": 1.0},
                              {"name": "mirror", "base_color": [1, 1, 1], "metallic": 1.0,
                               "roughness": 0.0}],
                   objects=[{"shape": "quad", "material": "mirror",
                             "corners": [[-20, 10, -20], [-20, 10, 20], [20, 10, 20],
                                         [20, 10, -20]],
                             **({"velocity": [0.0, b, 0.0]} if b else {})},
                            {"shape": "quad", "material": "line",
                             "corners": [[-20, -2, -20], [20, -2, -20], [20, -2, 20],
                                         [-20, -2, 20]]}])
    r = render(job, tmp_path)
    S = r.image.spectral.astype(np.float64).reshape(-1, r.image.spectral.shape[-1])
    return S, r.image.band_centers_nm


@pytest.fixture(scope="module")
def mirror_at_rest(tmp_path_factory):
    return mirror_render(tmp_path_factory.mktemp("rest"), 0.0)


@pytest.mark.parametrize("b", [0.1, -0.1])
def test_einsteins_moving_mirror(tmp_path, mirror_at_rest, b):
    """Light back from a mirror receding at b has its frequency scaled by
    k = (1 - b)/(1 + b): the 550 nm line appears at 550/k (672.2 nm receding, 450 nm
    approaching, physics.md) and the wavelength-integrated radiance scales by k⁴ (against
    the same mirror at rest). Tolerances: the line centroid within half a band (1 nm,
    the bands' quantisation) plus 5 σ of the pixel scatter; the flux ratio within 5 σ
    (pixel scatter of both renders, in quadrature) plus the 2° view's spread of k
    (|Δk/k| < 2 b sin²(1°) < 1e-4)."""
    S, lam = mirror_render(tmp_path, b)
    S0, _ = mirror_at_rest
    k = (1.0 - b) / (1.0 + b)
    flux, flux0 = S.sum(axis=1), S0.sum(axis=1)
    A = (S * lam).sum(axis=1)
    centroid = A.sum() / flux.sum()
    sigma_c = math.sqrt(len(A)) * np.std(A - centroid * flux, ddof=1) / flux.sum()
    assert abs(centroid - 550.0 / k) <= BANDS[2] / 2 + 5 * sigma_c, (centroid, 550.0 / k)
    ratio = flux.mean() / flux0.mean()
    rel = math.hypot(np.std(flux, ddof=1) / flux.mean(), np.std(flux0, ddof=1) / flux0.mean())
    sigma_r = ratio * rel / math.sqrt(len(flux))
    assert abs(ratio - k**4) <= 5 * sigma_r + 1e-4 * k**4, (ratio, k**4, sigma_r)


# ------------------------------------------------------------ the principle of relativity

BETA = np.array([0.5, 0.0, 0.0])
SCENE = (("glow hot", [2.0, 6.0, 0.5], {"emission_blackbody": 5800.0,
                                       "emission_strength": 1e-7}),
         ("glow line", [-1.5, 5.0, -0.8], {"emission_line": [600.0, 8.0],
                                           "emission_strength": 1.0}))


def relativity_jobs() -> tuple[dict, dict]:
    """A: the camera moves at β past a resting scene (snapshot at ct' = 0, event (0, 0)).
    B: the camera rests; every object moves at -β with the pivot it has in the camera's
    frame at t' = 0: p' = p - γ/(γ+1) (β·p) β (the spatial part of Λ(β) at the lab event
    t = β·p where t' = 0); the shapes are rest-frame shapes in both."""
    g = 1.0 / math.sqrt(1.0 - BETA @ BETA)
    mats = [{"name": n, "base_color": [0, 0, 0], **extra} for n, _, extra in SCENE]
    objs_a, objs_b = [], []
    for name, p, _ in SCENE:
        sphere = {"shape": "sphere", "radius": 0.7, "subdivisions": 5, "material": name}
        objs_a.append({**sphere, "center": p})
        p_b = np.array(p) - g / (g + 1.0) * (BETA @ p) * BETA
        objs_b.append({**sphere, "center": p_b.tolist(), "velocity": (-BETA).tolist()})
    common = dict(render={"width": 48, "height": 32, "spp": 16},
                  output={"formats": ["exr"], "aovs": ["doppler"]},
                  camera={"fov": 60.0}, materials=mats)
    return (base_job(**common, motion={"beta": BETA.tolist()}, objects=objs_a),
            base_job(**common, objects=objs_b))


def test_moving_camera_and_moving_scene_see_the_same_image(tmp_path):
    """Geometry (coverage), colour (every sensor channel) and brightness agree per pixel
    within 5 standard errors (the film's per-pixel variance of both renders), and the
    Doppler AOV (the camera's D in A, the bodies' D in B) agrees to 1e-4 where both hit.
    Both renders use the same random numbers per pixel and sample, so most of their
    noise cancels: the test is sharper than the σ suggests, never looser."""
    job_a, job_b = relativity_jobs()
    a = render(job_a, tmp_path / "a")
    b = render(job_b, tmp_path / "b")
    z_alpha = np.abs(a.alpha - b.alpha) / np.sqrt(
        (a.alpha * (1 - a.alpha) + b.alpha * (1 - b.alpha)) / 16 + 1e-12)
    assert np.all((z_alpha <= 5) | (np.abs(a.alpha - b.alpha) < 1e-9))
    assert a.alpha.sum() > 30  # both spheres are in view
    sigma = np.sqrt(a.sigma_y**2 + b.sigma_y**2)[..., None] * np.ones(3)
    diff = np.abs(a.sensor - b.sensor)
    assert np.all(diff <= 5 * sigma + 1e-6 * np.abs(a.sensor)), float(np.max(diff / sigma))
    hit = (a.alpha == 1.0) & (b.alpha == 1.0)
    da, db = a.image.aovs["doppler"][hit], b.image.aovs["doppler"][hit]
    np.testing.assert_allclose(da, db, rtol=1e-4)
    assert da.min() < 0.97 and da.max() > 1.01  # both red- and blueshifted parts



LIGHTS = {
    # a blackbody panel under the ceiling, easily found by BSDF sampling too
    "panel": {"shape": "box", "center": [0.0, 4.0, 2.8], "size": [5.0, 6.0, 0.2],
              "material": "hot", "strength": 3e-7},
    # a small blackbody sphere: only next-event estimation finds it often
    "bulb": {"shape": "sphere", "center": [1.5, 6.0, 1.8], "radius": 0.4,
             "subdivisions": 3, "material": "hot", "strength": 3e-6},
}


def room_jobs(light: str) -> tuple[dict, dict]:
    """:func:`relativity_jobs` for light that bounces: the camera inside a closed grey
    room with a grey ball, lit by one of :data:`LIGHTS`, paths of up to 5 segments. In B
    the whole room, its light included, is one body moving at -β, so most bounces go
    from a surface of that body to another (the rays carry their rest-frame form there
    and keep the body's frame, :func:`.rest_frames.nearest_ray` and ``shade``), and
    next-event estimation samples the light in the body's rest frame."""
    g = 1.0 / math.sqrt(1.0 - BETA @ BETA)
    spec = dict(LIGHTS[light])
    strength = spec.pop("strength")
    mats = [{"name": "grey", "base_color": [0.6, 0.6, 0.6]},
            {"name": "hot", "base_color": [0, 0, 0], "emission_blackbody": 5000.0,
             "emission_strength": strength}]
    shapes = [{"shape": "box", "center": [0.0, 3.0, 0.0], "size": [8.0, 10.0, 6.0],
               "material": "grey"},
              {"shape": "sphere", "center": [-1.0, 5.0, -1.5], "radius": 1.0,
               "subdivisions": 4, "material": "grey"}, spec]
    objs_a, objs_b = [], []
    for obj in shapes:
        p = np.array(obj["center"], np.float64)
        p_b = p - g / (g + 1.0) * (BETA @ p) * BETA
        objs_a.append(obj)
        objs_b.append({**obj, "center": p_b.tolist(), "velocity": (-BETA).tolist()})
    common = dict(render={"width": 40, "height": 30, "spp": 64, "max_depth": 5},
                  camera={"fov": 90.0}, materials=mats)
    return (base_job(**common, motion={"beta": BETA.tolist()}, objects=objs_a),
            base_job(**common, objects=objs_b))


@pytest.mark.parametrize("light", sorted(LIGHTS))
def test_a_moving_room_and_a_moving_camera_see_the_same_bounced_light(tmp_path, light):
    """The principle of relativity with light that bounces inside one moving body: per
    pixel within 5 standard errors in every sensor channel (as above), and the frame's
    mean within 4 standard errors of its own (the pixels' errors are independent). With
    the small bulb the per-pixel test holds only if B samples its light as A does (a
    light of the body the shading point is on, in their common rest frame): reached by
    BSDF sampling alone, B's pixels are too heavy-tailed for their σ."""
    job_a, job_b = room_jobs(light)
    a = render(job_a, tmp_path / "a")
    b = render(job_b, tmp_path / "b")
    assert a.alpha.min() == 1.0 and b.alpha.min() == 1.0  # inside the room everywhere
    sigma = np.sqrt(a.sigma_y**2 + b.sigma_y**2)[..., None] * np.ones(3)
    diff = np.abs(a.sensor - b.sensor)
    assert np.all(diff <= 5 * sigma + 1e-6 * np.abs(a.sensor)), float(np.max(diff / sigma))
    mean_sigma = math.sqrt(float((sigma[..., 1] ** 2).sum())) / sigma[..., 1].size
    assert abs(float(a.sensor[..., 1].mean() - b.sensor[..., 1].mean())) <= 4 * mean_sigma
    assert a.sensor[..., 1].mean() > 0.0

# ------------------------------------------------------------------------- near c

@pytest.mark.parametrize("b", [0.999, 1.0 - 1e-9])
def test_a_body_near_c_renders_finite(tmp_path, b):
    """|u| → 1 - 1e-9 and lab times of 1e6: every value finite (render() asserts no
    non-finite sample), the body still found where its light left it."""
    g = 1.0 / math.sqrt((1.0 - b) * (1.0 + b))
    job = base_job(render={"width": 16, "height": 16, "spp": 4, "max_depth": 3},
                   camera={"fov": 90.0}, motion={"ct": 1e6},
                   materials=[{"name": "w", "base_color": [0.8, 0.8, 0.8]},
                              {"name": "glow", "base_color": [0, 0, 0],
                               "emission": [1, 1, 1], "emission_strength": 1.0}],
                   objects=[
                       # a rod moving along the line of sight towards the camera, whose
                       # light now left it when its pivot was 5 ahead: pivot at t = 0
                       # is 5 + b·(1e6 + 5) further out (t_emit = 1e6 - 5)
                       {"shape": "box", "center": [0.0, 5.0 + b * (1e6 + 5.0), 0.0],
                        "size": [1.0, 1.0, 1.0], "material": "w",
                        "velocity": [0.0, -b, 0.0]},
                       {"shape": "sphere", "center": [0.0, 0.0, 0.0], "radius": 50.0,
                        "subdivisions": 2, "material": "glow"}])
    r = render(job, tmp_path)
    assert np.isfinite(r.rgb).all() and g > 20
    assert r.alpha.min() == 1.0  # the glowing sphere around everything


# ------------------------------------------------- light bounced off a moving body

def moving_bounce_job(u: float) -> dict:
    """A camera (2° view) looks at a static grey wall (y = 5, facing -y) at P = (0, 5, 0).
    The wall's only light comes from a large grey plane x = -1 (facing +x) moving at u
    along +y, in its own plane (so it is there at every time), lit by a sun whose light
    travels along -x (it grazes the wall: no direct light). max_depth 3: exactly the
    path camera → wall → moving plane → sun."""
    big = 400.0
    return base_job(
        render={"width": 8, "height": 8, "spp": 256, "max_depth": 3},
        camera={"fov": 2.0},
        materials=[{"name": "wall", "base_color": [0.5, 0.5, 0.5], "roughness": 1.0},
                   {"name": "body", "base_color": [0.8, 0.8, 0.8], "roughness": 1.0}],
        objects=[{"shape": "quad", "material": "wall",
                  "corners": [[-big, 5, -big], [big, 5, -big], [big, 5, big], [-big, 5, big]]},
                 {"shape": "quad", "material": "body",
                  "corners": [[-1, -big, -big], [-1, big, -big], [-1, big, big],
                              [-1, -big, big]],
                  **({"velocity": [0.0, u, 0.0]} if u else {})}],
        lights=[{"type": "sun", "direction": [-1.0, 0.0, 0.0], "color": [1.0, 1.0, 1.0],
                 "power": 1.0}])


def bounce_ratio_expected(u: float) -> np.ndarray:
    """An independent estimate of the wall's XYZ with the plane moving at u over the same
    with it at rest (physics.md's factors, integrated by quadrature in numpy).

    In the plane's rest frame the sun (lab backward direction x̂, u·x̂ = 0) arrives with
    D_out = γ at cos θ = 1/γ; a collimated beam's spectral irradiance goes as D_out³, so
    E_rest(λ) = γ³ (1/γ) E(γ λ). Towards P along the backward lab direction d (d_x < 0,
    d_y < 0: the quarter sphere the wall faces and the plane fills) the plane sends
    D_u⁵ L_rest(D_u λ), D_u = 1/(γ (1 + u d_y)), L_rest = ρ_B E_rest / π. The wall
    reflects ρ_w/π ∫ L (-d_y) dω; at rest the integral is ρ_B E(λ)/π · π/2.
    """
    from relray.core.physics import spectrum

    g = 1.0 / math.sqrt(1.0 - u * u)
    lam = spectrum.sensor_nm()
    cmf = spectrum.sensor_response("cie1931").astype(np.float64)  # (3, nλ)
    grid = spectrum.grid_nm()
    sun = spectrum.rgb_illuminant(np.ones(3)).astype(np.float64)
    e = lambda x: np.interp(np.log(x), np.log(grid), sun)  # noqa: E731
    # the quarter sphere d_x < 0, d_y < 0 by midpoint quadrature in (cos θ_y, φ)
    n = 400
    c = -(np.arange(n) + 0.5) / n                       # d_y = c ∈ (-1, 0)
    D = 1.0 / (g * (1.0 + u * c))                       # D_u per direction
    # ∫ over φ of the half with d_x < 0 is π for every d_y: weight (-d_y) · π · dc
    w = (-c) * math.pi / n
    moving = np.array([[np.sum(w * D**5 * g**2 * e(g * D * L)) for L in lam]])[0]
    static = e(lam) * math.pi / 2.0
    return (cmf * moving).sum(axis=1) / (cmf * static).sum(axis=1)


def test_light_bounced_off_a_moving_body_onto_a_static_wall(tmp_path):
    """The wall's colour and brightness through a moving diffuse body at 0.5 c, against
    the independent estimate above: per XYZ channel, the ratio moving / at rest within
    5 σ (pixel scatter of both renders) plus the quadrature's and the finite plane's
    share (< 1e-3: the plane, 400 wide, misses 1/400 of the directions near grazing)."""
    u = 0.5
    moving = render(moving_bounce_job(u), tmp_path / "moving")
    rest = render(moving_bounce_job(0.0), tmp_path / "rest")
    a = moving.sensor.reshape(-1, 3)
    b = rest.sensor.reshape(-1, 3)
    ratio = a.mean(axis=0) / b.mean(axis=0)
    rel = np.hypot(a.std(axis=0, ddof=1) / a.mean(axis=0), b.std(axis=0, ddof=1) / b.mean(axis=0))
    sigma = ratio * rel / math.sqrt(len(a))
    expected = bounce_ratio_expected(u)
    assert np.all(np.abs(ratio - expected) <= 5 * sigma + 1e-3 * expected), (ratio, expected,
                                                                             sigma)
    assert expected[2] / expected[0] > 1.2  # the test can tell colour: blueshifted light


def test_many_velocity_groups_each_seen_where_its_light_left_it(tmp_path):
    """16 glowing spheres, each with its own velocity (16 groups), placed so that the
    light reaching the camera at t = 0 left each one straight ahead of a pixel column:
    every sphere is seen at its column, whatever its speed (0 … 0.95 c, across the
    view). Coverage per column block: each sphere covers its own block, within a pixel."""
    n, dist = 16, 30.0
    speeds = np.linspace(0.0, 0.95, n)
    width = 8 * n
    t = math.tan(math.radians(90.0) / 2)
    objects = []
    for k, b in enumerate(speeds):
        x = ((k + 0.5) / n * 2.0 - 1.0) * t * dist   # where it is seen, at depth dist
        # emitted at t_e = -|(x, dist)|, then it moved on at b along +x for |t_e|
        objects.append({"shape": "sphere", "radius": 0.6, "subdivisions": 3,
                        "material": "glow",
                        "center": [x + b * math.hypot(x, dist), dist, 0.0],
                        "velocity": [float(b), 0.0, 0.0]})
    job = base_job(render={"width": width, "height": 8, "spp": 4},
                   camera={"fov": 2 * math.degrees(math.atan(t * 8 / width))},
                   materials=[{"name": "glow", "base_color": [0, 0, 0],
                               "emission": [1, 1, 1], "emission_strength": 1.0}],
                   objects=objects)
    r = render(job, tmp_path)
    cols = r.alpha.sum(axis=0)
    centres = [(np.arange(8 * k, 8 * k + 8) + 0.5) @ cols[8 * k:8 * k + 8]
               / cols[8 * k:8 * k + 8].sum() for k in range(n)]
    np.testing.assert_allclose(centres, (np.arange(n) + 0.5) * 8, atol=1.0)


# ------------------------------------------------------- a rod along the line of sight

def retarded_distance(c: np.ndarray, u: np.ndarray) -> float:
    """Lab distance s at which a point moving as c + u t is seen from the origin at t = 0:
    |c - u s| = s (emitted at t = -s)."""
    a = 1.0 - u @ u
    b = 2.0 * (c @ u)
    return float((-b + math.sqrt(b * b + 4.0 * a * (c @ c))) / (2.0 * a))


@pytest.mark.parametrize("b", [0.5, -0.5])
def test_a_rod_along_the_line_of_sight_looks_longer_approaching(tmp_path, b):
    """physics.md: a rod along the line of sight appears √((1+β)/(1-β)) times its rest
    length: 1.732 approaching (β = 0.5 towards the camera), 0.577 receding. The rod's ends
    are two small glowing plates (rest length L = 4 apart along the view, ±0.5 aside so
    both are seen); the Depth AOV gives each end's apparent distance. Checked: each
    end's depth against its light-travel-time solution (float32 ray precision, 1e-4 of
    the distance), and the apparent length over L against the formula (the ends are
    seen 1.4° off the axis: that changes the ratio by < 1e-3)."""
    L, g = 4.0, 1.0 / math.sqrt(1.0 - b * b)
    u = np.array([0.0, -b, 0.0])
    # lab positions at t = 0 (the lab sees the rod contracted: L/γ); the near end is seen
    # 20 away (|c - u s| = s on the axis: c_y = 20 (1 - β))
    near = np.array([-0.5, 20.0 * (1.0 - b), 0.0])
    far = near + np.array([1.0, L / g, 0.0])
    plate = [[-0.3, 0.0, -0.3], [0.3, 0.0, -0.3], [0.3, 0.0, 0.3], [-0.3, 0.0, 0.3]]
    objects = [{"shape": "quad", "material": "glow", "velocity": u.tolist(),
                "corners": (np.array(plate) + c).tolist()} for c in (near, far)]
    job = base_job(render={"width": 128, "height": 128, "spp": 4},
                   output={"formats": ["exr"], "aovs": ["depth"]}, camera={"fov": 20.0},
                   materials=[{"name": "glow", "base_color": [0, 0, 0],
                               "emission": [1, 1, 1], "emission_strength": 1.0}],
                   objects=objects)
    r = render(job, tmp_path)
    depth = r.image.aovs["depth"]
    full = r.alpha == 1.0
    left, right = full & (np.arange(128) < 64), full & (np.arange(128) >= 64)
    assert left.sum() > 8 and right.sum() > 8
    s_near, s_far = retarded_distance(near, u), retarded_distance(far, u)
    # each plate faces the camera: its depth over its pixels varies by < 1e-4 relative
    np.testing.assert_allclose(np.median(depth[left]), s_near, rtol=2e-4)
    np.testing.assert_allclose(np.median(depth[right]), s_far, rtol=2e-4)
    apparent = (np.median(depth[right]) - np.median(depth[left])) / L
    assert apparent == pytest.approx(math.sqrt((1 + b) / (1 - b)), rel=2e-3)


# ------------------------------------------------------------------- the Terrell cube

FACES = {"front": [[-0.5, -0.5, -0.5], [0.5, -0.5, -0.5], [0.5, -0.5, 0.5], [-0.5, -0.5, 0.5]],
         "trailing": [[-0.5, -0.5, -0.5], [-0.5, 0.5, -0.5], [-0.5, 0.5, 0.5],
                      [-0.5, -0.5, 0.5]],
         "leading": [[0.5, -0.5, -0.5], [0.5, 0.5, -0.5], [0.5, 0.5, 0.5], [0.5, -0.5, 0.5]]}


def face_width(tmp_path, faces: tuple[str, ...], b: float) -> tuple[float, float]:
    """Apparent width (scene units at the cube's distance 200) of some faces of a unit
    cube passing at b along +x, seen straight ahead from a camera at rest, and its σ."""
    dist, w, h, spp = 200.0, 256, 64, 16
    fov = 0.4  # vertical, degrees: the cube spans about 100 columns
    centre = np.array([b * dist, dist, 0.0])  # its light left it straight ahead at t = -200
    job = base_job(render={"width": w, "height": h, "spp": spp, "spectral": "rgb"},
                   camera={"fov": fov},
                   materials=[{"name": "glow", "base_color": [0, 0, 0],
                               "emission": [1, 1, 1], "emission_strength": 1.0}],
                   objects=[{"shape": "quad", "material": "glow", "velocity": [b, 0.0, 0.0],
                             "pivot": centre.tolist(),
                             "corners": (np.array(FACES[face]) + centre).tolist()}
                            for face in faces])
    r = render(job, tmp_path / "_".join(faces))
    rows = r.alpha[h // 2 - 8:h // 2 + 8]          # rows well inside the cube's height
    px = 2.0 * math.tan(math.radians(fov) / 2.0) / h * dist
    widths = rows.sum(axis=1) * px
    sigma = math.sqrt(float((rows * (1 - rows)).sum(axis=1).mean()) / spp) * px
    return float(widths.mean()), sigma


def test_the_terrell_cube_shows_its_trailing_face(tmp_path):
    """physics.md: a distant cube passing perpendicular looks rotated: its facing side is
    a/γ wide and its trailing face, edge-on at rest, β a wide, beside it (the two
    together 1/γ + β); the leading face lies behind the facing side (together no wider
    than the facing side alone). Tolerance: 5 σ of the coverage's sampling error plus
    the perspective of a cube 200 away (its depth changes the scale by 1/400: 0.25 %)."""
    b = 0.6
    g = 1.0 / math.sqrt(1.0 - b * b)
    for faces, expect in ((("front",), 1.0 / g), (("trailing",), b),
                          (("front", "trailing"), 1.0 / g + b),
                          (("front", "leading"), 1.0 / g)):
        width, sigma = face_width(tmp_path, faces, b)
        assert abs(width - expect) <= 5 * sigma + 0.0025 * expect, (faces, width, expect,
                                                                    sigma)


# ------------------------------------------ every BSDF through the rest-frame code path

def test_every_material_moving_at_a_vanishing_speed_renders_as_at_rest(tmp_path):
    """Lambert, rough and smooth conductors and glass, at any depth: moving at 1e-12 c
    (so through the rest-frame path: the boost, both Doppler factors, the NEE Jacobian
    and the lab offsets) each object renders as when it rests, pixel by pixel within
    5 σ of the film's noise (the same random numbers; the rest-frame path rounds
    differently)."""
    mats = [{"name": "lambert", "base_color": [0.7, 0.3, 0.2], "roughness": 1.0},
            {"name": "rough metal", "base_color": [0.9, 0.8, 0.5], "metallic": 1.0,
             "roughness": 0.3},
            {"name": "mirror", "base_color": [0.9, 0.9, 0.9], "metallic": 1.0,
             "roughness": 0.0},
            {"name": "glass", "base_color": [1, 1, 1], "transmission": 1.0, "ior": 1.5,
             "roughness": 0.0},
            {"name": "lamp", "base_color": [0, 0, 0], "emission": [1, 1, 1],
             "emission_strength": 3.0}]
    spheres = [("lambert", [-1.6, 6, 0]), ("rough metal", [-0.5, 6, 0]),
               ("mirror", [0.6, 6, 0]), ("glass", [1.7, 6, 0])]

    def job(v):
        objs = [{"shape": "sphere", "center": c, "radius": 0.5, "subdivisions": 4,
                 "material": m, **({"velocity": [v, 0.0, v]} if v else {})}
                for m, c in spheres]
        objs += [{"shape": "quad", "material": "lambert",
                  "corners": [[-9, -2, -0.5], [9, -2, -0.5], [9, 20, -0.5], [-9, 20, -0.5]]},
                 {"shape": "quad", "material": "lamp",
                  "corners": [[-1, 4, 3], [1, 4, 3], [1, 7, 3], [-1, 7, 3]]}]
        return base_job(render={"width": 48, "height": 24, "spp": 16, "max_depth": 6},
                        camera={"fov": 30.0}, materials=mats, objects=objs,
                        scene={"background": [0.1, 0.1, 0.15]})

    a = render(job(0.0), tmp_path / "rest")
    b = render(job(1e-12), tmp_path / "moving")
    sigma = np.sqrt(a.sigma_y**2 + b.sigma_y**2)[..., None]
    diff = np.abs(a.sensor - b.sensor)
    assert np.all(diff <= 5 * sigma + 1e-5 * np.abs(a.sensor) + 1e-7), float(
        np.max(diff / (sigma + 1e-12)))
    assert np.array_equal(a.alpha > 0, b.alpha > 0)


def test_doppler_off_leaves_the_mirrors_line_in_place(tmp_path):
    """``doppler = false`` applies to bodies as to the camera: the receding mirror's line
    stays at 550 nm (the geometry still moves)."""
    S, lam = mirror_render_switch(tmp_path, 0.1, doppler=False)
    centroid = (S * lam).sum() / S.sum()
    assert abs(centroid - 550.0) <= BANDS[2] / 2 + 0.5, centroid


# ------------------------------------------------------------- moving lights and NEE

def moving_light_job(motion: dict) -> dict:
    """A camera looks down at a static grey floor lit only by a glowing 4×4 panel 2 above
    it that slides at 0.5 c along +x in its own plane (so it is always there)."""
    return base_job(
        render={"width": 24, "height": 24, "spp": 256, "max_depth": 2},
        camera={"position": [0.0, -3.0, 3.0], "look_at": [0.0, 0.0, 0.0], "fov": 40.0},
        materials=[{"name": "floor", "base_color": [0.6, 0.6, 0.6], "roughness": 1.0},
                   {"name": "panel", "base_color": [0, 0, 0], "emission": [1, 1, 1],
                    "emission_strength": 1.0}],
        objects=[{"shape": "quad", "material": "floor",
                  "corners": [[-20, -20, 0], [20, -20, 0], [20, 20, 0], [-20, 20, 0]]},
                 {"shape": "quad", "material": "panel",
                  "corners": [[-2, -2, 2], [2, -2, 2], [2, 2, 2], [-2, 2, 2]], **motion}])


def test_next_event_estimation_towards_a_moving_light_is_unbiased(tmp_path):
    """A light moving at a constant velocity is sampled by next-event estimation in its
    rest frame (with MIS); the same motion given as a worldline of two segments is
    reached by BSDF sampling only. Both estimate the same image: the floor's mean XYZ
    agree within 5 σ (the scatter of the per-pixel differences: both images share the
    floor's shading, which cancels), and NEE is the less noisy of the two."""
    u = 0.5
    nee = render(moving_light_job({"velocity": [u, 0.0, 0.0]}), tmp_path / "nee")
    bsdf = render(moving_light_job(
        {"worldline": {"t": [-1000.0, 0.0, 1000.0],
                       "pivot": [[-1000.0 * u, 0.0, 2.0], [0.0, 0.0, 2.0],
                                 [1000.0 * u, 0.0, 2.0]]}}), tmp_path / "bsdf")
    floor = (nee.alpha == 1.0) & (nee.luminance < 5.0)  # leave out the panel itself
    d = nee.sensor[floor] - bsdf.sensor[floor]
    sigma = d.std(axis=0, ddof=1) / math.sqrt(len(d))
    assert np.all(np.abs(d.mean(axis=0)) <= 5 * sigma), (d.mean(axis=0), sigma)
    assert np.median(nee.sigma_y[floor]) < 0.7 * np.median(bsdf.sigma_y[floor])
