"""Renders inside Blender: stills, a keyframed-β animation, passes, cancelling, bad β."""

from __future__ import annotations

import math
import time

import bpy
import numpy as np
import pytest
import rendering
from conftest import ext_module

SQRT3 = math.sqrt(3.0)


def _ratio_blue_red(rgba: np.ndarray) -> float:
    return float(rgba[..., 2].mean() / rgba[..., 0].mean())


def test_still_cornell(cornell, engine, tmp_path):
    scene = cornell
    scene.render.dither_intensity = 0.0
    scene.view_layers[0].use_pass_z = True
    rendering.set_output(scene, tmp_path, "still", "PNG")
    t0 = time.perf_counter()
    rendering.render_still(scene, write=True)
    seconds = time.perf_counter() - t0
    res = engine.RESULTS[1]
    rgba = res["rgba"]
    assert rgba.shape == (48, 48, 4)
    assert np.all(np.isfinite(rgba))
    assert res["d_range"] == (1.0, 1.0) and res["gamma"] == 1.0
    # Orientation: the ceiling light is at the top, the red wall left, the green right.
    lum = rendering.luminance(rgba)
    top, bottom = lum[:8].mean(), lum[-8:].mean()
    assert np.unravel_index(np.argmax(lum), lum.shape)[0] < 16
    left, right = rgba[20:28, :4].mean(axis=(0, 1)), rgba[20:28, -4:].mean(axis=(0, 1))
    assert left[0] > 2 * left[1] and right[1] > 1.5 * right[0], (left, right)
    assert top > 0 and bottom > 0
    # Blender wrote the frame through its output format: the same picture, the right way up.
    png = rendering.load_image(tmp_path / "still.png")
    assert png.shape == (48, 48, 4)
    expected = rendering.srgb_encode(rgba[..., :3])
    assert np.abs(png[..., :3] - expected).max() < 2.5 / 255
    assert np.all(png[..., 3] == 1.0)
    # Depth: the view's centre meets a block or the back wall (4.9 m away).
    depth = res["aovs"]["depth"]
    assert 3.0 < depth[24, 24] < 4.95
    print(f"cornell 48x48 16 spp in Blender: export {res['export_seconds'] * 1000:.1f} ms, "
          f"prepare {res['prepare_seconds']:.2f} s, render {res['render_seconds']:.2f} s, "
          f"F12 total {seconds:.2f} s")


def test_passes_registered(cornell, engine, tmp_path):
    """update_render_passes: Combined, Depth (Blender's Z toggle), Doppler and LabTime."""
    scene = cornell
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    names = rendering.registered_passes(scene)
    for name in ("Image", "Alpha", "Depth", "Doppler", "LabTime"):
        assert name in names, names
    layer.relray.use_pass_doppler = False
    layer.use_pass_z = False
    names = rendering.registered_passes(scene)
    assert "Doppler" not in names and "Depth" not in names and "LabTime" in names, names
    layer.relray.use_pass_doppler = True
    layer.use_pass_z = True
    rendering.set_output(scene, tmp_path, "passes", "EXR_MULTILAYER")
    rendering.render_still(scene, write=True)
    assert set(engine.RESULTS[1]["aovs"]) == {"depth", "doppler", "lab_time"}
    # (Blender 5.0 itself writes only Combined there; the engine adds its passes)
    channels = rendering.exr_channels(tmp_path / "passes.exr")
    for ch in ("Combined.R", "Combined.A", "Depth.Z", "Doppler.D", "LabTime.T"):
        assert f"{layer.name}.{ch}" in channels, channels
    import OpenImageIO as oiio  # noqa: N813

    buf = oiio.ImageBuf(str(tmp_path / "passes.exr"))
    names = list(buf.spec().channelnames)
    px = buf.get_pixels(oiio.FLOAT)
    for ch, aov in (("Depth.Z", "depth"), ("Doppler.D", "doppler"), ("LabTime.T", "lab_time")):
        plane = px[..., names.index(f"{layer.name}.{ch}")]
        np.testing.assert_array_equal(plane, engine.RESULTS[1]["aovs"][aov])


