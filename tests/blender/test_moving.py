"""Moving objects in Blender: the Object › Relativity panel, F12 and the farm export."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest
import rendering
import scenes
from conftest import ext_module
from test_farm import _compare, core_render

D = 1.0 / math.sin(math.radians(10.0))  # the sphere is 10° in angular radius at rest
SIZE = 48


def moving_ball_scene(velocity) -> bpy.types.Scene:
    """A camera at the origin looking along +y (90° field), a glowing unit sphere straight
    ahead at distance D with ``object.relray.velocity``."""
    scene = scenes.reset_scene()
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.render.dither_intensity = 0.0
    scene.relray.samples = 16
    scene.relray.seed = 3
    cam_data = bpy.data.cameras.new("cam")
    cam_data.angle = math.radians(90.0)
    cam = bpy.data.objects.new("cam", cam_data)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)  # -Z (the view) onto +y, +Y up onto +z
    scene.collection.objects.link(cam)
    scene.camera = cam
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, D, 0.0), segments=64,
                                         ring_count=32)
    ball = bpy.context.active_object
    ball.name = "ball"
    ball.data.materials.append(scenes.principled("glow", (0.0, 0.0, 0.0),
                                                 emission=(1.0, 1.0, 1.0), strength=1.0))
    ball.relray.velocity = velocity
    return scene


def test_the_object_velocity_property_and_panel(ext):
    scene = moving_ball_scene((0.5, 0.0, 0.0))
    ball = scene.objects["ball"]
    assert tuple(ball.relray.velocity) == pytest.approx((0.5, 0.0, 0.0))
    assert ball.relray.gamma == pytest.approx(1.0 / math.sqrt(0.75))
    assert hasattr(bpy.types, "RELRAY_PT_object_relativity")
    ball.relray.velocity = (0.0, 0.0, 0.0)
    assert ball.relray.gamma == pytest.approx(1.0)


def coverage_column(rgba: np.ndarray) -> tuple[float, float]:
    """(column, row) of the coverage's centroid, in pixels (row 0 = top)."""
    a = rgba[..., 3].astype(np.float64)
    rows, cols = np.mgrid[0:a.shape[0], 0:a.shape[1]] + 0.5
    return float((a * cols).sum() / a.sum()), float((a * rows).sum() / a.sum())


def test_f12_shows_the_moving_sphere_where_its_light_left_it(ext, engine):
    """At rest the ball is in the middle; moving at u = 0.5 c along +x it is seen where its
    light left it. Its centre is at (u t, D) at lab time t; the light reaching the camera
    at t = 0 left at t_e < 0 with (-t_e)² = (u t_e)² + D², so t_e = -γD and the centre was
    at x = -uγD: the centre's ray comes from the direction (-u, 1/γ), 60° from -x (tan =
    -uγ = -0.577 on the image plane). The finite sphere's outline is a circle centred
    60.378° from -x (physics.md's Penrose–Terrell row: aberration moves the centre of a
    10° circle by 0.378°): the image plane's x = -cot 60.378° = -0.569, column 10.35 of
    48 (the static ball: column 24). The coverage centroid of a small circle seen off-axis
    lies within a pixel of its centre's projection (1.5 px allowed)."""
    for velocity, column in (((0.0, 0.0, 0.0), SIZE / 2),
                             ((0.5, 0.0, 0.0), (1.0 - 1.0 / math.tan(math.radians(60.378)))
                              * SIZE / 2)):
        scene = moving_ball_scene(velocity)
        rendering.render_still(scene)
        col, row = coverage_column(engine.RESULTS[1]["rgba"])
        assert abs(col - column) < 1.5 and abs(row - SIZE / 2) < 1.0, (velocity, col, row)


def test_the_farm_job_renders_the_moving_sphere_as_f12_does(ext, engine, tmp_path):
    scene = moving_ball_scene((0.5, 0.0, 0.2))
    rendering.render_still(scene)
    in_blender = engine.RESULTS[1]["rgba"]
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    farm = ext_module("relblend.farm")
    gl, _ = farm.read_glb(out / "scene.glb")
    node = next(n for n in gl["nodes"] if n.get("name") == "ball")
    # Blender's (x, y, z) is glTF's (x, z, -y)
    assert node["extras"]["relray"]["velocity"] == pytest.approx([0.5, 0.2, 0.0])
    assert node["extras"]["relray"]["pivot"] == pytest.approx([0.0, 0.0, -D])
    rgba, _ = core_render(out / "job.toml", 1)
    mean_rel, block = _compare(in_blender, rgba)
    assert mean_rel < 0.03 and block < 0.10, (mean_rel, block)
    assert abs(coverage_column(rgba)[0] - coverage_column(in_blender)[0]) < 0.5


