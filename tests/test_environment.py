"""Environment maps (core/render/environment.py, scene.environment): orientation, the
furnace, NEE + MIS against a quadrature, a moving camera's D⁵ L_lab(Dλ), bad input.

The maps are small EXR files written here with OpenImageIO (top row first, as files
store them; the reader turns them bottom row first). Expected values are computed in
the tests from the contract (job-format.md "Skies": φ = π − 2πu + rotation_z, θ = π(1 − v)
from +Z; texels are RGB emitters k·s(λ)·D65_ext(λ), physics.md), not with the renderer's
own direction maps or spectra.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest
from numba import njit
from render_helpers import (
    aberrate,
    base_job,
    camera_axes,
    doppler,
    pixel_average,
    pixel_to_pixelcoords,
    render,
    zscore,
)

from relray.core.physics import rgb_table, spectrum
from relray.core.render import environment
from relray.core.scene.job import job_summary, parse_job

GREY = {"name": "grey", "base_color": [0.5, 0.5, 0.5], "roughness": 1.0}
FAR_SPECK = {"shape": "sphere", "center": [0.0, -1000.0, 0.0], "radius": 0.01,
             "subdivisions": 0, "material": "grey"}


def write_map(path, rgb_bottom_first: np.ndarray):
    """An EXR of the map given bottom row first (row 0 = v = 0)."""
    px = np.ascontiguousarray(np.asarray(rgb_bottom_first, np.float32)[::-1])
    h, w, c = px.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, oiio.FLOAT))
    assert out.write_image(px)
    out.close()
    return path


def write_spectral_map(path, nm, bands_bottom_first, extra=()):
    """A spectral EXR in the Fichet et al. 2021 layout: channel ``S0.<λ>nm`` (decimal
    comma) per wavelength of ``nm``, the cube given bottom row first (H, W, B); ``extra``
    adds (name, value) channels of a constant value (e.g. R, G, B to be ignored)."""
    cube = np.asarray(bands_bottom_first, np.float32)[::-1]
    h, w, b = cube.shape
    names = ["S0." + f"{lam:.6f}".replace(".", ",") + "nm" for lam in nm]
    planes = [cube[..., k] for k in range(b)] + [np.full((h, w), v, np.float32)
                                                for _, v in extra]
    names += [n for n, _ in extra]
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    assert out.write_image(np.ascontiguousarray(np.stack(planes, axis=2)))
    out.close()
    return path


def planck_map(T: float, h: int, w: int, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths, cube): B(λ, T) / B(550 nm, T) at n wavelengths log-spaced over
    150 nm – 12 µm, the same in every texel."""
    nm = np.geomspace(150.0, 12000.0, n)
    values = spectrum.planck(nm, T) / spectrum.planck(550.0, T)
    return nm, np.broadcast_to(values, (h, w, n))


def direction_of(u: float, v: float, rot_deg: float = 0.0) -> np.ndarray:
    """The contract's direction of map coordinates (u, v)."""
    phi = math.pi - 2.0 * math.pi * u + math.radians(rot_deg)
    theta = math.pi * (1.0 - v)
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                     math.cos(theta)])


def emitter_spectrum(rgb, lam: np.ndarray) -> np.ndarray:
    """k·s(λ)·D65_ext(λ) of an RGB emitter texel (physics.md), evaluated here."""
    rgb = np.asarray(rgb, float)
    k = 2.0 * rgb.max()
    c0, c1, c2 = rgb_table.coefficients(rgb / k).astype(np.float64)
    t = (np.clip(lam, 380.0, 720.0) - 380.0) / 340.0
    x = (c0 * t + c1) * t + c2
    s = 0.5 + 0.5 * x / np.sqrt(1.0 + x * x)
    return k * s * spectrum.lookup(spectrum.d65_ext(), lam)


def sensor_of(L_of_lam, D: np.ndarray) -> np.ndarray:
    """(…, 3) sensor values D⁵ ∫ c̄(λ) L(Dλ) dλ (0.05 nm midpoint rule over 360–830 nm, the
    response linearly interpolated between its 1 nm nodes as the film does)."""
    resp = spectrum.sensor_response("cie1931").astype(np.float64)
    lam = np.arange(360.0, 830.0, 0.05) + 0.025
    cbar = np.stack([np.interp(lam, spectrum.sensor_nm(), r) for r in resp])
    D = np.asarray(D, float)
    L = L_of_lam(D[..., None] * lam)
    return D[..., None] ** 5 * np.einsum("...l,cl->...c", L, cbar) * 0.05


def env_job(tmp_path, rgb_map, **sections):
    write_map(tmp_path / "sky.exr", rgb_map)
    env = {"file": "sky.exr", **sections.pop("environment", {})}
    scene = {"background": [0.0, 0.0, 0.0], "environment": env}
    return base_job(scene=scene, **sections)


# ------------------------------------------------------------------------ orientation


