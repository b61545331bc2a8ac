"""Export for farm: scene.glb + job TOML reproduce the in-Blender render."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import bpy
import numpy as np
import pytest
import rendering
from conftest import HOST, ext_module


def core_render(job_path: Path, frame: int) -> tuple[np.ndarray, object]:
    """The core's render of one frame of a job file (as `relray render`), in memory."""
    job_mod = ext_module("core.scene.job")
    render = ext_module("core.render.frames")
    scene_mod = ext_module("core.scene.geometry")
    motion = ext_module("core.scene.motion")
    camera = ext_module("core.render.camera")
    job = job_mod.load_job(job_path)
    scene = scene_mod.build_scene(job)
    cam = motion.resolve_camera(job, scene)
    s = job.render
    renderer = render.FrameRenderer(render.prepare(scene, s.spectral), s,
                                    camera.PinholeCamera.from_settings(cam, s.width, s.height),
                                    aovs=job.output.aovs)
    event = dict(motion.frame_events(job))[frame]
    film, _ = renderer.render(event, frame)
    return film.resolve(renderer.to_rgb).rgba, event


def _compare(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(mean |a - b| / mean a, worst 8×8-block relative difference) over RGB."""
    a, b = np.asarray(a, np.float64)[..., :3], np.asarray(b, np.float64)[..., :3]
    mean_rel = float(np.abs(a - b).mean() / a.mean())
    h, w = a.shape[0] // 8 * 8, a.shape[1] // 8 * 8
    ba = a[:h, :w].reshape(h // 8, 8, w // 8, 8, 3).mean(axis=(1, 3))
    bb = b[:h, :w].reshape(h // 8, 8, w // 8, 8, 3).mean(axis=(1, 3))
    floor = 0.05 * a.mean()
    block = float((np.abs(ba - bb) / np.maximum(ba, floor)).max())
    return mean_rel, block


@pytest.fixture
def farm_scene(ext):
    import scenes

    scene = scenes.build_cornell(blackbody_ball=True)
    light = bpy.data.lights.new("fill", "POINT")
    light.energy = 20.0
    obj = bpy.data.objects.new("fill", light)
    obj.location = (0.5, -0.5, 1.5)
    scene.collection.objects.link(obj)
    cam = scene.camera.data
    cam.relray.beta = (0.2, 0.5, 0.1)
    cam.relray.ct = 1.5
    scene.view_layers[0].use_pass_z = True
    scene.render.dither_intensity = 0.0
    return scene


def test_farm_job_reproduces_the_blender_render(farm_scene, engine, tmp_path):
    scene = farm_scene
    rendering.set_output(scene, tmp_path, "blender", "PNG")
    rendering.render_still(scene, write=True)
    in_blender = engine.RESULTS[1]
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    job_path = out / "job.toml"
    doc = tomllib.loads(job_path.read_text())
    assert doc["scene"]["file"] == "scene.glb" and (out / "scene.glb").is_file()
    assert doc["motion"]["keyframes"][0]["beta"] == pytest.approx([0.2, 0.5, 0.1])
    assert doc["motion"]["ct"] == pytest.approx(1.5)
    assert doc["render"]["seed"] == 7 and doc["render"]["spp"] == 16
    assert (out / "meshes" / "hot.ply").is_file()  # the blackbody ball, beside the glb
    assert any(m.get("emission_blackbody") == pytest.approx(3000.0) for m in doc["materials"])
    assert [light["type"] for light in doc["lights"]] == ["area", "point"]
    area = doc["lights"][0]  # the ceiling light, with its rotation about its axis
    assert area["size"] == pytest.approx([0.5, 0.4]) and area["up"] == pytest.approx([0, 1, 0])
    farm = ext_module("relblend.farm")
    gl, _ = farm.read_glb(out / "scene.glb")
    red = next(m for m in gl["materials"] if m["name"] == "red")
    assert red["pbrMetallicRoughness"]["baseColorFactor"][:3] == pytest.approx([0.63, 0.065,
                                                                                0.05])
    rgba, event = core_render(job_path, 1)
    ev = in_blender["event"]
    np.testing.assert_allclose(event.x, ev.x, atol=1e-6)
    np.testing.assert_allclose(event.beta, ev.beta, atol=1e-7)
    assert event.t == pytest.approx(ev.t, abs=1e-6)
    mean_rel, block = _compare(in_blender["rgba"], rgba)
    diff = np.abs(in_blender["rgba"] - rgba)
    differing = (diff > 1e-6).any(axis=2).mean()
    print(f"farm vs Blender: max |Δ| {diff.max():.3g}, pixels differing {differing:.1%}, "
          f"mean |Δ| {100 * mean_rel:.3f} %, worst 8x8 block {100 * block:.1f} %")
    assert mean_rel < 0.03 and block < 0.10, (mean_rel, block)
    if HOST == "bpy-module":  # the real command line, as a farm node runs it
        relray = Path(sys.executable).parent / "relray"
        proc = subprocess.run([str(relray), "render", str(job_path), "--quiet"],
                              capture_output=True, text=True, env=dict(os.environ))
        assert proc.returncode == 0, proc.stderr
        cli_png = rendering.load_image(out / "out" / "frame_0001.png")[..., :3]
        blender_png = rendering.load_image(tmp_path / "blender.png")[..., :3]
        assert np.abs(cli_png - blender_png).mean() < 0.02


def test_farm_animation_has_the_engines_events(cornell, engine, tmp_path):
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 4
    cam = scene.camera.data
    cam.relray.mode = "WORLDLINE"
    cam.relray.ct, cam.relray.ct_per_frame = 0.5, 0.4
    rendering.key_beta(scene, cam, 1, (0.0, 0.0, 0.0))
    rendering.key_beta(scene, cam, 4, (0.3, 0.6, 0.0))
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.relray.samples = 1
    rendering.set_output(scene, tmp_path, "f", "PNG")
    rendering.render_animation(scene)
    assert bpy.ops.relray.export_farm(directory=str(tmp_path / "farm")) == {"FINISHED"}
    job_mod = ext_module("core.scene.job")
    motion = ext_module("core.scene.motion")
    job = job_mod.load_job(tmp_path / "farm" / "job.toml")
    assert job.motion.mode == "worldline" and job.motion.frames == (1, 4)
    assert len(job.motion.keyframes) == 4 and job.motion.ct_per_frame == pytest.approx(0.4)
    for frame, ev in motion.frame_events(job):
        got = engine.RESULTS[frame]["event"]
        np.testing.assert_allclose(ev.x, got.x, atol=1e-9)
        np.testing.assert_allclose(ev.beta, got.beta, atol=1e-9)
        assert ev.t == pytest.approx(got.t, abs=1e-9)
        assert ev.tau == pytest.approx(got.tau, abs=1e-9)


def test_farm_snapshot_ct_per_frame(cornell, tmp_path):
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 3
    cam = scene.camera.data
    for frame, ct in ((1, 0.0), (3, 1.0)):
        cam.relray.ct = ct
        cam.keyframe_insert("relray.ct", frame=frame)
    ext_module("relblend.presets").set_linear(cam, "relray.ct")
    assert bpy.ops.relray.export_farm(directory=str(tmp_path)) == {"FINISHED"}
    doc = tomllib.loads((tmp_path / "job.toml").read_text())
    assert doc["motion"]["ct_per_frame"] == pytest.approx(0.5)
    assert doc["motion"]["mode"] == "snapshot"


def test_farm_refuses_what_a_job_cannot_hold(cornell, tmp_path):
    farm = ext_module("relblend.farm")
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 3
    cam = scene.camera
    for frame, ct in ((1, 0.0), (2, 0.2), (3, 1.0)):  # ct' not linear in the frame
        cam.data.relray.ct = ct
        cam.data.keyframe_insert("relray.ct", frame=frame)
    with pytest.raises(farm.FarmExportError, match="linearly"):
        farm.export_farm(bpy.context, tmp_path)
    with pytest.raises(RuntimeError, match="linearly"):
        bpy.ops.relray.export_farm(directory=str(tmp_path))
    cam.data.animation_data_clear()
    cam.keyframe_insert("location", frame=1)
    cam.location.x += 1.0
    cam.keyframe_insert("location", frame=3)
    with pytest.raises(farm.FarmExportError, match="camera moves"):
        farm.export_farm(bpy.context, tmp_path)


def test_toml_writer_round_trips(ext):
    farm = ext_module("relblend.farm")
    doc = {"render": {"width": 4, "spectral": "rgb", "doppler": False},
           "motion": {"beta": [0.1, 0.2, 0.3], "keyframes": [{"frame": 1, "beta": [0, 0, 0]}]},
           "materials": [{"name": 'a "quoted" name', "base_color": [1.0, 0.5, 0.0]}],
           "objects": [{"corners": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]}]}
    assert tomllib.loads(farm.toml_dumps(doc, "a header")) == doc
    with pytest.raises(farm.FarmExportError):
        farm.toml_dumps({"render": {"x": math.nan}})
