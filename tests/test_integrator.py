"""core/render/integrator.py: area lights are lights, not geometry (as in Blender Cycles).

A job's ``[[lights]]`` area light is an emissive one-sided rectangle that no BVH holds:
it casts no shadow (shadow rays of every light pass it), it is nothing from behind (rays
pass it), and a ray crossing its front adds its radiance L = P/(πA), MIS-weighted against
next-event estimation, and goes on (Cycles: kernel/light/area.h area_light_intersect is
one-sided, kernel/integrator/shade_light.h continues the path through a light as a
transparent bounce, and lights are not in the BVH that shadow rays test). A quad object
with the same emissive material stays geometry: the contrast renders below show what the
area light must not do.

Every expectation is analytic (form factors of a rectangle, a sun's or a point light's
irradiance, emission seen straight on), written out here or in render_helpers.py, not
taken from core. Tolerances are Monte Carlo errors: σ_p of each pixel from the film's
``rel_error``; every pixel within 6σ_p (σ estimated from 32 samples: t-tails) and the sum
of the z-scores within 5√N; in ``rgb`` mode with max_depth 1 (emission only, no random
choice but the pixel jitter) pixels away from the light's outline are exact to float32.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from render_helpers import (
    base_job,
    camera_axes,
    make_job,
    pixel_average,
    rectangle_form_factor,
    render,
    zscore,
)

from relray.core.physics import spectrum
from relray.core.render import frames, integrator
from relray.core.scene.geometry import build_scene, scene_from_parts

RHO = 0.5  # the grey floor (a flat sigmoid spectrum)
SUN = np.array([0.3, 0.2, -1.0])  # where the sun's light goes
SUN_E = 2.0  # its irradiance, W/m²
POINT = np.array([0.0, 0.0, 1.5])
POINT_W = 50.0  # I = P / (4π) (Blender's W)
FLOOR = {"shape": "quad", "material": "floor",
         "corners": [[-40, -40, 0], [40, -40, 0], [40, 40, 0], [-40, 40, 0]]}
FLOOR_CAM = {"position": [0.0, -3.0, 1.0], "look_at": [0.0, 0.0, 0.0], "fov": 30.0}


def assert_within_mc_error(r, expected: np.ndarray) -> None:
    """Every pixel's luminance within 6σ_p of ``expected``, the z-score sum within 5√N."""
    z = zscore(r.luminance, expected, r.sigma_y)
    assert np.all(np.abs(z) <= 6.0), np.max(np.abs(z))
    assert abs(z.sum()) <= 5.0 * math.sqrt(z.size), z.mean()


def floor_points(cam: dict):
    """f(d_cam) -> the floor points z = 0 the camera's rays reach (β = 0), and the
    camera's axes."""
    c = np.asarray(cam["position"], float)

    def points(d):
        t = -c[2] / d[..., 2]
        return c + t[..., None] * d
    return points, camera_axes(c, cam["look_at"], cam.get("up", [0, 0, 1]))


def direct(P: np.ndarray, kind: str) -> np.ndarray:
    """Luminance of the grey floor at points P lit by the sun or the point light alone:
    ρ/π E cos θ, and ρ/π I cos θ / r² (white lights: D65 with Y = 1)."""
    if kind == "sun":
        return RHO / np.pi * SUN_E * (-SUN[2] / np.linalg.norm(SUN)) * np.ones(P.shape[:-1])
    q = POINT - P
    r2 = (q * q).sum(-1)
    return RHO / np.pi * POINT_W / (4.0 * np.pi) * (q[..., 2] / np.sqrt(r2)) / r2


def in_rectangle(P, w, z, x0, x1, y0, y1) -> np.ndarray:
    """Whether the ray P + s w (s > 0) crosses the horizontal rectangle [x0, x1] × [y0, y1]
    at height z."""
    s = (z - P[..., 2]) / w[..., 2]
    Q = P + s[..., None] * w
    return (s > 0) & (Q[..., 0] >= x0) & (Q[..., 0] <= x1) & (Q[..., 1] >= y0) & \
        (Q[..., 1] <= y1)


# the rectangle between the lights and the floor (tests a): centre, size, height; the
# camera under it looks straight down (so it sees the floor only, not the light's front)
BLOCK_C, BLOCK_S, BLOCK_Z = (0.2, 0.3), (0.8, 0.6), 0.75
DOWN_CAM = {"position": [0.4, 0.45, 0.6], "look_at": [0.4, 0.45, 0.0], "up": [0, 1, 0],
            "fov": 100.0}