@pytest.mark.parametrize(("rot", "beta"), [(0.0, 0.0), (30.0, 0.0), (-20.0, 0.0),
                                           (30.0, 0.6)])
def test_marker_appears_where_the_contract_says(tmp_path, rot, beta):
    """A one-texel red marker at (u, v) of a 72 × 36 map (5° texels) appears, for a
    camera looking along +Y (fov 100°), centred on the pixel of the contract's direction
    of the texel's centre (within a pixel: the marker spans ~3 pixels); a green marker
    checks up/down (v) separately. Mirrored u, a wrong origin of φ or rotation_z with
    the wrong sign move them by tens of pixels. With the camera moving at β = 0.6 along
    +Y (rgb mode: aberration only) the markers appear at the camera directions whose
    aberrated lab directions are the texels' (the hand-written aberrate of
    render_helpers, inverted here with −β and checked): a lookup by the camera-frame
    direction would leave them where they were at rest, 5–10 pixels away."""
    W, H, fov = 96, 64, 100.0
    m = np.zeros((36, 72, 3))
    r_red, c_red = 21, 15      # v ≈ 0.60, u ≈ 0.215: right of +Y, above the horizon
    r_grn, c_grn = 12, 22      # v ≈ 0.35, u ≈ 0.31: left of +Y, below
    m[r_red, c_red] = (1.0, 0.0, 0.0)
    m[r_grn, c_grn] = (0.0, 1.0, 0.0)
    job = env_job(tmp_path, m, environment={"rotation_z": rot},
                  render={"width": W, "height": H, "spp": 4, "spectral": "rgb"},
                  camera={"fov": fov}, motion={"beta": [0.0, beta, 0.0]},
                  materials=[GREY], objects=[FAR_SPECK])
    r = render(job, tmp_path)
    axes = camera_axes([0, 0, 0], [0, 1, 0], [0, 0, 1])
    for ch, (row, col) in ((0, (r_red, c_red)), (1, (r_grn, c_grn))):
        d_lab = direction_of((col + 0.5) / 72, (row + 0.5) / 36, rot)
        d = aberrate(d_lab, [0.0, -beta, 0.0])
        assert np.allclose(aberrate(d, [0.0, beta, 0.0]), d_lab, atol=1e-12)
        right, up, fwd = axes
        x, y = d @ right / (d @ fwd), d @ up / (d @ fwd)
        pc, pr = pixel_to_pixelcoords(x, y, W, H, fov)
        assert d @ fwd > 0.0 and 3 < pc < W - 3 and 3 < pr < H - 3  # well inside the view
        img = r.rgb[..., ch]
        assert img.max() > 0.5
        rows, cols = np.mgrid[0:H, 0:W] + 0.5
        cr = (img * rows).sum() / img.sum()
        cc = (img * cols).sum() / img.sum()
        assert abs(cr - pr) < 1.0 and abs(cc - pc) < 1.0, (ch, cr, pr, cc, pc)


# ------------------------------------------------------------------------ furnace


@pytest.mark.parametrize("mode", ["rgb", "cie1931", "spectral"])
def test_furnace_convex_body_is_rho_times_l(tmp_path, mode):
    """A diffuse sphere of albedo ρ = 0.5 in a uniform map of radiance L: every pixel on
    it is ρ·L in expectation (a convex body sees only the map: one bounce, depth 2), and
    the map seen directly is L. In cie1931 L is the texel's RGB-emitter spectrum, its Y
    computed here (emitter_spectrum); the grey reflectance is exactly 0.5. "spectral": a
    spectral EXR of a 4000 K blackbody (cie1931), L its Y computed here from Planck's law
    (the map's 400 bands are linearly interpolated: < 1e-4 relative in the visible).
    Tolerance: per pixel |z| ≤ 6 with σ from the film's rel_error, and the mean z over
    the body's pixels within 5/√N (a 1 % bias would fail it)."""
    rgb = np.array([0.8, 0.6, 0.3])
    W, H = 32, 32
    nm, cube = planck_map(4000.0, 8, 16)
    job = env_job(tmp_path, np.broadcast_to(rgb, (8, 16, 3)),
                  render={"width": W, "height": H, "spp": 16, "max_depth": 2,
                          "spectral": "cie1931" if mode == "spectral" else mode},
                  camera={"position": [0.0, -4.0, 0.0], "look_at": [0.0, 0.0, 0.0],
                          "fov": 40.0},
                  materials=[GREY],
                  objects=[{"shape": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0,
                            "subdivisions": 5, "material": "grey"}])
    if mode == "spectral":
        write_spectral_map(tmp_path / "sky.exr", nm, cube)
    r = render(job, tmp_path)
    if mode == "rgb":
        L = rgb[1]
    elif mode == "spectral":
        L = sensor_of(lambda lam: spectrum.planck(lam, 4000.0) / spectrum.planck(550.0, 4000.0),
                      np.ones(1))[0, 1]
    else:
        L = sensor_of(lambda lam: emitter_spectrum(rgb, lam), np.ones(1))[0, 1]
    Y, sig = r.luminance, r.sigma_y
    body = r.alpha == 1.0
    sky = r.alpha == 0.0
    assert body.sum() > 200 and sky.sum() > 200
    z = zscore(Y[body], 0.5 * L, sig[body])
    assert np.all(np.abs(z) <= 6.0), np.abs(z).max()
    assert abs(z.mean()) <= 5.0 / math.sqrt(z.size), z.mean()
    if mode == "rgb":  # no wavelengths: the map seen directly has no noise at all
        assert np.allclose(Y[sky], L, rtol=1e-6)
    else:
        zs = zscore(Y[sky], L, sig[sky])
        assert np.all(np.abs(zs) <= 6.0), np.abs(zs).max()
        assert abs(zs.mean()) <= 5.0 / math.sqrt(zs.size), zs.mean()


