"""The denoising AOVs (``albedo``, ``normal``: core/render/integrator.py, "Denoising
features") and ``render.clamp`` (core/render/film.py, "Clamp"), rendered end to end.

Scenes are seen by a camera at the origin looking along +y (render_helpers.base_job).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from render_helpers import base_job, make_job, render

from relray.core.errors import UserError
from relray.core.output.digest import frame_digest
from relray.core.render import frames as frames_mod
from relray.core.render.film import Film
from relray.core.runner import render_job
from relray.core.scene import job as jobmod
from relray.core.scene.motion import frame_events

CORNELL = Path(__file__).resolve().parents[1] / "presets" / "cornell.toml"
WALL_RGB = [0.2, 0.5, 0.7]


def _quad(center, u, v, material, **extra):
    """A quad centred at ``center`` with half-edges ``u`` and ``v`` (corners in order)."""
    c, u, v = (np.asarray(x, float) for x in (center, u, v))
    corners = [c - u - v, c + u - v, c + u + v, c - u + v]
    return {"shape": "quad", "material": material,
            "corners": [[float(x) for x in p] for p in corners], **extra}


def _wall(material="wall", flip=False, **extra):
    """A wall at y = 5 filling the view (its front face towards the camera unless flipped)."""
    u = [3.0, 0.0, 0.0] if not flip else [-3.0, 0.0, 0.0]
    return _quad([0.0, 5.0, 0.0], u, [0.0, 0.0, 3.0], material, **extra)


def _features_job(materials, objects, **sections):
    job = base_job(materials=materials, objects=objects,
                   output={"aovs": ["albedo", "normal"]}, **sections)
    job["render"] = {**job["render"], "width": 12, "height": 10, "spp": 8, "max_depth": 4}
    return job


# ----------------------------------------------------------------------------- albedo, normal
@pytest.mark.parametrize(("material", "mode"), [
    ({"roughness": 1.0}, "cie1931"),
    ({"roughness": 1.0}, "rgb"),
    # an emitter's albedo is its base colour (Cycles ignores emission closures)
    ({"emission": [1.0, 0.5, 0.0], "emission_strength": 20.0}, "cie1931"),
    # a rough metal (α = 0.36 > 0.075) is not specular: the features stop on it
    ({"metallic": 1.0, "roughness": 0.6}, "cie1931"),
], ids=["lambert", "lambert-rgb", "emitter", "rough-metal"])
def test_wall_albedo_is_its_base_colour_and_normal_faces_the_camera(tmp_path, material, mode):
    job = _features_job([{"name": "wall", "base_color": WALL_RGB, **material}], [_wall()],
                        render={"spectral": mode},
                        lights=[{"type": "point", "position": [0, 0, 0], "power": 50.0}])
    r = render(job, tmp_path)
    assert (r.alpha == 1.0).all()
    albedo, normal = r.image.aovs["albedo"], r.image.aovs["normal"]
    assert albedo.shape == (10, 12, 3) and normal.shape == (10, 12, 3)
    np.testing.assert_allclose(albedo, np.broadcast_to(WALL_RGB, albedo.shape), atol=1e-6)
    np.testing.assert_allclose(normal, np.broadcast_to([0, -1, 0], normal.shape), atol=1e-6)


def test_normal_faces_the_ray_on_a_back_face(tmp_path):
    """Surfaces are two-sided: the shading normal is turned towards the ray (as Cycles)."""
    job = _features_job([{"name": "wall", "base_color": WALL_RGB}], [_wall(flip=True)])
    normal = render(job, tmp_path).image.aovs["normal"]
    np.testing.assert_allclose(normal, np.broadcast_to([0, -1, 0], normal.shape), atol=1e-6)


def test_sky_gives_zero_and_a_sphere_faces_the_camera_at_the_centre(tmp_path):
    """Escaped rays: albedo 0 and normal 0 (not the sky's colour); the sphere's centre
    pixel has its normal towards the camera; its other pixels show its base colour."""
    red = [0.9, 0.1, 0.1]
    job = _features_job([{"name": "ball", "base_color": red}],
                        [{"shape": "sphere", "material": "ball", "center": [0.0, 5.0, 0.0],
                          "radius": 0.6}],
                        scene={"background": [0.9, 0.4, 0.2]})
    job["render"].update(width=15, height=15, spp=64)
    r = render(job, tmp_path)
    albedo, normal = r.image.aovs["albedo"], r.image.aovs["normal"]
    sky = r.alpha == 0.0
    hit = r.alpha == 1.0
    assert sky.sum() > 20 and hit.sum() > 20 and sky[0, 0] and sky[-1, -1]
    assert (albedo[sky] == 0.0).all() and (normal[sky] == 0.0).all()
    np.testing.assert_allclose(albedo[hit], np.broadcast_to(red, albedo[hit].shape), atol=1e-6)
    centre = normal[7, 7].astype(np.float64)
    # a mean of unit normals over the pixel: not renormalised, so a little shorter than 1
    assert 0.99 < np.linalg.norm(centre) <= 1.0 + 1e-6
    angle = math.degrees(math.acos(-centre[1] / np.linalg.norm(centre)))
    assert angle < 0.5, centre
    # the left half of the sphere's normals point left (-x), the upper half up (+z)
    assert normal[7, 4, 0] < -0.3 and normal[4, 7, 2] > 0.3


@pytest.mark.parametrize(("roughness", "max_depth", "want"), [
    (0.0, 4, "wall"),         # a mirror: the features are the reflected wall's, times its colour
    (0.0, 1, "nothing"),      # the path ends on the mirror: 0 and 0
    (0.6, 4, "metal"),        # a rough metal: its own
], ids=["mirror", "mirror-ends", "rough-metal"])
def test_features_go_through_a_mirror(tmp_path, roughness, max_depth, want):
    """Cycles' rule: through a vertex whose specular lobes weigh ≥ 3/4 the features go on,
    the albedo multiplied by its specular albedo (the mirror's base colour)."""
    mirror_rgb = [0.9, 0.8, 0.6]
    s = 1 / math.sqrt(2.0)
    # the mirror x + y = 4 (normal (-1, -1, 0)/√2) sends the view along -x onto a wall
    # at x = -4 that faces +x
    mirror = _quad([0.0, 4.0, 0.0], [2 * s, -2 * s, 0.0], [0.0, 0.0, 2.0], "mirror")
    wall = _quad([-4.0, 4.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 4.0], "wall")
    job = _features_job([{"name": "wall", "base_color": WALL_RGB},
                         {"name": "mirror", "base_color": mirror_rgb, "metallic": 1.0,
                          "roughness": roughness}], [mirror, wall])
    job["render"]["max_depth"] = max_depth
    r = render(job, tmp_path)
    albedo, normal = r.image.aovs["albedo"], r.image.aovs["normal"]
    if want == "wall":
        expect_a, expect_n = np.multiply(mirror_rgb, WALL_RGB), [1.0, 0.0, 0.0]
    elif want == "metal":
        expect_a, expect_n = mirror_rgb, [-s, -s, 0.0]
    else:
        expect_a, expect_n = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    np.testing.assert_allclose(albedo, np.broadcast_to(expect_a, albedo.shape), atol=1e-6)
    np.testing.assert_allclose(normal, np.broadcast_to(expect_n, normal.shape), atol=1e-6)


def test_moving_wall_albedo_has_no_doppler_and_its_normal_is_the_contracted_planes(tmp_path):
    """A wall moving at u = 0.6 x̂ (γ = 1.25), tilted 45° about z in its rest frame
    (tangent (1, -1, 0)): the albedo is its base colour (no Doppler shift), the normal
    that of the plane the lab sees, contracted along x: tangents (1/γ, -1, 0) and
    (0, 0, 1), normal ∝ (-1, -1/γ, 0) on the camera's side (the camera sees the plane
    where light left it 2.5-3.4 units away)."""
    s = 1 / math.sqrt(2.0)
    wall = _quad([0.0, 5.0, 0.0], [20 * s, -20 * s, 0.0], [0.0, 0.0, 20.0], "wall",
                 velocity=[0.6, 0.0, 0.0])
    job = _features_job([{"name": "wall", "base_color": WALL_RGB}], [wall])
    r = render(job, tmp_path)
    assert (r.alpha == 1.0).all()
    assert abs(r.image.aovs["albedo"] - np.float32(WALL_RGB)).max() < 1e-6
    # (the camera sees the body's light Doppler-shifted, so the image is not the albedo)
    expect = np.array([-1.0, -0.8, 0.0]) / math.hypot(1.0, 0.8)
    normal = r.image.aovs["normal"]
    np.testing.assert_allclose(normal, np.broadcast_to(expect, normal.shape), atol=2e-6)
    # a wall moving in its own plane keeps its normal
    wide = _quad([0.0, 5.0, 0.0], [40.0, 0.0, 0.0], [0.0, 0.0, 3.0], "wall",
                 velocity=[0.6, 0.0, 0.0])
    job2 = _features_job([{"name": "wall", "base_color": WALL_RGB}], [wide])
    n2 = render(job2, tmp_path).image.aovs["normal"]
    np.testing.assert_allclose(n2, np.broadcast_to([0, -1, 0], n2.shape), atol=1e-6)


def _cornell(tmp_path, aovs=("depth",), **render_keys):
    job = jobmod.load_job(CORNELL)
    settings = dict(width=24, height=20, spp=4, max_depth=5, threads=2) | render_keys
    return dataclasses.replace(job, render=dataclasses.replace(job.render, **settings),
                               output=dataclasses.replace(job.output, aovs=tuple(aovs),
                                                          dir=Path(tmp_path)))


def _render_job(job, whole_paths: bool = True):
    renderer = frames_mod.build_renderer(job)
    renderer.whole_paths = renderer.whole_paths and whole_paths
    frame, event = frame_events(job)[0]
    film, _ = renderer.render(event, frame)
    return renderer, film.resolve(renderer.to_rgb)


def test_features_leave_the_image_alone_and_are_not_traced_unless_asked(tmp_path):
    """The feature code uses no random numbers and changes no path: the Cornell box's
    image is bit-identical with and without the albedo/normal AOVs (features are traced
    by the wavefront integrator: the plain render is made by it too); without them the
    renderer does not trace them, and takes whole paths (render/whole_paths.py), whose
    image is the same to float32 rounding."""
    plain_r, plain = _render_job(_cornell(tmp_path), whole_paths=False)
    feat_r, feat = _render_job(_cornell(tmp_path, aovs=("depth", "albedo", "normal")))
    assert not plain_r.features and feat_r.features and not feat_r.whole_paths
    assert set(plain.aovs) == {"depth"}
    np.testing.assert_array_equal(plain.rgba, feat.rgba)
    np.testing.assert_array_equal(plain.aovs["depth"], feat.aovs["depth"])
    whole_r, whole = _render_job(_cornell(tmp_path))
    assert whole_r.whole_paths
    np.testing.assert_allclose(whole.rgba, plain.rgba, rtol=1e-4, atol=1e-6)
    np.testing.assert_array_equal(whole.aovs["depth"], plain.aovs["depth"])
    albedo = feat.aovs["albedo"]
    assert albedo.min() >= 0.0 and albedo.max() <= 1.0 and albedo.mean() > 0.2
    length = np.linalg.norm(feat.aovs["normal"], axis=2)
    assert length.max() <= 1.0 + 1e-6 and np.median(length) > 0.99


def test_exr_of_a_rendered_job_has_the_denoising_layers(tmp_path):
    """End to end (job file → EXR): Albedo.R/G/B and Normal.X/Y/Z as OpenImageIO reads them."""
    job_file = tmp_path / "wall.toml"
    job_file.write_text(
        '[render]\nwidth = 8\nheight = 6\nspp = 4\nthreads = 1\n'
        '[output]\ndir = "out"\nname = "f{frame}"\nformats = ["exr"]\n'
        'aovs = ["depth", "albedo", "normal"]\n'
        '[camera]\nposition = [0, 0, 0]\nlook_at = [0, 1, 0]\nup = [0, 0, 1]\nfov = 20\n'
        f'[[materials]]\nname = "wall"\nbase_color = {WALL_RGB}\n'
        '[[objects]]\nshape = "quad"\nmaterial = "wall"\n'
        'corners = [[-3, 5, -3], [3, 5, -3], [3, 5, 3], [-3, 5, 3]]\n')
    [path] = render_job(jobmod.load_job(job_file), show_progress=False)
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    pixels = inp.read_image(oiio.FLOAT)
    inp.close()
    names = list(spec.channelnames)
    for c in ("Albedo.R", "Albedo.G", "Albedo.B", "Normal.X", "Normal.Y", "Normal.Z",
              "Depth.Z"):
        assert c in names, names
    for c, v in zip(("Albedo.R", "Albedo.G", "Albedo.B"), WALL_RGB, strict=True):
        np.testing.assert_allclose(pixels[..., names.index(c)], v, atol=1e-6)
    for c, v in zip(("Normal.X", "Normal.Y", "Normal.Z"), (0, -1, 0), strict=True):
        np.testing.assert_allclose(pixels[..., names.index(c)], v, atol=1e-6)


# ----------------------------------------------------------------------------- clamp
def _firefly_job(**render_keys):
    """A diffuse floor, a large mirror behind it and a small, very bright emitter out of
    the camera's view: the floor sees the emitter directly (next-event estimation, quiet)
    and through the mirror, a path that only BSDF sampling finds, rarely and very
    brightly (fireflies)."""
    job = base_job(
        camera={"position": [0.0, -4.0, 2.0], "look_at": [0.0, 0.0, 0.3], "fov": 40.0},
        materials=[{"name": "floor", "base_color": [0.7, 0.7, 0.7], "roughness": 1.0},
                   {"name": "mirror", "base_color": [0.95, 0.9, 0.8], "metallic": 1.0,
                    "roughness": 0.0},
                   {"name": "hot", "emission": [1.0, 0.8, 0.5],
                    "emission_strength": 200.0}],
        objects=[_quad([0.0, -0.5, 0.0], [4.0, 0.0, 0.0], [0.0, 3.5, 0.0], "floor"),
                 _quad([0.0, 3.0, 2.0], [4.0, 0.0, 0.0], [0.0, 0.0, 2.0], "mirror"),
                 {"shape": "sphere", "material": "hot", "center": [0.0, 2.0, 2.5],
                  "radius": 0.3, "subdivisions": 2}],
    )
    job["render"].update({"width": 24, "height": 20, "spp": 16, "max_depth": 3, "threads": 1,
                          **render_keys})
    return job


def _samples_seen(monkeypatch, job_dict, tmp_path):
    """Render; return the image and the linear Rec.709 value of every sample the film got
    (in order: one thread)."""
    seen = []
    original = Film.add_samples

    def spy(self, pixel, sensor, *args, **kwargs):
        seen.append(np.array(sensor, np.float64))
        return original(self, pixel, sensor, *args, **kwargs)

    monkeypatch.setattr(Film, "add_samples", spy)
    r = render(job_dict, tmp_path)
    monkeypatch.setattr(Film, "add_samples", original)
    return r, np.concatenate(seen) @ r.to_rgb.T


def test_clamp_bounds_every_sample_keeps_its_colour_and_darkens_the_fireflies(
        tmp_path, monkeypatch):
    plain, rgb = _samples_seen(monkeypatch, _firefly_job(), tmp_path)
    peak = np.abs(rgb).max(axis=1)
    limit = 20.0 * float(np.median(peak[peak > 0]))
    n_over = int((peak > limit).sum())
    assert 5 <= n_over < 0.01 * len(peak)  # fireflies: rare and far above the rest
    assert peak.max() > 5 * limit
    clamped, rgb_c = _samples_seen(monkeypatch, _firefly_job(clamp=limit), tmp_path)
    peak_c = np.abs(rgb_c).max(axis=1)
    assert peak_c.max() <= limit * (1 + 1e-9)
    # one factor per sample: k = min(1, C / max |rgb|); the others untouched, bit for bit
    k = np.minimum(1.0, limit / np.maximum(peak, 1e-300))
    np.testing.assert_allclose(rgb_c, rgb * k[:, None], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(rgb_c[peak <= limit], rgb[peak <= limit])
    # the pixel means respect it too; the fireflies' pixels and the image's mean drop
    assert np.abs(clamped.rgb).max() <= limit * (1 + 1e-6)
    assert clamped.rgb.max() < 0.5 * plain.rgb.max()
    assert clamped.rgb.mean() < 0.8 * plain.rgb.mean()
    np.testing.assert_array_equal(clamped.alpha, plain.alpha)


def test_clamp_zero_is_bit_identical_to_no_clamp(tmp_path):
    """``clamp = 0`` (and a clamp no sample reaches) gives the same film, bit for bit, as the
    job without the key; the spectral bands too."""
    def film_of(**render_keys):
        job = _firefly_job(**render_keys)
        job["render"]["threads"] = 2
        job["output"]["formats"] = ["exr", "spectral-exr"]
        return render(job, tmp_path).image

    plain = film_of()
    for other in (film_of(clamp=0.0), film_of(clamp=1e15)):
        np.testing.assert_array_equal(other.rgba, plain.rgba)
        np.testing.assert_array_equal(other.spectral, plain.spectral)
        np.testing.assert_array_equal(other.rel_error, plain.rel_error)


def test_clamp_is_in_the_summary_and_in_the_frames_digest(tmp_path):
    job = make_job(_firefly_job(), tmp_path)
    assert job.render.clamp == 0.0
    assert "clamp       off" in jobmod.job_summary(job)
    clamped = make_job(_firefly_job(clamp=2.5), tmp_path)
    assert clamped.render.clamp == 2.5
    assert "clamp       2.5 (" in jobmod.job_summary(clamped)
    frame, event = frame_events(job)[0]
    # resume renders a frame again when its clamp changed
    assert frame_digest(job, frame, event) != frame_digest(clamped, frame, event)


@pytest.mark.parametrize(("value", "word"), [
    ("-1", ">= 0 (got -1)"), ("nan", "finite, not nan"), ("-inf", "finite, not -inf"),
    ('"on"', "a number, not a string"), ("[1.0]", "a number, not an array"),
])
def test_bad_clamp_is_refused_naming_the_key_and_the_file(tmp_path, value, word):
    path = tmp_path / "bad.toml"
    path.write_text(f"[render]\nclamp = {value}\n[[materials]]\nname = \"m\"\n"
                    "[[objects]]\nshape = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n"
                    "material = \"m\"\n")
    with pytest.raises(UserError) as err:
        jobmod.load_job(path)
    message = str(err.value)
    assert err.value.key == "render.clamp"
    assert f"{path.resolve()}: key 'render.clamp': " in message and word in message, message
    assert "\n" not in message