@pytest.mark.parametrize("kind", ["sun", "point"])
def test_an_area_light_casts_no_shadow(tmp_path, kind):
    """A sun or a point light over a grey floor (ρ = 0.5) and, between them, an area light
    facing up (its back to the floor, its front to the black sky): the floor's radiance is
    the light's alone, ρ/π E cos θ or ρ/π I cos θ/r², also in the rectangle's would-be
    shadow, as in Cycles, where shadow rays do not see lights. The same rectangle as a quad
    object with the same emissive material (geometry) does shadow that region: there the
    render is under half the expected value (only the black sky and the quad's back are
    left to reach). max_depth 2, 32 spp, 24 × 24 pixels; the expectation is the pixel mean
    (16 × 16 sub-grid) of the analytic radiance. Catches area lights in the BVH that
    shadow rays test.
    """
    W = H = 24
    (cx, cy), (sx, sy) = BLOCK_C, BLOCK_S
    x0, x1, y0, y1 = cx - sx / 2, cx + sx / 2, cy - sy / 2, cy + sy / 2
    lamp = ({"type": "sun", "direction": SUN.tolist(), "power": SUN_E} if kind == "sun"
            else {"type": "point", "position": POINT.tolist(), "power": POINT_W})
    mats = [{"name": "floor", "base_color": [RHO] * 3, "roughness": 1.0}]
    render_keys = {"width": W, "height": H, "spp": 32, "max_depth": 2}
    area = {"type": "area", "position": [cx, cy, BLOCK_Z], "direction": [0, 0, 1],
            "up": [0, 1, 0], "size": [sx, sy], "power": 10.0}
    r = render(base_job(render=render_keys, camera=DOWN_CAM, materials=mats,
                        objects=[FLOOR], lights=[lamp, area]), tmp_path)
    points, axes = floor_points(DOWN_CAM)
    fov = DOWN_CAM["fov"]
    expected, _ = pixel_average(lambda d: direct(points(d), kind), W, H, fov, axes)
    assert np.all(r.alpha == 1.0)
    assert_within_mc_error(r, expected)

    def shadowed(d):
        P = points(d)
        w = -SUN / np.linalg.norm(SUN) * np.ones_like(P) if kind == "sun" else POINT - P
        return in_rectangle(P, w, BLOCK_Z, x0, x1, y0, y1).astype(float)
    shadow, _ = pixel_average(shadowed, W, H, fov, axes)
    assert (shadow == 1.0).sum() >= 20  # the would-be shadow is in view
    # the same rectangle as geometry: normal (c1-c0)x(c2-c0) = +z, as the light's
    mats.append({"name": "lamp", "base_color": [0.0, 0.0, 0.0], "emission": [1, 1, 1],
                 "emission_strength": 10.0 / (math.pi * sx * sy),
                 "one_sided_emission": True})
    quad = {"shape": "quad", "material": "lamp", "corners": [
        [x0, y0, BLOCK_Z], [x1, y0, BLOCK_Z], [x1, y1, BLOCK_Z], [x0, y1, BLOCK_Z]]}
    g = render(base_job(render=render_keys, camera=DOWN_CAM, materials=mats,
                        objects=[FLOOR, quad], lights=[lamp]), tmp_path)
    dark = shadow == 1.0
    assert np.all(g.luminance[dark] < 0.5 * expected[dark])
    assert np.all(r.luminance[dark] > 0.5 * expected[dark])


# the area lights over the floor (test d): (half width, half height, height, radiance)
UPPER = (0.6, 0.6, 1.5, 3.0)
LOWER = (0.3, 0.2, 1.1, 2.0)
PANEL = (4.0, 4.0, 1.5, 1.0)  # large: BSDF sampling carries most of its light


def area_light(a: float, b: float, h: float, L_e: float) -> dict:
    """A [[lights]] area light of 2a × 2b at height h over the origin, facing down, of
    radiance L_e (white): power P = π A L_e."""
    return {"type": "area", "position": [0.0, 0.0, h], "direction": [0, 0, -1],
            "size": [2 * a, 2 * b], "up": [0, 1, 0], "power": math.pi * 4 * a * b * L_e}