# ------------------------------------------------------------------------ NEE + MIS


def test_bright_patch_lights_a_plane_as_the_quadrature_says(tmp_path):
    """A diffuse plane (ρ = 0.5) under a map with a dim sky (0.05) and a bright patch
    (200, 3 × 2 texels of 5°, 20–30° above the horizon): L = ρ E/π, E = Σ over the upper
    hemisphere's texels of L_t ∫ cos θ dω = L_t Δφ (sin² θ₁ − sin² θ₀)/2, summed here
    exactly per texel. rgb mode (the quadrature is per channel); NEE + MIS at every
    pixel, z-scores as in the furnace test. Without MIS weights (or with a wrong pdf) the
    patch is counted twice or not in proportion."""
    m = np.full((36, 72, 3), 0.05)
    m[22:24, 20:23] = (200.0, 150.0, 100.0)
    W, H = 24, 24
    job = env_job(tmp_path, m,
                  render={"width": W, "height": H, "spp": 32, "max_depth": 2,
                          "spectral": "rgb"},
                  camera={"position": [0.0, 0.0, 1.0], "look_at": [0.0, 0.0, 0.0],
                          "up": [0.0, 1.0, 0.0], "fov": 30.0},
                  materials=[GREY],
                  objects=[{"shape": "quad", "corners": [[-50, -50, 0], [50, -50, 0],
                                                         [50, 50, 0], [-50, 50, 0]],
                            "material": "grey"}])
    r = render(job, tmp_path)
    assert np.all(r.alpha == 1.0)
    theta = math.pi * (1.0 - np.arange(37) / 36)  # row edges, row 0 at the bottom
    cos_int = (2.0 * math.pi / 72) * 0.5 * (np.sin(theta[1:]) ** 2 - np.sin(theta[:-1]) ** 2)
    upper = np.arange(36) >= 18
    E = (m[upper] * np.abs(cos_int[upper])[:, None, None]).sum(axis=(0, 1))
    expected = 0.5 * E[1] / math.pi
    z = zscore(r.luminance, expected, r.sigma_y)
    assert np.all(np.abs(z) <= 6.0), np.abs(z).max()
    assert abs(z.mean()) <= 5.0 / math.sqrt(z.size), (r.luminance.mean(), expected)


# ------------------------------------------------------------------------ moving camera


def test_moving_camera_sees_d5_l_lab_of_d_lambda(tmp_path):
    """A uniform orange map seen from a camera at β = (0.4, 0.3, 0): per pixel sensor Y
    = <D⁵ ∫ ȳ(λ) L_lab(Dλ) dλ> over the pixel, L_lab the texel's RGB-emitter spectrum
    k·s(λ)·D65_ext(λ) evaluated here (the band-clamped sigmoid keeps its edge values
    outside 380–720 nm, D65_ext its Planck tail). z-scores as in test_uniform_sky_d5.

    The issue's "a blackbody environment is B(D·T)" check needs a blackbody map: an RGB
    texel is a sigmoid times D65_ext, not a Planck spectrum (its band clamp makes it flat
    outside 380–720 nm), so no texel is a blackbody of any temperature; the D⁵ L(Dλ) law
    it rests on is what this test checks for the RGB emitter instead."""
    W, H, fov = 32, 24, 60.0
    beta = [0.4, 0.3, 0.0]
    rgb = np.array([0.9, 0.5, 0.2])
    job = env_job(tmp_path, np.broadcast_to(rgb, (4, 8, 3)),
                  render={"width": W, "height": H, "spp": 16, "doppler": True,
                          "searchlight": True},
                  camera={"fov": fov}, motion={"beta": beta},
                  materials=[GREY], objects=[FAR_SPECK])
    r = render(job, tmp_path)
    assert np.all(r.alpha == 0.0)
    axes = camera_axes([0, 0, 0], [0, 1, 0], [0, 0, 1])
    Dgrid = np.linspace(0.6, 2.0, 561)
    ygrid = sensor_of(lambda lam: emitter_spectrum(rgb, lam), Dgrid)[:, 1]
    expected, _ = pixel_average(lambda d: np.interp(doppler(d, beta), Dgrid, ygrid),
                                W, H, fov, axes)
    z = zscore(r.luminance, expected, r.sigma_y)
    assert np.all(np.abs(z) <= 6.0), np.abs(z).max()
    assert abs(z.sum()) <= 5.0 * math.sqrt(z.size), z.mean()
    assert expected.max() / expected.min() > 3.0


