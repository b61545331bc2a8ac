"""The Rendered viewport drawn by an interactive Blender on a virtual display (Xvfb and
Mesa's software OpenGL): what the screen shows is the viewport session's image through
the view transform. Runs under ``make test-blender`` (the chroot has xvfb-run and xwd);
the bpy module has no windows, so there it is skipped, naming where it runs."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import bpy
import numpy as np
import pytest
import rendering
import xscreen as screen
from conftest import HOST

HERE = Path(__file__).resolve().parent

pytestmark = pytest.mark.skipif(
    HOST != "blender" or shutil.which("xvfb-run") is None or shutil.which("xwd") is None,
    reason="needs an interactive Blender on a virtual display: make test-blender")


def run_probe(tmp_path: Path, mode: str) -> Path:
    """An interactive Blender (no splash: a .blend on the command line) runs the probe."""
    blend = tmp_path / "start.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True)
    out = tmp_path / "probe"
    out.mkdir()
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1280x720x24", bpy.app.binary_path,
           "--factory-startup", str(blend), "--python", str(HERE / "viewport_probe.py"),
           "--", str(out), mode]
    proc = subprocess.run(cmd, env=dict(os.environ), capture_output=True, text=True,
                          timeout=900)
    assert (out / "probe.json").is_file() or mode == "panels", \
        proc.stdout[-3000:] + proc.stderr[-3000:]
    return out


def test_the_rendered_viewport_shows_the_sessions_image(ext, tmp_path):
    out = run_probe(tmp_path, "viewport")
    probe = json.loads((out / "probe.json").read_text())
    assert "error" not in probe, probe.get("error")
    shot = screen.read_xwd(Path(probe["screen"]))
    seen = screen.crop(shot, probe["region"], probe["window"][1]).astype(np.float64)
    rgba = np.load(out / "view.npy")[::-1]  # row 0 at the top, as the screen
    expected = 255.0 * rendering.srgb_encode(rgba[..., :3])  # Standard view transform
    assert seen.shape == expected.shape, (seen.shape, expected.shape)
    diff = np.abs(seen - expected)
    assert diff.mean() < 3.0, diff.mean()  # 8-bit display, 16-bit float texture
    assert seen.std() > 20.0  # the box, not a blank region
    left, right = seen[:, : seen.shape[1] // 4], seen[:, -seen.shape[1] // 4:]
    assert left[..., 0].mean() > left[..., 1].mean()  # the red wall on the left
    assert right[..., 1].mean() > right[..., 0].mean()  # the green wall on the right


def test_the_relativity_panels_as_an_artist_sees_them(ext, tmp_path):
    """Scene › Relativity, the camera's Relativity with its motion from the animation and
    the object's, captured from the interactive Blender (the README's pictures: written
    to RELRAY_PICTURES_DIR when it is set, `make blender-pictures`)."""
    import OpenImageIO as oiio  # noqa: N813

    out = run_probe(tmp_path, "panels")
    pictures = Path(os.environ.get("RELRAY_PICTURES_DIR") or tmp_path / "pictures")
    pictures.mkdir(parents=True, exist_ok=True)
    for name in ("scene", "camera", "object"):
        info = json.loads((out / f"{name}.json").read_text())
        shot = screen.read_xwd(Path(info["screen"]))
        panel = screen.crop(shot, info["area"], info["window"][1])
        assert panel.shape[0] > 200 and panel.std() > 10.0, (name, panel.shape)
        buf = oiio.ImageBuf(oiio.ImageSpec(panel.shape[1], panel.shape[0], 3, oiio.UINT8))
        buf.set_pixels(oiio.ROI(), np.ascontiguousarray(panel))
        assert buf.write(str(pictures / f"panel_{name}.png")), oiio.geterror()
