"""Motion from the animation: the scene's speed of light, a camera and objects animated as
usual (their animated location is their lab worldline on ct = c · frame / fps)."""

from __future__ import annotations

import math
import tomllib

import bpy
import numpy as np
import pytest
import rendering
from conftest import ext_module
from test_farm import _compare, core_render
from test_moving import SIZE, D, coverage_column, moving_ball_scene

FPS = 24
C = 12.0  # scene units (m) per second: ct per frame = 0.5
CT_PER_FRAME = C / FPS


def clocked_scene(ball_velocity=(0.0, 0.0, 0.0)) -> bpy.types.Scene:
    """The moving-ball scene with c lowered to 12 m/s at 24 fps and the camera's motion
    from its animation."""
    scene = moving_ball_scene(ball_velocity)
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    scene.relray.speed_of_light = C
    scene.camera.data.relray.motion_source = "ANIMATION"
    return scene


def animate_location(obj, frames_locations, extrapolate: bool = True) -> None:
    """Key the object's location, linear keys (and linear extrapolation)."""
    for frame, loc in frames_locations:
        obj.location = loc
        obj.keyframe_insert("location", frame=frame)
    presets = ext_module("relblend.presets")
    for fc in presets.fcurves_of(obj):
        fc.extrapolation = "LINEAR" if extrapolate else "CONSTANT"
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def test_the_speed_of_light_and_motion_source_properties(ext):
    scene = moving_ball_scene((0.0, 0.0, 0.0))
    assert scene.relray.speed_of_light == pytest.approx(299_792_458.0)  # nothing changes
    assert scene.camera.data.relray.motion_source == "VELOCITY"
    assert scene.objects["ball"].relray.motion_source == "ANIMATION"
    scene.unit_settings.scale_length = 0.01  # one scene unit = 1 cm
    bpy.ops.relray.speed_of_light_preset(meters_per_second=10.0)
    assert scene.relray.speed_of_light == pytest.approx(1000.0)  # scene units per second
    assert hasattr(bpy.types, "RELRAY_PT_scene_relativity")


def test_an_animated_camera_renders_as_the_explicit_snapshot_job(ext, engine, tmp_path):
    """The camera keyed from x = 0 (frame 0) to x = 3 (frame 10), linear: with c = 12 m/s at
    24 fps it moves 0.3 per 0.5 of lab time, β = 0.6 along +x. Each frame's shutter event
    is (ct = 0.5 f, x = 0.3 f); the same frames come from a job written by hand in the
    seed's snapshot form (a camera at the origin at β = 0.6 since ct' = 0, shutter at
    ct' = 0.5 f / γ) and from the farm export."""
    scene = clocked_scene()
    cam = scene.camera
    animate_location(cam, ((0, (0.0, 0.0, 0.0)), (10, (3.0, 0.0, 0.0))))
    scene.frame_start, scene.frame_end = 1, 2
    rendering.set_output(scene, tmp_path, "anim_", "PNG")
    rendering.render_animation(scene)
    gamma = 1.0 / math.sqrt(1.0 - 0.36)
    frames = {}
    for f in (1, 2):
        ev = engine.RESULTS[f]["event"] if f in engine.RESULTS else None
        frames[f] = engine.RESULTS.get(f, {}).get("rgba")
        if ev is not None:
            assert ev.t == pytest.approx(0.5 * f, rel=1e-12)
            assert ev.x == pytest.approx([0.3 * f, 0.0, 0.0], abs=1e-6)
            assert ev.beta == pytest.approx([0.6, 0.0, 0.0], abs=1e-5)
            assert ev.tau == pytest.approx(0.5 * (f - 1) / gamma, abs=1e-5)
    scene.frame_set(1)
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    job = tomllib.loads((out / "job.toml").read_text())
    assert job["motion"]["mode"] == "events" and len(job["motion"]["events"]) == 2
    explicit = out / "explicit.toml"
    job["camera"]["position"] = [0.0, 0.0, 0.0]
    job["motion"] = {"mode": "snapshot", "beta": [0.6, 0.0, 0.0], "ct": 0.5 / gamma,
                     "ct_per_frame": 0.5 / gamma, "frames": [1, 2]}
    explicit.write_text(ext_module("relblend.farm").toml_dumps(job))
    engine.RESULTS_KEPT = 2
    for f in (1, 2):
        scene.frame_set(f)
        rendering.render_still(scene)
        in_blender = engine.RESULTS[f]["rgba"]
        for path in (explicit, out / "job.toml"):
            rgba, ev = core_render(path, f)
            assert ev.t == pytest.approx(0.5 * f, rel=1e-9, abs=1e-9)
            mean_rel, block = _compare(in_blender, rgba)
            assert mean_rel < 0.03 and block < 0.10, (path.name, f, mean_rel, block)
        assert abs(coverage_column(in_blender)[0] - SIZE / 2) > 2.0  # aberration shows
    engine.RESULTS_KEPT = 1


