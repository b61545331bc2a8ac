"""The world's Environment Texture: exported as the core's environment map, oriented and
turned (Mapping node) as Cycles shows it, and carried by the farm job."""

from __future__ import annotations

import math
import tomllib

import bpy
import numpy as np
import OpenImageIO as oiio
import pytest
import rendering
import scenes
from conftest import ext_module

W, H = 64, 48


def marker_map(path, width: int = 128, height: int = 64) -> None:
    """A dim blue equirectangular map with a bright red square at azimuth +Y (u = 0.25)
    and 10° above the horizon (linear EXR; row 0 of the file = the top)."""
    img = np.zeros((height, width, 3), np.float32)
    img[...] = (0.02, 0.03, 0.08)
    u, v = 0.25, 0.5 + 10.0 / 180.0
    c, r = int(u * width), int((1.0 - v) * height)
    img[r - 3:r + 3, c - 3:c + 3] = (4.0, 0.5, 0.2)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(width, height, 3, oiio.FLOAT))
    out.write_image(img)
    out.close()


def sky_scene(map_path, rotation_deg: float = 0.0, strength: float = 1.5):
    scene = scenes.reset_scene()
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.render.resolution_percentage = 100
    scene.relray.samples = 16
    scene.relray.seed = 3
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle = math.radians(60.0)
    cam = bpy.data.objects.new("camera", cam_data)
    cam.rotation_euler = (math.radians(90.0), 0.0, 0.0)  # looks along +Y
    scene.collection.objects.link(cam)
    scene.camera = cam
    # a speck far behind the camera: a job needs geometry, no ray meets it
    scenes.quad_object("speck", [(0, -90, 0), (0.01, -90, 0), (0.01, -90, 0.01),
                                 (0, -90, 0.01)], scenes.principled("grey", (0.5, 0.5, 0.5)))
    world = bpy.data.worlds.new("sky")
    scenes.use_nodes(world)
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    tex = nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(str(map_path))
    tex.interpolation = "Linear"
    links.new(tex.outputs["Color"], bg.inputs["Color"])
    if rotation_deg:
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value[2] = math.radians(rotation_deg)
        links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    scene.world = world
    return scene


def render_rgb(scene, engine_name: str, engine_mod) -> np.ndarray:
    """F12 with ``engine_name``; linear RGB (h, w, 3), row 0 = top."""
    scene.render.engine = engine_name
    if engine_name == "CYCLES":
        scene.cycles.samples = 16
        scene.cycles.device = "CPU"
        scene.cycles.use_denoising = False
    rendering.render_still(scene)
    if engine_name == "RELRAY":
        return engine_mod.RESULTS[scene.frame_current]["rgba"][..., :3].copy()
    result = bpy.data.images["Render Result"]
    path = rendering.frame_path(scene, scene.frame_current).with_suffix(".exr")
    result.save_render(str(path))
    img = rendering.load_image(path)
    return img[..., :3]


def centroid(rgb: np.ndarray) -> np.ndarray:
    """(row, col) centroid of the red marker."""
    w = np.clip(rgb[..., 0] - 2.0 * rgb[..., 2] - 0.2, 0.0, None)
    rows, cols = np.mgrid[0:rgb.shape[0], 0:rgb.shape[1]]
    return np.array([(w * rows).sum(), (w * cols).sum()]) / w.sum()


@pytest.mark.parametrize("rotation", [0.0, 25.0])
def test_environment_texture_matches_cycles(engine, tmp_path, rotation):
    if not rendering.engine_available("CYCLES"):
        pytest.fail("Cycles is not available in this Blender")
    path = tmp_path / "sky.exr"
    marker_map(path)
    scene = sky_scene(path, rotation)
    rendering.set_output(scene, tmp_path, "cyc_", "OPEN_EXR")
    ours = render_rgb(scene, "RELRAY", engine)
    cycles = render_rgb(scene, "CYCLES", engine)
    # the marker where Cycles puts it (to a pixel: both filter the map bilinearly)
    a, b = centroid(ours), centroid(cycles)
    assert np.hypot(*(a - b)) < 1.0, (a, b)
    if rotation == 0.0:  # straight ahead, 10° up: above the centre row
        assert abs(a[1] - (W - 1) / 2) < 1.5 and a[0] < (H - 1) / 2
    # and as bright: the texels are RGB emitters, round-tripped exactly
    red = ours[..., 0] > 1.0
    assert red.sum() >= 4
    np.testing.assert_allclose(ours[red].mean(0), cycles[red].mean(0), rtol=0.1)
    sky = ours[..., 0] < 0.1
    np.testing.assert_allclose(ours[sky].mean(0), cycles[sky].mean(0), rtol=0.05)


