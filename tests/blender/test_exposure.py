"""Auto exposure in Blender: metered per frame, smoothed over an animation, in the file."""

from __future__ import annotations

import math

import numpy as np
import rendering
import scenes
from test_moving import moving_ball_scene


def geometric_mean_luminance(rgb: np.ndarray) -> float:
    y = rendering.luminance(rgb)
    y = y[y > 1e-9 * y.max()]
    return float(np.exp(np.mean(np.log(y))))


def test_auto_exposure_keeps_a_fly_by_visible(ext, engine, tmp_path):
    """The ball ahead glowing as a 6000 K black body, seen at β = 0.5 towards it (beamed
    bright) and at β = 0.9 away from it (dimmed by orders of magnitude): with auto
    exposure both EXRs' lit
    pixels average (geometrically) within a factor of 2 of middle grey 0.18, although
    their unexposed luminances differ by more than 2^6; the stops are in the EXR's
    metadata and equal the frame's own metering (a still: no smoothing)."""
    import OpenImageIO as oiio  # noqa: N813

    raw, seen = {}, {}
    for name, beta in (("towards", (0.0, 0.5, 0.0)), ("away", (0.0, -0.9, 0.0))):
        scene = moving_ball_scene((0.0, 0.0, 0.0))
        scene.camera.data.relray.beta = beta
        ball = scene.objects["ball"]
        ball.data.materials[0] = scenes.blackbody_emitter("sun", 6000.0, 1.0)
        scene.relray.auto_exposure = True
        rendering.set_output(scene, tmp_path, f"{name}_", "OPEN_EXR")
        scene.render.image_settings.color_depth = "32"
        rendering.render_still(scene, write=True)
        path = tmp_path / f"{name}_.exr"  # a still: no frame number
        exposed = rendering.load_image(path)[..., :3]
        unexposed = engine.RESULTS[1]["rgba"][..., :3]
        seen[name] = geometric_mean_luminance(exposed)
        raw[name] = geometric_mean_luminance(unexposed)
        fe = engine.RESULTS[1]["exposure"]
        spec = oiio.ImageInput.open(str(path)).spec()
        assert float(spec.get_string_attribute("relray:exposure")) == fe.stops
        assert fe.stops == fe.metered
        scaled = unexposed * np.float32(2.0 ** fe.stops)
        assert np.allclose(exposed, scaled, rtol=1e-5, atol=1e-6 * scaled.max())
    assert raw["towards"] / raw["away"] > 2.0 ** 6, raw
    for name, y in seen.items():
        assert abs(math.log2(y / 0.18)) < 1.0, (name, y)
