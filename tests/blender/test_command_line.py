"""``blender -b scene.blend -E RELRAY -f 1`` and ``-a``: the command-line renders.

They need a Blender binary, so they run under ``make test-blender`` only (the bpy
module has none). The child Blender uses the same fresh user directory, where the
extension is installed, and enables it with ``--addons``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import bpy
import pytest
import rendering
from conftest import EXT_MODULE

pytestmark = pytest.mark.skipif(
    not bpy.app.binary_path or not Path(bpy.app.binary_path).is_file(),
    reason="needs a blender binary (make test-blender); the bpy module has none")


def _blender(*args: str) -> subprocess.CompletedProcess:
    # The child sees this process's extra module paths (the core's wheels in the chroot):
    # Blender ignores PYTHONPATH, so they are set by a --python-expr run before rendering.
    paths = repr([p for p in sys.path if p])
    setup = f"import sys; sys.path[:0] = [p for p in {paths} if p not in sys.path]"
    return subprocess.run([bpy.app.binary_path, "-b", "--python-expr", setup, "--addons",
                           EXT_MODULE, *args],
                          capture_output=True, text=True, env=dict(os.environ), timeout=600)


def test_frame_and_animation_from_the_command_line(cornell, tmp_path):
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 2
    scene.render.resolution_x = scene.render.resolution_y = 16
    scene.camera.data.relray.beta = (0.0, 0.4, 0.0)
    blend = tmp_path / "cornell.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    still = _blender(str(blend), "-E", "RELRAY", "-o", str(tmp_path / "still_####"), "-F",
                     "PNG", "-f", "1")
    assert still.returncode == 0, still.stdout + still.stderr
    assert "relray: frame 1: 16x16" in still.stdout
    assert rendering.load_image(tmp_path / "still_0001.png").shape == (16, 16, 4)
    anim = _blender(str(blend), "-E", "RELRAY", "-o", str(tmp_path / "anim_####"), "-F", "PNG",
                    "-a")
    assert anim.returncode == 0, anim.stdout + anim.stderr
    assert (tmp_path / "anim_0001.png").is_file() and (tmp_path / "anim_0002.png").is_file()


def test_bad_beta_fails_the_command_line_render(cornell, tmp_path):
    scene = cornell
    scene.frame_start, scene.frame_end = 1, 2
    scene.render.resolution_x = scene.render.resolution_y = 8
    cam = scene.camera.data
    rendering.key_beta(scene, cam, 1, (0.0, 0.0, 0.0))
    rendering.key_beta(scene, cam, 2, (0.75, 0.75, 0.0))
    blend = tmp_path / "bad.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    proc = _blender(str(blend), "-E", "RELRAY", "-o", str(tmp_path / "bad_####"), "-F", "PNG",
                    "-a")
    out = proc.stdout + proc.stderr
    assert "frame 2: the camera's |β| = 1.06066" in out, out
    assert (tmp_path / "bad_0001.png").is_file()
    assert not (tmp_path / "bad_0002.png").exists()
    assert proc.returncode != 0  # a farm sees the failure


def test_a_moving_object_renders_from_the_command_line(ext, tmp_path):
    """``blender -b`` renders the Penrose–Terrell displacement of a moving object as F12
    does (tests/blender/test_moving.py): the glowing sphere at 0.5 c is seen about column
    10.35 of 48 instead of the middle."""
    import math

    from test_moving import coverage_column, moving_ball_scene

    moving_ball_scene((0.5, 0.0, 0.0))
    blend = tmp_path / "moving.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    proc = _blender(str(blend), "-E", "RELRAY", "-o", str(tmp_path / "moving_####"), "-F",
                    "PNG", "-f", "1")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rgba = rendering.load_image(tmp_path / "moving_0001.png")
    # the film is not transparent (alpha 1 everywhere): the glowing sphere is where the
    # black image is bright
    rgba[..., 3] = rgba[..., :3].mean(axis=2) > 0.25
    column = (1.0 - 1.0 / math.tan(math.radians(60.378))) * 48 / 2
    assert abs(coverage_column(rgba)[0] - column) < 1.5