def test_keyframed_beta_animation(cornell, engine, tmp_path):
    """β = 0, then 0.5 towards the box, then 0.5 away: D, colour, brightness, aberration."""
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 3
    cam = scene.camera.data
    for frame, beta in ((1, (0, 0, 0)), (2, (0, 0.5, 0)), (3, (0, -0.5, 0))):
        rendering.key_beta(scene, cam, frame, beta)
    rendering.set_output(scene, tmp_path, "anim_", "PNG")
    rendering.render_animation(scene)
    for f in (1, 2, 3):
        assert rendering.frame_path(scene, f).is_file()
    r1, r2, r3 = (engine.RESULTS[f] for f in (1, 2, 3))
    np.testing.assert_allclose(r2["event"].beta, [0, 0.5, 0], atol=1e-12)
    # Doppler factor: D = 1/(γ(1 - β·d')) peaks at √3 in the middle of the view when
    # moving towards the box, and is 1/√3 there when moving away.
    motion = ext_module("relblend.motion")
    export = ext_module("relblend.export")
    camera = export.camera_settings(scene.camera.evaluated_get(
        bpy.context.evaluated_depsgraph_get()), 48, 48)
    assert r1["d_range"] == (1.0, 1.0)
    assert r2["d_range"][1] == pytest.approx(SQRT3, rel=2e-3)
    assert r3["d_range"][0] == pytest.approx(1 / SQRT3, rel=2e-3)
    lo2, hi2 = motion.view_doppler_range(camera, np.array([0, 0.5, 0]), 48, 48)
    assert r2["d_range"][0] == pytest.approx(lo2, rel=5e-3)
    assert hi2 == pytest.approx(SQRT3, rel=1e-9)
    dop = r2["aovs"]["doppler"]
    assert dop[23:25, 23:25].mean() == pytest.approx(SQRT3, rel=2e-3)
    assert dop[0, 0] < dop[24, 24]  # D falls off towards the corners
    # Colour: towards the box everything shifts blue and brightens (searchlight, D^5);
    # away from it, red and dim.
    assert _ratio_blue_red(r2["rgba"]) > 1.2 * _ratio_blue_red(r1["rgba"])
    assert _ratio_blue_red(r3["rgba"]) < 0.8 * _ratio_blue_red(r1["rgba"])
    lum = [rendering.luminance(r["rgba"][16:32, 16:32]).mean() for r in (r1, r2, r3)]
    assert lum[1] > 3 * lum[0] > 30 * lum[2], lum
    # Aberration: moving towards the box it shrinks (more rays escape past it).
    alpha = [r["rgba"][..., 3].mean() for r in (r1, r2, r3)]
    assert alpha[1] < alpha[0] - 0.1 and alpha[2] >= alpha[0], alpha
    # The frames Blender wrote differ the same way.
    pngs = [rendering.load_image(rendering.frame_path(scene, f))[16:32, 16:32, :3].mean()
            for f in (1, 2, 3)]
    assert pngs[1] > pngs[0] > pngs[2], pngs


def test_worldline_integrates_keyframed_beta(cornell, engine):
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 3
    cam_obj = scene.camera
    cam = cam_obj.data
    cam.relray.mode = "WORLDLINE"
    cam.relray.ct = 0.25
    cam.relray.ct_per_frame = 0.5
    rendering.key_beta(scene, cam, 1, (0.0, 0.0, 0.0))
    rendering.key_beta(scene, cam, 3, (0.0, 0.6, 0.0))
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.relray.samples = 1
    rendering.render_animation(scene)
    relativity = ext_module("core.physics.relativity")
    pos = np.array(cam_obj.location)
    f32 = np.float32  # the properties store float32: 0.6 and 0.3 (interpolated) as such
    keys = [(1, np.zeros(3)), (2, np.array([0, f32(0.3), 0])), (3, np.array([0, f32(0.6), 0]))]
    expected = relativity.worldline_events(pos, (1, 3), 0.25, 0.5, keyframes=keys)
    for f, ev in zip((1, 2, 3), expected, strict=True):
        got = engine.RESULTS[f]["event"]
        np.testing.assert_allclose(got.x, ev.x, rtol=0, atol=1e-12)
        assert got.t == pytest.approx(ev.t, abs=1e-12)
        assert got.tau == pytest.approx(0.25 + 0.5 * (f - 1), abs=1e-12)
    assert engine.RESULTS[3]["event"].x[1] > pos[1] + 0.5 * 0.3  # it did move forwards
    # A still of frame 3 alone (history evaluated with frame_set) gives the same event.
    engine.RESULTS.clear()
    scene.frame_set(3)
    rendering.render_still(scene)
    np.testing.assert_allclose(engine.RESULTS[3]["event"].x, expected[2].x, atol=1e-12)
    assert scene.frame_current == 3
    # The object's own location is its position at ct' = 0: moving it shifts the path.
    cam_obj.location.x += 1.0
    rendering.render_still(scene)
    np.testing.assert_allclose(engine.RESULTS[3]["event"].x - expected[2].x, [1, 0, 0],
                               atol=1e-12)


