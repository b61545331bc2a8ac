"""The Rendered viewport below the draw call: the view's camera, motion and progressive
render equal F12's through the scene camera (the draw itself needs an OpenGL context)."""

from __future__ import annotations

import time
from types import SimpleNamespace

import bpy
import numpy as np
import pytest
import rendering
from conftest import ext_module
from test_animation import animate_location, clocked_scene
from test_farm import _compare


def camera_view_context(scene, width: int, height: int, perspective: str = "CAMERA"):
    """What a 3D view looking through the scene camera holds (``RegionView3D``)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    window = cam.calc_matrix_camera(depsgraph, x=width, y=height)
    rv3d = SimpleNamespace(view_matrix=cam.matrix_world.inverted(), window_matrix=window,
                           view_perspective=perspective)
    return SimpleNamespace(region_data=rv3d), depsgraph


def render_view(engine, context, depsgraph, width, height):
    viewport = ext_module("relblend.viewport")
    scene_data = engine.view_scene(context, depsgraph, width, height)
    state = engine.view_state(context, depsgraph, width, height, scene_data)
    session = viewport.ViewportSession()
    session.show(state)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 300:
        image = session.latest()
        if image is not None and image.done:
            return state, image
        assert session.error is None, session.error
        time.sleep(0.05)
    raise AssertionError("the viewport render did not finish")


def test_the_view_camera_is_the_scene_camera_with_shift(cornell):
    export = ext_module("relblend.export")
    scene = cornell
    scene.camera.data.shift_x, scene.camera.data.shift_y = 0.1, -0.05
    context, depsgraph = camera_view_context(scene, 64, 48)
    view = export.view_camera(np.array(context.region_data.view_matrix),
                              np.array(context.region_data.window_matrix), 64, 48)
    cam = export.camera_settings(scene.camera.evaluated_get(depsgraph), 64, 48)
    assert view.fov == pytest.approx(cam.fov, rel=1e-6)
    assert view.shift == pytest.approx(cam.shift, abs=1e-6)
    np.testing.assert_allclose(view.rotation, cam.rotation, atol=1e-6)
    np.testing.assert_allclose(view.position, cam.position, atol=1e-6)


def test_the_camera_view_renders_what_f12_renders(cornell, engine):
    scene = cornell
    scene.camera.data.relray.beta = (0.3, 0.4, 0.0)
    scene.relray.preview_samples = scene.relray.samples
    rendering.render_still(scene)
    f12 = engine.RESULTS[1]
    context, depsgraph = camera_view_context(scene, 48, 48)
    state, image = render_view(engine, context, depsgraph, 48, 48)
    np.testing.assert_allclose(state.event.beta, f12["event"].beta, atol=1e-12)
    mean_rel, block = _compare(f12["rgba"], image.rgba[::-1])
    assert mean_rel < 0.03 and block < 0.10, (mean_rel, block)


def test_a_free_view_is_at_rest(cornell, engine):
    scene = cornell
    scene.camera.data.relray.beta = (0.0, 0.9, 0.0)
    context, depsgraph = camera_view_context(scene, 32, 32, perspective="PERSP")
    state = engine.view_state(context, depsgraph, 32, 32,
                              engine.view_scene(context, depsgraph, 32, 32))
    assert not np.any(state.event.beta)


def test_an_animated_camera_view_moves_as_in_f12(ext, engine):
    """Camera and ball keyed (linear) with c lowered: the viewport samples their location
    F-curves (it cannot change the frame) and gets F12's shutter event and worldline."""
    scene = clocked_scene()
    animate_location(scene.camera, ((0, (0.0, 0.0, 0.0)), (10, (3.0, 0.0, 0.0))))
    animate_location(scene.objects["ball"], ((0, (0.0, 6.0, 0.0)), (10, (1.0, 6.0, 0.0))))
    scene.frame_start, scene.frame_end = 1, 8
    scene.frame_set(4)
    rendering.render_still(scene)
    f12 = engine.RESULTS[4]
    context, depsgraph = camera_view_context(scene, 48, 48)
    scene_data = engine.view_scene(context, depsgraph, 48, 48)
    state = engine.view_state(context, depsgraph, 48, 48, scene_data)
    assert state.event.t == pytest.approx(f12["event"].t)
    np.testing.assert_allclose(state.event.beta, f12["event"].beta, atol=1e-6)
    np.testing.assert_allclose(state.event.x, f12["event"].x, atol=1e-5)
    wl = scene_data[2]["ball"].worldline
    np.testing.assert_allclose(np.diff(wl.pivot[:, 0]) / np.diff(wl.t), 0.2, rtol=1e-5)


