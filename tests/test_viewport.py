"""relblend.viewport: the Rendered viewport's progressive renders (no Blender needed)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from relray.core.render.camera import PinholeCamera
from relray.core.render.frames import FrameRenderer, prepare
from relray.core.scene.geometry import build_scene
from relray.core.scene.job import load_job
from relray.core.scene.motion import frame_events, resolve_camera
from relray.relblend import viewport

REPO = Path(__file__).resolve().parent.parent


def cornell_state(key: str = "a", width: int = 40, height: int = 32, spp: int = 8):
    job = load_job(REPO / "presets" / "cornell.toml")
    scene = build_scene(job)
    settings = replace(job.render, width=width, height=height, spp=spp, threads=2,
                       noise_threshold=0.0)
    frame, event = frame_events(job)[0]
    return viewport.ViewState(key, prepare(scene, settings.spectral), settings,
                              resolve_camera(job, scene), event, frame)


def wait_done(session: viewport.ViewportSession, timeout: float = 300.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        image = session.latest()
        if image is not None and image.done:
            return image
        assert session.error is None, session.error
        time.sleep(0.02)
    raise AssertionError("the viewport render did not finish")


def test_batches_double_and_cover_the_samples():
    assert viewport.batches(1) == [(0, 1)]
    assert viewport.batches(8) == [(0, 1), (1, 2), (2, 4), (4, 8)]
    assert viewport.batches(6) == [(0, 1), (1, 2), (2, 4), (4, 6)]


def test_the_refined_image_is_the_one_pass_render():
    """Preview first (blocky, 0 samples counted), then batches that add up to exactly the
    frame a single render of all samples gives."""
    state = cornell_state()
    seen = []
    session = viewport.ViewportSession()
    original = session._publish

    def spy(st, rgba, samples, done, cancel):
        seen.append((samples, done, rgba.shape))
        original(st, rgba, samples, done, cancel)

    session._publish = spy
    assert session.show(state)
    image = wait_done(session)
    assert seen[0][0] == 0 and not seen[0][1]  # the preview came first
    assert [s for s, _, _ in seen[1:]] == [1, 2, 4, 8]
    assert all(shape == (32, 40, 4) for _, _, shape in seen)
    s = state.settings
    one = FrameRenderer(state.prep, s, PinholeCamera.from_settings(state.camera, s.width,
                                                                   s.height))
    film, _ = one.render(state.event, state.frame)
    expected = film.resolve(one.to_rgb).rgba[::-1]  # Blender's rows: bottom first
    np.testing.assert_allclose(image.rgba, expected, rtol=1e-5, atol=1e-7)
    assert image.samples == 8 and image.key == "a"


def test_the_same_state_keeps_going_and_a_new_one_restarts():
    session = viewport.ViewportSession()
    assert session.show(cornell_state("a", spp=64))
    assert not session.show(cornell_state("a", spp=64))  # nothing changed
    t0 = time.monotonic()
    assert session.show(cornell_state("b", spp=2))  # cancels "a" between wavefronts
    image = wait_done(session)
    assert image.key == "b" and image.samples == 2
    assert time.monotonic() - t0 < 120.0
    session.stop()
    assert not session.busy()


def test_upscale_repeats_preview_pixels():
    small = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
    big = viewport.upscale(small, 6, 4)
    assert big.shape == (4, 6, 4)
    np.testing.assert_array_equal(big[::2, ::2], small)