def test_blackbody_environment_seen_moving_is_b_of_dt(tmp_path):
    """A spectral map of a 5000 K blackbody (B(λ, T)/B(550 nm, T) in every texel, 400
    bands over 150 nm – 12 µm) seen from a camera at β = (0.4, 0.3, 0): every pixel's
    spectral-exr bands (250–2450 nm, 200 nm wide, camera frame) are the band means of
    B(λ, D·T)/B(550 nm, T) averaged over the pixel, D = 1/(γ(1 − β·d')) from 0.86 to 1.67
    across the image (physics.md: D⁵ B(Dλ, T) = B(λ, D·T)); Planck's law evaluated here.

    Statistics: K = 16 independent renders (seeds); per pixel and band the mean and its
    standard error from the K values, z = (mean − expected)/√(sem² + (ε·expected)²), ε
    the largest relative error of the map's linear interpolation of Planck's law over
    the wavelengths looked up (measured here). Every |z| below the Student-t quantile
    (K − 1 degrees of freedom) of a family-wise false-alarm rate of 1e-3 over all values,
    and the mean z within 5 of its standard error. Without the searchlight factor (D⁴)
    the pixels are 10–50 % dark, without Doppler the infrared bands several times off."""
    from scipy import stats
    W, H, fov, K, T = 16, 12, 60.0, 16, 5000.0
    beta = [0.4, 0.3, 0.0]
    bands = [250.0, 2450.0, 200.0]
    nm, cube = planck_map(T, 4, 8)
    write_spectral_map(tmp_path / "sky.exr", nm, cube, extra=(("R", 1.0), ("G", 1.0),
                                                              ("B", 1.0)))
    runs = []
    for seed in range(K):
        job = base_job(scene={"background": [0.0, 0.0, 0.0],
                              "environment": {"file": "sky.exr"}},
                       render={"width": W, "height": H, "spp": 256, "seed": seed,
                               "doppler": True, "searchlight": True},
                       output={"formats": ["spectral-exr"], "spectral_bands": bands},
                       camera={"fov": fov}, motion={"beta": beta},
                       materials=[GREY], objects=[FAR_SPECK])
        r = render(job, tmp_path)
        runs.append(r.image.spectral.astype(np.float64))
    S = np.stack(runs)                       # (K, H, W, nb)
    centres = r.image.band_centers_nm
    axes = camera_axes([0, 0, 0], [0, 1, 0], [0, 0, 1])
    k = (np.arange(40) + 0.5) / 40.0
    b550 = spectrum.planck(550.0, T)

    def band_means(d):
        D = doppler(d, beta)[..., None, None]
        lam = centres[:, None] + (k - 0.5) * bands[2]
        return _planck_dt(lam, D * T).mean(axis=-1) / b550

    expected, _ = pixel_average(band_means, W, H, fov, axes, n_sub=8)   # (H, W, nb)
    D_all = doppler(directions_of_image(W, H, fov, axes), beta)
    assert 0.8 < D_all.min() < 0.9 and 1.6 < D_all.max() < 1.7
    lam_seen = np.geomspace(D_all.min() * bands[0] * 0.99, D_all.max() * bands[1] * 1.01, 4000)
    interp = np.interp(lam_seen, nm, cube[0, 0])
    eps = float(np.max(np.abs(interp / (spectrum.planck(lam_seen, T) / b550) - 1.0)))
    assert eps < 5e-3
    mean = S.mean(axis=0)
    sem = S.std(axis=0, ddof=1) / math.sqrt(K)
    assert np.all(sem > 0.0)
    z = (mean - expected) / np.sqrt(sem**2 + (eps * expected) ** 2)
    limit = stats.t.ppf(1.0 - 1e-3 / (2 * z.size), K - 1)
    assert np.all(np.abs(z) <= limit), (np.abs(z).max(), limit)
    t_sd = math.sqrt((K - 1) / (K - 3))      # the standard deviation of Student's t
    assert abs(z.mean()) <= 5.0 * t_sd / math.sqrt(z.size), z.mean()
    # the test can tell: D⁴ instead of D⁵, or the rest-frame 5000 K, are far outside
    assert np.abs((mean / mean_doppler(W, H, fov, axes, beta)[..., None] - expected)
                  / np.sqrt(sem**2 + (eps * expected) ** 2)).max() > 5 * limit