def area_radiance(P: np.ndarray, a: float, b: float, h: float, L_e: float) -> np.ndarray:
    """ρ L_e F: the grey floor's radiance at P under one such light (form factor F)."""
    return RHO * L_e * rectangle_form_factor(P[..., 0], P[..., 1], h, -a, a, -b, b)


@pytest.mark.parametrize("case", ["sun-through-light", "stacked", "moving-scene",
                                  "on-ceiling"])
def test_area_light_on_a_floor_matches_its_form_factor(tmp_path, case):
    """Energy of an area light: a grey floor (ρ = 0.5) under a 1.2 m square area light of
    radiance 3 facing down at 1.5 m has radiance ρ L_e F (F: the rectangle's form factor).

    sun-through-light: plus a sun shining through the light (no shadow): + ρ/π E cos θ.
    stacked: plus a smaller light (0.6 × 0.4, L_e = 2) 0.4 m below it, also facing down:
    the floor sees both, the upper one through the lower one, so a BSDF-sampled ray
    crosses two lights and adds each with its own MIS weight; the expectation is the sum.
    moving-scene: sun-through-light with a sphere moving at 0.5 c far behind the camera,
    out of every path that counts at max_depth 2: the same values, traced through the
    moving scene's BVHs (rays with lab times; the lights are in none of them).
    on-ceiling: an 8 m square light of radiance 1 lies in the plane of a grey ceiling at
    1.5 m (as an artist mounts one), without the sun: ρ L_e F again (the ceiling's own
    light needs a third segment). A BSDF ray meets the light and the ceiling at the same
    distance up to rounding; the light must count (as it does for the shadow ray of
    NEE, which stops short of the ceiling), or MIS loses part of the BSDF share, which
    is most of this large light's light (measured: 20 % of such rays lost without the
    ray-offset tolerance of integrator.shade).
    max_depth 2 (camera -> floor -> light: NEE and BSDF sampling with MIS), 32 spp; pixel
    means (16 × 16 sub-grid). Catches a light counted twice or not at all along a ray, MIS
    weights with the wrong distance or cosine, the wrong L = P/(πA), a shadow of the
    light, and the upper light hidden by the lower one.
    """
    W = H = 24
    main = PANEL if case == "on-ceiling" else UPPER
    lights = [area_light(*main)]
    objects = [FLOOR]
    if case == "stacked":
        lights.append(area_light(*LOWER))
    elif case == "on-ceiling":
        h = UPPER[2]
        objects.append({"shape": "quad", "material": "floor", "corners": [
            [-40, -40, h], [40, -40, h], [40, 40, h], [-40, 40, h]]})
    else:
        lights.append({"type": "sun", "direction": SUN.tolist(), "power": SUN_E})
    if case == "moving-scene":
        objects.append({"shape": "sphere", "center": [0.0, -30.0, 30.0], "radius": 0.5,
                        "material": "floor", "velocity": [0.5, 0.0, 0.0]})
    job = base_job(render={"width": W, "height": H, "spp": 32, "max_depth": 2},
                   camera=FLOOR_CAM, objects=objects, lights=lights,
                   materials=[{"name": "floor", "base_color": [RHO] * 3, "roughness": 1.0}])
    r = render(job, tmp_path)
    points, axes = floor_points(FLOOR_CAM)

    def f(d):
        P = points(d)
        second = (area_radiance(P, *LOWER) if case == "stacked" else
                  0.0 if case == "on-ceiling" else direct(P, "sun"))
        return area_radiance(P, *main) + second
    expected, _ = pixel_average(f, W, H, 30.0, axes)
    assert np.all(r.alpha == 1.0)
    assert_within_mc_error(r, expected)
    assert expected.max() / expected.min() > (1.1 if case == "on-ceiling" else 1.5)


# camera -> area light (at y = 0, 1.2 m square) -> wall (y = 2): the light's back or front
WALL = {"shape": "quad", "material": "wall",
        "corners": [[-40, 2, -40], [40, 2, -40], [40, 2, 40], [-40, 2, 40]]}
WALL_CAM = {"position": [0.0, -2.0, 0.0], "look_at": [0.0, 2.0, 0.0], "fov": 60.0}
HALF = 0.6