def f12_worldline(scene, name: str):
    """The worldline F12 gives an object: every sample evaluated by changing the frame
    (the engine's _setup_animation), for comparison with the viewport's."""
    animation, engine_mod = ext_module("relblend.animation"), ext_module("relblend.engine")
    export = ext_module("relblend.export")
    frame = scene.frame_current

    def set_frame(f: int, sub: float) -> None:
        scene.frame_set(f, subframe=sub)

    def matrix_of(n: str):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        return export.matrix_np(bpy.data.objects[n].evaluated_get(depsgraph).matrix_world)

    try:
        moving = animation.object_motions(animation.Samples({}), [name],
                                          engine_mod.scene_clock(scene), scene.frame_start,
                                          scene.frame_end, frame, set_frame, matrix_of)
    finally:
        scene.frame_set(frame)
    return moving[name].worldline


def test_a_child_of_an_animated_empty_moves_in_the_viewport_as_in_f12(ext, engine, capsys):
    """The ball is parented (with a parent inverse) to an empty whose location and
    rotation are keyed, and has a location key of its own: the viewport composes the
    chain from the F-curves (it cannot change the frame) and gets F12's worldline. A
    constrained object is the named limit: warned once, however often the view updates."""
    scene = clocked_scene()
    ball = scene.objects["ball"]
    pivot = bpy.data.objects.new("pivot", None)
    scene.collection.objects.link(pivot)
    pivot.location = (0.5, 1.0, 0.0)
    bpy.context.view_layer.update()
    ball.parent = pivot
    ball.matrix_parent_inverse = pivot.matrix_world.inverted()
    animate_location(pivot, ((0, (0.5, 1.0, 0.0)), (10, (2.5, 1.0, 0.0))))
    pivot.rotation_euler = (0.0, 0.0, 0.0)
    pivot.keyframe_insert("rotation_euler", frame=0)
    pivot.rotation_euler = (0.0, 0.0, 0.2)
    pivot.keyframe_insert("rotation_euler", frame=10)
    ball.keyframe_insert("location", frame=0)
    ball.location.z += 0.5
    ball.keyframe_insert("location", frame=10)
    scene.frame_start, scene.frame_end = 1, 8
    scene.frame_set(4)
    f12 = f12_worldline(scene, "ball")
    context, depsgraph = camera_view_context(scene, 32, 32)
    view = engine.view_scene(context, depsgraph, 32, 32)[2]["ball"].worldline
    np.testing.assert_allclose(view.t, f12.t, rtol=1e-6)
    np.testing.assert_allclose(view.pivot, f12.pivot, atol=1e-5)
    assert np.ptp(f12.pivot[:, 0]) > 0.5 and np.ptp(f12.pivot[:, 2]) > 0.1  # it moves
    assert "constraints" not in capsys.readouterr().out

    other = scene.objects["ball"].copy()
    other.name = "held"
    other.parent = None
    other.animation_data_clear()
    scene.collection.objects.link(other)
    other.constraints.new("COPY_LOCATION").target = pivot
    for _ in range(2):
        context, depsgraph = camera_view_context(scene, 32, 32)
        engine.view_scene(context, depsgraph, 32, 32)
    out = capsys.readouterr().out
    assert out.count("object 'held': the constraints of 'held' are not followed") == 1, out