def _planck_dt(lam: np.ndarray, T: np.ndarray) -> np.ndarray:
    """B(λ, T) for arrays of temperatures (broadcast), Planck's law written here."""
    h, c, kb = 6.62607015e-34, 299792458.0, 1.380649e-23
    lam_m = lam * 1e-9
    return 2.0 * h * c * c / lam_m**5 / np.expm1(h * c / (lam_m * kb * T)) * 1e-9


def directions_of_image(W, H, fov, axes) -> np.ndarray:
    """Unit camera-frame directions through a 4 × 4 sub-grid of every pixel."""
    from render_helpers import directions, ndc
    u = (np.arange(4) + 0.5) / 4
    cols = np.arange(W)[None, :, None, None] + u[None, None, None, :]
    rows = np.arange(H)[:, None, None, None] + u[None, None, :, None]
    cols, rows = np.broadcast_arrays(cols, rows)
    return directions(*ndc(cols, rows, W, H, fov), axes)


def mean_doppler(W, H, fov, axes, beta) -> np.ndarray:
    """Each pixel's mean Doppler factor."""
    return pixel_average(lambda d: doppler(d, beta), W, H, fov, axes, n_sub=8)[0]


def test_spectral_map_is_read_in_the_fichet_layout(tmp_path):
    """Channels S0.<λ><unit> in any order and unit (nm, um, THz: λ = c/ν) are the bands,
    sorted by wavelength; R, G, B beside them are ignored; rows come bottom first."""
    from relray.core.scene import sky
    h, w = 2, 3
    names = ["G", "S0.0,7um", "S0.400nm", "R", "S0.599,584916THz"]  # 700, 400, 500 nm
    data = np.zeros((h, w, len(names)), np.float32)
    for k in range(len(names)):
        data[..., k] = k + 10 * np.arange(h)[::-1, None]   # file's top row: the larger
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    out = oiio.ImageOutput.create(str(tmp_path / "s.exr"))
    assert out.open(str(tmp_path / "s.exr"), spec)
    assert out.write_image(data)
    out.close()
    write_map(tmp_path / "rgb.exr", np.ones((2, 4, 3)))
    for name, want in (("s.exr", True), ("rgb.exr", False)):
        env = parse_job(base_job(scene={"environment": {"file": name}}, materials=[GREY],
                                 objects=[FAR_SPECK]), tmp_path / "job.toml").scene.environment
        image = sky.load_environment(env, tmp_path / "job.toml")
        assert image.spectral is want
    image = sky.load_environment(
        parse_job(base_job(scene={"environment": {"file": "s.exr"}}, materials=[GREY],
                           objects=[FAR_SPECK]), tmp_path / "job.toml").scene.environment,
        tmp_path / "job.toml")
    assert np.allclose(image.wavelengths_nm, [400.0, 500.0, 700.0], rtol=1e-6)
    assert np.array_equal(image.pixels[0, 0], [2.0, 4.0, 1.0])    # bottom row
    assert np.array_equal(image.pixels[1, 0], [12.0, 14.0, 11.0])


def test_band_value_interpolates_and_is_zero_outside():
    nm = np.array([400.0, 500.0, 700.0])
    tex = np.array([[[1.0, 3.0, 2.0]]], np.float32)
    got = [environment.band_value(tex, 0, 0, nm, lam) for lam in
           (399.0, 400.0, 450.0, 500.0, 650.0, 700.0, 701.0)]
    assert got == pytest.approx([0.0, 1.0, 2.0, 3.0, 2.25, 2.0, 0.0])


def test_an_infrared_only_map_is_still_sampled():
    """A texel that shines only outside the visible (Y = 0) keeps a positive sampling
    weight (environment.SPECTRAL_FLOOR), so NEE covers it."""
    from relray.core.scene.sky import EnvironmentImage
    nm = np.array([2000.0, 3000.0])
    px = np.zeros((2, 2, 2), np.float32)
    px[1, 0] = [1.0, 1.0]
    w = environment.texel_weights(environment.texels(EnvironmentImage(px, 1.0, 0.0, nm)))
    assert w[1, 0] > 0.0 and np.count_nonzero(w) == 1


