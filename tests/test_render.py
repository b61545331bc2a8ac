"""core/render.py: frame selection, adaptive sampling, transparent film."""

import dataclasses
from pathlib import Path

import numpy as np

from relray.core import job as jobmod
from relray.core import render
from relray.core.camera import PinholeCamera
from relray.core.scene import build_scene

FLYBY = Path(__file__).resolve().parents[1] / "presets" / "flyby.toml"


def _renderer(noise_threshold: float, spp: int):
    job = jobmod.load_job(FLYBY.parent / "cornell.toml")
    settings = dataclasses.replace(job.render, width=32, height=32, spp=spp, max_depth=4,
                                   noise_threshold=noise_threshold)
    prep = render.prepare(build_scene(job), settings.spectral)
    cam = PinholeCamera.from_settings(job.camera, 32, 32)
    event = render.frame_events(job)[0][1]
    return render.FrameRenderer(prep, settings, cam), event


def test_sample_passes():
    assert render.sample_passes(0, 64, False) == [(0, 64)]
    assert render.sample_passes(0, 128, True) == [(0, 32), (32, 64), (64, 128)]
    assert render.sample_passes(0, 20, True) == [(0, 20)]
    assert render.sample_passes(0, 40, True)[-1] == (32, 40)


def test_adaptive_sampling_stops_converged_pixels_and_stays_unbiased():
    threshold = 0.1
    fr, ev = _renderer(noise_threshold=threshold, spp=128)
    film, _ = fr.render(ev, 1)
    spp = film.samples_per_pixel.ravel()
    lit = film.resolve(fr.to_rgb).rgba[..., 1].ravel() > 0.01
    # the black outside of the box stops after the first pass; among the lit pixels some
    # stop early and some need the cap (a relative error of 0.1 takes ~100 samples when
    # one sample's relative deviation is ~1)
    assert spp.min() == render.ADAPTIVE_FIRST_PASS and spp.max() == 128
    assert np.any(lit & (spp < 128)) and np.any(lit & (spp == 128))
    # every pixel either reached its error target or the cap
    err = film.relative_error().ravel()
    assert np.all((err <= threshold) | (spp == 128))
    # unbiased: the image mean agrees with a plain 128-spp render of the same seed within
    # the combined standard error of the two means (per-pixel errors added in quadrature)
    ref_fr, _ = _renderer(noise_threshold=0.0, spp=128)
    ref, _ = ref_fr.render(ev, 1)
    a = film.resolve(fr.to_rgb)
    b = ref.resolve(ref_fr.to_rgb)
    ya, yb = a.rgba[..., 1].ravel(), b.rgba[..., 1].ravel()
    se = np.sqrt(((a.rel_error.ravel() * ya) ** 2 + (b.rel_error.ravel() * yb) ** 2).sum())
    se /= len(ya)
    assert abs(ya.mean() - yb.mean()) < 5 * se


def test_transparent_film_hides_the_sky_from_the_camera_only():
    """render.transparent: escaped camera rays give alpha 0 and no radiance, while the sky
    still lights the scene (lit pixels are unchanged, sample for sample)."""
    from relray.core.job import parse_job

    data = {"render": {"width": 16, "height": 12, "spp": 4, "max_depth": 3},
            "scene": {"background": [0.5, 0.6, 0.7]},
            "materials": [{"name": "grey", "base_color": [0.5, 0.5, 0.5]}],
            "objects": [{"shape": "sphere", "center": [0.0, 0.0, 1.0], "radius": 0.8,
                         "material": "grey"}]}
    images = []
    for transparent in (False, True):
        data["render"]["transparent"] = transparent
        job = parse_job(data, FLYBY.parent / "job.toml")
        prep = render.prepare(build_scene(job), "cie1931")
        cam = PinholeCamera.from_settings(job.camera, 16, 12)
        fr = render.FrameRenderer(prep, job.render, cam)
        film, _ = fr.render(render.frame_events(job)[0][1], 1)
        images.append(film.resolve(fr.to_rgb).rgba)
    opaque, clear = images
    sky = opaque[..., 3] == 0
    assert sky.any() and (~sky).any()
    assert np.all(clear[sky] == 0)                       # sky pixels: transparent black
    assert np.all(opaque[sky][:, :3] > 0)                # ... which the opaque film shows
    full = opaque[..., 3] == 1
    np.testing.assert_array_equal(clear[full], opaque[full])   # lit by the sky all the same


def test_sub_range_has_the_full_animations_shutter_events():
    job = jobmod.load_job(FLYBY)
    full = dict(render.frame_events(job))
    part = render.frame_events(jobmod.with_overrides(job, frames=(40, 42)))
    assert [f for f, _ in part] == [40, 41, 42]
    for f, ev in part:
        assert ev.t == full[f].t and ev.tau == full[f].tau
        np.testing.assert_array_equal(ev.x, full[f].x)
        np.testing.assert_array_equal(ev.beta, full[f].beta)