def through_light(d: np.ndarray) -> np.ndarray:
    """Whether the camera ray d (from WALL_CAM) crosses the light's square at y = 0."""
    s = 2.0 / d[..., 1]
    x, z = s * d[..., 0], s * d[..., 2]
    return ((np.abs(x) <= HALF) & (np.abs(z) <= HALF)).astype(float)


def test_the_back_of_an_area_light_shows_what_is_behind_it(tmp_path):
    """The camera looks at the back of an area light (1.2 m square, radiance 3, white) that
    lights a coloured wall (ρ = (0.8, 0.4, 0.2)) 2 m behind it: every pixel, through the
    light or beside it, shows the wall, ρ L_e F (the form factor from the wall point to
    the light, parallel planes 2 m apart), and the light's back adds nothing; alpha is 1
    and the depth AOV is the wall's distance. ``rgb`` mode: G is the luminance channel
    (6σ_p per pixel, z-score sum within 5√N); R/G and B/G are ρ's ratios exactly, as every
    sample is the wall's colour times one white quantity. As geometry (the old behaviour)
    the square hid the wall: black pixels.
    """
    W = H = 24
    L_e = 3.0
    light = {"type": "area", "position": [0, 0, 0], "direction": [0, 1, 0], "up": [0, 0, 1],
             "size": [2 * HALF, 2 * HALF], "power": math.pi * (2 * HALF) ** 2 * L_e}
    rho = (0.8, 0.4, 0.2)
    job = base_job(render={"width": W, "height": H, "spp": 32, "max_depth": 2,
                           "spectral": "rgb"},
                   camera=WALL_CAM, objects=[WALL], lights=[light],
                   materials=[{"name": "wall", "base_color": list(rho), "roughness": 1.0}])
    r = render(job, tmp_path)
    c = np.asarray(WALL_CAM["position"], float)
    axes = camera_axes(c, WALL_CAM["look_at"], [0, 0, 1])

    def wall_f(d):
        s = 4.0 / d[..., 1]
        return rectangle_form_factor(s * d[..., 0], s * d[..., 2], 2.0, -HALF, HALF, -HALF,
                                     HALF)
    F, _ = pixel_average(wall_f, W, H, 60.0, axes)
    covered, _ = pixel_average(through_light, W, H, 60.0, axes)
    assert (covered == 1.0).sum() >= 50 and (covered == 0.0).sum() >= 50
    assert np.all(r.alpha == 1.0)
    assert_within_mc_error(r, rho[1] * L_e * F)
    rgb = r.rgb
    np.testing.assert_allclose(rgb[..., 0], 2.0 * rgb[..., 1], rtol=1e-5)
    np.testing.assert_allclose(rgb[..., 2], 0.5 * rgb[..., 1], rtol=1e-5)
    # the depth AOV: a mean of 32 jittered samples of 4/d_y over the pixel (6σ of its
    # spread within the pixel, sd/√32), not the light's distance (about half of it)
    depth, sd = pixel_average(lambda d: 4.0 / d[..., 1], W, H, 60.0, axes)
    assert np.all(np.abs(r.image.aovs["depth"] - depth) <= 6.0 * sd / math.sqrt(32) + 1e-5)