def test_uniform_map_equals_the_constant_sky_on_a_moving_body(tmp_path):
    """A grey map of radiance 0.7 is the constant background [0.7, 0.7, 0.7] by another
    light: a diffuse sphere moving at 0.6 c past a static floor (Doppler and searchlight
    on) looks the same under both, up to noise. This exercises the map from a moving
    vertex (next-event estimation sampled in the lab, seen in the body's rest frame: D_out
    and D_out⁵ on the lanes) and the miss of a ray that left the body (turned back into
    the lab there). Per pixel z = (Y₁ − Y₂)/√(σ₁² + σ₂²) within 6, their mean within 5/√N,
    and the mean luminance over the sphere's pixels (those whose Doppler AOV is not 1)
    within 5 σ of the two means (σ from the pixels' σ): dropping D_out⁵ and the shift on
    the map's next-event term makes the sphere 12 % darker, about 8 σ at these settings."""
    W = H = 32
    grey = {"name": "g", "base_color": [0.6, 0.6, 0.6], "roughness": 1.0}
    common = {"render": {"width": W, "height": H, "spp": 128, "max_depth": 4},
              "camera": {"position": [0.0, -6.0, 2.0], "look_at": [0.0, 0.0, 0.8],
                         "fov": 40.0},
              "motion": {"ct": 0.0},
              "materials": [grey],
              # at lab time 0 at x = 3.6: seen ~6 units (light-time) earlier near x = 0
              "objects": [{"shape": "sphere", "center": [3.6, 0.0, 1.0], "radius": 0.9,
                           "material": "g", "velocity": [0.6, 0.0, 0.0]},
                          {"shape": "quad", "material": "g",
                           "corners": [[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]]}]}
    a = render(env_job(tmp_path, np.full((8, 16, 3), 0.7), **common), tmp_path)
    b = render(base_job(scene={"background": [0.7, 0.7, 0.7]}, **common), tmp_path)
    assert 0.2 < a.alpha.mean() < 0.95
    sphere = np.abs(a.image.aovs["doppler"] - 1.0) > 1e-3
    assert sphere.sum() > 100
    z = zscore(a.luminance, b.luminance, np.sqrt(a.sigma_y ** 2 + b.sigma_y ** 2))
    assert np.all(np.abs(z) <= 6.0), np.abs(z).max()
    n = sphere.sum()
    sig_mean = math.sqrt(np.sum(a.sigma_y[sphere] ** 2) + np.sum(b.sigma_y[sphere] ** 2)) / n
    diff = a.luminance[sphere].mean() - b.luminance[sphere].mean()
    assert abs(diff) <= 5.0 * sig_mean, (diff, sig_mean)
    assert abs(z.mean()) <= 5.0 / math.sqrt(z.size), z.mean()


@pytest.mark.parametrize("mode", ["cie1931", "seed-gaussian", "rgb"])
def test_uniform_map_seen_directly_is_the_background_of_its_colour(tmp_path, mode):
    """An orange uniform map seen from a camera moving at β = 0.5 gives, pixel by pixel,
    what the constant background of the same colour gives (the same seed: the same
    rays and wavelengths), in each spectral mode: the map's texels are the RGB emitters
    of physics.md (cie1931: k·s(λ)·D65_ext with the table's polished coefficients
    against the background's own fit; seed-gaussian: the flat emitter of the mean;
    rgb: the colour). Tolerance 2e-3 relative: the two fits' residuals, no noise."""
    rgb = [0.9, 0.5, 0.2]
    sections = {"render": {"width": 16, "height": 12, "spp": 4, "spectral": mode},
                "camera": {"fov": 60.0}, "motion": {"beta": [0.3, 0.4, 0.0]},
                "materials": [GREY], "objects": [FAR_SPECK]}
    a = render(env_job(tmp_path, np.broadcast_to(rgb, (4, 8, 3)), **sections), tmp_path)
    b = render(base_job(scene={"background": rgb}, **sections), tmp_path)
    assert np.all(a.alpha == 0.0) and b.rgb.min() > 0.01
    assert np.allclose(a.rgb, b.rgb, rtol=2e-3, atol=0.0), np.abs(a.rgb / b.rgb - 1).max()


# ------------------------------------------------------------------------ the sampler


def test_sampler_pdf_matches_its_histogram_and_integrates_to_one():
    """env_sample's directions have the density env_pdf says: Σ pdf·ΔΩ over a fine grid
    is 1, and the fraction of 200k samples in each texel equals its pmf (multinomial
    z-scores, |z| ≤ 6). With rotation the pdf moves with the map."""
    rgb = np.zeros((6, 12, 3))
    rgb[...] = 0.1
    rgb[4, 3] = (5.0, 1.0, 0.0)
    from relray.core.scene.sky import EnvironmentImage
    img = EnvironmentImage(rgb.astype(np.float32), 1.0, 40.0)
    ke = environment.kernel_environment(img, "rgb", 0)
    rng = np.random.default_rng(1)
    n = 200_000
    u = rng.random((n, 2))
    dirs, pdfs, texel = sample_many(ke, u)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-9)
    back = np.array([pdf_at(ke, d) for d in dirs[:2000]])
    assert np.allclose(back, pdfs[:2000], rtol=1e-6)
    uv = np.array([uv_of(d, 40.0) for d in dirs])
    rr = np.minimum((uv[:, 1] * 6).astype(int), 5)
    cc = np.minimum((uv[:, 0] * 12).astype(int), 11)
    # the texel the sampler reports is the one its direction lies in (up to rounding on
    # a texel's edge)
    assert np.mean((texel[:, 0] == rr) & (texel[:, 1] == cc)) > 0.9999
    counts = np.zeros((6, 12))
    np.add.at(counts, (rr, cc), 1)
    p = ke.pmf.astype(float)
    z = (counts - n * p) / np.sqrt(n * p * (1 - p))
    assert np.all(np.abs(z) <= 6.0)
    # ∫ pdf dΩ = 1 on a 600 × 1200 midpoint grid
    th = (np.arange(600) + 0.5) / 600 * math.pi
    ph = (np.arange(1200) + 0.5) / 1200 * 2 * math.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    total = sum(pdf_at(ke, x) * s for x, s in zip(d, np.sin(T).ravel(), strict=True))
    assert abs(total * (math.pi / 600) * (2 * math.pi / 1200) - 1.0) < 2e-3


