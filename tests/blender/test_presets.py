"""Motion presets, the velocity keyframe operator, and the motion helpers."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest
from conftest import ext_module


def test_motion_presets_are_listed_and_applied(cornell):
    presets = ext_module("relblend.presets")
    files = presets.motion_presets()
    names = [p.name for p in files]
    assert {"flyby_ramp.toml", "accelerate.toml", "constant_09c.toml"} <= set(names)
    scene = cornell
    cam = scene.camera.data
    path = files[names.index("flyby_ramp.toml")]
    assert bpy.ops.relray.load_motion_preset(filepath=str(path)) == {"FINISHED"}
    assert cam.relray.mode == "WORLDLINE"
    assert (scene.frame_start, scene.frame_end) == (1, 48)
    assert cam.relray.ct_per_frame == pytest.approx(0.1)
    curves = [fc for fc in presets.fcurves_of(cam) if fc.data_path == "relray.beta"]
    assert len(curves) == 3 and all(len(fc.keyframe_points) == 4 for fc in curves)
    assert all(kp.interpolation == "LINEAR" for fc in curves for kp in fc.keyframe_points)
    scene.frame_set(18)  # halfway up the ramp from frame 6 (0) to frame 30 (0.9)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    beta = scene.camera.evaluated_get(depsgraph).data.relray.beta
    assert beta[1] == pytest.approx(0.45, abs=1e-6)
    # Constant acceleration: β keyed at every frame from the exact hyperbolic motion.
    path = files[names.index("accelerate.toml")]
    assert bpy.ops.relray.load_motion_preset(filepath=str(path)) == {"FINISHED"}
    curves = [fc for fc in presets.fcurves_of(cam) if fc.data_path == "relray.beta"]
    assert all(len(fc.keyframe_points) == 48 for fc in curves)
    y = next(fc for fc in curves if fc.array_index == 1)
    assert y.evaluate(48) == pytest.approx(math.tanh(0.25 * 47 * 0.15), rel=1e-6)


def test_add_velocity_keyframe(cornell):
    presets = ext_module("relblend.presets")
    scene = cornell
    cam = scene.camera.data
    with bpy.context.temp_override(camera=cam):
        scene.frame_set(1)
        cam.relray.beta = (0.0, 0.3, 0.0)
        assert bpy.ops.relray.add_velocity_keyframe() == {"FINISHED"}
        scene.frame_set(11)  # (re-evaluates the animation: set β after it)
        cam.relray.beta = (0.0, 0.6, 0.0)
        assert bpy.ops.relray.add_velocity_keyframe() == {"FINISHED"}
    paths = {fc.data_path for fc in presets.fcurves_of(cam)}
    assert paths == {"relray.beta", "relray.ct"}
    y = next(fc for fc in presets.fcurves_of(cam) if fc.data_path == "relray.beta"
             and fc.array_index == 1)
    assert y.evaluate(6) == pytest.approx(0.45, abs=1e-6)  # linear between the keys
    cam.relray.velocity_input = "SPEED"
    with bpy.context.temp_override(camera=cam):
        assert bpy.ops.relray.add_velocity_keyframe(include_ct=False) == {"FINISHED"}
    paths = {fc.data_path for fc in presets.fcurves_of(cam)}
    assert {"relray.speed", "relray.direction"} <= paths


def test_motion_helpers(ext):
    motion = ext_module("relblend.motion")
    v = motion.VelocitySettings(velocity_input="SPEED", speed=0.5, direction=(0, 0, -2),
                                axes="CAMERA")
    rot = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # a camera looking along +y
    np.testing.assert_allclose(motion.beta_lab(v, rot), [0, 0.5, 0], atol=1e-15)
    with pytest.raises(motion.MotionError, match="frame 7: the camera's"):
        motion.check_speed(np.array([0.8, 0.8, 0.0]), 7)
    with pytest.raises(motion.MotionError, match="not finite"):
        motion.check_speed(np.array([math.nan, 0, 0]), 3)
    assert motion.affine_fit([1, 2, 3], [0.5, 1.0, 1.5]) == pytest.approx((0.5, 0.5))
    assert motion.affine_fit([1, 2, 3], [0.0, 0.2, 1.0]) is None
    lo, hi = motion.view_doppler_range(
        ext_module("core.scene.description").CameraSettings(position=np.zeros(3), rotation=rot,
                                                            fov=40.0),
        np.array([0, 0.5, 0]), 32, 32)
    assert hi == pytest.approx(math.sqrt(3), rel=1e-12) and lo < hi


def test_panel_readout_of_the_view(cornell):
    ui = ext_module("relblend.ui")
    cam = cornell.camera.data
    bpy.context.view_layer.update()  # matrix_world of the new camera object
    assert ui.view_readout(bpy.context, cam).endswith("D 1.000 – 1.000")
    cam.relray.beta = (0.0, 0.5, 0.0)
    text = ui.view_readout(bpy.context, cam)
    assert text.startswith("|β| 0.5000") and text.endswith("– 1.732"), text
    cam.relray.beta = (0.8, 0.8, 0.0)
    assert "not renderable" in ui.view_readout(bpy.context, cam)