def test_the_farm_export_moves_what_f12_moves(ext, engine, tmp_path):
    """Only the moving objects F12 renders get ``extras.relray``: a moving cube in a
    collection excluded from the view layer is no error and not in the glb at all (the
    glTF exporter's ``use_renderable`` writes it; F12 does not render it)."""
    scene = moving_ball_scene((0.5, 0.0, 0.0))
    hidden = bpy.data.collections.new("hidden")
    scene.collection.children.link(hidden)
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(3.0, D, 0.0))
    cube = bpy.context.active_object
    cube.name = "cube"
    for c in list(cube.users_collection):
        c.objects.unlink(cube)
    hidden.objects.link(cube)
    cube.relray.velocity = (0.0, 0.0, 0.3)
    bpy.context.view_layer.layer_collection.children["hidden"].exclude = True
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    farm = ext_module("relblend.farm")
    gl, _ = farm.read_glb(out / "scene.glb")
    moving = sorted(n.get("name") for n in gl["nodes"] if "relray" in n.get("extras", {}))
    assert moving == ["ball"]
    assert "cube" not in {n.get("name") for n in gl["nodes"]}
    assert not bpy.data.objects["cube"].hide_render  # restored after the export


def test_a_velocity_at_or_above_c_stops_the_render(ext, engine):
    scene = moving_ball_scene((0.8, 0.7, 0.0))  # each component < 1, |v| = 1.063
    with pytest.raises(RuntimeError, match=r"object 'ball': its velocity \|v\| = 1\.06"):
        rendering.render_still(scene)


def test_a_non_finite_velocity_stops_the_render(ext, engine):
    scene = moving_ball_scene((0.0, 0.0, 0.0))
    ball = scene.objects["ball"]
    ball.relray.velocity = (float("nan"), 0.0, 0.0)
    if math.isfinite(ball.relray.velocity[0]):
        pytest.skip("this Blender does not store a NaN in the property")
    with pytest.raises(RuntimeError, match=r"object 'ball': its velocity .* is not finite"):
        rendering.render_still(scene)


def key_ct(scene, frames_ct) -> None:
    """Key the camera's ct' (snapshot mode, at rest: the lab time of each frame)."""
    cam = scene.camera.data
    for frame, ct in frames_ct:
        cam.relray.ct = ct
        cam.keyframe_insert("relray.ct", frame=frame)
    presets = ext_module("relblend.presets")
    for fc in presets.fcurves_of(cam):
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def test_an_animation_renders_the_moving_sphere_as_the_farm_job_does(ext, engine, tmp_path):
    """Ctrl-F12 over two frames whose lab time differs by 6 (ct' keyed, camera at rest):
    the sphere moves on between them, and each frame is the farm job's frame."""
    scene = moving_ball_scene((0.5, 0.0, 0.0))
    scene.frame_start, scene.frame_end = 1, 2
    key_ct(scene, ((1, 0.0), (2, 6.0)))
    rendering.set_output(scene, tmp_path, "anim_", "PNG")
    rendering.render_animation(scene)
    frames = {f: engine.RESULTS[f]["rgba"] for f in (1, 2)}
    for f, t in ((1, 0.0), (2, 6.0)):
        # the light reaching the camera at lab time t left the centre (0.5 t_e, D) at t_e:
        # (t - t_e)² = (0.5 t_e)² + D², the earlier root; seen at x/y = 0.5 t_e / D
        a, b, c = 0.75, -2.0 * t, t * t - D * D
        t_e = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
        column = (1.0 + 0.5 * t_e / D) * SIZE / 2
        assert abs(coverage_column(frames[f])[0] - column) < 1.5, (f, column)
    scene.frame_set(1)
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    for f in (1, 2):
        rgba, _ = core_render(out / "job.toml", f)
        mean_rel, block = _compare(frames[f], rgba)
        assert mean_rel < 0.03 and block < 0.10, (f, mean_rel, block)