def uv_of(d, rot_deg):
    v = 1.0 - math.acos(max(-1.0, min(1.0, d[2]))) / math.pi
    u = (math.pi + math.radians(rot_deg) - math.atan2(d[1], d[0])) / (2 * math.pi)
    return u - math.floor(u), v


@njit(cache=True)
def _guided_all(cdf, guide, u, out):
    for i in range(u.shape[0]):
        out[i] = environment.guided_bin(cdf, guide, u[i])


def test_the_guided_search_finds_the_bin_a_binary_search_finds():
    """guided_bin (the sampler's search from its guide table) against searchsorted's
    answer, clamped as the sampler clamps it, on CDFs with empty steps (runs of equal
    entries, at the start, inside and at the end), a CDF whose mass sits in one bin, and
    uniform ones; u at every entry, just below each, at the guide's bucket edges and just
    below them, and uniform."""
    rng = np.random.default_rng(5)
    w = rng.random(300) ** 6
    w[:20] = 0.0
    w[100:140] = 0.0
    w[-15:] = 0.0
    one = np.zeros(64)
    one[17] = 1.0
    # (six equal bins: just below 5/6, u·6 rounds up to 5, the bucket of the entry 5/6
    # itself: the guide must start below it)
    for weights in (w, one, np.ones(33), np.ones(6), rng.random(7)):
        cdf = np.concatenate([[0.0], np.cumsum(weights)]) / weights.sum()
        cdf[-1] = 1.0
        n = len(cdf) - 1
        guide = environment.guide_table(cdf)
        edges = np.arange(n) / n
        u = np.concatenate([cdf[:-1], np.nextafter(cdf[1:], 0.0), edges,
                            np.nextafter(edges[1:], 0.0), rng.random(20_000)])
        u = u[(u >= 0.0) & (u < 1.0)]
        got = np.empty(len(u), np.int64)
        _guided_all(cdf, guide, u, got)
        want = np.clip(np.searchsorted(cdf, u, side="right") - 1, 0, n - 1)
        assert np.array_equal(got, want)


def sample_many(ke, u):
    out = np.zeros((len(u), 3))
    pdf = np.zeros(len(u))
    texel = np.zeros((len(u), 2), int)
    for i, (a, b) in enumerate(u):
        w, p, r, c = environment.env_sample(ke.marg, ke.cond, ke.mguide, ke.cguide, ke.pmf,
                                            ke.rot, a, b)
        out[i] = w
        pdf[i] = p
        texel[i] = r, c
    return out, pdf, texel


def pdf_at(ke, d):
    return environment.env_pdf(ke.pmf, ke.rot, d[0], d[1], d[2])


def test_bilinear_lookup_of_the_map_seen_directly():
    """The directly seen map is bilinear between texel centres: a texel's centre gives
    that texel, the midpoint between two column centres their mean, u = 0 mixes the
    last and the first columns (the seam wraps), a row centre's neighbours above the top
    row's centre clamp to it; the nearest lookup gives the texel the direction is in."""
    rgb = np.arange(4 * 8 * 3, dtype=np.float64).reshape(4, 8, 3)
    from relray.core.scene.sky import EnvironmentImage
    ke = environment.kernel_environment(EnvironmentImage(rgb.astype(np.float32)), "rgb", 0)

    def value(u, v):
        d = direction_of(u, v)
        q = environment.env_bilinear(ke.tex, ke.rot, *d)
        return np.array(environment.env_lanes_bilinear(ke.tex, q, True, ke.nm, (0.0,) * 4,
                                                       (1.0,) * 4)[:3])

    assert np.allclose(value(2.5 / 8, 1.5 / 4), rgb[1, 2], atol=1e-4)
    assert np.allclose(value(3.0 / 8, 1.5 / 4), 0.5 * (rgb[1, 2] + rgb[1, 3]), atol=1e-4)
    assert np.allclose(value(1e-9, 2.5 / 4), 0.5 * (rgb[2, 0] + rgb[2, 7]), atol=1e-4)
    assert np.allclose(value(4.5 / 8, 0.95), rgb[3, 4], atol=1e-4)
    assert np.allclose(value(4.5 / 8, 0.3 / 4), rgb[0, 4], atol=1e-4)
    d = direction_of(5.2 / 8, 2.9 / 4)
    r, c, _ = environment.env_texel_pdf(ke.pmf, ke.rot, *d)
    assert (r, c) == (2, 5)