def seen_column(t: float, u: float) -> float:
    """Where the ball's centre (u t_e, D) is seen from the origin at lab time t: the light
    left it at t_e, (t - t_e)² = (u t_e)² + D², the earlier root."""
    a, b, c = 1.0 - u * u, -2.0 * t, t * t - D * D
    t_e = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
    return (1.0 + u * t_e / D) * SIZE / 2


def test_an_animated_object_is_seen_where_its_light_left_it(ext, engine, tmp_path):
    """The ball keyed from x = 0 (frame 0) to x = 2.5 (frame 10): u = 0.5 on the scene
    clock. Frames 1 and 12 (ct = 0.5, 6) show it where its light left it, not where it is
    at the frame (a Galilean renderer's answer); the farm job (its baked worldline in
    the glb's extras) renders the same frames."""
    scene = clocked_scene()
    ball = scene.objects["ball"]
    animate_location(ball, ((0, (0.0, D, 0.0)), (10, (2.5, D, 0.0))))
    scene.frame_start, scene.frame_end = 1, 12
    engine.RESULTS_KEPT = 2
    renders = {}
    for f in (1, 12):
        scene.frame_set(f)
        rendering.render_still(scene)
        renders[f] = engine.RESULTS[f]["rgba"]
        col = coverage_column(renders[f])[0]
        assert abs(col - seen_column(0.5 * f, 0.5)) < 1.5, (f, col, seen_column(0.5 * f, 0.5))
        galilean = (1.0 + 0.25 * f / D) * SIZE / 2
        assert abs(col - galilean) > 3.0
    engine.RESULTS_KEPT = 1
    scene.frame_set(1)
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    farm = ext_module("relblend.farm")
    gl, _ = farm.read_glb(out / "scene.glb")
    node = next(n for n in gl["nodes"] if n.get("name") == "ball")
    wl = node["extras"]["relray"]["worldline"]
    assert wl["t"][0] == pytest.approx(0.0) and np.diff(wl["t"]) == pytest.approx(0.5)
    for f in (1, 12):
        rgba, _ = core_render(out / "job.toml", f)
        mean_rel, block = _compare(renders[f], rgba)
        assert mean_rel < 0.03 and block < 0.10, (f, mean_rel, block)


def test_an_animation_faster_than_light_stops_naming_object_and_frame(ext, engine):
    scene = clocked_scene()
    ball = scene.objects["ball"]
    animate_location(ball, ((3, (0.0, D, 0.0)), (4, (0.6, D, 0.0))),  # 1.2 c in 3..4
                     extrapolate=False)
    scene.frame_set(1)
    with pytest.raises(RuntimeError, match=r"object 'ball': its animation moves it at 1\.2 c "
                                           r"at frame 3"):
        rendering.render_still(scene)


def test_an_animated_rotation_is_warned_once_and_the_start_pose_kept(ext, engine):
    scene = clocked_scene()
    ball = scene.objects["ball"]
    animate_location(ball, ((0, (0.0, D, 0.0)), (10, (1.0, D, 0.0))))
    ball.rotation_euler = (0.0, 0.0, 0.0)
    ball.keyframe_insert("rotation_euler", frame=0)
    ball.rotation_euler = (0.0, 0.0, 1.0)
    ball.keyframe_insert("rotation_euler", frame=10)
    scene.frame_set(2)
    rendering.render_still(scene)
    warnings = [w for w in engine.RESULTS[2]["warnings"] if "rotation or scale" in w]
    assert len(warnings) == 1 and "'ball'" in warnings[0]


def test_a_typed_camera_keeps_animated_objects_posed_per_frame(ext, engine):
    """With the camera's motion typed (Velocity, the default), nothing follows the scene
    clock: an animated object is where the frame puts it, as before."""
    scene = moving_ball_scene((0.0, 0.0, 0.0))
    scene.relray.speed_of_light = C
    ball = scene.objects["ball"]
    animate_location(ball, ((0, (0.0, D, 0.0)), (10, (2.5, D, 0.0))))
    scene.frame_set(4)
    rendering.render_still(scene)
    col = coverage_column(engine.RESULTS[4]["rgba"])[0]
    assert abs(col - (1.0 + 1.0 / D) * SIZE / 2) < 1.5