@pytest.mark.parametrize("spectral", ["rgb", "cie1931"])
def test_the_front_of_an_area_light_has_radiance_p_over_pi_a_and_the_ray_goes_on(
        tmp_path, spectral):
    """The camera looks at the front of a 1.2 m square area light of power P (white) in
    front of an emissive wall (radiance 0.25 · (1, 2, 3) in rgb, white 0.5 in cie1931);
    max_depth 1 (emission only). A pixel whose rays all cross the light sees
    L = P/(πA) + the wall (the ray goes on through the light, as Cycles' shade_light
    continues the path), a pixel beside it the wall alone. rgb: exact (float32) for those
    pixels; cie1931: luminance within 6σ_p (hero wavelengths are the only noise) and the
    z-score sum within 5√N. Catches L ≠ P/(πA), a path that ends at the light, a light
    seen twice.
    """
    W = H = 24
    P_w = 20.0
    L_e = P_w / (math.pi * (2 * HALF) ** 2)
    light = {"type": "area", "position": [0, 0, 0], "direction": [0, -1, 0], "up": [0, 0, 1],
             "size": [2 * HALF, 2 * HALF], "power": P_w}
    wall_L = np.array([0.25, 0.5, 0.75]) if spectral == "rgb" else np.full(3, 0.5)
    job = base_job(render={"width": W, "height": H, "spp": 32, "max_depth": 1,
                           "spectral": spectral},
                   camera=WALL_CAM, objects=[WALL], lights=[light],
                   materials=[{"name": "wall", "base_color": [0.0, 0.0, 0.0],
                               "emission": (wall_L / wall_L.max()).tolist(),
                               "emission_strength": float(wall_L.max())}])
    r = render(job, tmp_path)
    axes = camera_axes(np.asarray(WALL_CAM["position"], float), WALL_CAM["look_at"], [0, 0, 1])
    covered, _ = pixel_average(through_light, W, H, 60.0, axes)
    inside, outside = covered == 1.0, covered == 0.0
    assert inside.sum() >= 50 and outside.sum() >= 50
    assert np.all(r.alpha == 1.0)
    if spectral == "rgb":
        np.testing.assert_allclose(r.rgb[inside], np.broadcast_to(L_e + wall_L, (inside.sum(), 3)),
                                   rtol=1e-5)
        np.testing.assert_allclose(r.rgb[outside], np.broadcast_to(wall_L, (outside.sum(), 3)),
                                   rtol=1e-5)
    else:
        expected = 0.5 + L_e * covered
        edge = ~(inside | outside)  # partly covered pixels: jitter noise, not in the test
        z = zscore(r.luminance, expected, r.sigma_y)[~edge]
        assert np.all(np.abs(z) <= 6.0), np.max(np.abs(z))
        assert abs(z.sum()) <= 5.0 * math.sqrt(z.size), z.mean()


def test_a_scene_of_area_lights_only_has_no_geometry(tmp_path):
    """A scene of nothing but an area light facing the camera (as the Blender add-on may
    export through scene_from_parts; a job needs an object): no BVH at all. Rays through
    its square see L = P/(πA) exactly (rgb, max_depth 1), the others the black sky; alpha
    is 0 everywhere, since a light is not a surface (in Cycles the film's alpha comes from
    the background the path reaches, and a light does not stop the path)."""
    W = H = 24
    P_w = 20.0
    light = {"type": "area", "position": [0, 0, 0], "direction": [0, -1, 0], "up": [0, 0, 1],
             "size": [2 * HALF, 2 * HALF], "power": P_w}
    job = base_job(render={"width": W, "height": H, "spp": 8, "max_depth": 1,
                           "spectral": "rgb"}, camera=WALL_CAM, lights=[light],
                   materials=[{"name": "m"}],
                   objects=[{"shape": "sphere", "center": [0, 0, 0], "radius": 1,
                             "material": "m"}])
    lights_only = scene_from_parts(np.zeros((0, 3, 3)), None, np.zeros(0, np.int32), [],
                                   make_job(job, tmp_path).scene.lights, (0.0, 0.0, 0.0))
    assert lights_only.n_geometry == 0 and lights_only.light_triangles == 2
    r = render(job, tmp_path, scene=lights_only)
    axes = camera_axes(np.asarray(WALL_CAM["position"], float), WALL_CAM["look_at"], [0, 0, 1])
    covered, _ = pixel_average(through_light, W, H, 60.0, axes)
    inside, outside = covered == 1.0, covered == 0.0
    assert inside.sum() >= 50 and outside.sum() >= 50
    assert np.all(r.alpha == 0.0)
    np.testing.assert_allclose(r.rgb[inside], P_w / (math.pi * (2 * HALF) ** 2), rtol=1e-5)
    assert np.all(r.rgb[outside] == 0.0)