def test_camera_local_axes_and_speed_direction(cornell, engine):
    scene = cornell
    cam = scene.camera.data
    cam.relray.axes = "CAMERA"
    cam.relray.velocity_input = "SPEED"
    cam.relray.speed = 0.5
    cam.relray.direction = (0.0, 0.0, -1.0)  # the view direction: +y in the lab
    scene.render.resolution_x = scene.render.resolution_y = 8
    rendering.render_still(scene)
    np.testing.assert_allclose(engine.RESULTS[1]["event"].beta, [0, 0.5, 0], atol=1e-7)


def test_resolution_percentage_and_film_transparency(cornell, engine, tmp_path):
    scene = cornell
    scene.render.resolution_percentage = 50
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.5, 0.5, 0.5, 1)
    scene.camera.data.relray.beta = (0.0, 0.6, 0.0)  # aberration: the sky shows at the edges
    rendering.set_output(scene, tmp_path, "opaque", "PNG")
    rendering.render_still(scene, write=True)
    assert engine.RESULTS[1]["rgba"].shape == (24, 24, 4)
    opaque = rendering.load_image(tmp_path / "opaque.png")
    assert opaque.shape == (24, 24, 4)
    assert opaque[0, 0, 3] == 1.0 and opaque[0, 0, :3].min() > 0.3
    scene.render.film_transparent = True
    rendering.set_output(scene, tmp_path, "transparent", "PNG")
    rendering.render_still(scene, write=True)
    clear = rendering.load_image(tmp_path / "transparent.png")
    assert clear[0, 0, 3] == 0.0
    assert clear[12, 12, 3] == 1.0


def test_cancel_stops_within_a_second(cornell, engine):
    """A cancel request (Esc: test_break; here the script hook polled with it) stops the
    core between wavefronts; the frame is left unrendered."""
    scene = cornell
    scene.render.resolution_x = scene.render.resolution_y = 160
    scene.relray.samples = 4096  # minutes uncancelled on two cores
    t_request: list[float] = []
    start = time.perf_counter()

    def cancel() -> bool:
        if time.perf_counter() - start > 1.5:
            if not t_request:
                t_request.append(time.perf_counter())
            return True
        return False

    engine.SCRIPT_CANCEL = cancel
    try:
        rendering.render_still(scene)
    finally:
        engine.SCRIPT_CANCEL = None
    seconds = time.perf_counter() - start
    latency = engine.LAST_CANCEL_LATENCY
    assert t_request and latency is not None
    print(f"cancel: the render stopped {latency:.3f} s after the request "
          f"(render call {seconds:.2f} s)")
    assert latency < 1.0
    assert seconds < 1.5 + 2.0
    assert 1 not in engine.RESULTS


def test_bad_beta_keyframe_stops_the_animation(cornell, engine, tmp_path):
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 3
    cam = scene.camera.data
    rendering.key_beta(scene, cam, 1, (0.0, 0.0, 0.0))
    rendering.key_beta(scene, cam, 2, (0.8, 0.8, 0.0))  # each component < 1, |β| = 1.131
    rendering.key_beta(scene, cam, 3, (0.0, 0.0, 0.0))
    rendering.set_output(scene, tmp_path, "bad_", "PNG")
    with pytest.raises(RuntimeError) as info:
        rendering.render_animation(scene)
    message = str(info.value)
    assert "frame 2" in message and "1.13137" in message and "speed of light" in message
    assert rendering.frame_path(scene, 1).is_file()
    assert not rendering.frame_path(scene, 2).exists()
    assert not rendering.frame_path(scene, 3).exists()


def test_bad_beta_from_a_driver(cornell, engine):
    scene = cornell
    cam = scene.camera.data
    for index in (0, 1):
        fc = cam.driver_add("relray.beta", index)
        fc.driver.type = "SCRIPTED"
        fc.driver.expression = "0.4 * frame"
    scene.frame_set(1)
    rendering.render_still(scene)  # (0.4, 0.4, 0): fine
    scene.frame_set(2)
    with pytest.raises(RuntimeError, match=r"frame 2: the camera's \|β\| = 1\.13137"):
        rendering.render_still(scene)


def test_bad_beta_in_the_worldline_history(cornell, engine):
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 3
    cam = scene.camera.data
    cam.relray.mode = "WORLDLINE"
    rendering.key_beta(scene, cam, 1, (0.0, 0.0, 0.0))
    rendering.key_beta(scene, cam, 2, (0.9, 0.9, 0.0))
    rendering.key_beta(scene, cam, 3, (0.0, 0.0, 0.0))
    scene.frame_set(3)
    with pytest.raises(RuntimeError, match="frame 2"):
        rendering.render_still(scene)
