"""The Rendered viewport drawn by an interactive Blender on a virtual display (Xvfb and
Mesa's software OpenGL): what the screen shows is the viewport session's image through
the view transform. Runs under ``make test-blender`` (the chroot has xvfb-run and xwd);
the bpy module has no windows, so there it is skipped, naming where it runs."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
import rendering
import scenes
import xscreen as screen
from conftest import HOST

HERE = Path(__file__).resolve().parent

pytestmark = pytest.mark.skipif(
    HOST != "blender" or shutil.which("xvfb-run") is None or shutil.which("xwd") is None,
    reason="needs an interactive Blender on a virtual display: make test-blender")


def run_probe(tmp_path: Path, mode: str) -> Path:
    """An interactive Blender opens this scene and runs the probe. Its preferences are
    this session's, saved without the splash (a modal splash stops the window's redraws);
    the add-on is enabled with --addons; PYTHONPATH (this session's path: the chroot's
    wheels) counts with --python-use-system-env, for its warm-up child too."""
    bpy.context.preferences.view.show_splash = False
    bpy.ops.wm.save_userpref()
    blend = tmp_path / "start.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    out = tmp_path / "probe"
    out.mkdir()
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1280x720x24", bpy.app.binary_path,
           "--python-use-system-env", "--addons", "bl_ext.user_default.relray", str(blend),
           "--python", str(HERE / "viewport_probe.py"),
           "--", str(out), mode]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=2400)
    (out / "log.txt").write_text(proc.stdout + proc.stderr)
    assert (out / "probe.json").is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    probe = json.loads((out / "probe.json").read_text())
    assert "error" not in probe, probe["error"]
    return out


def test_the_rendered_viewport_shows_the_sessions_image(ext, tmp_path):
    scene = scenes.build_cornell(width=160, height=160)
    scene.relray.preview_samples = 4
    out = run_probe(tmp_path, "viewport")
    probe = json.loads((out / "probe.json").read_text())
    shot = screen.read_xwd(Path(probe["screen"]))
    seen = screen.crop(shot, probe["region"], probe["window"][1]).astype(np.float64)
    rgba = np.load(out / "view.npy")[::-1]  # row 0 at the top, as the screen
    expected = 255.0 * rendering.srgb_encode(rgba[..., :3])  # Standard view transform
    assert seen.shape == expected.shape, (seen.shape, expected.shape)
    # inside a 64-pixel margin: the header and the camera frame's border are drawn on top
    inner = (slice(64, -64), slice(64, -64))
    diff = np.abs(seen[inner] - expected[inner])
    assert diff.mean() < 1.0 and np.percentile(diff, 99) < 3.0, \
        (diff.mean(), np.percentile(diff, 99))  # 8-bit display of a 16-bit float texture
    assert seen.std() > 20.0  # the box, not a blank region
    rows, cols = np.nonzero(expected.sum(axis=2) > 10.0)  # the box inside the camera frame
    box = seen[rows.min():rows.max() + 1, cols.min():cols.max() + 1]
    left, right = box[:, : box.shape[1] // 5], box[:, -box.shape[1] // 5:]
    assert left[..., 0].mean() > left[..., 1].mean()  # the red wall on the left
    assert right[..., 1].mean() > right[..., 0].mean()  # the green wall on the right
    save_picture(np.clip(seen, 0, 255).astype(np.uint8), "viewport", tmp_path)


def save_picture(pixels: np.ndarray, name: str, tmp_path: Path) -> None:
    """An (h, w, 3) uint8 picture into RELRAY_PICTURES_DIR (the README's pictures)."""
    import OpenImageIO as oiio  # noqa: N813

    pictures = Path(os.environ.get("RELRAY_PICTURES_DIR") or tmp_path / "pictures")
    pictures.mkdir(parents=True, exist_ok=True)
    buf = oiio.ImageBuf(oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(pixels))
    assert buf.write(str(pictures / f"{name}.png")), oiio.geterror()


def test_the_relativity_panels_as_an_artist_sees_them(ext, tmp_path):
    """Scene › Relativity, the camera's Relativity with its motion from the animation and
    the object's, captured from the interactive Blender (the README's pictures: written
    to RELRAY_PICTURES_DIR when it is set, `make blender-pictures`)."""
    scene = scenes.build_cornell(width=160, height=160)
    scene.relray.speed_of_light = 10.0
    scene.camera.data.relray.motion_source = "ANIMATION"
    out = run_probe(tmp_path, "panels")
    for name in ("scene", "camera", "object"):
        info = json.loads((out / f"{name}.json").read_text())
        shot = screen.read_xwd(Path(info["screen"]))
        panel = screen.crop(shot, info["area"], info["window"][1])
        assert panel.shape[0] > 200 and panel.std() > 10.0, (name, panel.shape)
        save_picture(panel, f"panel_{name}", tmp_path)


def test_ctrl_f12_while_watching_the_rendered_viewport(ext, tmp_path):
    """The Rendered viewport is showing the scene when Ctrl-F12 starts (the render job
    beside the viewport's worker): Blender reports every frame and the job complete, the
    frames are those a render without the viewport writes (the same seed; the camera
    moves, so they differ from frame to frame), no traceback, and afterwards the viewport
    renders a new image (no deadlock: the interactive Blender must get there at all)."""
    scene = scenes.build_cornell(width=64, height=64)
    scene.relray.preview_samples = 2
    scene.render.dither_intensity = 0.0
    cam = scene.camera
    cam.keyframe_insert("location", frame=1)
    cam.location.x += 0.3
    cam.keyframe_insert("location", frame=3)
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(1)
    rendering.set_output(scene, tmp_path / "probe", "anim_", "PNG")
    scene.render.image_settings.color_mode = "RGB"
    out = run_probe(tmp_path, "animation")
    probe = json.loads((out / "probe.json").read_text())
    log = (out / "log.txt").read_text()
    assert "Traceback" not in log, log[-3000:]
    assert probe["events"].count("frame") == 3 and probe["events"][-1] == "complete", probe
    assert probe["samples"] == 3  # the viewport's new image, after the job
    rendering.set_output(scene, tmp_path / "ref", "anim_", "PNG")
    rendering.render_animation(scene)
    frames = []
    for f in (1, 2, 3):
        seen = rendering.load_image(tmp_path / "probe" / f"anim_{f:04d}.png")
        ref = rendering.load_image(tmp_path / "ref" / f"anim_{f:04d}.png")
        np.testing.assert_array_equal(seen, ref)
        frames.append(seen)
    assert np.abs(frames[0] - frames[2]).mean() > 0.01  # the frames differ