def test_an_area_light_reads_a_pending_doppler_shift_as_the_shifted_lanes(tmp_path):
    """A ray that left a moving body keeps its lanes' D_out shift pending
    (``Paths.pend``, integrator.pending_shift) until its next hit; an area light it
    crosses on the way must see the lab lanes: the same radiance as from lanes shifted
    at once (lamu + ln(D)·INV_DLOG, its columns, nothing pending), for D above and below
    1, to float32 rounding. Catches a light read at the body's rest-frame lanes."""
    light = {"type": "area", "position": [0, 0, 0], "direction": [0, -1, 0], "up": [0, 0, 1],
             "size": [2 * HALF, 2 * HALF], "power": 20.0}
    job = make_job(base_job(render={"width": 8, "height": 8, "spp": 1,
                                    "spectral": "cie1931"},
                            camera=WALL_CAM, objects=[WALL], lights=[light],
                            materials=[{"name": "wall", "base_color": [0.5, 0.5, 0.5]}]),
                   tmp_path)
    prep = frames.prepare(build_scene(job), "cie1931")
    sc = prep.kernel
    n = 64
    rng = np.random.default_rng(5)
    aim = np.column_stack([rng.uniform(-0.5, 0.5, n), np.zeros(n), rng.uniform(-0.5, 0.5, n)])
    x0 = np.array(WALL_CAM["position"], float)
    d = aim - x0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.ascontiguousarray(np.broadcast_to(x0 - prep.origin, (n, 3)), np.float32)
    hits = prep.tracer.intersect(o, d.astype(np.float32))
    lam0 = rng.uniform(400.0, 700.0, (n, 4))
    lamu0 = spectrum.grid_coordinates(lam0).astype(np.float32)
    D = rng.choice([0.7, 1.4], n)
    shift = (np.log(D) * spectrum.INV_DLOG)[:, None]

    def paths(lamu, pend):
        li, lf = np.empty((n, 4), np.int32), np.empty((n, 4), np.float32)
        integrator.column_split(lamu, sc.emit.shape[1], li, lf)
        z = np.zeros(n, np.float32)
        return integrator.Paths(
            np.arange(n, dtype=np.uint64), np.zeros((n, 4), np.float32),
            np.ones((n, 4), np.float32), li, lf, z, np.ones(n, np.int32),
            np.full(n, -1, np.int32), np.zeros((n, 4), np.float32),
            np.ascontiguousarray(lamu, np.float32), np.ones(n, np.int32),
            np.zeros((n, 2), np.float32), np.ascontiguousarray(pend, np.float64))

    rays = integrator.Rays(np.arange(n, dtype=np.int64), o, d.astype(np.float32),
                           np.zeros(n), np.full(n, -1, np.int32), np.zeros((n, 7), np.float32))
    hits = hits._replace(seg=np.full(n, -1, np.int32))
    at_once = paths(lamu0 + shift, np.ones(n))
    pending = paths(lamu0, D)
    integrator.cross_area_lights(sc, at_once, rays, hits, n, 0, 4)
    integrator.cross_area_lights(sc, pending, rays, hits, n, 0, 4)
    assert np.all(at_once.L.sum(axis=1) > 0.0)  # every ray crossed the light
    np.testing.assert_allclose(pending.L, at_once.L, rtol=2e-5)


def test_a_triangles_record_holds_its_tables_rows_in_one_aligned_cache_line():
    """integrator.triangle_records: the SIMD lanes read a hit's triangle from one 64-byte
    row (v0, e1, e2, ng, area, light pmf, material), equal to the tables the other kernels
    read, each row on a 64-byte boundary; a material index float32 cannot hold is
    refused."""
    rng = np.random.default_rng(3)
    tris = rng.normal(size=(1000, 3, 3))
    geo = integrator.triangle_geometry(tris, np.array([0.5, -1.0, 2.0]))
    mats = rng.integers(0, 40, 1000).astype(np.int32)
    mats[-1] = (1 << 24) - 1  # the largest index float32 holds exactly
    pmf = rng.random(1000).astype(np.float32)
    rec = integrator.triangle_records(geo, mats, pmf)
    assert rec.shape == (1000, 16) and rec.dtype == np.float32
    assert rec.ctypes.data % 64 == 0 and rec.strides == (64, 4)
    for col, key in ((integrator.REC_V0, "v0"), (integrator.REC_E1, "e1"),
                     (integrator.REC_E2, "e2"), (integrator.REC_NG, "ng")):
        np.testing.assert_array_equal(rec[:, col:col + 3], geo[key])
    np.testing.assert_array_equal(rec[:, integrator.REC_AREA], geo["area"])
    np.testing.assert_array_equal(rec[:, integrator.REC_PMF], pmf)
    np.testing.assert_array_equal(rec[:, integrator.REC_MAT].astype(np.int64), mats)
    mats[0] = 1 << 24
    with pytest.raises(ValueError, match="2\\*\\*24"):
        integrator.triangle_records(geo, mats, pmf)
