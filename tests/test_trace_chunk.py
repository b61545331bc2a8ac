"""core/render/frames.py FrameRenderer._trace_chunk: reused per-thread buffers, optional AOVs."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from relray.core.render import frames as render
from relray.core.render.camera import PinholeCamera
from relray.core.scene import job as jobmod
from relray.core.scene.geometry import build_scene

CORNELL = Path(__file__).resolve().parents[1] / "presets" / "cornell.toml"
ALL_AOVS = ("depth", "doppler", "lab_time")


@pytest.fixture(scope="module")
def cornell():
    job = jobmod.load_job(CORNELL)
    return job, build_scene(job)


def _render(cornell, mode, aovs=(), bands=None, threads=1, spp=4, beta=(0.0, 0.5, 0.2),
            renderer=None, samples=None):
    job, scene = cornell
    if renderer is None:
        s = dataclasses.replace(job.render, width=24, height=20, spp=spp, max_depth=4,
                                spectral=mode, threads=threads)
        cam = PinholeCamera.from_settings(job.camera, s.width, s.height)
        renderer = render.FrameRenderer(render.prepare(scene, mode), s, cam, aovs=aovs,
                                        bands=bands)
    from relray.core.physics import relativity

    ev = relativity.snapshot_event(np.asarray(job.camera.position, np.float64),
                                   np.asarray(beta, np.float64), 0.0)
    film, stats = renderer.render(ev, 1, samples=samples)
    return renderer, film, stats


def _sums(film):
    return [film.sum_sensor, film.sum_alpha, film.count, film.sum_aov, film.sum_band]


@pytest.mark.parametrize("mode", ["cie1931", "rgb"])
def test_buffers_reused_across_chunks_and_renders(cornell, mode):
    """A renderer reuses its chunk buffers: renders again, with other chunk sizes (sample
    batches, more threads), give the same sums as a fresh renderer."""
    bands = (400.0, 700.0, 50.0)
    r, a, sa = _render(cornell, mode, ALL_AOVS, bands)
    _, b, _ = _render(cornell, mode, renderer=r)  # same buffers, second frame
    for x, y in zip(_sums(a), _sums(b), strict=True):
        np.testing.assert_array_equal(x, y)
    _, c, _ = _render(cornell, mode, ALL_AOVS, bands, threads=2)
    for x, y in zip(_sums(a), _sums(c), strict=True):
        np.testing.assert_array_equal(x, y)
    # sample batches: smaller chunks through the same (larger) buffers, merged
    _, b0, _ = _render(cornell, mode, renderer=r, samples=(0, 1))
    _, b1, _ = _render(cornell, mode, renderer=r, samples=(1, 4))
    b0.merge(b1)
    np.testing.assert_allclose(b0.sum_sensor, a.sum_sensor, rtol=1e-12, atol=1e-300)
    np.testing.assert_array_equal(b0.count, a.count)
    assert sa.paths == 24 * 20 * 4 and 1.0 < sa.d_min < sa.d_max  # β toward the view: D > 1


def test_aovs_only_as_asked(cornell):
    _, full, _ = _render(cornell, "cie1931", ALL_AOVS)
    _, dop, _ = _render(cornell, "cie1931", ("doppler",))
    _, none, _ = _render(cornell, "cie1931", ())
    assert dop.sum_aov.shape[1] == 1 and none.sum_aov.shape[1] == 0
    np.testing.assert_array_equal(dop.sum_aov[:, 0], full.sum_aov[:, 1])
    np.testing.assert_array_equal(none.sum_sensor, full.sum_sensor)
    # depth: escaped samples count render.ESCAPED_DEPTH, hits their distance; alpha ∈ [0, 1]
    alpha = full.sum_alpha / full.count
    assert np.all((alpha >= 0.0) & (alpha <= 1.0)) and 0.0 < alpha.mean() < 1.0
    depth = full.sum_aov[:, 0] / full.count
    inside = alpha == 1.0
    assert np.all(depth[inside] < 100.0)
    assert np.all(depth[alpha == 0.0] == render.ESCAPED_DEPTH)