# ------------------------------------------------------------------------ job and CLI


def test_job_key_info_and_conflict_with_background(tmp_path):
    write_map(tmp_path / "sky.exr", np.ones((2, 4, 3)))
    data = base_job(scene={"environment": {"file": "sky.exr", "strength": 2.0,
                                           "rotation_z": 15.0}},
                    materials=[GREY], objects=[FAR_SPECK])
    job = parse_job(data, tmp_path / "job.toml")
    e = job.scene.environment
    assert e.file == tmp_path / "sky.exr" and e.strength == 2.0 and e.rotation_z == 15.0
    assert "environment" in job_summary(job) and "strength 2" in job_summary(job)
    data["scene"]["background"] = [0.1, 0.0, 0.0]
    from relray.core.errors import UserError
    with pytest.raises(UserError, match="scene.background"):
        parse_job(data, tmp_path / "job.toml")


def test_digest_covers_the_map_content(tmp_path):
    from relray.core.output.digest import job_digest
    write_map(tmp_path / "sky.exr", np.ones((2, 4, 3)))
    data = base_job(scene={"environment": {"file": "sky.exr"}},
                    materials=[GREY], objects=[FAR_SPECK])
    a = job_digest(parse_job(data, tmp_path / "job.toml"))
    write_map(tmp_path / "sky.exr", np.full((2, 4, 3), 2.0))
    b = job_digest(parse_job(data, tmp_path / "job.toml"))
    data["scene"]["environment"]["rotation_z"] = 1.0
    c = job_digest(parse_job(data, tmp_path / "job.toml"))
    assert len({a, b, c}) == 3


def test_a_map_whose_tables_do_not_fit_is_refused(tmp_path, monkeypatch):
    """The map's tables are checked against the memory limit when the scene is built
    (here a limit of 1000 bytes: 32 texels need 4096)."""
    from relray.core import resources
    from relray.core.errors import UserError
    from relray.core.scene import sky
    write_map(tmp_path / "sky.exr", np.ones((4, 8, 3)))
    spec = parse_job(base_job(scene={"environment": {"file": "sky.exr"}}, materials=[GREY],
                              objects=[FAR_SPECK]), tmp_path / "job.toml").scene.environment
    image = sky.load_environment(spec, tmp_path / "job.toml")
    assert image.pixels.shape == (4, 8, 3)
    st = (tmp_path / "sky.exr").stat()  # what identifies the file (the viewport's hash)
    assert image.source == f"{tmp_path / 'sky.exr'}:{st.st_size}:{st.st_mtime_ns}"
    monkeypatch.setattr(sky.resources, "memory_limit",
                        lambda: resources.MemoryLimit(1000, "the test"))
    with pytest.raises(UserError, match="scene.environment.file.*8 x 4 environment map"):
        sky.load_environment(spec, tmp_path / "job.toml")


CLI_JOB = """
[render]
width = 8
height = 8
spp = 1
[output]
dir = "out"
[scene]
environment = {{ file = "{file}", strength = {strength} }}
[[materials]]
name = "grey"
[[objects]]
shape = "sphere"
center = [0.0, 0.0, 0.0]
radius = 0.5
material = "grey"
"""


@pytest.mark.parametrize("case", ["missing", "empty", "nan", "negative strength",
                                  "one band", "spectral nan", "same wavelength"])
def test_bad_environment_is_one_line_exit_2_nothing_written(tmp_path, case):
    file, strength = "sky.exr", "1.0"
    spectral = {"one band": ([500.0], [1.0]), "spectral nan": ([500.0, 600.0], [1.0, np.nan]),
                "same wavelength": ([500.0, 600.0], [1.0, 1.0])}
    if case in spectral:  # "same wavelength": S0.500,000000nm and S0.0,5um
        nm, values = spectral[case]
        write_spectral_map(tmp_path / "sky.exr", nm, np.broadcast_to(values, (2, 4, len(nm))),
                           extra=(("S0.0,5um", 1.0),) if case == "same wavelength" else ())
    if case == "empty":  # a 0×0 Radiance HDR (libpng prints its own line for a 0×0 PNG)
        (tmp_path / "sky.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 0 +X 0\n")
        file = "sky.hdr"
    elif case == "nan":
        m = np.ones((2, 4, 3))
        m[1, 2, 0] = np.nan
        write_map(tmp_path / "sky.exr", m)
    elif case == "negative strength":
        write_map(tmp_path / "sky.exr", np.ones((2, 4, 3)))
        strength = "-1.0"
    job = tmp_path / "job.toml"
    job.write_text(CLI_JOB.format(file=file, strength=strength))
    r = subprocess.run([sys.executable, "-m", "relray.core.cli", "render", str(job)],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    key = "scene.environment.strength" if case == "negative strength" else \
        "scene.environment.file"
    assert key in lines[0] and str(job) in lines[0], lines[0]
    assert not (tmp_path / "out").exists()
