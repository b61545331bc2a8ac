"""core/render/frames.py: frame selection, adaptive sampling, transparent film."""

import dataclasses
from pathlib import Path

import numpy as np

from relray.core.render import frames as render
from relray.core.render.camera import PinholeCamera
from relray.core.scene import job as jobmod
from relray.core.scene import motion
from relray.core.scene.geometry import build_scene

FLYBY = Path(__file__).resolve().parents[1] / "presets" / "flyby.toml"


def _renderer(noise_threshold: float, spp: int, width: int = 32, height: int = 32,
              seed: int = 0, threads: int | None = None):
    job = jobmod.load_job(FLYBY.parent / "cornell.toml")
    settings = dataclasses.replace(job.render, width=width, height=height, spp=spp,
                                   max_depth=4, noise_threshold=noise_threshold, seed=seed,
                                   threads=job.render.threads if threads is None else threads)
    prep = render.prepare(build_scene(job), settings.spectral)
    cam = PinholeCamera.from_settings(job.camera, width, height)
    event = motion.frame_events(job)[0][1]
    return render.FrameRenderer(prep, settings, cam), event


def test_sample_passes():
    first = render.ADAPTIVE_FIRST_PASS
    assert first == 64
    assert render.sample_passes(0, 64, False) == [(0, 64)]
    assert render.sample_passes(0, 512, True) == [(0, 64), (64, 128), (128, 256), (256, 512)]
    assert render.sample_passes(0, 40, True) == [(0, 40)]
    assert render.sample_passes(0, 100, True) == [(0, 64), (64, 100)]
    # every pass of a power-of-two cap is an aligned power-of-two block of sample indices
    # (so each pixel keeps a power-of-two prefix of its Sobol sequence when it stops)
    passes = render.sample_passes(0, 1 << 12, True)
    assert passes[0][0] == 0 and passes[-1][1] == 1 << 12
    for (a, b), (c, _) in zip(passes, passes[1:] + [(1 << 12, 0)], strict=True):
        size = b - a
        assert size & (size - 1) == 0 and a % size == 0 and b == c


def test_pass_units_cover_the_pixels_once_in_order():
    pixels = np.arange(5000, dtype=np.int64)[::3]
    for n_samples, threads in ((64, 2), (256, 1), (1, 8), (4096, 3)):
        units = render.pass_units(pixels, n_samples, threads)
        np.testing.assert_array_equal(np.concatenate(units), pixels)
        assert len(units) >= min(4 * threads, len(pixels))
        assert max(len(u) for u in units) * n_samples <= 2 * max(render.WAVEFRONT, n_samples)
    assert render.pass_units(pixels[:3], 64, 4) == [pixels[:1], pixels[1:2], pixels[2:3]]
    assert render.pass_units(pixels[:0], 64, 4) == []


def test_adaptive_sampling_stops_converged_pixels_and_stays_unbiased():
    threshold, cap = 0.1, 256
    fr, ev = _renderer(noise_threshold=threshold, spp=cap)
    film, _ = fr.render(ev, 1)
    spp = film.samples_per_pixel
    first = render.ADAPTIVE_FIRST_PASS
    # pixels stop only at the ends of passes; some after the first, some at the cap
    assert set(np.unique(spp)) <= {first, 2 * first, cap}
    assert spp.min() == first and spp.max() == cap
    assert 0.5 < (spp < cap).mean() < 0.98
    # a stopped pixel met the threshold itself (its samples have not changed since; only
    # the image's mean brightness Ī in the normalisation has moved a little)
    err = film.adaptive_error()
    assert np.all(err[spp < cap] <= 1.01 * threshold)
    # ... and a pixel still above it ran to the cap
    assert np.all(spp[err > threshold] == cap)
    # the noisy ceiling next to the light (top rows) takes more samples than the
    # directly lit floor and walls (bottom half)
    assert spp[:6].mean() > 1.5 * spp[16:].mean()

    # (nearly) unbiased: against a plain render of the same seed (the same first samples
    # of every pixel), the stopped pixels are not systematically darker. Judging a pixel
    # by its own samples stops pixels that missed rare bright paths (-1.7 % here with the
    # old first pass of 8 samples and no window); the 64-sample first pass and the 3x3
    # window keep it at -0.4 %, an order of magnitude below the noise the threshold allows.
    plain_fr, _ = _renderer(noise_threshold=0.0, spp=cap)
    plain, _ = plain_fr.render(ev, 1)
    ya = film.sum_sensor[:, 1] / film.count
    yp = plain.sum_sensor[:, 1] / plain.count
    stopped = spp.ravel() < cap
    assert abs(ya[stopped].sum() / yp[stopped].sum() - 1.0) < 0.1 * threshold
    np.testing.assert_array_equal(ya[~stopped], yp[~stopped])   # capped: the same samples
    # and the image means agree within the Monte Carlo error of the two renders (another
    # seed for the plain render, standard errors from the per-pixel variances)
    other_fr, _ = _renderer(noise_threshold=0.0, spp=cap, seed=1)
    other, _ = other_fr.render(ev, 1)
    yo = other.sum_sensor[:, 1] / other.count
    sa = film.relative_error().ravel() * ya
    so = other.relative_error().ravel() * yo
    se = np.sqrt((sa**2).sum() + (so**2).sum()) / len(ya)
    assert abs(ya.mean() - yo.mean()) < 4 * se


def test_adaptive_sampling_does_not_depend_on_the_thread_count():
    """Tiles and work units change with the thread count (48x40: 32-pixel tiles for 1
    thread, 16-pixel tiles for 3); the stopping decisions see the whole frame, and every
    pixel's samples arrive in order, so the film is bit-identical."""
    films = []
    for threads in (1, 3):
        assert render.tiles(48, 40, 1) != render.tiles(48, 40, 3)
        fr, ev = _renderer(noise_threshold=0.1, spp=256, width=48, height=40, threads=threads)
        films.append(fr.render(ev, 1)[0])
    a, b = films
    assert len(np.unique(a.count)) == 3            # the adaptive passes did run
    for x, y in ((a.count, b.count), (a.sum_sensor, b.sum_sensor), (a.sum_sq, b.sum_sq),
                 (a.sum_alpha, b.sum_alpha)):
        np.testing.assert_array_equal(x, y)


def test_adaptive_progress_counts_every_path_of_the_cap():
    """Progress adds the traced paths plus, for a stopped pixel, the samples it skips."""
    fr, ev = _renderer(noise_threshold=0.1, spp=256)
    ticks = []
    film, stats = fr.render(ev, 1, progress=ticks.append)
    assert sum(ticks) == 32 * 32 * 256
    assert stats.paths == film.total_samples + film.nonfinite_samples < 32 * 32 * 256


def test_transparent_film_hides_the_sky_from_the_camera_only():
    """render.transparent: escaped camera rays give alpha 0 and no radiance, while the sky
    still lights the scene (lit pixels are unchanged, sample for sample)."""
    from relray.core.scene.job import parse_job

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
        film, _ = fr.render(motion.frame_events(job)[0][1], 1)
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
    full = dict(motion.frame_events(job))
    part = motion.frame_events(jobmod.with_overrides(job, frames=(40, 42)))
    assert [f for f, _ in part] == [40, 41, 42]
    for f, ev in part:
        assert ev.t == full[f].t and ev.tau == full[f].tau
        np.testing.assert_array_equal(ev.x, full[f].x)
        np.testing.assert_array_equal(ev.beta, full[f].beta)