def test_environment_in_the_export_and_the_farm_job(engine, tmp_path):
    path = tmp_path / "sky.exr"
    marker_map(path)
    scene = sky_scene(path, 25.0, strength=2.0)
    export = ext_module("relblend.export")
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert ex.environment is not None and ex.environment.file == path
    assert ex.environment.strength == pytest.approx(2.0)
    assert ex.environment.rotation_z == pytest.approx(-25.0)  # Mapping turns the lookup
    assert np.all(ex.scene.background == 0.0) and ex.scene.environment is not None
    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    doc = tomllib.loads((out / "job.toml").read_text())
    env = doc["scene"]["environment"]
    assert env["file"] == "textures/sky.exr" and (out / env["file"]).is_file()
    assert env["strength"] == pytest.approx(2.0) and env["rotation_z"] == pytest.approx(-25.0)
    assert "background" not in doc["scene"] or not any(doc["scene"]["background"])
    scene.world.node_tree.nodes["Environment Texture"].image.filepath = str(tmp_path / "gone.exr")
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert ex.environment is None and any("no file" in w for w in ex.warnings.messages)


def test_a_procedural_sky_is_baked_and_rendered_as_cycles_shows_it(engine, tmp_path,
                                                                     monkeypatch):
    """A Sky Texture world: not baked, F12 warns and uses a colour; World › Sky › Bake
    Sky renders it once (Cycles, equirectangular) and then relray shows what Cycles
    shows: the same mean colour and the same brightening towards the horizon."""
    if not rendering.engine_available("CYCLES"):
        pytest.fail("Cycles is not available in this Blender")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    sky_bake = ext_module("relblend.sky_bake")
    monkeypatch.setattr(sky_bake, "BAKE_SIZE", (512, 256))
    path = tmp_path / "unused.exr"
    marker_map(path)
    scene = sky_scene(path)
    scene.camera.rotation_euler = (math.radians(80.0), 0.0, 0.0)  # the horizon in view
    world = scene.world
    nodes, links = world.node_tree.nodes, world.node_tree.links
    nodes.remove(nodes["Environment Texture"])
    sky = nodes.new("ShaderNodeTexSky")
    sky.sun_disc = False  # (a sub-texel disc: energy at one pixel, not a sky to compare)
    links.new(sky.outputs["Color"], nodes["Background"].inputs["Color"])
    nodes["Background"].inputs["Strength"].default_value = 0.3
    export = ext_module("relblend.export")
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert ex.environment is None and any("not baked" in w for w in ex.warnings.messages)
    assert bpy.ops.relray.bake_sky() == {"FINISHED"}
    baked = sky_bake.baked_path(world)
    assert baked.is_file() and baked.parent == tmp_path / "cache" / "relray" / "sky"
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert ex.environment.file == baked and ex.environment.strength == 1.0
    rendering.set_output(scene, tmp_path, "cyc_", "OPEN_EXR")
    ours = render_rgb(scene, "RELRAY", engine)
    cycles = render_rgb(scene, "CYCLES", engine)
    np.testing.assert_allclose(ours.mean((0, 1)), cycles.mean((0, 1)), rtol=0.05)
    rows_ours = ours.mean(axis=(1, 2)).reshape(8, -1).mean(1)
    rows_cycles = cycles.mean(axis=(1, 2)).reshape(8, -1).mean(1)
    np.testing.assert_allclose(rows_ours, rows_cycles, rtol=0.08)
    # (not a flat image: sky above, the darker ground below the horizon)
    assert rows_cycles.max() > 2.0 * rows_cycles.min()


def test_the_viewport_scene_hash_follows_the_map_file_not_its_pixels(engine):
    """engine.scene_hash identifies a map read from a file by its path, size and time
    (no pass over its pixels on every update) and a map made in memory by its pixels:
    either way a different map is a different hash, the same map the same."""
    from types import SimpleNamespace
    sky = ext_module("core.scene.sky")

    def scene(env):
        return SimpleNamespace(triangles=np.zeros((1, 3, 3)), normals=None,
                               material_ids=np.zeros(1, np.int32), background=np.zeros(3),
                               tri_group=None, uvs=None, groups=(), environment=env,
                               stars=None, materials=[], light_triangles=0, lights=[])

    px = np.ones((2, 4, 3), np.float32)
    a = engine.scene_hash(scene(sky.EnvironmentImage(px, source="/m.exr:10:1")), "cie1931")
    same = engine.scene_hash(scene(sky.EnvironmentImage(px * 2, source="/m.exr:10:1")),
                             "cie1931")
    saved = engine.scene_hash(scene(sky.EnvironmentImage(px, source="/m.exr:10:2")),
                              "cie1931")
    mem = [engine.scene_hash(scene(sky.EnvironmentImage(p)), "cie1931") for p in (px, px * 2)]
    assert a == same and a != saved and mem[0] != mem[1]
