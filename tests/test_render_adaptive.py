"""Adaptive sampling: pixels stop early, and the image stays unbiased."""

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
    assert render.sample_passes(0, 64, True) == [(0, 8), (8, 16), (16, 32), (32, 64)]
    assert render.sample_passes(0, 5, True) == [(0, 5)]
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
