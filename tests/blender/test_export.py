"""The exporter: depsgraph → core Scene (meshes, instances, materials, lights, world, camera)."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest
import scenes
from conftest import ext_module


def _export(scene=None, width=None, height=None):
    export = ext_module("relblend.export")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return export.export_scene(depsgraph, None, width, height)


def _material(ex, name):
    return next(m for m in ex.scene.materials if m.name == name)


def test_meshes_modifiers_and_instances(cornell):
    ex = _export()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    block = bpy.data.objects["block"].evaluated_get(depsgraph)
    block_mesh = block.to_mesh()
    block_mesh.calc_loop_triangles()
    n_block = len(block_mesh.loop_triangles)
    block.to_mesh_clear()
    assert n_block > 12  # the Bevel modifier is applied
    # 5 walls (2 each), two instances of the block, the area light's quad (a light, not
    # geometry: the last two triangles, in no BVH).
    assert len(ex.scene.triangles) == 10 + 2 * n_block + 2
    assert ex.scene.light_triangles == 2 and ex.scene.n_geometry == 10 + 2 * n_block
    assert ex.scene.triangles.dtype == np.float64 and ex.scene.normals.shape[1:] == (3, 3)
    white = [i for i, m in enumerate(ex.scene.materials) if m.name == "white"][0]
    tris = ex.scene.triangles[ex.scene.material_ids == white].reshape(-1, 3)
    # The tall instance reaches 1.2 m (scale 0.6, 0.6, 1.2 of a 1 m block), the short 0.6.
    blocks = tris[(tris[:, 2] > 0.01) & (tris[:, 2] < 1.99) & (np.abs(tris[:, 1]) < 0.99)
                  & (np.abs(tris[:, 0]) < 0.99)]
    assert blocks[:, 2].max() == pytest.approx(1.2, abs=1e-5)
    tall = blocks[blocks[:, 2] > 0.7]
    assert tall[:, 0].mean() == pytest.approx(-0.34, abs=0.05)
    assert ex.seconds < 1.0
    unit = np.linalg.norm(ex.scene.normals, axis=2)
    np.testing.assert_allclose(unit, 1.0, atol=1e-5)


def test_geometry_nodes_instances(ext):
    """Instance on Points of a generated cube: every instance placed by its own matrix."""
    scene = scenes.reset_scene()
    tree = bpy.data.node_groups.new("scatter", "GeometryNodeTree")
    tree.interface.new_socket(name="Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket(name="Geometry", in_out="OUTPUT",
                              socket_type="NodeSocketGeometry")
    tree.nodes.new("NodeGroupInput")
    out = tree.nodes.new("NodeGroupOutput")
    line = tree.nodes.new("GeometryNodeMeshLine")
    line.inputs["Count"].default_value = 3
    cube = tree.nodes.new("GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (0.2, 0.2, 0.2)
    inst = tree.nodes.new("GeometryNodeInstanceOnPoints")
    tree.links.new(line.outputs["Mesh"], inst.inputs["Points"])
    tree.links.new(cube.outputs["Mesh"], inst.inputs["Instance"])
    tree.links.new(inst.outputs["Instances"], out.inputs[0])
    obj = bpy.data.objects.new("scatter", bpy.data.meshes.new("scatter"))
    obj.modifiers.new("gn", "NODES").node_group = tree
    obj.location = (0.5, 0.0, 0.0)
    scene.collection.objects.link(obj)
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    ex = _export(width=8, height=8)
    tris = ex.scene.triangles
    assert len(tris) == 3 * 12
    centres = np.sort(tris.reshape(-1, 3)[:, 2])
    for z in (0.0, 1.0, 2.0):  # the line's points, 1 m apart along z
        assert np.any(np.abs(centres - (z + 0.1)) < 1e-6)
    np.testing.assert_allclose(tris.reshape(-1, 3)[:, 0].mean(), 0.5, atol=1e-6)


def test_principled_emission_blackbody_texture(ext):
    scenes.reset_scene()
    scene = bpy.context.scene
    mats = []
    m = scenes.principled("p", (0.2, 0.4, 0.6), emission=(2.0, 1.0, 0.5), strength=3.0,
                          roughness=0.25)
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Metallic"].default_value = 0.3
    bsdf.inputs["IOR"].default_value = 1.33
    name_t = "Transmission Weight" if "Transmission Weight" in bsdf.inputs else "Transmission"
    bsdf.inputs[name_t].default_value = 0.5
    mats.append(m)
    mats.append(scenes.blackbody_emitter("bb", 3000.0, 5.0))
    # An emission shader.
    em = bpy.data.materials.new("em")
    scenes.use_nodes(em)
    nodes = em.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    e = nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (0.0, 0.5, 1.0, 1.0)
    e.inputs["Strength"].default_value = 2.0
    em.node_tree.links.new(e.outputs[0], nodes["Material Output"].inputs["Surface"])
    mats.append(em)
    # An image texture on the base colour: its mean colour (sRGB 8-bit pixels).
    img = bpy.data.images.new("tex", 2, 2, alpha=True)
    img.pixels.foreach_set(np.array([1, 0, 0, 1] * 2 + [0, 0, 1, 1] * 2, np.float32))
    tex = scenes.principled("tex", (0.5, 0.5, 0.5))
    tnode = tex.node_tree.nodes.new("ShaderNodeTexImage")
    tnode.image = img
    tex.node_tree.links.new(tnode.outputs["Color"],
                            tex.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    mats.append(tex)
    # An unsupported node on the base colour, used by two objects: one warning.
    odd = scenes.principled("odd", (0.1, 0.9, 0.1))
    noise = odd.node_tree.nodes.new("ShaderNodeTexNoise")
    odd.node_tree.links.new(noise.outputs["Color"],
                            odd.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    mats += [odd, odd]
    for i, mat in enumerate(mats):
        scenes.quad_object(f"q{i}", [(i, 0, 0), (i + 0.5, 0, 0), (i + 0.5, 0.5, 0),
                                     (i, 0.5, 0)], mat)
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    ex = _export(width=16, height=16)
    p = _material(ex, "p")
    assert p.base_color == pytest.approx((0.2, 0.4, 0.6))
    assert (p.metallic, p.roughness, p.transmission, p.ior) == pytest.approx((0.3, 0.25, 0.5,
                                                                              1.33))
    assert p.emission == pytest.approx((1.0, 0.5, 0.25)) and p.emission_strength == \
        pytest.approx(6.0)
    bb = _material(ex, "bb")
    assert bb.emission_blackbody == pytest.approx(3000.0) and bb.emission_strength == 5.0
    assert bb.base_color == (0.0, 0.0, 0.0)
    e = _material(ex, "em")
    assert e.emission == pytest.approx((0.0, 0.5, 1.0)) and e.emission_strength == 2.0
    t = _material(ex, "tex")
    assert t.base_color == pytest.approx((0.5, 0.0, 0.5), abs=1e-3)
    o = _material(ex, "odd")
    assert o.base_color == pytest.approx((0.1, 0.9, 0.1), abs=1e-6)
    warnings = ex.warnings.messages
    assert sum("material 'odd'" in w for w in warnings) == 1, warnings
    assert any("material 'tex'" in w and "mean colour" in w for w in warnings), warnings


def test_lights_in_blender_units(ext):
    scenes.reset_scene()
    scene = bpy.context.scene
    specs = [("point", "POINT", (1, 2, 3), (0, 0, 0)), ("spot", "SPOT", (0, 0, 5), (0, 0, 0)),
             ("sun", "SUN", (0, 0, 9), (math.radians(30), 0, 0)),
             ("area", "AREA", (0, 0, 4), (0, 0, math.radians(30)))]
    for name, kind, loc, rot in specs:
        light = bpy.data.lights.new(name, kind)
        obj = bpy.data.objects.new(name, light)
        obj.location, obj.rotation_euler = loc, rot
        scene.collection.objects.link(obj)
    L = bpy.data.lights
    L["point"].energy, L["point"].shadow_soft_size, L["point"].color = 100.0, 0.1, (1, 0.5, 0.25)
    L["spot"].energy, L["spot"].spot_size, L["spot"].spot_blend = 50.0, math.radians(60), 0.3
    L["sun"].energy = 3.0
    L["area"].energy, L["area"].shape = 2.0, "RECTANGLE"
    L["area"].size, L["area"].size_y = 1.0, 0.5
    if hasattr(L["point"], "exposure"):
        L["point"].exposure = 1.0
    scenes.quad_object("floor", [(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)],
                       scenes.principled("w", (0.5, 0.5, 0.5)))
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    ex = _export(width=16, height=16)
    lights = {light.name: light for light in ex.scene.lights}
    point = lights["point"]
    expected = 200.0 if hasattr(L["point"], "exposure") else 100.0
    assert point.type == "point" and point.power == pytest.approx(expected)
    assert point.radius == pytest.approx(0.1) and tuple(point.position) == (1, 2, 3)
    np.testing.assert_allclose(point.color, (1, 0.5, 0.25))
    spot = lights["spot"]
    assert spot.spot_size == pytest.approx(math.radians(60)) and spot.spot_blend == \
        pytest.approx(0.3)
    np.testing.assert_allclose(spot.direction, (0, 0, -1), atol=1e-7)
    sun = lights["sun"]
    assert sun.type == "sun" and sun.power == pytest.approx(3.0)
    np.testing.assert_allclose(sun.direction, (0, math.sin(math.radians(30)),
                                               -math.cos(math.radians(30))), atol=1e-6)
    # The area light: a [[lights]] area light turned 30° about z (its up), which the core
    # makes an exact one-sided quad of radiance P / (π A).
    area = next(light for light in ex.lights if light.type == "area")
    assert "area" not in lights and area.size == pytest.approx((1.0, 0.5))
    np.testing.assert_allclose(area.up, (-math.sin(math.radians(30)),
                                         math.cos(math.radians(30)), 0.0), atol=1e-7)
    i = next(i for i, m in enumerate(ex.scene.materials) if m.name == "area_light:area")
    material, quad = ex.scene.materials[i], ex.scene.triangles[ex.scene.material_ids == i]
    c = quad.reshape(-1, 3)
    np.testing.assert_allclose(c[:, 2], 4.0)
    edge = quad[0, 2] - quad[0, 1]  # the width (local x): corners c1 -> c2
    assert np.linalg.norm(edge) == pytest.approx(1.0)
    assert math.degrees(math.atan2(edge[1], edge[0])) == pytest.approx(30.0, abs=1e-4)
    assert material.one_sided_emission
    assert material.emission_strength == pytest.approx(2.0 / (math.pi * 0.5))
    n = np.cross(quad[0, 1] - quad[0, 0], quad[0, 2] - quad[0, 0])
    assert n[2] < 0  # emits downwards, along the light's -z


@pytest.mark.parametrize("scale", [(2.0, 3.0, 1.0), (-1.0, 0.5, 2.0)])
def test_area_light_quad_follows_the_object_transform(ext, scale):
    """Scaled, turned and mirrored: the quad's corners are the light's corners under the
    object's matrix, and it still emits along the object's -Z."""
    scene = scenes.reset_scene()
    light = bpy.data.lights.new("panel", "AREA")
    light.shape, light.size, light.size_y, light.energy = "RECTANGLE", 0.4, 0.2, 5.0
    obj = bpy.data.objects.new("panel", light)
    obj.location, obj.scale = (0.5, -1.0, 3.0), scale
    obj.rotation_euler = (math.radians(20), math.radians(-35), math.radians(60))
    scene.collection.objects.link(obj)
    scene.camera = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(scene.camera)
    bpy.context.view_layer.update()
    ex = _export(width=8, height=8)
    m = np.array(obj.matrix_world)
    local = np.array([[x, y, 0.0, 1.0] for x in (-0.2, 0.2) for y in (-0.1, 0.1)])
    expected = np.unique(np.round((local @ m.T)[:, :3], 6), axis=0)  # rows, sorted
    (i,) = [i for i, mat in enumerate(ex.scene.materials) if mat.name == "area_light:panel"]
    quad = ex.scene.triangles[ex.scene.material_ids == i]
    corners = np.unique(np.round(quad.reshape(-1, 3), 6), axis=0)
    np.testing.assert_allclose(corners, expected, atol=2e-6)
    n = np.cross(quad[0, 1] - quad[0, 0], quad[0, 2] - quad[0, 0])
    assert n @ (-m[:3, 2]) > 0  # emits along the object's -Z


def test_values_beyond_a_jobs_ranges_are_clamped_by_the_core_with_a_warning(ext):
    """Blender's sockets allow a base colour above 1, an IOR below 1, a negative power:
    the core's validators (the job format's own) clamp them, each with a warning."""
    scene = scenes.reset_scene()
    mat = scenes.principled("hot", (1.5, 0.5, 0.2))
    mat.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value = 0.5
    scenes.quad_object("floor", [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], mat)
    light = bpy.data.lights.new("dark", "POINT")
    light.energy = -5.0
    scene.collection.objects.link(bpy.data.objects.new("dark", light))
    scene.camera = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(scene.camera)
    ex = _export(width=8, height=8)
    spec = _material(ex, "hot")
    assert spec.base_color == (1.0, 0.5, pytest.approx(0.2)) and spec.ior == 1.0
    (point,) = ex.scene.lights
    assert point.power == 0.0
    assert ex.warnings.messages == [
        "material 'hot': base_color = 1.5 clamped to 1 (outside the range relray renders)",
        "material 'hot': ior = 0.5 clamped to 1 (outside the range relray renders)",
        "light 'dark': power = -5 clamped to 0 (outside the range relray renders)"]


def test_world_background(ext):
    scene = scenes.reset_scene()
    world = bpy.data.worlds.new("w")
    scenes.use_nodes(world)
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.1, 0.2, 0.3, 1.0)
    bg.inputs["Strength"].default_value = 2.0
    scene.world = world
    export = ext_module("relblend.export")
    warnings = export.Warnings()
    np.testing.assert_allclose(export.world_background(world, warnings), (0.2, 0.4, 0.6),
                               atol=1e-6)
    assert export.world_background(None, warnings).tolist() == [0, 0, 0]


@pytest.mark.parametrize("fit,size,shift", [
    ("AUTO", (64, 36), (0.0, 0.0)), ("AUTO", (36, 64), (0.1, -0.05)),
    ("HORIZONTAL", (50, 40), (0.0, 0.2)), ("VERTICAL", (64, 48), (0.15, 0.0)),
    ("VERTICAL", (40, 60), (-0.1, 0.1)),
])
def test_camera_matches_blenders_projection(ext, fit, size, shift):
    """Pixel directions of the core camera land where Blender projects them."""
    from bpy_extras.object_utils import world_to_camera_view

    scene = scenes.reset_scene()
    scene.render.resolution_x, scene.render.resolution_y = size
    cam_data = bpy.data.cameras.new("c")
    cam_data.sensor_fit = fit
    cam_data.lens = 35.0
    cam_data.shift_x, cam_data.shift_y = shift
    cam = bpy.data.objects.new("c", cam_data)
    cam.location = (1.0, -2.0, 0.5)
    cam.rotation_euler = (math.radians(80), math.radians(5), math.radians(20))
    scene.collection.objects.link(cam)
    scene.camera = cam
    bpy.context.view_layer.update()
    export = ext_module("relblend.export")
    core_camera = ext_module("core.render.camera")
    settings = export.camera_settings(cam, *size)
    pin = core_camera.PinholeCamera.from_settings(settings, *size)
    w, h = size
    cols = np.array([0.0, w / 2, w, 5.5, w - 3.25])
    rows = np.array([0.0, h / 2, h, h - 2.5, 7.0])
    d = pin.directions_cam(cols, rows)
    from mathutils import Vector

    for col, row, di in zip(cols, rows, d, strict=True):
        p = np.asarray(settings.position) + 7.0 * di
        uv = world_to_camera_view(scene, cam, Vector(p))
        assert uv.x == pytest.approx(col / w, abs=1e-5)
        assert uv.y == pytest.approx(1.0 - row / h, abs=1e-5)  # Blender's v is bottom-up
